//! A fibre-direction spread the data cannot tell from 0 is held at 0.
//!
//! Spread 0 is the aligned rung itself, bit for bit (`model::azimuth_spread`); any spread above
//! it averages the rung over N turned fibre directions (16 by default), so every evaluation
//! after the fit (renders, samplers, Mitsuba, shaders) costs N times the aligned rung's. A fit
//! that frees the spread (a named rung without a config, `--model auto`) can end a hair above 0
//! on data of aligned fibres (the shipped silk: 0.12 +/- 0.15 deg), and that hair made its
//! sampler 16x slower for nothing the data can see.
//!
//! The test, after the fit's standard errors: when the fitted spread s is within
//! [`TRY_WITHIN_SE`] standard errors of 0 (or has none: at its bound 0, where the data do not
//! "ask for less", as a bound elsewhere means, but are content with aligned fibres), the fit is polished again from each of
//! its minima with the spread held at 0, and the held fit replaces it unless the data reject it,
//! by the F test of one held parameter:
//!
//! ```text
//! F = (chi2_held - chi2_free) / (chi2_free / (n - p_free)) < F_LIMIT (3.84: 5 % of chi2 with 1 dof)
//! ```
//!
//! (with sigmas and a model that fits within the noise, chi2_free / (n - p) ~ 1 and this is the
//! likelihood-ratio test; without, the residual variance stands for the noise). The spread's
//! record then says it is held, why, and the figures.

use super::{finish, parameters, polish, problem, FitOutcome};
use crate::fit::basins::Basin;
use crate::fit::config::FitConfig;
use crate::load::samples::Samples;
use anyhow::Result;
use nalgebra::DVector;
use parameters::{Param, ParamSet};
use problem::FitProblem;

/// A spread within this many of its standard errors of 0 is tried at 0. Generous: the law is
/// symmetric, so the rung changes with s^2 near 0 and the linearised standard error there
/// understates how little the data see (the shipped silk's twin capture: 0.25 +/- 0.13 deg, 2
/// standard errors, yet F = 0.88); the F test decides, this only spares the polish where a
/// spread is plainly there (the felt's 70-180 deg).
pub const TRY_WITHIN_SE: f64 = 4.0;
/// The held fit is kept while F stays below this: the 95th percentile of chi-square with one
/// degree of freedom.
pub const F_LIMIT: f64 = 3.841_458_820_694_124;

/// What [`try_hold`] needs of the free fit.
pub struct Free<'a> {
    /// The free fit's problem on all samples, its template and its minima (theta, cost).
    pub full: &'a FitProblem<'a>,
    pub template: &'a ParamSet,
    pub minima: &'a [(DVector<f64>, f64)],
    /// Its outcome (standard errors, statistics).
    pub outcome: &'a FitOutcome,
}

/// The fit with the spread held at 0 when the data cannot tell it from 0 (module docs); `None`
/// when the spread is not free, is clearly above 0, the data reject 0, or the config keeps it
/// free (`keep_free_spread`: `--model auto`'s candidates, ranked as fitted).
/// `problem_of(template)`: the free fit's problem on all samples with another template.
pub fn try_hold<'a>(
    free: Free<'a>,
    problem_of: &dyn Fn(ParamSet) -> FitProblem<'a>,
    samples: &Samples,
    cfg: &FitConfig,
    notes: Vec<String>,
    bar: &indicatif::ProgressBar,
) -> Result<Option<(FitOutcome, String)>> {
    if cfg.keep_free_spread {
        return Ok(None);
    }
    let name = Param::AzimuthSpread.name();
    let Some(k) = free
        .template
        .shapes
        .iter()
        .position(|s| s.kind == Param::AzimuthSpread && s.vary)
    else {
        return Ok(None);
    };
    let Some(record) = free.outcome.records.iter().find(|r| r.name == name) else {
        return Ok(None);
    };
    let (s, se) = (record.value[0], record.std_error[0]);
    if se.is_some_and(|se| s >= TRY_WITHIN_SE * se) {
        return Ok(None);
    }
    let mut template = free.template.clone();
    template.shapes[k].vary = false;
    template.shapes[k].value = 0.0;
    let held = problem_of(template.clone());
    let basins: Vec<Basin> = free
        .minima
        .iter()
        .map(|(theta, cost)| {
            let mut set = free.full.set_at(theta, free.template);
            set.shapes[k].value = 0.0;
            set.shapes[k].vary = false;
            Basin {
                theta: held.theta_of(&set),
                cost: *cost,
            }
        })
        .collect();
    let opt = &cfg.optimizer;
    let minima = if held.dim() == 0 {
        vec![(template.clone(), f64::NAN)]
    } else {
        polish::final_stage(
            &held,
            &template,
            &basins,
            opt.max_iterations,
            opt.tolerance,
            bar,
        )?
        .into_iter()
        .map(|m| (held.set_at(&m.theta, &template), m.cost))
        .collect()
    };
    let outcome = finish::finish(&held, samples, free.outcome.channels, &minima, notes)?;
    let st = &free.outcome.statistics;
    let dof = st.n.saturating_sub(st.free_parameters).max(1) as f64;
    let f = (outcome.statistics.chi_square - st.chi_square) / (st.chi_square / dof);
    if !(f < F_LIMIT) {
        return Ok(None);
    }
    let fitted = match se {
        Some(se) => format!("fitted {s:.3} +/- {se:.3} deg"),
        None if s <= 0.0 => "the fit ended at 0".to_string(),
        None => format!("fitted {s:.3} deg, no standard error"),
    };
    let why = format!(
        "held at 0: the data cannot tell it from 0 ({fitted}; with it held F = {:.2}, below \
         {F_LIMIT:.2}, the 5 % level); spread 0 is the aligned rung, {}x cheaper to evaluate",
        f.max(0.0),
        cfg.knobs.azimuth_nodes
    );
    Ok(Some((outcome, why)))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_limit_is_chi_squares_95th_percentile_with_one_degree_of_freedom() {
        // P(chi2_1 < x) = erf(sqrt(x / 2)), erf by Simpson's rule
        let (z, n) = ((F_LIMIT / 2.0).sqrt(), 10_000);
        let h = z / n as f64;
        let g = |t: f64| (-t * t).exp();
        let sum: f64 = (0..=n)
            .map(|i| {
                let w = if i == 0 || i == n { 1.0 } else if i % 2 == 1 { 4.0 } else { 2.0 };
                w * g(i as f64 * h)
            })
            .sum();
        let p = 2.0 / std::f64::consts::PI.sqrt() * sum * h / 3.0;
        assert!((p - 0.95).abs() < 1e-12, "{p}");
    }
}
