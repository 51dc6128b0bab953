//! The library's entry points: a request in, an outcome out. The command line (`cli`) and any
//! other front end (the Python package) call these; they hold the orchestration of the stages
//! (load -> model -> fit -> export) and no argument parsing or printing of results.

pub mod batch;
pub mod board;
pub mod calibrate;
pub mod capture;
pub mod data;
pub mod energy;
pub mod eval;
pub mod export;
pub mod fit;
pub mod material;
pub mod render;
pub mod score;
pub mod tiles;
pub mod view;

pub use crate::export::atomic::Outputs;
pub use crate::export::result_json::ResultFile;
pub use crate::export::summary_csv::Row as SummaryRow;
pub use crate::fit::config::{FitConfig, Metric, ModelChoice};
pub use crate::fit::determined::Undetermined;
pub use crate::fit::maps::TexelMaps;
pub use crate::fit::score::text as score_text;
pub use crate::fit::selection::{Candidate, SelectionOutcome};
pub use crate::fit::{FitOutcome, ParamRecord};
pub use crate::load::capture::Subsample;
pub use crate::load::gonio::{AngleUnit, GonioOptions};
pub use crate::load::image_io::LinearImage;
pub use crate::load::rgl::MeasuredOptions;
pub use crate::load::samples::{DataKind, Origin, Sample, Samples};
pub use crate::load::LoadOptions;
pub use crate::model::frame::Vec3;
pub use crate::model::ModelId;
pub use crate::progress::Progress;
pub use capture::{ImageScene, SceneCamera, SceneLight};
pub use fit::{FitOptions, Held, HeldSamples, LoadFlags, OwnedArrays};

/// Run `f` on a pool of `threads` worker threads (`None`: rayon's global pool, as many as the
/// machine has cores unless `RAYON_NUM_THREADS` says otherwise). Every parallel stage of the
/// library runs on the pool it is called from.
pub fn with_threads<T: Send>(
    threads: Option<usize>,
    f: impl FnOnce() -> T + Send,
) -> anyhow::Result<T> {
    match threads {
        None => Ok(f()),
        Some(0) => anyhow::bail!("--threads 0: give at least 1 thread"),
        Some(n) => Ok(rayon::ThreadPoolBuilder::new()
            .num_threads(n)
            .build()
            .map_err(|e| anyhow::anyhow!("--threads {n}: cannot start the threads: {e}"))?
            .install(f)),
    }
}
