//! Exposure brackets: several frames of one light and view, each with its own exposure, merged
//! into one linear image with a per-pixel noise estimate, as HDR merging in capture pipelines
//! does (inverse-variance weights, clipped and black frames left out).
//!
//! Frame j of a bracket holds linear values c_j (codes scaled to [0, 1], or float values) with
//! a factor f_j from value to radiance (the frame's `exposure`; the image's own `exposure`
//! multiplies every frame's). Its estimate of the pixel's value (in radiance / the image's
//! exposure) is c_j f_j. The sensor's noise is modelled per channel as
//!
//! ```text
//! var(c) = var0 + gain * c                    (read noise + shot noise, in value units)
//! ```
//!
//! and estimated from the bracket itself: for two frames a, b valid at a pixel (neither clipped
//! nor black, and under 95 % of the clip level, so that clipping does not truncate the noise),
//! d = c_a f_a - c_b f_b has E[d^2] = var0 (f_a^2 + f_b^2) + gain (f_a^2 c_a + f_b^2 c_b), a
//! linear model in (var0, gain) fitted by iteratively reweighted least squares over every pixel
//! of every pair of frames adjacent in exposure (weights 1 / E[d^2]^2: d^2 has variance
//! 2 E[d^2]^2). A capture pools the pairs of all its brackets (one camera; at most
//! [`MAX_NOISE_ROWS`] per bracket and channel) into one model, which gives every image's sigmas;
//! each bracket's own estimate (or, if its frames overlap too little, shot noise alone) only
//! weights its merge. The merged value is the inverse-variance weighted mean of the valid frames'
//! estimates, the variances evaluated at the merged value (twice, from the frames' own values
//! first), and its variance 1 / sum_j 1 / (f_j^2 var(v / f_j)): what the fit's sigmas are
//! (`ImageNoise::sigma`).

use super::image_io::LinearImage;
use anyhow::{bail, Result};

/// The fewest pixel pairs (per channel) from which a bracket's noise is estimated.
pub const MIN_NOISE_PAIRS: usize = 16;

/// Frames whose value lies above this fraction of their clip level are not used to estimate
/// the noise (clipping truncates it).
const NOISE_CLIP_FRACTION: f64 = 0.95;

/// The noise of one image's values.
#[derive(Clone, Debug, PartialEq)]
pub struct ImageNoise {
    /// The frames merged into the image: (factor relative to the image's exposure, the value at
    /// which the frame saturates), longest exposure (smallest factor) first. An image without a
    /// bracket has one frame with factor 1.
    pub frames: Vec<(f64, f32)>,
    /// Per channel, the variance of a frame's value at zero (read noise), in value units^2.
    pub var0: [f64; 3],
    /// Per channel, the variance per unit value (shot noise).
    pub gain: [f64; 3],
    /// Per channel, the (var0, gain) whose inverse variances weighted the frames when they were
    /// merged: the bracket's own estimate, or shot noise alone (0, 1). When the capture's
    /// pooled model differs, the merged value's variance is that of these weights under it.
    pub weights: [(f64, f64); 3],
    /// Pixel pairs (summed over channels) the model was estimated from: one bracket's, or in a
    /// loaded capture all its brackets' pooled; 0 for a bracket whose frames overlap too little
    /// to estimate alone (it was merged with shot-noise weights, var0 = 0, gain = 1).
    pub pairs: usize,
}

impl ImageNoise {
    /// The noise an image gives itself (`noise = { var0, gain }`), one frame saturating at
    /// `clip`.
    pub fn given(n: &super::capture::NoiseSpec, clip: f32) -> Self {
        Self {
            frames: vec![(1.0, clip)],
            var0: n.var0,
            gain: n.gain,
            weights: [(0.0, 1.0); 3],
            pairs: 0,
        }
    }

    /// The variance of one frame's value `c` in channel `ch`.
    fn variance(&self, ch: usize, c: f64) -> f64 {
        self.var0[ch] + self.gain[ch] * c.max(0.0)
    }

