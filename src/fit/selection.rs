//! `--model auto`: choose among the candidates (every rung of `selection.rungs`, cheapest
//! first, each without and with the fuzz layer) by their held-out error in the fit's metric.
//!
//! - **Cross-validation.** Data with fewer than `selection.cv_below` samples are split into
//!   `selection.folds` seeded folds; every sample is predicted once by a fit that never saw it.
//!   Each candidate is fitted once on all samples (the global search), and each fold's fit is
//!   warm-started there and polished on the other folds. More data are split once
//!   (`selection.holdout` held out) and each candidate is fitted on the training part.
//! - **Speed.** Candidates are ranked with coarse knobs ([`ranking_config`]: fewer quadrature
//!   nodes, histogram bins, azimuth nodes and starts) on at most `selection.rank_samples` training
//!   samples; those within reach of the best (two standard errors) whose model the knobs change
//!   are refined: refitted at the config's knobs, warm-started from their coarse optimum.
//! - **The one-standard-error rule.** The error of a candidate is the RMS of its held-out
//!   residuals in the fit's metric (what the fit minimises: log, linear, per sigma or weight);
//!   its standard error comes from the spread of the per-sample squared residuals. The simplest
//!   candidate (fewest free parameters, then cheapest rung, the one without the fuzz layer
//!   before the one with it) whose mean squared held-out residual lies within one standard
//!   error of the best's is chosen. No candidate is chosen over a simpler one that is better
//!   beyond that noise. `selection.tolerance` replaces the standard error by a relative
//!   tolerance on the RMS error.

use super::config::{FitConfig, Metric};
use super::parameters::{Param, ParamSet};
use super::problem::FitProblem;
use super::{fit_with_hints, FitOutcome};
use crate::load::samples::Samples;
use crate::model::ModelId;
use anyhow::{bail, Result};
use rand::seq::SliceRandom;
use rand::SeedableRng;
use rayon::prelude::*;
use std::time::Instant;

#[derive(Clone, Debug, serde::Serialize)]
pub struct Candidate {
    /// The candidate as the table names it: the rung, `+ fuzz` with the fuzz layer.
    pub name: String,
    pub rung: String,
    /// With the fuzz layer (`fuzz`, `fuzz_depth`, `fuzz_asymmetry` free).
    pub fuzz: bool,
    pub free_parameters: usize,
    /// RMS of the held-out residuals in the fit's metric (`metric`), every held-out sample.
    pub cv_error: f64,
    /// Standard error of `cv_error` (from the per-sample squared residuals).
    pub cv_standard_error: f64,
    /// `cv_error` of each fold (one entry for a single split).
    pub fold_errors: Vec<f64>,
    /// The standard error of each fold's error.
    pub fold_standard_errors: Vec<f64>,
    /// Unweighted RMSE of model - data on the held-out samples, 1/sr.
    pub heldout_rmse: f64,
    pub heldout_relative_rmse: f64,
    /// RMS of ln(m + eps) - ln(y + eps) on the held-out samples (eps: the `log` metric's floor).
    pub heldout_log_error: f64,
    /// Cost of one model evaluation (one sample, all heights), single thread, ns.
    pub ns_per_eval: f64,
    pub fit_seconds: f64,
    /// The knobs the errors were measured with: "coarse" (ranking) or "config" (refined, or a
    /// model the knobs do not change).
    pub knobs: String,
    pub chosen: bool,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub error: Option<String>,
}

impl Candidate {
    /// The per-fold held-out errors, "0.123, 0.145, ...", for the tables.
    pub fn folds_text(&self) -> String {
        self.fold_errors
            .iter()
            .map(|e| format!("{e:.3}"))
            .collect::<Vec<_>>()
            .join(", ")
    }
}

#[derive(Clone, Debug, serde::Serialize)]
pub struct SelectionOutcome {
    pub candidates: Vec<Candidate>,
    /// The chosen candidate's name.
    pub chosen: String,
    pub chosen_rung: String,
    pub chosen_fuzz: bool,
    pub rule: String,
    /// "5-fold cross-validation" or "one split (20 % held out)".
    pub validation: String,
    pub folds: usize,
    /// The metric the errors are in (the fit's).
    pub metric: String,
    pub train_samples: usize,
    pub heldout_samples: usize,
    /// Shape values of the chosen candidate's fit: an extra start for the final fit.
    #[serde(skip)]
    pub hints: Vec<Vec<(Param, f64)>>,
    /// The configuration of the chosen candidate (its rung, the fuzz layer on or off).
    #[serde(skip)]
    pub chosen_config: Option<FitConfig>,
}

