//! What a data set holds, for `fibrefit inspect`: counts, value ranges, angle coverage, drops.

use super::samples::{DataKind, Dropped, Samples};
use serde::Serialize;

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

impl Summary {
    pub fn of(s: &Samples) -> Self {
        let mut brdf_range = vec![(f64::INFINITY, f64::NEG_INFINITY); s.channels];
        let mut th = ([0u64; 9], [0u64; 9]);
        let mut ph = ([0u64; 12], [0u64; 12]);
        let theta_bin = |z: f64| ((z.clamp(-1.0, 1.0).acos().to_degrees() / 10.0) as usize).min(8);
        let phi_bin =
            |x: f64, y: f64| ((y.atan2(x).to_degrees().rem_euclid(360.0) / 30.0) as usize).min(11);
        for smp in &s.samples {
            for (c, r) in brdf_range.iter_mut().enumerate() {
                r.0 = r.0.min(smp.value[c]);
                r.1 = r.1.max(smp.value[c]);
            }
            th.0[theta_bin(smp.l.z)] += 1;
            th.1[theta_bin(smp.v.z)] += 1;
            ph.0[phi_bin(smp.l.x, smp.l.y)] += 1;
            ph.1[phi_bin(smp.v.x, smp.v.y)] += 1;
        }
        Summary {
            source: s.source.display().to_string(),
            kind: match s.kind {
                DataKind::Gonio => "goniometric",
                DataKind::Capture => "image capture",
                DataKind::Measured => "measured BRDF file",
            },
            samples: s.samples.len(),
            channels: s.channels,
            brdf_range,
            has_sigma: s.samples.iter().any(|x| x.sigma.is_some()),
            has_topology_map: s
                .samples
                .iter()
                .any(|x| x.map_value.is_some() || x.texel_height.is_some()),
            has_tangent: s.samples.iter().any(|x| x.fibre_azimuth.is_some()),
            theta_light_hist: th.0,
            theta_view_hist: th.1,
            phi_light_hist: ph.0,
            phi_view_hist: ph.1,
            dropped: s.dropped.clone(),
            skipped_examples: s.skipped_examples.clone(),
            format: None,
            delimiter: None,
        }
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
