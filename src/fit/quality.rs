//! Is the fit the best the data allow, and does it fit within the noise? The `quality` block of
//! the result JSON and the report, and the warnings a user cannot miss.
//!
//! - Noise: with sigmas, the reduced chi-square against its expected spread sqrt(2 / (n - p));
//!   without, the noise is estimated from the data where they allow it (goniometric: repeated
//!   direction pairs, pooled variance; captures: second differences of the residuals between
//!   neighbouring pixels of one image, which share light and view, var(r[x-1] - 2 r[x] + r[x+1])
//!   = 6 sigma^2 for white noise, so smooth misfit does not count as noise) and compared with the
//!   residual variance; otherwise it says that no estimate is possible.
//! - Distinct minima: the other minima polished on all samples whose cost is within 4 residual
//!   variances of the best (a likelihood-ratio test at about 95 % for one parameter): the data do
//!   not decide between them.
//! - Residual structure: the mean weighted residual in bins of the half-vector angle theta_h and of
//!   the half vector's azimuth relative to the fibres (folded into [0, 90] deg: T and -T, and the
//!   mirror across T, are the same); a bin whose mean is more than 4 standard errors from zero is
//!   systematically off.

use crate::load::samples::{Origin, Sample};
use serde::Serialize;
use std::collections::BTreeMap;

/// Bins further than this many standard errors from zero are flagged.
pub const BIN_Z_LIMIT: f64 = 4.0;
/// A reduced chi-square further than this many expected spreads from 1 is flagged.
pub const CHI2_Z_LIMIT: f64 = 5.0;
/// Minima within this many residual variances of the best are not decided by the data.
pub const AMBIGUOUS_DELTA: f64 = 4.0;
/// Two free parameters whose correlation is this close to +-1 (computed with every free
/// parameter free, those at a bound too) are not separated by the data: one of them is held.
pub const DEGENERATE_CORRELATION: f64 = 0.995;

#[derive(Clone, Debug, Serialize)]
pub struct Quality {
    /// "fits within the noise", "does not fit within the noise", or "noise unknown"; for data
    /// without sigmas judged by the floor, "within 1.2x of what the data allow" or "misses
    /// structure the data hold: ..." (`fit::floor::judge`).
    pub verdict: String,
    pub noise: NoiseCheck,
    /// Distinct minima on all samples, best first (the first is the fit): the best and those
    /// within [`AMBIGUOUS_DELTA`] residual variances of it, the ones the data do not decide
    /// between.
    pub minima: Vec<MinimumOut>,
    /// Other distinct minima found, more than [`AMBIGUOUS_DELTA`] residual variances above the
    /// best (not listed: the data rule them out).
    pub minima_beyond: usize,
    /// True when another minimum's cost is within 4 residual variances of the best.
    pub ambiguous: bool,
    pub residual_bins: Vec<ResidualBin>,
    /// Pairs of parameters the data do not separate, most correlated first, and which of each
    /// pair is held ([`degeneracies`]).
    pub degeneracies: Vec<Degeneracy>,
    /// The free values the data do not determine (at a bound, held by a degeneracy, or along
    /// which the cost is flat), with the value used and why ([`crate::fit::determined`]).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub undetermined: Vec<crate::fit::determined::Undetermined>,
    pub warnings: Vec<String>,
    /// The model's held-out error against the floor, what the data themselves allow
    /// (`fit::floor`); it gives the verdict of data without sigmas.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub floor: Option<crate::fit::floor::FloorCheck>,
}

/// Two parameters the data do not separate: their correlation is within
/// 1 - [`DEGENERATE_CORRELATION`] of +-1 (with every free parameter free, also one at a bound,
/// whose role the other then takes: kd at 0 beside a broad specular lobe, say).
#[derive(Clone, Debug, Serialize)]
pub struct Degeneracy {
    pub a: String,
    pub b: String,
    /// Their correlation, every free parameter free.
    pub correlation: f64,
    /// The one held: at its bound (where it ended), or at its fitted value for the standard
    /// errors (the less determined of the two, relative to its range); the other's standard
    /// error is conditional on it.
    pub held: String,
    /// "at its bound" or "at its fitted value".
    pub held_at: String,
    pub note: String,
}