fn subset(s: &Samples, idx: &[usize]) -> Samples {
    Samples {
        samples: idx.iter().map(|&i| s.samples[i].clone()).collect(),
        ..s.clone()
    }
}

/// The least-squares problem of `samples` at the fitted outcome `o` (its set and topology map)
/// with the knobs of `cfg`: how a fit is evaluated on other samples.
pub fn problem_at<'a>(o: &FitOutcome, cfg: &FitConfig, samples: &'a Samples) -> FitProblem<'a> {
    FitProblem::new(
        samples.samples.iter().collect(),
        o.set.clone(),
        cfg.metric,
        cfg.knobs.quadrature_order,
        cfg.knobs.histogram_bins,
        o.map.clone(),
        cfg.optimizer.separable,
    )
    .with_azimuth_nodes(cfg.knobs.azimuth_nodes)
}

/// The fitted model's values (per sample and channel) on `samples`, and the problem it used.
pub fn model_values_on<'a>(
    o: &FitOutcome,
    cfg: &FitConfig,
    samples: &'a Samples,
) -> Result<(FitProblem<'a>, Vec<[f64; 3]>)> {
    let p = problem_at(o, cfg, samples);
    let cols = p.columns(&o.set)?;
    let values = p.model_values(&cols, &o.set);
    Ok((p, values))
}

/// Unweighted RMSE, relative RMSE and log error of `values` against the samples `test`
/// (`ch` channels).
fn plain_errors(
    values: &[[f64; 3]],
    test: &[&crate::load::samples::Sample],
    ch: usize,
) -> (f64, f64, f64) {
    let raw: Vec<[f64; 3]> = test.iter().map(|s| s.value).collect();
    let floors: Vec<f64> = (0..ch)
        .map(|c| super::problem::log_floor(&raw, c))
        .collect();
    let (mut se, mut sy, mut sl, mut n) = (0.0, 0.0, 0.0, 0.0);
    for (m, s) in values.iter().zip(test) {
        for (c, (mc, yc)) in m[..ch].iter().zip(&s.value[..ch]).enumerate() {
            se += (mc - yc).powi(2);
            sy += yc.powi(2);
            sl += ((mc.max(0.0) + floors[c]).ln() - (yc.max(0.0) + floors[c]).ln()).powi(2);
            n += 1.0;
        }
    }
    ((se / n).sqrt(), (se / sy).sqrt(), (sl / n).sqrt())
}

/// Per held-out sample of `test`, the mean over channels of the squared log error
/// (ln(m + eps) - ln(y + eps))^2 of the fitted outcome `o` (eps: the `log` metric's floor of
/// `test`): the terms of [`heldout`]'s log error, whose RMS and standard error
/// [`rms_and_se`] gives.
pub fn heldout_log_terms(o: &FitOutcome, cfg: &FitConfig, test: &Samples) -> Result<Vec<f64>> {
    let (_, values) = model_values_on(o, cfg, test)?;
    let ch = o.channels;
    let raw: Vec<[f64; 3]> = test.samples.iter().map(|s| s.value).collect();
    let floors: Vec<f64> = (0..ch)
        .map(|c| super::problem::log_floor(&raw, c))
        .collect();
    Ok(values
        .iter()
        .zip(&test.samples)
        .map(|(m, s)| {
            (0..ch)
                .map(|c| {
                    ((m[c].max(0.0) + floors[c]).ln() - (s.value[c].max(0.0) + floors[c]).ln())
                        .powi(2)
                })
                .sum::<f64>()
                / ch as f64
        })
        .collect())
}

/// Held-out RMSE, relative RMSE and log error of a fitted outcome, and the single-thread cost
/// per sample.
pub fn heldout(o: &FitOutcome, cfg: &FitConfig, test: &Samples) -> Result<(f64, f64, f64, f64)> {
    let (p, values) = model_values_on(o, cfg, test)?;
    let refs: Vec<&crate::load::samples::Sample> = test.samples.iter().collect();
    let (rmse, rel, log) = plain_errors(&values, &refs, o.channels);
    let ns = ns_per_sample(&p, &o.set, test);
    Ok((rmse, rel, log, ns))
}

/// Single-thread cost (ns per sample) of the model of `p` at `set` on up to 500 of `s`.
fn ns_per_sample(p: &FitProblem, set: &ParamSet, s: &Samples) -> f64 {
    let model = p.model_for(set);
    let frame = crate::model::frame::FibreFrame::from_azimuth(0.0);
    let k = s.samples.len().min(500);
    let pairs: Vec<crate::model::DirectionPair> = s.samples[..k]
        .iter()
        .map(|x| crate::model::DirectionPair::new(&frame, &x.l, &x.v))
        .collect();
    let mut bases = vec![crate::model::Basis::default(); k];
    let t = Instant::now();
    model.basis_many(&pairs, &mut bases);
    std::hint::black_box(&bases);
    (t.elapsed().as_nanos() as f64 / k.max(1) as f64).max(1.0)
}