    /// The standard deviations of a merged pixel's values `px` (one per channel): the frames
    /// in which no channel reached 95 % of the clip level, combined by their inverse variances
    /// (as `merge` combined them).
    pub fn sigmas(&self, px: &[f32]) -> [f64; 3] {
        let mut out = [0.0; 3];
        let unclipped = |f: f64, clip: f32| {
            px.iter()
                .all(|&v| (v as f64 / f) < NOISE_CLIP_FRACTION * clip as f64)
        };
        for (ch, o) in out.iter_mut().enumerate().take(px.len()) {
            let v = px[ch] as f64;
            // var(sum w_j x_j / sum w_j) = sum w_j^2 var_j / (sum w_j)^2, w_j the merge's
            // weights (1 / var_j when they came from this model)
            let (wv, wg) = self.weights[ch];
            let (mut sw, mut sw2v) = (0.0, 0.0);
            for &(f, clip) in &self.frames {
                if unclipped(f, clip) {
                    let c = (v / f).max(0.0);
                    let var = f * f * self.variance(ch, c);
                    let w = if self.frames.len() == 1 {
                        1.0
                    } else {
                        1.0 / (f * f * (wv + wg * c)).max(1e-300)
                    };
                    sw += w;
                    sw2v += w * w * var;
                }
            }
            *o = if sw > 0.0 {
                sw2v.sqrt() / sw
            } else {
                // clipped in every frame (such pixels are dropped as saturated): the shortest
                // exposure's
                let &(f, _) = self.frames.last().expect("an image has a frame");
                f * self.variance(ch, v / f).sqrt()
            };
        }
        out
    }
}

/// The pixel pairs of one bracket from which the noise is estimated: per channel, rows
/// (A, B, d^2, r_a, r_b, f_a, f_b, clip_a, clip_b) with E[d^2] = var0 A + gain B (r = c f, the
/// frames' estimates), at most [`MAX_NOISE_ROWS`] per channel (every k-th pixel).
#[derive(Clone, Debug, Default)]
pub struct NoiseRows(pub Vec<Vec<[f64; 9]>>);

/// The most pixel pairs per channel a bracket keeps for the capture's noise estimate.
pub const MAX_NOISE_ROWS: usize = 50_000;

/// Merge a bracket's `frames` (each with its factor; same size and channels, checked by the
/// caller) into one image, its noise model (estimated from this bracket alone, or, when its
/// frames overlap too little, shot noise only: `pairs` 0) and the pixel pairs the capture's
/// estimate pools.
pub fn merge(frames: &[(LinearImage, f64)]) -> Result<(LinearImage, ImageNoise, NoiseRows)> {
    let mut order: Vec<usize> = (0..frames.len()).collect();
    order.sort_by(|&a, &b| frames[a].1.total_cmp(&frames[b].1));
    for w in order.windows(2) {
        if frames[w[0]].1 == frames[w[1]].1 {
            bail!(
                "two frames have the same exposure {}; a bracket's frames differ in exposure",
                frames[w[0]].1
            );
        }
    }
    let first = &frames[0].0;
    let (n, ch) = (first.width * first.height, first.channels);
    let mut noise = ImageNoise {
        frames: order
            .iter()
            .map(|&j| (frames[j].1, frames[j].0.clip))
            .collect(),
        var0: [0.0; 3],
        gain: [1.0; 3],
        weights: [(0.0, 1.0); 3],
        pairs: 0,
    };
    let rows = NoiseRows((0..ch).map(|c| noise_rows(frames, &order, c)).collect());
    let own: Option<Vec<(f64, f64, usize)>> = rows.0.iter().map(|r| fit_noise(r)).collect();
    if let Some(own) = own {
        for (c, (var0, gain, pairs)) in own.into_iter().enumerate() {
            noise.var0[c] = var0;
            noise.gain[c] = gain;
            noise.pairs += pairs;
        }
    }
    for c in ch..3 {
        noise.var0[c] = noise.var0[ch - 1];
        noise.gain[c] = noise.gain[ch - 1];
    }
    for c in 0..3 {
        noise.weights[c] = (noise.var0[c], noise.gain[c]);
    }
    let mut data = vec![0.0f32; n * ch];
    let mut saturated = vec![false; n];
    for p in 0..n {
        // the frames under 95 % of their clip level in every channel (near the clip level,
        // clipping truncates the noise, so a frame's value there is biased low)
        let unclipped: Vec<usize> = order
            .iter()
            .copied()
            .filter(|&j| {
                let img = &frames[j].0;
                !img.saturated[p]
                    && (0..ch).all(|c| {
                        (img.data[p * ch + c] as f64) < NOISE_CLIP_FRACTION * img.clip as f64
                    })
            })
            .collect();
        if unclipped.is_empty() {
            saturated[p] = true;
            let (img, f) = &frames[*order.last().unwrap()];
            for c in 0..ch {
                data[p * ch + c] = (img.data[p * ch + c] as f64 * f) as f32;
            }
            continue;
        }
        for c in 0..ch {
            let valid: Vec<(f64, f64)> = unclipped
                .iter()
                .filter(|&&j| frames[j].0.data[p * ch + c] > 0.0)
                .map(|&j| (frames[j].0.data[p * ch + c] as f64, frames[j].1))
                .collect();
            if valid.is_empty() {
                // black in every unclipped frame: the longest of them reads 0
                let j = unclipped[0];
                data[p * ch + c] = (frames[j].0.data[p * ch + c] as f64 * frames[j].1) as f32;
                continue;
            }
            // weights from the frames' own values, then from the merged value
            let mean = |at: &dyn Fn(f64, f64) -> f64| -> f64 {
                let (mut sw, mut swx) = (0.0, 0.0);
                for &(cv, f) in &valid {
                    let w = 1.0 / (f * f * noise.variance(c, at(cv, f)));
                    sw += w;
                    swx += w * cv * f;
                }
                swx / sw
            };
            let v0 = mean(&|cv, _| cv);
            let v1 = mean(&|_, f| v0 / f);
            data[p * ch + c] = mean(&|_, f| v1 / f) as f32;
        }
    }
    Ok((
        LinearImage {
            width: first.width,
            height: first.height,
            channels: ch,
            data,
            saturated,
            clip: f32::INFINITY,
        },
        noise,
        rows,
    ))
}

