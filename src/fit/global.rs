//! The global stage: find every basin of the shape space that could hold the global minimum.
//!
//! Once the albedos are solved exactly (separable least squares), a cross-section rung has two to
//! five shape parameters, so the shape space can be covered:
//! 1. a seeded Latin-hypercube design of `global_candidates` points over the optimizer's box
//!    (the azimuth over one period), plus the user's start and any hints, each costed on a seeded
//!    subsample of `global_subsample` samples;
//! 2. the `starts` best candidates that lie apart from each other (distance >= 0.1 of the box,
//!    periodic in the azimuth) are polished by a few Levenberg–Marquardt iterations;
//! 3. the geometry scan: a second design over the fibre geometry alone (spacing, height, map
//!    scale; a third of it on the touching-fibre face d = min) with the other coordinates at the
//!    best basin so far, its best distinct points polished likewise;
//! 4. all polished points are clustered into basins (distance < 0.02 of the box); the basins
//!    whose cost is competitive with the best (at most [`MAX_BASINS`]) are polished further on the
//!    subsample.
//!
//! What comes out is the list of distinct competitive basins, best first; the final stage
//! polishes each on all samples.

pub use super::basins::{Basin, Keyed, Metric, BASIN_SEPARATION};
use super::config::Optimizer;
use super::parameters::ParamSet;
use super::polish::run_lm;
use super::problem::FitProblem;
use anyhow::Result;
use indicatif::ProgressBar;
use nalgebra::DVector;
use rand::seq::SliceRandom;
use rand::Rng;
use rayon::prelude::*;

