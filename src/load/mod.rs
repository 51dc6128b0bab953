//! Loaders: files in, validated [`samples::Samples`] out. No model code here.

pub mod capture;
pub mod gonio;
pub mod image_io;
pub mod queries;
pub mod samples;
pub mod summary;

use anyhow::{bail, Result};
use std::path::Path;

/// Everything a user can set about loading.
#[derive(Clone, Debug, Default)]
pub struct LoadOptions {
    pub gonio: gonio::GonioOptions,
    pub subsample: capture::Subsample,
}

/// Load a goniometric CSV (`.csv`) or an image capture description (`.toml`).
pub fn load_data(path: &Path, opts: &LoadOptions) -> Result<samples::Samples> {
    match path
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase)
        .as_deref()
    {
        Some("csv") => gonio::load(path, opts.gonio),
        Some("toml") => capture::load(path, opts.subsample),
        _ => bail!(
            "{}: unknown data file type; expected a goniometric .csv or an image capture .toml",
            path.display()
        ),
    }
}
