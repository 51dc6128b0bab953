//! A capture image's scene for renderers outside fibrefit (the Mitsuba scene of
//! `fibrefit.mitsuba.capture_scene`): the swatch, the light and the camera of one image of a
//! capture TOML, read as the fit reads them (`load::capture`) and put the way a
//! renderer sets them up. Millimetres throughout (the scene's unit), the swatch frame (z the
//! macro normal, x the swatch's x axis; the swatch a `size_mm` rectangle centred on the origin),
//! angles in degrees. Rendered with the capture's rectification, pixel (row, column) of the
//! render is pixel (row, column) of the captured file.

use crate::load::capture::{light_at, view_at, Camera, CaptureFile, Light};
use crate::model::frame::Vec3;
use anyhow::{anyhow, bail, Result};
use serde::Serialize;
use std::path::Path;

/// Near clipping distance of every camera, mm.
const NEAR_CLIP_MM: f64 = 1e-3;

/// One image of a capture as a renderer's scene.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct ImageScene {
    /// The swatch's size (width along x, height along y), mm.
    pub size_mm: [f64; 2],
    /// The image's size in pixels (width, height): the film's.
    pub width: usize,
    /// See `width`.
    pub height: usize,
    /// The light.
    pub light: SceneLight,
    /// The camera.
    pub camera: SceneCamera,
}

/// The light of a capture image.
#[derive(Clone, Debug, PartialEq, Serialize)]
#[serde(tag = "type", rename_all = "kebab-case")]
pub enum SceneLight {
    /// A distant light.
    Directional {
        /// Unit vector from the swatch towards the light (swatch frame).
        towards_light: [f64; 3],
        /// Irradiance perpendicular to the light, in the units of the capture's pixels (radiance
        /// per unit irradiance times this is what a pixel holds).
        irradiance: f64,
    },
    /// A point light.
    Point {
        /// The light's position, mm (swatch frame).
        position_mm: [f64; 3],
        /// Radiant intensity in the scene's units: irradiance = `intensity_mm` / r^2 with r the
        /// distance in mm (the capture's `intensity`, stated for r in metres, times 10^6).
        intensity_mm: f64,
    },
}

/// The camera of a capture image, rectified to the swatch.
#[derive(Clone, Debug, PartialEq, Serialize)]
#[serde(tag = "type", rename_all = "kebab-case")]
pub enum SceneCamera {
    /// A distant camera: an orthographic projection whose affine camera-to-world map puts the
    /// ray through film point (fx, fy) in [0, 1]^2 on the swatch point of that pixel, along
    /// `-towards_camera`. The film's camera coordinates are (1 - 2 fx, (1 - 2 fy) H / W, z), as
    /// Mitsuba's orthographic sensor has them.
    Orthographic {
        /// Unit vector from the swatch towards the camera (swatch frame).
        towards_camera: [f64; 3],
        /// The 4 x 4 camera-to-world matrix, rows (mm): column x is (-w/2, 0, 0) and column y
        /// (0, h W / (2 H), 0) (the film's camera coordinates onto the swatch point of each
        /// pixel), column z is `-towards_camera`, the translation `far` mm along
        /// `towards_camera`, far = 10 (w + h).
        to_world: [[f64; 4]; 4],
        /// Near clipping distance, mm.
        near_clip_mm: f64,
        /// Far clipping distance, mm (4 far: beyond the swatch from any view).
        far_clip_mm: f64,
    },
    /// A pinhole camera looking straight down at the swatch from `position_mm`, its image plane
    /// parallel to the swatch with an off-axis frustum over it (so the picture is the rectified
    /// image).
    Pinhole {
        /// The centre of projection, mm (swatch frame; z > 0).
        position_mm: [f64; 3],
        /// The 4 x 4 camera-to-world matrix, rows (mm): x flipped, z down, at `position_mm`.
        to_world: [[f64; 4]; 4],
        /// Field of view across the image's width (x), degrees: 2 atan(w / (2 z)).
        fov_x_deg: f64,
        /// Principal point offset along x as a fraction of the film's width: -x / w.
        principal_point_offset_x: f64,
        /// Principal point offset along y as a fraction of the film's height: y / h.
        principal_point_offset_y: f64,
        /// Near clipping distance, mm.
        near_clip_mm: f64,
        /// Far clipping distance, mm: 10 (z + w + h).
        far_clip_mm: f64,
    },
}

