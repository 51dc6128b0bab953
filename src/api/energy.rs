//! The white furnace of a fitted material: does it reflect more light than it receives?
//!
//! A material's directional albedo at the view v, rho(v) = int f(l, v) cos(theta_l) dl over the
//! hemisphere, is the fraction of light arriving along v that it reflects (reciprocity); a
//! physical material keeps it at most 1. A fit can exceed it: data in the wrong units (a
//! reflectance factor, pi times the BRDF, or a reference's scale), or a rung or correction
//! extrapolated to grazing views the data do not cover. A renderer's path tracer then brightens
//! the material at every bounce. The fit checks the material it delivers (the rung with its
//! fuzz layer and correction, the global parameters) at [`THETA_DEG`] x [`PHI_DEG`] with the
//! material's own importance sampler: rho is the mean of its weights f cos / pdf over a
//! stratified grid of uniforms.

use super::material::Material;
use std::path::Path;

/// The views' polar angles, degrees from the normal.
pub const THETA_DEG: [f64; 6] = [0.0, 30.0, 60.0, 75.0, 85.0, 89.0];
/// The views' azimuths, degrees from the fibres.
pub const PHI_DEG: [f64; 3] = [0.0, 45.0, 90.0];
/// Strata per side of the uniforms' grid at each view (a rung evaluated at 30 k samples/s checks
/// its 18 views in about a second on one core).
pub const STRATA: usize = 24;

/// The directional albedo at one view.
#[derive(Clone, Debug)]
pub struct ViewAlbedo {
    /// The view's polar angle, degrees from the normal.
    pub theta_deg: f64,
    /// The view's azimuth, degrees from the fibres.
    pub phi_deg: f64,
    /// Per channel (a grey material repeats its value).
    pub albedo: [f64; 3],
    /// Its standard error, from the weights' spread as if they were independent (the grid's
    /// stratification only lowers the true error).
    pub se: [f64; 3],
}

/// The directional albedo of `m` (global parameters, no maps) at every view of [`THETA_DEG`] x
/// [`PHI_DEG`], `strata` x `strata` samples each.
pub fn furnace(m: &Material, strata: usize) -> Vec<ViewAlbedo> {
    let n = strata.max(1);
    let psi = m.params.fibre_azimuth;
    let mut views = Vec::new();
    let mut rows_v = Vec::new();
    let mut rows_u = Vec::new();
    for &th in &THETA_DEG {
        for &ph in &PHI_DEG {
            let (t, p) = (th.to_radians(), psi + ph.to_radians());
            let v = [t.sin() * p.cos(), t.sin() * p.sin(), t.cos()];
            views.push((th, ph));
            for i in 0..n {
                for j in 0..n {
                    rows_v.push(v);
                    // the cell's centre, jittered by a fixed low-discrepancy offset
                    let jitter =
                        |k: usize, a: f64| (k as f64 + (a * (k + 1) as f64).fract()) / n as f64;
                    rows_u.push([
                        jitter(i, 0.618_033_988_749_895),
                        jitter(j, 0.754_877_666_246_693),
                    ]);
                }
            }
        }
    }
    let samples = m
        .sample_many(&rows_v, &rows_u, None, None)
        .expect("unit views and uniforms in [0, 1)");
    views
        .iter()
        .zip(samples.chunks(n * n))
        .map(|(&(theta_deg, phi_deg), s)| {
            let count = s.len() as f64;
            let mut albedo = [0.0; 3];
            let mut se = [0.0; 3];
            for c in 0..3 {
                let mean = s.iter().map(|x| x.weight[c]).sum::<f64>() / count;
                let var = s.iter().map(|x| (x.weight[c] - mean).powi(2)).sum::<f64>() / count;
                albedo[c] = mean;
                se[c] = (var / count).sqrt();
            }
            ViewAlbedo {
                theta_deg,
                phi_deg,
                albedo,
                se,
            }
        })
        .collect()
}

/// The warning for views whose albedo exceeds 1 by more than three standard errors (and by
/// 0.5 %), naming the largest; `None` when the material keeps the energy it receives.
pub fn gain_warning(rows: &[ViewAlbedo], channels: usize) -> Option<String> {
    let names = ["r", "g", "b"];
    let gains = |r: &ViewAlbedo, c: usize| r.albedo[c] > 1.005 && r.albedo[c] - 3.0 * r.se[c] > 1.0;
    let over: Vec<(&ViewAlbedo, usize)> = rows
        .iter()
        .flat_map(|r| {
            (0..channels)
                .filter(move |&c| gains(r, c))
                .map(move |c| (r, c))
        })
        .collect();
    // the largest; of equal ones, the first (the view nearest the normal)
    let &(worst, c) = over.iter().reduce(|a, b| {
        if b.0.albedo[b.1] > a.0.albedo[a.1] {
            b
        } else {
            a
        }
    })?;
    let views = rows
        .iter()
        .filter(|r| (0..channels).any(|c| gains(r, c)))
        .count();
    let channel = if channels > 1 {
        format!(" ({})", names[c])
    } else {
        String::new()
    };
    let everywhere = over.iter().any(|(r, _)| r.theta_deg == 0.0);
    let hint = if everywhere {
        ". It does so at normal incidence too: are the data a BRDF in 1/sr (a reflectance \
         factor is pi times it), on the right reference's scale?"
    } else {
        ". Only at grazing views: the fit extrapolates there"
    };
    Some(format!(
        "the material reflects more light than it receives: its directional albedo \
         reaches {:.3}{channel} +/- {:.3} for light from {:.0} deg ({:.0} deg from the fibres), \
         above 1 at {views} of {} views checked: a renderer's path tracer brightens it at every \
         bounce{hint}",
        worst.albedo[c],
        worst.se[c],
        worst.theta_deg,
        worst.phi_deg,
        rows.len()
    ))
}

/// The energy check of a fit's result (its JSON, labelled `source`): the warning, if any; a
/// material that cannot be built for the check is a warning too.
pub fn check_result(result: &serde_json::Value, source: &Path) -> Option<String> {
    match Material::from_result(result, source, None) {
        Ok((m, _)) => gain_warning(&furnace(&m, STRATA), m.channels),
        Err(e) => Some(format!(
            "the energy check could not build the material: {e:#}"
        )),
    }
}
