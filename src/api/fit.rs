//! `fit`: a request in (data, configuration, what to recover), a [`FitRun`] out (the result
//! file, the outcome, the samples, the maps, the report text); [`FitRun::write`] puts its files
//! into outputs reserved with [`FitTargets::reserve`]. The CLI (`fibrefit fit`) and any other
//! front end call these; nothing here parses arguments or prints results.

pub use super::data::LoadFlags;
use crate::export::atomic::{OutputId, Outputs};
use crate::export::maps_out::{self, MapFiles};
use crate::export::report::{self, ReportFiles};
use crate::export::result_json as rj;
use crate::fit::config::{FitConfig, Metric};
use crate::fit::maps::TexelMaps;
use crate::fit::problem::model_for;
use crate::fit::selection::SelectionOutcome;
use crate::fit::{self, parameters::Param, FitOutcome};
use crate::load::capture_store::CaptureStore;
use crate::load::samples::{DataKind, Samples};
use crate::load::{load_data, LoadOptions};
use crate::model::ModelId;
use anyhow::{anyhow, bail, Context, Result};
use std::path::{Path, PathBuf};

/// The configuration of a fit: a config file, or the defaults of a rung (`model`), with
/// `model`, `metric` and `fuzz` overriding it; validated. `fuzz`: `Some(true)` adds the fuzz
/// layer (to the rung, or to every candidate of `auto`), `Some(false)` leaves it out (`auto`
/// tries no candidate with it; refused when the config lists one of its parameters), `None`
/// the config's (or the default: `auto` tries each rung without and with it). Without a config a measured-BRDF file
/// (.bsdf, .binary) is fitted with the log metric; other data without a named metric (no
/// `--metric`, no `metric` in the config) take the metric they ask for when loaded
/// (`metric_for_data`). A named rung frees every shape parameter
/// as `auto` does ([`FitConfig::free_unlisted_shapes`]: starts and bounds there). `--model`
/// over a config written for another rung ignores the parameters that rung lacks, with a note
/// ([`FitConfig::retarget`]).
pub fn configure(
    config: Option<&Path>,
    model: Option<&str>,
    metric: Option<&str>,
    fuzz: Option<bool>,
    data: &Path,
) -> Result<FitConfig> {
    let mut cfg = match (config, model) {
        (Some(path), _) => FitConfig::load(path)?,
        (None, Some(m)) => {
            let mut c: FitConfig = toml::from_str(&format!("model = {m:?}\n"))?;
            let measured = data.extension().is_some_and(|e| {
                e.eq_ignore_ascii_case("bsdf") || e.eq_ignore_ascii_case("binary")
            });
            if measured {
                c.metric = Metric::Log;
                c.metric_reason =
                    Some("log: a measured-BRDF file (values spanning decades, no sigmas)".into());
            } else {
                c.metric_follows_data = true;
            }
            c
        }
        (None, None) => bail!("give --config FILE, or --model ID|auto to fit with the defaults"),
    };
    if let Some(m) = model {
        let choice: crate::fit::config::ModelChoice = m
            .parse()
            .map_err(|e: String| anyhow!("--model: `model`: {e}"))?;
        match (config.is_some(), choice) {
            // a config written for another rung (or for auto) tried with this one
            (true, crate::fit::config::ModelChoice::Rung(id)) if cfg.model != choice => {
                cfg.retarget(id)?
            }
            _ => cfg.model = choice,
        }
    }
    if let Some(m) = metric {
        cfg.metric = serde_json::from_value(serde_json::Value::String(m.to_string()))
            .map_err(|_| anyhow!("--metric {m}: expected linear, log or cosine"))?;
        cfg.metric_follows_data = false;
        cfg.metric_reason = Some(format!("{m}: --metric {m}"));
    } else if config.is_some() && !cfg.metric_follows_data {
        let m = crate::fit::selection::metric_name(cfg.metric);
        cfg.metric_reason = Some(format!("{m}: the config's `metric`"));
    }
    match fuzz {
        Some(true) => {
            cfg.add_fuzz_layer();
        }
        Some(false) => {
            if let Some(p) = cfg.listed_fuzz_parameter() {
                bail!(
                    "--no-fuzz (fuzz = False): the config lists the fuzz layer's parameter `{p}`; \
                     remove it from [parameters] to fit without the layer"
                );
            }
            cfg.selection.fuzz = false;
        }
        None => {}
    }
    cfg.validate().map_err(|e| anyhow!("--model: {e}"))?;
    if config.is_none() && !cfg.model.is_auto() {
        // no config: a named rung fits what the data can determine, as auto's rungs do
        let id = cfg.model_id()?;
        cfg.free_unlisted_shapes(id);
        cfg.validate().map_err(|e| anyhow!("--model: {e}"))?;
    }
    Ok(cfg)
}