/// The pairs of free parameters (full-Jacobian columns named `names`) the data do not separate,
/// from `correlations` of the covariance with every column free: |r| >= [`DEGENERATE_CORRELATION`],
/// most correlated first. Of each pair one is held: one at a bound (`at_bound`) if either is,
/// else the one with the larger standard error relative to its range (`relative_se`, None: not
/// determined at all); a pair one of whose parameters is already held adds none. Returns the
/// pairs and the columns newly held at their fitted values (not at a bound).
pub fn degeneracies(
    names: &[String],
    correlations: &[(usize, usize, f64)],
    at_bound: &[bool],
    relative_se: &[Option<f64>],
) -> (Vec<Degeneracy>, Vec<usize>) {
    let mut pairs: Vec<&(usize, usize, f64)> = correlations
        .iter()
        .filter(|x| x.2.abs() >= DEGENERATE_CORRELATION)
        .collect();
    pairs.sort_by(|x, y| y.2.abs().total_cmp(&x.2.abs()));
    let mut held_cols: Vec<usize> = Vec::new();
    let mut out = Vec::new();
    for &&(a, b, r) in &pairs {
        let is_held = |k: usize| at_bound[k] || held_cols.contains(&k);
        let (held, at_bound_held) = if is_held(a) || is_held(b) {
            // already held (at a bound, or for a more correlated pair): the pair needs no other
            let k = if is_held(b) && !is_held(a) {
                b
            } else if is_held(a) && !is_held(b) {
                a
            } else if at_bound[b] {
                b
            } else {
                a
            };
            (k, at_bound[k])
        } else {
            let rel = |k: usize| relative_se[k].unwrap_or(f64::INFINITY);
            let k = if rel(b) > rel(a) { b } else { a };
            held_cols.push(k);
            (k, false)
        };
        let other = if held == a { b } else { a };
        let held_at = if at_bound_held {
            "at its bound"
        } else {
            "at its fitted value"
        };
        let note = format!(
            "the data do not separate `{}` and `{}` (correlation {r:+.4}{}): `{}` is held {held_at}{}",
            names[a],
            names[b],
            if at_bound[a] || at_bound[b] {
                ", with the one at its bound free"
            } else {
                ""
            },
            names[held],
            if at_bound_held {
                format!(", where `{}` takes its role", names[other])
            } else {
                format!(
                    " (no standard error; `{}`'s is conditional on it): give data that tell them apart, or fix one in the config",
                    names[other]
                )
            }
        );
        out.push(Degeneracy {
            a: names[a].clone(),
            b: names[b].clone(),
            correlation: r,
            held: names[held].clone(),
            held_at: held_at.into(),
            note,
        });
    }
    (out, held_cols)
}

#[derive(Clone, Debug, Serialize)]
pub struct NoiseCheck {
    /// "sigmas", "repeated directions", "neighbouring pixels" or "none".
    pub source: String,
    /// Residual variance over the noise variance (the reduced chi-square with sigmas).
    pub ratio: Option<f64>,
    /// Expected standard deviation of the ratio for a model that fits.
    pub expected_spread: Option<f64>,
    /// Estimated noise standard deviation, 1/sr (no sigmas), weighted like the residuals.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub noise_estimate: Option<f64>,
    /// Degrees of freedom behind the estimate.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub estimate_dof: Option<usize>,
    pub note: String,
}

#[derive(Clone, Debug, Serialize)]
pub struct MinimumOut {
    pub parameters: BTreeMap<String, f64>,
    pub cost: f64,
    /// (cost - best cost) / residual variance.
    pub delta: f64,
}

#[derive(Clone, Debug, Serialize)]
pub struct ResidualBin {
    /// "half-vector angle" or "half-vector azimuth from the fibres".
    pub axis: String,
    pub lo_deg: f64,
    pub hi_deg: f64,
    pub n: usize,
    /// Mean weighted residual (model - data), in units of the residual standard deviation.
    pub mean: f64,
    /// mean / its standard error.
    pub z: f64,
    pub flagged: bool,
}

