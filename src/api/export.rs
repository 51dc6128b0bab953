//! `export`: the fitted model as shader code a renderer runs (checked on the GPU driver against
//! the Rust model when asked) and as a glTF material on a preview mesh (a `fit --maps` result's
//! maps as its textures), built in memory; the caller writes them into its reserved outputs.

use crate::export::blender_out::BlenderMaterial;
use crate::export::gltf_out::{self, VertexFrames};
pub use crate::export::material_textures::{MapTexture, MaterialTextures};
pub use crate::export::materialx_out::{OpenPbrMaterial, Value as OpenPbrValue};
use crate::export::shader::{self, check, gpu::Gpu, Language};
use crate::fit::gltf_material::{self, FittedMaterial};
use crate::load::mesh;
use crate::load::texel_maps::TexelMapsIn;
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
    /// A Blender script making a Principled BSDF material of a `principled` fit, named this
    /// (None: no script; an empty name: the result's file stem).
    pub blender: Option<String>,
    /// An OpenPBR Surface material of an `openpbr` fit (MaterialX document, USD stage): its
    /// name (empty: the result's file stem) and the flag asking for it, as errors name it
    /// (None: none).
    pub openpbr: Option<(String, &'static str)>,
    /// Where notes, the check's figures and warnings go.
    pub progress: crate::progress::Progress,
}

/// The exported files, in memory.
pub struct ExportOutcome {
    /// The rung of the result exported.
    pub model: ModelId,
    /// The shader source, in the language asked for.
    pub shader: Option<String>,
    /// The GLB preview's bytes and the glTF material it carries.
    pub glb: Option<(Vec<u8>, GltfRoute)>,
    /// The per-texel maps the GLB carries as textures (a `fit --maps` result).
    pub textures: Option<GlbTextures>,
    /// The Blender material and its script, with the fit's error against its data.
    pub blender: Option<(BlenderMaterial, String, DataError)>,
    /// The OpenPBR material (its MaterialX document and USD stage come from it), with the
    /// fit's error against its data.
    pub openpbr: Option<(OpenPbrMaterial, DataError)>,
    /// The result's values its data did not determine (at a bound, held, flat cost): the
    /// exports use them as given and say so (a warning, the shader's header, the GLB
    /// material's `extras.fibrefit.undetermined`).
    pub undetermined: Vec<crate::api::Undetermined>,
}

/// The glTF material a GLB carries, and how it was made.
#[derive(Clone, Debug)]
pub enum GltfRoute {
    /// A `gltf` fit (no fuzz layer), or the `gltf` material another rung's fit recorded
    /// (fitted to the same data): its own values, written exactly.
    Fitted {
        /// The values written.
        values: gltf_out::RungValues,
        /// The fit's error against its data, as the result states it.
        error: DataError,
        /// The rung of the fit that recorded the material (None: the result is the gltf fit).
        recorded_by: Option<ModelId>,
    },
    /// A glTF material fitted to the result's model (another rung, or a `gltf` fit with a
    /// component glTF cannot carry): its error is against the model, not the data.
    Converted {
        /// The material fitted to the model, with its errors against the model.
        material: FittedMaterial,
        /// Why a `gltf` result was converted rather than written (None for other rungs).
        why: Option<String>,
        /// The converted fit's own error against its data, as the result states it.
        source_error: DataError,
    },
}

/// A fit's error against its data, as its result file states it (none for a parameter file).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct DataError {
    /// The data file the fit read.
    pub data: Option<String>,
    /// Samples fitted.
    pub samples: Option<usize>,
    /// RMS of model - data over every sample and channel, 1/sr (`statistics.rmse`).
    pub rmse: Option<f64>,
    /// `rmse` over the RMS of the data (`statistics.relative_rmse`): in-sample.
    pub relative_rmse: Option<f64>,
    /// Held-out error: RMS in the fit's metric of `--model auto`'s chosen candidate
    /// (`model_selection`), or the floor check's (`quality.floor`) where the result has one.
    pub heldout_error: Option<f64>,
    /// The metric of `heldout_error`.
    pub heldout_metric: Option<String>,
    /// The chosen candidate's relative RMSE on its held-out samples.
    pub heldout_relative_rmse: Option<f64>,
    /// The chosen candidate's log error on its held-out samples.
    pub heldout_log_error: Option<f64>,
    /// The floor (what the data allow), where the result measured it (`quality.floor`).
    pub floor: Option<f64>,
    /// `heldout_error` / `floor`.
    pub floor_ratio: Option<f64>,
}

impl DataError {
    /// The errors `result` (a fitted result's JSON) states; all none for anything else.
    pub fn of_result(result: &Path) -> Self {
        match crate::load::input::read_text(result)
            .ok()
            .and_then(|t| serde_json::from_str::<serde_json::Value>(&t).ok())
        {
            Some(v) => Self::of_value(&v),
            None => Self::default(),
        }
    }

    /// The errors a result's JSON `v` states (a result, or one of its `renderer_materials`,
    /// whose `heldout` holds its candidate's held-out errors).
    pub fn of_value(v: &serde_json::Value) -> Self {
        let num = |x: &serde_json::Value| x.as_f64().filter(|f| f.is_finite());
        let stats = &v["statistics"];
        let mut e = Self {
            data: v["data"]["file"].as_str().map(str::to_string),
            samples: v["data"]["samples"].as_u64().map(|n| n as usize),
            rmse: num(&stats["rmse"]),
            relative_rmse: num(&stats["relative_rmse"]),
            ..Self::default()
        };
        let chosen = v["model_selection"]
            .as_array()
            .and_then(|c| c.iter().find(|c| c["chosen"].as_bool() == Some(true)));
        if let Some(c) = chosen {
            e.heldout_error = num(&c["cv_error"]);
            e.heldout_metric = v["selection"]["metric"].as_str().map(str::to_string);
            e.heldout_relative_rmse = num(&c["heldout_relative_rmse"]);
            e.heldout_log_error = num(&c["heldout_log_error"]);
        }
        let heldout = &v["heldout"];
        if let Some(h) = num(&heldout["cv_error"]) {
            e.heldout_error = Some(h);
            e.heldout_metric = heldout["metric"].as_str().map(str::to_string);
            e.heldout_relative_rmse = num(&heldout["heldout_relative_rmse"]);
            e.heldout_log_error = num(&heldout["heldout_log_error"]);
        }
        let floor = &v["quality"]["floor"];
        if let Some(h) = num(&floor["heldout_error"]) {
            e.heldout_error = Some(h);
            e.heldout_metric = floor["metric"]
                .as_str()
                .or(v["knobs"]["metric"].as_str())
                .map(str::to_string);
            e.floor = num(&floor["floor"]);
            e.floor_ratio = num(&floor["ratio"]);
        }
        e
    }

