//! Writers of the outputs a user asks for (result JSON, fit report and plots, maps, pictures,
//! eval tables, glTF, shaders, Blender scripts): every file goes through [`atomic::Outputs`], so a failed run
//! never leaves a half-written file or clobbers an existing one. The benchmarks' reports are
//! written by `bench::report`.

pub mod atomic;
pub mod blender_out;
pub mod brdf_plots;
pub mod coverage_plot;
pub mod dng;
pub mod eval_table;
pub mod gltf_out;
pub mod images;
pub mod maps_out;
pub mod material_textures;
pub mod materialx_out;
pub mod picture;
pub mod plots;
pub mod report;
pub mod result_json;
pub mod shader;
pub mod summary_csv;
pub mod tangent_field;
pub mod usd_out;
pub mod view;