/// Half-vector angle from N and azimuth from the fibres (folded into [0, 90]), degrees.
pub fn half_vector_angles(s: &Sample, psi: f64) -> Option<(f64, f64)> {
    let h = s.l + s.v;
    let norm = h.norm();
    if !(norm > 1e-12) {
        return None;
    }
    let h = h / norm;
    let theta = h.z.clamp(-1.0, 1.0).acos().to_degrees();
    let phi = h.y.atan2(h.x) - s.fibre_azimuth.unwrap_or(psi);
    let mut a = phi.to_degrees().rem_euclid(180.0);
    if a > 90.0 {
        a = 180.0 - a;
    }
    Some((theta, a))
}

/// Edges of the residual-structure bins: half-vector angle 0-90 deg in 10, azimuth from the
/// fibres 0-90 deg in 15.
const THETA_EDGES: [f64; 10] = [0.0, 10.0, 20.0, 30.0, 40.0, 50.0, 60.0, 70.0, 80.0, 90.0];
const AZIMUTH_EDGES: [f64; 7] = [0.0, 15.0, 30.0, 45.0, 60.0, 75.0, 90.0];

/// The bin of `x` among `edges` (lo <= x < hi; the last bin holds its upper edge too).
fn bin_of(edges: &[f64], x: f64) -> Option<usize> {
    let last = *edges.last().expect("edges");
    edges
        .windows(2)
        .position(|w| x >= w[0] && (x < w[1] || (w[1] == last && x <= w[1])))
}

/// Sums of the mean residual over channels per residual-structure bin (sum, count), added
/// sample by sample in the samples' order: data read a piece at a time give the very sums of
/// all of them at once.
#[derive(Clone, Debug, Default)]
pub struct BinSums {
    theta: [(f64, usize); 9],
    azimuth: [(f64, usize); 6],
}

impl BinSums {
    /// Add sample `s` with its weighted residuals (one per channel).
    pub fn add(&mut self, s: &Sample, psi: f64, residuals: &[f64]) {
        if let Some((t, a)) = half_vector_angles(s, psi) {
            let r = residuals.iter().sum::<f64>() / residuals.len() as f64;
            if let Some(k) = bin_of(&THETA_EDGES, t) {
                self.theta[k].0 += r;
                self.theta[k].1 += 1;
            }
            if let Some(k) = bin_of(&AZIMUTH_EDGES, a) {
                self.azimuth[k].0 += r;
                self.azimuth[k].1 += 1;
            }
        }
    }

    /// The bins with samples, in residual standard deviations `s_all`.
    fn bins(&self, s_all: f64) -> Vec<ResidualBin> {
        let mut out = bins("half-vector angle", &THETA_EDGES, &self.theta, s_all);
        out.extend(bins(
            "half-vector azimuth from the fibres",
            &AZIMUTH_EDGES,
            &self.azimuth,
            s_all,
        ));
        out
    }
}

fn bins(axis: &str, edges: &[f64], sums: &[(f64, usize)], s_all: f64) -> Vec<ResidualBin> {
    let mut out = Vec::new();
    for (w, &(sum, n)) in edges.windows(2).zip(sums) {
        if n == 0 {
            continue;
        }
        let mean = sum / n as f64 / s_all;
        let z = mean * (n as f64).sqrt();
        out.push(ResidualBin {
            axis: axis.into(),
            lo_deg: w[0],
            hi_deg: w[1],
            n,
            mean,
            z,
            flagged: n >= 10 && z.abs() > BIN_Z_LIMIT,
        });
    }
    out
}

/// Pooled noise variance of repeated direction pairs (same l and v to 1e-9), weighted like the
/// residuals, and its degrees of freedom.
fn repeats_variance(samples: &[&Sample], scale: &[[f64; 3]], ch: usize) -> Option<(f64, usize)> {
    repeats_estimate(repeats_sums(samples, scale, ch))
}

/// [`repeats_variance`] of pooled sums (sum of squares, degrees of freedom).
pub fn repeats_estimate((ss, dof): (f64, usize)) -> Option<(f64, usize)> {
    (dof >= 5).then(|| (ss / dof as f64, dof))
}

