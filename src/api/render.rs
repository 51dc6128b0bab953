//! `render`: a material on an object (or a scene), as a picture and its AOVs.
//! [`Render::prepare`] loads the parameters, the scene and the maps (so the caller can reserve
//! its outputs knowing every input), [`Render::run`] renders; [`paper_figures`] renders the topology-map paper's
//! figures 6 and 7 as one grid. Files are written by `picture`.

use crate::load::texel_maps::TexelMapsIn;
use crate::model::frame::{direction_from_angles, Vec3};
use crate::model::params::{ModelParams, RawParams};
use crate::model::topology::TopologyMap;
use crate::model::{self, ModelId};
use crate::render::mesh_object::{MeshObject, TangentSource};
use crate::render::objects::Object;
use crate::render::scene::{Scene, SceneFile};
use crate::render::{self, Camera, Light, Material, Picture};
use anyhow::{anyhow, bail, Result};
use std::path::{Path, PathBuf};

pub use crate::render::lighting::Preset as LightPreset;

/// One object at the origin, directional lights (a preset's, or the caller's of unit
/// irradiance), an orthographic camera.
#[derive(Clone, Debug)]
pub struct FlagScene {
    /// torus, sphere, swatch or MESH.obj
    pub object: String,
    /// Meshes' fibre field: curvature, uv or constant.
    pub tangents: String,
    /// The lighting: a preset's lights placed around the camera, or (`Flat`) `lights`.
    pub preset: LightPreset,
    /// Directions towards the lights of `Flat` (unit, world z up).
    pub lights: Vec<Vec3>,
    /// Direction towards the camera.
    pub camera: Vec3,
    /// Picture size [width, height] in pixels.
    pub size: [usize; 2],
    /// Rays per pixel along each axis (supersample^2 rays per pixel).
    pub supersample: usize,
    /// Irradiance of a fill light from the camera's direction (0: none).
    pub fill: f64,
}

/// Where the scene comes from.
#[derive(Clone, Debug)]
pub enum SceneSource {
    /// A scene file (docs/guide/render.md; format in src/render/scene.rs).
    File(PathBuf),
    /// An object, lights and camera from command-line flags.
    Flags(FlagScene),
}

/// A render to make.
#[derive(Clone, Debug)]
pub struct RenderRequest {
    /// A parameter file `eval` accepts (or a fitted result).
    pub params: PathBuf,
    /// The rung, overriding the file's.
    pub model: Option<String>,
    /// The scene: a scene file or flags.
    pub scene: SceneSource,
    /// Per-texel maps [default: those a fitted result names, found beside it].
    pub maps: Option<PathBuf>,
    /// Ward on a curvature-tangent mesh: alphas F |k1|, F |k2|.
    pub ward_curvature_alpha: Option<f64>,
    /// How the subsample rays are shaded (adaptive by default: smooth interior pixels once).
    pub subsamples: render::Subsamples,
    /// Where the progress bar and warnings go.
    pub progress: crate::progress::Progress,
}

/// A render with everything loaded.
pub struct Render {
    /// The rung rendered.
    pub model: ModelId,
    /// Its parameters (albedos linear, angles in radians, lengths in fibre radii).
    pub params: ModelParams,
    /// The objects, lights and camera.
    pub scene: Scene,
    texel_maps: Option<TexelMapsIn>,
    ward_curvature_alpha: Option<f64>,
    subsamples: render::Subsamples,
    inputs: Vec<PathBuf>,
    progress: crate::progress::Progress,
}

