//! `fibrefit export RESULT.json --shader wgsl|glsl|hlsl|msl --out FILE` and
//! `--gltf FILE.glb [--object ...]`: the fitted model as shader code a renderer runs, and as a
//! glTF material for engines without custom shaders.

use crate::export::atomic::Outputs;
use crate::export::gltf_out::{self, VertexFrames};
use crate::export::shader::{self, check, gpu::Gpu, Language};
use crate::fit::gltf_material;
use crate::load::mesh;
use crate::model::topology::max_height;
use crate::model::{self, ModelId, ModelParams};
use crate::render::preview_mesh::{self, FramedMesh};
use anyhow::{anyhow, bail, Result};
use clap::Args;
use std::path::{Path, PathBuf};

#[derive(Debug, Args)]
#[command(after_help = "\
SHADER: one source file with no entry points and no bindings: include it in your shader and
call fibrefit_brdf(l, v, n, t) -> vec3 (the BRDF in 1/sr per channel; unit directions towards
the light and the viewer, the macro normal and the fibre tangent in any orthonormal frame; 0 at
and below either horizon), fibrefit_brdf_at(l, v, n, t, height, azimuth_offset) for renderers
that feed per-texel maps, and the per-component fibrefit_basis(...) for albedo maps. The fitted
parameters are baked in (fibrefit_params()); every entry point has a _with form taking a
FibrefitParams (e.g. from your uniform buffer). The file's header documents all of it. WGSL is
the master; GLSL (4.50, no #version line), HLSL and MSL are translated and validated by naga.
Every rung but `reference` (an adaptive integration, the yardstick).
--check runs the exported shader as a compute shader on this machine's Vulkan driver against the
Rust model (10 000 random light/view pairs in random frames, texel heights, and the extremes)
and refuses to write it if it disagrees by more than f32 allows (the bound is printed).
GLTF: a preview mesh (swatch, sphere, seed 001's torus, or an OBJ with curvature-aligned tangents)
with NORMAL, TANGENT (the fibre direction), TEXCOORD_0 and a glTF material fitted to the model:
base colour, roughness, KHR_materials_anisotropy and KHR_materials_ior, fitted over 1500
direction pairs like the result's Ward fallback; the material's extras state its error.")]
pub struct ExportArgs {
    /// A fitted result (.json) or any parameter file `eval` accepts
    pub result: PathBuf,
    /// Model id [default: the file's `model`]
    #[arg(long, value_name = "ID")]
    pub model: Option<String>,
    /// Write the model as shader source in LANG: wgsl, glsl, hlsl or msl (needs --out)
    #[arg(long, value_name = "LANG", requires = "out")]
    pub shader: Option<String>,
    /// The shader file to write
    #[arg(long, value_name = "FILE", requires = "shader")]
    pub out: Option<PathBuf>,
    /// Run the exported shader on this machine's GPU driver against the Rust model first
    #[arg(long, requires = "shader")]
    pub check: bool,
    /// Write a preview mesh with a fitted glTF material (.glb)
    #[arg(long, value_name = "FILE.glb")]
    pub gltf: Option<PathBuf>,
    /// The glTF's mesh: swatch, sphere, torus or MESH.obj
    #[arg(
        long,
        value_name = "OBJECT",
        default_value = "swatch",
        requires = "gltf"
    )]
    pub object: String,
    /// No summary on stderr
    #[arg(long, short)]
    pub quiet: bool,
}

