//! The bundle adjustment: every corner of every photo reprojected through the shared
//! intrinsics and the photo's pose, the squared pixel errors minimised by the fitter's bounded
//! Levenberg-Marquardt (central finite-difference Jacobian), and the camera positions' standard
//! errors from the Jacobian at the minimum.

use super::{Calibration, Views};
use crate::board::camera::{Intrinsics, Pose};
use crate::fit::lm::BoundedLm;
use anyhow::{anyhow, Result};
use argmin::core::{Error, Executor, Jacobian, Operator, State};
use nalgebra::{DMatrix, DVector, Rotation3, Vector3};

/// Parameters of the intrinsics: focal length, principal point (2), k1, k2.
const NK: usize = 5;
/// Parameters of a pose: rotation (axis x angle, 3) and position (mm, 3).
const NP: usize = 6;

/// The adjustment as argmin sees it.
struct Problem<'a> {
    views: &'a Views,
    /// The intrinsics held (not adjusted).
    fixed: Option<Intrinsics>,
}

impl Problem<'_> {
    fn offset(&self) -> usize {
        if self.fixed.is_some() {
            0
        } else {
            NK
        }
    }

    fn intrinsics(&self, x: &DVector<f64>) -> Intrinsics {
        match self.fixed {
            Some(k) => k,
            None => Intrinsics {
                size_px: self.views.size_px,
                focal_px: x[0],
                principal_px: [x[1], x[2]],
                k: [x[3], x[4]],
            },
        }
    }

    fn pose(&self, x: &DVector<f64>, photo: usize) -> Pose {
        let o = self.offset() + NP * photo;
        Pose {
            rotation: Rotation3::from_scaled_axis(Vector3::new(x[o], x[o + 1], x[o + 2])),
            position: Vector3::new(x[o + 3], x[o + 4], x[o + 5]),
        }
    }

    fn pack(&self, k: &Intrinsics, poses: &[Pose]) -> DVector<f64> {
        let mut x = Vec::new();
        if self.fixed.is_none() {
            x.extend([k.focal_px, k.principal_px[0], k.principal_px[1], k.k[0], k.k[1]]);
        }
        for p in poses {
            x.extend(p.rotation.scaled_axis().iter());
            x.extend(p.position.iter());
        }
        DVector::from_vec(x)
    }

    /// Residuals (px): x then y error of every corner, photo by photo.
    fn residuals(&self, x: &DVector<f64>) -> DVector<f64> {
        let k = self.intrinsics(x);
        let mut r = Vec::new();
        for (photo, corners) in self.views.corners.iter().enumerate() {
            let pose = self.pose(x, photo);
            for c in corners {
                let p = pose.to_camera(&Vector3::new(c.board_mm[0], c.board_mm[1], 0.0));
                match k.project(&p) {
                    Some(q) => r.extend([q[0] - c.pixel[0], q[1] - c.pixel[1]]),
                    None => r.extend([1e6, 1e6]),
                }
            }
        }
        DVector::from_vec(r)
    }
}

impl Operator for Problem<'_> {
    type Param = DVector<f64>;
    type Output = DVector<f64>;
    fn apply(&self, x: &DVector<f64>) -> Result<DVector<f64>, Error> {
        Ok(self.residuals(x))
    }
}

impl Jacobian for Problem<'_> {
    type Param = DVector<f64>;
    type Jacobian = DMatrix<f64>;
    fn jacobian(&self, x: &DVector<f64>) -> Result<DMatrix<f64>, Error> {
        let m = self.residuals(x).len();
        let mut j = DMatrix::zeros(m, x.len());
        for i in 0..x.len() {
            let h = 1e-6 * x[i].abs().max(1.0);
            let (mut a, mut b) = (x.clone(), x.clone());
            a[i] += h;
            b[i] -= h;
            let d = (self.residuals(&a) - self.residuals(&b)) / (2.0 * h);
            j.set_column(i, &d);
        }
        Ok(j)
    }
}

/// Adjust `start` and `poses` to every corner of `views` (the intrinsics held when `fixed`).
pub fn adjust(views: &Views, start: Intrinsics, poses: Vec<Pose>, fixed: bool) -> Result<Calibration> {
    let problem = Problem {
        views,
        fixed: fixed.then_some(start),
    };
    let x0 = problem.pack(&start, &poses);
    let n = x0.len();
    let mut lo = DVector::from_element(n, f64::NEG_INFINITY);
    let hi = DVector::from_element(n, f64::INFINITY);
    if !fixed {
        lo[0] = 1.0; // a focal length of at least a pixel
    }
    let solver = BoundedLm::new(lo, hi, 1e-14);
    let state = Executor::new(problem, solver)
        .configure(|c| c.param(x0).max_iters(200))
        .run()
        .map_err(|e| anyhow!("the bundle adjustment failed: {e}"))?
        .state;
    let problem = Problem {
        views,
        fixed: fixed.then_some(start),
    };
    let x = state
        .get_best_param()
        .cloned()
        .ok_or_else(|| anyhow!("the bundle adjustment found nothing"))?;
    let r = problem.residuals(&x);
    let intrinsics = problem.intrinsics(&x);
    let mut rms_px = Vec::new();
    let mut at = 0;
    for corners in &views.corners {
        let n2 = 2 * corners.len();
        let ss = r.rows(at, n2).norm_squared();
        rms_px.push((ss / corners.len() as f64).sqrt());
        at += n2;
    }
    // standard errors: sigma^2 (J^T J)^-1, sigma^2 from the residuals
    let j = problem.jacobian(&x).map_err(|e| anyhow!("{e}"))?;
    let dof = (r.len() as f64 - n as f64).max(1.0);
    let sigma2 = r.norm_squared() / dof;
    let cov = (j.transpose() * &j)
        .try_inverse()
        .map(|c| c * sigma2)
        .unwrap_or_else(|| DMatrix::from_element(n, n, f64::NAN));
    let o = problem.offset();
    let position_se_mm = (0..views.corners.len())
        .map(|p| {
            let b = o + NP * p + 3;
            [0, 1, 2].map(|i| cov[(b + i, b + i)].max(0.0).sqrt())
        })
        .collect();
    Ok(Calibration {
        intrinsics,
        poses: (0..views.corners.len()).map(|p| problem.pose(&x, p)).collect(),
        rms_px,
        position_se_mm,
    })
}
