//! Synthetic goniometric sets: directions on a grid or drawn at random, each rendered from the
//! rung and noised from one seeded stream, written as the CSV the gonio loader reads.

use super::{GonioSpec, Noise};
use crate::model::frame::{direction_from_angles, FibreFrame};
use crate::model::params::ModelParams;
use crate::model::{DirectionPair, ShadingModel};
use anyhow::{bail, Result};
use rand::{Rng, SeedableRng};
use rayon::prelude::*;

/// Directions as (theta_i, phi_i, theta_o, phi_o) in degrees.
fn gonio_directions(g: &GonioSpec) -> Result<Vec<[f64; 4]>> {
    match (&g.grid, &g.random) {
        (Some(grid), None) => {
            let mut out = Vec::new();
            for &ti in &grid.theta_i {
                for &pi in &grid.phi_i {
                    for &to in &grid.theta_o {
                        for &po in &grid.phi_o {
                            if ti < 90.0 && to < 90.0 && ti >= 0.0 && to >= 0.0 {
                                out.push([ti, pi, to, po]);
                            }
                        }
                    }
                }
            }
            Ok(out)
        }
        (None, Some(r)) => {
            if !(r.max_theta_deg > 0.0 && r.max_theta_deg < 90.0) {
                bail!("gonio.random.max_theta_deg must lie in (0, 90)");
            }
            let mut rng = rand::rngs::StdRng::seed_from_u64(r.seed);
            let cos_max = r.max_theta_deg.to_radians().cos();
            let mut dir = || {
                // uniform in solid angle above theta_max, rounded to 1e-6 degrees so the CSV
                // holds exactly the rendered directions
                let z: f64 = cos_max + (1.0 - cos_max) * rng.random::<f64>();
                let round = |x: f64| (x * 1e6).round() / 1e6;
                (
                    round(z.acos().to_degrees()),
                    round(rng.random::<f64>() * 360.0),
                )
            };
            Ok((0..r.count)
                .map(|_| {
                    let (a, b) = dir();
                    let (c, d) = dir();
                    [a, b, c, d]
                })
                .collect())
        }
        _ => bail!("[gonio] needs exactly one of `grid` or `random`"),
    }
}

/// The CSV of the set `g` asks for: a header, then per direction its angles, values (BRDF, or
/// radiance with the irradiance), and sigmas when there is noise.
pub(super) fn render_gonio(
    g: &GonioSpec,
    shading: &dyn ShadingModel,
    p: &ModelParams,
    noise: &Noise,
) -> Result<String> {
    let radiance = match g.values.as_str() {
        "brdf" => false,
        "radiance" => true,
        other => bail!("gonio.values = '{other}': expected \"brdf\" or \"radiance\""),
    };
    if radiance && !(g.irradiance > 0.0) {
        bail!("gonio.irradiance must be positive");
    }
    let dirs = gonio_directions(g)?;
    if dirs.is_empty() {
        bail!("[gonio] gives no directions above the horizon");
    }
    let frame = FibreFrame::from_azimuth(p.fibre_azimuth);
    let channels = p.albedos.channels();
    let values: Vec<[f64; 3]> = dirs
        .par_iter()
        .map(|d| {
            let l = direction_from_angles(d[0].to_radians(), d[1].to_radians());
            let v = direction_from_angles(d[2].to_radians(), d[3].to_radians());
            let b = shading.basis(&DirectionPair::new(&frame, &l, &v));
            [
                b.brdf(&p.albedos, 0),
                b.brdf(&p.albedos, 1),
                b.brdf(&p.albedos, 2),
            ]
        })
        .collect();
    let mut rng = rand::rngs::StdRng::seed_from_u64(noise.spec.seed);
    let base = if radiance { "radiance" } else { "brdf" };
    let names = |b: &str| -> Vec<String> {
        if channels == 1 {
            vec![b.to_string()]
        } else {
            ["r", "g", "b"].iter().map(|c| format!("{b}_{c}")).collect()
        }
    };
    let mut header = vec![
        "theta_i".to_string(),
        "phi_i".into(),
        "theta_o".into(),
        "phi_o".into(),
    ];
    header.extend(names(base));
    if radiance {
        header.push("irradiance".into());
    }
    if noise.active() {
        header.extend(names("sigma"));
    }
    let mut out = header.join(",") + "\n";
    for (d, f) in dirs.iter().zip(&values) {
        let to_file = if radiance {
            g.irradiance * d[0].to_radians().cos()
        } else {
            1.0
        };
        let mut row: Vec<String> = d.iter().map(|x| x.to_string()).collect();
        for &fc in &f[..channels] {
            row.push((noise.apply(fc, &mut rng) * to_file).to_string());
        }
        if radiance {
            row.push(g.irradiance.to_string());
        }
        if noise.active() {
            for &fc in &f[..channels] {
                row.push((noise.sigma(fc) * to_file).to_string());
            }
        }
        out += &row.join(",");
        out.push('\n');
    }
    Ok(out)
}
