//! Loading flags shared by every command that reads measurements.

use crate::api::fit::LoadFlags;
use crate::load::LoadOptions;
use anyhow::Result;
use clap::Args;

#[derive(Debug, Args, Clone)]
pub struct LoadArgs {
    /// Goniometric tables: the unit of the angle columns, converted on loading [default: deg,
    /// or the fit config's `[data] angles`]
    #[arg(long, value_name = "UNIT", value_parser = ["deg", "rad"])]
    pub angles: Option<String>,
    /// Goniometric CSV: skip bad rows (counted and reported) instead of stopping at the first
    #[arg(long)]
    pub skip_bad_rows: bool,
    /// Goniometric CSV: the angles really are small degrees (do not stop on radian-looking data)
    #[arg(long)]
    pub small_angles_ok: bool,
    /// Goniometric CSV: the file's own column names, e.g. theta_i=theta_in,phi_i=phi_in,brdf=f
    /// (beside a fit config's [columns], which these override)
    #[arg(long, value_name = "OURS=THEIRS,...")]
    pub columns: Option<String>,
    /// Image captures: use every STRIDE-th pixel in x and y [default: 1, or the fit config's]
    #[arg(long, value_name = "STRIDE")]
    pub stride: Option<usize>,
    /// Image captures: keep a seeded random fraction of the pixels, in (0, 1] [default: 1]
    #[arg(long, value_name = "F")]
    pub fraction: Option<f64>,
    /// Seed of the random pixel fraction
    #[arg(long, value_name = "SEED", default_value_t = 0)]
    pub subsample_seed: u64,
    /// Measured-BRDF files (.bsdf): direction pairs drawn, light and view uniform in solid angle
    #[arg(long, value_name = "COUNT", default_value_t = 3000)]
    pub directions: usize,
    /// Measured-BRDF files: seed of the drawn directions
    #[arg(long, value_name = "SEED", default_value_t = 0)]
    pub direction_seed: u64,
    /// Measured-BRDF files: largest theta of light and view, degrees (the light also stays within
    /// the file's measured incidence range)
    #[arg(long, value_name = "DEG", default_value_t = 78.0)]
    pub max_theta: f64,
}

impl LoadArgs {
    /// The flags as the library takes them (`--columns` parsed).
    pub fn flags(&self) -> Result<LoadFlags> {
        Ok(LoadFlags {
            skip_bad_rows: self.skip_bad_rows,
            small_angles_ok: self.small_angles_ok,
            columns: match &self.columns {
                Some(text) => crate::load::gonio::parse_columns(text)?,
                None => Vec::new(),
            },
            angles: self
                .angles
                .as_deref()
                .map(|a| a.parse().map_err(|e: String| anyhow::anyhow!("--angles: {e}")))
                .transpose()?,
            stride: self.stride,
            fraction: self.fraction,
            subsample_seed: self.subsample_seed,
            directions: self.directions,
            direction_seed: self.direction_seed,
            max_theta_deg: self.max_theta,
        })
    }

    /// Loading options without a config ([`LoadFlags::options`]).
    pub fn options(&self) -> Result<LoadOptions> {
        self.flags()?.options()
    }
}
