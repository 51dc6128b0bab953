//! The correction stage: where a fit of data without sigmas misses structure the data hold
//! (beyond [`crate::fit::floor::WITHIN`] the floor), a smooth reciprocal factor
//! ([`crate::model::correction`]) on the fitted rung, its degree chosen held out on `--model
//! auto`'s folds (or split): the fewest terms whose held-out error is within one standard error
//! of the best's, the standard error that of their paired difference (every candidate is judged
//! on the same held-out samples, so their errors move together; auto's rule for rungs takes the
//! best's own standard error), no correction among the candidates. Kept only where it pays.
//!
//! Beside the material's reciprocal series, each degree d fits the instrument's light/view
//! imbalance, exp(sum_{k=1..d} b_k (P_k(x_i) - P_k(x_o))) ([`Correction::instrument`]): a
//! material is reciprocal, so what of the data is not is the instrument's, and a model of the
//! measurement has to carry it to be judged against the floor (a predictor of the data). The
//! held-out errors, the verdict and the residual bins are the measurement model's; the material
//! delivered (eval, render, exports) is the rung times the reciprocal series alone, and its
//! held-out error is reported beside (`material_error`).
//!
//! Each fold's series is fitted to the training part's log residuals of the fit to all samples
//! (the rung's parameters hardly move between folds) and judged on the fold's held-out values
//! of the rung's own fold fit, times the series. The kept series is then fitted to every
//! sample's log residual.

use crate::fit::selection::{rms_and_se, HeldOut};
use crate::load::samples::{Sample, Samples};
use crate::model::correction::{coordinates, Correction, MAX_DEGREE};
use crate::model::frame::Local;
use serde::Serialize;

/// Each fold's training part holds at least this many samples per term of a series tried.
pub const SAMPLES_PER_TERM: usize = 5;

/// One degree tried: its held-out error (RMS in the `log` metric) and standard error.
#[derive(Clone, Debug, Serialize, PartialEq)]
pub struct Tried {
    /// Total degree; `None`: no correction (the rung alone).
    pub degree: Option<usize>,
    /// Coefficients per channel (0 for none), the material's series and the instrument's.
    pub terms: usize,
    pub error: f64,
    pub standard_error: f64,
    /// The standard error of its held-out error's difference from the best's, the two paired
    /// on the same samples (RMS units; 0 for the best): the rule's yardstick.
    pub paired_standard_error: f64,
    /// Its held-out error without the instrument's terms: the material's.
    pub material_error: f64,
}

/// A kept correction and how it was chosen.
#[derive(Clone, Debug, Serialize, PartialEq)]
pub struct CorrectionFit {
    /// The series, fitted to every sample.
    pub correction: Correction,
    /// The rung's held-out error alone and its standard error.
    pub rung_error: f64,
    pub rung_standard_error: f64,
    /// The held-out error with the correction, and its standard error.
    pub error: f64,
    pub standard_error: f64,
    /// The held-out error of the corrected material alone, without the instrument's terms.
    pub material_error: f64,
    /// The reciprocal floor (what a material can reach on data that are not reciprocal), where
    /// the floor check measured one: the yardstick of `material_error`.
    pub reciprocal_floor: Option<f64>,
    /// Every degree tried, none first.
    pub tried: Vec<Tried>,
    /// How samples were held out (auto's words).
    pub validation: String,
}

/// What the stage decided.
pub enum Decision {
    /// A correction pays: it, and the model's held-out errors with it.
    Kept(CorrectionFit, HeldOut),
    /// None does (the degrees tried, none first).
    NotKept(Vec<Tried>),
}

fn local(v: &crate::model::Vec3) -> Local {
    Local {
        t: v.x,
        b: v.y,
        n: v.z,
    }
}

/// The series' coordinates of a sample (swatch frame; z the normal).
pub fn sample_point(s: &Sample) -> (f64, f64, f64) {
    coordinates(&local(&s.l), &local(&s.v))
}

fn log_floors(samples: &[&Sample]) -> [f64; 3] {
    let raw: Vec<[f64; 3]> = samples.iter().map(|s| s.value).collect();
    [0, 1, 2].map(|c| crate::fit::problem::log_floor(&raw, c))
}

/// Mean over channels of the squared `log` metric residual of `value` against `s`.
fn log_term(s: &Sample, value: &[f64; 3], eps: &[f64; 3], channels: usize) -> f64 {
    use crate::fit::config::Metric;
    let scale = crate::fit::problem::residual_scale(Metric::Log, s);
    (0..channels)
        .map(|c| crate::fit::problem::metric_residual(Metric::Log, scale[c], eps[c], s, c, value[c]).powi(2))
        .sum::<f64>()
        / channels as f64
}

