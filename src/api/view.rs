//! `view`: the viewer page of a fitted result (built by the export stage's `view`): the exact
//! model through its exported shader beside the glTF route's material, the measured against the
//! fitted BRDF, the parameter table. [`prepare`] loads the result (and the data it names) and
//! builds the page in memory, [`write()`] writes it; `fit --report` builds the same page from the
//! fit in memory ([`fit_page`]).

use crate::export::shader::{self, Language};
use crate::export::view::{self, compare, ViewContent, ViewMesh};
use crate::fit::gltf_material;
use crate::load::samples::Samples;
use crate::model::frame::{direction_from_angles, FibreFrame, Vec3};
use crate::model::params::GltfShape;
use crate::model::rungs::gltf::GltfVariant;
use crate::model::{self, Albedos, BrdfFn, DirectionPair, ModelId, ModelParams};
use crate::render::preview_mesh;
use anyhow::{anyhow, Context, Result};
use serde_json::{json, Value};
use std::path::{Path, PathBuf};

/// A page to build.
#[derive(Clone, Debug)]
pub struct ViewRequest {
    /// A fitted result (.json) or a parameter file.
    pub result: PathBuf,
    /// The measurements to compare with [default: the data file the result names, beside it].
    pub data: Option<PathBuf>,
    /// Where notes and warnings go.
    pub progress: crate::progress::Progress,
}

/// A built page and the files it read.
pub struct ViewPage {
    /// The HTML, self-contained.
    pub html: String,
    /// Every file read (none may be the output).
    pub inputs: Vec<PathBuf>,
    /// Whether the measured-against-fitted picture is in it, and why not.
    pub comparison: (bool, String),
}

/// The default light of `render` (and the page's), THETA,PHI degrees.
pub const LIGHT_DEG: (f64, f64) = (40.0, 120.0);
/// The default camera of `render` (and the page's), THETA,PHI degrees.
pub const CAMERA_DEG: (f64, f64) = (50.0, 270.0);

/// Load what `req` names and build the page.
pub fn prepare(req: &ViewRequest) -> Result<ViewPage> {
    let (raw, id, params) = crate::api::eval::load_params(&req.result, None, &req.progress)?;
    let mut inputs = vec![req.result.clone()];
    inputs.extend(raw.topology_map.iter().cloned());
    let text = crate::load::input::read_text(&req.result)?;
    let result: Value = serde_json::from_str(&text).unwrap_or(Value::Null);
    let (samples, why_not) = match data_of(req, &result)? {
        DataFound::Loaded(path, samples) => {
            inputs.push(path);
            (Some(samples), None)
        }
        DataFound::Not(why) => (None, Some(why)),
    };
    let title = req.result.file_name().map_or_else(
        || req.result.display().to_string(),
        |n| n.to_string_lossy().into_owned(),
    );
    let content = content(&title, &result, id, &params, samples.as_ref(), why_not)?;
    let comparison = (
        content.comparison.available,
        content.comparison.note.clone(),
    );
    Ok(ViewPage {
        html: view::page(&content)?,
        inputs,
        comparison,
    })
}

/// Build the page of `req` and write it to `out` (atomically), never onto a file it was built
/// from: `out` is checked against the result and `--data` before the work (and its folder for
/// being writable), and against every file read after it. Nothing is written on an error.
pub fn write(req: &ViewRequest, out: &Path) -> Result<ViewPage> {
    let mut first = vec![req.result.clone()];
    first.extend(req.data.iter().cloned());
    // a first check before the work (given up: it writes nothing)
    crate::export::atomic::Outputs::new(&first).file(out, "--out")?;
    let page = prepare(req)?;
    let mut outs = crate::export::atomic::Outputs::new(&page.inputs);
    let id = outs.file(out, "--out")?;
    outs.put(id, page.html.as_bytes())?;
    outs.commit()?;
    Ok(page)
}

/// The page of a fit in memory (`fit --report`): its result (as it will be written) and the
/// samples it fitted.
pub fn fit_page(
    result: &crate::export::result_json::ResultFile,
    samples: &Samples,
) -> Result<String> {
    let v = serde_json::to_value(result)?;
    let raw = crate::export::result_json::params_of_result(&v)?;
    let (id, params, _) = crate::export::result_json::checked_params(&raw, None, "the fit")?;
    let title = format!("{} fit of {}", result.model, result.data.file);
    view::page(&content(&title, &v, id, &params, Some(samples), None)?)
}

/// The data to compare with, or why there are none.
enum DataFound {
    Loaded(PathBuf, Samples),
    Not(String),
}