impl Render {
    /// Load what `req` names and check it.
    pub fn prepare(req: &RenderRequest) -> Result<Self> {
        let (raw, id, params) =
            crate::api::eval::load_params(&req.params, req.model.as_deref(), &req.progress)?;
        let scene = match &req.scene {
            SceneSource::File(path) => SceneFile::load(path)?.build(
                path,
                params.fibre_azimuth.to_degrees(),
                params.spacing,
            )?,
            SceneSource::Flags(f) => flags_scene(f, &params)?,
        };
        let mut inputs = vec![req.params.clone()];
        inputs.extend(scene.inputs.iter().cloned());
        let maps = maps_dir(req.maps.as_deref(), &req.params, &req.progress)?;
        if let Some(dir) = &maps {
            for f in crate::load::texel_maps::MAP_FILES {
                inputs.push(dir.join(f));
            }
        }
        inputs.extend(raw.topology_map.iter().cloned());
        if let Some(f) = req.ward_curvature_alpha {
            if !id.has(crate::model::Ability::WardLobe) {
                bail!("--ward-curvature-alpha: the Ward rung's alphas; this is `{id}`");
            }
            if !(f.is_finite() && f > 0.0) {
                bail!("--ward-curvature-alpha {f}: expected a finite positive factor");
            }
            let curvature_mesh = matches!(&req.scene, SceneSource::Flags(s)
                if s.object.to_ascii_lowercase().ends_with(".obj") && s.tangents == "curvature");
            if matches!(req.scene, SceneSource::Flags(_)) && !curvature_mesh {
                bail!("--ward-curvature-alpha: needs a mesh (--object MESH.obj) with --tangents curvature");
            }
        }
        let texel_maps = match &maps {
            Some(dir) => {
                let m = TexelMapsIn::load(dir, None).map_err(|e| anyhow!("--maps: {e:#}"))?;
                m.lobe_for(id, dir).map_err(|e| anyhow!("--maps: {e:#}"))?;
                Some(m)
            }
            None => None,
        };
        Ok(Self {
            model: id,
            params,
            scene,
            texel_maps,
            ward_curvature_alpha: req.ward_curvature_alpha,
            subsamples: req.subsamples,
            inputs,
            progress: req.progress,
        })
    }

    /// Every file the render reads (none may be an output).
    pub fn inputs(&self) -> &[PathBuf] {
        &self.inputs
    }

    /// Render the picture (with its AOVs).
    pub fn run(&self) -> Result<Picture> {
        let params = &self.params;
        let shading = model::build(self.model, params)?;
        let map = params.topology.map.clone();
        let material = Material {
            model: shading.as_ref(),
            albedos: params.albedos,
            channels: params.albedos.channels(),
            spacing: params.spacing,
            height: params.topology.height,
            map_scale: params.topology.map_scale,
            topology_map: map.as_deref(),
            texel_maps: self.texel_maps.as_ref(),
            fibre_azimuth_deg: params.fibre_azimuth.to_degrees(),
            ward_curvature: self.ward_curvature_alpha,
            lobe: params.lobe(self.model),
            correction: params.correction.as_ref(),
        };
        let scene = &self.scene;
        let bar = self.progress.bar(scene.camera.height as u64, "render");
        let pic = render::render_with(
            &scene.objects,
            &material,
            &scene.lights,
            &scene.camera,
            scene.supersample,
            self.subsamples,
            &bar,
        );
        bar.finish_and_clear();
        Ok(pic)
    }
}

/// Directional lights of unit irradiance towards `dirs`.
fn directional(dirs: &[Vec3]) -> Vec<Light> {
    dirs.iter()
        .map(|&direction| Light::Directional {
            direction,
            irradiance: 1.0,
        })
        .collect()
}

/// The object `name` (torus, sphere, swatch or a mesh MESH.obj with the fibre field `tangents`).
pub fn object(name: &str, tangents: &str, params: &ModelParams) -> Result<Object> {
    let psi = params.fibre_azimuth.to_degrees();
    Ok(match name {
        "torus" => Object::Torus {
            spacing: params.spacing,
        },
        "sphere" => Object::Sphere { psi_deg: psi },
        "swatch" => Object::Swatch { psi_deg: psi },
        o if o.to_ascii_lowercase().ends_with(".obj") => {
            let source = match tangents {
                "curvature" => TangentSource::Curvature,
                "uv" => TangentSource::Uv,
                "constant" => TangentSource::Constant { psi_deg: psi },
                t => bail!("--tangents {t}: expected curvature, uv or constant"),
            };
            let mesh = crate::load::mesh::load_obj(Path::new(o))?;
            Object::Mesh(std::sync::Arc::new(MeshObject::new(mesh, source, psi)?))
        }
        o => bail!("--object {o}: expected torus, sphere, swatch or a mesh file MESH.obj"),
    })
}

