//! Basins of the cost: points the polishing reached, and when two of them are one (a distance
//! as a fraction of the parameter box). Shared by the global stage and the polishing.

use nalgebra::DVector;

/// A basin found on the subsample: its polished point and cost there.
#[derive(Clone, Debug)]
pub struct Basin {
    pub theta: DVector<f64>,
    pub cost: f64,
}

/// Polished points closer than this are one basin.
pub const BASIN_SEPARATION: f64 = 0.02;

/// Distance between two points as a fraction of the box, RMS over the coordinates; periodic
/// coordinates (the azimuth) take the shorter way round.
pub fn box_distance(
    a: &DVector<f64>,
    b: &DVector<f64>,
    lo: &DVector<f64>,
    hi: &DVector<f64>,
    periods: &[Option<f64>],
) -> f64 {
    let n = a.len().max(1) as f64;
    let sum: f64 = (0..a.len())
        .map(|i| {
            let mut d = (a[i] - b[i]).abs();
            if let Some(p) = periods[i] {
                d = d.rem_euclid(p);
                d = d.min(p - d);
            }
            (d / (hi[i] - lo[i]).max(1e-12)).powi(2)
        })
        .sum();
    (sum / n).sqrt()
}
