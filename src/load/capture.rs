//! Image captures: a TOML description of a swatch and its images (example:
//! `configs/capture_example.toml`). Every pixel of every image becomes a sample with its own
//! light and view directions, fibre tangent and topology-map texel; the pixels are held compactly
//! by texel in a `CaptureStore` (`capture_store.rs`, which reads captures through this file).
//!
//! Pixel (x, y) (column x, row y from the top) of a W x H image covers the swatch point
//! p = (((x + 0.5)/W - 0.5) w, (0.5 - (y + 0.5)/H) h, 0) mm for a swatch of w x h mm centred on
//! the origin: images are rectified to the swatch plane. The value of a pixel times `exposure` is
//! the radiance towards the camera, in the units of the light's irradiance; the BRDF is
//! radiance / (E cos theta_i) with E the irradiance perpendicular to the light: `irradiance` for
//! a directional light, `intensity / r^2` (r in metres) for a point light.

use super::image_io::{Encoding, LinearImage};
use crate::model::frame::{direction_from_angles, Vec3};
use anyhow::{anyhow, bail, Result};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

#[derive(Clone, Debug, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct CaptureFile {
    /// The relative standard error (R, G, B) of the values' common scale, when the capture's
    /// radiometry was calibrated (`fibrefit calibrate`: the reference patch pooled over the
    /// photos): the fitted albedos' standard errors include it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub scale_rel_se: Option<[f64; 3]>,
    pub swatch: Swatch,
    pub images: Vec<ImageSpec>,
}

#[derive(Clone, Debug, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Swatch {
    /// Physical size (width along x, height along y), millimetres.
    pub size_mm: [f64; 2],
    /// Region of interest [x0, y0, x1, y1] in pixels (half-open); default: the whole image.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub roi: Option<[usize; 4]>,
    /// Grayscale mask image: pixels with value 0 are left out.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub mask: Option<PathBuf>,
    /// Fibre azimuth psi, degrees, for the whole swatch.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub fibre_azimuth_deg: Option<f64>,
    /// Grayscale tangent map: psi = -90 + 180 m degrees per pixel.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub tangent_map: Option<PathBuf>,
    /// Grayscale topology map (PNG 8/16-bit or EXR) registered to the image pixels.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub topology_map: Option<PathBuf>,
    /// Float EXR of the texel height H in fibre radii per pixel (a recovered `height.exr`);
    /// instead of `topology_map`. NaN texels are left out.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub height_map: Option<PathBuf>,
    /// Float EXR of the fibre azimuth psi in degrees per pixel (a recovered
    /// `fibre_azimuth.exr`); instead of `tangent_map` or `fibre_azimuth_deg`. NaN texels are
    /// left out.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub fibre_azimuth_map: Option<PathBuf>,
}

#[derive(Clone, Debug, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct ImageSpec {
    /// The image (EXR, PNG or TIFF); or, instead, `bracket`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub file: Option<PathBuf>,
    /// An exposure bracket instead of `file`: two or more frames of this light and view, each
    /// with its own exposure (pixel value x frame exposure x `exposure` = radiance), merged into
    /// one linear image (`capture_store::merge_bracket`).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub bracket: Vec<BracketFrame>,
    /// PNG only: `linear` or `srgb`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub encoding: Option<Encoding>,
    /// Factor from pixel value to radiance (default 1).
    #[serde(default = "one")]
    pub exposure: f64,
    /// EXR only: values at or above this are saturated (PNG: the top code always is).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub saturation: Option<f32>,
    /// The image's noise, when known (e.g. estimated by `fibrefit calibrate`): the variance of
    /// a pixel value v is `var0 + gain v`, per channel, in the image's own value units. The
    /// fit's sigmas come from it. A bracket estimates its own instead.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub noise: Option<NoiseSpec>,
    pub light: Light,
    pub camera: Camera,
}

/// An image's camera noise (Poissonian-Gaussian): variance `var0 + gain x value` per channel
/// (R, G, B; a grey image uses the first).
#[derive(Clone, Debug, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct NoiseSpec {
    /// The variance at value 0 (read noise), value units squared.
    pub var0: [f64; 3],
    /// The variance per unit value (shot noise), value units.
    pub gain: [f64; 3],
}

fn one() -> f64 {
    1.0
}

/// One frame of an exposure bracket.
#[derive(Clone, Debug, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct BracketFrame {
    pub file: PathBuf,
    /// Factor from this frame's pixel value to radiance (before the image's `exposure`): a
    /// frame exposed 4 times longer has a quarter of the factor.
    pub exposure: f64,
}