/// The maps directory: --maps, else the one a `fit --maps` result names, relative to the
/// result's folder (docs/formats.md) and never to the working directory; a warning through
/// `progress` says where it was looked for when it is not there.
pub fn maps_dir(
    given: Option<&Path>,
    params: &Path,
    progress: &crate::progress::Progress,
) -> Result<Option<PathBuf>> {
    if let Some(d) = given {
        return Ok(Some(d.to_path_buf()));
    }
    let Some((named, looked)) = named_maps_dir(params)? else {
        return Ok(None);
    };
    if looked.is_dir() {
        check_map_hashes(params, &looked)?;
        return Ok(Some(looked));
    }
    progress.warn(&format!(
        "{}: rendering without the maps (give --maps DIR)",
        missing_maps(params, &named, &looked)
    ));
    Ok(None)
}

/// The maps directory a result JSON names (`maps.directory`) and where that is: beside the
/// result (or the absolute path it gives). `None` for a parameter file or a result without maps.
pub fn named_maps_dir(params: &Path) -> Result<Option<(String, PathBuf)>> {
    let is_json = params
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("json"));
    if !is_json {
        return Ok(None);
    }
    let v: serde_json::Value = serde_json::from_str(&crate::load::input::read_text(params)?)
        .map_err(|e| anyhow!("{}: {e}", params.display()))?;
    let Some(named) = v["maps"]["directory"].as_str() else {
        return Ok(None);
    };
    let looked = params.parent().unwrap_or(Path::new(".")).join(named);
    Ok(Some((named.to_string(), looked)))
}

/// The maps in `dir` (found beside the result `params`) are the ones the result recorded
/// (`maps.sha256`: each EXR's SHA-256); results written before the hashes pass unchecked.
fn check_map_hashes(params: &Path, dir: &Path) -> Result<()> {
    let v: serde_json::Value = serde_json::from_str(&crate::load::input::read_text(params)?)
        .map_err(|e| anyhow!("{}: {e}", params.display()))?;
    let Some(recorded) = v["maps"]["sha256"].as_object() else {
        return Ok(());
    };
    for (file, expected) in recorded {
        let Some(expected) = expected.as_str() else {
            continue;
        };
        let at = dir.join(file);
        if !at.is_file() {
            bail!(
                "{}: the map {} that the result recorded is not there (copy the maps directory with the result)",
                params.display(),
                at.display()
            );
        }
        let got =
            crate::load::input::read_input_as(&at, crate::load::MAX_INPUT_BYTES, "map")?.sha256;
        if !got.eq_ignore_ascii_case(expected) {
            bail!(
                "{}: the map {} is not the one this result was fitted with: its sha256 is {got}, the result recorded {expected} (maps.sha256); restore the fit's maps, or give --maps DIR to use these",
                params.display(),
                at.display()
            );
        }
    }
    Ok(())
}

/// What a warning says of a maps directory a result names that is not there.
pub fn missing_maps(params: &Path, named: &str, looked: &Path) -> String {
    format!(
        "{} names the maps directory `{named}`, which is not there (looked for beside the result: {}; a result's maps are never looked for in the working directory)",
        params.display(),
        looked.display()
    )
}

/// The scene the flags describe: one object at the origin, the preset's directional lights
/// (or `flat`: the flags' of unit irradiance) and the fill, an orthographic camera.
fn flags_scene(f: &FlagScene, params: &ModelParams) -> Result<Scene> {
    let obj = object(&f.object, &f.tangents, params)?;
    let mut lights = f
        .preset
        .lights(f.camera)
        .unwrap_or_else(|| directional(&f.lights));
    lights.extend(crate::render::fill_light(f.camera, f.fill, "--fill")?);
    let [w, h] = f.size;
    crate::render::check_budget(w, h, f.supersample, "--size/--supersample")?;
    let camera = Camera {
        direction: f.camera,
        target: obj.centre(),
        width: w,
        height: h,
        half_width: obj.bound() * 1.05 * (w as f64 / h as f64).max(1.0),
        pinhole: None,
    };
    let inputs = if f.object.to_ascii_lowercase().ends_with(".obj") {
        vec![PathBuf::from(&f.object)]
    } else {
        vec![]
    };
    Ok(Scene {
        objects: vec![obj],
        lights,
        camera,
        supersample: f.supersample,
        exposure: None,
        inputs,
    })
}

