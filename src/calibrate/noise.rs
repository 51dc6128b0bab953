//! The camera's noise, estimated from the photos themselves: Poissonian-Gaussian, a linear
//! value v has variance `var0 + gain x v` per channel (read noise and shot noise; Foi et al.
//! 2008, "Practical Poissonian-Gaussian noise modeling and fitting for single-image raw-data",
//! IEEE TIP 17(10)), as brackets estimate it for image captures.
//!
//! The printed board around the window is flat: paper, the grey patch, black ink and the table
//! beyond, lit more or less by the flash, at every exposure: levels from dark to bright. Each
//! photo is sampled there as rectifying samples the window (bilinear, at the texel spacing), so
//! the variance found is that of a rectified texel. The samples are cut into blocks of 5 x 5;
//! a block's residual variance about a fitted plane (22 degrees of freedom) estimates the
//! variance at its mean. Blocks over printed edges vary far more than noise: a first model from
//! the lower fifth of each level band (scaled by that quantile of the chi-square) keeps the
//! blocks within 2.5 times it, and the model is refitted to those, weighted by their expected
//! variance, until it settles.

use super::Calibration;
use crate::load::board::BoardFile;
use crate::load::photo::Photo;
use nalgebra::Vector3;

/// Samples on a block's side.
const SIDE: usize = 5;
/// Degrees of freedom of a block's residual variance about its plane.
const DOF: f64 = (SIDE * SIDE - 3) as f64;
/// Blocks whose variance exceeds this multiple of the model hold more than noise.
const KEEP_BELOW: f64 = 2.5;
/// A block is clipped when a pixel it blends reaches this (linear).
const CLIPPED: f32 = 0.98;
/// Millimetres kept clear around the window (the swatch may overhang it).
const WINDOW_MARGIN_MM: f64 = 3.0;
/// Fewest blocks a channel's model needs.
pub const MIN_BLOCKS: usize = 50;

/// The camera's noise model, per channel, in a photo's linear value units.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CameraNoise {
    /// The variance at value 0 (read noise).
    pub var0: [f64; 3],
    /// The variance per unit value (shot noise).
    pub gain: [f64; 3],
    /// Flat blocks the model rests on (per channel, the fewest).
    pub blocks: usize,
}

impl CameraNoise {
    /// The standard deviation of a value `v` in channel `c`.
    pub fn sigma(&self, c: usize, v: f64) -> f64 {
        (self.var0[c] + self.gain[c] * v.max(0.0)).sqrt()
    }
}

/// The flat blocks of every photo so far: per channel, (mean, residual variance).
#[derive(Default)]
pub struct FlatBlocks {
    blocks: [Vec<(f64, f64)>; 3],
}

impl FlatBlocks {
    /// Add photo `k`'s blocks: the board's paper outside the window, sampled every `step_mm`
    /// (the rectified texels' spacing) as [`super::rectify`] samples the window.
    pub fn add(
        &mut self,
        board: &BoardFile,
        cal: &Calibration,
        k: usize,
        photo: &Photo,
        step_mm: [f64; 2],
    ) {
        let [px0, py0, px1, py1] = board.paper_mm;
        let w = board.window_mm;
        let near_window = |x: f64, y: f64| {
            x > w[0] - WINDOW_MARGIN_MM
                && x < w[2] + WINDOW_MARGIN_MM
                && y > w[1] - WINDOW_MARGIN_MM
                && y < w[3] + WINDOW_MARGIN_MM
        };
        let pose = &cal.poses[k];
        let (bw, bh) = (step_mm[0] * SIDE as f64, step_mm[1] * SIDE as f64);
        let (nx, ny) = (
            ((px1 - px0) / bw).floor() as usize,
            ((py1 - py0) / bh).floor() as usize,
        );
        let mut z = [[0.0f64; SIDE * SIDE]; 3];
        for by in 0..ny {
            for bx in 0..nx {
                let (x0, y0) = (px0 + bx as f64 * bw, py0 + by as f64 * bh);
                if near_window(x0, y0)
                    || near_window(x0 + bw, y0)
                    || near_window(x0, y0 + bh)
                    || near_window(x0 + bw, y0 + bh)
                    || (x0 < w[0] && x0 + bw > w[2]) && (y0 < w[3] && y0 + bh > w[1])
                {
                    continue;
                }
                let mut ok = true;
                for j in 0..SIDE {
                    for i in 0..SIDE {
                        let p = Vector3::new(
                            x0 + (i as f64 + 0.5) * step_mm[0],
                            y0 + (j as f64 + 0.5) * step_mm[1],
                            0.0,
                        );
                        let Some([u, v]) = cal.intrinsics.project(&pose.to_camera(&p)) else {
                            ok = false;
                            break;
                        };
                        match (photo.sample(u, v), photo.peak_near(u, v)) {
                            (Some(rgb), Some(peak)) if peak < CLIPPED => {
                                for c in 0..3 {
                                    z[c][j * SIDE + i] = rgb[c] as f64;
                                }
                            }
                            _ => {
                                ok = false;
                                break;
                            }
                        }
                    }
                    if !ok {
                        break;
                    }
                }
                if !ok {
                    continue;
                }
                for c in 0..3 {
                    self.blocks[c].push(plane_residual(&z[c]));
                }
            }
            if self.blocks[0].len() > 2_000_000 {
                break;
            }
        }
    }

