//! Score a fitted result against any dataset `fit` accepts: how well does the fit describe data
//! it may never have seen (a held-out set, another capture of the same swatch)?
//!
//! The result's model is evaluated exactly as the fit evaluated it (same rung, knobs, topology
//! map, per-sample fibre directions and map values, residual metric), so scoring a fit's own
//! training data reproduces the fit's statistics.
//!
//! Per channel: RMSE (1/sr), relative RMSE (RMSE / RMS data), and a log error, the RMS of
//! ln(max(m, 0) + eps) - ln(max(y, 0) + eps) with eps = 1 % of the channel's median value (the
//! `log` metric's floor: relative to the data, so noise around zero does not dominate). Overall: chi-square and its
//! reduced value when the data carry sigmas (else the weighted sum of squares), and the quality
//! block's residual-structure bins.

use super::config::{Knobs, Metric};
use super::parameters::{Param, ParamSet};
use super::problem::FitProblem;
use super::quality;
use super::uncertainty::{statistics_of_sums, Statistics};
use crate::load::capture_store::CaptureStore;
use crate::load::samples::{Sample, Samples};
use crate::model::topology::TopologyMap;
use anyhow::{Context, Result};
use serde::Serialize;
use std::sync::Arc;

/// A fitted result read back: the parameter set (nothing varies), its knobs and its free
/// parameter count.
pub struct FittedResult {
    pub set: ParamSet,
    pub metric: Metric,
    pub knobs: Knobs,
    pub free_parameters: usize,
    /// The smooth correction the result keeps on its rung (`correction.series`), if any: the
    /// model scored is the rung times its factor, the material (the instrument's terms of the
    /// fit's data, if any, are not applied: other data come from other instruments).
    pub correction: Option<crate::model::correction::Correction>,
}

#[derive(Clone, Debug, Serialize)]
pub struct ChannelScore {
    pub channel: String,
    pub rmse: f64,
    pub relative_rmse: f64,
    pub log_error: f64,
}

#[derive(Clone, Debug, Serialize)]
pub struct Score {
    pub model: String,
    pub samples: usize,
    pub statistics: Statistics,
    pub channels: Vec<ChannelScore>,
    pub residual_bins: Vec<quality::ResidualBin>,
    /// The fit's verdict on these data, in its words (quality::assess): "fits within the
    /// noise", "does not fit within the noise" or "noise unknown"; without sigmas, judged by
    /// the floor: "within 1.2x of what the data allow" or "misses structure the data hold: ...".
    pub verdict: String,
    /// How the noise was judged (sigmas, repeated directions, neighbouring pixels, none).
    pub noise: quality::NoiseCheck,
    /// The model's error on these data (RMS in the result's metric) against their floor:
    /// what a nonparametric predictor of the data themselves reaches held out (`fit::floor`);
    /// it gives the verdict of data without sigmas. Absent for captures.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub floor: Option<super::floor::FloorCheck>,
}

/// Texels per piece of a capture scored a piece at a time (whole image rows).
const CHUNK_TEXELS: usize = 16_384;

/// Score `result` against `samples`.
pub fn score(result: &FittedResult, samples: &Samples) -> Result<Score> {
    let map = topology_map(result)?;
    let ch = samples.channels;
    let values: Vec<[f64; 3]> = samples.samples.iter().map(|s| s.value).collect();
    let eps = [0, 1, 2].map(|c| super::problem::log_floor(&values, c));
    drop(values);
    let problem = problem_for(result, &map, samples.samples.iter().collect(), eps);
    let mut run = Running::new(ch, eps);
    run.add(result, &problem)?;
    let repeats =
        || quality::repeats_estimate(quality::repeats_sums(&problem.samples, problem.scale(), ch));
    let mut score = run.finish(result, repeats);
    // a capture's score has no floor (its pixels are judged by their neighbours' noise), so
    // that this path and the one a piece at a time (`score_capture`) say the same
    if samples.kind != crate::load::samples::DataKind::Capture {
        with_floor(&mut score, samples, result.metric, eps);
    }
    Ok(score)
}

/// The floor of the scored `samples` (log floors `eps`) in `score`, and, without sigmas or
/// neighbouring pixels, the verdict it gives. Too few samples: none.
fn with_floor(score: &mut Score, samples: &Samples, metric: Metric, eps: [f64; 3]) {
    let st = &score.statistics;
    let error = (st.chi_square / st.n.max(1) as f64).sqrt();
    let Ok(f) = super::floor::of_scored(samples, metric, eps, error) else {
        return;
    };
    if !st.sigmas_given && score.noise.source != "neighbouring pixels" {
        score.verdict = f.verdict.clone();
    }
    score.floor = Some(f);
}

