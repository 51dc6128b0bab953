//! `score`: a fitted result evaluated exactly as the fit did (rung, knobs, topology map,
//! residual metric) on any dataset `fit` accepts: held-out data, another capture. A capture is
//! read into the compact store and scored a piece at a time (as `fit` reads it).

use crate::fit::score::{self, Score};
use crate::load::capture_store::CaptureStore;
use crate::load::{is_capture, load_data, LoadOptions};
use anyhow::Result;
use std::path::Path;

/// Score the result file `result` on `data`.
pub fn score(result: &Path, data: &Path, load: &LoadOptions) -> Result<Score> {
    if is_capture(data) {
        let store = CaptureStore::load(data, load.subsample)?;
        let fitted = crate::export::result_json::read_result(result, store.channels)?;
        check_scratch(result, &fitted, store.sample_count())?;
        return score::score_capture(&fitted, &store);
    }
    let samples = load_data(data, load)?;
    let fitted = crate::export::result_json::read_result(result, samples.channels)?;
    check_scratch(result, &fitted, samples.samples.len())?;
    score::score(&fitted, &samples)
}

/// The memory budget of a fit, for the result's knobs, before any evaluation.
fn check_scratch(result: &Path, fitted: &score::FittedResult, samples: usize) -> Result<()> {
    crate::fit::config::check_scratch(fitted.set.rung, fitted.knobs.histogram_bins, samples)
        .map_err(|e| anyhow::anyhow!("{}: {e}", result.display()))
}
