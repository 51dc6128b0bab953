//! The renderer JSON (schema `fibrefit-result/1`, documented in docs/formats.md), written and read in
//! this one place: the fitted model with its conventions, parameters and uncertainties,
//! statistics, knobs, provenance, check values for renderer ports, and the renderers' own
//! materials fitted to the same data ([`ResultFile`]); read back as parameters ([`read_params`]: `eval`, `render`, `export`,
//! `synth`) or as a fit's parameter set ([`read_result`]: `score`, map tiles).

use crate::fit::config::{FitConfig, Knobs as FitKnobs, Metric, ParamEntry};
use crate::fit::parameters::ParamSet;
use crate::fit::score::FittedResult;
use crate::fit::FitOutcome;
use crate::model::params::{Albedo, ModelParams, RawParams};
use crate::model::ModelId;
use anyhow::{anyhow, bail, Result};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// Schema of the result JSON a fit is exported as (and `score`, `eval`, `render` read back).
pub const SCHEMA: &str = "fibrefit-result/1";

/// A parameter file (TOML or JSON) or a fitted result, as parameters; a result's relative
/// topology map is taken from beside it ([`locate_map`]).
pub fn read_params(path: &Path) -> Result<RawParams> {
    if path.is_dir() {
        // named as what it is, whatever its name says (a folder `fit.json`, `data.csv`)
        return RawParams::load(path);
    }
    let is_json = path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("json"));
    if !is_json {
        return RawParams::load(path);
    }
    let text = crate::load::input::read_text_as(path, "parameter file")?;
    let value: serde_json::Value =
        serde_json::from_str(&text).map_err(|e| anyhow!("{}: {e}", path.display()))?;
    let is_result = value
        .get("schema")
        .and_then(|s| s.as_str())
        .is_some_and(|s| s.starts_with("fibrefit-result/"));
    if !is_result {
        return RawParams::load(path);
    }
    raw_of_result(&value, path)
}

/// The parameters of the result `value` read from `path` (a relative topology map taken from
/// beside it, checked by its hash: [`locate_map`]).
fn raw_of_result(value: &serde_json::Value, path: &Path) -> Result<RawParams> {
    let mut raw = params_of_result(value).map_err(|e| anyhow!("{}: {e}", path.display()))?;
    if let Some(map) = &raw.topology_map {
        raw.topology_map = Some(locate_map(path, map, recorded_map_hash(value))?);
    }
    Ok(raw)
}

/// The SHA-256 a result records of its topology map (`knobs.topology_map_sha256`; absent in
/// files written before it was recorded).
fn recorded_map_hash(value: &serde_json::Value) -> Option<&str> {
    value["knobs"]["topology_map_sha256"].as_str()
}

/// Where the topology map `named` by the result at `result` is: relative to the result's own
/// folder (never the working directory), so a result folder copied with its map loads
/// anywhere. Refused, naming the path looked for, when it is not there; refused, naming both
/// hashes, when the result records the map's SHA-256 and the file's differs.
pub fn locate_map(result: &Path, named: &Path, sha256: Option<&str>) -> Result<PathBuf> {
    let folder = match result.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
        _ => PathBuf::from("."),
    };
    let at = folder.join(named);
    // the absolute path tried, for the messages (`..` taken off the resolved folder)
    let base = std::fs::canonicalize(&folder)
        .unwrap_or_else(|_| std::env::current_dir().unwrap_or_default().join(&folder));
    let mut shown = PathBuf::new();
    for c in base.join(named).components() {
        match c {
            std::path::Component::ParentDir => {
                shown.pop();
            }
            std::path::Component::CurDir => {}
            c => shown.push(c),
        }
    }
    if !at.is_file() {
        bail!(
            "{}: the topology map the result names (knobs.topology_map = {:?}) is not there: \
             looked for {} ({}); copy the map with the result, keeping their relative layout",
            result.display(),
            named.display().to_string(),
            shown.display(),
            match named.is_relative() {
                true => "relative to the result's folder, never the working directory",
                false => "an absolute path",
            }
        );
    }
    if let Some(expected) = sha256 {
        let got = crate::load::input::read_input_as(
            &at,
            crate::load::MAX_INPUT_BYTES,
            "topology map",
        )?
        .sha256;
        if !got.eq_ignore_ascii_case(expected) {
            bail!(
                "{}: the topology map {} is not the one this result was fitted with: its sha256 \
                 is {got}, the result recorded {expected} (knobs.topology_map_sha256); restore \
                 that map, or fit again with this one",
                result.display(),
                shown.display()
            );
        }
    }
    Ok(at)
}

