//! A glTF 2.0 material fitted to a fitted fibre model, for engines without custom shaders: the
//! core metallic-roughness BRDF (dielectric, metallic 0) with KHR_materials_anisotropy and
//! KHR_materials_ior, fitted to the model's BRDF over the Ward fallback's kind of direction set.
//!
//! The BRDF is the one the glTF specification (Appendix B and the extensions' texts) defines:
//!
//! ```text
//! f = (1 - F) base / pi + F D V,     F = F0 + (1 - F0) (1 - |v.h|)^5,  F0 = ((ior - 1)/(ior + 1))^2
//! alpha = roughness^2,  alpha_t = mix(alpha, 1, strength^2),  alpha_b = alpha
//! D = 1 / (pi alpha_t alpha_b ((a_t.h / alpha_t)^2 + (a_b.h / alpha_b)^2 + (n.h)^2)^2)
//! V = 1 / (2 (n.l |(alpha_t a_t.v, alpha_b a_b.v, n.v)| + n.v |(alpha_t a_t.l, alpha_b a_b.l, n.l)|))
//! ```
//!
//! with the anisotropy direction a_t = T cos(rotation) + B sin(rotation) (T the mesh's TANGENT,
//! the fibre direction; B = N x T) and a_b = N x a_t. The base colour enters linearly, so for each
//! (roughness, strength, ior, rotation) it is solved per channel by least squares (clamped to
//! [0, 1]); those three are searched on a grid, for rotations 0 and 90 degrees, and polished by
//! argmin's Nelder–Mead. The error is the RMS difference of f N.l (the radiance under unit
//! irradiance, 1/sr) over the directions.

use crate::model::frame::{DirectionPair, Local};
use crate::model::{Albedos, ShadingModel};
use anyhow::{anyhow, Result};
use argmin::core::{CostFunction, Error as ArgminError, Executor, State};
use argmin::solver::neldermead::NelderMead;
use nalgebra::DVector;
use std::f64::consts::PI;

/// Directions the material is fitted over (light and view uniform in solid angle up to 80 deg),
/// as many as the Ward fallback.
pub const DIRECTIONS: usize = crate::fit::ward_fallback::DIRECTIONS;

/// Parameter ranges searched.
pub const ROUGHNESS_RANGE: (f64, f64) = (0.02, 1.0);
pub const IOR_RANGE: (f64, f64) = (1.0, 10.0);

/// A glTF material's BRDF parameters.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PbrMaterial {
    /// baseColorFactor (linear RGB).
    pub base_color: [f64; 3],
    pub roughness: f64,
    /// KHR_materials_anisotropy: anisotropyStrength in [0, 1] and anisotropyRotation (radians,
    /// from the TANGENT towards the bitangent).
    pub anisotropy_strength: f64,
    pub anisotropy_rotation: f64,
    /// KHR_materials_ior.
    pub ior: f64,
}

/// The specular part F D V and the diffuse weight (1 - F)/pi of the glTF BRDF at a local pair
/// (T = x, B = y, N = z), both directions above the horizon.
pub fn pbr_terms(
    roughness: f64,
    strength: f64,
    rotation: f64,
    ior: f64,
    p: &DirectionPair,
) -> (f64, f64) {
    let (l, v) = ([p.l.t, p.l.b, p.l.n], [p.v.t, p.v.b, p.v.n]);
    let mut h = [l[0] + v[0], l[1] + v[1], l[2] + v[2]];
    let hn = (h[0] * h[0] + h[1] * h[1] + h[2] * h[2]).sqrt();
    if !(hn > 0.0) || l[2] <= 0.0 || v[2] <= 0.0 {
        return (0.0, 0.0);
    }
    h.iter_mut().for_each(|x| *x /= hn);
    let (s, c) = rotation.sin_cos();
    // a_t = (c, s, 0), a_b = N x a_t = (-s, c, 0)
    let at = |w: &[f64; 3]| c * w[0] + s * w[1];
    let ab = |w: &[f64; 3]| -s * w[0] + c * w[1];
    let alpha = roughness * roughness;
    let alpha_t = alpha + (1.0 - alpha) * strength * strength;
    let alpha_b = alpha;
    let f = (at(&h) / alpha_t).powi(2) + (ab(&h) / alpha_b).powi(2) + h[2] * h[2];
    let d = 1.0 / (PI * alpha_t * alpha_b * f * f);
    let lam =
        |w: &[f64; 3]| ((alpha_t * at(w)).powi(2) + (alpha_b * ab(w)).powi(2) + w[2] * w[2]).sqrt();
    let vis = 0.5 / (l[2] * lam(&v) + v[2] * lam(&l));
    let f0 = ((ior - 1.0) / (ior + 1.0)).powi(2);
    let vh = (v[0] * h[0] + v[1] * h[1] + v[2] * h[2]).abs();
    let fr = f0 + (1.0 - f0) * (1.0 - vh).powi(5);
    (fr * d * vis, (1.0 - fr) / PI)
}