/// Log residuals ln(y + eps) - ln(m + eps) of `idx` at the full fit's values `full`.
fn targets(samples: &Samples, idx: &[usize], full: &[[f64; 3]], eps: &[f64; 3]) -> Vec<[f64; 3]> {
    idx.iter()
        .map(|&i| {
            let (s, m) = (&samples.samples[i], &full[i]);
            [0, 1, 2].map(|c| {
                (s.value[c].max(0.0) + eps[c]).ln() - (m[c].max(0.0) + eps[c]).ln()
            })
        })
        .collect()
}

/// The series of each of `degrees` fitted to the log residuals of the samples `idx` at the
/// full fit's values `full` (`eps`: their own log floors).
fn fit_on(
    samples: &Samples,
    idx: &[usize],
    full: &[[f64; 3]],
    eps: &[f64; 3],
    degrees: &[usize],
    channels: usize,
) -> Vec<Option<Correction>> {
    let refs: Vec<&Sample> = idx.iter().map(|&i| &samples.samples[i]).collect();
    let pts: Vec<_> = refs.iter().map(|s| sample_point(s)).collect();
    let w: Vec<f64> = refs.iter().map(|s| s.weight).collect();
    Correction::fit_degrees(degrees, &pts, &targets(samples, idx, full, eps), &w, channels, true)
}

/// Coefficients per channel of a correction of total degree `d` as this stage fits it: the
/// material's series and the instrument's terms.
pub fn columns(d: usize) -> usize {
    crate::model::correction::coefficient_count(d, true)
}

/// The paired standard error, in RMS units, of the difference between the held-out errors
/// whose per-sample squared terms are `a` and `b` (the same samples, in the same order).
fn paired_se(a: &[f64], b: &[f64]) -> f64 {
    let n = a.len().min(b.len());
    if n < 2 {
        return 0.0;
    }
    let d: Vec<f64> = a.iter().zip(b).map(|(x, y)| x - y).collect();
    let mean = d.iter().sum::<f64>() / n as f64;
    let var = d.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1) as f64;
    let ra = (a.iter().sum::<f64>() / n as f64).sqrt();
    let rb = (b.iter().sum::<f64>() / n as f64).sqrt();
    // rms_a - rms_b = (mean a - mean b) / (rms_a + rms_b)
    (var / n as f64).sqrt() / (ra + rb).max(f64::MIN_POSITIVE)
}

