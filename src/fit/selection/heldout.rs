//! A fitted model's held-out error on the folds (or the split) `--model auto` measures its
//! candidates on, per held-out sample: what the floor (`fit::floor`) is compared with.

use super::*;

/// One fold of cross-validation, or the one split: the samples a fit saw and those it is
/// judged on (indices into the data).
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Split {
    /// The samples the fit of this fold was trained on.
    pub train: Vec<usize>,
    /// The samples it is judged on.
    pub test: Vec<usize>,
}

/// A model's held-out errors in the fit's metric, per held-out sample.
#[derive(Clone, Debug, Default)]
pub struct HeldOut {
    /// The folds (or the one split) measured on.
    pub splits: Vec<Split>,
    /// Per held-out sample (the splits' `test` samples in order), the mean over channels of the
    /// squared residual in the metric.
    pub errors: Vec<f64>,
    /// The model's values on those samples, in the same order.
    pub values: Vec<[f64; 3]>,
    /// The RMS held-out error: sqrt(mean(errors)).
    pub error: f64,
    /// Its standard error.
    pub standard_error: f64,
    /// "5-fold cross-validation" or "one split (20 % held out; ...)".
    pub validation: String,
}

/// The splits of `plan` over `n` samples: for cross-validation each fold against the others;
/// for one split the held-out part against the samples the fits trained on (the anchor).
pub(super) fn splits_of(plan: &Plan, n: usize) -> Vec<Split> {
    plan.folds
        .iter()
        .map(|fold| Split {
            train: match plan.cross_validated {
                true => complement(n, fold),
                false => plan.anchor.clone(),
            },
            test: fold.clone(),
        })
        .collect()
}

/// How `plan` holds samples out, in words.
pub(super) fn validation_text(plan: &Plan, cfg: &FitConfig, n: usize) -> String {
    validation_of(plan, &cfg.selection, n)
}

fn validation_of(plan: &Plan, sel: &crate::fit::config::Selection, n: usize) -> String {
    match plan.cross_validated {
        true => format!("{}-fold cross-validation", plan.folds.len()),
        false => format!(
            "one split ({:.0} % held out; {n} samples, cross-validation below {})",
            100.0 * sel.holdout,
            sel.cv_below
        ),
    }
}

/// The seeded folds (fewer than `sel.cv_below` samples) or the one split (training on the
/// whole training part) a named rung's fit of `n` samples is measured on, and their words.
pub fn splits_for(n: usize, sel: &crate::fit::config::Selection, seed: u64) -> Result<(Vec<Split>, String)> {
    if n < 10 {
        bail!("a held-out error needs at least 10 samples; got {n}");
    }
    let mut plan = plan_of(n, sel, seed);
    if !plan.cross_validated {
        plan.anchor = plan.train.clone();
    }
    Ok((splits_of(&plan, n), validation_of(&plan, sel, n)))
}

/// The chosen candidate's held-out errors of an auto run (`None` when it kept none).
pub fn of_selection(s: &SelectionOutcome) -> Option<HeldOut> {
    let c = s.candidates.iter().find(|c| c.chosen)?;
    (!c.heldout_errors.is_empty()).then(|| HeldOut {
        splits: s.splits.clone(),
        errors: c.heldout_errors.clone(),
        values: c.heldout_values.clone(),
        error: c.cv_error,
        standard_error: c.cv_standard_error,
        validation: s.validation.clone(),
    })
}

/// A named rung's fit (`set`, fitted to all of `samples` with `cfg`) measured as `--model auto`
/// measures a candidate, on the same seeded folds or split: each fold's fit (the whole
/// training part of a split) warm-started at `set` and polished for [`REFINE_ITERATIONS`] LM
/// steps on its training samples, judged on the samples it did not see. Warm-started from an
/// optimum that saw every sample, it is a little optimistic.
pub fn of_fit(samples: &Samples, cfg: &FitConfig, set: &ParamSet) -> Result<HeldOut> {
    let n = samples.samples.len();
    if n < 10 {
        bail!("a held-out error needs at least 10 samples; got {n}");
    }
    let mut plan = plan(n, cfg);
    if !plan.cross_validated {
        plan.anchor = plan.train.clone();
    }
    let m = measure(samples, &plan, cfg, set, REFINE_ITERATIONS, set.channels)?;
    let (error, standard_error) = rms_and_se(&m.errors);
    Ok(HeldOut {
        splits: splits_of(&plan, n),
        errors: m.errors,
        values: m.values,
        error,
        standard_error,
        validation: validation_text(&plan, cfg, n),
    })
}
