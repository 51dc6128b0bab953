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
//!   are refined: refitted at the config's knobs, warm-started from their coarse optimum. The
//!   chosen candidate's final fit on all samples runs its global stage at those coarse knobs too
//!   (`FitConfig::search_knobs`; where its anchor was found) and polishes every basin at the
//!   config's knobs.
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
use super::{fit_with_hints, FitOutcome};
use crate::fit::problem::FitProblem;
use crate::load::samples::Samples;
use crate::model::ModelId;
use anyhow::{bail, Result};
use rand::seq::SliceRandom;
use rand::SeedableRng;
use rayon::prelude::*;
use std::time::Instant;

/// One candidate of `--model auto`: a rung, with or without the fuzz layer, and its held-out
/// errors.
#[derive(Clone, Debug, serde::Serialize)]
pub struct Candidate {
    /// The candidate as the table names it: the rung, `+ fuzz` with the fuzz layer.
    pub name: String,
    /// The rung's id.
    pub rung: String,
    /// With the fuzz layer (`fuzz`, `fuzz_depth`, `fuzz_asymmetry` free).
    pub fuzz: bool,
    /// Free parameters of its fit.
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
    /// `heldout_rmse` over the RMS of the held-out data.
    pub heldout_relative_rmse: f64,
    /// RMS of ln(m + eps) - ln(y + eps) on the held-out samples (eps: the `log` metric's floor).
    pub heldout_log_error: f64,
    /// Cost of one model evaluation (one sample, all heights), single thread, ns.
    pub ns_per_eval: f64,
    /// Wall time of its fits and measurements, seconds.
    pub fit_seconds: f64,
    /// The knobs the errors were measured with: "coarse" (ranking) or "config" (refined, or a
    /// model the knobs do not change).
    pub knobs: String,
    /// Chosen by the rule.
    pub chosen: bool,
    /// Why it could not be fitted, if it failed.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub error: Option<String>,
    /// Per held-out sample, the mean over channels of its squared residual (in the order of
    /// the selection's splits' held-out samples).
    #[serde(skip)]
    pub heldout_errors: Vec<f64>,
    /// The model's values on the held-out samples, in the same order.
    #[serde(skip)]
    pub heldout_values: Vec<[f64; 3]>,
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

/// How `--model auto` chose: the candidates, the rule and the choice.
#[derive(Clone, Debug, serde::Serialize)]
pub struct SelectionOutcome {
    /// Every candidate, in the order tried.
    pub candidates: Vec<Candidate>,
    /// The chosen candidate's name.
    pub chosen: String,
    /// The chosen candidate's rung.
    pub chosen_rung: String,
    /// The chosen candidate has the fuzz layer.
    pub chosen_fuzz: bool,
    /// The rule, in words (with the best's figures).
    pub rule: String,
    /// "5-fold cross-validation" or "one split (20 % held out)".
    pub validation: String,
    /// Folds of cross-validation (1 for one split).
    pub folds: usize,
    /// The metric the errors are in (the fit's).
    pub metric: String,
    /// Samples each candidate was fitted on and held out, per fold and in all.
    pub counts: Counts,
    /// Shape values of the chosen candidate's fit: an extra start for the final fit.
    #[serde(skip)]
    pub hints: Vec<Vec<(Param, f64)>>,
    /// The configuration of the chosen candidate (its rung, the fuzz layer on or off).
    #[serde(skip)]
    pub chosen_config: Option<FitConfig>,
    /// The folds (or the one split) every candidate was measured on.
    #[serde(skip)]
    pub splits: Vec<Split>,
}

mod heldout;
mod measure;
mod rule;
mod run;
mod table;

pub use heldout::{of_fit, of_selection, splits_for, HeldOut, Split};
use measure::*;
pub use measure::{
    heldout, heldout_log_terms, model_values_on, plain_errors, problem_at, ranking_config,
};
pub use rule::*;
pub use run::select_with;
pub use table::{metric_name, table};

/// The best candidate that is a renderer's own material (a rung with
/// [`crate::model::Rung::renderer`], without the fuzz layer), per renderer, beside the choice.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct RendererRoute {
    /// The renderer, in words.
    pub renderer: String,
    /// Its best candidate (the rung).
    pub candidate: String,
    /// Its held-out error and standard error (the fit's metric).
    pub cv_error: f64,
    pub cv_standard_error: f64,
    /// The choice and its held-out error.
    pub chosen: String,
    pub chosen_error: f64,
    /// Whether its error is within the choice's standard error of the choice's.
    pub within_noise: bool,
    /// What the difference means, in one line.
    pub text: String,
}

