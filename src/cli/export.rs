//! `fibrefit export RESULT.json --shader wgsl|glsl|glsl-es|hlsl|msl --out FILE`,
//! `--gltf FILE.glb [--object ...]` and `--blender FILE.py [--name NAME]`: the fitted model as
//! shader code a renderer runs, as a glTF material for engines without custom shaders, and as a
//! Blender material.

use crate::api::export::{self as export_api, ExportOutcome, ExportRequest, GltfRoute};
use crate::export::atomic::Outputs;
use crate::export::shader::Language;
use anyhow::{anyhow, bail, Result};
use clap::Args;
use std::path::PathBuf;

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
GLTF: a preview mesh (swatch, sphere, the topology-map paper's torus, or an OBJ with curvature-aligned tangents)
with NORMAL, TANGENT (the UV u axis on the swatch and sphere, the fibres at fibre_azimuth_deg from
it; the fibre direction on the torus and an OBJ), TEXCOORD_0 and a glTF material. A `gltf` fit
(without the fuzz layer, which glTF cannot carry) is written exactly: base colour, metallic,
roughness, KHR_materials_anisotropy (across the fibres), _specular, _ior and _sheen as fitted,
its kd and fibre-direction maps as textures; its error against the data is printed and stated
in the material's extras. Any other fit's result carries the gltf material fitted to the same
data (renderer_materials): that is written exactly, with its own error against the data. A
parameter file, a per-texel fit or an older result gets a glTF material converted from the
model: base colour, roughness, KHR_materials_anisotropy and KHR_materials_ior (and _sheen where
it helps), fitted over 1500 direction pairs; the extras label it a conversion with its error
against the model. A `fit --maps` result's maps (the directory its
`maps.directory` names) become PNG textures in the GLB: base colour (sRGB, from kd/ks/height),
metallic-roughness (from height) and the anisotropy texture (fibre direction from the azimuth
map, strength from height).
BLENDER: a Python script that makes (or rebuilds in place) a material with a Principled BSDF
carrying a `principled` fit's values exactly (the rung is that node as Cycles evaluates it;
python/tests/test_blender.py renders it in Cycles), a Tangent node (UV Map) and Anisotropic
Rotation so the fibres lie at fibre_azimuth_deg from the UV u axis; run it in Blender or exec it
with the bpy module (fibrefit.blender.material in Python). Any other fit's result carries the
principled material fitted to the same data, which is written; parameter files are refused: fit with
--model principled. docs/guide/blender.md.
MATERIALX: a MaterialX 1.39 document with an OpenPBR Surface (open_pbr_surface) carrying an
`openpbr` fit's values exactly (the rung is that node as MaterialX implements it; every input
the fit's subset fixes is written too), its tangent the geometry's UV tangent turned about the
normal so the fibres lie at fibre_azimuth_deg from u. Validated by the materialx package and
its generated GLSL compiled in the tests (python/tests/test_materialx.py).
USD: a USD stage (.usda) with that material: its MaterialX render context (outputs:mtlx:surface)
is the same OpenPBR network as UsdShade shaders, its universal surface a UsdPreviewSurface
fallback for viewers without MaterialX (not the fit: no fuzz, no anisotropy), and a swatch bound
to it. Any other fit's result carries the openpbr material fitted to the same data, which is
written; parameter files are refused: fit with --model openpbr. docs/guide/materialx.md.")]
pub struct ExportArgs {
    /// A fitted result (.json) or any parameter file `eval` accepts
    pub result: PathBuf,
    /// Model id [default: the file's `model`]
    #[arg(long, value_name = "ID")]
    pub model: Option<String>,
    /// Write the model as shader source in LANG: wgsl, glsl (4.50 core), glsl-es (3.00, WebGL2:
    /// three.js's ShaderMaterial; its #version and precision lines first), hlsl or msl (needs
    /// --out)
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
    /// Write a Blender script (.py) that makes a Principled BSDF material with a `principled`
    /// fit's values (run it in Blender, or exec it with the bpy module)
    #[arg(long, value_name = "FILE.py")]
    pub blender: Option<PathBuf>,
    /// Write a MaterialX document (.mtlx) with an OpenPBR Surface carrying an `openpbr` fit's
    /// values
    #[arg(long, value_name = "FILE.mtlx")]
    pub materialx: Option<PathBuf>,
    /// Write a USD stage (.usda) with that OpenPBR material (MaterialX render context) and a
    /// UsdPreviewSurface fallback, bound to a swatch
    #[arg(long, value_name = "FILE.usda")]
    pub usd: Option<PathBuf>,
    /// The material's name in Blender, MaterialX or USD [default: the result's file stem;
    /// MaterialX and USD turn other characters than letters, digits and _ into _]
    #[arg(long, value_name = "NAME")]
    pub name: Option<String>,
    /// No summary on stderr
    #[arg(long, short)]
    pub quiet: bool,
}

