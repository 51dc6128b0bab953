//! fibrefit: fit fibre reflectance models to goniometric and image measurements.
//!
//! Data flows one way: [`load`] -> [`model`] -> fit -> [`export`] (and [`render`] beside it);
//! [`cli`] drives it.

// `!(x > 0.0)` is used on purpose: it is also true for NaN, which must take the safe branch.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

pub mod bench;
pub mod cli;
pub mod export;
pub mod fit;
pub mod load;
pub mod model;
pub mod progress;
pub mod render;
pub mod synth;
