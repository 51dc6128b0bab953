//! The fit configuration (TOML; examples in `configs/`): rung, parameters with value/min/max/vary,
//! residual metric, knobs, optimizer settings, starts and seed. Unknown keys, min > max and starts
//! outside their bounds are errors that name the key.

use crate::model::params::Albedo;
use crate::model::rungs::gltf::GltfVariant;
use crate::model::{ModelId, Param};
use anyhow::{anyhow, bail, Result};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

mod sections;
mod validate;
mod work;

pub use sections::*;
use sections::{default_metric, default_starts};
pub use work::*;

/// The residual a fit minimises the squares of.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Deserialize, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Metric {
    /// model - data (divided by sigma, or times sqrt(weight))
    Linear,
    /// ln(model + eps) - ln(data + eps), eps = 1 % of the channel's median value: relative
    /// errors, for data spanning decades (measured BRDFs with peaks); with sigmas the residual
    /// is scaled by (data + eps)/sigma, so near the data it equals the linear one
    Log,
    /// (model - data) cos(theta_i): residuals in intensity, as a shader sees them
    Cosine,
}

/// One parameter's entry: `value` (start), `min`, `max`, `vary`, and for `ks` only `colour`.
#[derive(Clone, Debug, Default, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct ParamEntry {
    pub value: Option<Albedo>,
    pub min: Option<f64>,
    pub max: Option<f64>,
    pub vary: Option<bool>,
    /// `ks` only: `true` fits the specular weight per channel of RGB data. By default (`false`)
    /// it is one grey value shared by the channels: a dielectric fibre's surface reflection is
    /// colourless, and the dye's colour lives in the albedos (kd, the substrate, the fuzz layer).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub colour: Option<bool>,
}

/// What a fit fits: one rung, or `auto` (every candidate rung, chosen by held-out error).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Deserialize, Serialize)]
#[serde(try_from = "String", into = "String")]
pub enum ModelChoice {
    /// Every candidate rung, chosen by held-out error.
    Auto,
    /// One rung.
    Rung(ModelId),
}

impl ModelChoice {
    /// Whether this is `auto`.
    pub fn is_auto(self) -> bool {
        self == ModelChoice::Auto
    }
}

impl std::str::FromStr for ModelChoice {
    type Err = String;
    fn from_str(s: &str) -> std::result::Result<Self, String> {
        match s {
            "auto" => Ok(ModelChoice::Auto),
            _ => s.parse().map(ModelChoice::Rung),
        }
    }
}

impl TryFrom<String> for ModelChoice {
    type Error = String;
    fn try_from(s: String) -> std::result::Result<Self, String> {
        s.parse()
    }
}

impl From<ModelChoice> for String {
    fn from(m: ModelChoice) -> String {
        m.to_string()
    }
}

impl std::fmt::Display for ModelChoice {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            ModelChoice::Auto => f.write_str("auto"),
            ModelChoice::Rung(id) => write!(f, "{id}"),
        }
    }
}