/// Iterations of the first, short polish of every start.
const FIRST_POLISH_ITERATIONS: u64 = 6;
/// Iterations of the polish of the competitive basins on the subsample.
const BASIN_POLISH_ITERATIONS: u64 = 30;
/// Candidates closer than this (fraction of the box, RMS over the coordinates) are one start.
const START_SEPARATION: f64 = 0.1;
/// A seeded Latin-hypercube design of `count` points in the box [lo, hi].
pub fn latin_hypercube(
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

/// What the global stage works on: the subsample problem, its parameter template, and the
/// bar its LM iterations advance.
#[derive(Clone, Copy)]
pub struct Stage<'p, 'a> {
    pub sub: &'p FitProblem<'a>,
    pub template: &'p ParamSet,
    pub bar: &'p ProgressBar,
}

/// Run the global stage on the subsample problem `stage.sub`. `starts` are points that are
/// always polished (the user's start, hints); the design adds the rest.
pub fn search(
    stage: Stage,
    starts: Vec<DVector<f64>>,
    opt: &Optimizer,
    polish_count: usize,
    rng: &mut impl Rng,
) -> Result<Vec<Basin>> {
    let Stage { sub, template, bar } = stage;
    let (lo, hi) = sub.design_box();
    let metric = Metric::of(sub, template);
    let count = opt
        .global_candidates
        .unwrap_or_else(|| crate::fit::config::default_candidates(lo.len()));
    let tol = opt.tolerance.max(1e-6);
    let forced = starts.len();
    let mut candidates = starts;
    candidates.extend(latin_hypercube(&lo, &hi, count, rng));
    let mut found = screen_and_polish(stage, candidates, forced, polish_count, tol)?;
    // Round 2, the geometry scan: the fibre geometry (spacing, height, map scale) is where the
    // distinct minima are (a flat layer at d = 2 looks like raised fibres touching at any d);
    // the azimuth and the lobe are well determined once the geometry is roughly right. So the
    // geometric coordinates are designed again with the others at the best basin.
    let geometric = sub.geometric();
    if geometric.iter().any(|&g| g) && geometric.iter().any(|&g| !g) {
        let best = cluster(found.clone(), &metric)[0].theta.clone();
        let n_geo = geometric.iter().filter(|&&g| g).count();
        // a third of them on the face of touching fibres (the smallest spacing): the common
        // case, and a face a box-filling design reaches only by chance
        let spacing = sub.spacing_entry();
        let second: Vec<DVector<f64>> = latin_hypercube(&lo, &hi, 16 + 24 * n_geo, rng)
            .into_iter()
            .enumerate()
            .map(|(j, mut c)| {
                for k in 0..c.len() {
                    if !geometric[k] {
                        c[k] = best[k];
                    }
                }
                if let Some(k) = spacing.filter(|_| j % 3 == 0) {
                    c[k] = hi[k]; // 1/d at its top: d at its minimum
                }
                c
            })
            .collect();
        found.extend(screen_and_polish(
            stage,
            second,
            0,
            polish_count.div_ceil(2),
            tol,
        )?);
    }
    let basins = competitive(cluster(found, &metric), sub);
    bar.inc_length(basins.len() as u64 * BASIN_POLISH_ITERATIONS);
    let polished: Vec<Basin> = basins
        .into_iter()
        .map(|b| {
            let (theta, cost, _) =
                run_lm(sub, template, b.theta, BASIN_POLISH_ITERATIONS, tol, bar)?;
            Ok(Basin { theta, cost })
        })
        .collect::<Result<_>>()?;
    Ok(competitive(cluster(polished, &metric), sub))
}

/// Cost every candidate, pick the first `forced` and the best others that lie apart (up to
/// `polish_count` in all), and give each a short polish.
fn screen_and_polish(
    stage: Stage,
    candidates: Vec<DVector<f64>>,
    forced: usize,
    polish_count: usize,
    tol: f64,
) -> Result<Vec<Basin>> {
    let Stage { sub, template, bar } = stage;
    let metric = Metric::of(sub, template);
    // the costs only rank the design's points that fill the polish budget after the forced
    // starts: where the forced starts fill it (`--model auto`'s later candidates, started from
    // every simpler candidate's optimum) no point is polished, so none is costed
    let design = match polish_count > forced {
        true => forced..candidates.len(),
        false => forced..forced,
    };
    // the design's costs: candidate k's at k - forced
    let costs: Vec<f64> = candidates[design.clone()]
        .par_iter()
        .map(|c| {
            sub.evaluate(c, template)
                .map(|(r, _)| r.norm_squared())
                .unwrap_or(f64::INFINITY)
        })
        .collect();
    let cost = |k: usize| costs[k - forced];
    let mut order: Vec<usize> = design.collect();
    order.sort_by(|&a, &b| cost(a).total_cmp(&cost(b)));
    let mut chosen: Vec<usize> = (0..forced).collect();
    let keyed: Vec<Keyed> = candidates.iter().map(|c| metric.keyed(c.clone())).collect();
    for &k in &order {
        if chosen.len() >= polish_count.max(forced) {
            break;
        }
        if cost(k).is_finite()
            && chosen
                .iter()
                .all(|&c| metric.distance(&keyed[k], &keyed[c]) > START_SEPARATION)
        {
            chosen.push(k);
        }
    }
    bar.inc_length(chosen.len() as u64 * FIRST_POLISH_ITERATIONS);
    chosen
        .iter()
        .map(|&k| {
            let (theta, cost, _) = run_lm(
                sub,
                template,
                candidates[k].clone(),
                FIRST_POLISH_ITERATIONS,
                tol,
                bar,
            )?;
            Ok(Basin { theta, cost })
        })
        .collect()
}

/// Merge points closer than [`BASIN_SEPARATION`] (by `metric`: points a symmetry of the rung
/// maps onto each other are one), keeping the cheaper; best first.
pub fn cluster(mut points: Vec<Basin>, metric: &Metric) -> Vec<Basin> {
    points.sort_by(|a, b| a.cost.total_cmp(&b.cost));
    let mut out: Vec<(Keyed, Basin)> = Vec::new();
    for p in points {
        let k = metric.keyed(p.theta.clone());
        if out
            .iter()
            .all(|(q, _)| metric.distance(&k, q) > BASIN_SEPARATION)
        {
            out.push((k, p));
        }
    }
    out.into_iter().map(|(_, b)| b).collect()
}

/// The basins (best first) whose cost could still beat the best's once polished: within
/// max(50 %, 25 residual variances) of the best cost, at most [`MAX_BASINS`].
pub fn competitive(basins: Vec<Basin>, problem: &FitProblem) -> Vec<Basin> {
    let Some(best) = basins.first().map(|b| b.cost) else {
        return basins;
    };
    let n = problem.residual_count();
    let s2 = best / (n.saturating_sub(problem.dim()).max(1)) as f64;
    let limit = best + (0.5 * best).max(25.0 * s2);
    basins
        .into_iter()
        .filter(|b| b.cost <= limit)
        .take(MAX_BASINS)
        .collect()
}

/// At most this many basins go on to the next stage.
pub const MAX_BASINS: usize = 4;