/// Single-thread cost (ns per sample) of `rc`'s model at its start values on up to 200 samples
/// of `s`, at least 1 (1000 when the rung cannot be set up for these data).
fn probe_ns(s: &Samples, rc: &FitConfig) -> f64 {
    let Ok(st) = super::setup::setup(s, rc) else {
        return 1000.0;
    };
    let model = super::problem::model_for(
        &st.template,
        rc.knobs.quadrature_order,
        rc.knobs.histogram_bins,
        rc.knobs.azimuth_nodes,
        st.map.clone(),
    );
    let frame = crate::model::frame::FibreFrame::from_azimuth(0.0);
    let k = s.samples.len().min(200);
    let pairs: Vec<crate::model::DirectionPair> = s.samples[..k]
        .iter()
        .map(|x| crate::model::DirectionPair::new(&frame, &x.l, &x.v))
        .collect();
    let mut bases = vec![crate::model::Basis::default(); k];
    let t = Instant::now();
    model.basis_many(&pairs, &mut bases);
    std::hint::black_box(&bases);
    (t.elapsed().as_nanos() as f64 / k.max(1) as f64).max(1.0)
}

/// The knobs candidates are ranked with: at most 8 quadrature nodes, 4 histogram bins, 8
/// azimuth nodes, 3 starts, 40 iterations and a global subsample of 400. Cheap rungs (lambert,
/// hast-diffuse, ward, max-normal without spread) do not use them and are measured exactly.
pub fn ranking_config(rc: &FitConfig) -> FitConfig {
    let mut c = rc.clone();
    c.knobs.quadrature_order = rc.knobs.quadrature_order.min(8);
    c.knobs.histogram_bins = rc.knobs.histogram_bins.min(4);
    c.knobs.azimuth_nodes = rc.knobs.azimuth_nodes.min(8);
    c.starts = rc.starts.min(3);
    c.optimizer.max_iterations = rc.optimizer.max_iterations.min(40);
    c.optimizer.global_subsample = rc.optimizer.global_subsample.min(400);
    c
}

/// Do the knobs change this fitted model (quadrature, histogram or spread nodes in use)?
fn knobs_matter(set: &ParamSet) -> bool {
    let spread = set
        .shapes
        .iter()
        .any(|s| s.kind == Param::AzimuthSpread && (s.vary || s.value > 0.0));
    spread || set.rung.is_cross_section()
}

/// A fit of `train` warm-started at `start` (LM only, at most `iterations`; none: the albedos
/// re-solved at `start`'s shapes), judged on `test`: the set, the per-sample mean squared
/// residuals on `test` in the fit's metric (the training data's log floor) and the model values.
fn refit_and_predict(
    train: &Samples,
    test: &Samples,
    rc: &FitConfig,
    start: &ParamSet,
    iterations: u64,
) -> Result<(ParamSet, Vec<f64>, Vec<[f64; 3]>)> {
    let st = super::setup::setup(train, rc)?;
    fn make<'s>(
        s: &'s Samples,
        template: &ParamSet,
        rc: &FitConfig,
        st: &super::setup::Setup,
    ) -> FitProblem<'s> {
        FitProblem::new(
            s.samples.iter().collect(),
            template.clone(),
            rc.metric,
            rc.knobs.quadrature_order,
            rc.knobs.histogram_bins,
            st.map.clone(),
            rc.optimizer.separable,
        )
        .with_azimuth_nodes(rc.knobs.azimuth_nodes)
    }
    let train_p = make(train, &st.template, rc, &st);
    let mut begin = st.template.clone();
    for s in begin.shapes.iter_mut() {
        if let Some(x) = start.shapes.iter().find(|x| x.kind == s.kind) {
            s.value = x.value.clamp(s.min, s.max);
        }
    }
    for a in begin.albedos.iter_mut() {
        if let Some(b) = start.albedos.iter().find(|b| b.component == a.component) {
            for c in 0..3 {
                a.value[c] = b.value[c].clamp(a.min, a.max);
            }
        }
    }
    let theta0 = train_p.theta_of(&begin);
    let theta = match iterations > 0 && train_p.dim() > 0 {
        true => {
            let tol = rc.optimizer.tolerance.max(1e-6);
            let bar = indicatif::ProgressBar::hidden();
            super::polish::run_lm(&train_p, &st.template, theta0, iterations, tol, &bar)?.0
        }
        false => theta0,
    };
    let (_, set) = train_p.evaluate(&theta, &st.template)?;
    let test_p = make(test, &set, rc, &st).with_log_floor_of(&train_p);
    let cols = test_p.columns(&set)?;
    let r = test_p.residuals(&cols, &set);
    let ch = test_p.channels();
    let errors: Vec<f64> = (0..test.samples.len())
        .map(|i| (0..ch).map(|c| r[i * ch + c].powi(2)).sum::<f64>() / ch as f64)
        .collect();
    if errors.iter().any(|e| !e.is_finite()) {
        bail!("a held-out residual is not finite");
    }
    let values = test_p.model_values(&cols, &set);
    Ok((set, errors, values))
}

