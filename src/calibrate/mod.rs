//! Calibrating photos of a board: the cameras' shared intrinsics (focal length, principal
//! point, radial distortion k1, k2) and each photo's pose in the board frame, from the
//! markers' corners. A closed-form start (Zhang's homography method with the principal point at
//! the image's centre and square pixels), then a bundle adjustment of every corner over all
//! photos with the fitter's own bounded Levenberg-Marquardt ([`crate::fit::lm::BoundedLm`]).
//!
//! Reference: Z. Zhang (2000), "A flexible new technique for camera calibration", IEEE PAMI
//! 22(11).

pub mod blur;
pub mod bundle;
pub mod coverage;
pub mod homography;
pub mod noise;
pub mod overlay;
pub mod rectify;

use crate::board::camera::{Intrinsics, Pose};
use anyhow::{bail, Result};

/// One marker corner seen in one photo.
#[derive(Clone, Copy, Debug)]
pub struct Corner {
    /// Its position on the board (mm, z = 0).
    pub board_mm: [f64; 2],
    /// Where the detector found it (px).
    pub pixel: [f64; 2],
}

/// The corners seen in each photo, and the photos' size.
#[derive(Clone, Debug)]
pub struct Views {
    /// Every photo's size in pixels (one camera: all equal).
    pub size_px: [u32; 2],
    /// Each photo's corners.
    pub corners: Vec<Vec<Corner>>,
}

/// What the calibration found.
#[derive(Clone, Debug)]
pub struct Calibration {
    /// The shared intrinsics.
    pub intrinsics: Intrinsics,
    /// Each photo's pose.
    pub poses: Vec<Pose>,
    /// Each photo's RMS reprojection error (px).
    pub rms_px: Vec<f64>,
    /// Each photo's camera position's standard error (mm, x y z) from the adjustment.
    pub position_se_mm: Vec<[f64; 3]>,
}

/// Fewest corners a photo's pose needs (two markers).
pub const MIN_CORNERS: usize = 8;

/// Calibrate `views`: intrinsics and poses (the intrinsics held at `fixed` when given).
pub fn calibrate(views: &Views, fixed: Option<&Intrinsics>) -> Result<Calibration> {
    if views.corners.is_empty() {
        bail!("no photos to calibrate");
    }
    for (k, c) in views.corners.iter().enumerate() {
        if c.len() < MIN_CORNERS {
            bail!(
                "photo {k}: {} marker corners; a pose needs at least {MIN_CORNERS}",
                c.len()
            );
        }
    }
    let hs: Vec<_> = views
        .corners
        .iter()
        .map(|c| homography::fit(c))
        .collect::<Result<_>>()?;
    let start = match fixed {
        Some(k) => *k,
        None => homography::intrinsics_start(views.size_px, &hs),
    };
    let poses: Vec<Pose> = hs
        .iter()
        .map(|h| homography::pose(&start, h))
        .collect::<Result<_>>()?;
    bundle::adjust(views, start, poses, fixed.is_some())
}