/// A fit configuration (TOML, `configs/`): the rung, parameters, metric, knobs, optimizer,
/// starts, seed, maps, components and model selection.
#[derive(Clone, Debug, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct FitConfig {
    /// A rung, or `auto` (model selection).
    pub model: ModelChoice,
    /// The residual metric.
    #[serde(default = "default_metric")]
    pub metric: Metric,
    /// Local polishing runs started from the best candidates of the global stage.
    #[serde(default = "default_starts")]
    pub starts: usize,
    /// Seed of every random choice (starts, subsamples, folds): a fit is repeatable.
    #[serde(default)]
    pub seed: u64,
    /// Evaluation knobs (quadrature, histogram, subsampling).
    #[serde(default)]
    pub knobs: Knobs,
    /// Optimizer settings (LM iterations and tolerance, global search).
    #[serde(default)]
    pub optimizer: Optimizer,
    /// Listed parameters by name: start, bounds, free or fixed.
    #[serde(default)]
    pub parameters: BTreeMap<String, ParamEntry>,
    /// Switch model components on and off, so a scene pays only for what it needs.
    #[serde(default)]
    pub components: Components,
    /// `--model auto`: how rungs are compared.
    #[serde(default)]
    pub selection: Selection,
    /// Per-texel maps recovered from an image capture (`fibrefit fit --maps DIR`).
    #[serde(default)]
    pub maps: MapsConfig,
    /// `[columns]`: a goniometric CSV's own column names, `ours = "theirs"` (as `--columns`).
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub columns: BTreeMap<String, String>,
    /// `[data]`: how the lab's goniometric tables are written (`angles = "rad"`, as `--angles`).
    #[serde(default, skip_serializing_if = "DataSection::is_default")]
    pub data: DataSection,
    /// What configuring decided that the user should read (parameters another rung lacks,
    /// ignored): shown with the fit's warnings. Not a key of the file.
    #[serde(skip)]
    pub notes: Vec<String>,
    /// Neither the file nor `--metric` named the metric: the fit takes the one the data ask for
    /// (`metric_for_data`, applied by `api::fit`). Not a key of the file.
    #[serde(skip)]
    pub metric_follows_data: bool,
    /// Why the fit uses its metric (said in the report and the result). Not a key of the file.
    #[serde(skip)]
    pub metric_reason: Option<String>,
    /// Keep a fitted fibre-direction spread free even where the data cannot tell it from 0
    /// (`fit::spread_hold` not tried): `--model auto`'s candidate fits, which rank each rung as
    /// fitted; the chosen one's final fit is held. Not a key of the file.
    #[serde(skip)]
    pub keep_free_spread: bool,
    /// The knobs of the global stage's subsample problem, where they differ from `knobs`:
    /// `--model auto`'s final fit searches at the ranking knobs its candidates were compared at
    /// (the basins are where they were found; the final stage polishes each at `knobs` on all
    /// samples). None: the global stage uses `knobs`. Not a key of the file.
    #[serde(skip)]
    pub search_knobs: Option<Knobs>,
}

/// The one parameter with a colour choice (`[parameters] ks = { colour = true }`): the specular
/// weight of the fibre rungs, grey unless asked.
pub const COLOUR_CHOICE: Param = Param::Ks;

/// How many of the data's positive values must lie above the 99th over the 1st percentile for
/// the metric to follow the data into the log metric: an order of magnitude.
pub const LOG_METRIC_SPAN: f64 = 10.0;

/// The metric the data ask for when neither the config nor `--metric` names one: the log metric
/// when the data carry no sigmas and their positive values span more than an order of
/// magnitude (99th over 1st percentile above [`LOG_METRIC_SPAN`]), else the linear one; with
/// the reason, in words.
pub fn metric_for_data(samples: &crate::load::samples::Samples) -> (Metric, String) {
    let ch = samples.channels.max(1);
    if !samples.samples.is_empty() && samples.samples.iter().all(|s| s.sigma.is_some()) {
        return (
            Metric::Linear,
            "linear: the data give sigmas (chi-square against their noise)".into(),
        );
    }
    let mut v: Vec<f64> = samples
        .samples
        .iter()
        .flat_map(|s| s.value[..ch].iter().copied())
        .filter(|x| *x > 0.0 && x.is_finite())
        .collect();
    if v.len() < 2 {
        return (
            Metric::Linear,
            "linear: too few positive values to measure their span".into(),
        );
    }
    v.sort_by(f64::total_cmp);
    let at = |q: f64| v[((v.len() - 1) as f64 * q).round() as usize];
    let span = at(0.99) / at(0.01);
    match span > LOG_METRIC_SPAN {
        true => (
            Metric::Log,
            format!(
                "log, chosen from the data: no sigmas and the values span {span:.0}x (99th over \
                 1st percentile of the positive values, above {LOG_METRIC_SPAN:.0}x); --metric \
                 linear overrides"
            ),
        ),
        false => (
            Metric::Linear,
            format!(
                "linear, chosen from the data: the values span {span:.1}x (99th over 1st \
                 percentile, at most {LOG_METRIC_SPAN:.0}x); --metric log overrides"
            ),
        ),
    }
}