/// How the samples are held out: `folds` lists of held-out indices (disjoint; all of them for
/// cross-validation, one list for a single split).
struct Plan {
    folds: Vec<Vec<usize>>,
    cross_validated: bool,
    /// The indices the candidates' anchor fits use (all samples for cross-validation, at most
    /// `rank_samples` of the training split otherwise).
    anchor: Vec<usize>,
    /// A single split's training indices (empty for cross-validation).
    train: Vec<usize>,
}

fn plan(n: usize, cfg: &FitConfig) -> Plan {
    let mut idx: Vec<usize> = (0..n).collect();
    idx.shuffle(&mut rand::rngs::StdRng::seed_from_u64(cfg.seed ^ 0x5e1ec7));
    let sel = &cfg.selection;
    if n < sel.cv_below {
        let k = sel.folds.min(n);
        let folds = (0..k)
            .map(|j| idx.iter().skip(j).step_by(k).copied().collect())
            .collect();
        Plan {
            folds,
            cross_validated: true,
            anchor: (0..n).collect(),
            train: vec![],
        }
    } else {
        let n_test = ((n as f64 * sel.holdout).ceil() as usize).clamp(1, n - 1);
        let (test, train) = idx.split_at(n_test);
        Plan {
            folds: vec![test.to_vec()],
            cross_validated: false,
            anchor: train[..train.len().min(sel.rank_samples)].to_vec(),
            train: train.to_vec(),
        }
    }
}

/// Held-out errors of one candidate at one configuration.
struct Measured {
    /// Per-sample mean squared residual (metric), in the order of the plan's folds.
    errors: Vec<f64>,
    fold_errors: Vec<f64>,
    fold_standard_errors: Vec<f64>,
    rmse: f64,
    rel: f64,
    log: f64,
}

fn complement(n: usize, fold: &[usize]) -> Vec<usize> {
    let mut out = vec![true; n];
    for &i in fold {
        out[i] = false;
    }
    (0..n).filter(|&i| out[i]).collect()
}

/// Measure a candidate whose anchor fit (on the plan's anchor samples) is `anchor`: every
/// fold's fit warm-started there (`iterations` LM steps at most), judged on the fold.
fn measure(
    samples: &Samples,
    plan: &Plan,
    rc: &FitConfig,
    anchor: &ParamSet,
    iterations: u64,
    channels: usize,
) -> Result<Measured> {
    let n = samples.samples.len();
    let per_fold: Vec<Result<(Vec<f64>, Vec<[f64; 3]>)>> = plan
        .folds
        .par_iter()
        .map(|fold| {
            let train_idx = match plan.cross_validated {
                true => complement(n, fold),
                false => plan.anchor.clone(),
            };
            let train = subset(samples, &train_idx);
            let test = subset(samples, fold);
            let (_, e, v) = refit_and_predict(&train, &test, rc, anchor, iterations)?;
            Ok((e, v))
        })
        .collect();
    let mut errors = Vec::new();
    let mut values = Vec::new();
    let mut fold_errors = Vec::new();
    let mut fold_standard_errors = Vec::new();
    let mut tested = Vec::new();
    for (fold, r) in plan.folds.iter().zip(per_fold) {
        let (e, v) = r?;
        let (rms, se) = rms_and_se(&e);
        fold_errors.push(rms);
        fold_standard_errors.push(se);
        errors.extend(e);
        values.extend(v);
        tested.extend(fold.iter().map(|&i| &samples.samples[i]));
    }
    let (rmse, rel, log) = plain_errors(&values, &tested, channels);
    Ok(Measured {
        errors,
        fold_errors,
        fold_standard_errors,
        rmse,
        rel,
        log,
    })
}

/// The RMS of per-sample squared residuals `e` (the square root of their mean) and its
/// standard error (the mean's, sd / sqrt(n), carried through the square root).
pub fn rms_and_se(e: &[f64]) -> (f64, f64) {
    let n = e.len() as f64;
    let mean = e.iter().sum::<f64>() / n;
    let var = e.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1.0).max(1.0);
    let rms = mean.sqrt();
    (rms, (var / n).sqrt() / (2.0 * rms).max(f64::MIN_POSITIVE))
}

