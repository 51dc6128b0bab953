//! The fit configuration (TOML; examples in `configs/`): rung, parameters with value/min/max/vary,
//! residual metric, knobs, optimizer settings, starts and seed. Unknown keys, min > max and starts
//! outside their bounds are errors that name the key.

use crate::model::params::Albedo;
use crate::model::{ModelId, Param};
use anyhow::{anyhow, bail, Result};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

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

#[derive(Clone, Debug, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Knobs {
    #[serde(default = "default_order")]
    pub quadrature_order: usize,
    #[serde(default = "default_bins")]
    pub histogram_bins: usize,
    /// Image captures: every `stride`-th pixel in x and y.
    #[serde(default = "one_usize")]
    pub stride: usize,
    /// Image captures: seeded random fraction of pixels kept.
    #[serde(default = "one_f64")]
    pub fraction: f64,
    /// Nodes of the fibre-direction spread quadrature (used when `azimuth_spread_deg` > 0).
    #[serde(default = "default_azimuth_nodes")]
    pub azimuth_nodes: usize,
    /// Image captures: the global fit uses at most this many texels (a seeded sample, every
    /// image's pixel of each), the statistics over every pixel are computed after; 0: every
    /// texel. A capture at camera resolution over-determines the few global parameters many
    /// times over: their standard errors, from the sample, are honest and only wider.
    #[serde(default = "default_fit_texels")]
    pub fit_texels: usize,
    /// Topology map for goniometric spots (the spot averages over its histogram); relative to
    /// the config file. Image captures carry their own.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub topology_map: Option<PathBuf>,
}

/// Texels of a capture's global fit by default (8 images: 262 144 pixel values).
pub const DEFAULT_FIT_TEXELS: usize = 32_768;

fn default_fit_texels() -> usize {
    DEFAULT_FIT_TEXELS
}

impl Default for Knobs {
    fn default() -> Self {
        Self {
            quadrature_order: 16,
            histogram_bins: 16,
            stride: 1,
            fraction: 1.0,
            azimuth_nodes: default_azimuth_nodes(),
            fit_texels: default_fit_texels(),
            topology_map: None,
        }
    }
}

#[derive(Clone, Debug, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Optimizer {
    /// Levenberg–Marquardt iterations per start.
    #[serde(default = "default_iterations")]
    pub max_iterations: u64,
    /// Stop when the relative decrease of the cost in an iteration is below this.
    #[serde(default = "default_tolerance")]
    pub tolerance: f64,
    /// Candidates costed by the global stage (a seeded Latin-hypercube design over the shape
    /// parameters); default 32 + 24 per free shape parameter.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub global_candidates: Option<usize>,
    /// Samples (randomly chosen, seeded) the global stage and the start polishing use.
    #[serde(default = "default_subsample")]
    pub global_subsample: usize,
    /// Solve the albedos exactly inside every step (separable least squares). Off: the albedos
    /// are ordinary parameters of the Levenberg–Marquardt iteration.
    #[serde(default = "yes")]
    pub separable: bool,
}

impl Default for Optimizer {
    fn default() -> Self {
        Self {
            max_iterations: default_iterations(),
            tolerance: default_tolerance(),
            global_candidates: None,
            global_subsample: default_subsample(),
            separable: true,
        }
    }
}

/// Most quadrature nodes of one model evaluation (`quadrature_order` x `azimuth_nodes`): 2^16,
/// 256 times the default 16 x 16. Each knob alone may reach its own maximum (1024).
pub const MAX_NODES_PER_EVALUATION: usize = 1 << 16;
/// Most candidates of the global stage (`optimizer.global_candidates`).
pub const MAX_GLOBAL_CANDIDATES: usize = 100_000;
/// Most samples the global stage costs each candidate on (`optimizer.global_subsample`).
pub const MAX_GLOBAL_SUBSAMPLE: usize = 1_000_000;
/// Most polishing starts (`starts`).
pub const MAX_STARTS: usize = 1_000;
/// Most Levenberg-Marquardt iterations per start (`optimizer.max_iterations`).
pub const MAX_ITERATIONS: u64 = 100_000;