/// Score `result` against the capture held by `store`, a piece at a time (whole rows of one
/// image, in the order of [`CaptureStore::to_samples`]): no more than one piece's samples exist
/// at once, and the numbers are those of [`score`] on every sample (sums in the same order; the
/// noise from neighbouring pixels summed row by row).
pub fn score_capture(result: &FittedResult, store: &CaptureStore) -> Result<Score> {
    score_capture_in_pieces(result, store, CHUNK_TEXELS)
}

/// [`score_capture`] in pieces of whole image rows of at least `piece_texels` texels.
pub fn score_capture_in_pieces(
    result: &FittedResult,
    store: &CaptureStore,
    piece_texels: usize,
) -> Result<Score> {
    let map = topology_map(result)?;
    let ch = store.channels;
    // the log floors: 1 % of each channel's median over every sample
    let mut eps = [0.0; 3];
    for (c, e) in eps.iter_mut().enumerate() {
        *e = super::problem::log_floor_of_magnitudes(store.channel_magnitudes(c.min(ch - 1)));
    }
    let mut run = Running::new(ch, eps);
    let pieces = store.row_chunks(piece_texels);
    for k in 0..store.images() {
        for texels in &pieces {
            let samples = store.image_samples(k, texels.clone());
            if samples.samples.is_empty() {
                continue;
            }
            let problem = problem_for(result, &map, samples.samples.iter().collect(), eps);
            run.add(result, &problem)?;
        }
    }
    // repeated directions (asked only without sigmas and neighbours): a texel's pixels in
    // every image, texels a chunk at a time
    let repeats = || {
        let mut sums = (0.0, 0);
        let all: Vec<usize> = (0..store.texels().len()).collect();
        for ids in all.chunks(piece_texels) {
            let samples = store.samples_of(ids);
            let problem = problem_for(result, &map, samples.samples.iter().collect(), eps);
            let (ss, dof) = quality::repeats_sums(&problem.samples, problem.scale(), ch);
            sums.0 += ss;
            sums.1 += dof;
        }
        quality::repeats_estimate(sums)
    };
    Ok(run.finish(result, repeats))
}

fn topology_map(result: &FittedResult) -> Result<Option<Arc<TopologyMap>>> {
    Ok(match &result.knobs.topology_map {
        Some(p) => Some(Arc::new(
            TopologyMap::load(p).context("the result's knobs.topology_map")?,
        )),
        None => None,
    })
}

/// The fit's problem on `samples` (the `log` metric's floors `eps` of all the data).
fn problem_for<'a>(
    result: &FittedResult,
    map: &Option<Arc<TopologyMap>>,
    samples: Vec<&'a Sample>,
    eps: [f64; 3],
) -> FitProblem<'a> {
    let problem = FitProblem::new(
        samples,
        result.set.clone(),
        super::problem::Settings {
            metric: result.metric,
            quadrature_order: result.knobs.quadrature_order,
            histogram_bins: result.knobs.histogram_bins,
            separable: false,
        },
        map.clone(),
    )
    .with_azimuth_nodes(result.knobs.azimuth_nodes);
    match result.metric {
        Metric::Log => problem.with_log_floor(eps),
        _ => problem,
    }
}

/// The model values of `problem` times the correction `k`'s factor, and their residuals in
/// the result's metric (the log floors `eps`).
fn corrected(
    problem: &FitProblem,
    cols: &[crate::fit::problem::Columns],
    result: &FittedResult,
    k: &crate::model::correction::Correction,
    eps: &[f64; 3],
) -> (Vec<[f64; 3]>, nalgebra::DVector<f64>) {
    let ch = problem.channels();
    let mut model = problem.model_values(cols, &result.set);
    for (m, s) in model.iter_mut().zip(&problem.samples) {
        let (ci, co, cd) = crate::fit::correction::sample_point(s);
        let f = k.factor_at(ci, co, cd);
        for c in 0..3 {
            m[c] *= f[c];
        }
    }
    let scale = problem.scale();
    let mut r = nalgebra::DVector::zeros(model.len() * ch);
    for (i, (m, s)) in model.iter().zip(&problem.samples).enumerate() {
        for c in 0..ch {
            r[i * ch + c] = crate::fit::problem::metric_residual(
                result.metric,
                scale[i][c],
                eps[c],
                s,
                c,
                m[c],
            );
        }
    }
    (model, r)
}

/// A score's sums over the samples, added a piece at a time in the samples' order.
struct Running {
    channels: usize,
    /// Per channel: the floor of the log error (the `log` metric's, of all the data).
    eps: [f64; 3],
    samples: usize,
    chi_square: f64,
    /// Sum of (model - data)^2 and of data^2 over every value, and the number of values.
    values: (f64, f64, usize),
    /// Per channel: sum of (model - data)^2, of data^2, of the squared log error.
    per_channel: [(f64, f64, f64); 3],
    sigmas: bool,
    quality: quality::Sums,
}