/// A fit as a front end asks for it (the command line's `fibrefit fit` flags, the Python
/// package's keyword arguments): [`FitOptions::request`] merges the config file with the
/// overrides and the loading flags into a [`FitRequest`], the one place that merge happens.
#[derive(Clone, Debug)]
pub struct FitOptions {
    /// A fit config (TOML); `None`: every setting at its default (then `model` is needed).
    pub config: Option<PathBuf>,
    /// A rung id or `auto`, overriding the config's `model`.
    pub model: Option<String>,
    /// The residual metric (`linear`, `log` or `cosine`), overriding the config's.
    pub metric: Option<String>,
    /// The fuzz layer: `Some(true)` added, `Some(false)` left out, `None` the config's (see
    /// [`configure`]).
    pub fuzz: Option<bool>,
    /// The loading flags (merged with the config's stride, fraction and `[columns]`).
    pub load: LoadFlags,
    /// What the fit recovers besides the global parameters.
    pub maps: Maps,
    /// Where progress lines, bars, notes and warnings go.
    pub progress: crate::progress::Progress,
    /// The `gltf` rung's variant (`khronos` or `threejs`), overriding the config's
    /// `knobs.gltf_variant` ([`FitConfig::apply_gltf_variant`]).
    pub gltf_variant: Option<String>,
    /// The smooth correction of the rung (`fit::correction`): `Some(false)` never
    /// (`--no-correction`), `Some(true)` where it pays, `None` the config's
    /// (`[components] correction`, true by default).
    pub correction: Option<bool>,
}

impl FitOptions {
    /// The fit of `data` these options ask for: the configuration ([`configure`]: the config
    /// file or a rung's defaults, with `model`, `metric` and `fuzz` over it) and the loading
    /// options ([`LoadFlags::options_for`] the configuration). Not yet [`check`]ed.
    pub fn request(&self, data: &Path) -> Result<FitRequest> {
        let mut config = configure(
            self.config.as_deref(),
            self.model.as_deref(),
            self.metric.as_deref(),
            self.fuzz,
            data,
        )?;
        let variant = self
            .gltf_variant
            .as_deref()
            .map(|v| {
                v.parse()
                    .map_err(|e: String| anyhow!("--gltf-variant: {e}"))
            })
            .transpose()?;
        config.apply_gltf_variant(variant)?;
        if let Some(c) = self.correction {
            config.components.correction = c;
        }
        config
            .validate()
            .map_err(|e| anyhow!("--gltf-variant: {e}"))?;
        let load = self.load.options_for(&config)?;
        Ok(FitRequest {
            data: data.to_path_buf(),
            config,
            load,
            maps: self.maps.clone(),
            progress: self.progress,
            held: None,
        })
    }

    /// The fit of measurements a program holds (`data`: numpy arrays, a pandas DataFrame's
    /// table), configured as [`FitOptions::request`] configures a file's (a table's columns and
    /// angle unit from the loading flags and the config). Not yet [`check`]ed.
    pub fn request_held(&self, data: Held) -> Result<FitRequest> {
        let name = match &data {
            Held::Table { name, .. } | Held::Arrays { name, .. } => name.clone(),
        };
        let mut req = self.request(Path::new(&name))?;
        if req.maps != Maps::None {
            bail!("{name}: per-texel maps come from an image capture (a capture TOML), not from samples in memory");
        }
        use sha2::{Digest, Sha256};
        let mut hash = Sha256::new();
        let samples = match data {
            Held::Table { text, name } => {
                hash.update(text.as_bytes());
                crate::load::gonio::read(text.as_bytes(), &name, &req.load.gonio)?
            }
            Held::Arrays { arrays, name } => {
                let a = &arrays;
                let numbers = a.l.iter().chain(&a.v).flatten();
                let numbers = numbers.chain(&a.values).chain(a.sigma.iter().flatten());
                for x in numbers {
                    hash.update(x.to_le_bytes());
                }
                crate::load::arrays::samples(&arrays.view(), &name)?
            }
        };
        let sha256 = hash.finalize().iter().map(|b| format!("{b:02x}")).collect();
        req.held = Some(std::sync::Arc::new(HeldSamples { samples, sha256 }));
        Ok(req)
    }

    /// Every file the fit of `req` (made by [`FitOptions::request`]) reads, the config file
    /// included.
    pub fn inputs(&self, req: &FitRequest) -> Vec<PathBuf> {
        inputs(req, self.config.as_deref())
    }
}

/// Measurements a program holds, to fit without a file ([`FitOptions::request_held`]).
#[derive(Clone, Debug)]
pub enum Held {
    /// A goniometric table's text (a DataFrame written as CSV), read as a file's would be;
    /// `name` labels its errors (`NAME:LINE: problem`, line 1 the header).
    Table {
        /// The table: a header line, then one row per measurement.
        text: String,
        /// What errors and the result call the data.
        name: String,
    },
    /// Directions and values as arrays (see `Arrays`).
    Arrays {
        /// The arrays.
        arrays: OwnedArrays,
        /// What errors and the result call the data.
        name: String,
    },
}

/// Samples held in memory, with the SHA-256 (hex) of what they were made from (the table's
/// text; the arrays' values as little-endian f64: l, v, values, then sigma), which the result
/// records as a file's hash.
#[derive(Clone, Debug)]
pub struct HeldSamples {
    /// The samples.
    pub samples: Samples,
    /// The hash of their source.
    pub sha256: String,
}

/// `Arrays` owning its rows.
#[derive(Clone, Debug, Default)]
pub struct OwnedArrays {
    /// Unit directions towards the light (swatch frame, normal +z).
    pub l: Vec<[f64; 3]>,
    /// Unit directions towards the viewer.
    pub v: Vec<[f64; 3]>,
    /// BRDF values in 1/sr, `channels` per row.
    pub values: Vec<f64>,
    /// 1 (grey) or 3 (RGB).
    pub channels: usize,
    /// Standard deviations in 1/sr: one per row or one per value.
    pub sigma: Option<Vec<f64>>,
}