    /// Whether the result states any error against data.
    pub fn is_known(&self) -> bool {
        self.relative_rmse.is_some() || self.heldout_error.is_some()
    }

    /// In words, for stderr: "relative RMS error 8.1 % over 3000 samples of silk.csv; held-out
    /// error 0.135 (log)".
    pub fn text(&self) -> String {
        if !self.is_known() {
            return "no error against data: the file is a parameter file, not a fit".into();
        }
        let mut parts = Vec::new();
        if let Some(r) = self.relative_rmse {
            parts.push(format!(
                "relative RMS error {:.1} % over {} samples{} (in-sample)",
                100.0 * r,
                self.samples.map_or("its".into(), |n| n.to_string()),
                self.data
                    .as_ref()
                    .map_or(String::new(), |d| format!(" of {d}"))
            ));
        }
        if let Some(h) = self.heldout_error {
            let mut t = format!(
                "held-out error {h:.3}{}",
                self.heldout_metric
                    .as_ref()
                    .map_or(String::new(), |m| format!(" ({m} metric)"))
            );
            if let Some(r) = self.heldout_relative_rmse {
                t += &format!(", held-out relative RMS {:.1} %", 100.0 * r);
            }
            if let (Some(f), Some(q)) = (self.floor, self.floor_ratio) {
                t += &format!(", {q:.2}x the floor {f:.3}");
            }
            parts.push(t);
        }
        parts.join("; ")
    }

    /// As the GLB's extras state it.
    pub fn json(&self) -> serde_json::Value {
        serde_json::json!({
            "data": self.data,
            "samples": self.samples,
            "rms_error_per_sr": self.rmse,
            "relative_rms_error": self.relative_rmse,
            "relative_rms_error_is": "in-sample: over every sample fitted, against the data (the result's statistics.relative_rmse)",
            "heldout_error": self.heldout_error,
            "heldout_metric": self.heldout_metric,
            "heldout_relative_rms_error": self.heldout_relative_rmse,
            "heldout_log_error": self.heldout_log_error,
            "floor": self.floor,
            "floor_ratio": self.floor_ratio,
            "text": self.text(),
        })
    }
}

/// What the GLB's textures were made from.
#[derive(Clone, Debug)]
pub struct GlbTextures {
    /// The maps directory the result names.
    pub directory: PathBuf,
    /// Width of the textures, pixels (the maps' grid).
    pub width: usize,
    /// Height of the textures, pixels.
    pub height: usize,
    /// The textures, in the document's order: "base colour", "metallic-roughness",
    /// "anisotropy".
    pub names: Vec<&'static str>,
    /// The glTF shape refitted at the texels' heights (empty without a height map).
    pub height_nodes: Vec<gltf_material::HeightNode>,
}

use crate::load::texel_maps::MAP_FILES;