impl Running {
    fn new(channels: usize, eps: [f64; 3]) -> Self {
        Self {
            channels,
            eps,
            samples: 0,
            chi_square: 0.0,
            values: (0.0, 0.0, 0),
            per_channel: [(0.0, 0.0, 0.0); 3],
            sigmas: true,
            // the second differences are kept in case the data carry no sigmas
            quality: quality::Sums::new(true),
        }
    }

    /// Add the samples of `problem` (its log floors those of all the data).
    fn add(&mut self, result: &FittedResult, problem: &FitProblem) -> Result<()> {
        let ch = self.channels;
        let cols = problem.columns(&result.set)?;
        let (model, r) = match &result.correction {
            None => (
                problem.model_values(&cols, &result.set),
                problem.residuals(&cols, &result.set),
            ),
            Some(k) => corrected(problem, &cols, result, k, &self.eps),
        };
        drop(cols);
        self.chi_square += r.norm_squared();
        for (m, s) in model.iter().zip(&problem.samples) {
            for c in 0..ch {
                let (m, y) = (m[c], s.value[c]);
                self.values.0 += (m - y) * (m - y);
                self.values.1 += y * y;
            }
            self.values.2 += ch;
        }
        for (c, (sq, yy, log)) in self.per_channel.iter_mut().enumerate().take(ch) {
            let eps = self.eps[c];
            for (m, s) in model.iter().zip(&problem.samples) {
                let (m, y) = (m[c], s.value[c]);
                *sq += (m - y).powi(2);
                *yy += y * y;
                *log += ((m.max(0.0) + eps).ln() - (y.max(0.0) + eps).ln()).powi(2);
            }
        }
        self.sigmas &= problem.samples.iter().all(|s| s.sigma.is_some());
        self.samples += problem.samples.len();
        self.quality.add(
            &problem.samples,
            r.as_slice(),
            ch,
            result.set.shape_value(Param::Azimuth).to_radians(),
        );
        Ok(())
    }

    fn finish(
        self,
        result: &FittedResult,
        repeats: impl FnOnce() -> Option<(f64, usize)>,
    ) -> Score {
        let ch = self.channels;
        let stats = statistics_of_sums(
            self.chi_square,
            self.quality.n,
            result.free_parameters,
            self.sigmas,
            self.values,
        );
        let names = if ch == 1 {
            vec!["grey"]
        } else {
            vec!["r", "g", "b"]
        };
        let n = self.samples.max(1) as f64;
        let channels = (0..ch)
            .map(|c| {
                let (sq, yy, log) = self.per_channel[c];
                let rms_y = (yy / n).sqrt();
                let rmse = (sq / n).sqrt();
                ChannelScore {
                    channel: names[c].into(),
                    rmse,
                    relative_rmse: rmse / rms_y.max(f64::MIN_POSITIVE),
                    log_error: (log / n).sqrt(),
                }
            })
            .collect();
        let q = quality::assess_sums(
            &self.quality,
            result.free_parameters,
            self.sigmas,
            repeats,
            &[],
        );
        Score {
            model: result.set.rung.to_string(),
            samples: self.samples,
            statistics: stats,
            channels,
            residual_bins: q.residual_bins,
            verdict: q.verdict,
            noise: q.noise,
            floor: None,
        }
    }
}

/// The score as text.
pub fn text(s: &Score) -> String {
    let st = &s.statistics;
    let mut t = format!(
        "[[Score]]\n    model              = {}\n    samples            = {}\n    residuals          = {}\n    free parameters    = {} (of the fit)\n",
        s.model, s.samples, st.n, st.free_parameters
    );
    if st.sigmas_given {
        t += &format!(
            "    chi-square         = {:.6e}\n    reduced chi-square = {:.6}\n",
            st.chi_square, st.reduced_chi_square
        );
    } else {
        t += &format!(
            "    sum of squares     = {:.6e}  (no sigmas: chi-square not defined)\n",
            st.chi_square
        );
    }
    t += &format!(
        "    RMSE               = {:.6e} 1/sr\n    relative RMSE      = {:.4} %\n",
        st.rmse,
        100.0 * st.relative_rmse
    );
    t += "    per channel:        RMSE [1/sr]   relative RMSE   log error\n";
    for c in &s.channels {
        t += &format!(
            "      {:<16} {:.6e}   {:>10.4} %   {:.6}\n",
            c.channel,
            c.rmse,
            100.0 * c.relative_rmse,
            c.log_error
        );
    }
    t += &quality::bins_text(&s.residual_bins);
    if let Some(f) = &s.floor {
        t += "[[Floor]] (what the data themselves allow)\n";
        t += &super::floor::text(f);
    }
    // the verdict last, in the fit report's words
    t += &format!(
        "[[Verdict]]\n    verdict            = {}\n    noise ({})  {}\n",
        s.verdict, s.noise.source, s.noise.note
    );
    t
}