/// (var0, gain, pairs) of channel `c` from the differences of frames adjacent in exposure.
fn noise_rows(frames: &[(LinearImage, f64)], order: &[usize], c: usize) -> Vec<[f64; 9]> {
    let mut rows: Vec<[f64; 9]> = Vec::new();
    let n = frames[0].0.width * frames[0].0.height;
    let stride = (n * (order.len() - 1)).div_ceil(MAX_NOISE_ROWS).max(1);
    let mut seen = 0usize;
    for w in order.windows(2) {
        let ((a, fa), (b, fb)) = (&frames[w[0]], &frames[w[1]]);
        let ch = a.channels;
        for p in 0..n {
            if a.saturated[p] || b.saturated[p] {
                continue;
            }
            let (ca, cb) = (a.data[p * ch + c] as f64, b.data[p * ch + c] as f64);
            if !(ca > 0.0 && cb > 0.0) {
                continue;
            }
            seen += 1;
            if seen % stride != 0 {
                continue;
            }
            let d = ca * fa - cb * fb;
            rows.push([
                fa * fa + fb * fb,
                fa * fa * ca + fb * fb * cb,
                d * d,
                ca * fa,
                cb * fb,
                *fa,
                *fb,
                a.clip as f64,
                b.clip as f64,
            ]);
        }
    }
    rows
}

/// The least-squares (var0, gain) of `y = var0 a + gain b` from its normal equations
/// (`[sum a^2, sum a b, sum b^2]`, `[sum a y, sum b y]`, weighted), both kept >= 0: they are
/// variances, so a negative one is refitted at 0 with the other alone. A singular system
/// (every b in proportion to a) gives var0 alone.
pub(crate) fn nonnegative_pair([aa, ab, bb]: [f64; 3], [ay, by]: [f64; 2]) -> (f64, f64) {
    let det = aa * bb - ab * ab;
    let (mut var0, mut gain) = if det > 1e-12 * aa * bb {
        ((ay * bb - by * ab) / det, (aa * by - ab * ay) / det)
    } else {
        (ay / aa, 0.0)
    };
    if gain < 0.0 {
        gain = 0.0;
        var0 = ay / aa;
    }
    if var0 < 0.0 {
        var0 = 0.0;
        gain = if bb > 0.0 { by / bb } else { 0.0 };
    }
    (var0, gain)
}

