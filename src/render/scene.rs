//! `fibrefit render --scene SCENE.toml`: more than the flags say: several objects (moved and
//! scaled), directional and point lights, an orthographic or pinhole camera, size, supersampling
//! and exposure. Paths are relative to the scene file.
//!
//! ```toml
//! size = [640, 480]
//! supersample = 2
//! exposure = 1.5                   # PNG only; "auto" by default
//! fill = 0.25                      # a fill light from the camera's direction; default 0 (none)
//! [camera]                         # orthographic from (theta, phi), or:
//! type = "orthographic"
//! theta_deg = 50
//! phi_deg = 270
//! # type = "pinhole", position = [0, -6, 4], look_at = [0, 0, 0], fov_deg = 40
//! [[lights]]
//! type = "directional"             # theta_deg, phi_deg, irradiance (default 1)
//! theta_deg = 40
//! phi_deg = 120
//! [[lights]]
//! type = "point"                   # position, intensity: E = intensity / r^2
//! position = [2, -2, 3]
//! intensity = 10
//! [[objects]]
//! type = "torus"                   # torus, sphere, swatch or mesh (file, tangents)
//! offset = [-1.2, 0, 0]
//! scale = 1.0
//! ```

use super::mesh_object::{MeshObject, TangentSource};
use super::objects::Object;
use super::{Camera, Light};
use crate::model::frame::{direction_from_angles, Vec3};
use anyhow::{anyhow, bail, Result};
use serde::Deserialize;
use std::path::{Path, PathBuf};

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SceneFile {
    #[serde(default = "default_size")]
    pub size: [usize; 2],
    #[serde(default = "default_supersample")]
    pub supersample: usize,
    #[serde(default)]
    pub exposure: Option<toml::Value>,
    /// Irradiance of a fill light from the camera's direction (0: none; the lights are as
    /// written).
    #[serde(default)]
    pub fill: f64,
    pub camera: CameraSpec,
    pub lights: Vec<LightSpec>,
    pub objects: Vec<ObjectSpec>,
}

fn default_size() -> [usize; 2] {
    [512, 512]
}

fn default_supersample() -> usize {
    2
}

fn one() -> f64 {
    1.0
}

#[derive(Debug, Deserialize)]
#[serde(tag = "type", rename_all = "kebab-case", deny_unknown_fields)]
pub enum CameraSpec {
    Orthographic {
        theta_deg: f64,
        phi_deg: f64,
        /// Half the image width in scene units [default: the objects fill the image].
        #[serde(default)]
        half_width: Option<f64>,
    },
    Pinhole {
        position: [f64; 3],
        #[serde(default)]
        look_at: [f64; 3],
        fov_deg: f64,
    },
}

#[derive(Debug, Deserialize)]
#[serde(tag = "type", rename_all = "kebab-case", deny_unknown_fields)]
pub enum LightSpec {
    Directional {
        theta_deg: f64,
        phi_deg: f64,
        #[serde(default = "one")]
        irradiance: f64,
    },
    Point {
        position: [f64; 3],
        intensity: f64,
    },
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ObjectSpec {
    #[serde(rename = "type")]
    pub kind: String,
    #[serde(default)]
    pub file: Option<PathBuf>,
    #[serde(default)]
    pub tangents: Option<String>,
    #[serde(default)]
    pub offset: [f64; 3],
    #[serde(default = "one")]
    pub scale: f64,
}

/// A scene ready to render.
pub struct Scene {
    pub objects: Vec<Object>,
    pub lights: Vec<Light>,
    pub camera: Camera,
    pub supersample: usize,
    /// "auto" or a number (PNG).
    pub exposure: Option<String>,
    /// Files the scene reads (never replaced by an output).
    pub inputs: Vec<PathBuf>,
}

fn finite(v: &[f64], what: &str, at: &str) -> Result<()> {
    if v.iter().any(|x| !x.is_finite()) {
        bail!("{at}: {what} = {v:?} must be finite");
    }
    Ok(())
}

impl SceneFile {
    pub fn load(path: &Path) -> Result<Self> {
        let text = crate::load::input::read_text_as(path, "the scene")?;
        toml::from_str(&text)
            .map_err(|e| anyhow!("{}: {}", path.display(), e.to_string().trim_end()))
    }

    /// The scene, its objects made with the material's fibre azimuth `psi_deg` and `spacing`.
    pub fn build(&self, path: &Path, psi_deg: f64, spacing: f64) -> Result<Scene> {
        let at = path.display().to_string();
        let base = path.parent().unwrap_or(Path::new("."));
        let [w, h] = self.size;
        super::check_budget(w, h, self.supersample, &at)?;
        if self.objects.is_empty() || self.lights.is_empty() {
            bail!("{at}: a scene needs [[objects]] and [[lights]]");
        }
        let mut inputs = vec![path.to_path_buf()];
        let mut objects = Vec::new();
        for (k, o) in self.objects.iter().enumerate() {
            let at = format!("{at}: [[objects]] {}", k + 1);
            let material = ObjectMaterial { psi_deg, spacing };
            objects.push(o.build(&at, base, material, &mut inputs)?);
        }
        let mut lights = Vec::new();
        for (k, l) in self.lights.iter().enumerate() {
            let at = format!("{at}: [[lights]] {}", k + 1);
            lights.push(l.build(&at)?);
        }
        let camera = self.camera.build(&at, (w, h), &objects)?;
        lights.extend(super::fill_light(
            camera.direction,
            self.fill,
            &format!("{at}: fill ="),
        )?);
        let exposure = self.exposure(&at)?;
        Ok(Scene {
            objects,
            lights,
            camera,
            supersample: self.supersample,
            exposure,
            inputs,
        })
    }