/// The one check of a parameter set's values that every command reading a result or a
/// parameter file makes (`eval`, `render`, `export`, `score`, map tiles): the rung (`model`,
/// else the file's) and its validated parameters, with warnings about the parameters the rung
/// does not use. Errors are labelled `name` (the file).
pub fn checked_params(
    raw: &RawParams,
    model: Option<&str>,
    name: &str,
) -> Result<(ModelId, ModelParams, Vec<String>)> {
    let id_text = model
        .map(str::to_string)
        .or_else(|| raw.model.clone())
        .ok_or_else(|| anyhow!("no model given: pass --model ID or set `model` in {name}"))?;
    let id: ModelId = id_text.parse().map_err(|e: String| anyhow!(e))?;
    let (params, warnings) =
        ModelParams::from_raw(raw, id).map_err(|e| anyhow!("{name}: {e:#}"))?;
    Ok((id, params, warnings))
}

/// Read a `fibrefit-result/1` JSON for data with `channels` channels.
pub fn read_result(path: &Path, channels: usize) -> Result<FittedResult> {
    let text = crate::load::input::read_text_as(path, "result file")?;
    let v: serde_json::Value =
        serde_json::from_str(&text).map_err(|e| anyhow!("{}: {e}", path.display()))?;
    // its parameters and knobs checked exactly as `eval`, `render` and `export` check them (a
    // partial result is refused below, with its own message)
    if v.get("partial").and_then(|p| p.as_bool()) != Some(true) {
        let raw = raw_of_result(&v, path)?;
        checked_params(&raw, None, &path.display().to_string())?;
    }
    let mut r = result_from_value(&v, &path.display().to_string(), channels)?;
    // a relative topology map lies beside the result (as fit writes it), checked by its hash
    if let Some(map) = r.knobs.topology_map.as_mut() {
        *map = locate_map(path, map, recorded_map_hash(&v))?;
    }
    Ok(r)
}

/// [`read_result`] of a result already parsed; `name` labels errors.
pub fn result_from_value(
    v: &serde_json::Value,
    name: &str,
    channels: usize,
) -> Result<FittedResult> {
    let at = |what: &str| anyhow!("{}: {what}", name);
    if v.get("partial").and_then(|p| p.as_bool()) == Some(true) {
        return Err(at(
            "a partial result of an interrupted `fit --model auto` (it lists the rungs finished, \
             but no fitted model): run the fit again to finish it",
        ));
    }
    match v.get("schema").and_then(|s| s.as_str()) {
        Some(SCHEMA) => {}
        Some(other) => bail!(
            "{}: schema `{other}` is not one this fibrefit reads ({})",
            name,
            SCHEMA
        ),
        None => return Err(at("not a fibrefit result (no `schema`)")),
    }
    let model = v
        .get("model")
        .and_then(|m| m.as_str())
        .ok_or_else(|| at("no `model`"))?;
    let params = v
        .get("parameters")
        .and_then(|p| p.as_object())
        .ok_or_else(|| at("no `parameters`"))?;
    let (entries, free, rgb) = fitted_entries(params, &at)?;
    if rgb && channels == 1 {
        bail!("{}: an RGB result cannot score grey data", name);
    }
    let (metric, knobs) = knobs_of(v.get("knobs"), &at)?;
    let cfg = FitConfig {
        model: model
            .parse()
            .map_err(|e: String| at(&format!("`model`: {e}")))?,
        metric,
        starts: 1,
        seed: 0,
        knobs: knobs.clone(),
        optimizer: Default::default(),
        parameters: entries,
        components: Default::default(),
        selection: Default::default(),
        maps: Default::default(),
        columns: Default::default(),
        data: Default::default(),
        notes: Vec::new(),
        metric_follows_data: false,
        metric_reason: None,
        keep_free_spread: false,
        search_knobs: None,
    };
    cfg.validate().map_err(|e| anyhow!("{}: {e}", name))?;
    let mut set = ParamSet::from_config(&cfg, channels).map_err(|e| anyhow!("{}: {e}", name))?;
    // an albedo the result says was fitted grey stays one value for every channel when a later
    // stage frees it again (the texel stage's globals, a tile's): its labels are the fit's
    for a in &mut set.albedos {
        a.grey |= channels > 1
            && params
                .get(a.name)
                .and_then(|e| e.get("grey"))
                .and_then(|g| g.as_bool())
                .unwrap_or(false);
    }
    let correction = match v.get("correction").and_then(|c| c.get("series")) {
        Some(series) => {
            let k: crate::model::correction::Correction = serde_json::from_value(series.clone())
                .map_err(|e| at(&format!("`correction.series`: {e}")))?;
            Some(k.checked().map_err(|e| at(&format!("`correction.series`: {e}")))?)
        }
        None => None,
    };
    Ok(FittedResult {
        set,
        metric,
        knobs,
        free_parameters: free,
        correction,
    })
}

