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
use super::parameters::{ParamSet, Shape};
use super::problem::FitProblem;
use super::quality;
use super::uncertainty::{statistics, Statistics};
use crate::load::samples::Samples;
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
    /// noise", "does not fit within the noise" or "noise unknown".
    pub verdict: String,
    /// How the noise was judged (sigmas, repeated directions, neighbouring pixels, none).
    pub noise: quality::NoiseCheck,
}

/// Score `result` against `samples`.
pub fn score(result: &FittedResult, samples: &Samples) -> Result<Score> {
    let map = match &result.knobs.topology_map {
        Some(p) => Some(Arc::new(
            TopologyMap::load(p).context("the result's knobs.topology_map")?,
        )),
        None => None,
    };
    let ch = samples.channels;
    let problem = FitProblem::new(
        samples.samples.iter().collect(),
        result.set.clone(),
        result.metric,
        result.knobs.quadrature_order,
        result.knobs.histogram_bins,
        map,
        false,
    )
    .with_azimuth_nodes(result.knobs.azimuth_nodes);
    let cols = problem.columns(&result.set)?;
    let r = problem.residuals(&cols, &result.set);
    let values = problem.model_values(&cols, &result.set);
    let mut model_flat = Vec::with_capacity(values.len() * ch);
    let mut data_flat = Vec::with_capacity(values.len() * ch);
    for (m, s) in values.iter().zip(&samples.samples) {
        model_flat.extend_from_slice(&m[..ch]);
        data_flat.extend_from_slice(&s.value[..ch]);
    }
    let sigmas = samples.samples.iter().all(|s| s.sigma.is_some());
    let stats = statistics(
        r.norm_squared(),
        r.len(),
        result.free_parameters,
        sigmas,
        &model_flat,
        &data_flat,
    );
    let names = if ch == 1 {
        vec!["grey"]
    } else {
        vec!["r", "g", "b"]
    };
    let channels = (0..ch)
        .map(|c| {
            let pairs: Vec<(f64, f64)> = values
                .iter()
                .zip(&samples.samples)
                .map(|(m, s)| (m[c], s.value[c]))
                .collect();
            let n = pairs.len().max(1) as f64;
            let rms_y = (pairs.iter().map(|p| p.1 * p.1).sum::<f64>() / n).sqrt();
            let rmse = (pairs.iter().map(|p| (p.0 - p.1).powi(2)).sum::<f64>() / n).sqrt();
            let eps = super::problem::log_floor(
                &samples.samples.iter().map(|s| s.value).collect::<Vec<_>>(),
                c,
            );
            let log_error = (pairs
                .iter()
                .map(|p| ((p.0.max(0.0) + eps).ln() - (p.1.max(0.0) + eps).ln()).powi(2))
                .sum::<f64>()
                / n)
                .sqrt();
            ChannelScore {
                channel: names[c].into(),
                rmse,
                relative_rmse: rmse / rms_y.max(f64::MIN_POSITIVE),
                log_error,
            }
        })
        .collect();
    let q = quality::assess(&quality::Inputs {
        samples: &problem.samples,
        scale: problem.scale(),
        residuals: r.as_slice(),
        channels: ch,
        free_parameters: result.free_parameters,
        sigmas_given: sigmas,
        psi: result.set.shape_value(Shape::Azimuth).to_radians(),
        minima: &[],
    });
    Ok(Score {
        model: result.set.rung.to_string(),
        samples: samples.samples.len(),
        statistics: stats,
        channels,
        residual_bins: q.residual_bins,
        verdict: q.verdict,
        noise: q.noise,
    })
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
    // the verdict last, in the fit report's words
    t += &format!(
        "[[Verdict]]\n    verdict            = {}\n    noise ({})  {}\n",
        s.verdict, s.noise.source, s.noise.note
    );
    t
}