/// The pooled sums behind [`repeats_variance`]: sum of squared deviations from each repeated
/// pair's mean and degrees of freedom. Samples that can repeat each other (for a capture: one
/// texel's pixels in every image) must come in one call.
pub fn repeats_sums(samples: &[&Sample], scale: &[[f64; 3]], ch: usize) -> (f64, usize) {
    // pixels of a capture repeat a direction pair only at the same place on the swatch: two
    // texels seen from the same directions differ by their topology and fibre direction
    let key = |s: &Sample| {
        let q = |x: f64| (x * 1e9).round() as i64;
        let (x, y) = match s.origin {
            Origin::Pixel { x, y, .. } => (i64::from(x), i64::from(y)),
            Origin::Line(_) => (-1, -1),
        };
        [
            q(s.l.x),
            q(s.l.y),
            q(s.l.z),
            q(s.v.x),
            q(s.v.y),
            q(s.v.z),
            x,
            y,
        ]
    };
    // ordered: the same sum every run
    let mut groups: BTreeMap<[i64; 8], Vec<usize>> = BTreeMap::new();
    for (i, s) in samples.iter().enumerate() {
        groups.entry(key(s)).or_default().push(i);
    }
    let (mut ss, mut dof) = (0.0, 0usize);
    for g in groups.values().filter(|g| g.len() > 1) {
        for c in 0..ch {
            let vals: Vec<f64> = g
                .iter()
                .map(|&i| samples[i].value[c] * scale[i][c])
                .collect();
            let mean = vals.iter().sum::<f64>() / vals.len() as f64;
            ss += vals.iter().map(|v| (v - mean).powi(2)).sum::<f64>();
            dof += vals.len() - 1;
        }
    }
    (ss, dof)
}

/// Noise variance from second differences of the residuals along image rows (pixels of one
/// image share light and view, so their model values change smoothly):
/// mean((r[x0] - 2 r[x1] + r[x2])^2) / 6 over consecutive kept pixels of a row with equal gaps
/// x1 - x0 = x2 - x1 (neighbours, or every stride-th pixel of a subsampled capture).
#[cfg(test)]
fn pixel_variance(samples: &[&Sample], residuals: &[f64], ch: usize) -> Option<(f64, usize)> {
    pixel_estimate(pixel_sums(samples, residuals, ch))
}

/// The noise variance of summed second differences (sum of squares, count), as
/// [`pixel_sums`] describes, when there are at least 10.
pub fn pixel_estimate((ss, count): (f64, usize)) -> Option<(f64, usize)> {
    (count >= 10).then(|| (ss / count as f64 / 6.0, count))
}

/// The sums behind the noise from neighbouring pixels (above): squared second differences
/// and their count. An image row's samples must come in one call.
pub fn pixel_sums(samples: &[&Sample], residuals: &[f64], ch: usize) -> (f64, usize) {
    // ordered rows: the sum runs in the same order every run (a hash map's order changed the
    // estimate's last digits from run to run)
    let mut rows: BTreeMap<(u32, u32), Vec<(u32, usize)>> = BTreeMap::new();
    for (i, s) in samples.iter().enumerate() {
        if let Origin::Pixel { image, x, y } = s.origin {
            rows.entry((image, y)).or_default().push((x, i));
        }
    }
    let (mut ss, mut count) = (0.0, 0usize);
    for row in rows.values_mut() {
        row.sort_unstable();
        for w in row.windows(3) {
            let ((x0, a), (x1, i), (x2, b)) = (w[0], w[1], w[2]);
            if x1 - x0 != x2 - x1 || x1 - x0 > 8 {
                continue;
            }
            for c in 0..ch {
                let d = residuals[a * ch + c] - 2.0 * residuals[i * ch + c] + residuals[b * ch + c];
                ss += d * d;
                count += 1;
            }
        }
    }
    (ss, count)
}