/// How far a candidate's error measured with the coarse ranking knobs may lie from its error
/// at the config's knobs (relative, either way); `fibrefit bench selection --slow` measures
/// both (reports/selection.md).
pub const KNOBS_TOLERANCE: f64 = 0.05;

/// LM iterations of a refinement at the config's knobs (from the coarse optimum) and of each
/// fold's warm-started fit.
pub const REFINE_ITERATIONS: u64 = 10;

/// The candidates measured with coarse knobs whose refinement could change the rule's choice
/// (their errors known within [`KNOBS_TOLERANCE`]): none when the choice is certain. Scanning
/// the candidates simplest first, the first that is neither surely within the threshold nor
/// surely beyond it is undecided, together with every coarse candidate that may set the
/// threshold (the best).
pub fn undecided(candidates: &[Candidate], tolerance: Option<f64>) -> Vec<usize> {
    let coarse = |c: &Candidate| c.knobs == "coarse";
    let range = |c: &Candidate| match coarse(c) {
        true => (
            c.cv_error * (1.0 - KNOBS_TOLERANCE),
            c.cv_error * (1.0 + KNOBS_TOLERANCE),
        ),
        false => (c.cv_error, c.cv_error),
    };
    let ok: Vec<usize> = (0..candidates.len())
        .filter(|&k| candidates[k].error.is_none() && candidates[k].cv_error.is_finite())
        .collect();
    let Some(&best) = ok
        .iter()
        .min_by(|&&a, &&b| candidates[a].cv_error.total_cmp(&candidates[b].cv_error))
    else {
        return vec![];
    };
    let best_lo = ok
        .iter()
        .map(|&k| range(&candidates[k]).0)
        .fold(f64::INFINITY, f64::min);
    let best_hi = ok
        .iter()
        .map(|&k| range(&candidates[k]).1)
        .fold(f64::INFINITY, f64::min);
    let se = candidates[best].cv_standard_error;
    let threshold = |b: f64| match tolerance {
        Some(t) => b * (1.0 + t),
        None => b + se,
    };
    let (t_lo, t_hi) = (threshold(best_lo), threshold(best_hi));
    let mut order = ok.clone();
    order.sort_by_key(|&k| (candidates[k].free_parameters, k));
    for k in order {
        let (lo, hi) = range(&candidates[k]);
        if hi <= t_lo {
            return vec![];
        }
        if lo > t_hi {
            continue;
        }
        // undecided: this one, and the coarse ones that may be the best
        let mut out: Vec<usize> = ok
            .iter()
            .copied()
            .filter(|&j| coarse(&candidates[j]) && range(&candidates[j]).0 <= best_hi)
            .collect();
        if coarse(&candidates[k]) && !out.contains(&k) {
            out.push(k);
        }
        return out;
    }
    vec![]
}

/// The rule's choice among measured `candidates` (in the list's order: cheapest rung first,
/// each without the fuzz layer before with it), on the pooled errors (`fold` None) or one
/// fold's: the simplest (fewest free parameters, then the list's order) whose error is at
/// most the best's plus its standard error (or, with `tolerance`, the best's times 1 +
/// tolerance). `None` when none was measured.
pub fn rule_choice(
    candidates: &[Candidate],
    fold: Option<usize>,
    tolerance: Option<f64>,
) -> Option<usize> {
    let score = |c: &Candidate| -> Option<(f64, f64)> {
        if c.error.is_some() {
            return None;
        }
        let s = match fold {
            None => (c.cv_error, c.cv_standard_error),
            Some(j) => (*c.fold_errors.get(j)?, *c.fold_standard_errors.get(j)?),
        };
        s.0.is_finite().then_some(s)
    };
    let (best, se) = candidates
        .iter()
        .filter_map(score)
        .min_by(|a, b| a.0.total_cmp(&b.0))?;
    let threshold = match tolerance {
        Some(t) => best * (1.0 + t),
        None => best + se,
    };
    let mut order: Vec<usize> = (0..candidates.len())
        .filter(|&k| score(&candidates[k]).is_some())
        .collect();
    order.sort_by_key(|&k| (candidates[k].free_parameters, k));
    order
        .into_iter()
        .find(|&k| score(&candidates[k]).is_some_and(|(e, _)| e <= threshold))
}

pub fn select(samples: &Samples, cfg: &FitConfig) -> Result<SelectionOutcome> {
    select_with(
        samples,
        cfg,
        &crate::progress::Progress::quiet(),
        &mut |_| {},
    )
}