    /// The model of every channel, or None when some channel has fewer than [`MIN_BLOCKS`]
    /// flat blocks or they cannot tell read noise from shot noise.
    pub fn fit(&self) -> Option<CameraNoise> {
        let mut out = CameraNoise {
            var0: [0.0; 3],
            gain: [0.0; 3],
            blocks: usize::MAX,
        };
        for c in 0..3 {
            let (v, g, used) = fit_channel(&self.blocks[c])?;
            out.var0[c] = v;
            out.gain[c] = g;
            out.blocks = out.blocks.min(used);
        }
        Some(out)
    }
}

/// (mean, residual variance about the least-squares plane) of a block of samples.
fn plane_residual(z: &[f64; SIDE * SIDE]) -> (f64, f64) {
    let h = (SIDE as f64 - 1.0) / 2.0;
    let (mut sz, mut sxz, mut syz, mut sxx) = (0.0, 0.0, 0.0, 0.0);
    for j in 0..SIDE {
        for i in 0..SIDE {
            let (x, y) = (i as f64 - h, j as f64 - h);
            let v = z[j * SIDE + i];
            sz += v;
            sxz += x * v;
            syz += y * v;
            sxx += x * x;
        }
    }
    let n = (SIDE * SIDE) as f64;
    // the grid is symmetric: sum x = sum y = sum xy = 0, sum y^2 = sum x^2
    let (a, b, c) = (sz / n, sxz / sxx, syz / sxx);
    let mut ss = 0.0;
    for j in 0..SIDE {
        for i in 0..SIDE {
            let (x, y) = (i as f64 - h, j as f64 - h);
            let r = z[j * SIDE + i] - a - b * x - c * y;
            ss += r * r;
        }
    }
    (a, ss / DOF)
}

/// The standard normal's 0.2-quantile.
const Z_FIFTH: f64 = -0.841_621_233_572_914_3;

/// The quantile of a chi-square with `k` degrees of freedom over `k` at the standard normal's
/// quantile `z` (Wilson-Hilferty).
fn chi2_quantile_ratio(z: f64, k: f64) -> f64 {
    let a = 2.0 / (9.0 * k);
    (1.0 - a + z * a.sqrt()).powi(3)
}

/// (var0, gain, blocks used) of one channel's blocks.
fn fit_channel(blocks: &[(f64, f64)]) -> Option<(f64, f64, usize)> {
    if blocks.len() < MIN_BLOCKS {
        return None;
    }
    // start: in each of up to 20 bands of level (equal counts), the lower fifth of the
    // variances, scaled to the mean of a chi-square
    let mut sorted: Vec<(f64, f64)> = blocks.to_vec();
    sorted.sort_by(|a, b| a.0.total_cmp(&b.0));
    let bands = (sorted.len() / 25).clamp(2, 20);
    let q = chi2_quantile_ratio(Z_FIFTH, DOF);
    let mut points = Vec::new();
    for band in sorted.chunks(sorted.len().div_ceil(bands)) {
        let mut v: Vec<f64> = band.iter().map(|b| b.1).collect();
        v.sort_by(f64::total_cmp);
        let m = band.iter().map(|b| b.0).sum::<f64>() / band.len() as f64;
        points.push((m, v[v.len() / 5] / q));
    }
    let (mut var0, mut gain) = weighted_line(&points, |_| 1.0)?;
    let mut used = 0;
    for _ in 0..8 {
        let model = |m: f64| (var0 + gain * m.max(0.0)).max(1e-30);
        let kept: Vec<(f64, f64)> = blocks
            .iter()
            .copied()
            .filter(|&(m, v)| v < KEEP_BELOW * model(m))
            .collect();
        used = kept.len();
        if used < MIN_BLOCKS {
            return None;
        }
        let (v, g) = weighted_line(&kept, |m| 1.0 / model(m).powi(2))?;
        let settled = (v - var0).abs() <= 1e-4 * v.max(1e-30) && (g - gain).abs() <= 1e-4 * g.max(1e-30);
        (var0, gain) = (v, g);
        if settled {
            break;
        }
    }
    // the kept blocks are those under KEEP_BELOW x the model: their mean is that much short of
    // the chi-square's
    let trunc = truncated_mean_ratio(KEEP_BELOW, DOF);
    Some((var0 / trunc, gain / trunc, used))
}