/// (var0, gain, pairs used) fitted to `rows` (of one channel, from one bracket or pooled);
/// `None` when fewer than [`MIN_NOISE_PAIRS`] pairs qualify or they cannot tell read noise
/// from shot noise (every pair at nearly one value).
pub fn fit_noise(rows: &[[f64; 9]]) -> Option<(f64, f64, usize)> {
    // A pair enters where its value lies 3 standard deviations above 0 in both frames (codes
    // are clamped at 0, which truncates the noise) and under 95 % of both clip levels. The value
    // tested is the pair's inverse-variance weighted mean, which is uncorrelated with the
    // difference d, so the selection does not bias d^2 (selecting on either frame's own value
    // would).
    let keep = |r: &[f64; 9], v: f64, g: f64| -> bool {
        let var = |c: f64| (v + g * c.max(0.0)).max(1e-300);
        let (fa, fb) = (r[5], r[6]);
        let (wa, wb) = (
            1.0 / (fa * fa * var(r[3] / fa)),
            1.0 / (fb * fb * var(r[4] / fb)),
        );
        let m = (wa * r[3] + wb * r[4]) / (wa + wb);
        let (ca, cb) = (m / fa, m / fb);
        ca < NOISE_CLIP_FRACTION * r[7]
            && cb < NOISE_CLIP_FRACTION * r[8]
            && ca * ca > 9.0 * var(ca)
            && cb * cb > 9.0 * var(cb)
    };
    let solve = |weight: &dyn Fn(&[f64; 9]) -> f64, (v, g): (f64, f64)| -> (f64, f64, usize) {
        let (mut aa, mut ab, mut bb, mut ay, mut by) = (0.0, 0.0, 0.0, 0.0, 0.0);
        let mut used = 0;
        for r in rows.iter().filter(|r| keep(r, v, g)) {
            used += 1;
            let w = weight(r);
            aa += w * r[0] * r[0];
            ab += w * r[0] * r[1];
            bb += w * r[1] * r[1];
            ay += w * r[0] * r[2];
            by += w * r[1] * r[2];
        }
        if used == 0 {
            return (0.0, 0.0, 0);
        }
        let (var0, gain) = nonnegative_pair([aa, ab, bb], [ay, by]);
        (var0, gain, used)
    };
    let scale = rows.iter().map(|r| r[2]).sum::<f64>() / rows.len().max(1) as f64;
    // first pass: shot noise only (weights from the frames' values), then reweighted
    let (mut var0, mut gain, mut used) = solve(&|r| 1.0 / (r[0] + r[1]).powi(2), (0.0, 1e-12));
    for _ in 0..6 {
        let (v, g) = (var0, gain);
        (var0, gain, used) = solve(
            &|r| {
                let e = (v * r[0] + g * r[1]).max(1e-6 * scale).max(1e-300);
                1.0 / (e * e)
            },
            (v, g),
        );
    }
    if used < MIN_NOISE_PAIRS {
        return None;
    }
    // the values must spread for var0 and gain to separate: B / A (the pairs' mean value)
    // over at least a factor 2 between its 10th and 90th percentiles
    let mut level: Vec<f64> = rows
        .iter()
        .filter(|r| keep(r, var0, gain))
        .map(|r| r[1] / r[0])
        .collect();
    level.sort_by(f64::total_cmp);
    let (lo, hi) = (level[level.len() / 10], level[level.len() * 9 / 10]);
    if !(hi > 2.0 * lo) {
        return None;
    }
    // a noiseless bracket (synthetic frames) would give 0: floor it at the 16-bit code's
    // quantisation, (1/65535)^2 / 12, so that weights and sigmas stay finite
    let floor = (1.0 / 65535.0f64).powi(2) / 12.0;
    Some((var0.max(floor), gain, used))
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_distr::{Distribution, Normal};

    /// A bracket of `factors` of a ramp of radiances, with noise var0 + gain c per frame value,
    /// quantised to 16 bits and clipped at 1.
    fn bracket(
        factors: &[f64],
        var0: f64,
        gain: f64,
        seed: u64,
    ) -> (Vec<(LinearImage, f64)>, Vec<f64>) {
        let n = 4000;
        let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
        let truth: Vec<f64> = (0..n).map(|i| 0.002 * 1.003f64.powi(i as i32)).collect();
        let frames = factors
            .iter()
            .map(|&f| {
                let mut data = Vec::new();
                let mut saturated = Vec::new();
                for &r in &truth {
                    let c = r / f;
                    let noisy = c + Normal::new(0.0, (var0 + gain * c).sqrt())
                        .unwrap()
                        .sample(&mut rng);
                    let code = (noisy.clamp(0.0, 1.0) * 65535.0).round();
                    saturated.push(code >= 65535.0);
                    data.push((code / 65535.0) as f32);
                }
                (
                    LinearImage {
                        width: n,
                        height: 1,
                        channels: 1,
                        data,
                        saturated,
                        clip: 1.0,
                    },
                    f,
                )
            })
            .collect();
        (frames, truth)
    }

    #[test]
    fn the_noise_model_is_recovered_from_the_bracket() {
        let (var0, gain) = (4e-6, 2e-4);
        let (frames, truth) = bracket(&[1.0, 4.0, 16.0], var0, gain, 1);
        let (img, noise, _) = merge(&frames).unwrap();
        assert!((noise.var0[0] / var0 - 1.0).abs() < 0.2, "{noise:?}");
        assert!((noise.gain[0] / gain - 1.0).abs() < 0.1, "{noise:?}");
        // every pixel of the ramp (0.002 .. 320 over the 3 frames' clip levels 1, 4, 16) well
        // below the shortest frame's clip level is merged (within 5 % of it, it is saturated); the standardised errors have unit variance
        // (above 0.01, where no frame clamps noise at 0)
        let mut z2 = 0.0;
        for (p, &r) in truth.iter().enumerate() {
            let v = img.data[p] as f64;
            if r < 16.0 * 0.9 {
                assert!(!img.saturated[p]);
            }
            if r > 0.01 && r < 16.0 * 0.9 {
                let z = (v - r) / noise.sigmas(&[v as f32])[0];
                z2 += z * z;
            }
        }
        let m = truth
            .iter()
            .filter(|&&r| r > 0.01 && r < 16.0 * 0.9)
            .count() as f64;
        assert!((z2 / m - 1.0).abs() < 0.1, "mean z^2 = {}", z2 / m);
        // above the shortest frame's clip level the pixel is saturated
        assert!(img.saturated[truth.iter().position(|&r| r > 16.5).unwrap()]);
    }

    #[test]
    fn the_merge_beats_every_single_frame() {
        let (frames, truth) = bracket(&[1.0, 4.0, 16.0], 4e-6, 2e-4, 2);
        let (img, noise, _) = merge(&frames).unwrap();
        // at a radiance every frame resolves, the merged sigma is below each frame's own
        let v = 0.5;
        let single: Vec<f64> = noise
            .frames
            .iter()
            .map(|&(f, _)| f * noise.variance(0, v / f).sqrt())
            .collect();
        assert!(
            single.iter().all(|&s| noise.sigmas(&[v as f32])[0] < s),
            "{single:?}"
        );
        // and the merged values follow the truth without bias in every decade
        for decade in [0.01, 0.1, 1.0, 10.0] {
            let (mut sum, mut n) = (0.0, 0.0);
            for (p, &r) in truth.iter().enumerate() {
                if r > decade && r < 1.4 * decade {
                    sum += (img.data[p] as f64 - r) / noise.sigmas(&[r as f32])[0];
                    n += 1.0;
                }
            }
            assert!(
                (sum / n).abs() < 4.0 / n.sqrt(),
                "decade {decade}: mean z {}",
                sum / n
            );
        }
    }

    #[test]
    fn a_repeated_exposure_is_refused_and_a_bracket_without_overlap_estimates_nothing() {
        let (frames, _) = bracket(&[1.0, 1.0], 1e-6, 1e-4, 3);
        assert!(merge(&frames)
            .unwrap_err()
            .to_string()
            .contains("same exposure"));
        // a frame 1e8 times shorter shares no unclipped, non-black pixels with the first: the
        // bracket merges (shot-noise weights) but estimates no noise of its own
        let (frames, _) = bracket(&[1e-4, 1e4], 1e-12, 0.0, 4);
        let (_, noise, rows) = merge(&frames).unwrap();
        assert_eq!(noise.pairs, 0);
        assert!(fit_noise(&rows.0[0]).is_none());
    }
}
