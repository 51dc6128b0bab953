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
        return score::score_capture(&fitted, &store);
    }
    let samples = load_data(data, load)?;
    let fitted = crate::export::result_json::read_result(result, samples.channels)?;
    score::score(&fitted, &samples)
}