fn xyz(v: Vec3) -> [f64; 3] {
    [v.x, v.y, v.z]
}

/// Image `index` of the capture TOML `capture` as a renderer's scene. Refused: an index beyond
/// the capture's images, a view-map camera (per-pixel views have no single camera), a pinhole
/// at or below the swatch, and a pinhole image whose pixels are not square (a perspective
/// camera's film cannot be rectified to it). Reads the image's (first) file for its size.
pub fn image_scene(capture: &Path, index: usize) -> Result<ImageScene> {
    let desc = CaptureFile::load(capture)?;
    let n = desc.images.len();
    let spec = desc.images.get(index).ok_or_else(|| {
        anyhow!(
            "{}: image {index} asked for, but the capture has {n} images",
            capture.display()
        )
    })?;
    let here = || format!("{}: image {index}", capture.display());
    let base = capture.parent().unwrap_or(Path::new("."));
    let (first, _) = spec.frames()[0];
    let file = crate::load::capture::resolve(base, first);
    let img = crate::load::image_io::read(&file, spec.encoding, spec.saturation)?;
    let (w_px, h_px) = (img.width, img.height);
    let [w, h] = desc.swatch.size_mm;
    let origin = Vec3::zeros();
    let light = match &spec.light {
        Light::Directional { .. } => {
            let (towards, irradiance) = light_at(&spec.light, &origin);
            SceneLight::Directional {
                towards_light: xyz(towards),
                irradiance,
            }
        }
        Light::Point {
            position_mm,
            intensity,
        } => SceneLight::Point {
            position_mm: *position_mm,
            // E = intensity / r^2 with r in metres: 10^6 / r^2 with r in mm
            intensity_mm: intensity * 1e6,
        },
    };
    let camera = match &spec.camera {
        Camera::Orthographic { .. } => {
            let v = view_at(&spec.camera, &origin).expect("an orthographic camera has a view");
            let aspect = h_px as f64 / w_px as f64;
            let far = 10.0 * (w + h);
            SceneCamera::Orthographic {
                towards_camera: xyz(v),
                to_world: [
                    [-w / 2.0, 0.0, -v.x, far * v.x],
                    [0.0, h / (2.0 * aspect), -v.y, far * v.y],
                    [0.0, 0.0, -v.z, far * v.z],
                    [0.0, 0.0, 0.0, 1.0],
                ],
                near_clip_mm: NEAR_CLIP_MM,
                far_clip_mm: 4.0 * far,
            }
        }
        Camera::Pinhole { position_mm } => {
            let [cx, cy, cz] = *position_mm;
            if cz <= 0.0 {
                bail!(
                    "{}: the pinhole is not above the swatch (z = {cz} mm)",
                    here()
                );
            }
            let (pw, ph) = (w / w_px as f64, h / h_px as f64);
            if (pw - ph).abs() > 1e-9 * pw.max(ph) {
                bail!(
                    "{}: pixels of {pw} x {ph} mm are not square; a perspective camera cannot \
                     render this rectified image",
                    here()
                );
            }
            SceneCamera::Pinhole {
                position_mm: *position_mm,
                to_world: [
                    [-1.0, 0.0, 0.0, cx],
                    [0.0, 1.0, 0.0, cy],
                    [0.0, 0.0, -1.0, cz],
                    [0.0, 0.0, 0.0, 1.0],
                ],
                fov_x_deg: (2.0 * (w / (2.0 * cz)).atan()).to_degrees(),
                principal_point_offset_x: -cx / w,
                principal_point_offset_y: cy / h,
                near_clip_mm: NEAR_CLIP_MM,
                far_clip_mm: 10.0 * (cz + w + h),
            }
        }
        Camera::ViewMap { .. } => bail!(
            "{}: a view-map camera (per-pixel views) has no single camera to render with",
            here()
        ),
    };
    Ok(ImageScene {
        size_mm: desc.swatch.size_mm,
        width: w_px,
        height: h_px,
        light,
        camera,
    })
}

/// [`image_scene`] as JSON (the serde form of [`ImageScene`]: `light` and `camera` tagged by
/// `type`).
pub fn image_scene_json(capture: &Path, index: usize) -> Result<String> {
    Ok(serde_json::to_string(&image_scene(capture, index)?)?)
}