/// Choose a correction of the fit whose values on every sample are `full` and whose held-out
/// errors are `heldout` (its splits, its held-out values); `channels` fitted.
pub fn choose(samples: &Samples, heldout: &HeldOut, full: &[[f64; 3]], channels: usize) -> Decision {
    let n_train = heldout.splits.iter().map(|s| s.train.len()).min().unwrap_or(0);
    let degrees: Vec<usize> = (0..=MAX_DEGREE)
        .filter(|&d| columns(d) * SAMPLES_PER_TERM <= n_train)
        .collect();
    // Per candidate (none, then each degree), the held-out terms and values in the splits'
    // order (the measurement model's), and the terms of the material alone.
    let mut errors: Vec<Vec<f64>> = vec![Vec::new(); degrees.len() + 1];
    let mut material: Vec<Vec<f64>> = vec![Vec::new(); degrees.len() + 1];
    let mut values: Vec<Vec<[f64; 3]>> = vec![Vec::new(); degrees.len() + 1];
    let mut offset = 0;
    let mut failed = vec![false; degrees.len()];
    for split in &heldout.splits {
        let train: Vec<&Sample> = split.train.iter().map(|&i| &samples.samples[i]).collect();
        let eps = log_floors(&train);
        let fold_values = &heldout.values[offset..offset + split.test.len()];
        offset += split.test.len();
        for (&i, v) in split.test.iter().zip(fold_values) {
            let e = log_term(&samples.samples[i], v, &eps, channels);
            errors[0].push(e);
            material[0].push(e);
            values[0].push(*v);
        }
        let fitted = fit_on(samples, &split.train, full, &eps, &degrees, channels);
        for (k, corr) in fitted.into_iter().enumerate() {
            failed[k] |= corr.is_none();
            let corr = corr.unwrap_or_else(Correction::identity);
            for (&i, v) in split.test.iter().zip(fold_values) {
                let s = &samples.samples[i];
                let (ci, co, cd) = sample_point(s);
                let f = corr.factor_at(ci, co, cd);
                let inst = corr.instrument_at(ci, co);
                let mat = [0, 1, 2].map(|c| v[c] * f[c]);
                let m = [0, 1, 2].map(|c| mat[c] * inst[c]);
                errors[k + 1].push(log_term(s, &m, &eps, channels));
                material[k + 1].push(log_term(s, &mat, &eps, channels));
                values[k + 1].push(m);
            }
        }
    }
    let mut tried: Vec<Tried> = (0..=degrees.len())
        .map(|k| {
            let (error, standard_error) = rms_and_se(&errors[k]);
            let degree = k.checked_sub(1).map(|j| degrees[j]);
            let failed = k > 0 && failed[k - 1];
            Tried {
                degree,
                terms: degree.map_or(0, columns),
                error: if failed { f64::INFINITY } else { error },
                standard_error,
                paired_standard_error: 0.0,
                material_error: if failed { f64::INFINITY } else { rms_and_se(&material[k]).0 },
            }
        })
        .collect();
    let Some(best) = (0..tried.len())
        .filter(|&k| tried[k].error.is_finite())
        .min_by(|&a, &b| tried[a].error.total_cmp(&tried[b].error))
    else {
        return Decision::NotKept(tried);
    };
    for k in 0..tried.len() {
        tried[k].paired_standard_error = paired_se(&errors[k], &errors[best]);
    }
    let chosen = (0..tried.len())
        .find(|&k| tried[k].error <= tried[best].error + tried[k].paired_standard_error)
        .unwrap_or(best);
    let Some(degree) = tried[chosen].degree else {
        return Decision::NotKept(tried);
    };
    let all: Vec<usize> = (0..samples.samples.len()).collect();
    let eps = log_floors(&samples.samples.iter().collect::<Vec<_>>());
    let fitted = fit_on(samples, &all, full, &eps, &[degree], channels);
    let Some(correction) = fitted.into_iter().next().flatten() else {
        return Decision::NotKept(tried);
    };
    let (error, standard_error) = (tried[chosen].error, tried[chosen].standard_error);
    let material_error = tried[chosen].material_error;
    let (rung_error, rung_standard_error) = (tried[0].error, tried[0].standard_error);
    let corrected = HeldOut {
        splits: heldout.splits.clone(),
        errors: errors.swap_remove(chosen),
        values: values.swap_remove(chosen),
        error,
        standard_error,
        validation: heldout.validation.clone(),
    };
    Decision::Kept(
        CorrectionFit {
            correction,
            rung_error,
            rung_standard_error,
            error,
            standard_error,
            material_error,
            reciprocal_floor: None,
            tried,
            validation: heldout.validation.clone(),
        },
        corrected,
    )
}

/// The correction's lines of a report: what it is, the rung's held-out error and the
/// corrected one, the degrees tried.
pub fn text(c: &CorrectionFit) -> String {
    use std::fmt::Write;
    let mut t = String::new();
    let k = &c.correction;
    let _ = writeln!(
        t,
        "correction    a reciprocal smooth factor on the rung, exp(series of degree {} in \
         cos theta_i, cos theta_o, cos dphi; {} terms per channel): structure the rung misses, \
         not a physical parameter",
        k.degree,
        k.terms()
    );
    if !k.instrument.is_empty() {
        let _ = writeln!(
            t,
            "              with the instrument's light/view imbalance beside it ({} terms per \
             channel in cos theta_i against cos theta_o; what of the data is not reciprocal): \
             part of the model of the measurement, not of the material",
            k.instrument.len()
        );
    }
    let _ = writeln!(
        t,
        "              held-out log error {:.4} +- {:.4} with it, {:.4} +- {:.4} the rung alone ({:.2}x; {}); \
         the verdict, the floor and the residual bins are the corrected model's, the fit \
         statistics the rung's",
        c.error,
        c.standard_error,
        c.rung_error,
        c.rung_standard_error,
        c.error / c.rung_error.max(f64::MIN_POSITIVE),
        c.validation
    );
    if !k.instrument.is_empty() {
        let against = c
            .reciprocal_floor
            .map(|r| {
                format!(
                    " ({:.2}x what a material can reach, the reciprocal floor {r:.4})",
                    c.material_error / r.max(f64::MIN_POSITIVE)
                )
            })
            .unwrap_or_default();
        let _ = writeln!(
            t,
            "              the material delivered (the rung times the series, the instrument's \
             terms aside): held-out log error {:.4}{against}",
            c.material_error
        );
    }
    let tried: Vec<String> = c
        .tried
        .iter()
        .map(|x| match x.degree {
            None => format!("none {:.4}", x.error),
            Some(d) => format!("{d}: {:.4}", x.error),
        })
        .collect();
    let _ = writeln!(
        t,
        "              degrees tried (held-out error; the fewest terms within one paired standard \
         error of the best kept): {}",
        tried.join(", ")
    );
    t
}