/// Most sample evaluations a fit may plan ([`FitConfig::check_work`]): 1e10, about 8 hours on
/// 2 cores at the rate of the shipped silk fit (5.4e5 planned in 1.5 s).
pub const MAX_PLANNED_EVALUATIONS: f64 = 1e10;

/// Samples a worker thread evaluates together (the fit's batches).
pub const EVALUATION_BATCH: usize = 512;
/// Scratch bytes per sample and histogram bin of a batch of varying-topology evaluations (four
/// fibre occlusion problems of twelve f64 each, their gap ends and arcs), rounded up.
pub const SCRATCH_PER_BIN: f64 = 1024.0;
/// Most scratch memory a fit's model evaluations may take per worker thread: 1 GiB.
pub const MAX_SCRATCH_BYTES: u64 = 1 << 30;

/// [`FitConfig::planned_scratch_bytes`] of one rung with `histogram_bins`, for `samples`
/// evaluated in batches (what `score` plans for a result's knobs).
pub fn scratch_bytes(rung: ModelId, histogram_bins: usize, samples: usize) -> f64 {
    if !rung.reads(Param::HistogramBins) {
        return 0.0;
    }
    samples.min(EVALUATION_BATCH) as f64 * histogram_bins as f64 * SCRATCH_PER_BIN
}

/// Refuse evaluating rung `rung` with `histogram_bins` on `samples` samples when its scratch
/// memory per thread ([`scratch_bytes`]) is beyond [`MAX_SCRATCH_BYTES`], with the estimate.
pub fn check_scratch(rung: ModelId, histogram_bins: usize, samples: usize) -> Result<()> {
    let bytes = scratch_bytes(rung, histogram_bins, samples);
    if bytes > MAX_SCRATCH_BYTES as f64 {
        bail!(
            "evaluating `{rung}` with histogram_bins = {histogram_bins} would take about {:.1} GiB \
             of memory per thread ({} samples a batch x {histogram_bins} x {SCRATCH_PER_BIN} bytes): \
             more than the {} GiB allowed per thread",
            bytes / (1u64 << 30) as f64,
            samples.min(EVALUATION_BATCH),
            MAX_SCRATCH_BYTES >> 30
        );
    }
    Ok(())
}

/// Candidates of the global stage when the config does not say: 32 plus 24 per free shape
/// parameter.
pub fn default_candidates(dim: usize) -> usize {
    32 + 24 * dim
}

fn default_azimuth_nodes() -> usize {
    crate::model::azimuth_spread::DEFAULT_AZIMUTH_NODES
}
fn default_order() -> usize {
    16
}
fn default_bins() -> usize {
    16
}
fn one_usize() -> usize {
    1
}
fn one_f64() -> f64 {
    1.0
}
fn default_iterations() -> u64 {
    100
}
fn default_tolerance() -> f64 {
    1e-9
}
fn default_subsample() -> usize {
    600
}
fn yes() -> bool {
    true
}
fn default_starts() -> usize {
    6
}

/// What a fit fits: one rung, or `auto` (every candidate rung, chosen by held-out error).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Deserialize, Serialize)]
#[serde(try_from = "String", into = "String")]
pub enum ModelChoice {
    Auto,
    Rung(ModelId),
}

impl ModelChoice {
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

#[derive(Clone, Debug, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct FitConfig {
    /// A rung, or `auto` (model selection).
    pub model: ModelChoice,
    #[serde(default = "default_metric")]
    pub metric: Metric,
    /// Local polishing runs started from the best candidates of the global stage.
    #[serde(default = "default_starts")]
    pub starts: usize,
    #[serde(default)]
    pub seed: u64,
    #[serde(default)]
    pub knobs: Knobs,
    #[serde(default)]
    pub optimizer: Optimizer,
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
    /// What configuring decided that the user should read (parameters another rung lacks,
    /// ignored): shown with the fit's warnings. Not a key of the file.
    #[serde(skip)]
    pub notes: Vec<String>,
    /// Neither the file nor `--metric` named the metric: the fit takes the one the data ask for
    /// ([`metric_for_data`], applied by `api::fit`). Not a key of the file.
    #[serde(skip)]
    pub metric_follows_data: bool,
    /// Why the fit uses its metric (said in the report and the result). Not a key of the file.
    #[serde(skip)]
    pub metric_reason: Option<String>,
}