/// Everything the quality block needs from the fit.
pub struct Inputs<'a> {
    pub samples: &'a [&'a Sample],
    /// Residual scale per sample and channel (1/sigma or sqrt(weight)).
    pub scale: &'a [[f64; 3]],
    /// Weighted residuals, sample-major.
    pub residuals: &'a [f64],
    pub channels: usize,
    pub free_parameters: usize,
    pub sigmas_given: bool,
    /// Fibre azimuth of the fit, radians.
    pub psi: f64,
    /// Distinct minima (free shape values by name, cost), best first.
    pub minima: &'a [(Vec<(String, f64)>, f64)],
}

pub fn assess(inp: &Inputs) -> Quality {
    let mut sums = Sums::new(!inp.sigmas_given);
    sums.add(inp.samples, inp.residuals, inp.channels, inp.psi);
    assess_sums(
        &sums,
        inp.free_parameters,
        inp.sigmas_given,
        || repeats_variance(inp.samples, inp.scale, inp.channels),
        inp.minima,
    )
}

/// What [`assess`] sums over the residuals, for data read a piece at a time (a capture scored
/// chunk by chunk): the residual count and sum of squares, the second differences along image
/// rows (when the noise is to be estimated from them) and the residual-structure bins. Pieces
/// added in the samples' order give the sums of all samples at once.
#[derive(Clone, Debug)]
pub struct Sums {
    pub n: usize,
    pub cost: f64,
    /// (sum of squares, count) of second differences; `None` when sigmas are given.
    pixels: Option<(f64, usize)>,
    bins: BinSums,
}

impl Sums {
    /// Empty sums; `estimate_noise`: the data carry no sigmas, so the noise is estimated from
    /// neighbouring pixels.
    pub fn new(estimate_noise: bool) -> Self {
        Self {
            n: 0,
            cost: 0.0,
            pixels: estimate_noise.then_some((0.0, 0)),
            bins: BinSums::default(),
        }
    }

    /// Add `samples` with their weighted residuals (sample-major); an image row's samples come
    /// in one piece.
    pub fn add(&mut self, samples: &[&Sample], residuals: &[f64], channels: usize, psi: f64) {
        self.n += residuals.len();
        for r in residuals {
            self.cost += r * r;
        }
        if let Some((ss, count)) = &mut self.pixels {
            let (s, c) = pixel_sums(samples, residuals, channels);
            *ss += s;
            *count += c;
        }
        for (s, r) in samples.iter().zip(residuals.chunks(channels)) {
            self.bins.add(s, psi, r);
        }
    }

    /// The noise variance the second differences give ([`pixel_estimate`]).
    pub fn pixel_estimate(&self) -> Option<(f64, usize)> {
        self.pixels.and_then(pixel_estimate)
    }
}

/// [`assess`] from its sums; `repeats` gives the noise estimate from repeated direction pairs
/// ([`repeats_variance`]), asked for only when no sigmas are given and the neighbouring pixels
/// give none.
pub fn assess_sums(
    sums: &Sums,
    free_parameters: usize,
    sigmas_given: bool,
    repeats: impl FnOnce() -> Option<(f64, usize)>,
    minima: &[(Vec<(String, f64)>, f64)],
) -> Quality {
    let n = sums.n;
    let p = free_parameters;
    let dof = n.saturating_sub(p).max(1);
    let cost = sums.cost;
    let s2 = cost / dof as f64;
    let mut warnings = Vec::new();
    let noise = noise_check(sums, s2, dof, sigmas_given, repeats);
    let verdict = verdict(&noise, &mut warnings);
    let (minima, minima_beyond) = distinct_minima(minima, cost, s2, &mut warnings);
    let ambiguous = minima.len() > 1;
    // residual structure
    let s_all = s2.sqrt().max(f64::MIN_POSITIVE);
    let residual_bins = sums.bins.bins(s_all);
    let flagged: Vec<String> = residual_bins
        .iter()
        .filter(|b| b.flagged)
        .map(|b| {
            format!(
                "{} {:.0}-{:.0} deg: mean {:+.2} sd ({:+.1} standard errors, {} samples)",
                b.axis, b.lo_deg, b.hi_deg, b.mean, b.z, b.n
            )
        })
        .collect();
    if !flagged.is_empty() {
        warnings.push(format!(
            "systematic residuals (model - data) in {} bins: {}",
            flagged.len(),
            flagged.join("; ")
        ));
    }
    Quality {
        verdict: verdict.into(),
        noise,
        minima,
        minima_beyond,
        ambiguous,
        residual_bins,
        degeneracies: Vec::new(),
        undetermined: Vec::new(),
        warnings,
        floor: None,
    }
}

