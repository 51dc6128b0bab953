//! Samples a program already holds: light and view directions with their BRDF values (and
//! optionally sigmas), as numpy arrays from Python. The same checks as a goniometric table's
//! rows (`gonio`): unit directions above the horizon, finite values within the range fibrefit
//! computes with, positive sigmas, no negatives beyond noise; errors name the array and row.

use super::gonio::{MAX_MAGNITUDE, MIN_SIGMA, NEGATIVE_FRACTION, NEGATIVE_SIGMAS};
use super::samples::{DataKind, Dropped, Origin, Sample, Samples};
use crate::model::frame::Vec3;
use anyhow::{bail, Result};

/// Directions whose length is this far from 1 are refused (closer ones are normalised).
const UNIT_TOLERANCE: f64 = 1e-3;

/// Measurements as arrays, row by row (row k: `l[k]`, `v[k]`, `values[k * channels..]`).
#[derive(Clone, Copy, Debug)]
pub struct Arrays<'a> {
    /// Unit directions towards the light, swatch frame (N = +z).
    pub l: &'a [[f64; 3]],
    /// Unit directions towards the viewer, swatch frame.
    pub v: &'a [[f64; 3]],
    /// The BRDF values in 1/sr, `channels` per row (row-major).
    pub values: &'a [f64],
    /// 1 (grey) or 3 (RGB).
    pub channels: usize,
    /// Standard deviations of the values in 1/sr: one per row (every channel), or `channels`
    /// per row.
    pub sigma: Option<&'a [f64]>,
}

/// The samples of `a`; `name` labels errors (`NAME: l[3] ...`) and the samples' source.
pub fn samples(a: &Arrays, name: &str) -> Result<Samples> {
    let n = a.l.len();
    check_shapes(a, name)?;
    let mut samples = Vec::with_capacity(n);
    let mut negatives = Vec::new();
    for k in 0..n {
        let l = direction(a.l[k], "l", k, name)?;
        let v = direction(a.v[k], "v", k, name)?;
        let value = row_values(a.values, a.channels, k, name)?;
        let sigma = match a.sigma {
            Some(s) => Some(row_sigma(s, s.len() / n, k, name)?),
            None => None,
        };
        for c in 0..a.channels {
            match sigma {
                Some(s) if value[c] < -NEGATIVE_SIGMAS * s[c] => bail!(
                    "{name}: values[{k}] = {} is negative beyond noise (more than {NEGATIVE_SIGMAS} sigma)",
                    value[c]
                ),
                None if value[c] < 0.0 => negatives.push((k, value[c])),
                _ => {}
            }
        }
        samples.push(Sample {
            l,
            v,
            fibre_azimuth: None,
            map_value: None,
            texel_height: None,
            value,
            sigma,
            weight: 1.0,
            origin: Origin::Line(k as u64 + 1),
        });
    }
    let largest = a.values.iter().copied().fold(0.0, f64::max);
    if let Some((k, value)) = negatives
        .into_iter()
        .find(|&(_, x)| x < -NEGATIVE_FRACTION * largest)
    {
        bail!(
            "{name}: values[{k}] = {value} is negative beyond noise (more than {} % of the largest value {largest}); give sigma if this is noise",
            NEGATIVE_FRACTION * 100.0
        );
    }
    Ok(Samples {
        samples,
        channels: a.channels,
        kind: DataKind::Gonio,
        source: name.into(),
        dropped: Dropped::default(),
        skipped_examples: Vec::new(),
        image_size: None,
        scale_rel_se: None,
    })
}

/// As many rows in every array, at least one, 1 or 3 channels, sigmas per row or per value.
fn check_shapes(a: &Arrays, name: &str) -> Result<()> {
    let n = a.l.len();
    if n == 0 {
        bail!("{name}: no samples (l, v and values are empty)");
    }
    if a.v.len() != n {
        bail!("{name}: l has {n} rows, v has {}", a.v.len());
    }
    if a.channels != 1 && a.channels != 3 {
        bail!(
            "{name}: values has {} columns; expected 1 (grey) or 3 (RGB)",
            a.channels
        );
    }
    if a.values.len() != n * a.channels {
        bail!(
            "{name}: l has {n} rows, values has {}",
            a.values.len() / a.channels
        );
    }
    if let Some(s) = a.sigma {
        if s.len() != n && s.len() != n * a.channels {
            bail!(
                "{name}: sigma has {} entries; expected one per row ({n}) or one per value ({} rows x {})",
                s.len(),
                n,
                a.channels
            );
        }
    }
    Ok(())
}

/// Row `k` of the direction array `what`: finite, of unit length (within [`UNIT_TOLERANCE`],
/// then normalised), above the horizon.
fn direction(d: [f64; 3], what: &str, k: usize, name: &str) -> Result<Vec3> {
    let w = Vec3::new(d[0], d[1], d[2]);
    let len = w.norm();
    if !len.is_finite() || (len - 1.0).abs() > UNIT_TOLERANCE {
        bail!(
            "{name}: {what}[{k}] = ({}, {}, {}) has length {len}; directions must be unit vectors (swatch frame, normal +z)",
            d[0], d[1], d[2]
        );
    }
    if d[2] <= 0.0 {
        bail!(
            "{name}: {what}[{k}] = ({}, {}, {}) is at or below the horizon (z <= 0; the swatch normal is +z)",
            d[0], d[1], d[2]
        );
    }
    Ok(w / len)
}

/// Row `k`'s BRDF values (grey repeated): finite, within [`MAX_MAGNITUDE`].
fn row_values(values: &[f64], channels: usize, k: usize, name: &str) -> Result<[f64; 3]> {
    let mut out = [0.0; 3];
    for c in 0..channels {
        let x = values[k * channels + c];
        if !(x.abs() <= MAX_MAGNITUDE) {
            bail!("{name}: values[{k}] = {x} is not a BRDF value fibrefit computes with (finite, |f| <= {MAX_MAGNITUDE:e} 1/sr)");
        }
        out[c] = x;
    }
    if channels == 1 {
        out = [out[0]; 3];
    }
    Ok(out)
}

/// Row `k`'s sigmas (`per_row` of them: 1 for every channel, or one per channel), each in
/// [[`MIN_SIGMA`], [`MAX_MAGNITUDE`]] (grey repeated).
fn row_sigma(sigma: &[f64], per_row: usize, k: usize, name: &str) -> Result<[f64; 3]> {
    let mut out = [0.0; 3];
    for (c, o) in out.iter_mut().enumerate() {
        let x = sigma[k * per_row + c.min(per_row - 1)];
        if !(MIN_SIGMA..=MAX_MAGNITUDE).contains(&x) {
            bail!("{name}: sigma[{k}] = {x} must be positive and finite (in [{MIN_SIGMA:e}, {MAX_MAGNITUDE:e}] 1/sr)");
        }
        *o = x;
    }
    Ok(out)
}