impl ImageSpec {
    /// The image's files with their exposure factors relative to `exposure`: the file with 1,
    /// or the bracket's frames with theirs.
    pub fn frames(&self) -> Vec<(&Path, f64)> {
        match &self.file {
            Some(f) => vec![(f.as_path(), 1.0)],
            None => self
                .bracket
                .iter()
                .map(|b| (b.file.as_path(), b.exposure))
                .collect(),
        }
    }

    /// The image as messages name it: its file, or its bracket's files.
    pub fn label(&self) -> String {
        match &self.file {
            Some(f) => f.display().to_string(),
            None => format!(
                "bracket of {}",
                self.bracket
                    .iter()
                    .map(|b| b.file.display().to_string())
                    .collect::<Vec<_>>()
                    .join(", ")
            ),
        }
    }
}

#[derive(Clone, Debug, Deserialize, Serialize, PartialEq)]
#[serde(tag = "type", rename_all = "kebab-case", deny_unknown_fields)]
pub enum Light {
    /// A distant light from (theta, phi) degrees with irradiance E perpendicular to it.
    Directional {
        theta_deg: f64,
        phi_deg: f64,
        irradiance: f64,
    },
    /// A point light at `position_mm` (swatch frame) with radiant intensity: E = intensity / r^2,
    /// r in metres.
    Point {
        position_mm: [f64; 3],
        intensity: f64,
    },
}

#[derive(Clone, Debug, Deserialize, Serialize, PartialEq)]
#[serde(tag = "type", rename_all = "kebab-case", deny_unknown_fields)]
pub enum Camera {
    /// A distant camera looking from (theta, phi) degrees.
    Orthographic { theta_deg: f64, phi_deg: f64 },
    /// A pinhole camera with its centre of projection at `position_mm` (swatch frame); the image
    /// is rectified to the swatch plane, so only the pose matters per pixel.
    Pinhole { position_mm: [f64; 3] },
    /// Per-pixel unit view directions (swatch frame) in an EXR's R, G, B channels.
    ViewMap { file: PathBuf },
}

/// Subsampling of capture pixels: every `stride`-th pixel in x and y, and/or a seeded random
/// fraction.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Subsample {
    /// Keep every `stride`-th pixel in x and y (1: all).
    pub stride: usize,
    /// Then keep this seeded fraction of them, in (0, 1].
    pub fraction: f64,
    /// Seed of the fraction's choice.
    pub seed: u64,
}

impl Default for Subsample {
    fn default() -> Self {
        Self {
            stride: 1,
            fraction: 1.0,
            seed: 0,
        }
    }
}

impl Subsample {
    pub(crate) fn keeps(&self, image: usize, x: usize, y: usize) -> bool {
        if x % self.stride != 0 || y % self.stride != 0 {
            return false;
        }
        if self.fraction >= 1.0 {
            return true;
        }
        let h = splitmix64(
            self.seed ^ splitmix64(((image as u64) << 42) ^ ((y as u64) << 21) ^ x as u64),
        );
        ((h >> 11) as f64 / (1u64 << 53) as f64) < self.fraction
    }
}