/// A candidate of `--model auto` just finished (measured or failed).
pub struct RungDone<'a> {
    /// Every candidate finished so far, this one last.
    pub candidates: &'a [Candidate],
    /// This candidate's anchor fit (`None` when it failed).
    pub outcome: Option<&'a FitOutcome>,
    /// The candidates to try, in order (their names).
    pub rungs: &'a [String],
    pub train_samples: usize,
    pub heldout_samples: usize,
}

/// The candidates of `cfg`: every rung, without and with the fuzz layer (only with it when the
/// config lists a fuzz parameter or `--fuzz` asked; only without when `selection.fuzz` is
/// false): (name, rung, fuzz, config).
pub fn candidates_of(cfg: &FitConfig) -> Result<Vec<(String, ModelId, bool, FitConfig)>> {
    let listed = cfg.listed_fuzz_parameter().is_some();
    let mut out = Vec::new();
    for name in &cfg.selection.rungs {
        let id: ModelId = name.parse().map_err(|e: String| anyhow::anyhow!(e))?;
        let rc = cfg.for_rung(id);
        let variants: &[bool] = match (listed, cfg.selection.fuzz) {
            (true, _) => &[true],
            (false, true) => &[false, true],
            (false, false) => &[false],
        };
        for &fuzz in variants {
            let mut c = rc.clone();
            if fuzz && !listed {
                c.add_fuzz_layer();
            }
            let label = match fuzz {
                true => format!("{id} + fuzz"),
                false => id.to_string(),
            };
            out.push((label, id, fuzz, c));
        }
    }
    Ok(out)
}

