//! Synthetic photos of a calibration board with a swatch in its window: the board's picture as
//! the paper's (Lambertian) texture, the swatch's radiance from a rung and its parameters, a
//! perspective camera with radial distortion, a point light (a flash beside the lens), noise,
//! and 8-bit sRGB out. The whole photo route (`fibrefit calibrate`) is tested against them.

use crate::board::camera::{pixel_on_board, Intrinsics, Pose};
use crate::load::board::BoardFile;
use crate::load::image_io::{linear_to_srgb, srgb_to_linear};
use crate::model::frame::{DirectionPair, FibreFrame};
use crate::model::params::ModelParams;
use crate::model::ShadingModel;
use anyhow::{bail, Result};
use image::{GrayImage, RgbImage};
use nalgebra::Vector3;
use rand::SeedableRng;
use rand_distr::{Distribution, Normal};
use rayon::prelude::*;

/// The scene every photo shares: the board, its picture and the swatch in its window.
pub struct PhotoScene<'a> {
    /// The board's description.
    pub board: &'a BoardFile,
    /// `board.png` (8-bit grey, sRGB).
    pub picture: &'a GrayImage,
    /// The swatch's model and parameters (None: the window is bare paper).
    pub swatch: Option<(&'a dyn ShadingModel, &'a ModelParams)>,
    /// The table's reflectance around the paper.
    pub table_reflectance: f64,
}

/// One photo: camera, light and how it is exposed and noised.
#[derive(Clone, Debug)]
pub struct PhotoShot {
    /// The camera's intrinsics.
    pub intrinsics: Intrinsics,
    /// The camera's pose.
    pub pose: Pose,
    /// The point light (mm, board frame).
    pub light_mm: Vector3<f64>,
    /// The light's intensity (as a capture's point light: irradiance at 1 m).
    pub intensity: f64,
    /// Linear pixel value per unit radiance.
    pub exposure: f64,
    /// Noise: standard deviation of a linear value v, `sqrt(floor^2 + (relative v)^2)`.
    pub noise_relative: f64,
    /// Noise floor (linear).
    pub noise_floor: f64,
    /// Seed of the photo's noise.
    pub seed: u64,
    /// Supersamples per pixel side (anti-aliasing).
    pub supersample: usize,
}

impl PhotoScene<'_> {
    /// The linear reflectance of the printed paper at board point (x, y) (mm), bilinear in
    /// the picture; the table outside it.
    fn paper(&self, x: f64, y: f64) -> f64 {
        let [u, v] = self.board.mm_to_png(x, y);
        let (w, h) = (self.picture.width() as f64, self.picture.height() as f64);
        if !(0.0..w).contains(&u) || !(0.0..h).contains(&v) {
            return self.table_reflectance;
        }
        let (fu, fv) = ((u - 0.5).max(0.0), (v - 0.5).max(0.0));
        let (u0, v0) = (fu.floor() as u32, fv.floor() as u32);
        let (u1, v1) = (
            (u0 + 1).min(self.picture.width() - 1),
            (v0 + 1).min(self.picture.height() - 1),
        );
        let (a, b) = (fu - u0 as f64, fv - v0 as f64);
        let g = |uu: u32, vv: u32| srgb_to_linear(self.picture.get_pixel(uu, vv)[0] as f32 / 255.0) as f64;
        (1.0 - b) * ((1.0 - a) * g(u0, v0) + a * g(u1, v0)) + b * ((1.0 - a) * g(u0, v1) + a * g(u1, v1))
    }

    /// The radiance (RGB) leaving board point `p` towards the camera at `eye` under `shot`.
    fn radiance(&self, shot: &PhotoShot, p: &Vector3<f64>, eye: &Vector3<f64>) -> [f64; 3] {
        let d = shot.light_mm - p;
        let r_m = d.norm() / 1000.0;
        let l = d.normalize();
        let e = shot.intensity / (r_m * r_m) * l.z.max(0.0);
        let w = self.board.window_mm;
        let in_window = p.x > w[0] && p.x < w[2] && p.y > w[1] && p.y < w[3];
        match self.swatch {
            Some((model, params)) if in_window => {
                let v = (eye - p).normalize();
                let frame = FibreFrame::from_azimuth(params.fibre_azimuth);
                let basis = model.basis(&DirectionPair::new(&frame, &l, &v));
                [0, 1, 2].map(|ch| basis.brdf(&params.albedos, ch) * e)
            }
            _ => [self.paper(p.x, p.y) / std::f64::consts::PI * e; 3],
        }
    }

    /// The photo `shot` takes: linear RGB per pixel, noised, encoded as 8-bit sRGB.
    pub fn render(&self, shot: &PhotoShot) -> Result<RgbImage> {
        let k = &shot.intrinsics;
        let [w, h] = k.size_px;
        if w == 0 || h == 0 || shot.supersample == 0 {
            bail!("a photo needs pixels and at least 1 supersample");
        }
        let n = shot.supersample;
        let rows: Vec<Vec<u8>> = (0..h)
            .into_par_iter()
            .map(|y| {
                let mut rng = rand::rngs::StdRng::seed_from_u64(
                    shot.seed.wrapping_mul(0x9e37_79b9_7f4a_7c15) ^ y as u64,
                );
                let unit = Normal::new(0.0, 1.0).expect("a unit normal");
                let mut row = Vec::with_capacity(3 * w as usize);
                for x in 0..w {
                    let mut sum = [0.0; 3];
                    for sy in 0..n {
                        for sx in 0..n {
                            let u = x as f64 + (sx as f64 + 0.5) / n as f64;
                            let v = y as f64 + (sy as f64 + 0.5) / n as f64;
                            let rad = match pixel_on_board(k, &shot.pose, u, v) {
                                Some(p) => self.radiance(shot, &p, &shot.pose.position),
                                None => [0.0; 3],
                            };
                            for c in 0..3 {
                                sum[c] += rad[c];
                            }
                        }
                    }
                    for s in sum {
                        let value = s / (n * n) as f64 * shot.exposure;
                        let sigma = shot.noise_floor.hypot(shot.noise_relative * value);
                        let noisy = value + sigma * unit.sample(&mut rng);
                        let e = linear_to_srgb(noisy.clamp(0.0, 1.0) as f32);
                        row.push((e * 255.0).round().clamp(0.0, 255.0) as u8);
                    }
                }
                row
            })
            .collect();
        let data: Vec<u8> = rows.into_iter().flatten().collect();
        Ok(RgbImage::from_raw(w, h, data).expect("w x h x 3 values"))
    }
}
