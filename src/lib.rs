//! fibrefit: fit fibre reflectance models to goniometric and image measurements.
//!
//! Data flows one way: [`load`] -> [`model`] -> fit -> [`export`] (and [`render`] beside it);
//! [`api`] holds the entry points (a request in, an outcome out) that [`cli`] and other front
//! ends call.

// `!(x > 0.0)` is used on purpose: it is also true for NaN, which must take the safe branch.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

/// Lines on standard error that never panic: std's `eprintln!` panics when stderr is closed or
/// full (`2>/dev/full`), and a message is no reason to lose a run. This one shadows it in the
/// whole crate (macros defined before the modules are in scope in them) and drops the error.
macro_rules! eprintln {
    ($($arg:tt)*) => {{
        use std::io::Write as _;
        let _ = writeln!(std::io::stderr(), $($arg)*);
    }};
}

pub mod api;
pub mod bench;
pub mod cli;
pub mod export;
pub mod fit;
pub mod load;
pub mod model;
pub mod progress;
pub mod render;
pub mod synth;
