//! Rectifying calibrated photos onto the window's texel grid (undistorted, resampled
//! bilinearly) and making their values absolute from the reference patch: per photo and
//! channel, the light-intensity x exposure product that makes the patch read its known
//! reflectance, so the capture's point lights have intensity 1 and its albedos come out
//! absolute (white balance included).

use super::Calibration;
use crate::load::board::BoardFile;
use crate::load::capture::pixel_position;
use crate::load::photo::Photo;
use anyhow::{bail, Result};
use nalgebra::Vector3;

/// What rectifying every photo leaves besides the images (each written as it is made).
pub struct Rectified {
    /// Texels across and down the window.
    pub size: [usize; 2],
    /// 255 where some photo sees the texel well and it is not at the window's edge, 0
    /// elsewhere.
    pub mask: Vec<u8>,
    /// Each photo's light x exposure product per channel from the reference patch.
    pub scale: Vec<[f64; 3]>,
    /// Each photo's fraction of window texels it sees well.
    pub seen: Vec<f64>,
}

/// Views more oblique than this (cosine to the normal) are masked.
const MIN_VIEW_COS: f64 = 0.17;
/// A texel whose photo value reaches this (linear) is clipped.
const CLIPPED: f32 = 0.98;
/// Texels this close to the window's edge (mm) are masked (the swatch's edge, the outline).
const EDGE_MM: f64 = 1.0;

/// Rectifies calibrated photos one at a time onto a texel grid over the board's window, so
/// that only one photo's pixels need be held.
pub struct Rectifier<'a> {
    board: &'a BoardFile,
    cal: &'a Calibration,
    done: Rectified,
}

impl<'a> Rectifier<'a> {
    /// A `size` texel grid over `board`'s window for the photos `cal` calibrated.
    pub fn new(board: &'a BoardFile, cal: &'a Calibration, size: [usize; 2]) -> Self {
        Self {
            board,
            cal,
            done: Rectified {
                size,
                mask: vec![0u8; size[0] * size[1]],
                scale: Vec::new(),
                seen: Vec::new(),
            },
        }
    }

    /// Photo `k` (lit by a point light at `light`, mm) rectified: its linear RGB texels (row 0
    /// at the window's top) in units where the point light has intensity 1; NaN where that
    /// photo does not see the texel well (out of frame, too oblique, clipped): the photo's own
    /// mask, which the capture's loader honours. Photos come in order, from 0.
    pub fn photo(&mut self, k: usize, photo: &Photo, light: &Vector3<f64>) -> Result<Vec<f32>> {
        let (board, cal, size) = (self.board, self.cal, self.done.size);
        assert_eq!(k, self.done.scale.len(), "photos are rectified in order");
        let w = board.window_mm;
        let size_mm = [w[2] - w[0], w[3] - w[1]];
        let centre = Vector3::new(0.5 * (w[0] + w[2]), 0.5 * (w[1] + w[3]), 0.0);
        let n = size[0] * size[1];
        let pose = &cal.poses[k];
        let s = patch_scale(board, cal, k, photo, light)?;
        let mut img = vec![f32::NAN; 3 * n];
        let mut good = 0usize;
        for y in 0..size[1] {
            for x in 0..size[0] {
                let p = centre + pixel_position(size_mm, size[0], size[1], x, y);
                let i = y * size[0] + x;
                let near_edge = p.x - w[0] < EDGE_MM
                    || w[2] - p.x < EDGE_MM
                    || p.y - w[1] < EDGE_MM
                    || w[3] - p.y < EDGE_MM;
                let view_cos = (pose.position - p).normalize().z;
                let value = cal
                    .intrinsics
                    .project(&pose.to_camera(&p))
                    .and_then(|[u, v]| Some((photo.sample(u, v)?, photo.peak_near(u, v)?)));
                match value {
                    Some((rgb, peak)) if !near_edge && view_cos > MIN_VIEW_COS && peak < CLIPPED => {
                        for c in 0..3 {
                            img[3 * i + c] = (rgb[c] as f64 / s[c]) as f32;
                        }
                        self.done.mask[i] = 255;
                        good += 1;
                    }
                    _ => {}
                }
            }
        }
        self.done.scale.push(s);
        self.done.seen.push(good as f64 / n as f64);
        Ok(img)
    }

    /// What the photos left: the mask, each one's scale and share seen.
    pub fn finish(self) -> Rectified {
        self.done
    }
}

/// Photo `k`'s light x exposure product per channel: the patch's mean value over the mean of
/// what a unit light gives there (reflectance / pi x cos(theta_i) / r^2, r in metres).
fn patch_scale(
    board: &BoardFile,
    cal: &Calibration,
    k: usize,
    photo: &Photo,
    light: &Vector3<f64>,
) -> Result<[f64; 3]> {
    let r = board.patch.rect_mm;
    let pose = &cal.poses[k];
    let (mut sum, mut unit, mut count) = ([0.0; 3], 0.0, 0usize);
    let steps = 12;
    for j in 0..steps {
        for i in 0..steps {
            // the patch's middle, 2 mm in from its edges
            let x = r[0] + 2.0 + (r[2] - r[0] - 4.0) * (i as f64 + 0.5) / steps as f64;
            let y = r[1] + 2.0 + (r[3] - r[1] - 4.0) * (j as f64 + 0.5) / steps as f64;
            let p = Vector3::new(x, y, 0.0);
            let Some(rgb) = cal
                .intrinsics
                .project(&pose.to_camera(&p))
                .and_then(|[u, v]| photo.sample(u, v))
            else {
                continue;
            };
            let d = light - p;
            let r_m = d.norm() / 1000.0;
            let g = board.patch.reflectance / std::f64::consts::PI * (d.z / d.norm()).max(0.0)
                / (r_m * r_m);
            for c in 0..3 {
                sum[c] += rgb[c] as f64;
            }
            unit += g;
            count += 1;
        }
    }
    if count < steps * steps / 2 || unit <= 0.0 || sum.iter().any(|&s| s <= 0.0) {
        bail!(
            "{}: the reference patch is not in the picture (or not lit): frame the whole board",
            photo.path.display()
        );
    }
    Ok(sum.map(|s| s / unit))
}
