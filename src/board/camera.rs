//! A photo's camera: pinhole intrinsics with radial distortion (k1, k2) and a pose in the board
//! frame, in OpenCV's conventions (camera x right, y down, z along the view; pixel (0, 0) covers
//! [0, 1] x [0, 1]).

use nalgebra::{Matrix3, Rotation3, Vector3};
use serde::{Deserialize, Serialize};

/// Intrinsics: focal length (px, square pixels, no skew), principal point (px) and radial
/// distortion `x_d = x (1 + k1 r^2 + k2 r^4)` of normalised coordinates.
#[derive(Clone, Copy, Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Intrinsics {
    /// Image size in pixels, [width, height].
    pub size_px: [u32; 2],
    /// Focal length in pixels.
    pub focal_px: f64,
    /// Principal point in pixels.
    pub principal_px: [f64; 2],
    /// Radial distortion [k1, k2].
    pub k: [f64; 2],
}

/// A camera's pose: board point X is at `rotation * (X - position)` in the camera frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Pose {
    /// World (board frame) to camera rotation.
    pub rotation: Rotation3<f64>,
    /// The lens centre in the board frame (mm).
    pub position: Vector3<f64>,
}

impl Pose {
    /// A camera at `position` looking at `target`, the board's +z (or, looking straight down,
    /// +y) appearing up in the picture.
    pub fn look_at(position: Vector3<f64>, target: Vector3<f64>) -> Self {
        let z = (target - position).normalize();
        let mut up = Vector3::z();
        if (up - up.dot(&z) * z).norm() < 1e-6 {
            up = Vector3::y();
        }
        let y = -(up - up.dot(&z) * z).normalize();
        let x = y.cross(&z);
        let m = Matrix3::from_rows(&[x.transpose(), y.transpose(), z.transpose()]);
        Self {
            rotation: Rotation3::from_matrix_unchecked(m),
            position,
        }
    }

    /// The board point `p` in the camera frame.
    pub fn to_camera(&self, p: &Vector3<f64>) -> Vector3<f64> {
        self.rotation * (p - self.position)
    }

    /// The direction `d` of the camera frame in the board frame.
    pub fn to_board_direction(&self, d: &Vector3<f64>) -> Vector3<f64> {
        self.rotation.inverse() * d
    }
}

impl Intrinsics {
    /// The distortion factor at squared radius `r2`.
    fn factor(&self, r2: f64) -> f64 {
        1.0 + self.k[0] * r2 + self.k[1] * r2 * r2
    }

    /// The pixel of camera-frame point `p` (None behind the camera).
    pub fn project(&self, p: &Vector3<f64>) -> Option<[f64; 2]> {
        if p.z <= 1e-9 {
            return None;
        }
        let (x, y) = (p.x / p.z, p.y / p.z);
        let d = self.factor(x * x + y * y);
        Some([
            self.focal_px * x * d + self.principal_px[0],
            self.focal_px * y * d + self.principal_px[1],
        ])
    }

    /// The undistorted normalised coordinates of pixel position `(u, v)` (fixed-point
    /// inversion of the distortion).
    pub fn unproject(&self, u: f64, v: f64) -> [f64; 2] {
        let xd = (u - self.principal_px[0]) / self.focal_px;
        let yd = (v - self.principal_px[1]) / self.focal_px;
        let (mut x, mut y) = (xd, yd);
        for _ in 0..20 {
            let d = self.factor(x * x + y * y);
            (x, y) = (xd / d, yd / d);
        }
        [x, y]
    }
}

/// Where the ray of pixel position `(u, v)` meets the board plane z = 0 (None when it does not,
/// in front of the camera).
pub fn pixel_on_board(k: &Intrinsics, pose: &Pose, u: f64, v: f64) -> Option<Vector3<f64>> {
    let [x, y] = k.unproject(u, v);
    let d = pose.to_board_direction(&Vector3::new(x, y, 1.0));
    if d.z.abs() < 1e-12 {
        return None;
    }
    let t = -pose.position.z / d.z;
    (t > 0.0).then(|| pose.position + t * d)
}

/// The lens blur both sides of the photo route share: `synth --photos` blurs its photos with it
/// and `calibrate` measures a photo's blur by fitting it. Blurs the interleaved `image` (`w` x
/// `h` pixels of `channels` values) in place by a Gaussian of standard deviation `sigma` px,
/// truncated at 3 sigma, separable, edges clamped.
pub fn gaussian_blur(image: &mut [f64], w: usize, h: usize, channels: usize, sigma: f64) {
    use rayon::prelude::*;
    assert_eq!(image.len(), w * h * channels);
    let r = (3.0 * sigma).ceil() as isize;
    let kernel: Vec<f64> = (-r..=r)
        .map(|i| (-0.5 * (i as f64 / sigma).powi(2)).exp())
        .collect();
    let total: f64 = kernel.iter().sum();
    let kernel: Vec<f64> = kernel.iter().map(|k| k / total).collect();
    let pass = |src: &[f64], dst: &mut [f64], along_x: bool| {
        dst.par_chunks_mut(channels * w)
            .enumerate()
            .for_each(|(y, row)| {
                for x in 0..w {
                    let out = &mut row[channels * x..channels * (x + 1)];
                    out.iter_mut().for_each(|o| *o = 0.0);
                    for (j, kv) in kernel.iter().enumerate() {
                        let o = j as isize - r;
                        let (xx, yy) = if along_x {
                            ((x as isize + o).clamp(0, w as isize - 1) as usize, y)
                        } else {
                            (x, (y as isize + o).clamp(0, h as isize - 1) as usize)
                        };
                        let at = channels * (yy * w + xx);
                        for (c, o) in out.iter_mut().enumerate() {
                            *o += kv * src[at + c];
                        }
                    }
                }
            });
    };
    let mut tmp = vec![0.0; image.len()];
    pass(image, &mut tmp, true);
    pass(&tmp, image, false);
}
