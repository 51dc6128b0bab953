//! Synthetic photos of a calibration board with a swatch in its window: the board's picture as
//! the paper's (Lambertian) texture, the swatch's radiance from a rung and its parameters, a
//! perspective camera with radial distortion, a point light (a flash beside the lens), noise,
//! and 8-bit sRGB out. The whole photo route (`fibrefit calibrate`) is tested against them.

use crate::board::camera::{gaussian_blur, pixel_on_board, Intrinsics, Pose};
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
    /// A second point light lit in the photo besides it (mm, board frame; intensity), e.g. the
    /// room's lamp an ambient frame records.
    pub room_light: Option<(Vector3<f64>, f64)>,
    /// Linear pixel value per unit radiance.
    pub exposure: f64,
    /// Noise as a camera's (Poissonian-Gaussian): a linear value v has variance
    /// `floor^2 + gain v`; `gain` is the shot noise's variance per unit value.
    pub noise_gain: f64,
    /// Noise floor: the standard deviation at value 0 (read noise, linear).
    pub noise_floor: f64,
    /// Seed of the photo's noise.
    pub seed: u64,
    /// Supersamples per pixel side (anti-aliasing).
    pub supersample: usize,
    /// The lens's blur: a Gaussian's standard deviation in pixels (0: sharp), e.g. defocus.
    pub blur_px: f64,
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
        let mut out = self.radiance_from(shot.light_mm, shot.intensity, p, eye);
        if let Some((at, intensity)) = shot.room_light {
            let more = self.radiance_from(at, intensity, p, eye);
            for c in 0..3 {
                out[c] += more[c];
            }
        }
        out
    }

    /// The radiance (RGB) leaving board point `p` towards `eye` under one point light.
    fn radiance_from(
        &self,
        light_mm: Vector3<f64>,
        intensity: f64,
        p: &Vector3<f64>,
        eye: &Vector3<f64>,
    ) -> [f64; 3] {
        let d = light_mm - p;
        let r_m = d.norm() / 1000.0;
        let l = d.normalize();
        let e = intensity / (r_m * r_m) * l.z.max(0.0);
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
        let [w, h] = shot.intrinsics.size_px;
        let data: Vec<u8> = self
            .render_linear(shot)?
            .into_iter()
            .map(|v| (linear_to_srgb(v) * 255.0).round().clamp(0.0, 255.0) as u8)
            .collect();
        Ok(RgbImage::from_raw(w, h, data).expect("w x h x 3 values"))
    }

    /// The photo `shot` takes as linear RGB values (row-major, interleaved), noised and clipped
    /// to [0, 1]: what a raw converter's linear output holds.
    pub fn render_linear(&self, shot: &PhotoShot) -> Result<Vec<f32>> {
        let k = &shot.intrinsics;
        let [w, h] = k.size_px;
        if w == 0 || h == 0 || shot.supersample == 0 {
            bail!("a photo needs pixels and at least 1 supersample");
        }
        let n = shot.supersample;
        // the clean picture (linear, exposed), then the lens's blur, then the sensor's noise
        let mut clean: Vec<f64> = (0..h)
            .into_par_iter()
            .flat_map_iter(|y| {
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
                    row.extend(sum.map(|s| s / (n * n) as f64 * shot.exposure));
                }
                row
            })
            .collect();
        if shot.blur_px > 0.0 {
            gaussian_blur(&mut clean, w as usize, h as usize, 3, shot.blur_px);
        }
        let rows: Vec<Vec<f32>> = clean
            .par_chunks(3 * w as usize)
            .enumerate()
            .map(|(y, clean)| {
                let mut rng = rand::rngs::StdRng::seed_from_u64(
                    shot.seed.wrapping_mul(0x9e37_79b9_7f4a_7c15) ^ y as u64,
                );
                let unit = Normal::new(0.0, 1.0).expect("a unit normal");
                clean
                    .iter()
                    .map(|&value| {
                        let sigma = (shot.noise_floor * shot.noise_floor
                            + shot.noise_gain * value.max(0.0))
                        .sqrt();
                        let noisy = value + sigma * unit.sample(&mut rng);
                        noisy.clamp(0.0, 1.0) as f32
                    })
                    .collect()
            })
            .collect();
        Ok(rows.into_iter().flatten().collect())
    }
}