impl OwnedArrays {
    /// The arrays, borrowed.
    pub(crate) fn view(&self) -> crate::load::arrays::Arrays<'_> {
        crate::load::arrays::Arrays {
            l: &self.l,
            v: &self.v,
            values: &self.values,
            channels: self.channels,
            sigma: self.sigma.as_deref(),
        }
    }
}

/// What a fit recovers besides the global parameters.
#[derive(Clone, Debug, PartialEq)]
pub enum Maps {
    /// Global parameters only.
    None,
    /// Only the global stage of map recovery (the globals that `--tile` runs share).
    Globals,
    /// Per-texel maps, to be written into this directory (named in the result).
    Into(PathBuf),
}

/// A fit to run.
#[derive(Clone, Debug)]
pub struct FitRequest {
    /// Goniometric CSV, capture TOML or measured BRDF file.
    pub data: PathBuf,
    /// The fit's configuration ([`configure`]: a config file, or a rung's defaults).
    pub config: FitConfig,
    /// Loading options ([`LoadFlags::options_for`] the config).
    pub load: LoadOptions,
    /// What is recovered besides the global parameters.
    pub maps: Maps,
    /// Where progress lines and bars go (the model-selection table is in the report).
    pub progress: crate::progress::Progress,
    /// Samples held in memory ([`FitOptions::request_held`]), fitted instead of reading
    /// `data`, which then only names them.
    pub held: Option<std::sync::Arc<HeldSamples>>,
}

/// A finished fit.
pub struct FitRun {
    /// The result file (schema fibrefit-result/1) as it will be written.
    pub result: rj::ResultFile,
    /// The fit itself: parameter set, records with standard errors, statistics, quality.
    pub outcome: FitOutcome,
    /// The samples the global fit used.
    pub samples: Samples,
    /// The configuration of the fitted rung (auto's choice applied).
    pub config: FitConfig,
    /// The rung fitted (auto's choice for `--model auto`).
    pub model: ModelId,
    /// `--model auto`: the candidates compared and the choice.
    pub selection: Option<SelectionOutcome>,
    /// The fit report (lmfit's layout), the model-selection table appended for auto.
    pub report_text: String,
    /// The per-texel maps (`Maps::Into`).
    pub maps: Option<TexelMaps>,
    /// Warnings beside the quality checks' own (those are in `outcome.quality`).
    pub warnings: Vec<String>,
    data: PathBuf,
    progress: crate::progress::Progress,
}

/// Every file a fit reads: its data (a capture's images and maps too), config, topology map.
pub fn inputs(req: &FitRequest, config_file: Option<&Path>) -> Vec<PathBuf> {
    let mut inputs = match req.held {
        Some(_) => Vec::new(),
        None => crate::load::input_files(&req.data),
    };
    inputs.extend(config_file.map(Path::to_path_buf));
    inputs.extend(req.config.knobs.topology_map.iter().cloned());
    inputs
}

/// Checks of a request that need no data (before any output is reserved).
pub fn check(req: &FitRequest) -> Result<()> {
    if req.maps != Maps::None {
        if req.config.model.is_auto() && matches!(req.maps, Maps::Into(_)) {
            bail!("--maps: name a rung (`model` or --model), not auto");
        }
        fit::maps::check_request(&req.config, &req.config.maps)?;
    }
    Ok(())
}

/// The texels of a capture the global fit uses: every one, or a seeded sample of
/// `[knobs] fit_texels` of them.
fn fit_texel_sample(store: &CaptureStore, cfg: &FitConfig) -> Vec<usize> {
    let n = match cfg.knobs.fit_texels {
        0 => usize::MAX,
        k => k,
    };
    store.sample_texels(n, cfg.seed ^ 0x6669_7474)
}

/// What a `--model auto` run has finished so far: what an interrupted run writes, marked
/// partial ([`AutoProgress::partial_json`], [`write_partial`]).
#[derive(Clone, Debug, Default)]
pub struct AutoProgress {
    /// The candidates to try, in order (rungs, each without and with the fuzz layer).
    pub rungs: Vec<String>,
    /// Every candidate finished (fitted or failed), as the model-selection table lists them.
    pub candidates: Vec<crate::fit::selection::Candidate>,
    /// The training fit's parameters of every rung fitted, as a result states them.
    pub fits: Vec<(String, serde_json::Value)>,
    /// Samples the candidates were fitted on and held out to measure their errors, per fold
    /// and in all.
    pub counts: crate::fit::selection::Counts,
    /// Set once every rung is done: the rung being refitted on all samples.
    pub chosen: Option<String>,
    /// The data file's name (no directory) and sample count.
    pub data_file: String,
    /// Samples in the data.
    pub samples: usize,
}

/// An [`AutoProgress`] shared between a fit and a signal handler.
pub type AutoSink = std::sync::Arc<std::sync::Mutex<AutoProgress>>;

impl AutoProgress {
    /// Where the run stood, in words.
    pub fn stage(&self) -> String {
        match &self.chosen {
            Some(c) => format!(
                "every rung fitted ({}); interrupted while refitting the chosen rung `{c}` on all samples",
                self.candidates.len()
            ),
            None => format!(
                "interrupted during model selection: {} of {} rungs finished",
                self.candidates.len(),
                self.rungs.len()
            ),
        }
    }