/// The mean of a chi-square with `k` degrees of freedom over `k`, kept below `t` (a ratio of
/// its mean), over its untruncated mean 1: by a fine sum over its density.
fn truncated_mean_ratio(t: f64, k: f64) -> f64 {
    // x = chi2 / k; density of x proportional to x^(k/2 - 1) exp(-k x / 2)
    let (mut num, mut den) = (0.0, 0.0);
    let n = 4000;
    for i in 0..n {
        let x = (i as f64 + 0.5) * t / n as f64;
        let d = ((k / 2.0 - 1.0) * x.ln() - k * x / 2.0).exp();
        num += x * d;
        den += d;
    }
    num / den
}

/// The line v = var0 + gain m through `points` (m, v), weighted, both coefficients >= 0
/// ([`crate::load::bracket::nonnegative_pair`]); None when nothing has weight.
fn weighted_line(points: &[(f64, f64)], weight: impl Fn(f64) -> f64) -> Option<(f64, f64)> {
    let (mut s, mut sm, mut smm, mut sv, mut smv) = (0.0, 0.0, 0.0, 0.0, 0.0);
    for &(m, v) in points {
        let w = weight(m);
        s += w;
        sm += w * m;
        smm += w * m * m;
        sv += w * v;
        smv += w * m * v;
    }
    if s <= 0.0 {
        return None;
    }
    let (var0, gain) = crate::load::bracket::nonnegative_pair([s, sm, smm], [sv, smv]);
    (var0 > 0.0 || gain > 0.0).then_some((var0, gain))
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_distr::{Distribution, Normal};

    /// Blocks of a flat field at many levels with known noise, a quarter of them over an edge:
    /// the model comes back within a few percent.
    #[test]
    fn recovers_a_known_model_despite_edges() {
        let (var0, gain) = (4e-6, 3e-5);
        let mut rng = rand::rngs::StdRng::seed_from_u64(7);
        let unit = Normal::new(0.0, 1.0).unwrap();
        let mut fb = FlatBlocks::default();
        for b in 0..6000 {
            let level = 0.01 + 0.8 * (b as f64 / 6000.0);
            let edge = b % 4 == 0;
            let mut z = [0.0; SIDE * SIDE];
            for (i, zi) in z.iter_mut().enumerate() {
                let truth = if edge && i % SIDE > 2 { level * 0.3 } else { level };
                *zi = truth + (var0 + gain * truth).sqrt() * unit.sample(&mut rng);
            }
            let r = plane_residual(&z);
            for c in 0..3 {
                fb.blocks[c].push(r);
            }
        }
        let n = fb.fit().unwrap();
        for c in 0..3 {
            assert!((n.var0[c] / var0 - 1.0).abs() < 0.15, "var0 {}", n.var0[c]);
            assert!((n.gain[c] / gain - 1.0).abs() < 0.05, "gain {}", n.gain[c]);
        }
    }

    #[test]
    fn truncated_chi_square_mean() {
        // nearly nothing of a chi-square with 22 degrees of freedom lies beyond 2.5x its mean
        let r = truncated_mean_ratio(2.5, 22.0);
        assert!(r < 1.0 && r > 0.999, "{r}");
        let r = truncated_mean_ratio(1.0, 22.0);
        assert!(r < 0.9, "{r}");
    }
}