/// The one parameter with a colour choice (`[parameters] ks = { colour = true }`): the specular
/// weight of the fibre rungs, grey unless asked.
pub const COLOUR_CHOICE: Param = Param::Ks;

/// `[maps]`: which per-texel maps `fit --maps` recovers beside the global parameters, and how.
#[derive(Clone, Debug, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct MapsConfig {
    /// Per-texel height H (the topology map), fibre radii (varying-topology, reference).
    #[serde(default)]
    pub height: bool,
    /// Per-texel fibre azimuth psi (the tangent map), degrees (every rung but lambert).
    #[serde(default)]
    pub fibre_azimuth: bool,
    /// Per-texel diffuse albedo kd (Ward: rho_d), per channel.
    #[serde(default)]
    pub kd: bool,
    /// Per-texel specular weight ks (Ward: rho_s), per channel.
    #[serde(default)]
    pub ks: bool,
    /// Alternations of (global fit given the maps, per-texel fits given the globals) at most;
    /// they stop earlier when the total cost falls by less than 1e-6 of itself.
    #[serde(default = "default_map_rounds")]
    pub rounds: usize,
    /// Texels (seeded sample) the global fit given the maps uses.
    #[serde(default = "default_global_texels")]
    pub global_texels: usize,
    /// Weight of the optional smoothness prior (0: off): per texel, w * (u - mean of its 4
    /// neighbours)^2 per nonlinear map value u (H in fibre radii, psi in units of 10 degrees),
    /// added to the texel's cost, for texels the images leave undetermined.
    #[serde(default)]
    pub smoothness: f64,
}

fn default_map_rounds() -> usize {
    20
}

fn default_global_texels() -> usize {
    512
}

impl Default for MapsConfig {
    fn default() -> Self {
        Self {
            height: false,
            fibre_azimuth: false,
            kd: false,
            ks: false,
            rounds: default_map_rounds(),
            global_texels: default_global_texels(),
            smoothness: 0.0,
        }
    }
}

impl MapsConfig {
    /// Names of the maps requested, in output order.
    pub fn requested(&self) -> Vec<&'static str> {
        [
            ("height", self.height),
            ("fibre_azimuth", self.fibre_azimuth),
            ("kd", self.kd),
            ("ks", self.ks),
        ]
        .into_iter()
        .filter(|x| x.1)
        .map(|x| x.0)
        .collect()
    }
}

/// Model components (applied on top of `[parameters]`).
#[derive(Clone, Debug, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Components {
    /// false: ks fixed at 0 (no specular lobe).
    #[serde(default = "yes")]
    pub specular: bool,
    /// false: ignore `knobs.topology_map` (spots see a uniform height spread).
    #[serde(default = "yes")]
    pub topology_map: bool,
    /// "tied" (shares kd, the default unless `substrate_albedo` is listed), "free", or "off"
    /// (albedo 0).
    #[serde(default)]
    pub substrate: Option<String>,
    /// false: spacing fixed at 2 (touching fibres).
    #[serde(default)]
    pub spacing_free: Option<bool>,
}

impl Default for Components {
    fn default() -> Self {
        Self {
            specular: true,
            topology_map: true,
            substrate: None,
            spacing_free: None,
        }
    }
}