/// The glTF BRDF of `m` per channel at a local pair.
pub fn pbr_brdf(m: &PbrMaterial, p: &DirectionPair) -> [f64; 3] {
    let (spec, diff) = pbr_terms(
        m.roughness,
        m.anisotropy_strength,
        m.anisotropy_rotation,
        m.ior,
        p,
    );
    m.base_color.map(|b| diff * b + spec)
}

/// A fitted material and how well it matches the model.
#[derive(Clone, Debug)]
pub struct FittedMaterial {
    pub material: PbrMaterial,
    /// RMS of (glTF - model) N.l over the directions and channels (radiance per unit
    /// irradiance, 1/sr); and relative to the RMS of the model's f N.l.
    pub rms_error: f64,
    pub relative_rms_error: f64,
    /// The same fit without anisotropy (strength 0): what the extension gains.
    pub isotropic_relative_rms_error: f64,
    pub directions: usize,
}

/// The fitting set: local pairs, the model's BRDF per channel, and each pair's weight N.l (so
/// residuals are in radiance per unit irradiance, what a preview shows; plain BRDF residuals
/// would be ruled by the 1/N.l growth of fibre BRDFs at grazing light).
struct Targets {
    pairs: Vec<DirectionPair>,
    values: Vec<[f64; 3]>,
    weights: Vec<f64>,
    channels: usize,
}

impl Targets {
    fn new(model: &dyn ShadingModel, albedos: &Albedos, seed: u64) -> Self {
        // xorshift; local directions in the fibre frame, uniform in solid angle up to 80 deg
        let mut s = (seed ^ 0x676c_5446).wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1;
        let mut u = move || {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            (s >> 11) as f64 / (1u64 << 53) as f64
        };
        let cos_max = 80f64.to_radians().cos();
        let mut dir = || {
            let z = cos_max + (1.0 - cos_max) * u();
            let r = (1.0 - z * z).sqrt();
            let p = 2.0 * PI * u();
            Local {
                t: r * p.cos(),
                b: r * p.sin(),
                n: z,
            }
        };
        let pairs: Vec<DirectionPair> = (0..DIRECTIONS)
            .map(|_| DirectionPair { l: dir(), v: dir() })
            .collect();
        let mut bases = vec![Default::default(); pairs.len()];
        model.basis_many(&pairs, &mut bases);
        let channels = albedos.channels();
        let values = bases
            .iter()
            .map(|b: &crate::model::Basis| {
                let mut v = [0.0; 3];
                for (c, x) in v.iter_mut().enumerate() {
                    *x = b.brdf(albedos, c.min(channels - 1));
                }
                v
            })
            .collect();
        let weights = pairs.iter().map(|p| p.l.n).collect();
        Self {
            pairs,
            values,
            weights,
            channels,
        }
    }

    /// Sum of squared residuals and the best base colour for (roughness, strength, ior, rotation).
    fn cost(&self, roughness: f64, strength: f64, ior: f64, rotation: f64) -> (f64, [f64; 3]) {
        let terms: Vec<(f64, f64)> = self
            .pairs
            .iter()
            .map(|p| pbr_terms(roughness, strength, rotation, ior, p))
            .collect();
        let mut base = [0.0; 3];
        let mut sse = 0.0;
        for c in 0..self.channels {
            let (mut num, mut den) = (0.0, 0.0);
            for (((spec, diff), y), w) in terms.iter().zip(&self.values).zip(&self.weights) {
                num += w * w * diff * (y[c] - spec);
                den += w * w * diff * diff;
            }
            let b = if den > 0.0 {
                (num / den).clamp(0.0, 1.0)
            } else {
                0.0
            };
            base[c] = b;
            for (((spec, diff), y), w) in terms.iter().zip(&self.values).zip(&self.weights) {
                sse += (w * (y[c] - diff * b - spec)).powi(2);
            }
        }
        for c in self.channels..3 {
            base[c] = base[0];
        }
        (sse, base)
    }
}

/// Nelder–Mead's objective: the cost at clamped (roughness, strength, ior), plus a penalty
/// outside the ranges so the simplex comes back.
struct Objective<'a> {
    targets: &'a Targets,
    rotation: f64,
    /// Strength fixed at 0 (the isotropic comparison).
    isotropic: bool,
}

