//! `export`: the fitted model as shader code a renderer runs (checked on the GPU driver against
//! the Rust model when asked) and as a glTF material on a preview mesh, built in memory; the
//! caller writes them into its reserved outputs.

use crate::export::gltf_out::{self, VertexFrames};
use crate::export::shader::{self, check, gpu::Gpu, Language};
use crate::fit::gltf_material::{self, FittedMaterial};
use crate::load::mesh;
use crate::model::topology::max_height;
use crate::model::{self, ModelId, ModelParams};
use crate::render::preview_mesh::{self, FramedMesh};
use anyhow::{anyhow, bail, Result};
use std::path::{Path, PathBuf};

/// What to export.
#[derive(Clone, Debug)]
pub struct ExportRequest {
    /// A parameter file or fitted result.
    pub result: PathBuf,
    /// The rung, overriding the file's.
    pub model: Option<String>,
    /// Shader source in this language.
    pub shader: Option<Language>,
    /// Run the shader on the GPU driver against the Rust model (and the result's check values)
    /// and refuse beyond the f32 bound.
    pub check: bool,
    /// A GLB preview with a fitted glTF material.
    pub gltf: bool,
    /// The preview mesh: swatch, sphere, torus or a .obj.
    pub object: String,
    /// No progress lines.
    pub quiet: bool,
}

/// The exported files, in memory.
pub struct ExportOutcome {
    pub model: ModelId,
    pub shader: Option<String>,
    pub glb: Option<(Vec<u8>, FittedMaterial)>,
}

/// Every file an export reads (none may be an output).
pub fn inputs(req: &ExportRequest) -> Vec<PathBuf> {
    let mut inputs = vec![req.result.clone()];
    if req.object.to_ascii_lowercase().ends_with(".obj") {
        inputs.push(PathBuf::from(&req.object));
    }
    inputs
}

/// Build what `req` asks for; a failure (a shader beyond its bound included) builds nothing.
pub fn export(req: &ExportRequest) -> Result<ExportOutcome> {
    let (_, id, params) =
        crate::api::eval::load_params(&req.result, req.model.as_deref(), req.quiet)?;
    if let Some(map) = &params.topology.map {
        // loaded (so it exists); say which, since the export bakes its histogram in
        if !req.quiet {
            eprintln!(
                "topology map {}: its {}-bin height histogram is baked in",
                map.source.display(),
                params.histogram_bins
            );
        }
    }
    let lines = provenance(&req.result, id, &params)?;
    // everything is built in memory first: a failure writes nothing
    let mut shader_text = None;
    if let Some(lang) = req.shader {
        let mut lines = lines.clone();
        let wgsl_src = shader::wgsl(id, &params, &lines)?;
        let wgsl_src = if req.check {
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
            if !req.quiet {
                eprintln!("{line}");
            }
            // the values the result itself states (what a renderer port checks against)
            let stated = crate::load::input::read_text(&req.result)
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
                if !req.quiet {
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
    if req.gltf {
        let model = model::build(id, &params)?;
        let psi_deg = params.fibre_azimuth.to_degrees();
        let mesh = preview(&req.object, psi_deg)?;
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
    Ok(ExportOutcome {
        model: id,
        shader: shader_text,
        glb,
    })
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
