//! fibrefit: fit fibre reflectance models to goniometric and image measurements.
//!
//! Data flows one way: [`load`] -> [`model`] -> fit -> [`export`] (and [`render`] beside it);
//! [`api`] holds the entry points (a request in, an outcome out) that [`cli`] and other front
//! ends call.

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
