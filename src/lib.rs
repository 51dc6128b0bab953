//! fibrefit: fit fibre reflectance models to goniometric and image measurements.
//!
//! The library's API is [`api`]: one entry point per command (`fit`, `eval`, `score`,
//! `render`, `export`, map `tiles`), a request in and an outcome out, and
//! [`api::material::Material`] (a fitted material as a renderer sees it). The command line
//! ([`command_line`]) and the Python package call it. Inside, data flows one way: load ->
//! model -> fit -> export (ARCHITECTURE.md); the stages are internal (public with the
//! `internals` feature, for the crate's own tests and benchmarks).
//!
//! Units: directions are unit vectors in the swatch frame (z the macro normal), angles in
//! degrees at the boundary, BRDFs in 1/sr, lengths in fibre radii.
//!
//! Fit a goniometric table and evaluate the fitted material:
//!
//! ```
//! use fibrefit::api::{self, fit::FitRequest, fit::Maps, material::Material, LoadOptions, Vec3};
//! use std::path::Path;
//! # fn main() -> anyhow::Result<()> {
//! let data = Path::new("data_synthetic/silk/gonio.csv");
//! // a rung's defaults (or a config file such as configs/fit_silk.toml)
//! let config = api::fit::configure(None, Some("hast-diffuse"), None, None, data)?;
//! let run = api::fit::fit(&FitRequest {
//!     data: data.into(),
//!     config,
//!     load: LoadOptions::default(),
//!     maps: Maps::None,
//!     progress: fibrefit::Progress::quiet(),
//!     held: None,
//! })?;
//! println!("{}", run.report_text); // statistics, parameters with standard errors, quality
//! let result = serde_json::to_value(&run.result)?; // what `fibrefit fit --out` writes
//! let (material, _warnings) = Material::from_result(&result, data, None)?;
//! let l = Vec3::new(0.0, 0.5, 0.8).normalize(); // towards the light
//! let v = Vec3::new(0.3, -0.4, 0.8).normalize(); // towards the viewer
//! let brdf = material.eval(&l, &v, None); // 1/sr, per channel
//! assert!(brdf[0] > 0.0);
//! # Ok(())
//! # }
//! ```

// `!(x > 0.0)` is used on purpose: it is also true for NaN, which must take the safe branch.
#![allow(clippy::neg_cmp_op_on_partial_ord)]
#![cfg_attr(not(feature = "internals"), warn(missing_docs))]
// helpers the stages keep for their own tests and benchmarks (public with `internals`) are
// unused by the library itself
#![cfg_attr(not(feature = "internals"), allow(dead_code))]

/// Lines on standard error that never panic: std's `eprintln!` panics when stderr is closed or
/// full (`2>/dev/full`), and a message is no reason to lose a run. This one shadows it in the
/// whole crate (macros defined before the modules are in scope in them) and drops the error.
macro_rules! eprintln {
    ($($arg:tt)*) => {{
        use std::io::Write as _;
        let _ = writeln!(std::io::stderr(), $($arg)*);
    }};
}

/// A stage of the pipeline: internal to the crate (`pub(crate)`), public with the `internals`
/// feature, which the crate's own tests, benchmarks and examples turn on.
macro_rules! stage {
    ($($(#[$meta:meta])* $name:ident;)*) => {$(
        $(#[$meta])*
        #[cfg(feature = "internals")]
        pub mod $name;
        $(#[$meta])*
        #[cfg(not(feature = "internals"))]
        pub(crate) mod $name;
    )*};
}

pub mod api;
stage! {
    bench;
    board;
    calibrate;
    cli;
    export;
    fit;
    load;
    model;
    progress;
    render;
    synth;
}

pub use api::Progress;

/// The `fibrefit` command line: runs the command `std::env::args` names and returns its exit
/// code (0 done, 2 refused or failed with a message on stderr, 130 interrupted).
pub fn command_line() -> std::process::ExitCode {
    cli::main()
}