#[derive(Clone, Debug, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Selection {
    /// Rungs tried by `--model auto`, cheapest first.
    #[serde(default = "default_rungs")]
    pub rungs: Vec<String>,
    /// Fraction of samples held out (seeded split) when the data are many (at least
    /// `cv_below` samples); fewer are cross-validated instead.
    #[serde(default = "default_holdout")]
    pub holdout: f64,
    /// Relative tolerance on the cross-validated error: with it, the simplest candidate within
    /// this fraction of the best error is chosen instead of the one within one standard error.
    pub tolerance: Option<f64>,
    /// Folds of the k-fold cross-validation (every sample held out once) used below `cv_below`
    /// samples.
    #[serde(default = "default_folds")]
    pub folds: usize,
    /// Data with fewer samples than this are cross-validated in `folds` folds; from this many
    /// on, one seeded split holds out `holdout` of them.
    #[serde(default = "default_cv_below")]
    pub cv_below: usize,
    /// Try every rung with and without the fuzz layer (false, or `--no-fuzz`: only without,
    /// unless `--fuzz` or `[parameters]` asks for the layer, which then goes over every rung).
    #[serde(default = "yes")]
    pub fuzz: bool,
    /// The candidates are ranked on at most this many samples (seeded) with coarse knobs; those
    /// within reach of the best are refined at the config's knobs.
    #[serde(default = "default_rank_samples")]
    pub rank_samples: usize,
    /// Rank with coarse knobs first ([`crate::fit::selection::ranking_config`]); false: every
    /// candidate is measured at the config's knobs (slower, for comparison).
    #[serde(default = "yes")]
    pub coarse_ranking: bool,
}

impl Default for Selection {
    fn default() -> Self {
        Self {
            rungs: default_rungs(),
            holdout: default_holdout(),
            tolerance: None,
            folds: default_folds(),
            cv_below: default_cv_below(),
            fuzz: true,
            rank_samples: default_rank_samples(),
            coarse_ranking: true,
        }
    }
}

fn default_folds() -> usize {
    5
}

fn default_cv_below() -> usize {
    2000
}

fn default_rank_samples() -> usize {
    1000
}

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

fn default_rungs() -> Vec<String> {
    crate::model::rungs::auto_candidates()
        .iter()
        .map(|id| id.to_string())
        .collect()
}

fn default_holdout() -> f64 {
    0.2
}

