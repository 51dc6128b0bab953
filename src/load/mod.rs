//! Loaders: files in, validated [`samples::Samples`] out. No model code here.

pub mod arrays;
pub mod board;
pub mod bracket;
pub mod capture;
pub mod capture_store;
pub mod curet;
pub mod gonio;
pub mod gray_map;
pub mod image_io;
pub mod input;
pub mod merl;
pub mod mesh;
pub mod params_file;
pub mod photo;
pub mod photo_lights;
pub mod queries;
pub mod rgl;
pub mod samples;
pub mod summary;
pub mod texel_maps;

#[cfg_attr(not(feature = "internals"), allow(unused_imports))] // for the tests and benchmarks
pub use input::{read_input, sha256_read, InputBytes, MAX_INPUT_BYTES};

use crate::model::frame::Vec3;
use anyhow::{bail, Result};
use std::path::Path;

/// Everything a user can set about loading.
#[derive(Clone, Debug, Default)]
pub struct LoadOptions {
    /// Options of goniometric tables (delimiter, columns, units).
    pub gonio: gonio::GonioOptions,
    /// Subsampling of capture pixels.
    pub subsample: capture::Subsample,
    /// Sampling of measured-BRDF files.
    pub measured: rgl::MeasuredOptions,
}

impl LoadOptions {
    /// The options, refused when a value is out of range (named as the command line's flag).
    pub fn checked(self) -> Result<Self> {
        if self.subsample.stride == 0 {
            bail!("--stride must be at least 1");
        }
        let f = self.subsample.fraction;
        if !(f > 0.0 && f <= 1.0) {
            bail!("--fraction must lie in (0, 1], got {f}");
        }
        gonio::check_columns(&self.gonio.columns)?;
        Ok(self)
    }
}

/// Every file loading `path` reads: the file itself and, for a capture, its images and maps
/// (so that no output of the run can replace one of them). Unreadable descriptions give just
/// the file; loading then reports the problem.
pub fn input_files(path: &Path) -> Vec<std::path::PathBuf> {
    let mut out = vec![path.to_path_buf()];
    let is_toml = path
        .extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| e.eq_ignore_ascii_case("toml"));
    if let (true, Ok(desc)) = (is_toml, capture::CaptureFile::load(path)) {
        let base = path.parent().unwrap_or(Path::new("."));
        let sw = &desc.swatch;
        for p in [
            &sw.mask,
            &sw.tangent_map,
            &sw.topology_map,
            &sw.height_map,
            &sw.fibre_azimuth_map,
        ]
        .into_iter()
        .flatten()
        {
            out.push(base.join(p));
        }
        for im in &desc.images {
            for (f, _) in im.frames() {
                out.push(base.join(f));
            }
            if let capture::Camera::ViewMap { file } = &im.camera {
                out.push(base.join(file));
            }
        }
    }
    out
}

/// The extensions of goniometric tables (any case): the delimiter is sniffed from the content
/// (comma, tab, semicolon or whitespace), never decided by the extension.
pub const GONIO_EXTENSIONS: [&str; 4] = ["csv", "tsv", "txt", "dat"];

/// Whether `path` names a goniometric table by its extension ([`GONIO_EXTENSIONS`]).
pub fn is_gonio_table(path: &Path) -> bool {
    path.extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| GONIO_EXTENSIONS.iter().any(|g| e.eq_ignore_ascii_case(g)))
}

/// Whether `path` names an image capture description (`.toml`).
pub fn is_capture(path: &Path) -> bool {
    path.extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| e.eq_ignore_ascii_case("toml"))
}

/// Load a goniometric table (`.csv`, `.tsv`, `.txt`, `.dat`), an image capture description
/// (`.toml`), an RGL measured BRDF (`.bsdf`, sampled at seeded directions) or a MERL `.binary`.
pub fn load_data(path: &Path, opts: &LoadOptions) -> Result<samples::Samples> {
    Ok(load_data_with_format(path, opts)?.0)
}

/// [`load_data`], and for a goniometric table what its header said (delimiter, columns).
pub fn load_data_with_format(
    path: &Path,
    opts: &LoadOptions,
) -> Result<(samples::Samples, Option<gonio::Format>)> {
    let plain = |s: samples::Samples| (s, None);
    if is_gonio_table(path) {
        return gonio::load_with_format(path, &opts.gonio).map(|(s, f)| (s, Some(f)));
    }
    match path
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase)
        .as_deref()
    {
        // every pixel as a sample (image by image, rows from the top), via the compact store
        Some("toml") => Ok(plain(
            capture_store::CaptureStore::load(path, opts.subsample)?.to_samples(),
        )),
        Some("bsdf") => rgl::load(path, opts.measured).map(plain),
        Some("binary") => merl::load(path, opts.measured).map(plain),
        _ => bail!(
            "{}: unknown data file type; expected a goniometric table (.csv, .tsv, .txt or .dat; comma-, tab-, semicolon- or whitespace-separated), an image capture .toml, an RGL measured BRDF .bsdf or a MERL .binary",
            path.display()
        ),
    }
}

/// The measured file at `path` as a function of the directions, for dense plots, when it is one
/// (RGL `.bsdf`: lights up to its measured incidence; MERL `.binary`); `None` for other data.
pub fn measured_brdf(path: &Path) -> Result<Option<crate::model::BrdfFn>> {
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase);
    Ok(match ext.as_deref() {
        Some("bsdf") => {
            let b = rgl::RglBsdf::load(path)?;
            let max_cos = b.max_theta_i.cos();
            Some(Box::new(move |l: &Vec3, v: &Vec3| {
                (l.z >= max_cos - 1e-12).then(|| b.brdf(l, v))
            }))
        }
        Some("binary") => {
            let b = merl::MerlBrdf::load(path)?;
            Some(Box::new(move |l: &Vec3, v: &Vec3| b.brdf(l, v)))
        }
        _ => None,
    })
}
