//! What both figures share: the BRDFs they draw, the swatch frame's directions, the PNG they
//! encode.

use crate::export::atomic::Sink;
use crate::model::frame::Vec3;
use anyhow::{anyhow, Result};

/// A BRDF per channel at (l, v) in the swatch frame; `None` where it is not defined (outside a
/// measured file's range).
pub type Brdf<'a> = &'a (dyn Fn(&Vec3, &Vec3) -> Option<[f64; 3]> + Sync);

/// A named BRDF drawn as a curve.
pub struct Curve<'a> {
    pub name: String,
    pub brdf: Brdf<'a>,
    /// Dashed (a measured file evaluated densely) rather than solid.
    pub dashed: bool,
}

pub(super) fn err<E: std::fmt::Debug>(e: E) -> anyhow::Error {
    anyhow!("plot: {e:?}")
}

pub(super) fn mean(v: &[f64; 3], channels: usize) -> f64 {
    v[..channels].iter().sum::<f64>() / channels as f64
}

/// Unit direction at signed angle `theta` (degrees) from N towards `axis`.
pub(super) fn in_plane(axis: &Vec3, theta_deg: f64) -> Vec3 {
    let t = theta_deg.to_radians();
    axis * t.sin() + Vec3::z() * t.cos()
}

/// The fibre tangent T at azimuth `psi_deg` and B = N x T.
pub(super) fn axes(psi_deg: f64) -> (Vec3, Vec3) {
    let p = psi_deg.to_radians();
    (
        Vec3::new(p.cos(), p.sin(), 0.0),
        Vec3::new(-p.sin(), p.cos(), 0.0),
    )
}

/// Encode the RGB buffer `buf` of a `w` x `h` figure as PNG into `path`.
pub(super) fn save(path: Sink, w: u32, h: u32, buf: Vec<u8>) -> Result<()> {
    let img = image::RgbImage::from_raw(w, h, buf).ok_or_else(|| anyhow!("plot buffer size"))?;
    path.png(&img)
}