/// What `fibrefit synth --photos` is asked.
#[derive(Clone, Debug)]
pub struct PhotoSetRequest {
    /// `board.toml` (its `board.png` beside it is the paper's texture).
    pub board: std::path::PathBuf,
    /// The swatch's parameter file (TOML, JSON or a fitted result).
    pub params: std::path::PathBuf,
    /// The rung (default: the parameter file's `model`).
    pub model: Option<String>,
    /// How many photos (around the board, 20-60 degrees of elevation, 300 mm away).
    pub count: usize,
    /// Seed of the noise.
    pub seed: u64,
    /// How the photos are written.
    pub format: PhotoFormat,
}

/// How synthetic photos are written.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum PhotoFormat {
    /// 8-bit sRGB JPEG (quality 95), as a phone's camera app writes.
    #[default]
    Jpeg,
    /// A Bayer-mosaic DNG (16-bit codes, black and white levels), as a camera's RAW mode
    /// writes: `crate::export::dng`.
    Dng,
}

/// The photo set's camera: a phone-like 1600 x 1200 sensor, f = 1000 px, barrel distortion.
pub const SET_CAMERA: Intrinsics = Intrinsics {
    size_px: [1600, 1200],
    focal_px: 1000.0,
    principal_px: [805.0, 596.0],
    k: [-0.08, 0.02],
};

/// The photo set's shot noise: variance per unit linear value (1 % at a value of 0.3).
pub const SET_NOISE_GAIN: f64 = 3e-5;
/// The photo set's read noise: standard deviation at value 0 (linear).
pub const SET_NOISE_FLOOR: f64 = 0.002;

/// The flash's position in the camera frame (mm) of the photo set.
pub const SET_FLASH_MM: [f64; 3] = [10.0, 0.0, 0.0];

/// A printed board with a swatch in its window, ready to photograph: what `synth --photos`,
/// `bench photos` and the photo tests render ([`SwatchOnBoard::scene`]).
pub struct SwatchOnBoard {
    pub board: BoardFile,
    /// `board.png` beside `board.toml`.
    pub picture: GrayImage,
    pub model: Box<dyn ShadingModel>,
    pub params: ModelParams,
}

impl SwatchOnBoard {
    /// The board of `board_toml` (its `board.png` beside it, of the size the TOML says) with a
    /// swatch of rung `id` at `params`.
    pub fn read(board_toml: &std::path::Path, id: crate::model::ModelId, params: ModelParams) -> Result<Self> {
        let board = BoardFile::read(board_toml)?;
        let png_path = board_toml.with_file_name("board.png");
        let picture = crate::load::image_io::decode_png(&png_path, "board picture")?.to_luma8();
        if [picture.width(), picture.height()] != board.png_px {
            bail!(
                "{}: {}x{} pixels, but board.toml says {:?}",
                png_path.display(),
                picture.width(),
                picture.height(),
                board.png_px
            );
        }
        let model = crate::model::build(id, &params)?;
        Ok(Self {
            board,
            picture,
            model,
            params,
        })
    }

    /// The scene: the board on a dark table (reflectance 0.05), the swatch in its window.
    pub fn scene(&self) -> PhotoScene<'_> {
        PhotoScene {
            board: &self.board,
            picture: &self.picture,
            swatch: Some((self.model.as_ref(), &self.params)),
            table_reflectance: 0.05,
        }
    }
}

/// Photo `i` of `n`'s camera: 300 mm from the window's centre, elevations cycling through
/// 20-60 degrees, azimuths all around.
pub fn set_pose(i: usize, n: usize) -> Pose {
    let elev = (20.0 + 40.0 * (i % 4) as f64 / 3.0).to_radians();
    let azim = (360.0 * i as f64 / n.max(1) as f64 + 10.0).to_radians();
    let eye = Vector3::new(azim.cos() * elev.cos(), azim.sin() * elev.cos(), elev.sin()) * 300.0;
    Pose::look_at(eye, Vector3::zeros())
}

