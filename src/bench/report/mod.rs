//! The benchmarks' own reports (`reports/*.md`, their CSVs and plots), written by `fibrefit
//! bench`: bench drives the stages and writes what it measured; `export/` holds only the
//! outputs a user asks for.

pub mod camera;
pub mod felt;
pub mod maps;
pub mod real;
pub mod renderers;
pub mod robustness;
pub mod sampling;
pub mod selection;
pub mod shader;
pub mod speed;
