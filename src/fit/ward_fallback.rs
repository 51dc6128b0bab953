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

pub struct WardFallback {
    /// Ward's parameters by name, one value or three.
    pub parameters: Vec<(String, Vec<f64>)>,
    /// Against the fitted model over the fitting directions, 1/sr.
    pub rms_error: f64,
    pub relative_rms_error: f64,
    pub directions: usize,
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
    };
    let psi = super::wrap_azimuth(psi_deg);
    let text = format!(
        "model = \"ward\"\nseed = {seed}\n[parameters]\nfibre_azimuth_deg = {{ value = {psi}, vary = false }}\nalpha_x = {{ value = 0.2 }}\nalpha_y = {{ value = 0.2 }}\n"
    );
    let ward_cfg: FitConfig = toml::from_str(&text)?;
    let w = super::fit(&data, &ward_cfg, true)?;
    Ok(WardFallback {
        parameters: w
            .records
            .iter()
            .map(|r| (r.name.clone(), r.value.clone()))
            .collect(),
        rms_error: w.statistics.rmse,
        relative_rms_error: w.statistics.relative_rmse,
        directions: DIRECTIONS,
    })
}
