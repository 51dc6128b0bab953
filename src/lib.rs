//! fibrefit: fit fibre reflectance models to goniometric and image measurements.
//!
//! Data flows one way: [`load`] -> [`model`] -> fit -> [`export`]; [`cli`] drives it.

pub mod cli;
pub mod export;
pub mod load;
pub mod model;
