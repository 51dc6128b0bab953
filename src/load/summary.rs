//! What a data set holds, for `fibrefit inspect`: counts, value ranges, angle coverage, drops.
//! Counted sample by sample, so a capture is summarised from its compact store without making
//! every sample at once.

use super::capture_store::CaptureStore;
use super::samples::{DataKind, Dropped, Sample, Samples};
use super::{is_capture, load_data_with_format, LoadOptions};
use anyhow::Result;
use rayon::prelude::*;
use serde::Serialize;
use std::path::Path;

#[derive(Clone, Debug, Serialize)]
pub struct Summary {
    pub source: String,
    pub kind: &'static str,
    pub samples: usize,
    pub channels: usize,
    /// Per channel: (min, max) BRDF, 1/sr.
    pub brdf_range: Vec<(f64, f64)>,
    pub has_sigma: bool,
    pub has_topology_map: bool,
    pub has_tangent: bool,
    /// Counts in 10-degree bins of theta (0-10, ..., 80-90).
    pub theta_light_hist: [u64; 9],
    pub theta_view_hist: [u64; 9],
    /// Counts in 30-degree bins of phi (0-30, ..., 330-360).
    pub phi_light_hist: [u64; 12],
    pub phi_view_hist: [u64; 12],
    pub dropped: Dropped,
    pub skipped_examples: Vec<String>,
    /// Goniometric CSV: the delimiter and columns its header gave (and any mapped).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub format: Option<String>,
    /// Goniometric CSV: the delimiter sniffed from the header (comma, tab, semicolon, whitespace).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub delimiter: Option<&'static str>,
    /// Measured-BRDF files: how far the file is from reciprocal at the drawn pairs.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub reciprocity: Option<Reciprocity>,
}

/// A measured file evaluated both ways, f(l, v) and f(v, l), at the drawn direction pairs whose
/// light and view both lie within its measured incidence. A material is reciprocal; a
/// measurement need not be (its light and view responses differ, its incidence slices are
/// measured one by one), and a model's log error on a pair and its swap is then at least half
/// their log ratio.
#[derive(Clone, Debug, Serialize)]
pub struct Reciprocity {
    /// Pairs evaluated both ways (both values positive).
    pub pairs: usize,
    /// Per channel, RMS over the pairs of ln f(l, v) - ln f(v, l).
    pub rms_log_ratio: Vec<f64>,
    /// The same over every channel.
    pub rms_log_ratio_all: f64,
    /// About the least RMS log error any reciprocal model (a material) can make on these pairs
    /// and their swaps: half of `rms_log_ratio_all`.
    pub least_log_error: f64,
}

/// Above this RMS log ratio a measured file is called not reciprocal (its own interpolation
/// and rounding stay far below it).
pub const RECIPROCAL_WITHIN: f64 = 0.01;

impl Reciprocity {
    /// `f` (a measured file; `None` outside its measured incidence) at `samples`' pairs, both
    /// ways; `None` with no pair measured both ways.
    pub fn of(f: &crate::model::BrdfFn, samples: &[Sample], channels: usize) -> Option<Self> {
        let ratios: Vec<[f64; 3]> = samples
            .par_iter()
            .filter_map(|s| {
                let (a, b) = (f(&s.l, &s.v)?, f(&s.v, &s.l)?);
                let ok = (0..channels).all(|c| a[c] > 0.0 && b[c] > 0.0);
                ok.then(|| std::array::from_fn(|c| (a[c] / b[c]).ln()))
            })
            .collect();
        if ratios.is_empty() {
            return None;
        }
        let n = ratios.len() as f64;
        let rms_log_ratio: Vec<f64> = (0..channels)
            .map(|c| (ratios.iter().map(|r| r[c] * r[c]).sum::<f64>() / n).sqrt())
            .collect();
        let all = (rms_log_ratio.iter().map(|x| x * x).sum::<f64>() / channels as f64).sqrt();
        Some(Self {
            pairs: ratios.len(),
            rms_log_ratio,
            rms_log_ratio_all: all,
            least_log_error: all / 2.0,
        })
    }
}

