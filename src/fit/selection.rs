//! `--model auto`: fit the rungs cheapest first on a training split, measure each on the
//! held-out split, and choose the cheapest whose held-out error is within a tolerance of the
//! best: with sigmas, within the data's relative noise level (RMS sigma / RMS data) of the best
//! relative RMSE; without sigmas, within 5 % of the best RMSE; `selection.tolerance` overrides
//! (relative to the best RMSE).

use super::config::FitConfig;
use super::parameters::Shape;
use super::problem::FitProblem;
use super::{fit_with_hints, FitOutcome};
use crate::load::samples::Samples;
use crate::model::ModelId;
use anyhow::{bail, Result};
use rand::seq::SliceRandom;
use rand::SeedableRng;
use std::time::Instant;

#[derive(Clone, Debug, serde::Serialize)]
pub struct Candidate {
    pub rung: String,
    pub free_parameters: usize,
    /// Unweighted RMSE of model - data on the held-out samples, 1/sr.
    pub heldout_rmse: f64,
    pub heldout_relative_rmse: f64,
    /// RMS of ln(m + eps) - ln(y + eps) on the held-out samples (eps: the `log` metric's floor).
    pub heldout_log_error: f64,
    /// Cost of one model evaluation (one sample, all heights), single thread, ns.
    pub ns_per_eval: f64,
    pub fit_seconds: f64,
    pub chosen: bool,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub error: Option<String>,
}

