//! The closed-form start: each photo's board-to-image homography (normalised DLT), the focal
//! length from all of them (Zhang's constraints with the principal point at the centre), and
//! each pose from its homography.

use super::Corner;
use crate::board::camera::{Intrinsics, Pose};
use anyhow::{bail, Result};
use nalgebra::{DMatrix, Matrix3, Rotation3, Vector3};

/// The similarity that moves `pts` to their centroid and a mean distance of sqrt(2).
fn normaliser(pts: impl Iterator<Item = [f64; 2]> + Clone) -> Matrix3<f64> {
    let n = pts.clone().count() as f64;
    let (mx, my) = pts
        .clone()
        .fold((0.0, 0.0), |(a, b), p| (a + p[0] / n, b + p[1] / n));
    let d = pts.map(|p| (p[0] - mx).hypot(p[1] - my)).sum::<f64>() / n;
    let s = std::f64::consts::SQRT_2 / d.max(1e-12);
    Matrix3::new(s, 0.0, -s * mx, 0.0, s, -s * my, 0.0, 0.0, 1.0)
}

/// The homography taking board points (mm) to pixels.
pub fn fit(corners: &[Corner]) -> Result<Matrix3<f64>> {
    let tx = normaliser(corners.iter().map(|c| c.board_mm));
    let tu = normaliser(corners.iter().map(|c| c.pixel));
    let mut a = DMatrix::<f64>::zeros(2 * corners.len(), 9);
    for (i, c) in corners.iter().enumerate() {
        let x = tx * Vector3::new(c.board_mm[0], c.board_mm[1], 1.0);
        let u = tu * Vector3::new(c.pixel[0], c.pixel[1], 1.0);
        let (x, y, u, v) = (x[0], x[1], u[0], u[1]);
        let r = [-x, -y, -1.0, 0.0, 0.0, 0.0, u * x, u * y, u];
        let s = [0.0, 0.0, 0.0, -x, -y, -1.0, v * x, v * y, v];
        for j in 0..9 {
            a[(2 * i, j)] = r[j];
            a[(2 * i + 1, j)] = s[j];
        }
    }
    let eig = (a.transpose() * &a).symmetric_eigen();
    let k = eig.eigenvalues.imin();
    let h = eig.eigenvectors.column(k);
    let hn = Matrix3::from_row_slice(h.as_slice());
    let Some(tu_inv) = tu.try_inverse() else {
        bail!("the corners are all at one pixel");
    };
    let hm = tu_inv * hn * tx;
    if !hm.iter().all(|v| v.is_finite()) || hm[(2, 2)].abs() < 1e-300 {
        bail!("the corners give no homography (all on a line?)");
    }
    Ok(hm / hm[(2, 2)])
}

/// Intrinsics to start from: the principal point at the centre, no distortion, and the focal
/// length that best makes every homography's first two columns orthogonal and of one length.
pub fn intrinsics_start(size_px: [u32; 2], hs: &[Matrix3<f64>]) -> Intrinsics {
    let c = [size_px[0] as f64 / 2.0, size_px[1] as f64 / 2.0];
    let shift = Matrix3::new(1.0, 0.0, -c[0], 0.0, 1.0, -c[1], 0.0, 0.0, 1.0);
    let (mut num, mut den) = (0.0, 0.0);
    for h in hs {
        let h = shift * h;
        let h = h / h.norm();
        let (h1, h2) = (h.column(0), h.column(1));
        // a = 1 / f^2: a (h1x h2x + h1y h2y) = -h1z h2z; a (|h1xy|^2 - |h2xy|^2) = h2z^2 - h1z^2
        for (coef, rhs) in [
            (h1[0] * h2[0] + h1[1] * h2[1], -h1[2] * h2[2]),
            (
                h1[0] * h1[0] + h1[1] * h1[1] - h2[0] * h2[0] - h2[1] * h2[1],
                h2[2] * h2[2] - h1[2] * h1[2],
            ),
        ] {
            num += coef * rhs;
            den += coef * coef;
        }
    }
    let a = num / den;
    let focal_px = if a > 0.0 && a.is_finite() {
        1.0 / a.sqrt()
    } else {
        size_px[0].max(size_px[1]) as f64
    };
    Intrinsics {
        size_px,
        focal_px,
        principal_px: c,
        k: [0.0, 0.0],
    }
}

/// The pose a homography gives with intrinsics `k` (distortion ignored).
pub fn pose(k: &Intrinsics, h: &Matrix3<f64>) -> Result<Pose> {
    let km = Matrix3::new(
        k.focal_px,
        0.0,
        k.principal_px[0],
        0.0,
        k.focal_px,
        k.principal_px[1],
        0.0,
        0.0,
        1.0,
    );
    let m = km.try_inverse().expect("a focal length > 0") * h;
    let mut l = 1.0 / m.column(0).norm();
    if (m.column(2) * l)[2] < 0.0 {
        l = -l; // the board in front of the camera
    }
    let (r1, r2, t) = (m.column(0) * l, m.column(1) * l, m.column(2) * l);
    let r3 = r1.cross(&r2);
    let mut r = Matrix3::from_columns(&[r1, r2, r3]);
    let svd = r.svd(true, true);
    let (Some(u), Some(vt)) = (svd.u, svd.v_t) else {
        bail!("no rotation from the homography");
    };
    r = u * vt;
    if r.determinant() < 0.0 {
        bail!("the homography is a reflection");
    }
    let rotation = Rotation3::from_matrix_unchecked(r);
    let position = -(rotation.inverse() * Vector3::from(t));
    Ok(Pose { rotation, position })
}