pub fn run(args: &ExportArgs) -> Result<()> {
    if args.shader.is_none()
        && args.gltf.is_none()
        && args.blender.is_none()
        && args.materialx.is_none()
        && args.usd.is_none()
    {
        bail!(
            "nothing to export: give --shader LANG --out FILE, --gltf FILE.glb, --blender FILE.py, \
             --materialx FILE.mtlx and/or --usd FILE.usda"
        );
    }
    if args.name.is_some() && args.blender.is_none() && args.materialx.is_none() && args.usd.is_none() {
        bail!("--name names the material of --blender, --materialx or --usd; none was given");
    }
    let openpbr_flag = match (&args.materialx, &args.usd) {
        (Some(_), Some(_)) => Some("--materialx/--usd"),
        (Some(_), None) => Some("--materialx"),
        (None, Some(_)) => Some("--usd"),
        (None, None) => None,
    };
    let lang: Option<Language> = args
        .shader
        .as_deref()
        .map(|s| s.parse().map_err(|e: String| anyhow!("--shader {e}")))
        .transpose()?;
    let req = ExportRequest {
        result: args.result.clone(),
        model: args.model.clone(),
        shader: lang,
        check: args.check,
        gltf: args.gltf.is_some(),
        object: args.object.clone(),
        blender: args
            .blender
            .as_ref()
            .map(|_| args.name.clone().unwrap_or_default()),
        openpbr: openpbr_flag.map(|f| (args.name.clone().unwrap_or_default(), f)),
        progress: crate::progress::Progress::new(args.quiet),
    };
    // every output reserved before the work (none an input or another output), written together
    let mut outs = Outputs::new(&export_api::inputs(&req));
    let shader_out = match &args.out {
        Some(out) => Some(outs.file(out, "--out")?),
        None => None,
    };
    let gltf_out = match &args.gltf {
        Some(g) => Some(outs.file(with_extension(g, "glb", "--gltf")?, "--gltf")?),
        None => None,
    };
    let blender_out = match &args.blender {
        Some(b) => Some(outs.file(with_extension(b, "py", "--blender")?, "--blender")?),
        None => None,
    };
    let materialx_out = match &args.materialx {
        Some(m) => Some(outs.file(with_extension(m, "mtlx", "--materialx")?, "--materialx")?),
        None => None,
    };
    let usd_out = match &args.usd {
        Some(u) => Some(outs.file(with_extension(u, "usda", "--usd")?, "--usd")?),
        None => None,
    };
    let ExportOutcome {
        model: id,
        shader: shader_text,
        glb,
        textures,
        blender,
        openpbr,
        ..
    } = export_api::export(&req)?;
    // write: every file staged, then committed together
    if let (Some(text), Some(id)) = (&shader_text, shader_out) {
        outs.put(id, text.as_bytes())?;
    }
    if let (Some((bytes, _)), Some(id)) = (&glb, gltf_out) {
        outs.put(id, bytes)?;
    }
    // a maps fit's textures beside each material file, named after it
    let (mut blender_textures, mut openpbr_textures) = (vec![], vec![]);
    if let (Some((m, _, _)), Some(id), Some(path)) = (&blender, blender_out, &args.blender) {
        export_api::stage_blender(&mut outs, id, m, (path, "--blender"), &mut blender_textures)?;
    }
    if let (Some((m, _)), Some(id), Some(path)) = (&openpbr, materialx_out, &args.materialx) {
        let to = (path.as_path(), "--materialx", false);
        export_api::stage_openpbr(&mut outs, id, m, to, &mut openpbr_textures)?;
    }
    if let (Some((m, _)), Some(id), Some(path)) = (&openpbr, usd_out, &args.usd) {
        let to = (path.as_path(), "--usd", true);
        export_api::stage_openpbr(&mut outs, id, m, to, &mut openpbr_textures)?;
    }
    outs.commit()?;
    if !args.quiet {
        if let (Some((m, _, error)), Some(path)) = (&blender, &args.blender) {
            eprintln!(
                "wrote {} (Blender material `{}`: the principled fit written exactly, a Principled BSDF; fibres at {:.1} deg from the UV u axis)",
                path.display(),
                m.name,
                m.fibre_azimuth_deg
            );
            eprintln!("  error against the data: {}", error.text());
            textures_said(&blender_textures);
        }
        if let Some((m, error)) = &openpbr {
            if let Some(path) = &args.materialx {
                eprintln!(
                    "wrote {} (MaterialX material `{}`: the openpbr fit written exactly, an OpenPBR Surface; fibres at {:.1} deg from the UV u axis)",
                    path.display(),
                    m.name,
                    m.fibre_azimuth_deg
                );
            }
            if let Some(path) = &args.usd {
                eprintln!(
                    "wrote {} (USD material `{}`: the openpbr fit as its MaterialX surface; a UsdPreviewSurface fallback, roughness {:.3}, without the fuzz and the anisotropy; a swatch bound to it)",
                    path.display(),
                    m.name,
                    m.preview_roughness()
                );
            }
            eprintln!("  error against the data: {}", error.text());
            textures_said(&openpbr_textures);
        }
        for line in summary(args, lang, id, &glb, &textures) {
            eprintln!("{line}");
        }
    }
    Ok(())
}

