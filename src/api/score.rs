//! `score`: a fitted result evaluated exactly as the fit did (rung, knobs, topology map,
//! residual metric) on any dataset `fit` accepts: held-out data, another capture.

use crate::fit::score::{self, Score};
use crate::load::{load_data, LoadOptions};
use anyhow::Result;
use std::path::Path;

/// Score the result file `result` on `data`.
pub fn score(result: &Path, data: &Path, load: &LoadOptions) -> Result<Score> {
    let samples = load_data(data, load)?;
    let fitted = crate::export::result_json::read_result(result, samples.channels)?;
    score::score(&fitted, &samples)
}
