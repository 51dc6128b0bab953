//! Fitting: bounded least squares on argmin, with uncertainties.
//!
//! Pipeline: parameters from the config -> a seeded global stage (a Latin-hypercube grid of
//! `global_candidates` shape vectors, cost on a `global_subsample` of the samples) -> the best
//! `starts` candidates polished on the subsample -> the best polished on all samples -> standard
//! errors, correlations and statistics at the solution. The fibre models are linear in their
//! albedos, which are solved exactly inside every step (see [`problem`]).

pub mod config;
pub mod lm;
pub mod parameters;
pub mod problem;
pub mod selection;
pub mod uncertainty;

use crate::load::samples::Samples;
use crate::model::topology::TopologyMap;
use anyhow::{anyhow, Context, Result};
use argmin::core::observers::{Observe, ObserverMode};
use argmin::core::{Error as ArgminError, Executor, State, KV};
use config::FitConfig;
use indicatif::ProgressBar;
use nalgebra::DVector;
use parameters::ParamSet;
use problem::{ArgminProblem, FitProblem};
use rand::seq::SliceRandom;
use rand::{Rng, SeedableRng};
use rayon::prelude::*;
use std::sync::Arc;
use std::time::Instant;

/// One parameter after the fit, in external units.
#[derive(Clone, Debug, serde::Serialize)]
pub struct ParamRecord {
    pub name: String,
    /// One value (shapes, grey albedos) or three (RGB albedos).
    pub value: Vec<f64>,
    pub std_error: Vec<Option<f64>>,
    pub init: Vec<f64>,
    pub min: f64,
    pub max: f64,
    pub fixed: bool,
    pub at_bound: Vec<bool>,
}

/// Everything a fit produced.
#[derive(Clone, Debug)]
pub struct FitOutcome {
    pub set: ParamSet,
    pub records: Vec<ParamRecord>,
    pub correlations: Vec<(String, String, f64)>,
    pub statistics: uncertainty::Statistics,
    pub warnings: Vec<String>,
    /// LM iterations of the final (all-sample) run.
    pub iterations: u64,
    /// Model evaluations over the samples, all stages.
    pub evaluations: usize,
    /// (start theta in external units, cost after polishing on the subsample).
    pub starts: Vec<(Vec<f64>, f64)>,
    pub elapsed_seconds: f64,
    /// Model value per sample and channel at the solution.
    pub fitted: Vec<[f64; 3]>,
    pub map: Option<Arc<TopologyMap>>,
}

struct ProgressObserver(ProgressBar);

impl Observe<lm::LmState> for ProgressObserver {
    fn observe_iter(&mut self, state: &lm::LmState, _kv: &KV) -> Result<(), ArgminError> {
        self.0.inc(1);
        self.0.set_message(format!("cost {:.5e}", state.get_cost()));
        Ok(())
    }
}