    /// The partial result: `"partial": true`, the rungs finished with their held-out errors
    /// and training-fit parameters. Not a result the other commands read (no fitted model).
    pub fn partial_json(&self) -> serde_json::Value {
        serde_json::json!({
            "schema": "fibrefit-partial/1",
            "partial": true,
            "tool": format!("fibrefit {}", env!("CARGO_PKG_VERSION")),
            "model": "auto",
            "interrupted": self.stage(),
            "note": "an interrupted `fibrefit fit --model auto`: the rungs finished before the \
                     signal, fitted on the training split; no rung was refitted on all samples, so \
                     this is no result to render, export or score: run the fit again to finish",
            "data": { "file": self.data_file, "samples": self.samples },
            "rungs_done": self.candidates.iter().map(|c| c.name.clone()).collect::<Vec<_>>(),
            "rungs_not_done": self.rungs.iter().skip(self.candidates.len()).cloned().collect::<Vec<_>>(),
            "chosen": self.chosen,
            "train_samples_per_fold": self.counts.train_samples_per_fold,
            "heldout_samples_per_fold": self.counts.heldout_samples_per_fold,
            "heldout_samples_total": self.counts.heldout_samples_total,
            "model_selection": self.candidates,
            "training_fits": self.fits.iter().map(|(r, p)| serde_json::json!({ "candidate": r, "parameters": p })).collect::<Vec<_>>(),
        })
    }

    /// The partial report (markdown): PARTIAL, where the run stood, the rungs finished.
    pub fn partial_report(&self) -> String {
        let mut t = format!(
            "# PARTIAL: interrupted `fibrefit fit --model auto` on {}\n\n{}.\n\n",
            self.data_file,
            self.stage()
        );
        t += "| candidate | free parameters | held-out error | standard error | held-out RMSE [1/sr] | held-out relative RMSE | held-out log error | fit time [s] |\n|---|---|---|---|---|---|---|---|\n";
        for c in &self.candidates {
            match &c.error {
                Some(e) => {
                    t += &format!(
                        "| {} | - | failed: {e} | | | | | {:.2} |\n",
                        c.name, c.fit_seconds
                    )
                }
                None => {
                    t += &format!(
                        "| {} | {} | {:.4} | {:.4} | {:.4e} | {:.2} % | {:.4} | {:.2} |\n",
                        c.name,
                        c.free_parameters,
                        c.cv_error,
                        c.cv_standard_error,
                        c.heldout_rmse,
                        100.0 * c.heldout_relative_rmse,
                        c.heldout_log_error,
                        c.fit_seconds
                    )
                }
            }
        }
        let left: Vec<&str> = self
            .rungs
            .iter()
            .skip(self.candidates.len())
            .map(String::as_str)
            .collect();
        if !left.is_empty() {
            t += &format!("\nNot fitted: {}.\n", left.join(", "));
        }
        t
    }
}

/// Write the partial result of an interrupted auto run to `json` and `dir/report.md` (each
/// optional), committed together through outputs that refuse `inputs`. Nothing when no rung
/// had finished. Returns the files written.
pub fn write_partial(
    p: &AutoProgress,
    json: Option<&Path>,
    report: Option<&Path>,
    inputs: &[PathBuf],
) -> Result<Vec<PathBuf>> {
    if p.candidates.is_empty() {
        return Ok(vec![]);
    }
    let mut outs = Outputs::new(inputs);
    let mut written = Vec::new();
    if let Some(path) = json {
        let id = outs.file(path, "--out")?;
        outs.put(
            id,
            (serde_json::to_string_pretty(&p.partial_json())? + "\n").as_bytes(),
        )?;
        written.push(path.to_path_buf());
    }
    if let Some(dir) = report {
        let dir = outs.dir(dir, "--report")?;
        let path = dir.join("report.md");
        let id = outs.file(&path, "--report")?;
        outs.put(id, p.partial_report().as_bytes())?;
        written.push(path);
    }
    outs.commit()?;
    Ok(written)
}

/// Run the fit `req` asks for.
pub fn fit(req: &FitRequest) -> Result<FitRun> {
    fit_reporting(req, None)
}

/// The data of a fit: a capture held compactly by texel (with the texels the global fit
/// samples), and the samples the global fit uses.
struct Loaded {
    store: Option<CaptureStore>,
    fit_texels: Option<Vec<usize>>,
    samples: Samples,
}

/// Load the data of `req`, check the work `cfg` plans on it, and let the metric follow the
/// data when nothing named it (goniometric and measured data; a capture's pixels and per-texel
/// maps keep the linear metric).
fn load_stage(req: &FitRequest, cfg: &mut FitConfig) -> Result<Loaded> {
    // captures are held compactly by texel; the global fit takes a seeded sample of texels
    let store = match req.held.is_none() && crate::load::is_capture(&req.data) {
        true => Some(CaptureStore::load(&req.data, req.load.subsample)?),
        false => None,
    };
    let fit_texels = store.as_ref().map(|st| fit_texel_sample(st, cfg));
    let samples = match (&store, &fit_texels, &req.held) {
        (Some(st), Some(ids), _) => st.samples_of(ids),
        (_, _, Some(held)) => held.samples.clone(),
        _ => load_data(&req.data, &req.load)?,
    };
    cfg.check_work(samples.samples.len())
        .map_err(|e| anyhow!("{}: {e}", req.data.display()))?;
    if cfg.metric_follows_data && req.maps == Maps::None && samples.kind != DataKind::Capture {
        let (m, why) = crate::fit::config::metric_for_data(&samples);
        cfg.metric = m;
        cfg.metric_reason = Some(why);
    }
    Ok(Loaded {
        store,
        fit_texels,
        samples,
    })
}

