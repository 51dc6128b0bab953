//! Topology (MODEL.md §4): how high the odd fibres climb, per texel and per spot.
//!
//! Height H = d sin(phi) of the odd fibres' axes, H in [0, H_max], H_max = sqrt(d^2 - 1).
//! A topology map m(u, v) in [0, 1] perturbs a base height H0 per texel:
//! H = clamp(H0 + s (2m - 1), 0, H_max), s = `map_scale`. A goniometric spot sees the mean of the
//! model over the map's height distribution; without a map, H ~ uniform[H0 - s, H0 + s], clamped.

use std::path::PathBuf;
use std::sync::Arc;

/// Largest height of the climbing fibres' axes: sqrt(d^2 - 1) (sqrt(3) at d = 2).
pub fn max_height(spacing: f64) -> f64 {
    (spacing * spacing - 1.0).max(0.0).sqrt()
}

/// Largest elevation: acos(1/d) (60 degrees at d = 2), where the raised fibres touch.
pub fn max_elevation(spacing: f64) -> f64 {
    (1.0 / spacing).acos()
}

/// phi = asin(H / d), clamped into [0, acos(1/d)].
pub fn elevation_from_height(height: f64, spacing: f64) -> f64 {
    (height / spacing)
        .clamp(0.0, 1.0)
        .asin()
        .min(max_elevation(spacing))
}

/// H = d sin(phi).
pub fn height_from_elevation(elevation: f64, spacing: f64) -> f64 {
    spacing * elevation.sin()
}

/// The mathematical topology: shading value t in [0, 1] -> phi = t acos(1/d).
pub fn elevation_from_shading(t: f64, spacing: f64) -> f64 {
    t.clamp(0.0, 1.0) * max_elevation(spacing)
}

/// Seed 001's torus with touching fibres (d = 2) wound round the tube with a fixed count: the
/// width available per fibre relative to the outer side is w(u) = (R + r cos u)/(R + r); one layer
/// of climbing halves the width, so phi = acos(w 2^k) with k the number of completed layers.
/// `u` is the tube angle (0 on the outer side).
pub fn torus_elevation(u: f64, major_radius: f64, minor_radius: f64) -> f64 {
    let w = (major_radius + minor_radius * u.cos()) / (major_radius + minor_radius);
    let mut scaled = w;
    // k completed layers: the smallest k with w 2^k > 1/2
    while scaled <= 0.5 && scaled > 0.0 {
        scaled *= 2.0;
    }
    scaled.clamp(0.5, 1.0).acos()
}

/// A grayscale topology map, values in [0, 1], row-major from the top-left texel.
#[derive(Clone, Debug, PartialEq)]
pub struct TopologyMap {
    pub width: usize,
    pub height: usize,
    pub values: Vec<f32>,
    pub source: PathBuf,
}

impl TopologyMap {
    /// Texel value at integer coordinates (clamped to the edge).
    pub fn texel(&self, x: usize, y: usize) -> f64 {
        let x = x.min(self.width - 1);
        let y = y.min(self.height - 1);
        self.values[y * self.width + x] as f64
    }

    /// K-bin histogram over [0, 1]: (mean map value in the bin, fraction of texels), empty bins
    /// dropped. Using each bin's mean (not its centre) keeps the mean height exact.
    pub fn histogram(&self, bins: usize) -> Vec<(f64, f64)> {
        let k = bins.max(1);
        let mut sum = vec![0.0f64; k];
        let mut count = vec![0usize; k];
        for &v in &self.values {
            let i = ((v as f64 * k as f64) as usize).min(k - 1);
            sum[i] += v as f64;
            count[i] += 1;
        }
        let n = self.values.len() as f64;
        (0..k)
            .filter(|&i| count[i] > 0)
            .map(|i| (sum[i] / count[i] as f64, count[i] as f64 / n))
            .collect()
    }

    /// The exact distribution of distinct values when there are at most `cap` of them,
    /// otherwise a `cap`-bin histogram of bin means (second-order accurate).
    pub fn distinct_values(&self, cap: usize) -> Vec<(f64, f64)> {
        let mut sorted: Vec<f32> = self.values.clone();
        sorted.sort_unstable_by(f32::total_cmp);
        let mut out: Vec<(f64, f64)> = Vec::new();
        let n = sorted.len() as f64;
        for v in sorted {
            match out.last_mut() {
                Some(last) if last.0 == v as f64 => last.1 += 1.0 / n,
                _ => {
                    if out.len() == cap {
                        return self.histogram(cap);
                    }
                    out.push((v as f64, 1.0 / n));
                }
            }
        }
        out
    }
}

/// The topology parameters of a spot: base height H0, map scale s and an optional map.
#[derive(Clone, Debug, PartialEq)]
pub struct Topology {
    pub height: f64,
    pub map_scale: f64,
    pub map: Option<Arc<TopologyMap>>,
}

impl Topology {
    pub fn flat() -> Self {
        Self {
            height: 0.0,
            map_scale: 0.0,
            map: None,
        }
    }

    /// Per-texel height H = clamp(H0 + s (2m - 1), 0, H_max).
    pub fn texel_height(&self, m: f64, spacing: f64) -> f64 {
        (self.height + self.map_scale * (2.0 * m - 1.0)).clamp(0.0, max_height(spacing))
    }

