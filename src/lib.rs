//! fibrefit: fit fibre reflectance models to goniometric and image measurements.
//!
//! The crate flows one way: [`load`] -> [`model`] -> fit -> [`export`].

pub mod model;
