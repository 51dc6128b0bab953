//! The one sample representation every loader produces and the model and fitter consume.

use crate::model::frame::Vec3;
use std::path::PathBuf;

/// One measurement: a BRDF value (1/sr) at a light/view pair.
#[derive(Clone, Debug, PartialEq)]
pub struct Sample {
    /// Unit direction towards the light, swatch frame.
    pub l: Vec3,
    /// Unit direction towards the viewer, swatch frame.
    pub v: Vec3,
    /// Fibre azimuth psi (radians) at this sample when the data carries it (tangent map);
    /// `None`: the parameter `fibre_azimuth_deg` applies.
    pub fibre_azimuth: Option<f64>,
    /// Topology map value m in [0, 1] of this pixel's texel; `None` for a spot that averages
    /// over the map (goniometric samples).
    pub map_value: Option<f64>,
    /// Height H (fibre radii) of this pixel's texel from a height map (a recovered
    /// `height.exr`); wins over `map_value`.
    pub texel_height: Option<f64>,
    /// BRDF per channel (grey data repeats channel 0), 1/sr.
    pub value: [f64; 3],
    /// Standard deviation of `value` per channel, when known.
    pub sigma: Option<[f64; 3]>,
    /// Relative weight in the fit (1 unless the file says otherwise).
    pub weight: f64,
    /// Where the sample came from: a CSV line, or (image index, x, y) of a capture.
    pub origin: Origin,
}

/// Where a sample came from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Origin {
    /// Line of a table (1 = the first line).
    Line(u64),
    /// A pixel of a capture: image index, column `x`, row `y` (from the top).
    Pixel {
        /// Index of the image in the capture.
        image: u32,
        /// Column, pixels from the left.
        x: u32,
        /// Row, pixels from the top.
        y: u32,
    },
}

/// What kind of data the samples came from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum DataKind {
    /// A goniometric table.
    Gonio,
    /// An image capture.
    Capture,
    /// A measured-BRDF file (RGL `.bsdf`) sampled at seeded directions.
    Measured,
}

/// Why samples were left out, counted.
#[derive(Clone, Debug, Default, PartialEq, Eq, serde::Serialize)]
pub struct Dropped {
    /// Pixels at the sensor's saturation level.
    pub saturated: u64,
    /// Pixels outside the region of interest or the mask.
    pub masked: u64,
    /// Light or view at or below the swatch plane.
    pub below_horizon: u64,
    /// Non-finite pixel values.
    pub invalid: u64,
    /// Rows skipped on request (`--skip-bad-rows`).
    pub skipped_rows: u64,
    /// Pixels left out by subsampling.
    pub subsampled: u64,
}

impl Dropped {
    pub fn total(&self) -> u64 {
        self.saturated
            + self.masked
            + self.below_horizon
            + self.invalid
            + self.skipped_rows
            + self.subsampled
    }
}

/// A measurement as samples: direction pairs with their values.
#[derive(Clone, Debug)]
pub struct Samples {
    /// The samples.
    pub samples: Vec<Sample>,
    /// 1 (grey) or 3 (RGB).
    pub channels: usize,
    /// The kind of data.
    pub kind: DataKind,
    /// The file they were loaded from.
    pub source: PathBuf,
    /// What loading dropped, and why.
    pub dropped: Dropped,
    /// First problem of each kind met when rows were skipped (for the report).
    pub skipped_examples: Vec<String>,
    /// Image captures: the images' size (width, height) in pixels, the texel grid of maps.
    pub image_size: Option<(usize, usize)>,
    /// The relative standard error (per channel) of the values' common scale, when the data
    /// state it (a calibrated capture's absolute radiometry): every albedo's standard error
    /// includes it, since scaling all values scales every albedo alike and nothing else.
    pub scale_rel_se: Option<[f64; 3]>,
}

impl Samples {
    /// The samples at `idx`, in that order, with these samples' description (kind, source,
    /// channels, ...); the other samples are not copied.
    pub fn subset(&self, idx: &[usize]) -> Self {
        Self {
            samples: idx.iter().map(|&i| self.samples[i].clone()).collect(),
            channels: self.channels,
            kind: self.kind.clone(),
            source: self.source.clone(),
            dropped: self.dropped.clone(),
            skipped_examples: self.skipped_examples.clone(),
            image_size: self.image_size,
            scale_rel_se: self.scale_rel_se,
        }
    }
}

/// The largest BRDF value a measured file (RGL `.bsdf`, MERL `.binary`) may give, in 1/sr: a
/// measured mirror-like peak stays in the thousands (the MERL and RGL databases' largest are
/// below 10^4); beyond 10^6 the file is not a measurement.
pub const MAX_MEASURED_BRDF: f64 = 1e6;

/// Refuse a measured file whose drawn values are not physical: all zero (nothing reflected),
/// or any beyond [`MAX_MEASURED_BRDF`]; the error names the file and the direction pair.
pub fn check_measured_values(samples: &[Sample], path: &std::path::Path) -> anyhow::Result<()> {
    if let Some((k, s)) = samples
        .iter()
        .enumerate()
        .find(|(_, s)| s.value.iter().any(|v| v.abs() > MAX_MEASURED_BRDF))
    {
        anyhow::bail!(
            "{}: gives f = {:?} 1/sr at drawn direction pair {} (light theta {:.2}, view theta {:.2} degrees): a measured BRDF beyond {MAX_MEASURED_BRDF:e} 1/sr is not physical",
            path.display(),
            s.value,
            k + 1,
            s.l.z.clamp(-1.0, 1.0).acos().to_degrees(),
            s.v.z.clamp(-1.0, 1.0).acos().to_degrees()
        );
    }
    if samples.iter().all(|s| s.value.iter().all(|&v| v == 0.0)) {
        anyhow::bail!(
            "{}: every drawn value is zero ({} direction pairs): the file reflects nothing, so there is nothing to fit",
            path.display(),
            samples.len()
        );
    }
    Ok(())
}
