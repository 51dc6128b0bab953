//! The rule that chooses among measured candidates (one standard error, or a relative
//! tolerance) and which coarse measurements could still change its choice.

use super::*;

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
