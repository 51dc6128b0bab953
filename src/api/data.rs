//! Data in: measurements loaded as samples, a capture's geometry and images as the fit reads
//! them, and the check that stops a wait on a FIFO or device (a front end's Ctrl-C).

use crate::load::samples::Samples;
use crate::load::LoadOptions;
use anyhow::Result;
use std::path::Path;

/// The samples of a goniometric CSV or TSV, an image capture (TOML) or a measured BRDF file
/// (`.bsdf`, `.binary`), loaded as `opts` says.
pub fn load(path: &Path, opts: &LoadOptions) -> Result<Samples> {
    crate::load::load_data(path, opts)
}

/// A capture's geometry as JSON, for renderers outside fibrefit: the swatch (`size_mm`,
/// `fibre_azimuth_deg`) and per image its file (absolute), size in pixels, exposure, light and
/// camera as the capture gives them (mm, degrees).
pub fn capture_geometry_json(capture: &Path) -> Result<String> {
    crate::load::capture::geometry_json(capture)
}

/// Image `index` of a capture as the fit reads it: linear radiance per unit irradiance
/// (exposure applied), channels interleaved, row 0 at the top, with per pixel whether it is
/// saturated.
pub fn capture_image(capture: &Path, index: usize) -> Result<crate::load::image_io::LinearImage> {
    crate::load::capture_store::radiance_image(capture, index)
}

/// Install a check asked while waiting on a FIFO or device (whether the user pressed Ctrl-C);
/// at most one, the first.
pub fn set_interrupt_check(check: fn() -> bool) {
    crate::load::input::set_interrupt_check(check)
}
