//! The measured against the fitted BRDF for the viewer's light: for a grid of light directions,
//! the measured samples whose light lies near it (their view directions, measured and fitted
//! values at their own directions) and the fitted BRDF over every view direction at the grid
//! light, so the page can draw both hemispheres for the light nearest to the one the user drags.

use crate::load::samples::Samples;
use crate::model::frame::{direction_from_angles, Vec3};
use serde::Serialize;

/// Polar angles of the grid's lights, degrees (azimuths every [`PHI_STEP_DEG`], one light at 0).
pub const THETAS_DEG: [f64; 6] = [0.0, 15.0, 30.0, 45.0, 60.0, 75.0];
/// Azimuth step of the grid's lights, degrees.
pub const PHI_STEP_DEG: f64 = 30.0;
/// A sample belongs to a grid light when its own light lies within this angle of it, degrees.
pub const NEAR_DEG: f64 = 10.0;
/// A grid light is shown when this many samples lie near it.
pub const MIN_SAMPLES: usize = 12;
/// The data have enough directions for the comparison when this many grid lights are shown.
pub const MIN_LIGHTS: usize = 6;
/// Most samples kept per grid light (the nearest).
pub const MAX_SAMPLES: usize = 160;
/// The fitted hemisphere's grid: `MAP_SIZE` x `MAP_SIZE` view directions over the unit disc
/// (orthographic, seen from above: x = sin theta cos phi, y = sin theta sin phi).
pub const MAP_SIZE: usize = 15;

/// One grid light: where it is, the samples near it and the fitted BRDF over the hemisphere.
#[derive(Clone, Debug, Serialize)]
pub struct LightNode {
    /// The light's polar and azimuth angles, degrees.
    pub theta: f64,
    pub phi: f64,
    /// Per sample near it: [theta_o, phi_o (degrees), measured, fitted at the sample's own
    /// light and view], the BRDF as the mean over the channels, 1/sr.
    pub samples: Vec<[f64; 4]>,
    /// The fitted BRDF (mean over the channels, 1/sr) at the grid light, row by row from
    /// y = +1, x from -1; null outside the disc or where the model gives none.
    pub fitted_map: Vec<Option<f64>>,
}

/// The comparison the page draws, or why there is none.
#[derive(Clone, Debug, Serialize)]
pub struct Comparison {
    /// Whether the data have enough directions ([`MIN_LIGHTS`] grid lights shown).
    pub available: bool,
    /// What the picture is, or why there is none.
    pub note: String,
    pub near_deg: f64,
    pub map_size: usize,
    pub nodes: Vec<LightNode>,
}

impl Comparison {
    /// No comparison, and why.
    pub fn none(why: impl Into<String>) -> Self {
        Self {
            available: false,
            note: why.into(),
            near_deg: NEAR_DEG,
            map_size: MAP_SIZE,
            nodes: Vec::new(),
        }
    }
}

/// The grid's light directions (theta, phi) in degrees.
fn grid_lights() -> Vec<(f64, f64)> {
    let mut out = Vec::new();
    for &t in &THETAS_DEG {
        if t == 0.0 {
            out.push((0.0, 0.0));
            continue;
        }
        let n = (360.0 / PHI_STEP_DEG).round() as usize;
        out.extend((0..n).map(|k| (t, k as f64 * PHI_STEP_DEG)));
    }
    out
}

/// The mean over the first `channels` values.
fn mean(v: &[f64; 3], channels: usize) -> f64 {
    let c = channels.clamp(1, 3);
    v[..c].iter().sum::<f64>() / c as f64
}

/// `x` to 4 significant digits (what a colour scale shows; keeps the page small).
fn digits(x: f64) -> f64 {
    if !x.is_finite() || x == 0.0 {
        return x;
    }
    format!("{x:.3e}").parse().unwrap_or(x)
}

/// (theta, phi) in degrees of a unit direction (phi in [0, 360)).
fn angles(d: &Vec3) -> (f64, f64) {
    let theta = d.z.clamp(-1.0, 1.0).acos().to_degrees();
    let phi = d.y.atan2(d.x).to_degrees().rem_euclid(360.0);
    (theta, phi)
}

/// The fitted BRDF over the disc of view directions for the light `l`.
fn fitted_map(l: &Vec3, fitted: super::Brdf, channels: usize) -> Vec<Option<f64>> {
    let n = MAP_SIZE;
    let mut out = Vec::with_capacity(n * n);
    for j in 0..n {
        for i in 0..n {
            let x = -1.0 + 2.0 * (i as f64 + 0.5) / n as f64;
            let y = 1.0 - 2.0 * (j as f64 + 0.5) / n as f64;
            let r2 = x * x + y * y;
            if r2 >= 1.0 {
                out.push(None);
                continue;
            }
            let v = Vec3::new(x, y, (1.0 - r2).sqrt());
            out.push(fitted(l, &v).map(|f| digits(mean(&f, channels))));
        }
    }
    out
}

/// The comparison of `samples` with `fitted` (the model as a function of swatch-frame
/// directions, per channel).
pub fn compare(samples: &Samples, fitted: super::Brdf) -> Comparison {
    let ch = samples.channels;
    let cos_near = NEAR_DEG.to_radians().cos();
    let mut nodes = Vec::new();
    for (theta, phi) in grid_lights() {
        let l = direction_from_angles(theta.to_radians(), phi.to_radians());
        let mut near: Vec<(f64, usize)> = samples
            .samples
            .iter()
            .enumerate()
            .filter_map(|(i, s)| {
                let c = s.l.dot(&l);
                (c >= cos_near && s.v.z > 0.0).then_some((-c, i))
            })
            .collect();
        if near.len() < MIN_SAMPLES {
            continue;
        }
        near.sort_by(|a, b| a.0.total_cmp(&b.0));
        near.truncate(MAX_SAMPLES);
        let points = near
            .iter()
            .filter_map(|&(_, i)| {
                let s = &samples.samples[i];
                let f = fitted(&s.l, &s.v)?;
                let (to, po) = angles(&s.v);
                Some([
                    (to * 100.0).round() / 100.0,
                    (po * 100.0).round() / 100.0,
                    digits(mean(&s.value, ch)),
                    digits(mean(&f, ch)),
                ])
            })
            .collect();
        nodes.push(LightNode {
            theta,
            phi,
            samples: points,
            fitted_map: fitted_map(&l, fitted, ch),
        });
    }
    let shown = nodes.len();
    if shown < MIN_LIGHTS {
        return Comparison::none(format!(
            "the data have too few directions for this picture: {shown} of the {} grid lights have {MIN_SAMPLES} or more samples whose light lies within {NEAR_DEG} deg (at least {MIN_LIGHTS} needed); an image capture has one light and one view per image",
            grid_lights().len()
        ));
    }
    Comparison {
        available: true,
        note: format!(
            "for the grid light nearest to the viewer's light ({shown} of {} grid lights at theta {} deg, every {PHI_STEP_DEG} deg in phi, have {MIN_SAMPLES} or more samples): the samples whose light lies within {NEAR_DEG} deg of it (at most {MAX_SAMPLES}, the nearest), measured and fitted at each sample's own directions, and the fitted BRDF over every view direction at the grid light; BRDF the mean over the channels, 1/sr, a log colour scale",
            grid_lights().len(),
            THETAS_DEG.map(|t| format!("{t:.0}")).join(", ")
        ),
        near_deg: NEAR_DEG,
        map_size: MAP_SIZE,
        nodes,
    }
}