/// The result's parameters as fixed entries at their fitted values, the number of free
/// parameters the fit had, and whether any is RGB.
fn fitted_entries(
    params: &serde_json::Map<String, serde_json::Value>,
    at: &dyn Fn(&str) -> anyhow::Error,
) -> Result<(BTreeMap<String, ParamEntry>, usize, bool)> {
    let mut entries = BTreeMap::new();
    let mut free = 0;
    let mut rgb = false;
    for (name, e) in params {
        let value: Albedo = serde_json::from_value(e.get("value").cloned().unwrap_or_default())
            .map_err(|_| {
                at(&format!(
                    "parameters.{name}.value is not a number or [r, g, b]"
                ))
            })?;
        rgb |= value.is_rgb();
        let fixed = e.get("fixed").and_then(|f| f.as_bool()).unwrap_or(true);
        if !fixed {
            // a grey fit of RGB data (ks) is one free parameter, its value repeated per channel
            let grey = e.get("grey").and_then(|g| g.as_bool()).unwrap_or(false);
            free += if value.is_rgb() && !grey { 3 } else { 1 };
        }
        // the fitted value only: the fit's bounds are checked against the fitted spacing
        entries.insert(
            name.clone(),
            ParamEntry {
                value: Some(value),
                vary: Some(false),
                ..Default::default()
            },
        );
    }
    Ok((entries, free, rgb))
}

/// The result's metric and knobs (defaults where a key is absent).
fn knobs_of(
    k: Option<&serde_json::Value>,
    at: &dyn Fn(&str) -> anyhow::Error,
) -> Result<(Metric, FitKnobs)> {
    let knob = |name: &str| k.and_then(|k| k.get(name));
    let metric: Metric = match knob("metric") {
        Some(m) => serde_json::from_value(m.clone())
            .map_err(|_| at("knobs.metric is not linear, log or cosine"))?,
        None => Metric::Linear,
    };
    let knobs = FitKnobs {
        quadrature_order: knob("quadrature_order")
            .and_then(|x| x.as_u64())
            .unwrap_or(16) as usize,
        histogram_bins: knob("histogram_bins")
            .and_then(|x| x.as_u64())
            .unwrap_or(16) as usize,
        azimuth_nodes: knob("azimuth_nodes")
            .and_then(|x| x.as_u64())
            .unwrap_or(crate::model::azimuth_spread::DEFAULT_AZIMUTH_NODES as u64)
            as usize,
        topology_map: knob("topology_map")
            .and_then(|x| x.as_str())
            .map(PathBuf::from),
        gltf_variant: match knob("gltf_variant") {
            Some(x) => serde_json::from_value(x.clone())
                .map_err(|_| at(&format!("knobs.gltf_variant = {x}: expected \"khronos\" or \"threejs\"")))?,
            None => Default::default(),
        },
        ..FitKnobs::default()
    };
    Ok((metric, knobs))
}

/// The parameters of a `fibrefit fit` result (schema `fibrefit-result/1`).
pub fn params_of_result(v: &serde_json::Value) -> Result<RawParams> {
    let schema = v.get("schema").and_then(|s| s.as_str()).unwrap_or_default();
    if schema != SCHEMA {
        bail!(
            "result schema `{schema}` is not one this fibrefit ({}) reads: it reads `{}`; \
             a newer fibrefit wrote this file",
            env!("CARGO_PKG_VERSION"),
            SCHEMA
        );
    }
    let params = v
        .get("parameters")
        .and_then(|p| p.as_object())
        .ok_or_else(|| anyhow!("result file has no `parameters`"))?;
    let mut flat = serde_json::Map::new();
    flat.insert(
        "model".into(),
        v.get("model")
            .cloned()
            .ok_or_else(|| anyhow!("result file has no `model`"))?,
    );
    for (name, entry) in params {
        let value = entry
            .get("value")
            .cloned()
            .ok_or_else(|| anyhow!("parameter `{name}` has no value"))?;
        flat.insert(name.clone(), value);
    }
    // a result records every knob of its fit; only those its model reads are parameters (the
    // rest would be warned about as unused, though the user never wrote them)
    let model: Option<crate::model::ModelId> = v
        .get("model")
        .and_then(|m| m.as_str())
        .and_then(|m| m.parse().ok());
    if let Some(k) = v.get("knobs") {
        for key in [
            "quadrature_order",
            "histogram_bins",
            "azimuth_nodes",
            "topology_map",
            "gltf_variant",
        ] {
            let used = model.is_none_or(|id| crate::model::params::uses(id, key));
            if let Some(x) = k.get(key).filter(|_| used) {
                let named = ["topology_map", "gltf_variant"].contains(&key);
                if !named && x.as_u64().is_none() {
                    bail!("knobs.{key} = {x}: expected a whole number >= 1");
                }
                flat.insert(key.into(), x.clone());
            }
        }
    }
    if let Some(series) = v.get("correction").and_then(|c| c.get("series")) {
        flat.insert("correction".into(), series.clone());
    }
    serde_json::from_value(serde_json::Value::Object(flat)).map_err(|e| anyhow!("{e}"))
}