/// Stage the Blender script of `m` into `id` (reserved at `out`, a `.py`) with a maps fit's
/// textures beside it (reserved here, `flag` naming the option; each (path, input) joins
/// `written`); returns the material as written (its textures named after `out`).
pub fn stage_blender(
    outs: &mut crate::export::atomic::Outputs,
    id: crate::export::atomic::OutputId,
    m: &BlenderMaterial,
    (out, flag): (&Path, &str),
    written: &mut Vec<(PathBuf, &'static str)>,
) -> Result<BlenderMaterial> {
    let m = m.clone().beside(out);
    m.textures.write_beside(outs, (out, flag), written)?;
    outs.put(id, m.script().as_bytes())?;
    Ok(m)
}

/// Stage the MaterialX document (`usd` false) or the USD stage (`usd` true) of `m` into `id`
/// (reserved at `out`) with a maps fit's textures beside it (reserved here, unless in
/// `written`: a document and a stage of one stem share them); returns the material as
/// written.
pub fn stage_openpbr(
    outs: &mut crate::export::atomic::Outputs,
    id: crate::export::atomic::OutputId,
    m: &OpenPbrMaterial,
    (out, flag, usd): (&Path, &str, bool),
    written: &mut Vec<(PathBuf, &'static str)>,
) -> Result<OpenPbrMaterial> {
    let m = m.clone().beside(out);
    m.textures.write_beside(outs, (out, flag), written)?;
    let text = if usd { m.usda() } else { m.document() };
    outs.put(id, text.as_bytes())?;
    Ok(m)
}

/// Every file an export reads (none may be an output).
pub fn inputs(req: &ExportRequest) -> Vec<PathBuf> {
    let mut inputs = vec![req.result.clone()];
    if req.object.to_ascii_lowercase().ends_with(".obj") {
        inputs.push(PathBuf::from(&req.object));
    }
    if req.gltf {
        // a failure to find them is reported by `export` itself
        if let Ok(Some(dir)) =
            crate::api::render::maps_dir(None, &req.result, &crate::progress::Progress::quiet())
        {
            inputs.extend(MAP_FILES.iter().map(|f| dir.join(f)));
        }
    }
    inputs
}

/// The maps directory a `fit --maps` result names (beside the result, never in the working
/// directory), with a warning when it names one that is not there.
fn maps_of(result: &Path, progress: &crate::progress::Progress) -> Result<Option<PathBuf>> {
    let found = crate::api::render::maps_dir(None, result, &crate::progress::Progress::quiet())?;
    if found.is_none() {
        if let Ok(Some((named, looked))) = crate::api::render::named_maps_dir(result) {
            progress.warn(&format!(
                "{}: the GLB carries no textures, only the global material",
                crate::api::render::missing_maps(result, &named, &looked)
            ));
        }
    }
    Ok(found)
}

/// Build what `req` asks for; a failure (a shader beyond its bound included) builds nothing.
pub fn export(req: &ExportRequest) -> Result<ExportOutcome> {
    let undetermined = crate::export::result_json::undetermined_of(&req.result);
    let (_, id, params) =
        crate::api::eval::load_params(&req.result, req.model.as_deref(), &req.progress)?;
    if let Some(map) = &params.topology.map {
        // loaded (so it exists); say which, since the export bakes its histogram in
        req.progress.say(&format!(
            "topology map {}: its {}-bin height histogram is baked in",
            map.source.display(),
            params.histogram_bins
        ));
    }
    let mut lines = provenance(&req.result, id, &params)?;
    // the values the data did not determine: used, but not as measurements
    lines.extend(undetermined.iter().map(|u| {
        format!(
            "UNDETERMINED: {}; used as given, not a measurement",
            crate::fit::determined::warning(u)
        )
    }));
    // a smooth correction on the rung: fibrefit applies it, the renderers' materials do not
    if let Some(k) = &params.correction {
        lines.push(format!(
            "CORRECTION: the result's smooth correction of the rung (degree {}, `correction`): \
             the shader's fibrefit_brdf includes it (fibrefit_correction); the glTF, Blender and \
             MaterialX/USD materials do not",
            k.degree
        ));
        let mut not_carried = Vec::new();
        if req.gltf {
            not_carried.push("--gltf");
        }
        if req.blender.is_some() {
            not_carried.push("--blender");
        }
        if let Some((_, flag)) = &req.openpbr {
            not_carried.push(*flag);
        }
        if !not_carried.is_empty() {
            req.progress.warn(&format!(
                "{}: the result's smooth correction of the rung (degree {}, `correction`) is not \
                 in {}: that renderer's material shows the rung alone (the shader export, eval, \
                 render, score and Material apply it; `correction.heldout` gives both errors)",
                req.result.display(),
                k.degree,
                not_carried.join(", ")
            ));
        }
    }
    // everything is built in memory first: a failure writes nothing
    let shader_text = match req.shader {
        Some(lang) => Some(shader_source(req, id, &params, lines.clone(), lang)?),
        None => None,
    };
    let (glb, textures) = match req.gltf {
        true => {
            let (glb, textures) = glb_preview(req, id, &params, &lines, &undetermined)?;
            (Some(glb), textures)
        }
        false => (None, None),
    };
    let blender = match &req.blender {
        Some(name) => {
            let (m, error) = blender_material(req, id, &params, name, &lines)?;
            let script = m.script();
            Some((m, script, error))
        }
        None => None,
    };
    let openpbr = match &req.openpbr {
        Some((name, flag)) => Some(openpbr_material(req, id, &params, (name, flag), &lines)?),
        None => None,
    };
    Ok(ExportOutcome {
        model: id,
        shader: shader_text,
        glb,
        textures,
        blender,
        openpbr,
        undetermined,
    })
}

/// Where a renderer's material comes from: the result itself (a fit of that renderer's rung), or
/// the renderer's own material its fit recorded, fitted to the same data (`renderer_materials`).
struct MaterialSource {
    id: ModelId,
    params: ModelParams,
    error: DataError,
    /// The rung of the result whose recorded material this is (None: the result itself).
    recorded_by: Option<ModelId>,
    /// Its values the data did not determine (a recorded material's own).
    undetermined: Vec<crate::fit::determined::Undetermined>,
}

/// The material of the rung with `ability` for the result `req.result` of rung `id`: the
/// result itself when it is that rung, else the one its fit recorded (`renderer_materials`),
/// else None (a parameter file, a per-texel fit, a result written before they were recorded).
fn material_source(
    req: &ExportRequest,
    id: ModelId,
    params: &ModelParams,
    ability: crate::model::Ability,
) -> Result<Option<MaterialSource>> {
    let own = id.has(ability).then(|| MaterialSource {
        id,
        params: params.clone(),
        error: DataError::of_result(&req.result),
        recorded_by: None,
        undetermined: crate::export::result_json::undetermined_of(&req.result),
    });
    // the result itself, unless it carries fibrefit's fuzz layer: then the plain material its
    // fit recorded, if any (else itself, which the caller refuses with the reason)
    if own.as_ref().is_some_and(|s| s.params.fuzz_depth == 0.0) {
        return Ok(own);
    }
    let recorded = match crate::load::input::read_text(&req.result)
        .ok()
        .and_then(|t| serde_json::from_str::<serde_json::Value>(&t).ok())
    {
        Some(v) => recorded_material(&v, ability, &req.result.display().to_string())?,
        None => None,
    };
    Ok(match recorded {
        Some(r) => Some(MaterialSource {
            id: r.id,
            params: r.params,
            error: r.error,
            recorded_by: Some(id),
            undetermined: r.undetermined,
        }),
        None => own,
    })
}

/// A renderer's own material a fit recorded (`renderer_materials`), checked.
pub struct RecordedMaterial {
    /// Its rung.
    pub id: ModelId,
    /// Its values.
    pub params: ModelParams,
    /// Its error against the data it was fitted to.
    pub error: DataError,
    /// Its values the data did not determine.
    pub undetermined: Vec<crate::fit::determined::Undetermined>,
}

/// The material of the rung with `ability` that the result `v` (its JSON, read from `file`)
/// recorded, fitted to the same data as the result's fit; None when it recorded none (a
/// parameter file, a per-texel fit, an older result, the fit being that material itself).
pub fn recorded_material(
    v: &serde_json::Value,
    ability: crate::model::Ability,
    file: &str,
) -> Result<Option<RecordedMaterial>> {
    let entry = v["renderer_materials"].as_array().and_then(|a| {
        a.iter().find(|e| {
            e["model"]
                .as_str()
                .and_then(|m| m.parse::<ModelId>().ok())
                .is_some_and(|m| m.has(ability))
        })
    });
    let Some(entry) = entry else {
        return Ok(None);
    };
    let label = format!("{file} (its renderer_materials)");
    let raw =
        crate::export::result_json::params_of_result(entry).map_err(|e| anyhow!("{label}: {e}"))?;
    let (id, params, _) = crate::export::result_json::checked_params(&raw, None, &label)?;
    let mut error = DataError::of_value(entry);
    error.data = error
        .data
        .or_else(|| v["data"]["file"].as_str().map(str::to_string));
    Ok(Some(RecordedMaterial {
        id,
        params,
        error,
        undetermined: crate::export::result_json::undetermined_in(entry),
    }))
}

/// A renderer's material of a result (its values exactly) of the rung with `ability`, for
/// export `flag`: the result itself, or the material its fit recorded, fitted to the same data
/// ([`material_source`]); anything else is refused (a parameter file of another rung: the
/// material would be a conversion, not a fit), as is a fit with fibrefit's fuzz layer (no
/// renderer has it). Returns the material's name (`name`, or the result's file stem when
/// empty), its header lines (`lines`, where it comes from, its error against the data) and its
/// source.
fn renderer_material(
    req: &ExportRequest,
    id: ModelId,
    params: &ModelParams,
    (flag, ability, rung): (&str, crate::model::Ability, &str),
    name: &str,
    lines: &[String],
) -> Result<(
    String,
    Vec<String>,
    MaterialSource,
    Option<(PathBuf, TexelMapsIn)>,
)> {
    let file = req.result.display();
    let target = ModelId::ALL
        .into_iter()
        .find(|m| m.has(ability))
        .and_then(|m| m.rung().renderer)
        .unwrap_or(rung);
    let Some(source) = material_source(req, id, params, ability)? else {
        bail!(
            "{flag}: {file} is a `{id}` result or parameter file without {target}'s own material \
             fitted to its data (a fit records it, beside the fit, unless it is per texel or \
             was written by an older fibrefit): run `fibrefit fit DATA --model {rung}` (or fit \
             DATA again with any rung) and export that result"
        );
    };
    if source.params.fuzz_depth > 0.0 {
        bail!(
            "{flag}: {file} is a {rung} + fuzz fit (fuzz_depth {}): {target} has no fuzz layer \
             of fibrefit's; fit `--model {rung}` without it",
            source.params.fuzz_depth
        );
    }
    let maps =
        crate::api::render::maps_dir(None, &req.result, &crate::progress::Progress::quiet())?;
    if maps.is_none() {
        if let Ok(Some((named, looked))) = crate::api::render::named_maps_dir(&req.result) {
            bail!(
                "{flag}: {}; the material's textures are made of them",
                crate::api::render::missing_maps(&req.result, &named, &looked)
            );
        }
    }
    let maps = match (maps, source.recorded_by) {
        (Some(dir), None) => {
            let m = TexelMapsIn::load(&dir, None)
                .map_err(|e| anyhow!("{flag}: the maps the result names: {e:#}"))?;
            m.lobe_for(id, &dir)
                .map_err(|e| anyhow!("{flag}: the maps the result names: {e:#}"))?;
            Some((dir, m))
        }
        (Some(dir), Some(_)) => {
            req.progress.warn(&format!(
                "{flag} carries the recorded global material only, not the per-texel maps in {}",
                dir.display()
            ));
            None
        }
        (None, _) => None,
    };
    let name = if name.is_empty() {
        req.result
            .file_stem()
            .map_or("fibrefit".into(), |s| s.to_string_lossy().into_owned())
    } else {
        name.to_string()
    };
    // a recorded material's values are its own: of the result's lines only where it came from
    let mut provenance = match source.recorded_by {
        Some(_) => lines.iter().take(1).cloned().collect(),
        None => lines.to_vec(),
    };
    if let Some(by) = source.recorded_by {
        let by = match params.fuzz_depth > 0.0 {
            true => format!("{by} + fuzz"),
            false => by.to_string(),
        };
        let line = format!(
            "the `{}` material {file}'s `{by}` fit recorded (renderer_materials): {target}'s own \
             material fitted to the same data, not a conversion of the `{by}` model",
            source.id
        );
        req.progress.say(&line);
        provenance.push(line);
        // its own values the data did not determine: used, but not as measurements
        for u in &source.undetermined {
            let w = format!(
                "{flag}: the recorded `{}` material's {}; used as given, not a measurement",
                source.id,
                crate::fit::determined::warning(u)
            );
            req.progress.warn(&w);
            provenance.push(format!(
                "UNDETERMINED: {}",
                crate::fit::determined::warning(u)
            ));
        }
    }
    provenance.push(format!("error against the data: {}", source.error.text()));
    Ok((name, provenance, source, maps))
}

/// The textures of material `stem` of `maps` (from `dir`): `(suffix, input, meaning)` of base
/// colour, roughness, anisotropy and the fibre direction's input (`rotation`: its value of a
/// fibre azimuth in degrees), each where the maps have it, the global value `p`'s in their
/// gaps. No maps: none.
fn material_textures(
    stem: &str,
    maps: Option<(PathBuf, TexelMapsIn)>,
    p: &ModelParams,
    id: ModelId,
    inputs: [(&'static str, &'static str, &'static str); 4],
    rotation: impl Fn(f64) -> f64,
) -> MaterialTextures {
    let stem = stem.to_string();
    let Some((dir, maps)) = maps else {
        return MaterialTextures {
            stem,
            ..Default::default()
        };
    };
    let size = (maps.width, maps.rows);
    let lobe = p.lobe(id);
    let grey = |v: f64| [v; 3];
    let mut textures = vec![];
    if maps.kd.is_some() {
        let kd = p.albedos.diffuse;
        textures.push(MapTexture::of(
            inputs[0],
            size,
            |x, y| {
                let c = |ch| TexelMapsIn::at(&maps.kd, x, y, ch);
                Some([c(0)?, c(1)?, c(2)?])
            },
            kd,
        ));
    }
    for (k, m, global) in [
        (1, &maps.roughness, lobe.roughness),
        (2, &maps.anisotropy, lobe.anisotropy),
    ] {
        if m.is_some() {
            textures.push(MapTexture::of(
                inputs[k],
                size,
                |x, y| TexelMapsIn::at(m, x, y, 0).map(grey),
                grey(global),
            ));
        }
    }
    if maps.psi.is_some() {
        let global = rotation(p.fibre_azimuth.to_degrees());
        textures.push(MapTexture::of(
            inputs[3],
            size,
            |x, y| TexelMapsIn::at(&maps.psi, x, y, 0).map(|d| grey(rotation(d))),
            grey(global),
        ));
    }
    MaterialTextures {
        textures,
        stem,
        dir: None,
        maps: Some(dir),
    }
}

/// The Blender material of a `principled` result, or of the `principled` material a result
/// recorded (its values exactly), named `name` (empty: the result's file stem).
fn blender_material(
    req: &ExportRequest,
    id: ModelId,
    params: &ModelParams,
    name: &str,
    lines: &[String],
) -> Result<(BlenderMaterial, DataError)> {
    let rung = (
        "--blender",
        crate::model::Ability::PrincipledMaterial,
        "principled",
    );
    let (name, provenance, source, maps) = renderer_material(req, id, params, rung, name, lines)?;
    let p = &source.params;
    let inputs = [
        (
            "base_color",
            "Base Color",
            "Base Color, scene-linear RGB (the fit's kd)",
        ),
        ("roughness", "Roughness", "Roughness"),
        ("anisotropic", "Anisotropic", "Anisotropic"),
        (
            "anisotropic_rotation",
            "Anisotropic Rotation",
            "Anisotropic Rotation, a fraction of a turn: (fibre azimuth + 90 deg) / 360",
        ),
    ];
    let turn = |psi: f64| crate::export::material_textures::turns(psi + 90.0);
    let textures = material_textures(&name, maps, p, source.id, inputs, turn);
    Ok((
        BlenderMaterial {
            name,
            base_color: p.albedos.diffuse,
            shape: p.principled,
            fibre_azimuth_deg: p.fibre_azimuth.to_degrees(),
            provenance,
            textures,
        },
        source.error,
    ))
}

/// The OpenPBR Surface material of an `openpbr` result, or of the `openpbr` material a result
/// recorded (its values exactly), named `name` (empty: the result's file stem) made a valid
/// MaterialX name.
fn openpbr_material(
    req: &ExportRequest,
    id: ModelId,
    params: &ModelParams,
    (name, flag): (&str, &str),
    lines: &[String],
) -> Result<(OpenPbrMaterial, DataError)> {
    let rung = (flag, crate::model::Ability::OpenPbrMaterial, "openpbr");
    let (name, provenance, source, maps) = renderer_material(req, id, params, rung, name, lines)?;
    let p = &source.params;
    let inputs = [
            ("base_color", "base_color", "base_color, linear RGB (the fit's kd)"),
            ("specular_roughness", "specular_roughness", "specular_roughness"),
            (
                "specular_roughness_anisotropy",
                "specular_roughness_anisotropy",
                "specular_roughness_anisotropy",
            ),
            (
                "tangent_rotation",
                "amount",
                "rotate3d's amount turning the UV tangent across the fibres, degrees: -(fibre azimuth + 90)",
            ),
        ];
    let name = OpenPbrMaterial::valid_name(&name);
    let amount = crate::export::materialx_out::rotation_amount;
    let textures = material_textures(&name, maps, p, source.id, inputs, amount);
    Ok((
        OpenPbrMaterial {
            name,
            base_color: p.albedos.diffuse,
            shape: p.openpbr,
            fibre_azimuth_deg: p.fibre_azimuth.to_degrees(),
            provenance,
            textures,
        },
        source.error,
    ))
}

/// The shader in `lang`, its provenance `lines` in its header; with `req.check`, run on the GPU
/// driver against the Rust model and the result's own check values first (the checks' figures
/// join the header), refused beyond the f32 bound.
fn shader_source(
    req: &ExportRequest,
    id: ModelId,
    params: &ModelParams,
    mut lines: Vec<String>,
    lang: Language,
) -> Result<String> {
    let wgsl_src = shader::wgsl(id, params, &lines)?;
    if !req.check {
        return shader::translate(&wgsl_src, lang);
    }
    let gpu = Gpu::new()?;
    let cases = check::cases(10_000, 1, max_height(params.spacing));
    let (a, bound) = check::on_gpu(&gpu, &wgsl_src, id, params, &cases)?;
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
    req.progress.say(&line);
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
        req.progress.say(&l);
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
    shader::translate(&shader::wgsl(id, params, &lines)?, lang)
}

/// Why a `gltf` result cannot be written exactly (None: it can): glTF has no extension for the
/// fuzz layer.
pub fn not_pure_gltf(id: ModelId, params: &ModelParams) -> Option<String> {
    if id != ModelId::Gltf {
        return None;
    }
    (params.fuzz_depth > 0.0).then(|| {
        format!(
            "the result is a gltf + fuzz fit (fuzz_depth {}): glTF has no extension for the fuzz layer, so the GLB carries a glTF material converted from the whole model (fitted to the model, not the data)",
            params.fuzz_depth
        )
    })
}

/// The GLB preview: the object with the result's glTF material, textured by the maps a
/// `fit --maps` result names when the mesh has texture coordinates. A `gltf` fit without the
/// fuzz layer is written exactly (its values, its maps as textures); any other result gets a
/// glTF material fitted to its model, labelled as a conversion.
fn glb_preview(
    req: &ExportRequest,
    id: ModelId,
    params: &ModelParams,
    lines: &[String],
    undetermined: &[crate::fit::determined::Undetermined],
) -> Result<((Vec<u8>, GltfRoute), Option<GlbTextures>)> {
    let psi_deg = params.fibre_azimuth.to_degrees();
    let (mesh, turn) = preview(&req.object, psi_deg)?;
    let maps = match maps_of(&req.result, &req.progress)? {
        Some(dir) if mesh.mesh.uvs.is_none() => {
            req.progress.warn(&format!(
                "{} has no texture coordinates: the GLB carries no textures of the maps in {}, only the global material",
                req.object,
                dir.display()
            ));
            None
        }
        other => other,
    };
    let error = DataError::of_result(&req.result);
    let tangent_words = if matches!(req.object.as_str(), "swatch" | "sphere") {
        format!("TANGENT is the UV u axis; the fibres lie at fibre_azimuth_deg {psi_deg} from it, towards the bitangent")
    } else {
        "TANGENT is the fibre direction (the mesh's own fibre field)".to_string()
    };
    let why = not_pure_gltf(id, params);
    // another rung's fit: the glTF material it recorded, fitted to the same data (not with maps:
    // their textures come from the fit's own maps)
    let recorded = match (id == ModelId::Gltf && why.is_none(), &maps) {
        (false, None) => material_source(req, id, params, crate::model::Ability::GltfMaterial)?
            .filter(|s| not_pure_gltf(s.id, &s.params).is_none()),
        _ => None,
    };
    if let (Some(w), None) = (&why, &recorded) {
        req.progress.warn(w);
    }
    let mut images = Vec::new();
    let mut textures = None;
    let (material, route) = if (id == ModelId::Gltf && why.is_none()) || recorded.is_some() {
        let (gid, gparams, error, route_words) = match &recorded {
            Some(s) => {
                let words = format!(
                    "recorded: the glTF material the `{id}` fit recorded (renderer_materials), the \
                     gltf rung fitted to the same data, every value written as fitted; not a \
                     conversion of the `{id}` model"
                );
                req.progress.say(&format!("--gltf: {words}"));
                for u in &s.undetermined {
                    req.progress.warn(&format!(
                        "--gltf: the recorded `{}` material's {}; used as given, not a measurement",
                        s.id,
                        crate::fit::determined::warning(u)
                    ));
                }
                (s.id, &s.params, s.error.clone(), words)
            }
            None => (
                id,
                params,
                error,
                "fitted: the gltf rung's own fit, every value written as fitted (the rung is this glTF material)".to_string(),
            ),
        };
        let psi_deg = gparams.fibre_azimuth.to_degrees();
        let turn = turn + (gparams.fibre_azimuth - params.fibre_azimuth);
        let values = gltf_out::RungValues {
            base_color: gparams.albedos.diffuse,
            shape: gparams.gltf,
            anisotropy_rotation: turn + std::f64::consts::FRAC_PI_2,
        };
        let extras = serde_json::json!({
            "model": gid.as_str(),
            "route": route_words,
            "error_against_data": error.json(),
            "fibre_azimuth_deg": psi_deg,
            "tangent": tangent_words,
            "anisotropy_direction": "across the fibres: anisotropyRotation = the fibres' angle from the TANGENT + 90 deg",
            "sheen_roughness": "the Charlie alpha is sheenRoughnessFactor^2 (the Khronos Sample Viewer and three.js)",
            "gltf_variant": gparams.gltf.variant.as_str(),
            "exact_in": gparams.gltf.variant.exact_in(),
            "source": lines,
        });
        let mut tx = None;
        if let Some(dir) = maps {
            let loaded = TexelMapsIn::load(&dir, None)
                .map_err(|e| anyhow!("the maps the result names: {e:#}"))?;
            if let Some((t, imgs, d)) = rung_textures(params, &loaded, &dir, &req.progress)? {
                images = imgs;
                textures = Some(t);
                tx = Some(d);
            }
        }
        (
            gltf_out::gltf_rung_material(&values, tx.as_ref(), extras),
            GltfRoute::Fitted {
                values,
                error,
                recorded_by: recorded.as_ref().and(Some(id)),
            },
        )
    } else {
        let model = model::build(id, params)?;
        let mut fitted = gltf_material::fit(model.as_ref(), &params.albedos, 1)?;
        // the fit's rotation is from the fibre direction; the file's from the TANGENT
        fitted.material.anisotropy_rotation += turn;
        let mut material = gltf_out::fitted_material(&fitted, id, lines);
        if let Some(dir) = maps {
            let loaded = TexelMapsIn::load(&dir, None)
                .map_err(|e| anyhow!("the maps the result names: {e:#}"))?;
            let t = map_textures(model.as_ref(), params, &fitted, &loaded, &dir)?;
            if let Some((tex, imgs, description)) = t {
                material = gltf_out::textured_material(&fitted, id, lines, Some(&description));
                images = imgs;
                textures = Some(tex);
            }
        }
        let e = &mut material["extras"]["fibrefit"];
        e["route"] = serde_json::json!(format!(
            "converted: a glTF material fitted to the {id} model (not to the data); its error against the model is relative_rms_error"
        ));
        if let Some(w) = &why {
            e["why_converted"] = serde_json::json!(w);
        }
        e["source_error_against_data"] = error.json();
        e["tangent"] = serde_json::json!(tangent_words);
        (
            material,
            GltfRoute::Converted {
                material: fitted,
                why,
                source_error: error,
            },
        )
    };
    let mut material = material;
    // a recorded material's own undetermined values, else the result's
    match &recorded {
        Some(s) => gltf_out::mark_undetermined(&mut material, &s.undetermined),
        None => gltf_out::mark_undetermined(&mut material, undetermined),
    }
    let mut bytes = Vec::new();
    gltf_out::write_glb_with_images(
        &mut bytes,
        &mesh.mesh,
        &VertexFrames {
            normals: &mesh.normals,
            tangents: &mesh.tangents,
            bitangents: &mesh.bitangents,
            undefined: &mesh.undefined,
        },
        Some(material),
        &images,
        &format!("fibrefit {} export", env!("CARGO_PKG_VERSION")),
    )?;
    Ok(((bytes, route), textures))
}

/// The textures of a `gltf` fit's maps (one texel per map pixel, rows from the top, as
/// [`map_textures`]): base colour (sRGB) from `kd.exr`; the metallic-roughness texture from
/// `roughness.exr` (G = roughness, linear 8-bit, `roughnessFactor` 1; B = 1, R = 0); and
/// KHR_materials_anisotropy's texture from `fibre_azimuth.exr` and `anisotropy_strength.exr`
/// (RG = (cos a, sin a) encoded [-1, 1] -> [0, 1], a = the texel's azimuth -
/// `fibre_azimuth_deg`; B = the texel's strength with `anisotropyStrength` 1, or 1 so the
/// strength is the fit's). A height or ks map (which a `gltf` fit does not write) is not read,
/// with a warning. A texel without a value takes the global.
fn rung_textures(
    params: &ModelParams,
    maps: &TexelMapsIn,
    dir: &Path,
    progress: &crate::progress::Progress,
) -> Result<
    Option<(
        GlbTextures,
        Vec<gltf_out::TextureImage>,
        gltf_out::RungTextures,
    )>,
> {
    let (w, h) = (maps.width, maps.rows);
    for (name, m) in [("height.exr", &maps.height), ("ks.exr", &maps.ks)] {
        if m.is_some() {
            progress.warn(&format!(
                "{}: a gltf fit has no {name} map (glTF's layers have weight 1 and the rung no topology): not read",
                dir.join(name).display()
            ));
        }
    }
    if [&maps.kd, &maps.psi, &maps.roughness, &maps.anisotropy]
        .iter()
        .all(|m| m.is_none())
    {
        return Ok(None);
    }
    let n = w
        .checked_mul(h)
        .and_then(|n| n.checked_mul(3))
        .ok_or_else(|| anyhow!("maps of {w}x{h} texels: too many for textures"))?;
    let psi_deg = params.fibre_azimuth.to_degrees();
    let (mut base, mut rough, mut aniso) = (vec![0u8; n], vec![0u8; n], vec![0u8; n]);
    let (strength, roughness) = (params.gltf.anisotropy, params.gltf.roughness);
    // the largest relative change 8-bit sRGB makes to a base colour channel above 0.01
    let mut worst_base: f64 = 0.0;
    for y in 0..h {
        for x in 0..w {
            let i = 3 * (y * w + x);
            for c in 0..3 {
                let k = TexelMapsIn::at(&maps.kd, x, y, c).unwrap_or(params.albedos.diffuse[c]);
                let e = gltf_out::srgb8(k);
                base[i + c] = e;
                if k > 0.01 {
                    worst_base = worst_base.max((srgb8_decoded(e) - k).abs() / k);
                }
            }
            let turn = TexelMapsIn::at(&maps.psi, x, y, 0).map_or(0.0, |p| {
                ((p - psi_deg + 90.0).rem_euclid(180.0) - 90.0).to_radians()
            });
            let b = match &maps.anisotropy {
                Some(_) => {
                    gltf_out::unorm8(TexelMapsIn::at(&maps.anisotropy, x, y, 0).unwrap_or(strength))
                }
                None => 255,
            };
            aniso[i..i + 3].copy_from_slice(&[
                gltf_out::unorm8(0.5 * (turn.cos() + 1.0)),
                gltf_out::unorm8(0.5 * (turn.sin() + 1.0)),
                b,
            ]);
            let r = TexelMapsIn::at(&maps.roughness, x, y, 0).unwrap_or(roughness);
            rough[i..i + 3].copy_from_slice(&[0, gltf_out::unorm8(r), 255]);
        }
    }
    let mut images = Vec::new();
    let mut names = Vec::new();
    let mut add = |name: &'static str, file: &str, rgb: &[u8]| -> Result<usize> {
        images.push(gltf_out::TextureImage {
            name: file.to_string(),
            png: gltf_out::png_rgb8(w, h, rgb)?,
        });
        names.push(name);
        Ok(images.len() - 1)
    };
    let t_base = maps
        .kd
        .is_some()
        .then(|| add("base colour", "base_color", &base))
        .transpose()?;
    let t_rough = maps
        .roughness
        .is_some()
        .then(|| add("metallic-roughness", "metallic_roughness", &rough))
        .transpose()?;
    let strength_mapped = maps.anisotropy.is_some();
    let t_aniso = (maps.psi.is_some() || strength_mapped)
        .then(|| add("anisotropy", "anisotropy", &aniso))
        .transpose()?;
    let description = serde_json::json!({
        "maps": file_name(dir),
        "size": [w, h],
        "registration": "one texel per map pixel; image row 0 is the maps' top row (the mesh's v = 1, TEXCOORD_0 t = 0)",
        "base_color": t_base.map(|_| format!(
            "sRGB 8-bit: the fit's kd map (the global kd where a texel has none); the encoding changes a channel above 0.01 by at most {:.2} %",
            100.0 * worst_base
        )),
        "anisotropy": t_aniso.map(|_| format!(
            "RG = (cos a, sin a) encoded [-1, 1] -> [0, 1], a = the texel's fibre azimuth - fibre_azimuth_deg {psi_deg} (0 without a fibre_azimuth map), turned further by anisotropyRotation (so across the texel's fibres); B = {}",
            if strength_mapped {
                "the texel's anisotropy strength (linear 8-bit; anisotropyStrength = 1)"
            } else {
                "1: the strength is anisotropyStrength"
            }
        )),
        "roughness": match t_rough {
            Some(_) => "metallic-roughness texture: G = the texel's roughness (linear 8-bit, roughnessFactor = 1), B = 1 (metallicFactor is the fit's), R unused".to_string(),
            None => "no texture: roughnessFactor is the global fit's (no roughness map)".to_string(),
        },
    });
    Ok(Some((
        GlbTextures {
            directory: dir.to_path_buf(),
            width: w,
            height: h,
            names,
            height_nodes: Vec::new(),
        },
        images,
        gltf_out::RungTextures {
            base_color: t_base,
            metallic_roughness: t_rough,
            anisotropy: t_aniso,
            strength_mapped,
            description,
        },
    )))
}

/// The linear value of an 8-bit sRGB code.
fn srgb8_decoded(e: u8) -> f64 {
    let c = f64::from(e) / 255.0;
    if c <= 0.04045 {
        c / 12.92
    } else {
        ((c + 0.055) / 1.055).powf(2.4)
    }
}

/// The textures of a `fit --maps` result's maps (one texel per map pixel, rows from the top: the
/// mesh's v = 1 is the maps' top row, as `render` reads them):
/// - base colour (sRGB) where there are kd, ks or height maps: per texel the least-squares base
///   colour of the glTF shape for the texel's albedos ([`gltf_material::TexelMaterials`]);
/// - metallic-roughness (G = roughness, B = metallic 0) where there is a height map: the
///   roughness refitted at the texel's height;
/// - KHR_materials_anisotropy's texture where there are azimuth or height maps: RG the fibre
///   direction relative to the TANGENT, a = the texel's azimuth - `fibre_azimuth_deg` (TANGENT
///   is the global fibre direction, the bitangent N x T, w = +1), as (cos a, sin a) encoded
///   [-1, 1] -> [0, 1]; B the strength refitted at the texel's height, or the global strength.
///
/// A texel without a value (NaN) takes the global one. `None` when the maps give no texture.
fn map_textures(
    model: &dyn model::ShadingModel,
    params: &ModelParams,
    fitted: &FittedMaterial,
    maps: &TexelMapsIn,
    dir: &Path,
) -> Result<Option<TexturesOut>> {
    let (w, h) = (maps.width, maps.rows);
    let h_max = max_height(params.spacing);
    let topology = model.rung().has(crate::model::Ability::Topology);
    let heights = topology.then_some(maps.height.as_ref()).flatten();
    let range = heights.and_then(|m| height_range(m, h_max));
    let albedo_maps = maps.kd.is_some() || maps.ks.is_some();
    let with_height = range.is_some();
    let (want_base, want_rough, want_aniso) = (
        albedo_maps || with_height,
        with_height,
        maps.psi.is_some() || with_height,
    );
    if !(want_base || want_aniso) {
        return Ok(None);
    }
    let source = TextureSource {
        maps,
        params,
        table: gltf_material::TexelMaterials::new(model, &params.albedos, fitted, range, 1)?,
        heights: heights.is_some(),
        h_max,
        psi_deg: params.fibre_azimuth.to_degrees(),
    };
    let [base, rough, aniso] = source.pixels()?;
    let mut images = Vec::new();
    let mut names = Vec::new();
    let mut add = |name: &'static str, file: &str, rgb: &[u8]| -> Result<usize> {
        images.push(gltf_out::TextureImage {
            name: file.to_string(),
            png: gltf_out::png_rgb8(w, h, rgb)?,
        });
        names.push(name);
        Ok(images.len() - 1)
    };
    let t_base = want_base
        .then(|| add("base colour", "base_color", &base))
        .transpose()?;
    let t_rough = want_rough
        .then(|| add("metallic-roughness", "metallic_roughness", &rough))
        .transpose()?;
    let t_aniso = want_aniso
        .then(|| add("anisotropy", "anisotropy", &aniso))
        .transpose()?;
    let nodes = source.table.nodes();
    let description = source.description(dir, [t_base, t_rough, t_aniso], with_height, &nodes);
    Ok(Some((
        GlbTextures {
            directory: dir.to_path_buf(),
            width: w,
            height: h,
            names,
            height_nodes: nodes,
        },
        images,
        gltf_out::MaterialTextures {
            base_color: t_base,
            metallic_roughness: t_rough,
            anisotropy: t_aniso,
            description,
        },
    )))
}

/// The least and largest finite height of the height map `m`, each clamped to [0, `h_max`];
/// none without a finite one.
fn height_range(m: &crate::load::image_io::LinearImage, h_max: f64) -> Option<(f64, f64)> {
    let finite = m.data.iter().filter(|v| v.is_finite());
    let (lo, hi) = finite.fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &v| {
        let v = f64::from(v).clamp(0.0, h_max);
        (lo.min(v), hi.max(v))
    });
    (lo <= hi).then_some((lo, hi))
}

/// What [`map_textures`] makes its textures of: the maps, the globals they vary around and the
/// glTF shapes per height.
struct TextureSource<'a> {
    maps: &'a TexelMapsIn,
    /// The globals: albedos where a map has no value, the fibre azimuth.
    params: &'a ModelParams,
    /// The glTF material of a texel by its height and albedos.
    table: gltf_material::TexelMaterials,
    /// Whether the texels' heights are read (the rung has a topology and there is a height map).
    heights: bool,
    /// H_max at the globals' spacing: the texels' heights are clamped to [0, H_max].
    h_max: f64,
    /// The global fibre azimuth in degrees (the TANGENT's direction).
    psi_deg: f64,
}

