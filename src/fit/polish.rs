//! Local polishing: bounded Levenberg–Marquardt runs from a start, and the final stage that
//! polishes every competitive basin of the global stage on all samples.

use super::basins::{Basin, Keyed, Metric, BASIN_SEPARATION};
use super::lm;
use super::parameters::ParamSet;
use super::problem::{ArgminProblem, FitProblem};
use anyhow::{anyhow, Result};
use argmin::core::observers::{Observe, ObserverMode};
use argmin::core::{Error as ArgminError, Executor, State, KV};
use indicatif::ProgressBar;
use nalgebra::DVector;

struct ProgressObserver(ProgressBar);

impl Observe<lm::LmState> for ProgressObserver {
    fn observe_iter(&mut self, state: &lm::LmState, _kv: &KV) -> Result<(), ArgminError> {
        self.0.inc(1);
        self.0.set_message(format!("cost {:.5e}", state.get_cost()));
        Ok(())
    }
}

/// One LM run from `theta0`: (best theta, its cost, iterations).
pub fn run_lm(
    problem: &FitProblem,
    base: &ParamSet,
    theta0: DVector<f64>,
    max_iters: u64,
    tolerance: f64,
    bar: &ProgressBar,
) -> Result<(DVector<f64>, f64, u64)> {
    let (lo, hi) = problem.bounds();
    let solver = lm::BoundedLm::new(lo, hi, tolerance);
    let op = ArgminProblem::new(problem, base.clone());
    let res = Executor::new(op, solver)
        .configure(|c| c.param(theta0).max_iters(max_iters))
        .add_observer(ProgressObserver(bar.clone()), ObserverMode::Always)
        .run()
        .map_err(|e| anyhow!("fit failed: {e:#}"))?;
    let state = res.state();
    let best = state
        .get_best_param()
        .cloned()
        .ok_or_else(|| anyhow!("fit failed: no solution"))?;
    Ok((best, state.get_best_cost(), state.get_iter()))
}

/// A minimum on all samples.
#[derive(Clone, Debug)]
pub struct Minimum {
    pub theta: DVector<f64>,
    pub cost: f64,
    pub iterations: u64,
}

/// Polish every basin on all samples; the distinct minima, best first (basins that converge to
/// the same point are merged).
pub fn final_stage(
    full: &FitProblem,
    template: &ParamSet,
    basins: &[Basin],
    max_iterations: u64,
    tolerance: f64,
    bar: &ProgressBar,
) -> Result<Vec<Minimum>> {
    bar.inc_length(basins.len() as u64 * max_iterations);
    let mut minima: Vec<Minimum> = basins
        .iter()
        .map(|b| {
            let (theta, cost, iterations) = run_lm(
                full,
                template,
                b.theta.clone(),
                max_iterations,
                tolerance,
                bar,
            )?;
            Ok(Minimum {
                theta,
                cost,
                iterations,
            })
        })
        .collect::<Result<_>>()?;
    minima.sort_by(|a, b| a.cost.total_cmp(&b.cost));
    // one basin per symmetry class too: the cheaper of two that are one after canonicalisation
    let metric = Metric::of(full, template);
    let mut distinct: Vec<(Keyed, Minimum)> = Vec::new();
    for m in minima {
        let k = metric.keyed(m.theta.clone());
        if distinct
            .iter()
            .all(|(d, _)| metric.distance(&k, d) > BASIN_SEPARATION)
        {
            distinct.push((k, m));
        }
    }
    let distinct: Vec<Minimum> = distinct.into_iter().map(|(_, m)| m).collect();
    Ok(distinct)
}
