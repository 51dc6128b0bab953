//! Loaders: files in, validated samples out. No model code here.

pub mod queries;
