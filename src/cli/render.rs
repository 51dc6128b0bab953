//! `fibrefit render`: a material on an object, as a picture and its AOVs; `--seed001` renders
//! seed 001's figures 6 and 7 as one grid.

use crate::export::atomic::{OutputId, Outputs};
use crate::model::frame::{direction_from_angles, Vec3};
use crate::model::params::{ModelParams, RawParams};
use crate::model::topology::TopologyMap;
use crate::model::{self, ModelId};
use crate::render::mesh_object::{MeshObject, TangentSource};
use crate::render::objects::Object;
use crate::render::scene::{Scene, SceneFile};
use crate::render::{self, Camera, Light, Material, Picture};
use anyhow::{anyhow, bail, Result};
use clap::Args;
use std::path::{Path, PathBuf};

#[derive(Debug, Args)]
#[command(after_help = "\
OBJECTS: torus (seed 001: fibres wound round the tube, climbing twice from the outer to the inner
side; a topology map adds map_scale (2 m - 1) to that height), sphere (fibres along the circles of
latitude about z, turned by fibre_azimuth_deg towards the meridians), swatch (the square
[-1, 1]^2 in z = 0, fibres at fibre_azimuth_deg from x). The objects sit at the origin in a world
whose z is up; angles in degrees, theta from +z, phi from +x towards +y (the capture
conventions).
OUTPUT: .exr: linear radiance R, G, B (1/sr x the lights' irradiance: with unit irradiance, the
BRDF times cos theta_i summed over the lights) and alpha A (the fraction of the pixel's rays that
hit); .png: 8-bit sRGB of radiance x exposure, with alpha. No cast shadows, no interreflection.
--aovs DIR writes normal.exr, tangent.exr, position.exr (world space, R, G, B = x, y, z; zero
outside the object) and, for fibre rungs with a topology, height.exr (H in fibre radii; NaN
outside) from each pixel's centre ray.")]
pub struct RenderArgs {
    /// Parameter file `eval` accepts (.toml or a fitted result .json)
    #[arg(long, value_name = "FILE", required_unless_present = "seed001")]
    pub params: Option<PathBuf>,
    /// Model id [default: the parameter file's `model`]
    #[arg(long, value_name = "ID")]
    pub model: Option<String>,
    /// torus, sphere, swatch or a triangle mesh MESH.obj
    #[arg(long, value_name = "OBJECT", default_value = "torus")]
    pub object: String,
    /// Meshes: the fibre tangent field: curvature (k1's direction, seed 004), uv (dp/du of the
    /// texture coordinates) or constant (fibre_azimuth_deg from x, projected on the surface)
    #[arg(long, value_name = "FIELD", default_value = "curvature")]
    pub tangents: String,
    /// A directional light of unit irradiance from THETA,PHI degrees (repeatable)
    /// [default: 40,120]
    #[arg(long, value_name = "THETA,PHI", allow_hyphen_values = true)]
    pub light: Vec<String>,
    /// An orthographic camera looking from THETA,PHI degrees [default: 50,270]
    #[arg(
        long,
        value_name = "THETA,PHI",
        default_value = "50,270",
        allow_hyphen_values = true
    )]
    pub camera: String,
    /// Image size in pixels
    #[arg(long, num_args = 2, value_names = ["W", "H"], default_values_t = [512, 512])]
    pub size: Vec<usize>,
    /// Rays per pixel along each axis (anti-aliasing: N x N rays)
    #[arg(long, value_name = "N", default_value_t = 2)]
    pub supersample: usize,
    /// PNG only: radiance factor before sRGB encoding, or `auto` (the 99th percentile of the
    /// object's pixels to 0.9)
    #[arg(long, value_name = "E|auto", default_value = "auto")]
    pub exposure: String,
    /// A scene file (objects moved and scaled, directional and point lights, orthographic or
    /// pinhole camera, size, supersampling, exposure; see README) in place of --object,
    /// --tangents, --light, --camera, --size and --supersample
    #[arg(long, value_name = "FILE")]
    pub scene: Option<PathBuf>,
    /// Per-texel maps from `fit --maps` (height.exr, fibre_azimuth.exr, kd.exr, ks.exr) over
    /// the object's (u, v) [default: the maps a fitted result names, found beside it]
    #[arg(long, value_name = "DIR")]
    pub maps: Option<PathBuf>,
    /// Ward on a mesh with curvature tangents: its alphas follow the curvature (seed 004):
    /// alpha_x = F |k1|, alpha_y = F |k2|, clamped to [0.01, 1] (F in the mesh's length unit)
    #[arg(long, value_name = "F")]
    pub ward_curvature_alpha: Option<f64>,
    /// Also write the per-pixel AOVs into DIR
    #[arg(long, value_name = "DIR")]
    pub aovs: Option<PathBuf>,
    /// Instead: seed 001's figures 6 and 7 as one grid (rows max-normal, poulin-fournier,
    /// varying-topology, varying-topology with a topology map; columns two lightings) into --out
    #[arg(long)]
    pub seed001: bool,
    /// Output image (.exr or .png)
    #[arg(long, value_name = "FILE")]
    pub out: PathBuf,
    /// No progress bar
    #[arg(long, short)]
    pub quiet: bool,
}