/// Render the set into `out`: `photo_NNN.jpg` and `truth.json` (intrinsics, each photo's
/// camera position and rotation, its flash and exposure, the parameters), all or nothing.
/// Returns the files written.
pub fn write_photo_set(
    req: &PhotoSetRequest,
    out: &std::path::Path,
    progress: &crate::progress::Progress,
) -> Result<Vec<std::path::PathBuf>> {
    if !(1..=64).contains(&req.count) {
        bail!("--count {}: expected 1 to 64 photos", req.count);
    }
    let raw = crate::export::result_json::read_params(&req.params)?;
    let (id, params, warnings) = crate::export::result_json::checked_params(
        &raw,
        req.model.as_deref(),
        &req.params.display().to_string(),
    )?;
    for w in &warnings {
        progress.warn(&format!("{}: {w}", req.params.display()));
    }
    let set = SwatchOnBoard::read(&req.board, id, params)?;
    let scene = set.scene();
    let inputs = [req.board.clone(), req.board.with_file_name("board.png"), req.params.clone()];
    let mut outs = crate::export::atomic::Outputs::new(&inputs);
    let dir = outs.dir(out, "--out")?;
    let mut files = Vec::new();
    let mut cameras = Vec::new();
    let bar = progress.bar(req.count as u64, "photos");
    for i in 0..req.count {
        let pose = set_pose(i, req.count);
        let shot = PhotoShot {
            room_light: None,
            intrinsics: SET_CAMERA,
            pose,
            light_mm: pose.position + pose.to_board_direction(&Vector3::from(SET_FLASH_MM)),
            intensity: 1.0,
            exposure: 0.5 * std::f64::consts::PI * 0.09 * (1.0 + 0.1 * (i % 5) as f64),
            noise_gain: SET_NOISE_GAIN,
            noise_floor: SET_NOISE_FLOOR,
            seed: req.seed.wrapping_add(i as u64),
            supersample: 3,
            blur_px: 0.0,
        };
        let (name, bytes) = match req.format {
            PhotoFormat::Jpeg => {
                let photo = scene.render(&shot)?;
                let name = format!("photo_{i:03}.jpg");
                let mut bytes = Vec::new();
                image::codecs::jpeg::JpegEncoder::new_with_quality(&mut bytes, 95)
                    .encode_image(&photo)
                    .map_err(|e| anyhow::anyhow!("{name}: {e}"))?;
                (name, bytes)
            }
            PhotoFormat::Dng => {
                let linear = scene.render_linear(&shot)?;
                let [w, h] = shot.intrinsics.size_px;
                let exposure = crate::export::dng::DngExposure {
                    time_s: 0.01 * (1.0 + 0.1 * (i % 5) as f64),
                    iso: 100,
                    f_number: 2.0,
                };
                let name = format!("photo_{i:03}.dng");
                (name, crate::export::dng::dng_bytes(w, h, &linear, exposure)?)
            }
        };
        let id_out = outs.file(&dir.join(&name), "--out")?;
        outs.put(id_out, &bytes)?;
        let r = pose.rotation.matrix();
        cameras.push(serde_json::json!({
            "file": name,
            "position_mm": [pose.position.x, pose.position.y, pose.position.z],
            "rotation_rows": [[r[(0, 0)], r[(0, 1)], r[(0, 2)]], [r[(1, 0)], r[(1, 1)], r[(1, 2)]], [r[(2, 0)], r[(2, 1)], r[(2, 2)]]],
            "light_mm": [shot.light_mm.x, shot.light_mm.y, shot.light_mm.z],
            "light_x_exposure": shot.intensity * shot.exposure,
        }));
        files.push(dir.join(name));
        bar.inc(1);
    }
    bar.finish_and_clear();
    let truth = serde_json::json!({
        "tool": "fibrefit synth --photos",
        "board": req.board.display().to_string(),
        "model": id.as_str(),
        "parameters": raw,
        "intrinsics": SET_CAMERA,
        "flash_offset_mm": SET_FLASH_MM,
        "noise": {"gain": SET_NOISE_GAIN, "floor": SET_NOISE_FLOOR, "variance": "floor^2 + gain x linear value", "seed": req.seed},
        "photos": cameras,
    });
    let truth_id = outs.file(&dir.join("truth.json"), "--out")?;
    let text = serde_json::to_string_pretty(&truth).map_err(|e| anyhow::anyhow!("truth.json: {e}"))?;
    outs.put(truth_id, text.as_bytes())?;
    outs.commit()?;
    files.push(dir.join("truth.json"));
    Ok(files)
}