/// The residual variance `s2` (on `dof` degrees of freedom) against the noise: the sigmas'
/// reduced chi-square, or the ratio to a noise variance estimated from neighbouring pixels or
/// repeated directions, or unknown.
fn noise_check(
    sums: &Sums,
    s2: f64,
    dof: usize,
    sigmas_given: bool,
    repeats: impl FnOnce() -> Option<(f64, usize)>,
) -> NoiseCheck {
    let spread = |k: usize| (2.0 / k as f64).sqrt();
    if sigmas_given {
        return NoiseCheck {
            source: "sigmas".into(),
            ratio: Some(s2),
            expected_spread: Some(spread(dof)),
            noise_estimate: None,
            estimate_dof: None,
            note: format!(
                "reduced chi-square {s2:.4}; a model that fits gives 1 +/- {:.4}",
                spread(dof)
            ),
        };
    }
    // repeated directions only when the pixels give no estimate (their grouping is costly)
    match sums
        .pixel_estimate()
        .map(|e| ("neighbouring pixels", e))
        .or_else(|| repeats().map(|e| ("repeated directions", e)))
    {
        Some((source, (var, k))) if var > 0.0 => {
            // the ratio of two variance estimates: spread from both
            let spr = (2.0 / dof as f64 + 2.0 / k as f64).sqrt();
            NoiseCheck {
                source: source.into(),
                ratio: Some(s2 / var),
                expected_spread: Some(spr),
                noise_estimate: Some(var.sqrt()),
                estimate_dof: Some(k),
                note: format!(
                    "residual variance / noise variance estimated from {source} = {:.4}; a model that fits gives 1 +/- {spr:.4}",
                    s2 / var
                ),
            }
        }
        _ => NoiseCheck {
            source: "none".into(),
            ratio: None,
            expected_spread: None,
            noise_estimate: None,
            estimate_dof: None,
            note: "no sigmas, no repeated directions and no neighbouring pixels: the noise \
                   cannot be estimated, so whether the model fits within it is unknown"
                .into(),
        },
    }
}

/// Does the model fit within the noise? A warning when it does not, when the residuals are
/// smaller than the noise, or when the noise is unknown.
fn verdict(noise: &NoiseCheck, warnings: &mut Vec<String>) -> &'static str {
    match (noise.ratio, noise.expected_spread) {
        (Some(r), Some(sp)) if (r - 1.0) > CHI2_Z_LIMIT * sp => {
            warnings.push(format!(
                "the model does not fit within the noise: {} (more than {CHI2_Z_LIMIT} spreads above)",
                noise.note
            ));
            "does not fit within the noise"
        }
        (Some(r), Some(sp)) if (1.0 - r) > CHI2_Z_LIMIT * sp => {
            warnings.push(format!(
                "the residuals are smaller than the noise: {}; the sigmas may be overestimated, or \
                 the model fits the noise",
                noise.note
            ));
            "fits within the noise"
        }
        (Some(_), Some(_)) => "fits within the noise",
        _ => {
            warnings.push(noise.note.clone());
            "noise unknown"
        }
    }
}