    /// K-bin discretisation of the spot's height distribution: (height, weight) pairs, weights
    /// summing to one, equal heights merged (clamping piles mass on 0 and H_max).
    pub fn discretise(&self, spacing: f64, bins: usize) -> Vec<(f64, f64)> {
        let k = bins.max(1);
        let nodes: Vec<(f64, f64)> = match &self.map {
            Some(map) => map
                .histogram(k)
                .into_iter()
                .map(|(m, w)| (self.texel_height(m, spacing), w))
                .collect(),
            None if self.map_scale == 0.0 => vec![(self.texel_height(0.5, spacing), 1.0)],
            None => (0..k)
                .map(|i| {
                    (
                        self.texel_height((i as f64 + 0.5) / k as f64, spacing),
                        1.0 / k as f64,
                    )
                })
                .collect(),
        };
        merge_equal_heights(nodes)
    }

    /// The exact law the reference integrates.
    pub fn exact_law(&self, spacing: f64) -> HeightLaw {
        let h_max = max_height(spacing);
        match &self.map {
            Some(map) => HeightLaw::Discrete(merge_equal_heights(
                map.distinct_values(4096)
                    .into_iter()
                    .map(|(m, w)| (self.texel_height(m, spacing), w))
                    .collect(),
            )),
            None if self.map_scale == 0.0 => HeightLaw::Point(self.height.clamp(0.0, h_max)),
            None => HeightLaw::Uniform {
                lo: self.height - self.map_scale,
                hi: self.height + self.map_scale,
                h_max,
            },
        }
    }
}

fn merge_equal_heights(mut nodes: Vec<(f64, f64)>) -> Vec<(f64, f64)> {
    nodes.sort_unstable_by(|a, b| a.0.total_cmp(&b.0));
    let mut out: Vec<(f64, f64)> = Vec::with_capacity(nodes.len());
    for (h, w) in nodes {
        match out.last_mut() {
            Some(last) if last.0 == h => last.1 += w,
            _ => out.push((h, w)),
        }
    }
    out
}

/// A height distribution as the reference sees it.
#[derive(Clone, Debug, PartialEq)]
pub enum HeightLaw {
    Point(f64),
    /// H uniform on [lo, hi], then clamped to [0, h_max] (point masses at the ends).
    Uniform {
        lo: f64,
        hi: f64,
        h_max: f64,
    },
    Discrete(Vec<(f64, f64)>),
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn height_elevation_round_trip_and_limits() {
        let d: f64 = 2.0;
        assert!((max_height(d) - 3f64.sqrt()).abs() < 1e-15);
        assert!((max_elevation(d).to_degrees() - 60.0).abs() < 1e-12);
        for phi in [0.0, 0.3, 0.9, max_elevation(d)] {
            let h = height_from_elevation(phi, d);
            assert!((elevation_from_height(h, d) - phi).abs() < 1e-12);
        }
        // seed 001: H = 2 sin(theta), theta 0..60 deg, from shading value 0..1
        assert!(
            (height_from_elevation(elevation_from_shading(1.0, d), d) - 3f64.sqrt()).abs() < 1e-12
        );
        assert_eq!(elevation_from_shading(0.0, d), 0.0);
    }

    #[test]
    fn torus_climbs_twice_from_outer_to_inner_side() {
        // outer side four times the inner: (R + r)/(R - r) = 4 -> R = 5/3 r
        let (r_major, r_minor) = (5.0, 3.0);
        assert!(torus_elevation(0.0, r_major, r_minor).abs() < 1e-12); // flat outside
        let inner = torus_elevation(std::f64::consts::PI, r_major, r_minor);
        assert!(
            inner.abs() < 1e-7,
            "inner side flat again after two layers: {inner}"
        );
        // somewhere in between the fibres are climbing
        let mid = torus_elevation(1.2, r_major, r_minor);
        assert!(mid > 0.1 && mid <= 60f64.to_radians() + 1e-12);
    }

    #[test]
    fn uniform_discretisation_clamps_and_keeps_weights() {
        let t = Topology {
            height: 0.1,
            map_scale: 0.25,
            map: None,
        };
        let nodes = t.discretise(2.0, 8);
        let total: f64 = nodes.iter().map(|n| n.1).sum();
        assert!((total - 1.0).abs() < 1e-15);
        assert_eq!(nodes[0].0, 0.0);
        // [-0.15, 0.35]: bin centres below 0 are -0.11875, -0.05625 -> 2 of 8 clamped
        assert!((nodes[0].1 - 0.25).abs() < 1e-15);
    }

    #[test]
    fn map_histogram_preserves_the_mean() {
        let values: Vec<f32> = (0..1000)
            .map(|i| ((i * 37) % 1000) as f32 / 999.0)
            .collect();
        let map = TopologyMap {
            width: 100,
            height: 10,
            values: values.clone(),
            source: PathBuf::new(),
        };
        let mean: f64 = values.iter().map(|&v| v as f64).sum::<f64>() / 1000.0;
        for k in [1, 4, 16, 64] {
            let h = map.histogram(k);
            let m: f64 = h.iter().map(|(v, w)| v * w).sum();
            assert!((m - mean).abs() < 1e-12);
        }
    }
}