/// THETA,PHI in degrees as a unit direction (theta in [0, 180], finite).
fn direction(text: &str, what: &str) -> Result<Vec3> {
    let parts: Vec<&str> = text.split(',').map(str::trim).collect();
    let nums: Vec<f64> = parts.iter().filter_map(|p| p.parse().ok()).collect();
    if parts.len() != 2 || nums.len() != 2 || nums.iter().any(|x| !x.is_finite()) {
        bail!("{what} {text}: expected THETA,PHI in degrees, e.g. 40,120");
    }
    if !(0.0..=180.0).contains(&nums[0]) {
        bail!(
            "{what} {text}: theta {} is outside [0, 180] degrees",
            nums[0]
        );
    }
    Ok(direction_from_angles(
        nums[0].to_radians(),
        nums[1].to_radians(),
    ))
}

fn object(name: &str, tangents: &str, params: &ModelParams) -> Result<Object> {
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

/// Write `pic` to `path` (.exr linear RGBA, .png sRGB RGBA with `exposure`); returns the
/// exposure used.
fn write_picture(
    outs: &mut Outputs,
    id: OutputId,
    pic: &Picture,
    exposure: &str,
) -> Result<Option<f64>> {
    let path = &outs.name(id).to_path_buf();
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase);
    let out = &mut *outs;
    let used = match ext.as_deref() {
        Some("exr") => {
            let data: Vec<f32> = pic
                .radiance
                .iter()
                .zip(&pic.alpha)
                .flat_map(|(c, a)| [c[0], c[1], c[2], *a])
                .collect();
            crate::export::images::write_exr_into(
                out.file_and_name(id).0,
                path,
                pic.width,
                pic.height,
                4,
                &data,
            )?;
            None
        }
        Some("png") => {
            let e = match exposure {
                "auto" => {
                    let mut lum: Vec<f32> = pic
                        .radiance
                        .iter()
                        .zip(&pic.alpha)
                        .filter(|(_, a)| **a > 0.0)
                        .map(|(c, a)| c[0].max(c[1]).max(c[2]) / a)
                        .collect();
                    lum.sort_by(f32::total_cmp);
                    let p99 = lum.get(lum.len() * 99 / 100).copied().unwrap_or(0.0);
                    if p99 > 0.0 {
                        0.9 / p99 as f64
                    } else {
                        1.0
                    }
                }
                t => t
                    .parse::<f64>()
                    .ok()
                    .filter(|e| e.is_finite() && *e > 0.0)
                    .ok_or_else(|| anyhow!("--exposure {t}: expected a positive number or auto"))?,
            };
            let bytes: Vec<u8> = pic
                .radiance
                .iter()
                .zip(&pic.alpha)
                .flat_map(|(c, a)| {
                    // premultiplied by coverage in the sum: undo it for the colour
                    let un = |v: f32| if *a > 0.0 { v / a } else { 0.0 };
                    let code = |v: f32| {
                        (crate::load::image_io::linear_to_srgb(
                            (un(v) as f64 * e).clamp(0.0, 1.0) as f32
                        ) * 255.0)
                            .round() as u8
                    };
                    [
                        code(c[0]),
                        code(c[1]),
                        code(c[2]),
                        (a * 255.0).round() as u8,
                    ]
                })
                .collect();
            let mut w = std::io::BufWriter::new(out.writer(id));
            image::RgbaImage::from_raw(pic.width as u32, pic.height as u32, bytes)
                .ok_or_else(|| anyhow!("image buffer size"))?
                .write_to(&mut w, image::ImageFormat::Png)
                .and_then(|_| std::io::Write::flush(&mut w).map_err(image::ImageError::IoError))
                .map_err(|e| anyhow!("{}: cannot write PNG: {e}", path.display()))?;
            Some(e)
        }
        _ => bail!(
            "--out {}: expected a .exr or .png file name",
            path.display()
        ),
    };
    Ok(used)
}

