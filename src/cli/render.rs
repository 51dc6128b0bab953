//! `fibrefit render`: a material on an object, as a picture and its AOVs; `--paper-figures` renders
//! the topology-map paper's figures 6 and 7 as one grid ([`crate::api::render`]).

use crate::api::render::{
    self as render_api, FlagScene, LightPreset, Render, RenderRequest, SceneSource,
};
use crate::export::atomic::Outputs;
use crate::export::picture::{reserve_aovs, write_aovs, write_labelled_grid, write_picture};
use crate::model::frame::{direction_from_angles, Vec3};
use anyhow::{bail, Result};
use clap::Args;
use std::path::PathBuf;

#[derive(Debug, Args)]
#[command(after_help = "\
OBJECTS: torus (the topology-map paper's: fibres wound round the tube, climbing twice from the outer to the inner
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
    /// A result JSON written by `fibrefit fit`, or a parameter TOML (MODEL.md §5)
    #[arg(long, value_name = "FILE", required_unless_present = "paper_figures")]
    pub params: Option<PathBuf>,
    /// Model id [default: the parameter file's `model`]
    #[arg(long, value_name = "ID")]
    pub model: Option<String>,
    /// torus, sphere, swatch or a triangle mesh MESH.obj
    #[arg(long, value_name = "OBJECT", default_value = "torus")]
    pub object: String,
    /// Meshes: the fibre tangent field: curvature (k1's direction, as principal-curvature-aligned shading does), uv (dp/du of the
    /// texture coordinates) or constant (fibre_azimuth_deg from x, projected on the surface)
    #[arg(long, value_name = "FIELD", default_value = "curvature")]
    pub tangents: String,
    /// Lighting: studio (a key light, a raking light at 80 deg and a rim light behind the
    /// object, so sheen, fuzz and anisotropy show), grazing (one light at 80 deg incidence) or
    /// flat (the --light lights) [default: studio, or flat when --light is given]
    #[arg(long, value_name = "PRESET", value_parser = ["studio", "grazing", "flat"])]
    pub preset: Option<String>,
    /// A directional light of unit irradiance from THETA,PHI degrees (repeatable; --preset
    /// flat) [default: 40,120]
    #[arg(long, value_name = "THETA,PHI", allow_hyphen_values = true)]
    pub light: Vec<String>,
    /// An orthographic camera looking from THETA,PHI degrees
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
    /// Shade every one of the N x N rays of every pixel (the exact box filter). By default an
    /// interior pixel whose radiance is smooth is shaded once, at its centre, and its rays' mean
    /// estimated from the neighbouring pixels' second differences where their third differences
    /// bound the estimate within 5e-4 of the picture's level; edges, highlights, creases and
    /// texture are shaded at every ray (`fibrefit bench render` measures the time and the
    /// difference)
    #[arg(long)]
    pub every_subsample: bool,
    /// PNG only: radiance factor before sRGB encoding (clipped at 1), or `auto` (the 99.5th
    /// percentile of the lit pixels to 0.8, brighter values compressed by a shoulder towards 1)
    #[arg(long, value_name = "E|auto", default_value = "auto")]
    pub exposure: String,
    /// Irradiance of a fill light from the camera's direction (the key lights have 1), so no
    /// visible side of the object is black; 0: none (scene files: their `fill`, default 0)
    #[arg(long, value_name = "E", default_value_t = crate::render::DEFAULT_FILL, allow_hyphen_values = true)]
    pub fill: f64,
    /// A scene file (objects moved and scaled, directional and point lights, orthographic or
    /// pinhole camera, size, supersampling, exposure; see docs/guide/render.md) in place of --object,
    /// --tangents, --light, --camera, --size and --supersample
    #[arg(long, value_name = "FILE")]
    pub scene: Option<PathBuf>,
    /// Per-texel maps from `fit --maps` (height.exr, fibre_azimuth.exr, kd.exr, ks.exr) over
    /// the object's (u, v) [default: the maps a fitted result names, found beside it]
    #[arg(long, value_name = "DIR")]
    pub maps: Option<PathBuf>,
    /// Ward on a mesh with curvature tangents: its alphas follow the curvature (principal-curvature-aligned shading):
    /// alpha_x = F |k1|, alpha_y = F |k2|, clamped to [0.01, 1] (F in the mesh's length unit)
    #[arg(long, value_name = "F")]
    pub ward_curvature_alpha: Option<f64>,
    /// Also write the per-pixel AOVs into DIR
    #[arg(long, value_name = "DIR")]
    pub aovs: Option<PathBuf>,
    /// Instead: figures 6 and 7 of the topology-map paper (Poulin-Fournier fibres climbing by a
    /// topology map) as one grid (rows max-normal, poulin-fournier, varying-topology,
    /// varying-topology with a topology map; columns two lightings) into --out
    #[arg(long, alias = "seed001")]
    pub paper_figures: bool,
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
    let camera = direction(&args.camera, "--camera")?;
    if args.paper_figures {
        let mut outs = Outputs::new(&[]);
        let picture_out = outs.file(&args.out, "--out")?;
        let s = render_api::paper_figures(
            camera,
            args.supersample,
            &crate::progress::Progress::new(args.quiet),
        )?;
        let (rows, cols) = (&s.rows, &s.columns);
        write_labelled_grid(&mut outs, picture_out, &s.grid, s.tile, rows, cols)?;
        outs.commit()?;
        if !args.quiet {
            eprintln!(
                "wrote {} (rows: max-normal, poulin-fournier, varying-topology, varying-topology + map; \
                 columns: light 35,120 and lights 70,20 + 30,250; camera {})",
                args.out.display(),
                args.camera
            );
        }
        return Ok(());
    }
    // lights given: they are the lighting; a preset that places its own is refused with them
    let preset = match (args.preset.as_deref(), args.light.is_empty()) {
        (None, true) => LightPreset::Studio,
        (None, false) => LightPreset::Flat,
        (Some(p), lights_empty) => {
            let p = LightPreset::parse(p)?;
            if p != LightPreset::Flat && !lights_empty {
                anyhow::bail!(
                    "--light sets the lights of --preset flat; --preset {} places its own",
                    args.preset.as_deref().unwrap_or_default()
                );
            }
            p
        }
    };
    let lights: Vec<Vec3> = if args.light.is_empty() {
        vec![direction("40,120", "--light")?]
    } else {
        args.light
            .iter()
            .map(|s| direction(s, "--light"))
            .collect::<Result<_>>()?
    };
    let req = RenderRequest {
        params: args
            .params
            .clone()
            .expect("clap: --params unless --paper-figures"),
        model: args.model.clone(),
        scene: match &args.scene {
            Some(path) => SceneSource::File(path.clone()),
            None => SceneSource::Flags(FlagScene {
                object: args.object.clone(),
                tangents: args.tangents.clone(),
                preset,
                lights,
                camera,
                size: [args.size[0], args.size[1]],
                supersample: args.supersample,
                fill: args.fill,
            }),
        },
        maps: args.maps.clone(),
        ward_curvature_alpha: args.ward_curvature_alpha,
        subsamples: match args.every_subsample {
            true => crate::render::Subsamples::Every,
            false => crate::render::Subsamples::Adaptive {
                tolerance: crate::render::ADAPTIVE_TOLERANCE,
            },
        },
        progress: crate::progress::Progress::new(args.quiet),
    };
    let render = Render::prepare(&req)?;
    // outputs checked before the work; none replaces an input
    let mut outs = Outputs::new(render.inputs());
    let picture_out = outs.file(&args.out, "--out")?;
    let aovs = match &args.aovs {
        Some(dir) => reserve_aovs(&mut outs, dir, render.model.has_topology())?,
        None => vec![],
    };
    let pic = render.run()?;
    let exposure = write_picture(
        &mut outs,
        picture_out,
        &pic,
        render.scene.exposure.as_deref().unwrap_or(&args.exposure),
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