/// The data `req` names (an error when it does not load), or the file the result names beside
/// it (a note when it is missing, does not load or is not the file fitted).
fn data_of(req: &ViewRequest, result: &Value) -> Result<DataFound> {
    if let Some(path) = &req.data {
        let samples = crate::load::load_data(path, &Default::default())
            .with_context(|| format!("--data {}", path.display()))?;
        return Ok(DataFound::Loaded(path.clone(), samples));
    }
    let Some(name) = result["data"]["file"].as_str().filter(|s| !s.is_empty()) else {
        return Ok(DataFound::Not(
            "no data: the file is a parameter file, not a fitted result".into(),
        ));
    };
    let folder = req.result.parent().unwrap_or(Path::new(""));
    let path = folder.join(name);
    if crate::load::is_capture(&path) {
        return Ok(DataFound::Not(format!(
            "{name} is an image capture: one light and one view per image, too few directions for this picture"
        )));
    }
    if !path.is_file() {
        return Ok(DataFound::Not(format!(
            "the data file the result names, {name}, is not beside it ({}); give it with --data",
            path.display()
        )));
    }
    let samples = match crate::load::load_data(&path, &Default::default()) {
        Ok(s) => s,
        Err(e) => return Ok(DataFound::Not(format!("{}: {e:#}", path.display()))),
    };
    let fitted = result["data"]["sha256"].as_str();
    let read = crate::load::sha256_read(&path);
    if let (Some(f), Some(r)) = (fitted, read.as_deref()) {
        if f != r {
            return Ok(DataFound::Not(format!(
                "{} is not the file fitted (sha256 {r}, the result's {f}); give the data with --data",
                path.display()
            )));
        }
    }
    Ok(DataFound::Loaded(path, samples))
}

/// Everything the page shows, for the result `result` (its JSON; null for a parameter file) of
/// rung `id` with parameters `params`, compared with `samples` (or `why_not`).
fn content(
    title: &str,
    result: &Value,
    id: ModelId,
    params: &ModelParams,
    samples: Option<&Samples>,
    why_not: Option<String>,
) -> Result<ViewContent> {
    let lines = vec![format!("{title} (fibrefit view)")];
    let exact_glsl = shader::translate(&shader::wgsl(id, params, &lines)?, Language::Glsl)
        .map_err(|e| anyhow!("the exact model's shader: {e:#}"))?;
    let (gltf_params, gltf_route) = gltf_route(id, params, result)?;
    let gltf_glsl = shader::translate(
        &shader::wgsl(ModelId::Gltf, &gltf_params, &lines)?,
        Language::Glsl,
    )?;
    let brdf = model_brdf(id, params)?;
    let comparison = match (samples, why_not) {
        (Some(s), _) => compare::compare(s, brdf.as_ref()),
        (None, why) => compare::Comparison::none(why.unwrap_or_else(|| "no data".into())),
    };
    let mut notes = Vec::new();
    if let Some(map) = &params.topology.map {
        notes.push(format!(
            "the topology map {} is not applied per texel here: the objects show its height distribution (the shader's baked histogram); `fibrefit render` applies it over the swatch",
            map.source.display()
        ));
    }
    if result["maps"].is_object() {
        notes.push("the result's per-texel maps (fit --maps) are not applied here: the objects show the global fit".into());
    }
    Ok(ViewContent {
        title: title.to_string(),
        model: id.as_str().to_string(),
        fibre_azimuth_deg: params.fibre_azimuth.to_degrees(),
        exact_glsl,
        gltf_glsl,
        gltf_route,
        meshes: meshes(id, params)?,
        result: view::result_summary(result),
        comparison,
        exposure: default_exposure(brdf.as_ref()),
        notes,
    })
}

/// The rung's BRDF per channel at swatch-frame directions (the fibres at the fitted azimuth),
/// times its smooth correction where the result keeps one, as `eval` computes it.
fn model_brdf(id: ModelId, params: &ModelParams) -> Result<BrdfFn> {
    let m = model::build(id, params)?;
    let albedos = params.albedos;
    let channels = albedos.channels();
    let frame = FibreFrame::from_azimuth(params.fibre_azimuth);
    let correction = params.correction.clone();
    Ok(Box::new(move |l: &Vec3, v: &Vec3| {
        let pair = DirectionPair::new(&frame, l, v);
        let b = m.basis(&pair);
        let f = correction.as_ref().map_or([1.0; 3], |k| k.factor(&pair));
        let mut out = [0.0; 3];
        for (c, o) in out.iter_mut().enumerate() {
            *o = b.brdf(&albedos, c.min(channels - 1)) * f[c.min(channels - 1)];
        }
        Some(out)
    }))
}