impl TextureSource<'_> {
    /// The RGB8 pixels of the base colour (sRGB), metallic-roughness and anisotropy textures,
    /// texel by texel, rows from the top.
    fn pixels(&self) -> Result<[Vec<u8>; 3]> {
        let (maps, h_max, psi_deg) = (self.maps, self.h_max, self.psi_deg);
        let (w, h) = (maps.width, maps.rows);
        let n = w
            .checked_mul(h)
            .and_then(|n| n.checked_mul(3))
            .ok_or_else(|| anyhow!("maps of {w}x{h} texels: too many for textures"))?;
        let (mut base, mut rough, mut aniso) = (vec![0u8; n], vec![0u8; n], vec![0u8; n]);
        let global = self.params.albedos;
        let tied = global.substrate == global.diffuse;
        for y in 0..h {
            for x in 0..w {
                let mut a = global;
                for c in 0..3 {
                    if let Some(k) = TexelMapsIn::at(&maps.kd, x, y, c) {
                        a.diffuse[c] = k;
                        if tied {
                            a.substrate[c] = k;
                        }
                    }
                    if let Some(k) = TexelMapsIn::at(&maps.ks, x, y, c) {
                        a.specular[c] = k;
                    }
                }
                let height = self
                    .heights
                    .then(|| TexelMapsIn::at(&maps.height, x, y, 0))
                    .flatten()
                    .map(|v| v.clamp(0.0, h_max));
                let m = self.table.at(height, &a);
                let turn = TexelMapsIn::at(&maps.psi, x, y, 0).map_or(0.0, |p| {
                    ((p - psi_deg + 90.0).rem_euclid(180.0) - 90.0).to_radians()
                });
                let i = 3 * (y * w + x);
                base[i..i + 3].copy_from_slice(&m.base_color.map(gltf_out::srgb8));
                rough[i..i + 3].copy_from_slice(&[0, gltf_out::unorm8(m.roughness), 0]);
                aniso[i..i + 3].copy_from_slice(&[
                    gltf_out::unorm8(0.5 * (turn.cos() + 1.0)),
                    gltf_out::unorm8(0.5 * (turn.sin() + 1.0)),
                    gltf_out::unorm8(m.anisotropy_strength),
                ]);
            }
        }
        Ok([base, rough, aniso])
    }

    /// The textures' description in the document: the maps' folder `dir`, which texture is
    /// which (`[base colour, metallic-roughness, anisotropy]`, each where made), `with_height`
    /// (strength refitted per height) and the height `nodes`.
    fn description(
        &self,
        dir: &Path,
        [t_base, t_rough, t_aniso]: [Option<usize>; 3],
        with_height: bool,
        nodes: &[gltf_material::HeightNode],
    ) -> serde_json::Value {
        let (w, h, psi_deg) = (self.maps.width, self.maps.rows, self.psi_deg);
        serde_json::json!({
            // the folder's name, not where it lies on this machine (no absolute paths in exports)
            "maps": file_name(dir),
            "size": [w, h],
            "registration": "one texel per map pixel; image row 0 is the maps' top row (the mesh's v = 1, TEXCOORD_0 t = 0)",
            "base_color": t_base.map(|_| "sRGB; per texel the least-squares base colour of the texel's glTF shape for its albedos (kd, ks maps; the global ones where a map has no value), as the global fit solves it"),
            "metallic_roughness": t_rough.map(|_| "G = roughness refitted to the model at the texel's height (linear between the height nodes), B = metallic 0"),
            "anisotropy": t_aniso.map(|_| format!(
                "RG = (cos a, sin a) encoded [-1, 1] -> [0, 1], a = the texel's fibre azimuth - fibre_azimuth_deg {psi_deg} (the TANGENT's direction), turned further by anisotropyRotation; B = strength{}",
                if with_height { " refitted at the texel's height" } else { ", the global one" }
            )),
            "height_nodes": nodes.iter().map(|n| serde_json::json!({
                "height": n.height,
                "roughness": n.roughness,
                "anisotropy_strength": n.anisotropy_strength,
                "relative_rms_error": n.relative_rms_error,
            })).collect::<Vec<_>>(),
        })
    }
}

