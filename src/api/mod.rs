//! The library's entry points: a request in, an outcome out. The command line (`cli`) and any
//! other front end (the Python package) call these; they hold the orchestration of the stages
//! (load -> model -> fit -> export) and no argument parsing or printing of results.

pub mod eval;
pub mod export;
pub mod fit;
pub mod material;
pub mod render;
pub mod score;
pub mod tiles;