/// The AOV files of a render (`height.exr` only for rungs with a topology), reserved in `dir`.
fn reserve_aovs(outs: &mut Outputs, dir: &Path, with_height: bool) -> Result<Vec<OutputId>> {
    outs.dir(dir, "--aovs")?;
    let mut names = vec!["normal.exr", "tangent.exr", "position.exr"];
    if with_height {
        names.push("height.exr");
    }
    names
        .into_iter()
        .map(|f| outs.file(&dir.join(f), "--aovs"))
        .collect()
}

/// Write the AOVs of `pic` into their reserved files (committed with the picture).
fn write_aovs(outs: &mut Outputs, ids: &[OutputId], pic: &Picture) -> Result<()> {
    let layers: [(&[[f32; 3]], usize); 3] = [
        (&pic.normal, 3),
        (&pic.tangent, 3),
        (&pic.position, 3),
    ];
    for (k, &id) in ids.iter().enumerate() {
        let data: Vec<f32> = match layers.get(k) {
            Some((v, _)) => v.iter().flatten().copied().collect(),
            None => pic.fibre_height.clone(),
        };
        let channels = layers.get(k).map_or(1, |l| l.1);
        let (f, name) = outs.file_and_name(id);
        crate::export::images::write_exr_into(f, name, pic.width, pic.height, channels, &data)?;
    }
    Ok(())
}

pub fn run(args: &RenderArgs) -> Result<()> {
    let ext = args
        .out
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase);
    if !matches!(ext.as_deref(), Some("exr" | "png")) {
        bail!(
            "--out {}: expected a .exr or .png file name",
            args.out.display()
        );
    }
    if args.supersample == 0 || args.supersample > 16 {
        bail!("--supersample {}: expected 1 to 16", args.supersample);
    }
    if args.seed001 {
        return seed001(args);
    }
    let params_path = args
        .params
        .as_ref()
        .expect("clap: --params unless --seed001");
    let (raw, id, params) =
        crate::api::eval::load_params(params_path, args.model.as_deref(), args.quiet)?;
    let scene = match &args.scene {
        Some(path) => {
            SceneFile::load(path)?.build(path, params.fibre_azimuth.to_degrees(), params.spacing)?
        }
        None => flags_scene(args, &params)?,
    };
    // outputs checked before the work; none replaces an input
    let mut inputs = vec![params_path.clone()];
    inputs.extend(scene.inputs.iter().cloned());
    let maps = maps_dir(args, params_path)?;
    if let Some(dir) = &maps {
        for f in ["height.exr", "fibre_azimuth.exr", "kd.exr", "ks.exr"] {
            inputs.push(dir.join(f));
        }
    }
    inputs.extend(raw.topology_map.iter().cloned());
    let mut outs = Outputs::new(&inputs);
    let picture_out = outs.file(&args.out, "--out")?;
    let aovs = match &args.aovs {
        Some(dir) => reserve_aovs(&mut outs, dir, id.has_topology())?,
        None => vec![],
    };
    if let Some(f) = args.ward_curvature_alpha {
        if id != ModelId::Ward {
            bail!("--ward-curvature-alpha: the Ward rung's alphas; this is `{id}`");
        }
        if !(f.is_finite() && f > 0.0) {
            bail!("--ward-curvature-alpha {f}: expected a finite positive factor");
        }
        let mesh = args.object.to_ascii_lowercase().ends_with(".obj");
        if args.scene.is_none() && !(mesh && args.tangents == "curvature") {
            bail!("--ward-curvature-alpha: needs a mesh (--object MESH.obj) with --tangents curvature");
        }
    }
    let texel_maps = match &maps {
        Some(dir) => Some(
            crate::load::texel_maps::TexelMapsIn::load(dir, None)
                .map_err(|e| anyhow!("--maps: {e:#}"))?,
        ),
        None => None,
    };
    let shading = model::build(id, &params)?;
    let map = params.topology.map.clone();
    let material = Material {
        model: shading.as_ref(),
        albedos: params.albedos,
        channels: params.albedos.channels(),
        spacing: params.spacing,
        height: params.topology.height,
        map_scale: params.topology.map_scale,
        topology_map: map.as_deref(),
        texel_maps: texel_maps.as_ref(),
        fibre_azimuth_deg: params.fibre_azimuth.to_degrees(),
        ward_curvature: args.ward_curvature_alpha,
    };
    let bar = crate::progress::bar(scene.camera.height as u64, "render", args.quiet);
    let pic = render::render(
        &scene.objects,
        &material,
        &scene.lights,
        &scene.camera,
        scene.supersample,
        &bar,
    );
    bar.finish_and_clear();
    let exposure = write_picture(
        &mut outs,
        picture_out,
        &pic,
        scene.exposure.as_deref().unwrap_or(&args.exposure),
    )?;
    write_aovs(&mut outs, &aovs, &pic)?;
    outs.commit()?;
    if !args.quiet {
        match exposure {
            Some(e) => eprintln!("wrote {} (exposure {e:.4})", args.out.display()),
            None => eprintln!("wrote {}", args.out.display()),
        }
    }
    Ok(())
}