fn splitmix64(mut z: u64) -> u64 {
    z = z.wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

impl CaptureFile {
    pub fn load(path: &Path) -> Result<Self> {
        let text = super::input::read_text(path)?;
        toml::from_str(&text)
            .map_err(|e| anyhow!("{}: {}", path.display(), e.to_string().trim_end()))
    }
}

/// Swatch point (mm) under pixel (x, y) of a `w` x `h` image.
pub fn pixel_position(size_mm: [f64; 2], w: usize, h: usize, x: usize, y: usize) -> Vec3 {
    Vec3::new(
        ((x as f64 + 0.5) / w as f64 - 0.5) * size_mm[0],
        (0.5 - (y as f64 + 0.5) / h as f64) * size_mm[1],
        0.0,
    )
}

/// Direction and perpendicular irradiance of `light` at swatch point `p` (mm).
pub fn light_at(light: &Light, p: &Vec3) -> (Vec3, f64) {
    match light {
        Light::Directional {
            theta_deg,
            phi_deg,
            irradiance,
        } => (
            direction_from_angles(theta_deg.to_radians(), phi_deg.to_radians()),
            *irradiance,
        ),
        Light::Point {
            position_mm,
            intensity,
        } => {
            let d = Vec3::from(*position_mm) - p;
            let r_m = d.norm() / 1000.0;
            (d.normalize(), intensity / (r_m * r_m))
        }
    }
}

/// View direction of a (non-map) camera at swatch point `p` (mm).
pub fn view_at(camera: &Camera, p: &Vec3) -> Option<Vec3> {
    match camera {
        Camera::Orthographic { theta_deg, phi_deg } => Some(direction_from_angles(
            theta_deg.to_radians(),
            phi_deg.to_radians(),
        )),
        Camera::Pinhole { position_mm } => Some((Vec3::from(*position_mm) - p).normalize()),
        Camera::ViewMap { .. } => None,
    }
}

pub(crate) fn resolve(base: &Path, p: &Path) -> PathBuf {
    if p.is_relative() {
        base.join(p)
    } else {
        p.to_path_buf()
    }
}

pub(crate) fn check_size(
    what: &str,
    path: &Path,
    got: (usize, usize),
    want: (usize, usize),
) -> Result<()> {
    if got != want {
        bail!(
            "{}: {what} is {}x{} pixels but the images are {}x{}; maps must be registered to the image pixels",
            path.display(),
            got.0,
            got.1,
            want.0,
            want.1
        );
    }
    Ok(())
}

/// Light, camera, exposure and saturation of image `k` (numbered from 1 in messages): every angle
/// finite and in [0, 90) degrees from the normal, irradiance, intensity and exposure finite and
/// positive, a saturation level only for EXR images and then finite and positive.
pub(crate) fn check_image_spec(name: &str, k: usize, spec: &ImageSpec) -> Result<()> {
    let at = format!("{name}: [[images]] {} ({})", k + 1, spec.label());
    match (&spec.file, spec.bracket.len()) {
        (Some(_), 0) => {}
        (Some(_), _) => bail!("{at}: give `file` or `bracket`, not both"),
        (None, 0) => {
            bail!("{at}: needs `file` (one image) or `bracket` (frames with their exposures)")
        }
        (None, 1) => {
            bail!("{at}: a bracket needs two or more frames; for one, give `file` and `exposure`")
        }
        (None, _) => {
            for (j, b) in spec.bracket.iter().enumerate() {
                if !(b.exposure.is_finite() && b.exposure > 0.0) {
                    bail!(
                        "{at}: bracket frame {} ({}): exposure = {} must be a finite positive number",
                        j + 1,
                        b.file.display(),
                        b.exposure
                    );
                }
            }
        }
    }
    let theta = |what: &str, t: f64| -> Result<()> {
        if !(t.is_finite() && (0.0..90.0).contains(&t)) {
            bail!("{at}: {what}.theta_deg = {t} must be a finite angle in [0, 90) degrees from the normal (90 is the horizon)");
        }
        Ok(())
    };
    let phi = |what: &str, p: f64| -> Result<()> {
        if !(p.is_finite() && (-360.0..=360.0).contains(&p)) {
            bail!("{at}: {what}.phi_deg = {p} must be a finite angle in [-360, 360] degrees");
        }
        Ok(())
    };
    let positive = |what: &str, v: f64| -> Result<()> {
        if !(v.is_finite() && v > 0.0) {
            bail!("{at}: {what} = {v} must be a finite positive number");
        }
        Ok(())
    };
    positive("exposure", spec.exposure)?;
    if let Some(n) = &spec.noise {
        if !spec.bracket.is_empty() {
            bail!("{at}: a bracket estimates its own noise from its frames: give `noise` for a single `file` only");
        }
        for (what, v) in [("var0", n.var0), ("gain", n.gain)] {
            if v.iter().any(|x| !(x.is_finite() && *x >= 0.0)) {
                bail!("{at}: noise.{what} = {v:?} must be three finite numbers >= 0");
            }
        }
        if (0..3).any(|c| n.var0[c] == 0.0 && n.gain[c] == 0.0) {
            bail!("{at}: noise = var0 {:?}, gain {:?} gives a channel no noise at all; leave `noise` out when it is unknown", n.var0, n.gain);
        }
    }
    match &spec.light {
        Light::Directional {
            theta_deg,
            phi_deg,
            irradiance,
        } => {
            theta("light", *theta_deg)?;
            phi("light", *phi_deg)?;
            positive("light.irradiance", *irradiance)?;
        }
        Light::Point {
            position_mm,
            intensity,
        } => {
            if position_mm.iter().any(|c| !c.is_finite()) {
                bail!("{at}: light.position_mm = {position_mm:?} must be finite");
            }
            if !(position_mm[2] > 0.0) {
                bail!("{at}: light.position_mm = {position_mm:?} must lie above the swatch (z > 0 mm)");
            }
            positive("light.intensity", *intensity)?;
        }
    }
    match &spec.camera {
        Camera::Orthographic { theta_deg, phi_deg } => {
            theta("camera", *theta_deg)?;
            phi("camera", *phi_deg)?;
        }
        Camera::Pinhole { position_mm } => {
            if position_mm.iter().any(|c| !c.is_finite()) || !(position_mm[2] > 0.0) {
                bail!("{at}: camera.position_mm = {position_mm:?} must be finite and above the swatch (z > 0 mm)");
            }
        }
        Camera::ViewMap { .. } => {}
    }
    if let Some(sat) = spec.saturation {
        let float = spec.frames().iter().all(|(f, _)| {
            f.extension()
                .and_then(|e| e.to_str())
                .is_some_and(|e| ["exr", "tif", "tiff"].contains(&e.to_ascii_lowercase().as_str()))
        });
        if !float {
            bail!("{at}: `saturation` applies to EXR images only (and floating-point TIFFs; 8/16-bit PNGs and TIFFs saturate at their largest code)");
        }
        positive("saturation", sat as f64)?;
    }
    Ok(())
}

/// Negative pixel values beyond noise (below -1 % of the image's largest value) are an error, as
/// in the CSV loader: a linear image of radiance cannot be negative.
pub(crate) fn check_no_negatives(path: &Path, img: &LinearImage) -> Result<()> {
    let largest = img
        .data
        .iter()
        .copied()
        .filter(|v| v.is_finite())
        .fold(0.0f32, f32::max);
    if let Some(i) = img
        .data
        .iter()
        .position(|&v| v.is_finite() && v < -0.01 * largest)
    {
        let px = i / img.channels;
        bail!(
            "{}: pixel ({}, {}) has value {}, negative beyond noise (more than 1 % of the largest value {largest}); images must hold linear radiance",
            path.display(),
            px % img.width,
            px / img.width,
            img.data[i]
        );
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pinhole_and_point_light_geometry_by_hand() {
        // 100 x 50 mm swatch, 4 x 2 pixels: pixel (3, 0) covers x = (3.5/4 - 0.5) 100 = 37.5,
        // y = (0.5 - 0.5/2) 50 = 12.5.
        let p = pixel_position([100.0, 50.0], 4, 2, 3, 0);
        assert_eq!(p, Vec3::new(37.5, 12.5, 0.0));
        // camera at (37.5, -287.5, 400): offset (0, -300, 400), length 500 -> v = (0, -0.6, 0.8)
        let v = view_at(
            &Camera::Pinhole {
                position_mm: [37.5, -287.5, 400.0],
            },
            &p,
        )
        .unwrap();
        assert!((v - Vec3::new(0.0, -0.6, 0.8)).norm() < 1e-15);
        // light at (37.5 + 300, 12.5, 400): offset (300, 0, 400), r = 0.5 m, E = 2 / 0.25 = 8
        let (l, e) = light_at(
            &Light::Point {
                position_mm: [337.5, 12.5, 400.0],
                intensity: 2.0,
            },
            &p,
        );
        assert!((l - Vec3::new(0.6, 0.0, 0.8)).norm() < 1e-15);
        assert!((e - 8.0).abs() < 1e-12);
    }

    #[test]
    fn subsampling_is_deterministic_and_near_the_fraction() {
        let s = Subsample {
            stride: 1,
            fraction: 0.25,
            seed: 7,
        };
        let kept = (0..200)
            .flat_map(|y| (0..200).map(move |x| (x, y)))
            .filter(|&(x, y)| s.keeps(0, x, y))
            .count();
        assert!((kept as f64 / 40000.0 - 0.25).abs() < 0.01, "{kept}");
        assert_eq!(s.keeps(0, 5, 9), s.keeps(0, 5, 9));
        let t = Subsample {
            stride: 4,
            fraction: 1.0,
            seed: 0,
        };
        assert!(t.keeps(0, 8, 4) && !t.keeps(0, 8, 5));
    }
}

/// A capture's geometry as JSON, for renderers outside fibrefit (the Python package's Mitsuba
/// scenes): the swatch (`size_mm`, `fibre_azimuth_deg`), and per image its file (absolute),
/// `width` and `height` in pixels (read from the file's header), `exposure`, `light` and
/// `camera` as the capture TOML gives them (units: mm, degrees; a point light's intensity in
/// the capture's units with r in metres).
pub fn geometry_json(path: &Path) -> Result<String> {
    let desc = CaptureFile::load(path)?;
    let base = path.parent().unwrap_or(Path::new("."));
    let mut images = Vec::new();
    for spec in &desc.images {
        let (first, _) = spec.frames()[0];
        let file = resolve(base, first);
        let img = super::image_io::read(&file, spec.encoding, spec.saturation)?;
        let mut v = serde_json::to_value(spec)?;
        v["file"] = serde_json::json!(std::path::absolute(&file)?.display().to_string());
        v["width"] = serde_json::json!(img.width);
        v["height"] = serde_json::json!(img.height);
        v["channels"] = serde_json::json!(img.channels);
        images.push(v);
    }
    let mut swatch = serde_json::to_value(&desc.swatch)?;
    swatch["fibre_azimuth_deg"] = serde_json::json!(desc.swatch.fibre_azimuth_deg);
    Ok(serde_json::to_string(&serde_json::json!({
        "capture": std::path::absolute(path)?.display().to_string(),
        "swatch": swatch,
        "images": images,
    }))?)
}