/// A result file (schema `fibrefit-result/1`, docs/formats.md): what a fit writes and `score`,
/// `eval`, `render` and `export` read.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct ResultFile {
    /// The schema name, `SCHEMA`.
    pub schema: String,
    /// The program that wrote it, `fibrefit VERSION`.
    pub tool: String,
    /// The rung fitted (its id, as `--model` takes it).
    pub model: String,
    /// Frames, angles, units and conventions in words.
    pub conventions: Conventions,
    /// Every parameter by name: value, standard error, bounds, why fixed or held.
    pub parameters: BTreeMap<String, ParamOut>,
    /// Correlations between free parameters above 0.1 in size.
    pub correlations: Vec<Correlation>,
    /// Fit statistics (samples, free parameters, chi-square, RMSE in 1/sr, AIC, BIC...).
    pub statistics: serde_json::Value,
    /// The knobs and settings the fit used.
    pub knobs: Knobs,
    /// The data fitted: file name, SHA-256 of the bytes read, kind, samples, channels.
    pub data: Provenance,
    /// The fitted BRDF (1/sr) at fixed direction pairs, for checking a renderer's port.
    pub check_values: Vec<CheckValue>,
    /// The renderers' own materials (the rungs with a renderer: `principled`, `openpbr`,
    /// `gltf`) fitted to the same data, for `export --blender`, `--materialx`, `--usd` and
    /// `--gltf` of this result: each a result of its own (`schema`, `model`, `parameters`,
    /// `statistics`, `knobs`, `data`) with `renderer`, `fit_seconds` and, after `--model auto`,
    /// `heldout` (its candidate's held-out errors). Absent when the fit is itself one, or per
    /// texel.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub renderer_materials: Vec<serde_json::Value>,
    /// `--model auto`: every candidate compared (errors, free parameters, time).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub model_selection: Vec<serde_json::Value>,
    /// `--model auto`: how the candidates were compared (validation, folds, rule, metric) and
    /// which was chosen.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub selection: Option<serde_json::Value>,
    /// The smooth reciprocal correction kept on the rung (`fit::correction`), absent when none
    /// paid: `series` (what `eval`, `render` and `Material` multiply the rung by), `terms`,
    /// the held-out errors with and without it, the degrees tried, and `check_values` of the
    /// corrected BRDF at the directions of `check_values`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub correction: Option<serde_json::Value>,
    /// Fit quality: noise verdict, distinct minima, residual structure (absent in files written
    /// before it existed).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub quality: Option<serde_json::Value>,
    /// `fit --maps`: the recovered per-texel maps (files, units, grid) and how they were found.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub maps: Option<serde_json::Value>,
    /// Every warning of the fit (quality checks, fallback, notes).
    pub warnings: Vec<String>,
}

#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Conventions {
    pub frame: String,
    pub angles: String,
    pub lengths: String,
    pub brdf: String,
    pub intensity: String,
    pub albedos: String,
}

impl Default for Conventions {
    fn default() -> Self {
        Self {
            frame: "swatch normal N = +z; fibre tangent T = (cos psi, sin psi, 0), psi = fibre_azimuth_deg; B = N x T; T and -T are the same fibres".into(),
            angles: "degrees; theta from N, phi from the swatch x axis towards y; directions point away from the surface".into(),
            lengths: "fibre radii (spacing, height, map_scale)".into(),
            brdf: "f(l, v) in 1/sr; 0 when l or v is at or below the horizon".into(),
            intensity: "I = f cos(theta_i): radiance per unit irradiance perpendicular to the light; a shader's colour per light is E * I (Lambert's shaded colour c = pi * I)".into(),
            albedos: "grey: one number; RGB: [r, g, b], linear".into(),
        }
    }
}