/// The exposure the page opens with: the swatch under `render`'s default light and camera
/// (with its fill light) at 0.8.
fn default_exposure(brdf: view::Brdf) -> f64 {
    let rad = |(t, p): (f64, f64)| direction_from_angles(t.to_radians(), p.to_radians());
    let (l, v) = (rad(LIGHT_DEG), rad(CAMERA_DEG));
    let f = |a: &Vec3| brdf(a, &v).map_or(0.0, |f| f.iter().copied().fold(0.0, f64::max));
    let radiance = f(&l) * l.z + crate::render::DEFAULT_FILL * f(&v) * v.z;
    if radiance.is_finite() && radiance > 0.0 {
        0.8 / radiance
    } else {
        1.0
    }
}

/// The objects: swatch, sphere, torus and cloth (each the export's preview mesh, coarser), the
/// torus with its climbing fibres' heights for rungs with a topology (as `render` has them).
fn meshes(id: ModelId, params: &ModelParams) -> Result<Vec<ViewMesh>> {
    let psi = params.fibre_azimuth.to_degrees();
    let (nu, nv) = (48, 24);
    let torus = preview_mesh::torus_grid(nu, nv)?;
    let heights = id.has_topology().then(|| {
        (0..torus.mesh.positions.len())
            .map(|k| {
                let b = ((k / (nu + 1)) as f64 / nv as f64 - 0.5) * std::f64::consts::TAU;
                crate::render::objects::torus_height(b, params.spacing)
            })
            .collect()
    });
    use crate::render::objects::{TORUS_MAJOR, TORUS_TUBE};
    Ok(vec![
        ViewMesh {
            name: "swatch",
            label: format!("swatch: the square [-1, 1]^2, normal +z, fibres at {psi:.1} deg from x (as render's)"),
            mesh: preview_mesh::swatch(psi)?,
            heights: None,
            bound: std::f64::consts::SQRT_2,
        },
        ViewMesh {
            name: "sphere",
            label: "sphere: fibres along the circles of latitude, turned by fibre_azimuth_deg towards the meridians (as render's)".into(),
            mesh: preview_mesh::sphere_grid(psi, 36, 18)?,
            heights: None,
            bound: 1.0,
        },
        ViewMesh {
            name: "torus",
            label: format!(
                "torus: fibres wound round the tube{} (as render's)",
                if heights.is_some() { ", climbing from the outer to the inner side" } else { "" }
            ),
            mesh: torus,
            heights,
            bound: TORUS_MAJOR + TORUS_TUBE,
        },
        ViewMesh {
            name: "cloth",
            label: format!("cloth draped over a dome, fibres along its warp at {psi:.1} deg from x, two-sided"),
            mesh: preview_mesh::cloth(psi, 32, 32)?,
            heights: None,
            bound: 1.75,
        },
    ])
}

/// The glTF route's material as `gltf` rung parameters, and what it is: a `gltf` fit's own
/// values (no fuzz layer), the `gltf` material the result's fit recorded (fitted to the same
/// data, as `export --gltf` writes it: its fibres turned from the result's by the difference of
/// their azimuths), or for a parameter file the material `export --gltf` fits to the model (metallic 0,
/// specular factor 1; its anisotropy direction at its fitted rotation from the fibres, where
/// the rung has it at 90 deg: the page turns the rung's fibre tangent by the difference).
fn gltf_route(id: ModelId, params: &ModelParams, result: &Value) -> Result<(ModelParams, Value)> {
    let why = crate::api::export::not_pure_gltf(id, params);
    let recorded = match id == ModelId::Gltf && why.is_none() {
        true => None,
        false => crate::api::export::recorded_material(
            result,
            crate::model::Ability::GltfMaterial,
            "the result",
        )?
        .filter(|r| crate::api::export::not_pure_gltf(r.id, &r.params).is_none()),
    };
    if let Some(r) = recorded {
        let route = json!({
            "kind": "recorded",
            "text": format!(
                "the glTF material the {id} fit recorded, fitted to the same data (not to the model), as `export --gltf` writes it: {}",
                r.error.text()
            ),
            "values": gltf_values(r.params.albedos.diffuse, &r.params.gltf),
            "error_against_data": r.error.json(),
            "azimuth_offset_rad": r.params.fibre_azimuth - params.fibre_azimuth,
        });
        let mut p = r.params;
        // drawn in the result's fibre frame, turned by the offset
        p.fibre_azimuth = params.fibre_azimuth;
        return Ok((p, route));
    }
    if id == ModelId::Gltf && why.is_none() {
        let g = params.gltf;
        let route = json!({
            "kind": "fitted",
            "text": "the result is a gltf fit: the GLB carries its own values exactly, so both sides show the same material (the gltf rung's shader)",
            "values": gltf_values(params.albedos.diffuse, &g),
            "azimuth_offset_rad": 0.0,
        });
        return Ok((params.clone(), route));
    }
    let model = model::build(id, params)?;
    let fitted = gltf_material::fit(model.as_ref(), &params.albedos, 1)?;
    let m = &fitted.material;
    let g = GltfShape {
        metallic: 0.0,
        roughness: m.roughness,
        anisotropy: m.anisotropy_strength,
        specular: 1.0,
        ior: m.ior,
        sheen: m.sheen.map_or(0.0, |s| s.colour),
        sheen_roughness: m.sheen.map_or(0.5, |s| s.roughness),
        // `export --gltf` fits the spec's material (what a GLB means), not three.js's
        variant: GltfVariant::Khronos,
    };
    let mut p = params.clone();
    p.gltf = g;
    p.albedos = Albedos {
        diffuse: m.base_color,
        specular: [1.0; 3],
        substrate: [0.0; 3],
        fuzz: [0.0; 3],
        rgb: params.albedos.rgb,
    };
    // the gltf rung has no Fresnel factor, spread or fuzz layer of its own
    p.fresnel_ior = 0.0;
    p.azimuth_spread_deg = 0.0;
    p.fuzz_depth = 0.0;
    let route = json!({
        "kind": "converted",
        "text": format!(
            "a glTF material fitted to the {id} model (not to the data), as `export --gltf` writes it: relative RMS error {:.1} % against the model over {} direction pairs ({:.1} % without anisotropy); drawn through the gltf rung's shader with metallic 0, specular factor 1 and its anisotropy direction at {:.1} deg from the fibres (the rung's is at 90 deg: its fibre tangent is turned by the difference)",
            100.0 * fitted.relative_rms_error,
            fitted.directions,
            100.0 * fitted.isotropic_relative_rms_error,
            m.anisotropy_rotation.to_degrees()
        ),
        "why_converted": why,
        "values": gltf_values(m.base_color, &g),
        "relative_rms_error_against_model": fitted.relative_rms_error,
        "anisotropy_rotation_from_fibres_deg": m.anisotropy_rotation.to_degrees(),
        "azimuth_offset_rad": m.anisotropy_rotation - std::f64::consts::FRAC_PI_2,
    });
    Ok((p, route))
}

