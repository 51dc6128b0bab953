//! The plots a BRDF person expects: the fitted model as continuous curves along slices at fixed
//! incidence, with the measured points that lie near each slice ([`slices`]), and hemisphere
//! maps of measured, fitted and residual values for a few incidence directions
//! ([`hemispheres`]).
//!
//! Conventions (stated in the figures): directions in the swatch frame with the fibre tangent T at
//! the fitted azimuth psi and B = N x T. A slice lies in the T-N plane ("along the fibres") or in
//! the B-N plane ("across the fibres"): the light at theta_i on the negative side of the plane's
//! axis, the view at a signed angle theta_o, positive on the far side (forward, towards the
//! mirror direction), negative on the light's side (back). Values are the BRDF in 1/sr, the mean
//! over the channels. A hemisphere map shows every view direction for one light, in orthographic
//! projection seen from above: right = +B (the far side of a light coming from -B), up = +T.

mod common;
mod hemispheres;
mod legend;
mod slices;

pub use common::{Brdf, Curve};
#[cfg_attr(not(feature = "internals"), allow(unused_imports))] // for the tests and benchmarks
pub use hemispheres::{
    hemispheres, HemispherePlot, CELL_PX, MAP_THETAS, MAX_IMAGE_ROWS, NEAR_LIGHT_DEG,
};
#[cfg_attr(not(feature = "internals"), allow(unused_imports))] // for the tests and benchmarks
pub use slices::{
    near_slice, slices, DrawnBin, NearSample, SlicePlot, SlicesDrawn, BIN_DEG, MAX_BAND_OFFSETS, NEAR_PLANE_COSINE, NEAR_THETA_DEG, SLICE_THETAS,
};