/// `--model auto`: compare the candidates, keeping `sink` up to date, and turn `cfg` into the
/// chosen candidate's configuration.
fn select_stage(
    req: &FitRequest,
    samples: &Samples,
    cfg: &mut FitConfig,
    sink: Option<&AutoSink>,
) -> Result<SelectionOutcome> {
    let with_sink = |f: &mut dyn FnMut(&mut AutoProgress)| {
        if let Some(s) = sink {
            f(&mut s.lock().unwrap_or_else(|p| p.into_inner()));
        }
    };
    with_sink(&mut |p| {
        p.rungs = fit::selection::candidates_of(cfg)
            .map(|l| l.into_iter().map(|c| c.0).collect())
            .unwrap_or_default();
        p.data_file = req
            .data
            .file_name()
            .map(|f| f.to_string_lossy().into_owned())
            .unwrap_or_default();
        p.samples = samples.samples.len();
    });
    let s = fit::selection::select_with(samples, cfg, &req.progress, &mut |d| {
        with_sink(&mut |p| {
            p.candidates = d.candidates.to_vec();
            p.counts = d.counts;
            if let (Some(o), Some(c)) = (d.outcome, d.candidates.last()) {
                p.fits.push((
                    c.name.clone(),
                    serde_json::to_value(rj::params_out(o)).unwrap_or_default(),
                ));
            }
        })
    })?;
    with_sink(&mut |p| p.chosen = Some(s.chosen.clone()));
    req.progress.line(&format!(
        "auto: chose {}; refitting it on all {} samples",
        s.chosen,
        samples.samples.len()
    ));
    let reason = cfg.metric_reason.clone();
    *cfg = match &s.chosen_config {
        Some(c) => c.clone(),
        None => cfg.for_rung(s.chosen_rung.parse().map_err(|e: String| anyhow!(e))?),
    };
    cfg.metric_reason = reason;
    // the table is said once: in the report (`FitRun::report_text`), which the CLI prints
    Ok(s)
}

/// The global fit: on the samples (from `hints`, the selection's starts), or, for maps, the
/// global stage of map recovery on a sample of texels (its work returned too).
fn global_fit(
    req: &FitRequest,
    cfg: &FitConfig,
    data: &Loaded,
    hints: &[Vec<(Param, f64)>],
) -> Result<(FitOutcome, Option<fit::maps::GlobalWork>)> {
    let id = cfg.model_id()?;
    if req.maps == Maps::None {
        let outcome = fit::fit_with_hints(&data.samples, cfg, &req.progress, hints)
            .with_context(|| format!("fitting {} to {}", id, req.data.display()))?;
        return Ok((outcome, None));
    }
    let store = data.store.as_ref().ok_or_else(|| {
        anyhow!("--maps needs an image capture (a capture TOML): per-texel maps come from pixels")
    })?;
    req.progress.line(&format!(
        "maps: global stage ({} of {}x{} texels)",
        cfg.maps.global_texels, store.width, store.height
    ));
    let st = fit::maps::global_stage(store, cfg, &cfg.maps, &req.progress)
        .with_context(|| format!("recovering maps with {} from {}", id, req.data.display()))?;
    let (outcome, work) = st.split();
    Ok((outcome, Some(work)))
}

/// A fit on a sample of a capture's texels, checked on every pixel (a warning when the sample
/// does not represent the capture).
fn all_pixels_stage(
    req: &FitRequest,
    cfg: &FitConfig,
    data: &Loaded,
    outcome: &mut FitOutcome,
) -> Result<Option<fit::all_pixels::AllPixels>> {
    let (Some(st), Some(ids)) = (&data.store, &data.fit_texels) else {
        return Ok(None);
    };
    let fitted_texels = ids.len();
    if fitted_texels >= st.texels().len() {
        return Ok(None);
    }
    req.progress.line(&format!(
        "fit: checking the fit of {fitted_texels} texels on all {}",
        st.texels().len()
    ));
    let all = fit::all_pixels::statistics(st, cfg, outcome, &req.progress)?;
    if let Some(w) =
        fit::all_pixels::warning(&all, outcome.statistics.reduced_chi_square, fitted_texels)
    {
        outcome.warnings.push(w);
    }
    Ok(Some(all))
}