#[derive(Clone, Debug, serde::Serialize)]
pub struct SelectionOutcome {
    pub candidates: Vec<Candidate>,
    pub chosen: String,
    pub rule: String,
    pub train_samples: usize,
    pub heldout_samples: usize,
    /// Shape values of every rung's training fit: extra starts for the final fit.
    #[serde(skip)]
    pub hints: Vec<Vec<(Shape, f64)>>,
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

/// Held-out RMSE, relative RMSE and log error of a fitted outcome, and the single-thread cost
/// per sample.
pub fn heldout(o: &FitOutcome, cfg: &FitConfig, test: &Samples) -> Result<(f64, f64, f64, f64)> {
    let (p, values) = model_values_on(o, cfg, test)?;
    let ch = o.channels;
    let raw: Vec<[f64; 3]> = test.samples.iter().map(|s| s.value).collect();
    let floors: Vec<f64> = (0..ch)
        .map(|c| super::problem::log_floor(&raw, c))
        .collect();
    let (mut se, mut sy, mut sl, mut n) = (0.0, 0.0, 0.0, 0.0);
    for (m, s) in values.iter().zip(&test.samples) {
        for (c, (mc, yc)) in m[..ch].iter().zip(&s.value[..ch]).enumerate() {
            se += (mc - yc).powi(2);
            sy += yc.powi(2);
            sl += ((mc.max(0.0) + floors[c]).ln() - (yc.max(0.0) + floors[c]).ln()).powi(2);
            n += 1.0;
        }
    }
    // single-thread cost of the model on up to 500 held-out samples, as one batch
    let model = p.model_for(&o.set);
    let frame = crate::model::frame::FibreFrame::from_azimuth(0.0);
    let k = test.samples.len().min(500);
    let pairs: Vec<crate::model::DirectionPair> = test.samples[..k]
        .iter()
        .map(|s| crate::model::DirectionPair::new(&frame, &s.l, &s.v))
        .collect();
    let mut bases = vec![crate::model::Basis::default(); k];
    let t = Instant::now();
    model.basis_many(&pairs, &mut bases);
    std::hint::black_box(&bases);
    let ns = t.elapsed().as_nanos() as f64 / k.max(1) as f64;
    Ok(((se / n).sqrt(), (se / sy).sqrt(), (sl / n).sqrt(), ns))
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

pub fn select(samples: &Samples, cfg: &FitConfig) -> Result<SelectionOutcome> {
    select_with(samples, cfg, true, &mut |_| {})
}

/// A rung of `--model auto` just finished (fitted or failed).
pub struct RungDone<'a> {
    /// Every rung finished so far, this one last.
    pub candidates: &'a [Candidate],
    /// This rung's training fit (`None` when it failed).
    pub outcome: Option<&'a FitOutcome>,
    /// The rungs to try, in order.
    pub rungs: &'a [String],
    pub train_samples: usize,
    pub heldout_samples: usize,
}

/// [`select`], with a progress line per rung on stderr (unless `quiet`: name, elapsed time, an
/// estimate of the time left) and `on_rung` called as each rung finishes (partial results).
pub fn select_with(
    samples: &Samples,
    cfg: &FitConfig,
    quiet: bool,
    on_rung: &mut dyn FnMut(&RungDone),
) -> Result<SelectionOutcome> {
    let n = samples.samples.len();
    if n < 10 {
        bail!("--model auto needs at least 10 samples to hold some out; got {n}");
    }
    let mut idx: Vec<usize> = (0..n).collect();
    idx.shuffle(&mut rand::rngs::StdRng::seed_from_u64(cfg.seed ^ 0x5e1ec7));
    let n_test = ((n as f64 * cfg.selection.holdout).ceil() as usize).clamp(1, n - 1);
    let (test_idx, train_idx) = idx.split_at(n_test);
    let train = subset(samples, train_idx);
    let test = subset(samples, test_idx);
    let sigmas = test.samples.iter().all(|s| s.sigma.is_some());
    let ch = samples.channels;
    let noise_rel = if sigmas {
        let (s2, y2): (f64, f64) = test.samples.iter().fold((0.0, 0.0), |(a, b), s| {
            let sg = s.sigma.expect("checked");
            (
                a + (0..ch).map(|c| sg[c] * sg[c]).sum::<f64>(),
                b + (0..ch).map(|c| s.value[c].powi(2)).sum::<f64>(),
            )
        });
        (s2 / y2).sqrt()
    } else {
        0.0
    };
    let mut candidates = Vec::new();
    let mut hints: Vec<Vec<(Shape, f64)>> = Vec::new();
    let mut fits: Vec<Option<(f64, f64, f64)>> = Vec::new();
    let started = Instant::now();
    let rungs = &cfg.selection.rungs;
    // the time left, estimated from the seconds per unit of planned work of the rungs done; a
    // rung's work: its planned evaluations times the cost of one (timed at its start values)
    let planned: Vec<f64> = match crate::progress::shown(quiet) {
        false => vec![0.0; rungs.len()],
        true => rungs
            .iter()
            .map(|r| match r.parse::<ModelId>() {
                Ok(id) => {
                    let rc = cfg.for_rung(id);
                    rc.planned_evaluations(train.samples.len()) * probe_ns(&train, &rc)
                }
                Err(_) => 0.0,
            })
            .collect(),
    };
    for (k, name) in rungs.iter().enumerate() {
        let id: ModelId = name.parse().map_err(|e: String| anyhow::anyhow!(e))?;
        let rc = cfg.for_rung(id);
        let elapsed = started.elapsed().as_secs_f64();
        let estimate = match planned[..k].iter().sum::<f64>() {
            done if k > 0 && done > 0.0 => format!(
                "; estimate: {} left",
                crate::progress::seconds(elapsed / done * planned[k..].iter().sum::<f64>())
            ),
            _ => String::new(),
        };
        crate::progress::line(
            quiet,
            &format!(
                "auto: rung {}/{} {name} (elapsed {}{estimate})",
                k + 1,
                rungs.len(),
                crate::progress::seconds(elapsed)
            ),
        );
        let t = Instant::now();
        let mut fitted = None;
        // every simpler rung's optimum is a start: a rung nested in a richer one (poulin-fournier
        // is varying-topology at height 0) then never ends worse than it on the training data
        let result = fit_with_hints(&train, &rc, true, &hints).and_then(|o| {
            let (rmse, rel, log, ns) = heldout(&o, &rc, &test)?;
            hints.push(o.set.shapes.iter().map(|s| (s.kind, s.value)).collect());
            let p = o.statistics.free_parameters;
            fitted = Some(o);
            Ok((p, rmse, rel, log, ns))
        });
        match result {
            Ok((p, rmse, rel, log, ns)) => {
                candidates.push(Candidate {
                    rung: name.clone(),
                    free_parameters: p,
                    heldout_rmse: rmse,
                    heldout_relative_rmse: rel,
                    heldout_log_error: log,
                    ns_per_eval: ns,
                    fit_seconds: t.elapsed().as_secs_f64(),
                    chosen: false,
                    error: None,
                });
                fits.push(Some((rmse, rel, log)));
            }
            Err(e) => {
                candidates.push(Candidate {
                    rung: name.clone(),
                    free_parameters: 0,
                    heldout_rmse: f64::NAN,
                    heldout_relative_rmse: f64::NAN,
                    heldout_log_error: f64::NAN,
                    ns_per_eval: f64::NAN,
                    fit_seconds: t.elapsed().as_secs_f64(),
                    chosen: false,
                    error: Some(format!("{e:#}")),
                });
                fits.push(None);
            }
        }
        let c = candidates.last().expect("pushed");
        crate::progress::line(
            quiet,
            &match &c.error {
                None => format!(
                    "auto: {name} fitted in {}: held-out relative RMSE {:.2} %",
                    crate::progress::seconds(c.fit_seconds),
                    100.0 * c.heldout_relative_rmse
                ),
                Some(e) => format!(
                    "auto: {name} failed after {}: {e}",
                    crate::progress::seconds(c.fit_seconds)
                ),
            },
        );
        on_rung(&RungDone {
            candidates: &candidates,
            outcome: fitted.as_ref(),
            rungs,
            train_samples: train.samples.len(),
            heldout_samples: test.samples.len(),
        });
    }
    let Some((best_rmse, best_rel, _)) = fits
        .iter()
        .flatten()
        .copied()
        .min_by(|a, b| a.0.total_cmp(&b.0))
    else {
        bail!("--model auto: no rung could be fitted");
    };
    let best_log = fits
        .iter()
        .flatten()
        .map(|f| f.2)
        .fold(f64::INFINITY, f64::min);
    type Accept = Box<dyn Fn(f64, f64, f64) -> bool>;
    let (rule, accept): (String, Accept) = match (cfg.selection.tolerance, cfg.metric) {
        // the log metric asks for relative errors: judge by them
        (t, super::config::Metric::Log) => {
            let t = t.unwrap_or(0.05);
            (
                format!(
                    "held-out log error within {:.1} % of the best (log metric)",
                    100.0 * t
                ),
                Box::new(move |_, _, log| log <= best_log * (1.0 + t)),
            )
        }
        (Some(t), _) => (
            format!("held-out RMSE within {:.1} % of the best", 100.0 * t),
            Box::new(move |rmse, _, _| rmse <= best_rmse * (1.0 + t)),
        ),
        (None, _) if sigmas => (
            format!(
                "held-out relative RMSE within the noise level ({:.2} %) of the best ({:.2} %)",
                100.0 * noise_rel,
                100.0 * best_rel
            ),
            Box::new(move |_, rel, _| rel <= best_rel + noise_rel),
        ),
        (None, _) => (
            "held-out RMSE within 5 % of the best (no sigmas given)".to_string(),
            Box::new(move |rmse, _, _| rmse <= best_rmse * 1.05),
        ),
    };
    let chosen = fits
        .iter()
        .position(|f| f.is_some_and(|(rmse, rel, log)| accept(rmse, rel, log)))
        .expect("the best rung is acceptable");
    candidates[chosen].chosen = true;
    Ok(SelectionOutcome {
        chosen: candidates[chosen].rung.clone(),
        candidates,
        rule,
        train_samples: train.samples.len(),
        heldout_samples: test.samples.len(),
        hints,
    })
}

/// The selection table in markdown.
pub fn table(s: &SelectionOutcome) -> String {
    let mut t = format!(
        "Model selection ({}; {} training / {} held-out samples)\n\n| rung | free parameters | held-out RMSE [1/sr] | held-out relative RMSE | held-out log error | ns per evaluation | fit time [s] | chosen |\n|---|---|---|---|---|---|---|---|\n",
        s.rule, s.train_samples, s.heldout_samples
    );
    for c in &s.candidates {
        match &c.error {
            Some(e) => {
                t += &format!(
                    "| {} | - | failed: {e} | | | | {:.2} | |\n",
                    c.rung, c.fit_seconds
                )
            }
            None => {
                t += &format!(
                    "| {} | {} | {:.4e} | {:.2} % | {:.4} | {:.0} | {:.2} | {} |\n",
                    c.rung,
                    c.free_parameters,
                    c.heldout_rmse,
                    100.0 * c.heldout_relative_rmse,
                    c.heldout_log_error,
                    c.ns_per_eval,
                    c.fit_seconds,
                    if c.chosen { "**yes**" } else { "" }
                )
            }
        }
    }
    t
}