/// [`select`], with a progress line per candidate through `progress` (name, elapsed
/// time, an estimate of the time left) and `on_rung` called as each candidate finishes
/// (partial results).
pub fn select_with(
    samples: &Samples,
    cfg: &FitConfig,
    progress: &crate::progress::Progress,
    on_rung: &mut dyn FnMut(&RungDone),
) -> Result<SelectionOutcome> {
    let n = samples.samples.len();
    if n < 10 {
        bail!("--model auto needs at least 10 samples to hold some out; got {n}");
    }
    let plan = plan(n, cfg);
    let anchor_samples = subset(samples, &plan.anchor);
    let heldout_samples: usize = plan.folds.iter().map(Vec::len).sum();
    let train_samples = match plan.cross_validated {
        true => n - n.div_ceil(plan.folds.len()),
        false => plan.train.len(),
    };
    let list = candidates_of(cfg)?;
    let names: Vec<String> = list.iter().map(|c| c.0.clone()).collect();
    let fold_iterations = cfg.optimizer.max_iterations.min(REFINE_ITERATIONS);
    let mut candidates: Vec<Candidate> = Vec::new();
    let mut anchors: Vec<Option<ParamSet>> = Vec::new();
    let mut hints: Vec<Vec<(Param, f64)>> = Vec::new();
    let started = Instant::now();
    // the time left, estimated from the seconds per unit of planned work of the candidates
    // done; a candidate's work: its planned evaluations times the cost of one
    let planned: Vec<f64> = match progress.shown() {
        false => vec![0.0; list.len()],
        true => list
            .iter()
            .map(|(_, _, _, rc)| {
                let rc = ranking_config(rc);
                rc.planned_evaluations(anchor_samples.samples.len())
                    * (1.0 + plan.folds.len() as f64 * 0.3)
                    * probe_ns(&anchor_samples, &rc)
            })
            .collect(),
    };
    for (k, (name, id, fuzz, rc)) in list.iter().enumerate() {
        let coarse = match cfg.selection.coarse_ranking {
            true => ranking_config(rc),
            false => rc.clone(),
        };
        let elapsed = started.elapsed().as_secs_f64();
        let estimate = match planned[..k].iter().sum::<f64>() {
            done if k > 0 && done > 0.0 => format!(
                "; estimate: {} left",
                crate::progress::seconds(elapsed / done * planned[k..].iter().sum::<f64>())
            ),
            _ => String::new(),
        };
        progress.line(&format!(
            "auto: rung {}/{} {name} (elapsed {}{estimate})",
            k + 1,
            list.len(),
            crate::progress::seconds(elapsed)
        ));
        let t = Instant::now();
        let mut fitted = None;
        // every simpler candidate's optimum is a start: a rung nested in a richer one
        // (poulin-fournier is varying-topology at height 0) then never ends worse than it
        let result = fit_with_hints(
            &anchor_samples,
            &coarse,
            &crate::progress::Progress::quiet(),
            &hints,
        )
        .and_then(|o| {
            let iters = match plan.cross_validated {
                true => fold_iterations,
                false => 0,
            };
            let m = measure(samples, &plan, &coarse, &o.set, iters, o.channels)?;
            let ns = ns_per_sample(
                &problem_at(&o, &coarse, &anchor_samples),
                &o.set,
                &anchor_samples,
            );
            hints.push(o.set.shapes.iter().map(|s| (s.kind, s.value)).collect());
            let p = o.statistics.free_parameters;
            // measured at the config's knobs: a model the knobs do not change, or no coarse
            // ranking asked for (then nothing is refined)
            let exact = !cfg.selection.coarse_ranking || !knobs_matter(&o.set);
            anchors.push(Some(o.set.clone()));
            fitted = Some(o);
            Ok((p, m, ns, exact))
        });
        let failed = |e: String, secs: f64| Candidate {
            name: name.clone(),
            rung: id.to_string(),
            fuzz: *fuzz,
            free_parameters: 0,
            cv_error: f64::NAN,
            cv_standard_error: f64::NAN,
            fold_errors: vec![],
            fold_standard_errors: vec![],
            heldout_rmse: f64::NAN,
            heldout_relative_rmse: f64::NAN,
            heldout_log_error: f64::NAN,
            ns_per_eval: f64::NAN,
            fit_seconds: secs,
            knobs: "coarse".into(),
            chosen: false,
            error: Some(e),
        };
        match result {
            Ok((p, m, ns, exact)) => {
                let mut c = failed(String::new(), 0.0);
                c.error = None;
                c.free_parameters = p;
                c.ns_per_eval = ns;
                c.knobs = if exact { "config" } else { "coarse" }.into();
                set_errors(&mut c, &m);
                c.fit_seconds = t.elapsed().as_secs_f64();
                candidates.push(c);
            }
            Err(e) => {
                anchors.push(None);
                candidates.push(failed(format!("{e:#}"), t.elapsed().as_secs_f64()));
            }
        }
        let c = candidates.last().expect("pushed");
        progress.line(&match &c.error {
            None => format!(
                "auto: {name} fitted in {}: held-out error {:.4} +/- {:.4} ({} metric{})",
                crate::progress::seconds(c.fit_seconds),
                c.cv_error,
                c.cv_standard_error,
                metric_name(cfg.metric),
                if c.knobs == "coarse" {
                    ", coarse knobs"
                } else {
                    ""
                }
            ),
            Some(e) => format!(
                "auto: {name} failed after {}: {e}",
                crate::progress::seconds(c.fit_seconds)
            ),
        });
        on_rung(&RungDone {
            candidates: &candidates,
            outcome: fitted.as_ref(),
            rungs: &names,
            train_samples,
            heldout_samples,
        });
    }
    // refine what the decision needs: a coarse error may differ from the config's knobs' by
    // KNOBS_TOLERANCE either way; the candidates whose refinement could change the choice are
    // refitted at the config's knobs from their coarse optimum, until the choice is certain
    if !candidates.iter().any(|c| c.error.is_none()) {
        bail!("--model auto: no rung could be fitted");
    }
    let mut tried = vec![false; list.len()];
    loop {
        let wanted = undecided(&candidates, cfg.selection.tolerance);
        let wanted: Vec<usize> = wanted.into_iter().filter(|&k| !tried[k]).collect();
        if wanted.is_empty() {
            break;
        }
        for k in wanted {
            tried[k] = true;
            let Some(set) = anchors[k].clone() else {
                continue;
            };
            let (name, _, _, rc) = &list[k];
            progress.line(&format!("auto: refining {name} at the config's knobs"));
            let t = Instant::now();
            let refined = refit_and_predict(
                &anchor_samples,
                &anchor_samples,
                rc,
                &set,
                REFINE_ITERATIONS,
            )
            .and_then(|(s, _, _)| {
                let iters = match plan.cross_validated {
                    true => REFINE_ITERATIONS,
                    false => 0,
                };
                let m = measure(samples, &plan, rc, &s, iters, s.channels)?;
                Ok((s, m))
            });
            match refined {
                Ok((s, m)) => {
                    let c = &mut candidates[k];
                    set_errors(c, &m);
                    c.fit_seconds += t.elapsed().as_secs_f64();
                    c.knobs = "config".into();
                    anchors[k] = Some(s);
                    progress.line(&format!(
                        "auto: {name} refined in {}: held-out error {:.4} +/- {:.4}",
                        crate::progress::seconds(t.elapsed().as_secs_f64()),
                        c.cv_error,
                        c.cv_standard_error
                    ));
                }
                Err(e) => progress.line(&format!(
                    "auto: {name} could not be refined (its coarse errors stand): {e:#}"
                )),
            }
        }
    }
    let best_k = candidates
        .iter()
        .enumerate()
        .filter(|(_, c)| c.error.is_none())
        .min_by(|a, b| a.1.cv_error.total_cmp(&b.1.cv_error))
        .map(|(k, _)| k)
        .expect("one candidate was measured");
    let rule = match cfg.selection.tolerance {
        Some(t) => format!(
            "the simplest candidate (fewest free parameters, cheapest rung, without the fuzz layer \
             before with it) whose held-out error ({} metric) is within {:.1} % of the best",
            metric_name(cfg.metric),
            100.0 * t
        ),
        None => format!(
            "one-standard-error rule: the simplest candidate (fewest free parameters, cheapest \
             rung, without the fuzz layer before with it) whose held-out error ({} metric) is at \
             most the best's plus its standard error ({}: {:.4} + {:.4})",
            metric_name(cfg.metric),
            candidates[best_k].name,
            candidates[best_k].cv_error,
            candidates[best_k].cv_standard_error
        ),
    };
    let chosen = rule_choice(&candidates, None, cfg.selection.tolerance)
        .expect("the best candidate is within its own noise");
    candidates[chosen].chosen = true;
    // the final fit starts (besides its own search) from the chosen candidate's optimum, which
    // began from every simpler candidate's
    let ordered_hints = vec![hints_for(&anchors[chosen])];
    let validation = match plan.cross_validated {
        true => format!("{}-fold cross-validation", plan.folds.len()),
        false => format!(
            "one split ({:.0} % held out; {} samples, cross-validation below {})",
            100.0 * cfg.selection.holdout,
            n,
            cfg.selection.cv_below
        ),
    };
    Ok(SelectionOutcome {
        chosen: candidates[chosen].name.clone(),
        chosen_rung: list[chosen].1.to_string(),
        chosen_fuzz: list[chosen].2,
        rule,
        validation,
        folds: plan.folds.len(),
        metric: metric_name(cfg.metric).into(),
        train_samples,
        heldout_samples,
        candidates,
        hints: ordered_hints,
        chosen_config: Some(list[chosen].3.clone()),
    })
}