impl FitConfig {
    /// Whether `[parameters]` lists `p`.
    pub fn lists(&self, p: Param) -> bool {
        self.parameters.contains_key(p.name())
    }

    /// The first fuzz-layer parameter `[parameters]` lists (the layer is on when any is).
    pub fn listed_fuzz_parameter(&self) -> Option<Param> {
        crate::model::parameter::fuzz_parameters().find(|&p| self.lists(p))
    }

    /// Switch the fuzz layer on (its parameters at their defaults unless listed).
    pub fn add_fuzz_layer(&mut self) {
        self.parameters
            .entry(Param::FuzzDepth.name().into())
            .or_default();
    }

    /// Read and validate a config file (errors name the file and key).
    pub fn load(path: &Path) -> Result<Self> {
        let text = crate::load::input::read_text_as(path, "fit config")?;
        let mut cfg: FitConfig = toml::from_str(&text)
            .map_err(|e| anyhow!("{}: {}", path.display(), e.to_string().trim_end()))?;
        // a file that names no metric lets the data choose it
        cfg.metric_follows_data = toml::from_str::<toml::Table>(&text)
            .map(|t| !t.contains_key("metric"))
            .unwrap_or(false);
        if let Some(map) = cfg.knobs.topology_map.clone() {
            // relative to the config's folder, wherever fibrefit runs: say so when it is missing
            let resolved = match map.is_relative() {
                true => path.parent().unwrap_or(Path::new(".")).join(&map),
                false => map.clone(),
            };
            if cfg.components.topology_map && !resolved.exists() {
                let folder = path.parent().filter(|p| !p.as_os_str().is_empty());
                let folder = folder
                    .and_then(|p| std::fs::canonicalize(p).ok())
                    .unwrap_or_else(|| std::env::current_dir().unwrap_or_default());
                let shown = match map.is_relative() {
                    true => folder.join(&map),
                    false => map.clone(),
                };
                bail!(
                    "{}: knobs.topology_map = {:?}: no such file {}{}",
                    path.display(),
                    map.display().to_string(),
                    shown.display(),
                    if map.is_relative() {
                        format!(
                            " (a relative path in a config is resolved relative to the config's folder, {}, \
                             not the working directory)",
                            folder.display()
                        )
                    } else {
                        String::new()
                    }
                );
            }
            cfg.knobs.topology_map = Some(resolved);
        }
        cfg.validate()
            .map_err(|e| anyhow!("{}: {e}", path.display()))?;
        Ok(cfg)
    }

    /// The rung (an error for `auto`, which has none until chosen).
    pub fn model_id(&self) -> Result<ModelId> {
        match self.model {
            ModelChoice::Rung(id) => Ok(id),
            ModelChoice::Auto => "auto".parse().map_err(|e: String| anyhow!("`model`: {e}")),
        }
    }

    /// This config with `model` set to `id`, keeping only the parameters that rung has. From an
    /// `auto` config, every shape parameter of the rung the config does not list is free
    /// ([`FitConfig::free_unlisted_shapes`]).
    pub fn for_rung(&self, id: ModelId) -> FitConfig {
        let mut c = self.clone();
        c.model = ModelChoice::Rung(id);
        let allowed = id.parameter_names();
        c.parameters.retain(|k, _| allowed.contains(&k.as_str()));
        if self.model.is_auto() {
            c.free_unlisted_shapes(id);
        }
        c
    }

    /// Free every shape parameter of rung `id` that `[parameters]` does not list, over its whole
    /// range (MODEL.md §5) from its default start: `exponent` [1, 1e4] from 20 (fitted in log
    /// space), `spacing` [2, 20] from 2, `height` [0, H_max(d)] from H_max(2)/2 = 0.866,
    /// `map_scale` [0, H_max(d)] from 0, `fibre_azimuth_deg` over its period (180 deg, periodic)
    /// from 0, `azimuth_spread_deg` [0, 180] from 0, `alpha_x`, `alpha_y` [0.0011, 1] from 0.2
    /// (log space). The albedos are always free (solved exactly); the Fresnel factor and the fuzz
    /// layer stay off unless listed. What the data fix anyway (a fibre direction every sample
    /// carries) and what `[components]` switch off are still held fixed, and the report says why.
    /// `--model auto` and a named rung without a config fit this way.
    pub fn free_unlisted_shapes(&mut self, id: ModelId) {
        // the albedos (solved, always free), the Fresnel factor and the fuzz layer (optional
        // components) are freed only when listed
        for p in id.parameters() {
            if !p.info().listed_only {
                self.parameters
                    .entry(p.name().to_string())
                    .or_insert(ParamEntry {
                        vary: Some(true),
                        ..Default::default()
                    });
            }
        }
    }