/// The distinct minima the data do not decide against (the best first; their cost above the
/// best in residual variances `s2`) and how many others were found; a warning when more than
/// one is left.
fn distinct_minima(
    minima: &[(Vec<(String, f64)>, f64)],
    cost: f64,
    s2: f64,
    warnings: &mut Vec<String>,
) -> (Vec<MinimumOut>, usize) {
    let best = minima.first().map_or(cost, |m| m.1);
    let all: Vec<MinimumOut> = minima
        .iter()
        .map(|(ps, c)| MinimumOut {
            parameters: ps.iter().cloned().collect(),
            cost: *c,
            delta: (c - best) / s2.max(f64::MIN_POSITIVE),
        })
        .collect();
    // only the minima the data do not decide against are listed (the best first)
    let found = all.len();
    let minima: Vec<MinimumOut> = all
        .into_iter()
        .enumerate()
        .filter(|(k, m)| *k == 0 || m.delta < AMBIGUOUS_DELTA)
        .map(|x| x.1)
        .collect();
    let minima_beyond = found - minima.len();
    let close: Vec<&MinimumOut> = minima.iter().skip(1).collect();
    if !close.is_empty() {
        let list: Vec<String> = std::iter::once(&minima[0])
            .chain(close.iter().copied())
            .map(|m| {
                let ps: Vec<String> = m
                    .parameters
                    .iter()
                    .map(|(k, v)| format!("{k} {v:.4}"))
                    .collect();
                format!(
                    "[{}] cost {:.6e} (+{:.2} residual variances)",
                    ps.join(", "),
                    m.cost,
                    m.delta
                )
            })
            .collect();
        warnings.push(format!(
            "the data do not decide between {} distinct minima: {}",
            close.len() + 1,
            list.join("; ")
        ));
    }
    (minima, minima_beyond)
}