/// The counts and ranges of [`Summary`], samples added one at a time.
#[derive(Clone, Debug)]
struct Tally {
    samples: usize,
    brdf_range: Vec<(f64, f64)>,
    has_sigma: bool,
    has_topology_map: bool,
    has_tangent: bool,
    theta: ([u64; 9], [u64; 9]),
    phi: ([u64; 12], [u64; 12]),
}

impl Tally {
    fn new(channels: usize) -> Self {
        Self {
            samples: 0,
            brdf_range: vec![(f64::INFINITY, f64::NEG_INFINITY); channels],
            has_sigma: false,
            has_topology_map: false,
            has_tangent: false,
            theta: ([0; 9], [0; 9]),
            phi: ([0; 12], [0; 12]),
        }
    }

    fn add(&mut self, smp: &Sample) {
        let theta_bin = |z: f64| ((z.clamp(-1.0, 1.0).acos().to_degrees() / 10.0) as usize).min(8);
        let phi_bin =
            |x: f64, y: f64| ((y.atan2(x).to_degrees().rem_euclid(360.0) / 30.0) as usize).min(11);
        self.samples += 1;
        for (c, r) in self.brdf_range.iter_mut().enumerate() {
            r.0 = r.0.min(smp.value[c]);
            r.1 = r.1.max(smp.value[c]);
        }
        self.theta.0[theta_bin(smp.l.z)] += 1;
        self.theta.1[theta_bin(smp.v.z)] += 1;
        self.phi.0[phi_bin(smp.l.x, smp.l.y)] += 1;
        self.phi.1[phi_bin(smp.v.x, smp.v.y)] += 1;
        self.has_sigma |= smp.sigma.is_some();
        self.has_topology_map |= smp.map_value.is_some() || smp.texel_height.is_some();
        self.has_tangent |= smp.fibre_azimuth.is_some();
    }

    /// Both tallies in one (counts add, ranges widen: the order does not matter).
    fn merge(mut self, other: Tally) -> Tally {
        self.samples += other.samples;
        for (a, b) in self.brdf_range.iter_mut().zip(&other.brdf_range) {
            a.0 = a.0.min(b.0);
            a.1 = a.1.max(b.1);
        }
        self.has_sigma |= other.has_sigma;
        self.has_topology_map |= other.has_topology_map;
        self.has_tangent |= other.has_tangent;
        let add = |a: &mut [u64], b: &[u64]| a.iter_mut().zip(b).for_each(|(x, y)| *x += y);
        add(&mut self.theta.0, &other.theta.0);
        add(&mut self.theta.1, &other.theta.1);
        add(&mut self.phi.0, &other.phi.0);
        add(&mut self.phi.1, &other.phi.1);
        self
    }

    fn summary(
        self,
        source: &Path,
        kind: DataKind,
        channels: usize,
        dropped: &Dropped,
        skipped_examples: &[String],
    ) -> Summary {
        Summary {
            source: source.display().to_string(),
            kind: match kind {
                DataKind::Gonio => "goniometric",
                DataKind::Capture => "image capture",
                DataKind::Measured => "measured BRDF file",
            },
            samples: self.samples,
            channels,
            brdf_range: self.brdf_range,
            has_sigma: self.has_sigma,
            has_topology_map: self.has_topology_map,
            has_tangent: self.has_tangent,
            theta_light_hist: self.theta.0,
            theta_view_hist: self.theta.1,
            phi_light_hist: self.phi.0,
            phi_view_hist: self.phi.1,
            dropped: dropped.clone(),
            skipped_examples: skipped_examples.to_vec(),
            format: None,
            delimiter: None,
            reciprocity: None,
        }
    }
}

/// The summary `inspect` prints of the data at `path`, loaded exactly as `fit` loads them: a
/// capture is read into the compact store and summarised pixel by pixel without making every
/// sample at once; other data are loaded whole (a goniometric CSV with what its header said).
pub fn summarise(path: &Path, opts: &LoadOptions) -> Result<Summary> {
    if is_capture(path) {
        return Ok(Summary::of_capture(&CaptureStore::load(
            path,
            opts.subsample,
        )?));
    }
    let (samples, format) = load_data_with_format(path, opts)?;
    let mut summary = Summary::of(&samples);
    if let Some(f) = format {
        summary.delimiter = Some(f.delimiter.name());
        summary.format = Some(f.describe());
    }
    if let Some(f) = super::measured_brdf(path)? {
        summary.reciprocity = Reciprocity::of(&f, &samples.samples, samples.channels);
    }
    Ok(summary)
}