/// The maps directory: --maps, else the one a `fit --maps` result names (relative to the
/// result file, then to the working directory), with a warning when it cannot be found.
fn maps_dir(args: &RenderArgs, params: &Path) -> Result<Option<PathBuf>> {
    if let Some(d) = &args.maps {
        return Ok(Some(d.clone()));
    }
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
    let beside = params.parent().unwrap_or(Path::new(".")).join(named);
    for d in [beside, PathBuf::from(named)] {
        if d.is_dir() {
            return Ok(Some(d));
        }
    }
    if !args.quiet {
        eprintln!(
            "warning: {} names the maps directory {named}, which is not beside it nor in the working directory: rendering without the maps (give --maps DIR)",
            params.display()
        );
    }
    Ok(None)
}

/// The scene the flags describe: one object at the origin, directional lights of unit
/// irradiance, an orthographic camera.
fn flags_scene(args: &RenderArgs, params: &ModelParams) -> Result<Scene> {
    let obj = object(&args.object, &args.tangents, params)?;
    let lights = lights_of(&args.light)?;
    let (w, h) = (args.size[0], args.size[1]);
    crate::render::check_budget(w, h, args.supersample, "--size/--supersample")?;
    let camera = Camera {
        direction: direction(&args.camera, "--camera")?,
        target: obj.centre(),
        width: w,
        height: h,
        half_width: obj.bound() * 1.05 * (w as f64 / h as f64).max(1.0),
        pinhole: None,
    };
    let inputs = if args.object.to_ascii_lowercase().ends_with(".obj") {
        vec![PathBuf::from(&args.object)]
    } else {
        vec![]
    };
    Ok(Scene {
        objects: vec![obj],
        lights,
        camera,
        supersample: args.supersample,
        exposure: None,
        inputs,
    })
}

fn lights_of(specs: &[String]) -> Result<Vec<Light>> {
    let specs: Vec<String> = if specs.is_empty() {
        vec!["40,120".into()]
    } else {
        specs.to_vec()
    };
    specs
        .iter()
        .map(|s| {
            Ok(Light::Directional {
                direction: direction(s, "--light")?,
                irradiance: 1.0,
            })
        })
        .collect()
}

/// Seed 001's figures 6 and 7: the torus in four rows (max-normal, poulin-fournier,
/// varying-topology, varying-topology with a topology map of scale 0.25) under two lightings.
fn seed001(args: &RenderArgs) -> Result<()> {
    let mut outs = Outputs::new(&[]);
    let picture_out = outs.file(&args.out, "--out")?;
    let size = 256usize;
    let lightings = [
        vec!["35,120".to_string()],
        vec!["70,20".to_string(), "30,250".to_string()],
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
        source: PathBuf::from("seed001-noise"),
    };
    let rows: [(&str, ModelId, bool); 4] = [
        ("max-normal", ModelId::MaxNormal, false),
        ("poulin-fournier", ModelId::PoulinFournier, false),
        ("varying-topology", ModelId::VaryingTopology, false),
        ("varying-topology + map", ModelId::VaryingTopology, true),
    ];
    let bar = crate::progress::bar(
        (rows.len() * lightings.len() * size) as u64,
        "seed 001",
        args.quiet,
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
        };
        for lights in &lightings {
            let camera = Camera {
                direction: direction(&args.camera, "--camera")?,
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
                &lights_of(lights)?,
                &camera,
                args.supersample,
                &bar,
            );
            tiles.push(pic);
        }
    }
    bar.finish_and_clear();
    // one exposure for the whole grid: the 99th percentile over every tile
    let mut lum: Vec<f32> = tiles
        .iter()
        .flat_map(|p| {
            p.radiance
                .iter()
                .zip(&p.alpha)
                .filter(|(_, a)| **a > 0.0)
                .map(|(c, a)| c[0].max(c[1]).max(c[2]) / a)
        })
        .collect();
    lum.sort_by(f32::total_cmp);
    let e = 0.9
        / lum
            .get(lum.len() * 99 / 100)
            .copied()
            .unwrap_or(1.0)
            .max(1e-12);
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
    write_picture(&mut outs, picture_out, &grid, &format!("{e}"))?;
    outs.commit()?;
    if !args.quiet {
        eprintln!(
            "wrote {} (rows: {}; columns: light 35,120 and lights 70,20 + 30,250; camera {})",
            args.out.display(),
            rows.map(|r| r.0).join(", "),
            args.camera
        );
    }
    Ok(())
}