/// One line per fact of where the parameters came from.
fn provenance(path: &Path, id: ModelId, p: &ModelParams) -> Result<Vec<String>> {
    // the hash of the bytes the parameters were read from
    let hex = crate::load::sha256_read(path)
        .ok_or_else(|| anyhow!("{}: no hash was recorded when it was read", path.display()))?;
    let name = path.file_name().map_or_else(
        || path.display().to_string(),
        |n| n.to_string_lossy().into_owned(),
    );
    let a = &p.albedos;
    let mut lines = vec![
        format!("from {name} (sha256 {hex})"),
        format!(
            "albedos: diffuse {:?}, specular {:?}, substrate {:?}, fuzz {:?}",
            a.diffuse, a.specular, a.substrate, a.fuzz
        ),
    ];
    if id.is_cross_section() || id == ModelId::MaxNormal {
        lines.push(format!(
            "exponent {}, spacing {}, fibre azimuth {} deg, spread {} deg, Fresnel ior {}",
            p.exponent,
            p.spacing,
            p.fibre_azimuth.to_degrees(),
            p.azimuth_spread_deg,
            p.fresnel_ior
        ));
    }
    if id == ModelId::Ward {
        lines.push(format!("alpha_x {}, alpha_y {}", p.alpha_x, p.alpha_y));
    }
    if id.has_topology() {
        lines.push(format!(
            "height H0 {}, map scale {}{}",
            p.topology.height,
            p.topology.map_scale,
            p.topology.map.as_ref().map_or(String::new(), |m| format!(
                ", topology map {} ({} bins)",
                m.source.display(),
                p.histogram_bins
            ))
        ));
    }
    if p.fuzz_depth > 0.0 {
        lines.push(format!(
            "fuzz layer depth {}, asymmetry {}",
            p.fuzz_depth, p.fuzz_asymmetry
        ));
    }
    Ok(lines)
}

/// The preview mesh for `--object`.
fn preview(object: &str, psi_deg: f64) -> Result<FramedMesh> {
    match object {
        "swatch" => preview_mesh::swatch(psi_deg),
        "sphere" => preview_mesh::sphere(psi_deg),
        "torus" => preview_mesh::torus(),
        o if o.to_ascii_lowercase().ends_with(".obj") => {
            preview_mesh::curvature_aligned(mesh::load_obj(Path::new(o))?, psi_deg)
        }
        o => bail!("--object {o}: expected swatch, sphere, torus or a .obj mesh"),
    }
}