/// The renderers' own materials among the candidates of `s`, each with its held-out error
/// beside the choice and what the difference means; empty when none was measured.
pub fn renderer_routes(s: &SelectionOutcome) -> Vec<RendererRoute> {
    let Some(chosen) = s.candidates.iter().find(|c| c.chosen) else {
        return Vec::new();
    };
    // each renderer's best candidate, in the order the renderers first appear
    let mut best: Vec<(&str, &Candidate)> = Vec::new();
    for c in s.candidates.iter().filter(|c| !c.fuzz && c.error.is_none()) {
        let Some(renderer) = c.rung.parse::<ModelId>().ok().and_then(|id| id.rung().renderer)
        else {
            continue;
        };
        match best.iter_mut().find(|b| b.0 == renderer) {
            Some(b) if c.cv_error < b.1.cv_error => b.1 = c,
            Some(_) => {}
            None => best.push((renderer, c)),
        }
    }
    let mut out = Vec::new();
    for (renderer, c) in best {
        let within = c.cv_error <= chosen.cv_error + chosen.cv_standard_error;
        let pct = 100.0 * (c.cv_error / chosen.cv_error - 1.0);
        let head = format!(
            "for {renderer}: `{}`, held-out error {:.4} +- {:.4}",
            c.name, c.cv_error, c.cv_standard_error
        );
        let text = if c.chosen {
            format!("{head}: it is the choice; its export carries the fit exactly")
        } else if within {
            format!(
                "{head}; the choice `{}` {:.4} ({pct:+.0} %): within the noise, the renderer's own material carries these data as well as the choice",
                chosen.name, chosen.cv_error
            )
        } else {
            format!(
                "{head}; the choice `{}` {:.4}: {pct:.0} % higher error in that renderer's own material; where that matters use the Mitsuba plugin or the exported shader (`export --shader`)",
                chosen.name, chosen.cv_error
            )
        };
        out.push(RendererRoute {
            renderer: renderer.to_string(),
            candidate: c.name.clone(),
            cv_error: c.cv_error,
            cv_standard_error: c.cv_standard_error,
            chosen: chosen.name.clone(),
            chosen_error: chosen.cv_error,
            within_noise: within || c.chosen,
            text,
        });
    }
    out
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
    /// Samples fitted on and held out, per fold and in all.
    pub counts: Counts,
}

/// How many samples a `--model auto` run fitted each candidate on and held out: per fold (what
/// one fit saw and was measured on) and in all (with cross-validation every sample once).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize)]
pub struct Counts {
    /// Folds of cross-validation (1 for one split).
    pub folds: usize,
    /// Samples one fit was trained on: all but one fold (the fewest over the folds), or the
    /// training split.
    pub train_samples_per_fold: usize,
    /// Samples one fold holds out (the most over the folds, which differ by at most one), or
    /// the held-out split.
    pub heldout_samples_per_fold: usize,
    /// Samples held out in all (every sample once with cross-validation).
    pub heldout_samples_total: usize,
}

impl Counts {
    /// The counts of `plan` over `n` samples.
    fn of(plan: &Plan, n: usize) -> Self {
        let heldout_samples_per_fold = plan.folds.iter().map(Vec::len).max().unwrap_or(0);
        Self {
            folds: plan.folds.len(),
            train_samples_per_fold: match plan.cross_validated {
                true => n - heldout_samples_per_fold,
                false => plan.train.len(),
            },
            heldout_samples_per_fold,
            heldout_samples_total: plan.folds.iter().map(Vec::len).sum(),
        }
    }

    /// In words: "240 training / 60 held-out samples per fold, 300 held out in all" (ranges
    /// where the folds differ by one), or "240 training / 60 held-out samples" for one split.
    pub fn text(&self) -> String {
        let (t, h) = (self.train_samples_per_fold, self.heldout_samples_per_fold);
        if self.folds <= 1 {
            return format!("{t} training / {h} held-out samples");
        }
        let (t, h) = match self.heldout_samples_total % self.folds {
            0 => (t.to_string(), h.to_string()),
            _ => (format!("{t}-{}", t + 1), format!("{}-{h}", h - 1)),
        };
        format!(
            "{t} training / {h} held-out samples per fold, {} held out in all",
            self.heldout_samples_total
        )
    }
}

/// The candidates of `cfg`: every rung, without and with the fuzz layer (only with it when the
/// config lists a fuzz parameter or `--fuzz` asked; only without when `selection.fuzz` is
/// false or the rung is not tried with it, [`crate::model::Rung::auto_fuzz`]): (name, rung,
/// fuzz, config).
pub fn candidates_of(cfg: &FitConfig) -> Result<Vec<(String, ModelId, bool, FitConfig)>> {
    let listed = cfg.listed_fuzz_parameter().is_some();
    let mut out = Vec::new();
    for name in &cfg.selection.rungs {
        let id: ModelId = name.parse().map_err(|e: String| anyhow::anyhow!(e))?;
        let rc = cfg.for_rung(id);
        let variants: &[bool] = match (listed, cfg.selection.fuzz && id.rung().auto_fuzz) {
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