#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct ParamOut {
    /// A number, or [r, g, b].
    pub value: serde_json::Value,
    pub std_error: serde_json::Value,
    pub min: f64,
    pub max: f64,
    pub fixed: bool,
    pub at_bound: bool,
    /// Why a fixed parameter is fixed: the config, the data, a component switched off, or
    /// recovered per texel (a map).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub fixed_reason: Option<String>,
    /// True when one value was fitted for all channels of RGB data (`value` repeats it per
    /// channel): `ks` unless the config asked for `colour = true`.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub grey: bool,
    /// Why a free parameter is held at its value (no standard error): the data do not separate
    /// it from another one (the `quality.degeneracies` pair).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub held: Option<String>,
    /// Whether the data determine the value (for an RGB albedo per channel, `[r, g, b]`): false
    /// when it ended at a bound, is held by a degeneracy or the cost is flat along it
    /// (`fit::determined`); `value` is then the value used, not a measurement. Absent for fixed
    /// parameters and in files written before it existed (read as determined).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub determined: Option<serde_json::Value>,
    /// Why the data do not determine it: a string (per channel: a string or null), present when
    /// `determined` is false for some value.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub undetermined_reason: Option<serde_json::Value>,
}

#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Correlation {
    pub a: String,
    pub b: String,
    pub r: f64,
}

#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Knobs {
    pub metric: String,
    pub quadrature_order: usize,
    pub histogram_bins: usize,
    /// Nodes of the fibre-direction spread quadrature.
    #[serde(default)]
    pub azimuth_nodes: usize,
    pub stride: usize,
    pub fraction: f64,
    /// Image captures: the texels the global fit used at most (0: all).
    #[serde(default)]
    pub fit_texels: usize,
    /// The topology map, relative to the result's folder (as written by `fit`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub topology_map: Option<String>,
    /// SHA-256 of the topology map's bytes as the fit read them: readers refuse a map that
    /// differs (absent in files written before it was recorded, which load unchecked).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub topology_map_sha256: Option<String>,
    pub separable: bool,
    pub starts: usize,
    pub seed: u64,
    /// Why the fit used its metric (the data, the config, `--metric`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub metric_reason: Option<String>,
    /// The `gltf` rung's variant (`khronos` or `threejs`; only in `gltf` results; absent:
    /// khronos).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub gltf_variant: Option<String>,
}

#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Provenance {
    pub file: String,
    pub sha256: String,
    pub kind: String,
    pub samples: usize,
    pub channels: usize,
}

#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct CheckValue {
    pub theta_i: f64,
    pub phi_i: f64,
    pub theta_o: f64,
    pub phi_o: f64,
    /// BRDF per channel, 1/sr (one entry for grey).
    pub brdf: Vec<f64>,
}

/// Fixed direction pairs (degrees) for check values: in-plane, cross-plane, grazing, mirror.
pub fn check_directions() -> Vec<[f64; 4]> {
    let mut v = Vec::new();
    for &(ti, pi, to, po) in &[
        (0.0, 0.0, 0.0, 0.0),
        (30.0, 90.0, 30.0, 90.0),
        (30.0, 90.0, 30.0, 270.0),
        (45.0, 0.0, 45.0, 180.0),
        (45.0, 0.0, 45.0, 0.0),
        (60.0, 45.0, 20.0, 225.0),
        (60.0, 135.0, 60.0, 315.0),
        (10.0, 200.0, 70.0, 20.0),
        (75.0, 90.0, 75.0, 270.0),
        (75.0, 0.0, 75.0, 180.0),
        (85.0, 30.0, 10.0, 210.0),
        (20.0, 300.0, 50.0, 120.0),
        (40.0, 10.0, 40.0, 100.0),
        (50.0, 250.0, 30.0, 250.0),
        (65.0, 170.0, 35.0, 350.0),
        (5.0, 0.0, 80.0, 90.0),
        (35.0, 60.0, 55.0, 240.0),
        (70.0, 330.0, 45.0, 150.0),
        (25.0, 120.0, 65.0, 300.0),
        (80.0, 270.0, 80.0, 90.0),
    ] {
        v.push([ti, pi, to, po]);
    }
    v
}

/// One number, or [r, g, b].
pub fn number_or_rgb(v: &[f64]) -> serde_json::Value {
    if v.len() == 1 {
        serde_json::json!(v[0])
    } else {
        serde_json::json!(v)
    }
}