impl Summary {
    pub fn of(s: &Samples) -> Self {
        let mut tally = Tally::new(s.channels);
        for smp in &s.samples {
            tally.add(smp);
        }
        tally.summary(
            &s.source,
            s.kind,
            s.channels,
            &s.dropped,
            &s.skipped_examples,
        )
    }

    /// The summary of a capture's every sample (those of [`CaptureStore::to_samples`]), made
    /// one at a time from the store, the images in parallel.
    pub fn of_capture(store: &CaptureStore) -> Self {
        let tally = (0..store.images())
            .into_par_iter()
            .map(|k| {
                let mut t = Tally::new(store.channels);
                for texel in 0..store.texels().len() {
                    if let Some(s) = store.sample(texel, k) {
                        t.add(&s);
                    }
                }
                t
            })
            .reduce(|| Tally::new(store.channels), Tally::merge);
        tally.summary(
            &store.source,
            DataKind::Capture,
            store.channels,
            &store.dropped,
            &[],
        )
    }

    /// A human-readable report.
    pub fn to_text(&self) -> String {
        let mut t = String::new();
        let ch = if self.channels == 1 {
            "grey".to_string()
        } else {
            "RGB".to_string()
        };
        t += &format!("{} ({})\n", self.source, self.kind);
        t += &format!("  samples          {}\n", self.samples);
        if let Some(f) = &self.format {
            t += &format!("  format           {f}\n");
        }
        t += &format!("  channels         {} ({ch})\n", self.channels);
        for (c, (lo, hi)) in self.brdf_range.iter().enumerate() {
            let name = if self.channels == 1 {
                String::new()
            } else {
                format!(" {}", ["r", "g", "b"][c])
            };
            t += &format!("  brdf{name:<2} [1/sr]    {lo:.6} .. {hi:.6}\n");
        }
        t += &format!(
            "  sigma given      {}\n  topology map     {}\n  per-sample tangent {}\n",
            yes(self.has_sigma),
            yes(self.has_topology_map),
            yes(self.has_tangent)
        );
        let hist = |name: &str, h: &[u64], step: usize| {
            let cells: Vec<String> = h
                .iter()
                .enumerate()
                .map(|(i, n)| format!("{}-{}:{n}", i * step, (i + 1) * step))
                .collect();
            format!("  {name:<16} {}\n", cells.join(" "))
        };
        t += "  angle coverage (degrees: count)\n";
        t += &hist("theta light", &self.theta_light_hist, 10);
        t += &hist("theta view", &self.theta_view_hist, 10);
        t += &hist("phi light", &self.phi_light_hist, 30);
        t += &hist("phi view", &self.phi_view_hist, 30);
        let d = &self.dropped;
        t += &format!(
            "  dropped          {} (saturated {}, masked/outside ROI {}, below horizon {}, non-finite {}, skipped rows {}, subsampled {})\n",
            d.total(),
            d.saturated,
            d.masked,
            d.below_horizon,
            d.invalid,
            d.skipped_rows,
            d.subsampled
        );
        for e in &self.skipped_examples {
            t += &format!("    skipped: {e}\n");
        }
        if let Some(r) = &self.reciprocity {
            let per: Vec<String> = r.rms_log_ratio.iter().map(|x| format!("{x:.4}")).collect();
            t += &format!(
                "  reciprocity      f(l, v) against f(v, l) at {} drawn pairs: RMS of the log ratio {} ({})\n",
                r.pairs,
                per.join(" / "),
                match r.rms_log_ratio_all > RECIPROCAL_WITHIN {
                    true => format!(
                        "not reciprocal: no material, a reciprocal BRDF, comes closer than about {:.4} RMS log error",
                        r.least_log_error
                    ),
                    false => "reciprocal".to_string(),
                }
            );
        }
        t
    }
}

fn yes(b: bool) -> &'static str {
    if b {
        "yes"
    } else {
        "no"
    }
}