    /// The exposure as the renderer reads it: "auto" or a number, as text.
    fn exposure(&self, at: &str) -> Result<Option<String>> {
        Ok(match &self.exposure {
            None => None,
            Some(toml::Value::String(s)) => Some(s.clone()),
            Some(toml::Value::Float(f)) => Some(f.to_string()),
            Some(toml::Value::Integer(i)) => Some(i.to_string()),
            Some(v) => bail!("{at}: exposure = {v}: expected a number or \"auto\""),
        })
    }
}

/// What a scene's objects take from the material: its fibre azimuth (degrees) and spacing.
#[derive(Clone, Copy)]
struct ObjectMaterial {
    psi_deg: f64,
    spacing: f64,
}

impl ObjectSpec {
    /// The object, placed (moved and scaled); a mesh's file (relative to `base`) is added to
    /// `inputs`. `at` names the object in errors.
    fn build(
        &self,
        at: &str,
        base: &Path,
        material: ObjectMaterial,
        inputs: &mut Vec<PathBuf>,
    ) -> Result<Object> {
        let o = self;
        let ObjectMaterial { psi_deg, spacing } = material;
        finite(&o.offset, "offset", at)?;
        if !(o.scale.is_finite() && o.scale > 0.0) {
            bail!("{at}: scale = {} must be finite and positive", o.scale);
        }
        let shape = match o.kind.as_str() {
            "torus" => Object::Torus { spacing },
            "sphere" => Object::Sphere { psi_deg },
            "swatch" => Object::Swatch { psi_deg },
            "mesh" => {
                let file = o
                    .file
                    .as_ref()
                    .ok_or_else(|| anyhow!("{at}: a mesh needs `file`"))?;
                let file = base.join(file);
                inputs.push(file.clone());
                let source = match o.tangents.as_deref().unwrap_or("curvature") {
                    "curvature" => TangentSource::Curvature,
                    "uv" => TangentSource::Uv,
                    "constant" => TangentSource::Constant { psi_deg },
                    t => bail!("{at}: tangents = {t:?}: expected curvature, uv or constant"),
                };
                let mesh = crate::load::mesh::load_obj(&file)?;
                Object::Mesh(std::sync::Arc::new(MeshObject::new(mesh, source, psi_deg)?))
            }
            t => bail!("{at}: type = {t:?}: expected torus, sphere, swatch or mesh"),
        };
        Ok(Object::Placed {
            inner: Box::new(shape),
            offset: Vec3::from(o.offset),
            scale: o.scale,
        })
    }
}

impl LightSpec {
    /// The light, its values checked; `at` names it in errors.
    fn build(&self, at: &str) -> Result<Light> {
        Ok(match *self {
            LightSpec::Directional {
                theta_deg,
                phi_deg,
                irradiance,
            } => {
                finite(
                    &[theta_deg, phi_deg, irradiance],
                    "theta_deg, phi_deg, irradiance",
                    at,
                )?;
                if irradiance < 0.0 {
                    bail!("{at}: irradiance = {irradiance} must not be negative");
                }
                Light::Directional {
                    direction: direction_from_angles(theta_deg.to_radians(), phi_deg.to_radians()),
                    irradiance,
                }
            }
            LightSpec::Point {
                position,
                intensity,
            } => {
                finite(&position, "position", at)?;
                if !(intensity.is_finite() && intensity >= 0.0) {
                    bail!("{at}: intensity = {intensity} must be finite and not negative");
                }
                Light::Point {
                    position: Vec3::from(position),
                    intensity,
                }
            }
        })
    }
}

impl CameraSpec {
    /// The camera for an image of `w` x `h` pixels; an orthographic one without a half width
    /// frames the `objects`' bounding sphere. `at` names the scene file in errors.
    fn build(&self, at: &str, (w, h): (usize, usize), objects: &[Object]) -> Result<Camera> {
        // the objects' bounding sphere
        let centre = objects
            .iter()
            .map(Object::centre)
            .fold(Vec3::zeros(), |a, b| a + b)
            / objects.len() as f64;
        let radius = objects
            .iter()
            .map(|o| (o.centre() - centre).norm() + o.bound())
            .fold(0.0, f64::max);
        let aspect = (w as f64 / h as f64).max(1.0);
        Ok(match *self {
            CameraSpec::Orthographic {
                theta_deg,
                phi_deg,
                half_width,
            } => {
                finite(
                    &[theta_deg, phi_deg],
                    "theta_deg, phi_deg",
                    &format!("{at}: [camera]"),
                )?;
                Camera {
                    direction: direction_from_angles(theta_deg.to_radians(), phi_deg.to_radians()),
                    target: centre,
                    width: w,
                    height: h,
                    half_width: half_width.unwrap_or(radius * 1.05 * aspect),
                    pinhole: None,
                }
            }
            CameraSpec::Pinhole {
                position,
                look_at,
                fov_deg,
            } => {
                finite(&position, "position", &format!("{at}: [camera]"))?;
                finite(&look_at, "look_at", &format!("{at}: [camera]"))?;
                if !(fov_deg > 0.0 && fov_deg < 170.0) {
                    bail!("{at}: [camera] fov_deg = {fov_deg}: expected (0, 170) degrees");
                }
                let (p, t) = (Vec3::from(position), Vec3::from(look_at));
                if (p - t).norm() == 0.0 {
                    bail!("{at}: [camera] position and look_at coincide");
                }
                Camera {
                    direction: (p - t).normalize(),
                    target: t,
                    width: w,
                    height: h,
                    half_width: 1.0,
                    pinhole: Some((p, fov_deg)),
                }
            }
        })
    }
}