pub fn params_out(outcome: &FitOutcome) -> BTreeMap<String, ParamOut> {
    let mut out = BTreeMap::new();
    for r in &outcome.records {
        let se: Vec<serde_json::Value> = r
            .std_error
            .iter()
            .map(|e| e.map_or(serde_json::Value::Null, |x| serde_json::json!(x)))
            .collect();
        out.insert(
            r.name.clone(),
            ParamOut {
                value: number_or_rgb(&r.value),
                std_error: if se.len() == 1 {
                    se[0].clone()
                } else {
                    serde_json::Value::Array(se)
                },
                min: r.min,
                max: r.max,
                fixed: r.fixed,
                at_bound: r.at_bound.iter().any(|&b| b),
                fixed_reason: r.fixed_reason.clone().filter(|_| r.fixed),
                grey: r.grey,
                held: r.held.clone(),
                determined: (!r.fixed).then(|| {
                    let d: Vec<bool> = (0..r.value.len())
                        .map(|c| r.undetermined(c).is_none())
                        .collect();
                    match d.len() {
                        1 => serde_json::json!(d[0]),
                        _ => serde_json::json!(d),
                    }
                }),
                undetermined_reason: (!r.undetermined.is_empty()).then(|| {
                    match r.value.len() {
                        1 => serde_json::json!(r.undetermined(0)),
                        n => serde_json::json!((0..n)
                            .map(|c| r.undetermined(c))
                            .collect::<Vec<_>>()),
                    }
                }),
            },
        );
    }
    out
}

/// The values a result JSON says its data do not determine (`parameters.*.determined` false),
/// with the value used and why, in the parameters' order; none for a parameter file or a
/// result written before `determined` existed. A grey albedo (`grey: true`) is one value.
pub fn undetermined_in(v: &serde_json::Value) -> Vec<crate::fit::determined::Undetermined> {
    let mut out = Vec::new();
    let Some(params) = v.get("parameters").and_then(|p| p.as_object()) else {
        return out;
    };
    for (name, e) in params {
        let grey = e.get("grey").and_then(|g| g.as_bool()).unwrap_or(false);
        let as_list = |x: Option<&serde_json::Value>| -> Vec<serde_json::Value> {
            match x {
                Some(serde_json::Value::Array(a)) => a.clone(),
                Some(x) => vec![x.clone()],
                None => Vec::new(),
            }
        };
        let determined = as_list(e.get("determined"));
        let values = as_list(e.get("value"));
        let reasons = as_list(e.get("undetermined_reason"));
        for (c, d) in determined.iter().enumerate() {
            if d.as_bool() != Some(false) || (grey && c > 0) {
                continue;
            }
            let label = if determined.len() == 1 || grey {
                name.clone()
            } else {
                format!("{name}[{}]", ["r", "g", "b"][c.min(2)])
            };
            out.push(crate::fit::determined::Undetermined {
                label,
                value: values.get(c).and_then(|x| x.as_f64()).unwrap_or(f64::NAN),
                reason: reasons
                    .get(c)
                    .and_then(|x| x.as_str())
                    .unwrap_or("the result says so")
                    .to_string(),
            });
        }
    }
    out
}

/// [`undetermined_in`] of the result file at `path` (none when it is not a readable result).
pub fn undetermined_of(path: &Path) -> Vec<crate::fit::determined::Undetermined> {
    if path.is_dir() {
        return Vec::new();
    }
    crate::load::input::read_text_as(path, "result file")
        .ok()
        .and_then(|t| serde_json::from_str::<serde_json::Value>(&t).ok())
        .map(|v| undetermined_in(&v))
        .unwrap_or_default()
}

pub fn knobs(cfg: &FitConfig, stride: usize, fraction: f64) -> Knobs {
    Knobs {
        metric: format!("{:?}", cfg.metric).to_lowercase(),
        quadrature_order: cfg.knobs.quadrature_order,
        histogram_bins: cfg.knobs.histogram_bins,
        azimuth_nodes: cfg.knobs.azimuth_nodes,
        stride,
        fraction,
        fit_texels: cfg.knobs.fit_texels,
        topology_map: cfg
            .knobs
            .topology_map
            .as_ref()
            .map(|p| p.display().to_string()),
        topology_map_sha256: None,
        separable: cfg.optimizer.separable,
        starts: cfg.starts,
        seed: cfg.seed,
        metric_reason: cfg.metric_reason.clone(),
        gltf_variant: (cfg.model == crate::fit::config::ModelChoice::Rung(ModelId::Gltf))
            .then(|| cfg.knobs.gltf_variant.to_string()),
    }
}