/// The residual bins as indented text lines, with a heading.
pub fn bins_text(bins: &[ResidualBin]) -> String {
    let mut t = String::from(
        "    residual bins (mean weighted residual model - data in residual sd, z = mean / standard error; * = systematic):\n",
    );
    for b in bins {
        t += &format!(
            "      {:<36} {:>4.0}-{:<4.0} n {:>6}  mean {:+.3}  z {:+6.1}{}\n",
            b.axis,
            b.lo_deg,
            b.hi_deg,
            b.n,
            b.mean,
            b.z,
            if b.flagged { " *" } else { "" }
        );
    }
    t
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::frame::{direction_from_angles, Vec3};
    use rand::SeedableRng;
    use rand_distr::{Distribution, StandardNormal};

    fn sample(l: Vec3, v: Vec3, y: f64, origin: Origin) -> Sample {
        Sample {
            l,
            v,
            fibre_azimuth: None,
            map_value: None,
            texel_height: None,
            value: [y; 3],
            sigma: None,
            weight: 1.0,
            origin,
        }
    }

    #[test]
    fn pairs_the_data_do_not_separate_are_named_and_one_of_each_held() {
        let names: Vec<String> = ["exponent", "spacing", "azimuth_spread_deg", "kd[r]", "ks"]
            .iter()
            .map(|s| s.to_string())
            .collect();
        // spacing ~ spread (spread less determined), kd[r] at its bound ~ ks, exponent ~ spacing
        // below the threshold, and spread ~ exponent after spread is held (no second hold)
        let correlations = [(1, 2, 0.998), (3, 4, -0.996), (0, 1, 0.99), (0, 2, 0.9955)];
        let at_bound = [false, false, false, true, false];
        let rel = [Some(0.01), Some(0.02), Some(0.3), None, Some(0.05)];
        let (d, held) = degeneracies(&names, &correlations, &at_bound, &rel);
        assert_eq!(held, vec![2], "{d:?}");
        assert_eq!(d.len(), 3, "{d:?}");
        assert_eq!(
            (d[0].a.as_str(), d[0].b.as_str(), d[0].held.as_str()),
            ("spacing", "azimuth_spread_deg", "azimuth_spread_deg")
        );
        assert_eq!(d[0].held_at, "at its fitted value");
        assert!(
            d[0].note.contains("+0.9980") && d[0].note.contains("conditional"),
            "{}",
            d[0].note
        );
        assert_eq!(
            (d[1].held.as_str(), d[1].held_at.as_str()),
            ("kd[r]", "at its bound")
        );
        assert!(
            d[1].note.contains("-0.9960") && d[1].note.contains("`ks` takes its role"),
            "{}",
            d[1].note
        );
        assert_eq!(d[2].held, "azimuth_spread_deg");
        // nothing near +-1: nothing held
        let (d, held) = degeneracies(&names, &[(0, 1, 0.9)], &at_bound, &rel);
        assert!(d.is_empty() && held.is_empty());
    }

    #[test]
    fn only_minima_within_the_threshold_are_listed() {
        let v = direction_from_angles(0.2, 2.0);
        let samples: Vec<Sample> = (0..50)
            .map(|k| {
                sample(
                    direction_from_angles(0.01 * k as f64, 0.1),
                    v,
                    1.0,
                    Origin::Line(2),
                )
            })
            .collect();
        let refs: Vec<&Sample> = samples.iter().collect();
        // residual variance 1e-4 * 50 / 49: minima +2 and +7430 residual variances above
        let s2 = 1e-4 * 50.0 / 49.0;
        let best = 50.0 * 1e-4;
        let minima = [
            (vec![("height".to_string(), 0.1)], best),
            (vec![("height".to_string(), 1.6)], best + 2.0 * s2),
            (vec![("height".to_string(), 0.9)], best + 7430.0 * s2),
        ];
        let q = assess(&Inputs {
            samples: &refs,
            scale: &vec![[1.0; 3]; 50],
            residuals: &vec![0.01; 50],
            channels: 1,
            free_parameters: 1,
            sigmas_given: true,
            psi: 0.0,
            minima: &minima,
        });
        assert_eq!(q.minima.len(), 2, "{:?}", q.minima);
        assert!(q.minima.iter().all(|m| m.delta < AMBIGUOUS_DELTA));
        assert_eq!(q.minima_beyond, 1);
        assert!(q.ambiguous);
        let w = q
            .warnings
            .iter()
            .find(|w| w.contains("do not decide"))
            .unwrap();
        assert!(
            w.contains("between 2 distinct minima") && !w.contains("7430"),
            "{w}"
        );
    }

    #[test]
    fn noise_is_estimated_from_neighbouring_pixels_and_from_repeats() {
        let mut rng = rand::rngs::StdRng::seed_from_u64(5);
        let sigma = 0.1;
        let l = direction_from_angles(0.4, 0.3);
        let v = direction_from_angles(0.2, 2.0);
        // pixels: residuals = a smooth misfit (a ramp, which second differences cancel) + noise
        let mut samples = Vec::new();
        let mut residuals = Vec::new();
        for y in 0..40u32 {
            for x in 0..40u32 {
                samples.push(sample(l, v, 1.0, Origin::Pixel { image: 0, x, y }));
                let z: f64 = StandardNormal.sample(&mut rng);
                residuals.push(0.05 * x as f64 + sigma * z);
            }
        }
        let refs: Vec<&Sample> = samples.iter().collect();
        let (var, k) = pixel_variance(&refs, &residuals, 1).unwrap();
        assert!(k > 1000);
        assert!((var.sqrt() / sigma - 1.0).abs() < 0.05, "{}", var.sqrt());
        // repeats: 200 directions measured 3 times each
        let mut samples = Vec::new();
        for k in 0..200 {
            let l = direction_from_angles(0.01 * k as f64, 0.1);
            let truth = 1.0 + k as f64 * 0.01;
            for _ in 0..3 {
                let z: f64 = StandardNormal.sample(&mut rng);
                samples.push(sample(l, v, truth + sigma * z, Origin::Line(2)));
            }
        }
        let refs: Vec<&Sample> = samples.iter().collect();
        let scale = vec![[1.0; 3]; refs.len()];
        let (var, dof) = repeats_variance(&refs, &scale, 1).unwrap();
        assert_eq!(dof, 400);
        assert!((var.sqrt() / sigma - 1.0).abs() < 0.08, "{}", var.sqrt());
        // without either, the verdict says the noise is unknown
        let single: Vec<Sample> = (0..50)
            .map(|k| {
                sample(
                    direction_from_angles(0.01 * k as f64, 0.1),
                    v,
                    1.0,
                    Origin::Line(2),
                )
            })
            .collect();
        let refs: Vec<&Sample> = single.iter().collect();
        let q = assess(&Inputs {
            samples: &refs,
            scale: &vec![[1.0; 3]; 50],
            residuals: &vec![0.01; 50],
            channels: 1,
            free_parameters: 1,
            sigmas_given: false,
            psi: 0.0,
            minima: &[],
        });
        assert_eq!(q.verdict, "noise unknown");
        assert!(q.warnings.iter().any(|w| w.contains("cannot be estimated")));
    }
}
