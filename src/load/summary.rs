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