/// The renderers' own materials (every rung with a [`crate::model::Rung::renderer`]) fitted to
/// the same data, for the exports of this result: all but the fit's own rung when the fit is a
/// renderer's material without the fuzz layer (its export is the fit); none per texel. Each is a global fit of that rung alone at the config's knobs,
/// without the fuzz layer (no renderer has fibrefit's), recorded as a result of its own
/// (`schema`, `model`, `parameters`, `statistics`, `knobs`, `data`) with its renderer, its fit
/// time and, after `--model auto`, its candidate's held-out errors. An optional stage: a failure
/// is a warning, never the loss of the fit.
fn renderer_stage(
    req: &FitRequest,
    cfg: &FitConfig,
    data: &Loaded,
    selection: Option<&fit::selection::SelectionOutcome>,
    warnings: &mut Vec<String>,
) -> Result<Vec<serde_json::Value>> {
    let id = cfg.model_id()?;
    let fuzz = cfg.listed_fuzz_parameter().is_some();
    let mut out = Vec::new();
    // large data: a seeded subset (fit::CHECK_SAMPLES), which each entry's `data` counts
    let samples = fit::check_subset(&data.samples, cfg.seed);
    for rid in crate::model::ModelId::ALL {
        let Some(renderer) = rid.rung().renderer else {
            continue;
        };
        if rid == id && !fuzz {
            continue; // the fit is that renderer's material itself
        }
        req.progress.line(&format!(
            "fit: {rid}, {renderer}'s own material, to the same data"
        ));
        let mut rc = cfg.for_rung(rid);
        rc.parameters
            .retain(|k, _| !crate::model::Param::from_name(k).is_some_and(|p| p.is_fuzz()));
        rc.free_unlisted_shapes(rid);
        let started = std::time::Instant::now();
        let quiet = crate::progress::Progress::quiet();
        let fitted = fit::fit_with_hints(&samples, &rc, &quiet, &[]).and_then(|o| {
            let model = model_for(
                &o.set,
                rc.knobs.quadrature_order,
                rc.knobs.histogram_bins,
                rc.knobs.azimuth_nodes,
                o.map.clone(),
            );
            let r = rj::assemble(rj::ResultParts {
                config: &rc,
                outcome: &o,
                model: model.as_ref(),
                samples: &samples,
                data: &req.data,
                data_sha256: req.held.as_ref().map(|h| h.sha256.clone()),
                stride: req.load.subsample.stride,
                fraction: req.load.subsample.fraction,
                all_pixels: None,
                selection: None,
                warnings: o.warnings.clone(),
            })?;
            Ok(serde_json::to_value(r)?)
        });
        let full = match fitted {
            Ok(v) => v,
            Err(e) => {
                warnings.push(format!(
                    "{renderer}'s own material (`{rid}`) could not be fitted to the data, so the \
                     result has none for it: {e:#}"
                ));
                continue;
            }
        };
        let mut entry = serde_json::Map::new();
        for key in [
            "schema",
            "model",
            "parameters",
            "statistics",
            "knobs",
            "data",
        ] {
            entry.insert(key.into(), full[key].clone());
        }
        // a renderer's material reads no topology map (the fit's own knobs name it, relative)
        if let Some(k) = entry.get_mut("knobs").and_then(|k| k.as_object_mut()) {
            k.remove("topology_map");
            k.remove("topology_map_sha256");
        }
        entry.insert("renderer".into(), renderer.into());
        entry.insert("fit_seconds".into(), started.elapsed().as_secs_f64().into());
        let candidate = selection.and_then(|s| {
            s.candidates
                .iter()
                .find(|c| c.rung == rid.as_str() && !c.fuzz && c.error.is_none())
        });
        if let (Some(c), Some(s)) = (candidate, selection) {
            entry.insert(
                "heldout".into(),
                serde_json::json!({
                    "cv_error": c.cv_error,
                    "cv_standard_error": c.cv_standard_error,
                    "metric": s.metric,
                    "heldout_relative_rmse": c.heldout_relative_rmse,
                    "heldout_log_error": c.heldout_log_error,
                }),
            );
        }
        out.push(serde_json::Value::Object(entry));
    }
    Ok(out)
}

