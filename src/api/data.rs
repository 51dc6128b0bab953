//! Data in: measurements loaded as samples, a capture's geometry and images as the fit reads
//! them, and the check that stops a wait on a FIFO or device (a front end's Ctrl-C).

pub use crate::load::gonio::AngleUnit;
use crate::load::samples::Samples;
use crate::load::LoadOptions;
use anyhow::Result;
use std::path::Path;

/// The samples of a goniometric table (`.csv`, `.tsv`, `.txt`, `.dat`), an image capture (TOML) or a measured BRDF file
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

/// The loading flags of a front end, as the command line's `--stride`, `--columns`, ...
/// give them (absent flags at the command line's defaults): taken as they are by commands
/// without a config ([`LoadFlags::options`]), merged with a fit config's by [`FitOptions`](super::fit::FitOptions).
#[derive(Clone, Debug, PartialEq)]
pub struct LoadFlags {
    /// Goniometric CSV: skip bad rows (counted and reported) instead of stopping at the first.
    pub skip_bad_rows: bool,
    /// Goniometric CSV: the angles really are small degrees (do not stop on radian-looking
    /// data).
    pub small_angles_ok: bool,
    /// Goniometric CSV: the file's own column names, (ours, theirs); they extend and override a
    /// config's `[columns]`.
    pub columns: Vec<(String, String)>,
    /// Goniometric tables: the unit of the angle columns (`--angles deg|rad`); `None`: the
    /// config's `[data] angles`, else degrees.
    pub angles: Option<AngleUnit>,
    /// Image captures: every `stride`-th pixel in x and y; `None`: the config's, else 1.
    pub stride: Option<usize>,
    /// Image captures: a seeded random fraction of the pixels, in (0, 1]; `None`: the
    /// config's, else 1.
    pub fraction: Option<f64>,
    /// Seed of the random pixel fraction.
    pub subsample_seed: u64,
    /// Measured-BRDF files: direction pairs drawn, light and view uniform in solid angle
    /// (a count).
    pub directions: usize,
    /// Measured-BRDF files: seed of the drawn directions.
    pub direction_seed: u64,
    /// Measured-BRDF files: largest theta of light and view, degrees.
    pub max_theta_deg: f64,
}

impl Default for LoadFlags {
    fn default() -> Self {
        let m = crate::load::rgl::MeasuredOptions::default();
        Self {
            skip_bad_rows: false,
            small_angles_ok: false,
            columns: Vec::new(),
            angles: None,
            stride: None,
            fraction: None,
            subsample_seed: 0,
            directions: m.directions,
            direction_seed: m.seed,
            max_theta_deg: m.max_theta_deg,
        }
    }
}

impl LoadFlags {
    /// The loading options, checked; `stride`, `fraction` and `angles` fall back to the given
    /// defaults (a config's), [`LoadFlags::columns`] extend and override `columns` (a config's
    /// `[columns]`).
    pub fn options_with(
        &self,
        stride: usize,
        fraction: f64,
        angles: AngleUnit,
        columns: &std::collections::BTreeMap<String, String>,
    ) -> Result<LoadOptions> {
        let mut map: Vec<(String, String)> = columns
            .iter()
            .map(|(k, v)| (k.clone(), v.clone()))
            .collect();
        for (ours, theirs) in &self.columns {
            map.retain(|(o, _)| o != ours);
            map.push((ours.clone(), theirs.clone()));
        }
        LoadOptions {
            gonio: crate::load::gonio::GonioOptions {
                skip_bad_rows: self.skip_bad_rows,
                small_angles_ok: self.small_angles_ok,
                columns: map,
                angles: self.angles.unwrap_or(angles),
            },
            subsample: crate::load::capture::Subsample {
                stride: self.stride.unwrap_or(stride),
                fraction: self.fraction.unwrap_or(fraction),
                seed: self.subsample_seed,
            },
            measured: crate::load::rgl::MeasuredOptions {
                directions: self.directions,
                seed: self.direction_seed,
                max_theta_deg: self.max_theta_deg,
            },
        }
        .checked()
    }

    /// The loading options without a config (stride and fraction 1 unless given), checked.
    pub fn options(&self) -> Result<LoadOptions> {
        self.options_with(1, 1.0, AngleUnit::Deg, &Default::default())
    }

    /// The loading options of a fit configured by `cfg`: its `[knobs]` stride and fraction
    /// and its `[data]` angle unit unless given, its `[columns]` extended and overridden by
    /// [`LoadFlags::columns`].
    pub fn options_for(&self, cfg: &crate::fit::config::FitConfig) -> Result<LoadOptions> {
        self.options_with(
            cfg.knobs.stride,
            cfg.knobs.fraction,
            cfg.data.angles,
            &cfg.columns,
        )
    }
}