/// A candidate's errors from its measurement.
fn set_errors(c: &mut Candidate, m: &Measured) {
    let (rms, se) = rms_and_se(&m.errors);
    c.cv_error = rms;
    c.cv_standard_error = se;
    c.fold_errors = m.fold_errors.clone();
    c.fold_standard_errors = m.fold_standard_errors.clone();
    c.heldout_rmse = m.rmse;
    c.heldout_relative_rmse = m.rel;
    c.heldout_log_error = m.log;
}

fn hints_for(a: &Option<ParamSet>) -> Vec<(Param, f64)> {
    a.as_ref()
        .map(|s| s.shapes.iter().map(|s| (s.kind, s.value)).collect())
        .unwrap_or_default()
}

pub fn metric_name(m: Metric) -> &'static str {
    match m {
        Metric::Linear => "linear",
        Metric::Log => "log",
        Metric::Cosine => "cosine",
    }
}

/// The selection table in markdown.
pub fn table(s: &SelectionOutcome) -> String {
    let mut t = format!(
        "Model selection by {} ({} training / {} held-out samples{}; errors in the {} metric)\n\
         Rule: {}.\n\n\
         | candidate | free parameters | held-out error | standard error | per fold | held-out RMSE [1/sr] | held-out relative RMSE | held-out log error | knobs | ns per evaluation | fit time [s] | chosen |\n\
         |---|---|---|---|---|---|---|---|---|---|---|---|\n",
        s.validation,
        s.train_samples,
        s.heldout_samples,
        if s.folds > 1 { " per fold" } else { "" },
        s.metric,
        s.rule
    );
    for c in &s.candidates {
        match &c.error {
            Some(e) => {
                t += &format!(
                    "| {} | - | failed: {e} | | | | | | | | {:.2} | |\n",
                    c.name, c.fit_seconds
                )
            }
            None => {
                t += &format!(
                    "| {} | {} | {:.4} | {:.4} | {} | {:.4e} | {:.2} % | {:.4} | {} | {:.0} | {:.2} | {} |\n",
                    c.name,
                    c.free_parameters,
                    c.cv_error,
                    c.cv_standard_error,
                    c.folds_text(),
                    c.heldout_rmse,
                    100.0 * c.heldout_relative_rmse,
                    c.heldout_log_error,
                    c.knobs,
                    c.ns_per_eval,
                    c.fit_seconds,
                    if c.chosen { "**yes**" } else { "" }
                )
            }
        }
    }
    t
}