/// [`fit`], keeping `sink` up to date with what an auto run has finished (for a partial
/// result). The stages: load, select (auto), the global fit, the all-pixel check, the
/// renderers' own materials, the result and report, the texel stage (maps).
pub fn fit_reporting(req: &FitRequest, sink: Option<&AutoSink>) -> Result<FitRun> {
    check(req)?;
    let mut cfg = req.config.clone();
    let data = load_stage(req, &mut cfg)?;
    let selection = match cfg.model.is_auto() {
        true => Some(select_stage(req, &data.samples, &mut cfg, sink)?),
        false => None,
    };
    let id = cfg.model_id()?;
    let hints = selection
        .as_ref()
        .map(|s| s.hints.clone())
        .unwrap_or_default();
    let (mut outcome, global_work) = global_fit(req, &cfg, &data, &hints)?;
    // what configuring decided (parameters of another rung ignored) is read with the warnings
    for (k, n) in cfg.notes.iter().enumerate() {
        if !outcome.warnings.contains(n) {
            outcome.warnings.insert(k, n.clone());
        }
    }
    // the floor: what the data themselves allow, on the held-out samples (not for maps)
    // (on a seeded subset of large data, fit::CHECK_SAMPLES, unless a selection's folds measured
    // the model's held-out error on all of them)
    if global_work.is_none() {
        let sel = selection.as_ref();
        let checked = match sel {
            Some(_) => std::borrow::Cow::Borrowed(&data.samples),
            None => fit::check_subset(&data.samples, cfg.seed),
        };
        fit::floor::judge::fit_stage(&checked, &cfg, &mut outcome, sel, &req.progress);
    }
    // parameters recovered per texel are not fixed: say so
    if global_work.is_some() {
        let per_texel = per_texel_names(&cfg.maps);
        fit::parameters::explain_fixed(&mut outcome.records, &cfg, &data.samples, &per_texel);
    }
    let channels = data.samples.channels;
    let all_pixels = match global_work {
        None => all_pixels_stage(req, &cfg, &data, &mut outcome)?,
        Some(_) => None,
    };
    let mut warnings = outcome.warnings.clone();
    // the fitted model, for the check values
    let model = model_for(
        &outcome.set,
        cfg.knobs.quadrature_order,
        cfg.knobs.histogram_bins,
        cfg.knobs.azimuth_nodes,
        outcome.map.clone(),
    );
    let renderer_materials = match global_work {
        None => renderer_stage(req, &cfg, &data, selection.as_ref(), &mut warnings)?,
        Some(_) => Vec::new(),
    };
    let assemble = |outcome: &FitOutcome, warnings: &[String]| {
        rj::assemble(rj::ResultParts {
            config: &cfg,
            outcome,
            model: model.as_ref(),
            samples: &data.samples,
            data: &req.data,
            data_sha256: req.held.as_ref().map(|h| h.sha256.clone()),
            stride: req.load.subsample.stride,
            fraction: req.load.subsample.fraction,
            all_pixels: all_pixels.as_ref(),
            selection: selection.as_ref(),
            warnings: warnings.to_vec(),
        })
    };
    let mut result = assemble(&outcome, &warnings)?;
    // the white furnace of the material delivered (rung, fuzz layer, correction; the globals):
    // a gain is a quality warning (the banner shows it), so the result is assembled again
    if let Some(w) = crate::api::energy::check_result(&serde_json::to_value(&result)?, &req.data) {
        outcome.quality.warnings.push(w.clone());
        outcome.warnings.push(w.clone());
        warnings.push(w);
        result = assemble(&outcome, &warnings)?;
    }
    let mut report_text = report::text(
        &outcome,
        id.as_str(),
        &req.data.display().to_string(),
        cfg.metric_reason.as_deref(),
    );
    result.renderer_materials = renderer_materials;
    report_text += &report::renderer_materials_text(&result.renderer_materials);
    if let Some(s) = &selection {
        report_text += &format!("[[Model selection]]\n{}", fit::selection::table(s));
    }
    let mut maps = None;
    match (&global_work, &req.maps) {
        (Some(work), Maps::Globals) => result.maps = Some(rj::globals_block(&cfg, work)),
        (Some(work), Maps::Into(dir)) => {
            // the texel stage takes the globals as the result states them, as tiles do
            let globals =
                rj::result_from_value(&serde_json::to_value(&result)?, "the global fit", channels)?
                    .set;
            let store = data
                .store
                .as_ref()
                .expect("the global stage needed the capture");
            let free = outcome.statistics.free_parameters;
            let run = fit::maps::texel_run(store, &cfg, &globals, work, free, &req.progress)?;
            report_text += &run.report_text(work);
            result.maps = Some(rj::maps_block(dir, &cfg, work, &run)?);
            result.warnings.extend(run.warnings);
            outcome.fitted =
                fit::maps::fitted_all(&data.samples, &cfg, &cfg.maps, &globals, &run.maps)?;
            maps = Some(run.maps);
        }
        _ => {}
    }
    Ok(FitRun {
        result,
        outcome,
        samples: data.samples,
        config: cfg,
        model: id,
        selection,
        report_text,
        maps,
        warnings,
        data: req.data.clone(),
        progress: req.progress,
    })
}

/// `path` relative to the directory `dir` (both resolved; `None` when either cannot be).
pub fn relative_to(path: &Path, dir: &Path) -> Option<PathBuf> {
    use std::path::Component;
    let path = std::fs::canonicalize(path).ok()?;
    let dir = std::fs::canonicalize(dir).ok()?;
    let (p, d): (Vec<Component>, Vec<Component>) =
        (path.components().collect(), dir.components().collect());
    let common = p.iter().zip(&d).take_while(|(a, b)| a == b).count();
    let mut out = PathBuf::new();
    for _ in common..d.len() {
        out.push("..");
    }
    for c in &p[common..] {
        out.push(c.as_os_str());
    }
    Some(if out.as_os_str().is_empty() {
        PathBuf::from(".")
    } else {
        out
    })
}

/// The global parameters a `[maps]` request recovers per texel instead.
fn per_texel_names(req: &crate::fit::config::MapsConfig) -> Vec<&'static str> {
    use crate::model::Param;
    let mut v = Vec::new();
    if req.height {
        v.extend([Param::Height, Param::MapScale]);
    }
    if req.fibre_azimuth {
        v.push(Param::Azimuth);
    }
    if req.kd {
        v.extend([Param::Kd, Param::RhoD]);
    }
    if req.ks {
        v.extend([Param::Ks, Param::RhoS]);
    }
    let mut names: Vec<&'static str> = v.into_iter().map(Param::name).collect();
    names.extend(req.lobe_maps().into_iter().map(|(_, name)| name));
    names
}

/// The files a fit writes, reserved before the work.
pub struct FitTargets {
    json: Option<OutputId>,
    maps: Option<MapFiles>,
    report: Option<(PathBuf, ReportFiles)>,
}

impl FitTargets {
    /// Reserve the result JSON (`json`), the maps of `req` and a report into `report`.
    pub fn reserve(
        outs: &mut Outputs,
        req: &FitRequest,
        json: Option<&Path>,
        report: Option<&Path>,
    ) -> Result<Self> {
        let json = json.map(|p| outs.file(p, "--out")).transpose()?;
        let maps = match &req.maps {
            Maps::Into(dir) => Some(MapFiles::reserve(outs, dir, &req.config.maps.requested())?),
            _ => None,
        };
        let report = match report {
            Some(dir) => {
                let mut files = ReportFiles::reserve(outs, dir)?;
                // a residual map per capture image
                if req.held.is_none() && crate::load::is_capture(&req.data) {
                    let n = crate::load::capture::CaptureFile::load(&req.data)?
                        .images
                        .len();
                    files.add_images(outs, 0..n as u32)?;
                }
                Some((dir.to_path_buf(), files))
            }
            None => None,
        };
        Ok(Self { json, maps, report })
    }
}