/// Everything a fit decided, from which its result file is assembled ([`assemble`]).
pub struct ResultParts<'a> {
    /// The configuration of the fitted rung (auto's choice applied).
    pub config: &'a FitConfig,
    pub outcome: &'a FitOutcome,
    /// The fitted model (the rung at the outcome's shapes and the config's knobs).
    pub model: &'a dyn crate::model::ShadingModel,
    pub samples: &'a crate::load::samples::Samples,
    /// The data file fitted (its name and the hash of the bytes its loader read are recorded).
    pub data: &'a Path,
    /// The hash of data held in memory (no loader read `data`, which only names them).
    pub data_sha256: Option<String>,
    /// The loader's subsampling: keep every `stride`-th sample, then this fraction.
    pub stride: usize,
    pub fraction: f64,
    /// A capture's fit on a sample of texels, checked on every pixel.
    pub all_pixels: Option<&'a crate::fit::all_pixels::AllPixels>,
    pub selection: Option<&'a crate::fit::selection::SelectionOutcome>,
    /// Every warning of the run (the quality checks', the fallback's, configuring's notes).
    pub warnings: Vec<String>,
}

/// The BRDF of the fitted model `m` (the rung of `outcome` at its shapes) at each of
/// [`check_directions`], per channel (1/sr).
pub fn check_values(
    m: &dyn crate::model::ShadingModel,
    outcome: &FitOutcome,
    channels: usize,
) -> Vec<CheckValue> {
    let albedos = crate::fit::problem::albedos_of(&outcome.set);
    let psi = outcome
        .set
        .shape_value(crate::fit::parameters::Param::Azimuth)
        .to_radians();
    check_directions()
        .into_iter()
        .map(|d| CheckValue {
            theta_i: d[0],
            phi_i: d[1],
            theta_o: d[2],
            phi_o: d[3],
            brdf: crate::model::brdf_at_degrees(m, &albedos, psi, d, channels),
        })
        .collect()
}

/// A result's `correction` block of the kept correction `c`, with the rung's `check_values`
/// times its factor.
pub fn correction_block(
    c: &crate::fit::correction::CorrectionFit,
    rung: &[CheckValue],
) -> Result<serde_json::Value> {
    let k = &c.correction;
    let checks: Vec<serde_json::Value> = rung
        .iter()
        .map(|r| {
            let (ti, pi, to, po) = (
                r.theta_i.to_radians(),
                r.phi_i.to_radians(),
                r.theta_o.to_radians(),
                r.phi_o.to_radians(),
            );
            let f = k.factor_at(ti.cos(), to.cos(), (pi - po).cos());
            let brdf: Vec<f64> = r.brdf.iter().enumerate().map(|(ch, b)| b * f[ch.min(2)]).collect();
            serde_json::json!({
                "theta_i": r.theta_i, "phi_i": r.phi_i, "theta_o": r.theta_o, "phi_o": r.phi_o,
                "brdf": brdf,
            })
        })
        .collect();
    Ok(serde_json::json!({
        "note": "not a physical parameter: the rung's BRDF per channel times exp(sum_k c_k B_k), \
                 B_k = P_a(2 cos theta_i - 1) P_b(2 cos theta_o - 1) P_c(cos(phi_i - phi_o)) \
                 + P_b(2 cos theta_i - 1) P_a(2 cos theta_o - 1) P_c(cos(phi_i - phi_o)) for the \
                 term (a, b, c) (one product when a = b), P_n Legendre polynomials; cosines \
                 clamped to cos_range, the exponent to log_range per channel. Structure the \
                 rung misses and the data hold; the rung's parameters keep their meaning. \
                 series.instrument (k = 1..degree, if present): the coefficients of \
                 P_k(2 cos theta_i - 1) - P_k(2 cos theta_o - 1), the measuring instrument's \
                 light/view imbalance fitted beside the series (what of the data is not \
                 reciprocal), not part of the material: eval, renderers and exports leave it out",
        "series": k,
        "terms": crate::model::correction::terms(k.degree),
        "heldout": {
            "error": c.error,
            "standard_error": c.standard_error,
            "rung_error": c.rung_error,
            "rung_standard_error": c.rung_standard_error,
            "material_error": c.material_error,
            "reciprocal_floor": c.reciprocal_floor,
            "validation": c.validation,
            "metric": "log",
        },
        "tried": c.tried,
        "check_values": checks,
    }))
}