fn run_lm(
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

/// A seeded Latin-hypercube grid of `count` points in the box [lo, hi].
fn latin_hypercube(
    lo: &DVector<f64>,
    hi: &DVector<f64>,
    count: usize,
    rng: &mut impl Rng,
) -> Vec<DVector<f64>> {
    let d = lo.len();
    let perms: Vec<Vec<usize>> = (0..d)
        .map(|_| {
            let mut p: Vec<usize> = (0..count).collect();
            p.shuffle(rng);
            p
        })
        .collect();
    (0..count)
        .map(|k| {
            DVector::from_iterator(
                d,
                (0..d).map(|i| {
                    let u = (perms[i][k] as f64 + rng.random::<f64>()) / count as f64;
                    lo[i] + u * (hi[i] - lo[i])
                }),
            )
        })
        .collect()
}

/// Fit `samples` as `cfg` says.
pub fn fit(samples: &Samples, cfg: &FitConfig, quiet: bool) -> Result<FitOutcome> {
    let t0 = Instant::now();
    let mut template = ParamSet::from_config(cfg, samples.channels)?;
    let mut notes = Vec::new();
    if samples.samples.iter().all(|s| s.fibre_azimuth.is_some()) {
        if let Some(s) = template
            .shapes
            .iter_mut()
            .find(|s| s.kind == parameters::Shape::Azimuth && s.vary)
        {
            s.vary = false;
            // report the data's direction: axial mean (angles doubled, period 180 degrees)
            let (sn, cs) = samples
                .samples
                .iter()
                .filter_map(|x| x.fibre_azimuth)
                .fold((0.0, 0.0), |(a, b), psi| {
                    (a + (2.0 * psi).sin(), b + (2.0 * psi).cos())
                });
            let mean = 0.5 * sn.atan2(cs).to_degrees();
            let uniform = samples
                .samples
                .iter()
                .all(|x| x.fibre_azimuth == samples.samples[0].fibre_azimuth);
            s.value = mean.clamp(s.min, s.max);
            s.init = s.value;
            notes.push(if uniform {
                format!("`fibre_azimuth_deg` held at {mean:.4}: the data give the fibre direction")
            } else {
                format!("`fibre_azimuth_deg` held fixed: the data give the fibre direction per pixel (tangent map); {mean:.4} is their axial mean")
            });
        }
    }
    let map = match &cfg.knobs.topology_map {
        Some(p) => Some(Arc::new(
            TopologyMap::load(p).context("knobs.topology_map")?,
        )),
        None => None,
    };
    let opt = &cfg.optimizer;
    let all: Vec<_> = samples.samples.iter().collect();
    let make = |subset: Vec<_>| {
        FitProblem::new(
            subset,
            template.clone(),
            cfg.metric,
            cfg.knobs.quadrature_order,
            cfg.knobs.histogram_bins,
            map.clone(),
            opt.separable,
        )
    };
    let full = make(all.clone());
    let mut rng = rand::rngs::StdRng::seed_from_u64(cfg.seed);
    let bar = crate::progress::bar(0, "fit", quiet);
    let mut evaluations = 0;
    let mut starts = Vec::new();
    let mut iterations = 0;
    let theta = if full.dim() == 0 {
        DVector::zeros(0)
    } else {
        // global stage on a seeded subsample
        let mut idx: Vec<usize> = (0..all.len()).collect();
        idx.shuffle(&mut rng);
        idx.truncate(opt.global_subsample.max(full.dim() * 4).min(all.len()));
        let sub = make(idx.iter().map(|&i| all[i]).collect());
        let (lo, hi) = sub.bounds();
        let mut candidates = vec![sub.theta_of(&template)];
        candidates.extend(latin_hypercube(&lo, &hi, opt.global_candidates, &mut rng));
        let costs: Vec<f64> = candidates
            .par_iter()
            .map(|c| {
                sub.evaluate(c, &template)
                    .map(|(r, _)| r.norm_squared())
                    .unwrap_or(f64::INFINITY)
            })
            .collect();
        let mut order: Vec<usize> = (0..candidates.len()).collect();
        order.sort_by(|&a, &b| costs[a].total_cmp(&costs[b]));
        // the user's start always runs; then the best distinct candidates
        let mut chosen: Vec<usize> = vec![0];
        let span: Vec<f64> = (0..lo.len()).map(|i| (hi[i] - lo[i]).max(1e-12)).collect();
        for &k in &order {
            if chosen.len() >= cfg.starts {
                break;
            }
            let far = chosen.iter().all(|&c| {
                (0..lo.len())
                    .map(|i| ((candidates[k][i] - candidates[c][i]) / span[i]).powi(2))
                    .sum::<f64>()
                    .sqrt()
                    > 0.05
            });
            if far {
                chosen.push(k);
            }
        }
        let polish_iters = 25;
        bar.set_length(chosen.len() as u64 * polish_iters + opt.max_iterations);
        let mut polished = Vec::new();
        for &k in &chosen {
            let (th, cost, _) = run_lm(
                &sub,
                &template,
                candidates[k].clone(),
                polish_iters,
                opt.tolerance.max(1e-6),
                &bar,
            )?;
            let ext: Vec<f64> = sub
                .set_at(&th, &template)
                .shapes
                .iter()
                .filter(|s| s.vary)
                .map(|s| s.value)
                .collect();
            starts.push((ext, cost));
            polished.push((th, cost));
        }
        evaluations += sub.evaluations.load(std::sync::atomic::Ordering::Relaxed);
        let best = polished
            .into_iter()
            .min_by(|a, b| a.1.total_cmp(&b.1))
            .map(|p| p.0)
            .expect("at least one start");
        let (th, _, iters) = run_lm(
            &full,
            &template,
            best,
            opt.max_iterations,
            opt.tolerance,
            &bar,
        )?;
        iterations = iters;
        th
    };
    bar.finish_and_clear();
    let mut set = full.set_at(&theta, &template);
    let cols = full.columns(&set)?;
    if full.separable {
        full.solve_albedos(&cols, &mut set);
    }
    let r = full.residuals(&cols, &set);
    let chi2 = r.norm_squared();
    let fitted = full.model_values(&cols, &set);
    let ch = samples.channels;
    let mut model_flat = Vec::with_capacity(fitted.len() * ch);
    let mut data_flat = Vec::with_capacity(fitted.len() * ch);
    for (m, s) in fitted.iter().zip(&samples.samples) {
        model_flat.extend_from_slice(&m[..ch]);
        data_flat.extend_from_slice(&s.value[..ch]);
    }
    let n = r.len();
    let p = full.free_shapes().len() + full.free_albedos().len();
    let sigmas = samples.samples.iter().all(|s| s.sigma.is_some());
    let statistics = uncertainty::statistics(chi2, n, p, sigmas, &model_flat, &data_flat);

    // standard errors over the full parameter vector
    let names = full.full_names();
    let near = |v: f64, b: f64, lo: f64, hi: f64| (v - b).abs() <= 1e-9 * (hi - lo).abs().max(1.0);
    let mut at_bound = Vec::new();
    for &i in full.free_shapes() {
        let s = &set.shapes[i];
        at_bound.push(near(s.value, s.min, s.min, s.max) || near(s.value, s.max, s.min, s.max));
    }
    for &(i, c) in full.free_albedos() {
        let a = &set.albedos[i];
        at_bound
            .push(near(a.value[c], a.min, a.min, a.max) || near(a.value[c], a.max, a.min, a.max));
    }
    let jac = full.full_jacobian(&set, &cols)?;
    evaluations += full.evaluations.load(std::sync::atomic::Ordering::Relaxed);
    let cov = uncertainty::covariance(&jac, &names, &at_bound, chi2, n);
    let mut warnings = notes;
    warnings.extend(cov.warnings.iter().cloned());

    // per-parameter records in external units
    let mut records = Vec::new();
    let mut col = 0;
    for s in set.shapes.iter() {
        let (se, ab) = if s.vary {
            let se = cov.std_error[col].map(|e| if s.kind.log_space() { e * s.value } else { e });
            let ab = at_bound[col];
            col += 1;
            (se, ab)
        } else {
            (None, false)
        };
        let value = if s.kind == parameters::Shape::Azimuth {
            wrap_azimuth(s.value)
        } else {
            s.value
        };
        records.push(ParamRecord {
            name: s.kind.name().to_string(),
            value: vec![value],
            std_error: vec![se],
            init: vec![s.init],
            min: s.min,
            max: s.max,
            fixed: !s.vary,
            at_bound: vec![ab],
        });
    }
    for (i, a) in set.albedos.iter().enumerate() {
        let mut se = vec![None; ch];
        let mut ab = vec![false; ch];
        if a.vary {
            for c in 0..ch {
                let k = full
                    .free_albedos()
                    .iter()
                    .position(|&(ii, cc)| ii == i && cc == c)
                    .expect("free albedo");
                let colk = full.free_shapes().len() + k;
                se[c] = cov.std_error[colk];
                ab[c] = at_bound[colk];
            }
        }
        records.push(ParamRecord {
            name: a.name.to_string(),
            value: a.value[..ch].to_vec(),
            std_error: se,
            init: a.init[..ch].to_vec(),
            min: a.min,
            max: a.max,
            fixed: !a.vary,
            at_bound: ab,
        });
    }
    for r in &records {
        if r.at_bound.iter().any(|&b| b) {
            warnings.push(format!(
                "`{}` ended at a bound of [{}, {}]: no standard error",
                r.name, r.min, r.max
            ));
        }
    }
    let correlations = cov
        .correlations
        .iter()
        .map(|&(a, b, r)| (names[a].clone(), names[b].clone(), r))
        .collect();
    Ok(FitOutcome {
        set,
        records,
        correlations,
        statistics,
        warnings,
        iterations,
        evaluations,
        starts,
        elapsed_seconds: t0.elapsed().as_secs_f64(),
        fitted,
        map,
    })
}

/// Azimuths are defined modulo 180 degrees: report them in [-90, 90).
pub fn wrap_azimuth(deg: f64) -> f64 {
    (deg + 90.0).rem_euclid(180.0) - 90.0
}