impl FitRun {
    /// The one-line summary `fibrefit fit --json` prints: the rung, the result file `out`, the
    /// sample count, the quality verdict, the errors, the spread of the residuals under its own
    /// name (`reduced_chi_square` with sigmas, `residual_variance` without: chi-square is not
    /// defined then, as the report says), the held-out error, the floor and their ratio
    /// (`heldout_error`, `floor`, `floor_ratio`, when the floor was measured; `reciprocal_floor`
    /// where the floor's predictor is not reciprocal; `correction_degree` and the rung's own
    /// `rung_heldout_error` where a smooth correction was kept), the labels of the
    /// values the data do not determine (`undetermined`: `spacing`, `kd[b]`), and the work
    /// done.
    pub fn summary_json(&self, out: Option<&Path>) -> serde_json::Value {
        let (o, s) = (&self.outcome, &self.outcome.statistics);
        let mut v = serde_json::json!({
            "model": self.model.as_str(),
            "out": out.map(|p| p.display().to_string()),
            "samples": self.samples.samples.len(),
            "verdict": o.quality.verdict,
            "rmse": s.rmse,
            "relative_rmse": s.relative_rmse,
            "sigmas_given": s.sigmas_given,
            "iterations": o.iterations,
            "evaluations": o.evaluations,
            "seconds": o.elapsed_seconds,
            "warnings": o.warnings.len(),
        });
        v[s.names().1] = s.reduced_chi_square.into();
        // the values the data do not determine (their values are used, not measured)
        v["undetermined"] = o
            .quality
            .undetermined
            .iter()
            .map(|u| u.label.clone())
            .collect::<Vec<_>>()
            .into();
        // the model's held-out error against what the data themselves allow (fit::floor)
        if let Some(f) = &o.quality.floor {
            v["heldout_error"] = f.heldout_error.into();
            v["floor"] = f.floor.into();
            v["floor_ratio"] = f.ratio.into();
            // data that are not reciprocal: what any material can reach
            if let Some(r) = &f.reciprocal {
                v["reciprocal_floor"] = r.floor.into();
            }
        }
        // a smooth correction kept on the rung (fit::correction): its degree and the rung's
        // own held-out error (`heldout_error` is the corrected model's)
        if let Some(c) = &o.correction {
            v["correction_degree"] = c.correction.degree.into();
            v["rung_heldout_error"] = c.rung_error.into();
        }
        v
    }

    /// Write the run's files into their reserved outputs (committed by the caller): the maps,
    /// the report (optional: its failure becomes a warning in the result, never the lost fit),
    /// then the result JSON.
    pub fn write(&mut self, outs: &mut Outputs, targets: &FitTargets) -> Result<()> {
        let progress = self.progress;
        if let (Some(files), Some(maps)) = (&targets.maps, &self.maps) {
            maps_out::write(outs, files, &self.config.maps.requested(), maps)?;
            if let Some(block) = self.result.maps.as_mut() {
                block["sha256"] = serde_json::to_value(files.exr_hashes(outs)?)?;
            }
        }
        if let Some((dir, files)) = &targets.report {
            let fitted = fit::fitted_brdf(&self.outcome, &self.config);
            let measured = crate::load::measured_brdf(&self.data).unwrap_or(None);
            if let Err(e) = report::write_dir(
                outs,
                files,
                &report::ReportContent {
                    outcome: &self.outcome,
                    samples: &self.samples,
                    text: &self.report_text,
                    fitted: fitted.as_ref(),
                    measured: measured.as_deref(),
                },
            ) {
                let w = format!("{}: the report could not be written: {e:#}", dir.display());
                progress.alert(&w);
                self.result.warnings.push(w);
                files.discard(outs);
            } else if let Err(e) = crate::api::view::fit_page(&self.result, &self.samples)
                .and_then(|html| files.put_view(outs, &html))
            {
                // the viewer page is optional like the report: a warning, never the lost fit
                let w = format!(
                    "{}: the viewer page could not be written: {e:#}",
                    dir.join("view.html").display()
                );
                progress.alert(&w);
                self.result.warnings.push(w);
                files.discard_view(outs);
            }
        }
        if let Some(id) = targets.json {
            let name = outs.name(id).to_path_buf();
            // no absolute paths in the result: the topology map and the maps directory are
            // named relative to the result's folder (where readers look for them)
            let folder = match name.parent() {
                Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
                _ => PathBuf::from("."),
            };
            if let Some(map) = &self.result.knobs.topology_map {
                if let Some(rel) = relative_to(Path::new(map), &folder) {
                    self.result.knobs.topology_map = Some(rel.display().to_string());
                }
            }
            if let Some(dir) = self
                .result
                .maps
                .as_ref()
                .and_then(|m| m["directory"].as_str())
                .map(PathBuf::from)
            {
                if let Some(rel) = relative_to(&dir, &folder) {
                    self.result.maps.as_mut().expect("read above")["directory"] =
                        serde_json::json!(rel.display().to_string());
                }
            }
            serde_json::to_writer_pretty(outs.writer(id), &self.result)
                .with_context(|| format!("--out {}: cannot write the result", name.display()))?;
        }
        Ok(())
    }
}