type TexturesOut = (
    GlbTextures,
    Vec<gltf_out::TextureImage>,
    gltf_out::MaterialTextures,
);

/// The last component of `path` (the whole path when it has none): what an export names.
fn file_name(path: &Path) -> String {
    path.file_name().map_or_else(
        || path.display().to_string(),
        |n| n.to_string_lossy().into_owned(),
    )
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
    if id.has(crate::model::Ability::SpecularLobe) {
        lines.push(format!(
            "exponent {}, spacing {}, fibre azimuth {} deg, spread {} deg, Fresnel ior {}",
            p.exponent,
            p.spacing,
            p.fibre_azimuth.to_degrees(),
            p.azimuth_spread_deg,
            p.fresnel_ior
        ));
    }
    if id.has(crate::model::Ability::WardLobe) {
        lines.push(format!("alpha_x {}, alpha_y {}", p.alpha_x, p.alpha_y));
    }
    if id.has_topology() {
        lines.push(format!(
            "height H0 {}, map scale {}{}",
            p.topology.height,
            p.topology.map_scale,
            p.topology.map.as_ref().map_or(String::new(), |m| format!(
                ", topology map {} ({} bins)",
                file_name(&m.source),
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

/// The preview mesh for `--object`, and the angle (radians) from its TANGENT to the fibres: on
/// the swatch and the sphere TANGENT is the UV u axis (as engines that derive tangents from the
/// texture coordinates have it) and the fibres lie at `psi_deg` from it; on the torus and an
/// OBJ TANGENT is the fibre direction itself (0).
fn preview(object: &str, psi_deg: f64) -> Result<(FramedMesh, f64)> {
    let psi = psi_deg.to_radians();
    match object {
        "swatch" => Ok((preview_mesh::swatch(0.0)?, psi)),
        "sphere" => Ok((preview_mesh::sphere(0.0)?, psi)),
        "torus" => Ok((preview_mesh::torus()?, 0.0)),
        o if o.to_ascii_lowercase().ends_with(".obj") => Ok((
            preview_mesh::curvature_aligned(mesh::load_obj(Path::new(o))?, psi_deg)?,
            0.0,
        )),
        o => bail!("--object {o}: expected swatch, sphere, torus or a .obj mesh"),
    }
}