/// The topology-map paper's figures 6 and 7: the torus in four rows (max-normal, poulin-fournier,
/// varying-topology, varying-topology with a topology map of scale 0.25) under two lightings,
/// as one picture of `tile` x `tile` renders seen from `camera` with `supersample`^2 rays per
/// pixel, with the rows' and columns' labels.
pub struct PaperFigures {
    /// The grid of tiles: one row per rung, one column per lighting (linear radiance).
    pub grid: Picture,
    /// The side of one tile, pixels.
    pub tile: usize,
    /// The rows' labels (rungs).
    pub rows: Vec<String>,
    /// The columns' labels (lightings).
    pub columns: Vec<String>,
}

/// The paper figures: each rung (rows) under each lighting (columns) on a torus.
pub fn paper_figures(
    camera: Vec3,
    supersample: usize,
    progress: &crate::progress::Progress,
) -> Result<PaperFigures> {
    let size = 256usize;
    let deg = |t: f64, p: f64| direction_from_angles(t.to_radians(), p.to_radians());
    let lightings = [
        vec![deg(35.0, 120.0)],
        vec![deg(70.0, 20.0), deg(30.0, 250.0)],
    ];
    let map = TopologyMap {
        width: 256,
        height: 256,
        values: crate::synth::generate_map(&crate::synth::MapSpec {
            width: 256,
            height: 256,
            seed: 1,
            waves: 48,
        }),
        source: PathBuf::from("paper-figures-noise"),
    };
    let rows: [(&str, ModelId, bool); 4] = [
        ("max-normal", ModelId::MaxNormal, false),
        ("poulin-fournier", ModelId::PoulinFournier, false),
        ("varying-topology", ModelId::VaryingTopology, false),
        ("varying-topology + map", ModelId::VaryingTopology, true),
    ];
    let bar = progress.bar(
        (rows.len() * lightings.len() * size) as u64,
        "paper figures",
    );
    let mut tiles = Vec::new();
    for (_, id, with_map) in rows {
        let raw: RawParams = toml::from_str(
            "kd = [0.55, 0.32, 0.18]\nks = [0.5, 0.45, 0.4]\nexponent = 60\nspacing = 2.0\nmap_scale = 0.25\n",
        )?;
        let (params, _) = ModelParams::from_raw(&raw, id)?;
        let shading = model::build(id, &params)?;
        let material = Material {
            model: shading.as_ref(),
            albedos: params.albedos,
            channels: 3,
            spacing: 2.0,
            height: 0.0,
            map_scale: if with_map { 0.25 } else { 0.0 },
            topology_map: with_map.then_some(&map),
            texel_maps: None,
            fibre_azimuth_deg: 0.0,
            ward_curvature: None,
            lobe: params.lobe(id),
            correction: None,
        };
        for lights in &lightings {
            let camera = Camera {
                direction: camera,
                target: Vec3::zeros(),
                width: size,
                height: size,
                half_width: (crate::render::objects::TORUS_MAJOR
                    + crate::render::objects::TORUS_TUBE)
                    * 1.05,
                pinhole: None,
            };
            let pic = render::render(
                &[Object::Torus { spacing: 2.0 }],
                &material,
                &directional(lights),
                &camera,
                supersample,
                &bar,
            );
            tiles.push(pic);
        }
    }
    bar.finish_and_clear();
    let cols = lightings.len();
    let (gw, gh) = (size * cols, size * rows.len());
    let mut grid = Picture {
        width: gw,
        height: gh,
        radiance: vec![[0.0; 3]; gw * gh],
        alpha: vec![0.0; gw * gh],
        normal: vec![],
        tangent: vec![],
        position: vec![],
        fibre_height: vec![],
        shaded_every: tiles.iter().map(|t| t.shaded_every).sum(),
    };
    for (k, pic) in tiles.iter().enumerate() {
        let (r, c) = (k / cols, k % cols);
        for y in 0..size {
            for x in 0..size {
                let i = (r * size + y) * gw + c * size + x;
                grid.radiance[i] = pic.radiance[y * size + x];
                grid.alpha[i] = pic.alpha[y * size + x];
            }
        }
    }
    Ok(PaperFigures {
        grid,
        tile: size,
        rows: rows.iter().map(|r| r.0.to_string()).collect(),
        columns: vec![
            "one light at 35,120".into(),
            "two lights at 70,20 and 30,250".into(),
        ],
    })
}
