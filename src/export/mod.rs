//! Writers: every output goes through [`atomic::AtomicFile`], so a failed run never leaves a
//! half-written file or clobbers an existing one.

pub mod atomic;
pub mod brdf_plots;
pub mod camera_report;
pub mod eval_table;
pub mod felt_report;
pub mod gltf_out;
pub mod images;
pub mod maps_out;
pub mod maps_report;
pub mod picture;
pub mod plots;
pub mod report;
pub mod result_json;
pub mod robustness_report;
pub mod shader;
pub mod shader_report;
pub mod speed_report;