impl Objective<'_> {
    fn clamp(&self, x: &DVector<f64>) -> (f64, f64, f64, f64) {
        let r = x[0].clamp(ROUGHNESS_RANGE.0, ROUGHNESS_RANGE.1);
        let s = if self.isotropic {
            0.0
        } else {
            x[1].clamp(0.0, 1.0)
        };
        let i = x[2].clamp(IOR_RANGE.0, IOR_RANGE.1);
        let outside = (x[0] - r).abs()
            + if self.isotropic {
                0.0
            } else {
                (x[1] - s).abs()
            }
            + (x[2] - i).abs();
        (r, s, i, outside)
    }
}

impl CostFunction for Objective<'_> {
    type Param = DVector<f64>;
    type Output = f64;
    fn cost(&self, x: &Self::Param) -> Result<f64, ArgminError> {
        let (r, s, i, outside) = self.clamp(x);
        let (sse, _) = self.targets.cost(r, s, i, self.rotation);
        Ok(sse * (1.0 + outside))
    }
}

/// The best (roughness, strength, ior, rotation) and its cost, with strength 0 if `isotropic`.
fn search(t: &Targets, isotropic: bool) -> Result<(f64, f64, f64, f64, f64)> {
    let mut best = (f64::INFINITY, 0.5, 0.0, 1.5, 0.0);
    let rotations: &[f64] = if isotropic { &[0.0] } else { &[0.0, 0.5 * PI] };
    let strengths: Vec<f64> = if isotropic {
        vec![0.0]
    } else {
        (0..=10).map(|k| k as f64 / 10.0).collect()
    };
    for &rot in rotations {
        for k in 0..24 {
            // log-spaced roughness
            let r =
                ROUGHNESS_RANGE.0 * (ROUGHNESS_RANGE.1 / ROUGHNESS_RANGE.0).powf(k as f64 / 23.0);
            for &s in &strengths {
                for ior in [1.2, 1.5, 2.0, 2.6, 4.0, 7.0] {
                    let (c, _) = t.cost(r, s, ior, rot);
                    if c < best.0 {
                        best = (c, r, s, ior, rot);
                    }
                }
            }
        }
    }
    let (_, r0, s0, i0, rot) = best;
    let objective = Objective {
        targets: t,
        rotation: rot,
        isotropic,
    };
    let start = DVector::from_vec(vec![r0, s0, i0]);
    let mut simplex = vec![start.clone()];
    for (k, step) in [0.1 * r0.max(0.05), 0.1, 0.2].iter().enumerate() {
        let mut p = start.clone();
        p[k] += if p[k] + step > [ROUGHNESS_RANGE.1, 1.0, IOR_RANGE.1][k] {
            -step
        } else {
            *step
        };
        simplex.push(p);
    }
    let solver = NelderMead::new(simplex)
        .with_sd_tolerance(1e-10)
        .map_err(|e| anyhow!("glTF material fit: {e}"))?;
    let res = Executor::new(objective, solver)
        .configure(|c| c.max_iters(300))
        .run()
        .map_err(|e| anyhow!("glTF material fit: {e}"))?;
    let x = res
        .state()
        .get_best_param()
        .cloned()
        .ok_or_else(|| anyhow!("glTF material fit: no solution"))?;
    let objective = Objective {
        targets: t,
        rotation: rot,
        isotropic,
    };
    let (r, s, i, _) = objective.clamp(&x);
    let (c, _) = t.cost(r, s, i, rot);
    Ok(if c <= best.0 { (c, r, s, i, rot) } else { best })
}

/// Fit a glTF material to `model` with `albedos` (the fibre frame's T is the mesh's TANGENT).
pub fn fit(model: &dyn ShadingModel, albedos: &Albedos, seed: u64) -> Result<FittedMaterial> {
    let t = Targets::new(model, albedos, seed);
    let n = (t.values.len() * t.channels) as f64;
    let mean_sq: f64 = t
        .values
        .iter()
        .zip(&t.weights)
        .map(|(v, w)| v[..t.channels].iter().map(|x| (w * x).powi(2)).sum::<f64>())
        .sum::<f64>()
        / n;
    let scale = mean_sq.sqrt().max(f64::MIN_POSITIVE);
    let (c, r, s, i, rot) = search(&t, false)?;
    let (ci, ..) = search(&t, true)?;
    let (_, base) = t.cost(r, s, i, rot);
    let rms = (c / n).sqrt();
    Ok(FittedMaterial {
        material: PbrMaterial {
            base_color: base,
            roughness: r,
            anisotropy_strength: s,
            anisotropy_rotation: rot,
            ior: i,
        },
        rms_error: rms,
        relative_rms_error: rms / scale,
        isotropic_relative_rms_error: (ci / n).sqrt() / scale,
        directions: t.pairs.len(),
    })
}