/// `path` when it ends in `.ext` (any case); else the error naming `flag`.
fn with_extension<'a>(path: &'a std::path::Path, ext: &str, flag: &str) -> Result<&'a std::path::Path> {
    let given = path.extension().and_then(|e| e.to_str());
    if !given.is_some_and(|e| e.eq_ignore_ascii_case(ext)) {
        bail!("{flag} {}: expected a .{ext} file name", path.display());
    }
    Ok(path)
}

/// What was written, one line each, for stderr: the shader, the GLB's material (the fit itself
/// or a conversion, with its errors), its textures, and a warning for a poor conversion.
fn summary(
    args: &ExportArgs,
    lang: Option<Language>,
    id: crate::model::ModelId,
    glb: &Option<(Vec<u8>, GltfRoute)>,
    textures: &Option<export_api::GlbTextures>,
) -> Vec<String> {
    let mut lines = Vec::new();
    if let (Some(lang), Some(path)) = (lang, &args.out) {
        lines.push(format!(
            "wrote {} ({} shader of model `{id}`)",
            path.display(),
            lang.as_str()
        ));
    }
    let (Some((_, route)), Some(path)) = (glb, &args.gltf) else {
        return lines;
    };
    let (fitted, why, source_error) = match route {
        GltfRoute::Fitted { values, error, .. } => {
            lines.push(format!("wrote {} ({}: {})", path.display(), args.object, fitted_text(values)));
            lines.push(format!("  error against the data: {}", error.text()));
            return with_textures(lines, textures);
        }
        GltfRoute::Converted { material, why, source_error } => (material, why, source_error),
    };
    lines.push(format!(
        "wrote {} ({}: {})",
        path.display(),
        args.object,
        converted_text(id, fitted)
    ));
    if why.is_some() {
        lines.push("  (converted: see the warning above)".to_string());
    }
    if source_error.is_known() {
        lines.push(format!(
            "  the `{id}` fit's own error against the data: {}",
            source_error.text()
        ));
    }
    let mut lines = with_textures(lines, textures);
    if fitted.relative_rms_error > 0.25 {
        lines.push(format!(
            "warning: the glTF material matches the fibre model only to {:.0} % RMS: a preview for engines without custom shaders, not the model (use --shader for that)",
            100.0 * fitted.relative_rms_error
        ));
    }
    lines
}

fn fitted_text(values: &crate::export::gltf_out::RungValues) -> String {
    let g = &values.shape;
    format!(
        "the gltf fit written exactly: base colour {:.3?}, metallic {:.3}, roughness {:.3}, \
         anisotropy strength {:.3} rotation {:.1} deg, specular {:.3}, ior {:.3}, {}",
        values.base_color,
        g.metallic,
        g.roughness,
        g.anisotropy,
        values.anisotropy_rotation.to_degrees(),
        g.specular,
        g.ior,
        if g.sheen > 0.0 {
            format!("sheen colour {:.3} roughness {:.3}", g.sheen, g.sheen_roughness)
        } else {
            "no sheen".to_string()
        }
    )
}

fn converted_text(id: crate::model::ModelId, fitted: &crate::fit::gltf_material::FittedMaterial) -> String {
    let m = &fitted.material;
    format!(
        "a glTF material converted from the `{id}` model: base colour {:.3?}, roughness {:.3}, anisotropy strength {:.2} rotation {:.0} deg, ior {:.2}, {}; \
         relative RMS error of f cos against the model {:.1} % over {} direction pairs; without anisotropy {:.1} %, with sheen {:.1} %, without {:.1} %",
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
    )
}

/// The textures line, where the GLB carries the maps.
fn with_textures(mut lines: Vec<String>, textures: &Option<export_api::GlbTextures>) -> Vec<String> {
    let Some(t) = textures else {
        return lines;
    };
    let heights = if t.height_nodes.is_empty() {
        String::new()
    } else {
        let (lo, hi) = t
            .height_nodes
            .iter()
            .fold((1.0f64, 0.0f64), |(lo, hi), n| (lo.min(n.roughness), hi.max(n.roughness)));
        format!(
            "; roughness {lo:.3}-{hi:.3} over heights {:.2}-{:.2} ({} nodes)",
            t.height_nodes[0].height,
            t.height_nodes[t.height_nodes.len() - 1].height,
            t.height_nodes.len()
        )
    };
    lines.push(format!(
        "  textures from the maps in {} ({}x{}): {}{heights}",
        t.directory.display(),
        t.width,
        t.height,
        t.names.join(", ")
    ));
    lines
}

/// The textures an export wrote, a line each.
fn textures_said(written: &[(PathBuf, &'static str)]) {
    for (file, input) in written {
        eprintln!("  wrote {} ({input} per texel)", file.display());
    }
}
