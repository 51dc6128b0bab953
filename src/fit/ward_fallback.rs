//! The Ward fallback: Ward's anisotropic lobe fitted to a fitted model's BRDF over a dense set of
//! directions, for renderers that have Ward but not the fibre model. A fit like any other.

use super::config::FitConfig;
use crate::load::samples::{DataKind, Dropped, Origin, Sample, Samples};
use crate::model::frame::direction_from_angles;
use crate::model::{brdf_at_degrees, Albedos, ShadingModel};
use anyhow::Result;
use rand::{Rng, SeedableRng};

/// Directions the lobe is fitted over (light and view uniform in solid angle up to 80 deg).
pub const DIRECTIONS: usize = 1500;

/// A fallback whose relative RMS error against the fitted model exceeds this is warned about.
pub const POOR_RELATIVE_ERROR: f64 = 0.25;

pub struct WardFallback {
    /// Ward's parameters by name, one value or three.
    pub parameters: Vec<(String, Vec<f64>)>,
    /// Against the fitted model over the fitting directions, 1/sr.
    pub rms_error: f64,
    pub relative_rms_error: f64,
    pub directions: usize,
    /// Why the fallback should not stand in for the model: more than [`POOR_RELATIVE_ERROR`]
    /// off it, or a parameter at a bound of its range (the best Ward lobe lies beyond it).
    pub warnings: Vec<String>,
}

/// The warnings of a fallback `relative_rms_error` off the model whose fit ended as `records`.
pub fn warnings(relative_rms_error: f64, records: &[super::ParamRecord]) -> Vec<String> {
    let mut out = Vec::new();
    if !(relative_rms_error <= POOR_RELATIVE_ERROR) {
        out.push(format!(
            "the Ward fallback is {:.0} % off the fitted model (relative RMS error {:.3} over {DIRECTIONS} directions, more than {:.0} %): Ward's lobe cannot take this BRDF's shape, so a renderer given only the fallback shows another material",
            100.0 * relative_rms_error,
            relative_rms_error,
            100.0 * POOR_RELATIVE_ERROR
        ));
    }
    for r in records.iter().filter(|r| !r.fixed) {
        for (c, (&v, &at)) in r.value.iter().zip(&r.at_bound).enumerate() {
            if !at {
                continue;
            }
            let name = if r.value.len() == 1 {
                r.name.clone()
            } else {
                format!("{}[{}]", r.name, ["r", "g", "b"][c])
            };
            let side = if (v - r.min).abs() <= (v - r.max).abs() {
                ("lower", r.min)
            } else {
                ("upper", r.max)
            };
            out.push(format!(
                "the Ward fallback's {name} ended at its {} bound {} (range [{}, {}]): the best Ward lobe lies beyond Ward's range there",
                side.0, side.1, r.min, r.max
            ));
        }
    }
    out
}

/// Fit Ward to `m` (with its albedos, fibres at `psi_deg`) over [`DIRECTIONS`] seeded pairs.
pub fn fit(
    m: &dyn ShadingModel,
    albedos: &Albedos,
    psi_deg: f64,
    seed: u64,
    channels: usize,
) -> Result<WardFallback> {
    let mut rng = rand::rngs::StdRng::seed_from_u64(seed ^ 0x5741_5244);
    let cos_max = 80f64.to_radians().cos();
    let mut dir = || {
        let z: f64 = cos_max + (1.0 - cos_max) * rng.random::<f64>();
        (z.acos().to_degrees(), rng.random::<f64>() * 360.0)
    };
    let samples: Vec<Sample> = (0..DIRECTIONS)
        .map(|k| {
            let (ti, pi) = dir();
            let (to, po) = dir();
            let f = brdf_at_degrees(m, albedos, psi_deg.to_radians(), [ti, pi, to, po], channels);
            let mut value = [f[0]; 3];
            value[..channels].copy_from_slice(&f);
            Sample {
                l: direction_from_angles(ti.to_radians(), pi.to_radians()),
                v: direction_from_angles(to.to_radians(), po.to_radians()),
                fibre_azimuth: None,
                map_value: None,
                texel_height: None,
                value,
                sigma: None,
                weight: 1.0,
                origin: Origin::Line(k as u64 + 2),
            }
        })
        .collect();
    let data = Samples {
        samples,
        channels,
        kind: DataKind::Gonio,
        source: "fitted model".into(),
        dropped: Dropped::default(),
        skipped_examples: vec![],
        image_size: None,
        scale_rel_se: None,
    };
    let psi = super::wrap_azimuth(psi_deg);
    let text = format!(
        "model = \"ward\"\nseed = {seed}\n[parameters]\nfibre_azimuth_deg = {{ value = {psi}, vary = false }}\nalpha_x = {{ value = 0.2 }}\nalpha_y = {{ value = 0.2 }}\n"
    );
    let ward_cfg: FitConfig = toml::from_str(&text)?;
    let w = super::fit(&data, &ward_cfg, &crate::progress::Progress::quiet())?;
    Ok(WardFallback {
        parameters: w
            .records
            .iter()
            .map(|r| (r.name.clone(), r.value.clone()))
            .collect(),
        rms_error: w.statistics.rmse,
        relative_rms_error: w.statistics.relative_rmse,
        directions: DIRECTIONS,
        warnings: warnings(w.statistics.relative_rmse, &w.records),
    })
}