    /// The `gltf` rung's variant: `variant` when given (`--gltf-variant`, the Python `fit`'s
    /// `gltf_variant`), else the config's `knobs.gltf_variant`. `threejs` fits only the `gltf`
    /// rung. three.js tints its direct specular's multiple-scattering factor with F0 =
    /// mix(F0, base colour, metallic), so its BRDF is quadratic in the base colour once
    /// metallic > 0: the global fit solves that exactly (`FitProblem::solve_albedos`), the
    /// per-texel maps' linear solves do not, so with `[maps]` a threejs fit holds `metallic` at 0
    /// (a config giving it another value, or bounds, is refused).
    pub fn apply_gltf_variant(&mut self, variant: Option<GltfVariant>) -> Result<()> {
        if let Some(v) = variant {
            self.knobs.gltf_variant = v;
        }
        let v = self.knobs.gltf_variant;
        if v.is_khronos() {
            return Ok(());
        }
        match self.model {
            ModelChoice::Rung(ModelId::Gltf) => {}
            ModelChoice::Auto => bail!(
                "gltf_variant = {v}: fit it with --model gltf (auto compares the rungs with the \
                 gltf rung as the Khronos specification defines it)"
            ),
            ModelChoice::Rung(id) => {
                bail!("gltf_variant = {v} is a knob of the gltf rung; model `{id}` has no variant")
            }
        }
        if self.maps.requested().is_empty() {
            return Ok(());
        }
        let name = Param::Metallic.name();
        if let Some(e) = self.parameters.get(name) {
            let nonzero = e.value.is_some_and(|a| a.channels() != [0.0; 3]);
            if nonzero || e.min.is_some() || e.max.is_some() {
                bail!(
                    "parameters.{name}: gltf_variant = {v} with [maps] holds metallic at 0 (three.js's \
                     BRDF is quadratic in the base colour once metallic > 0, and the per-texel \
                     maps solve the base colour linearly); remove `{name}` from [parameters], the \
                     maps, or fit the khronos variant"
                );
            }
        }
        self.parameters.insert(
            name.to_string(),
            ParamEntry {
                value: Some(Albedo::Grey(0.0)),
                vary: Some(false),
                ..Default::default()
            },
        );
        Ok(())
    }

    /// `--model id` over a config written for another rung: drop the parameters `id` lacks, with
    /// one note naming them. A name that is no rung's parameter (a typo) is still refused.
    pub fn retarget(&mut self, id: ModelId) -> Result<()> {
        let allowed = id.parameter_names();
        let mut ignored = Vec::new();
        for name in self.parameters.keys() {
            if allowed.contains(&name.as_str()) {
                continue;
            }
            if !ModelId::ALL
                .iter()
                .any(|r| r.parameter_names().contains(&name.as_str()))
            {
                bail!(
                    "parameters.{name}: not a parameter of any rung (of `{id}`: {})",
                    allowed.join(", ")
                );
            }
            ignored.push(name.clone());
        }
        if !ignored.is_empty() {
            self.parameters.retain(|k, _| allowed.contains(&k.as_str()));
            self.notes.push(format!(
                "--model {id}: the config's parameters {} are not parameters of `{id}` and are ignored",
                ignored
                    .iter()
                    .map(|n| format!("`{n}`"))
                    .collect::<Vec<_>>()
                    .join(", ")
            ));
        }
        self.model = ModelChoice::Rung(id);
        Ok(())
    }
}