/// The result file of a fit (its maps block, if any, added by the maps stage).
pub fn assemble(p: ResultParts) -> Result<ResultFile> {
    use crate::load::samples::DataKind;
    let (cfg, outcome, samples) = (p.config, p.outcome, p.samples);
    let channels = samples.channels;
    let mut knobs = knobs(cfg, p.stride, p.fraction);
    if let Some(mp) = &outcome.map {
        knobs.topology_map = Some(
            std::fs::canonicalize(&mp.source)
                .unwrap_or(mp.source.clone())
                .display()
                .to_string(),
        );
        // of the bytes the fit read (read again only if no loader recorded them)
        knobs.topology_map_sha256 = Some(match crate::load::sha256_read(&mp.source) {
            Some(h) => h,
            None => {
                crate::load::input::read_input_as(
                    &mp.source,
                    crate::load::MAX_INPUT_BYTES,
                    "topology map",
                )?
                .sha256
            }
        });
    }
    let selection = p.selection;
    Ok(ResultFile {
        schema: SCHEMA.into(),
        tool: format!("fibrefit {}", env!("CARGO_PKG_VERSION")),
        model: cfg.model_id()?.to_string(),
        conventions: Conventions::default(),
        parameters: params_out(outcome),
        correlations: outcome
            .correlations
            .iter()
            .map(|(a, b, r)| Correlation {
                a: a.clone(),
                b: b.clone(),
                r: *r,
            })
            .collect(),
        statistics: {
            let mut v = serde_json::to_value(&outcome.statistics)?;
            if let Some(all) = p.all_pixels {
                v["all_pixels"] = serde_json::to_value(all)?;
            }
            v
        },
        knobs,
        data: Provenance {
            file: p
                .data
                .file_name()
                .map(|f| f.to_string_lossy().into_owned())
                .unwrap_or_default(),
            // of the bytes the loader read, not of the file as it is now
            sha256: match &p.data_sha256 {
                Some(h) => h.clone(),
                None => crate::load::sha256_read(p.data).ok_or_else(|| {
                    anyhow!("{}: its loader recorded no hash", p.data.display())
                })?,
            },
            kind: match samples.kind {
                DataKind::Gonio => "goniometric".into(),
                DataKind::Capture => "image capture".into(),
                DataKind::Measured => "measured BRDF file".into(),
            },
            samples: samples.samples.len(),
            channels,
        },
        check_values: check_values(p.model, outcome, channels),
        renderer_materials: Vec::new(),
        model_selection: selection
            .map(|s| {
                s.candidates
                    .iter()
                    .map(|c| serde_json::to_value(c).unwrap_or_default())
                    .collect()
            })
            .unwrap_or_default(),
        selection: selection.map(|s| {
            serde_json::json!({
                "validation": s.validation,
                "folds": s.folds,
                "rule": s.rule,
                "metric": s.metric,
                "chosen": s.chosen,
                "chosen_rung": s.chosen_rung,
                "fuzz": s.chosen_fuzz,
                "train_samples_per_fold": s.counts.train_samples_per_fold,
                "heldout_samples_per_fold": s.counts.heldout_samples_per_fold,
                "heldout_samples_total": s.counts.heldout_samples_total,
                "renderer_routes": crate::fit::selection::renderer_routes(s),
            })
        }),
        correction: match &outcome.correction {
            Some(c) => Some(correction_block(c, &check_values(p.model, outcome, channels))?),
            None => None,
        },
        quality: Some(serde_json::to_value(&outcome.quality)?),
        maps: None,
        warnings: p.warnings,
    })
}

/// A result's `maps` block for maps written into `dir`: the files, the method (with the
/// stages' work) and each map's summary.
pub fn maps_block(
    dir: &Path,
    cfg: &FitConfig,
    work: &crate::fit::maps::GlobalWork,
    run: &crate::fit::maps::TexelRun,
) -> Result<serde_json::Value> {
    let mut desc = super::maps_out::describe(dir, &cfg.maps.requested(), &run.maps);
    desc["method"] = work.method(cfg);
    desc["method"]["residual_variance"] = serde_json::json!(run.variance);
    desc["method"]["global_stage_iterations"] = serde_json::json!(work.iterations);
    desc["method"]["global_stage_seconds"] = serde_json::json!(work.seconds);
    desc["method"]["texel_stage_seconds"] = serde_json::json!(run.seconds);
    desc["summary"] = serde_json::to_value(&run.summaries)?;
    Ok(desc)
}

/// A result's `maps` block for `--map-globals` (the global stage only, shared by tiles).
pub fn globals_block(cfg: &FitConfig, work: &crate::fit::maps::GlobalWork) -> serde_json::Value {
    serde_json::json!({
        "stage": "globals",
        "requested": cfg.maps.requested(),
        "method": work.method(cfg),
    })
}