fn default_metric() -> Metric {
    Metric::Linear
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

    pub fn model_id(&self) -> Result<ModelId> {
        match self.model {
            ModelChoice::Rung(id) => Ok(id),
            ModelChoice::Auto => "auto".parse().map_err(|e: String| anyhow!("`model`: {e}")),
        }
    }

    /// The work a fit of `samples` samples plans at most, in sample evaluations at the default
    /// quadrature: per rung tried, the global stage (candidates x subsample), the polishing of
    /// every start (starts x iterations x subsample) and the final run on all samples
    /// (iterations x samples), scaled by the quadrature nodes per evaluation over the default's.
    pub fn planned_evaluations(&self, samples: usize) -> f64 {
        let n = samples as f64;
        let sub = (self.optimizer.global_subsample as f64).min(n);
        let candidates = self
            .optimizer
            .global_candidates
            .unwrap_or_else(|| default_candidates(8)) as f64;
        let iterations = self.optimizer.max_iterations as f64;
        if let ModelChoice::Rung(id) = self.model {
            return (candidates * sub + self.starts as f64 * iterations * sub + iterations * n)
                * self.cost_per_evaluation(Some(id));
        }
        // auto: per candidate (each rung, with and without the fuzz layer) a fit on the ranking
        // samples and a warm-started refit per fold, plus the chosen one's fit on all samples
        // (the costliest rung's, as any may be chosen)
        let per_rung = if self.selection.fuzz { 2.0 } else { 1.0 };
        let rungs = self.auto_rungs();
        let tried: f64 = match rungs.is_empty() {
            true => self.cost_per_evaluation(None),
            false => rungs
                .iter()
                .map(|&r| self.cost_per_evaluation(Some(r)))
                .sum(),
        } * per_rung;
        let costliest = rungs
            .iter()
            .map(|&r| self.cost_per_evaluation(Some(r)))
            .fold(self.cost_per_evaluation(None), f64::max);
        let rank = n.min(self.selection.rank_samples as f64);
        let folds = self.selection.folds as f64;
        tried
            * (candidates * sub
                + self.starts as f64 * iterations * sub
                + iterations * rank
                + folds * iterations * rank)
            + (candidates * sub + self.starts as f64 * iterations * sub + iterations * n)
                * costliest
    }

    /// Whether the rung, or a rung `auto` tries, integrates over a height histogram.
    fn histogram_rungs(&self) -> bool {
        let rungs = match self.model {
            ModelChoice::Auto => self.auto_rungs(),
            ModelChoice::Rung(id) => vec![id],
        };
        rungs.iter().any(|&r| r.reads(Param::HistogramBins))
    }

    /// The rungs an `auto` fit tries (those of `selection.rungs` that parse).
    fn auto_rungs(&self) -> Vec<ModelId> {
        self.selection
            .rungs
            .iter()
            .filter_map(|r| r.parse().ok())
            .collect()
    }

    /// The cost of one sample evaluation of rung `id` (`None`: one that reads no histogram)
    /// over the default's: the quadrature nodes (`quadrature_order` x `azimuth_nodes`), times
    /// `histogram_bins` / 16 for a rung that integrates over a height histogram; at least 1.
    fn cost_per_evaluation(&self, id: Option<ModelId>) -> f64 {
        let nodes = (self.knobs.quadrature_order * self.knobs.azimuth_nodes) as f64 / 256.0;
        let bins = match id {
            Some(id) if id.reads(Param::HistogramBins) => self.knobs.histogram_bins as f64 / 16.0,
            _ => 1.0,
        };
        (nodes * bins.max(1.0)).max(1.0)
    }

    /// The scratch memory one worker thread's model evaluations take at most, in bytes, for a
    /// fit of `samples` samples: a rung that integrates over a height histogram (the varying
    /// topology) solves, per batch of up to [`EVALUATION_BATCH`] samples, every fibre of every
    /// bin at once, [`SCRATCH_PER_BIN`] bytes per sample and bin; other rungs take little.
    pub fn planned_scratch_bytes(&self, samples: usize) -> f64 {
        if !self.histogram_rungs() {
            return 0.0;
        }
        samples.min(EVALUATION_BATCH) as f64 * self.knobs.histogram_bins as f64 * SCRATCH_PER_BIN
    }

    /// Refuse, before the fit (and before any allocation), a plan beyond
    /// [`MAX_PLANNED_EVALUATIONS`] or [`MAX_SCRATCH_BYTES`], with the estimate; for a named
    /// rung and for `auto` (every rung it tries) alike.
    pub fn check_work(&self, samples: usize) -> Result<()> {
        let planned = self.planned_evaluations(samples);
        if planned > MAX_PLANNED_EVALUATIONS {
            bail!(
                "this fit plans up to {planned:.2e} sample evaluations ({samples} samples; starts = {}, \
                 optimizer.max_iterations = {}, global_candidates = {}, global_subsample = {}, \
                 quadrature_order x azimuth_nodes = {}{}{}): more than the {MAX_PLANNED_EVALUATIONS:.0e} \
                 a fit may take (about 8 hours on 2 cores); lower them or subsample the data",
                self.starts,
                self.optimizer.max_iterations,
                self.optimizer
                    .global_candidates
                    .map_or("default".to_string(), |c| c.to_string()),
                self.optimizer.global_subsample,
                self.knobs.quadrature_order * self.knobs.azimuth_nodes,
                if self.model.is_auto() {
                    format!(", {} rungs tried", self.selection.rungs.len())
                } else {
                    String::new()
                },
                if self.histogram_rungs() {
                    format!(", histogram_bins = {}", self.knobs.histogram_bins)
                } else {
                    String::new()
                }
            );
        }
        let scratch = self.planned_scratch_bytes(samples);
        if scratch > MAX_SCRATCH_BYTES as f64 {
            bail!(
                "this fit's model evaluations would take about {:.1} GiB of memory per thread \
                 ({} samples a batch x knobs.histogram_bins = {} x {SCRATCH_PER_BIN} bytes{}): more \
                 than the {} GiB a fit may take per thread; lower knobs.histogram_bins",
                scratch / (1u64 << 30) as f64,
                samples.min(EVALUATION_BATCH),
                self.knobs.histogram_bins,
                if self.model.is_auto() {
                    " for the varying-topology candidate"
                } else {
                    ""
                },
                MAX_SCRATCH_BYTES >> 30
            );
        }
        Ok(())
    }

    /// Checks that need no data: names, bounds, starts, knob ranges.
    pub fn validate(&self) -> Result<()> {
        if !self.model.is_auto() {
            return self.validate_rung();
        }
        // `auto`: each rung sees only its own parameters, so check the names against all rungs
        // here, or a misspelt one would be dropped silently
        let rungs: Vec<ModelId> = self
            .selection
            .rungs
            .iter()
            .map(|r| {
                r.parse()
                    .map_err(|e: String| anyhow!("selection.rungs: {e}"))
            })
            .collect::<Result<_>>()?;
        for name in self.parameters.keys() {
            if !rungs
                .iter()
                .any(|&r| r.parameter_names().contains(&name.as_str()))
            {
                let ids: Vec<&str> = rungs.iter().map(|r| r.as_str()).collect();
                bail!(
                    "parameters.{name}: not a parameter of any rung in selection.rungs ({})",
                    ids.join(", ")
                );
            }
        }
        for &r in &rungs {
            self.for_rung(r).validate_rung()?;
        }
        Ok(())
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

    fn validate_rung(&self) -> Result<()> {
        let id = self.model_id()?;
        let allowed = id.parameter_names();
        for (name, e) in &self.parameters {
            if !allowed.contains(&name.as_str()) {
                bail!(
                    "parameters.{name}: not a parameter of `{id}`; its parameters are {}",
                    allowed.join(", ")
                );
            }
            if e.colour.is_some() && name != COLOUR_CHOICE.name() {
                bail!(
                    "parameters.{name}.colour: only `{COLOUR_CHOICE}` has a colour choice (the \
                     albedos kd, substrate_albedo and fuzz are always fitted per channel: the dye's \
                     colour lives there; shape parameters have no colour)"
                );
            }
            // a fixed `ks` may be RGB (it is not fitted): a result's values read back, say
            if name == COLOUR_CHOICE.name() && e.colour != Some(true) && e.vary != Some(false) {
                if let Some(v) = e.value.filter(|v| v.is_rgb()) {
                    bail!(
                        "parameters.{name}.value = {:?}: an RGB start for a grey `{name}` (fitted as \
                         one value shared by the channels unless `colour = true`); give one number, \
                         or add `colour = true` to fit `{name}` per channel",
                        v.channels()
                    );
                }
            }
            if let (Some(lo), Some(hi)) = (e.min, e.max) {
                if !(lo <= hi) {
                    bail!("parameters.{name}: min = {lo} is greater than max = {hi}");
                }
            }
            for (what, v) in [("min", e.min), ("max", e.max)] {
                if let Some(v) = v {
                    if !v.is_finite() {
                        bail!("parameters.{name}.{what} = {v} is not finite");
                    }
                }
            }
            if let Some(v) = &e.value {
                for x in v.channels() {
                    if !x.is_finite() {
                        bail!("parameters.{name}.value = {x} is not finite");
                    }
                    if e.min.is_some_and(|lo| x < lo) || e.max.is_some_and(|hi| x > hi) {
                        bail!(
                            "parameters.{name}.value = {x} is outside its bounds [{}, {}]",
                            e.min.map_or("-inf".into(), |v| v.to_string()),
                            e.max.map_or("inf".into(), |v| v.to_string())
                        );
                    }
                }
            }
        }
        use crate::model::params::{MAX_HISTOGRAM_BINS, MAX_QUADRATURE_ORDER};
        if !(1..=MAX_QUADRATURE_ORDER).contains(&self.knobs.quadrature_order) {
            bail!(
                "knobs.quadrature_order = {} must lie in [1, {MAX_QUADRATURE_ORDER}]",
                self.knobs.quadrature_order
            );
        }
        if !(1..=MAX_HISTOGRAM_BINS).contains(&self.knobs.histogram_bins) {
            bail!(
                "knobs.histogram_bins = {} must lie in [1, {MAX_HISTOGRAM_BINS}]",
                self.knobs.histogram_bins
            );
        }
        let max_nodes = crate::model::azimuth_spread::MAX_AZIMUTH_NODES;
        if !(1..=max_nodes).contains(&self.knobs.azimuth_nodes) {
            bail!(
                "knobs.azimuth_nodes = {} must lie in [1, {max_nodes}]",
                self.knobs.azimuth_nodes
            );
        }
        let nodes = self.knobs.quadrature_order * self.knobs.azimuth_nodes;
        if nodes > MAX_NODES_PER_EVALUATION {
            bail!(
                "knobs.quadrature_order = {} x knobs.azimuth_nodes = {} = {nodes} quadrature nodes per model \
                 evaluation, {}x the default's: more than the {MAX_NODES_PER_EVALUATION} a fit may take \
                 (its time grows with the product); lower one of them",
                self.knobs.quadrature_order,
                self.knobs.azimuth_nodes,
                nodes / 256
            );
        }
        if let Some(c) = self.optimizer.global_candidates {
            if !(1..=MAX_GLOBAL_CANDIDATES).contains(&c) {
                bail!("optimizer.global_candidates = {c} must lie in [1, {MAX_GLOBAL_CANDIDATES}]");
            }
        }
        if !(1..=MAX_GLOBAL_SUBSAMPLE).contains(&self.optimizer.global_subsample) {
            bail!(
                "optimizer.global_subsample = {} must lie in [1, {MAX_GLOBAL_SUBSAMPLE}]",
                self.optimizer.global_subsample
            );
        }
        if self.starts > MAX_STARTS {
            bail!("starts = {} must lie in [1, {MAX_STARTS}]", self.starts);
        }
        if self.optimizer.max_iterations > MAX_ITERATIONS {
            bail!(
                "optimizer.max_iterations = {} must lie in [1, {MAX_ITERATIONS}]",
                self.optimizer.max_iterations
            );
        }
        if self.knobs.stride == 0 || !(self.knobs.fraction > 0.0 && self.knobs.fraction <= 1.0) {
            bail!("knobs.stride must be >= 1 and knobs.fraction in (0, 1]");
        }
        if let Some(sub) = &self.components.substrate {
            if !["tied", "free", "off"].contains(&sub.as_str()) {
                bail!("components.substrate = '{sub}': expected \"tied\", \"free\" or \"off\"");
            }
        }
        if !(2..=100).contains(&self.selection.folds) {
            bail!(
                "selection.folds = {} must lie in [2, 100]",
                self.selection.folds
            );
        }
        if self.selection.rank_samples < 10 {
            bail!(
                "selection.rank_samples = {} must be at least 10",
                self.selection.rank_samples
            );
        }
        if !(self.selection.holdout > 0.0 && self.selection.holdout < 1.0) {
            bail!(
                "selection.holdout = {} must lie in (0, 1)",
                self.selection.holdout
            );
        }
        for r in &self.selection.rungs {
            r.parse::<ModelId>()
                .map_err(|e| anyhow!("selection.rungs: {e}"))?;
        }
        if self.starts == 0 {
            bail!("starts must be at least 1");
        }
        if !(self.optimizer.tolerance > 0.0) || self.optimizer.max_iterations == 0 {
            bail!("optimizer.tolerance must be > 0 and optimizer.max_iterations >= 1");
        }
        Ok(())
    }
}