fn gltf_values(base: [f64; 3], g: &GltfShape) -> Value {
    json!({
        "baseColorFactor": base,
        "metallicFactor": g.metallic,
        "roughnessFactor": g.roughness,
        "anisotropyStrength": g.anisotropy,
        "specularFactor": g.specular,
        "ior": g.ior,
        "sheenColorFactor": g.sheen,
        "sheenRoughnessFactor": g.sheen_roughness,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The converted glTF material drawn as the `gltf` rung with its fibre tangent turned by
    /// `azimuth_offset_rad` is the material `export --gltf` fits (its own BRDF, no sheen here).
    #[test]
    fn the_converted_material_is_the_gltf_rung_turned_by_the_offset() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("pf.toml");
        std::fs::write(
            &path,
            "model = \"poulin-fournier\"\nkd = [0.55, 0.35, 0.30]\nks = 0.25\nexponent = 60\nspacing = 2.0\nfibre_azimuth_deg = 20\n",
        )
        .unwrap();
        let raw = crate::export::result_json::read_params(&path).unwrap();
        let (id, params, _) =
            crate::export::result_json::checked_params(&raw, None, "pf.toml").unwrap();
        let (p, route) = gltf_route(id, &params, &Value::Null).unwrap();
        assert_eq!(route["kind"], "converted");
        let offset = route["azimuth_offset_rad"].as_f64().unwrap();
        let fitted = gltf_material::fit(
            model::build(id, &params).unwrap().as_ref(),
            &params.albedos,
            1,
        )
        .unwrap();
        assert!(
            fitted.material.sheen.is_none(),
            "this material has no sheen"
        );
        let rung = model::build(ModelId::Gltf, &p).unwrap();
        let (psi, turned) = (
            FibreFrame::from_azimuth(params.fibre_azimuth),
            FibreFrame::from_azimuth(params.fibre_azimuth + offset),
        );
        let mut worst: f64 = 0.0;
        for (ti, pi, to, po) in [
            (30.0, 10.0, 40.0, 200.0),
            (60.0, 100.0, 20.0, 300.0),
            (10.0, 250.0, 70.0, 80.0),
        ] {
            let d = |t: f64, p: f64| direction_from_angles(f64::to_radians(t), f64::to_radians(p));
            let (l, v) = (d(ti, pi), d(to, po));
            let want = gltf_material::pbr_brdf(&fitted.material, &DirectionPair::new(&psi, &l, &v));
            let b = rung.basis(&DirectionPair::new(&turned, &l, &v));
            for c in 0..3 {
                let got = b.brdf(&p.albedos, c);
                worst = worst.max((got - want[c]).abs() / want[c]);
            }
        }
        assert!(worst < 1e-9, "worst relative difference {worst}");
    }
}
