//! A capture's global fit checked on every pixel, when the fit used a sample of its texels
//! (`[knobs] fit_texels`): the fitted model evaluated over the whole capture, a chunk of texels
//! at a time (no more than one chunk's samples exist at once), and its residual statistics set
//! beside the sample's, so a sample that does not represent the capture is found out.

use super::config::FitConfig;
use super::FitOutcome;
use crate::load::capture_store::CaptureStore;
use anyhow::Result;
use rayon::prelude::*;

/// Texels per chunk of the pass.
const CHUNK_TEXELS: usize = 8192;

/// Residual statistics over every pixel of a capture at the fitted parameters.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct AllPixels {
    pub texels: usize,
    /// Residuals (pixel values x channels).
    pub n: usize,
    /// Sum of squared weighted residuals.
    pub sum_of_squares: f64,
    /// sum_of_squares / (n - free parameters): comparable with the fit's residual variance.
    pub residual_variance: f64,
    /// Unweighted RMS of model - data, 1/sr.
    pub rmse: f64,
    /// RMSE / RMS(data).
    pub relative_rmse: f64,
}

/// The fitted model of `outcome` over every texel of `store`.
pub fn statistics(
    store: &CaptureStore,
    cfg: &FitConfig,
    outcome: &FitOutcome,
    progress: &crate::progress::Progress,
) -> Result<AllPixels> {
    let texels = store.texels().len();
    let chunks: Vec<Vec<usize>> = (0..texels)
        .collect::<Vec<_>>()
        .chunks(CHUNK_TEXELS)
        .map(<[usize]>::to_vec)
        .collect();
    let bar = progress.bar(chunks.len() as u64, "fit: every pixel");
    // per chunk: (sum of squares, residuals, sum of squared errors, sum of squared data)
    let sums: Vec<(f64, usize, f64, f64)> = chunks
        .iter()
        .map(|ids| -> Result<_> {
            let samples = store.samples_of(ids);
            let p = super::selection::problem_at(outcome, cfg, &samples);
            let cols = p.columns(&outcome.set)?;
            let r = p.residuals(&cols, &outcome.set);
            let model = p.model_values(&cols, &outcome.set);
            let ch = store.channels;
            let (e2, d2) = samples
                .samples
                .par_iter()
                .zip(model.par_iter())
                .map(|(s, m)| {
                    (0..ch).fold((0.0, 0.0), |(e, d), c| {
                        (e + (m[c] - s.value[c]).powi(2), d + s.value[c].powi(2))
                    })
                })
                .reduce(|| (0.0, 0.0), |a, b| (a.0 + b.0, a.1 + b.1));
            bar.inc(1);
            Ok((r.norm_squared(), samples.samples.len() * ch, e2, d2))
        })
        .collect::<Result<_>>()?;
    bar.finish_and_clear();
    let (ss, n, e2, d2) = sums.iter().fold((0.0, 0, 0.0, 0.0), |a, b| {
        (a.0 + b.0, a.1 + b.1, a.2 + b.2, a.3 + b.3)
    });
    let dof = n.saturating_sub(outcome.statistics.free_parameters).max(1);
    let rmse = (e2 / n.max(1) as f64).sqrt();
    Ok(AllPixels {
        texels,
        n,
        sum_of_squares: ss,
        residual_variance: ss / dof as f64,
        rmse,
        relative_rmse: rmse / (d2 / n.max(1) as f64).sqrt(),
    })
}

/// A warning when the model fits the whole capture clearly worse than the sample it was fitted
/// on (residual variance more than 1.5 times the sample's).
pub fn warning(all: &AllPixels, sample_variance: f64, sample_texels: usize) -> Option<String> {
    (all.residual_variance > 1.5 * sample_variance).then(|| {
        format!(
            "over every pixel ({} texels) the residual variance is {:.3e}, {:.1} times that of the {} texels the global fit used: the sample does not represent the capture; raise [knobs] fit_texels (0 = every texel)",
            all.texels,
            all.residual_variance,
            all.residual_variance / sample_variance,
            sample_texels
        )
    })
}