pub fn run(args: &ExportArgs) -> Result<()> {
    if args.shader.is_none() && args.gltf.is_none() {
        bail!("nothing to export: give --shader LANG --out FILE and/or --gltf FILE.glb");
    }
    let lang: Option<Language> = args
        .shader
        .as_deref()
        .map(|s| s.parse().map_err(|e: String| anyhow!("--shader {e}")))
        .transpose()?;
    let mut inputs = vec![args.result.clone()];
    if args.object.to_ascii_lowercase().ends_with(".obj") {
        inputs.push(PathBuf::from(&args.object));
    }
    // every output reserved before the work (none an input or another output), written together
    let mut outs = Outputs::new(&inputs);
    let shader_out = match &args.out {
        Some(out) => Some(outs.file(out, "--out")?),
        None => None,
    };
    let mut gltf_out = None;
    if let Some(g) = &args.gltf {
        let ext = g
            .extension()
            .and_then(|e| e.to_str())
            .map(str::to_ascii_lowercase);
        if ext.as_deref() != Some("glb") {
            bail!("--gltf {}: expected a .glb file name", g.display());
        }
        gltf_out = Some(outs.file(g, "--gltf")?);
    }
    let (_, id, params) =
        crate::api::eval::load_params(&args.result, args.model.as_deref(), args.quiet)?;
    if let Some(map) = &params.topology.map {
        // loaded (so it exists); say which, since the export bakes its histogram in
        if !args.quiet {
            eprintln!(
                "topology map {}: its {}-bin height histogram is baked in",
                map.source.display(),
                params.histogram_bins
            );
        }
    }
    let lines = provenance(&args.result, id, &params)?;
    // everything is built in memory first: a failure writes nothing
    let mut shader_text = None;
    if let Some(lang) = lang {
        let mut lines = lines.clone();
        let wgsl_src = shader::wgsl(id, &params, &lines)?;
        let wgsl_src = if args.check {
            let gpu = Gpu::new()?;
            let cases = check::cases(10_000, 1, max_height(params.spacing));
            let (a, bound) = check::on_gpu(&gpu, &wgsl_src, id, &params, &cases)?;
            let line = format!(
                "checked on {}: {} cases, relative error p99 {:.2e} (bound {:.1e}), max {:.2e}; \
                 worst case at {:.2} of its tolerance ({:.1e} + {:.1e} / min(N.l, N.v))",
                gpu.adapter,
                a.cases,
                a.p99_relative,
                bound.p99,
                a.max_relative,
                a.worst_over_tolerance,
                bound.max,
                bound.grazing
            );
            if !args.quiet {
                eprintln!("{line}");
            }
            // the values the result itself states (what a renderer port checks against)
            let stated = crate::load::input::read_text(&args.result)
                .ok()
                .and_then(|t| serde_json::from_str::<serde_json::Value>(&t).ok())
                .map(|v| check::stated_check_values(&v, params.fibre_azimuth))
                .unwrap_or_default();
            let mut stated_line = None;
            if !stated.is_empty() {
                let cases: Vec<check::Case> = stated.iter().map(|(c, _)| *c).collect();
                let outputs = gpu.evaluate(&wgsl_src, &cases)?;
                let (max_rel, worst) = check::compare_stated(&stated, &outputs, &bound);
                let l = format!(
                    "the result's {} check values: largest relative error {max_rel:.2e} ({worst:.2} of the tolerance)",
                    stated.len()
                );
                if !args.quiet {
                    eprintln!("{l}");
                }
                if worst > 1.0 {
                    bail!("the exported shader disagrees with the result's own check values: {l}; nothing written");
                }
                stated_line = Some(l);
            }
            if !bound.holds(&a) {
                bail!(
                    "the exported shader disagrees with the Rust model on this GPU driver beyond \
                     f32 limits: {line}; worst case {} (Rust {}, shader {}); nothing written",
                    a.worst.0,
                    a.worst.1,
                    a.worst.2
                );
            }
            lines.push(line);
            lines.extend(stated_line);
            shader::wgsl(id, &params, &lines)?
        } else {
            wgsl_src
        };
        shader_text = Some(shader::translate(&wgsl_src, lang)?);
    }
    let mut glb = None;
    if args.gltf.is_some() {
        let model = model::build(id, &params)?;
        let psi_deg = params.fibre_azimuth.to_degrees();
        let mesh = preview(&args.object, psi_deg)?;
        let fitted = gltf_material::fit(model.as_ref(), &params.albedos, 1)?;
        let material = gltf_out::fitted_material(&fitted, id, &lines);
        let mut bytes = Vec::new();
        gltf_out::write_glb(
            &mut bytes,
            &mesh.mesh,
            &VertexFrames {
                normals: &mesh.normals,
                tangents: &mesh.tangents,
                bitangents: &mesh.bitangents,
                undefined: &mesh.undefined,
            },
            Some(material),
            &format!("fibrefit {} export", env!("CARGO_PKG_VERSION")),
        )?;
        glb = Some((bytes, fitted));
    }
    // write: every file staged, then committed together
    if let (Some(text), Some(id)) = (&shader_text, shader_out) {
        outs.put(id, text.as_bytes())?;
    }
    if let (Some((bytes, _)), Some(id)) = (&glb, gltf_out) {
        outs.put(id, bytes)?;
    }
    outs.commit()?;
    if !args.quiet {
        if let (Some(lang), Some(path)) = (lang, &args.out) {
            eprintln!(
                "wrote {} ({} shader of model `{id}`)",
                path.display(),
                lang.as_str()
            );
        }
        if let (Some((_, fitted)), Some(path)) = (&glb, &args.gltf) {
            let m = &fitted.material;
            eprintln!(
                "wrote {} ({}: base colour {:.3?}, roughness {:.3}, anisotropy strength {:.2} rotation {:.0} deg, ior {:.2}, {}; \
                 relative RMS error of f cos {:.1} % over {} direction pairs; without anisotropy {:.1} %, with sheen {:.1} %, without {:.1} %)",
                path.display(),
                args.object,
                m.base_color,
                m.roughness,
                m.anisotropy_strength,
                m.anisotropy_rotation.to_degrees(),
                m.ior,
                m.sheen.map_or("no sheen".to_string(), |s| format!(
                    "sheen colour {:.2} roughness {:.2}",
                    s.colour, s.roughness
                )),
                100.0 * fitted.relative_rms_error,
                fitted.directions,
                100.0 * fitted.isotropic_relative_rms_error,
                100.0 * fitted.with_sheen_relative_rms_error,
                100.0 * fitted.without_sheen_relative_rms_error
            );
        }
    }
    if let Some((_, fitted)) = &glb {
        if fitted.relative_rms_error > 0.25 && !args.quiet {
            eprintln!(
                "warning: the glTF material matches the fibre model only to {:.0} % RMS: a preview for engines without custom shaders, not the model (use --shader for that)",
                100.0 * fitted.relative_rms_error
            );
        }
    }
    Ok(())
}
