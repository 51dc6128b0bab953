//! A glTF 2.0 material fitted to a fitted fibre model, for engines without custom shaders: the
//! core metallic-roughness BRDF (dielectric, metallic 0) with KHR_materials_anisotropy and
//! KHR_materials_ior, and KHR_materials_sheen when it measurably helps ([`SHEEN_GAIN`]), fitted
//! to the model over a dense set of direction pairs ([`DIRECTIONS`]).
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
/// as many as the old Ward fallback had.
pub const DIRECTIONS: usize = 1500;

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
    /// KHR_materials_sheen, when it is part of the material.
    pub sheen: Option<Sheen>,
}

/// KHR_materials_sheen: a grey sheenColorFactor and sheenRoughnessFactor.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Sheen {
    pub colour: f64,
    pub roughness: f64,
}

/// The sheen lobe of KHR_materials_sheen per unit sheen colour at a local pair: the "Charlie"
/// distribution (Estevez and Kulla) and its visibility with the curve-fitted lambda, as the
/// extension's text and the Khronos sample viewer write them.
pub fn sheen_lobe(roughness: f64, p: &DirectionPair) -> f64 {
    let (nl, nv) = (p.l.n, p.v.n);
    if nl <= 0.0 || nv <= 0.0 {
        return 0.0;
    }
    let h = [p.l.t + p.v.t, p.l.b + p.v.b, p.l.n + p.v.n];
    let hn = (h[0] * h[0] + h[1] * h[1] + h[2] * h[2]).sqrt();
    let nh = if hn > 0.0 { h[2] / hn } else { 1.0 };
    let alpha = roughness.max(1e-6).powi(2);
    let inv = 1.0 / alpha;
    let d = (2.0 + inv) * (1.0 - nh * nh).max(0.0).powf(0.5 * inv) / (2.0 * PI);
    let r = (1.0 - alpha) * (1.0 - alpha);
    let mix = |a: f64, b: f64| a + (b - a) * r;
    let curve = |x: f64| {
        mix(21.5473, 25.3245) / (1.0 + mix(3.82987, 3.32435) * x.powf(mix(0.19823, 0.16801)))
            + mix(-1.97760, -1.27393) * x
            + mix(-4.32054, -4.85967)
    };
    let lambda = |c: f64| {
        if c < 0.5 {
            curve(c).exp()
        } else {
            (2.0 * curve(0.5) - curve(1.0 - c)).exp()
        }
    };
    let v = (1.0 / ((1.0 + lambda(nv) + lambda(nl)) * 4.0 * nv * nl)).clamp(0.0, 1.0);
    d * v
}

/// The sheen lobe's directional albedo E(mu) = int sheen_lobe cos dw over the light directions,
/// tabulated at mu = 0, 1/32, .., 1 (midpoint rule, 32 polar x 32 azimuths over the half the
/// lobe's mirror symmetry leaves), for the extension's albedo scaling
/// of the base: min(1 - c E(N.v), 1 - c E(N.l)).
fn sheen_albedo_table(roughness: f64) -> [f64; 33] {
    let mut out = [0.0; 33];
    let (nt, np) = (32, 32);
    for (k, o) in out.iter_mut().enumerate() {
        let mu = (k as f64 / 32.0).max(1e-4);
        let v = Local {
            t: (1.0 - mu * mu).sqrt(),
            b: 0.0,
            n: mu,
        };
        let mut sum = 0.0;
        for i in 0..nt {
            let th = (i as f64 + 0.5) / nt as f64 * 0.5 * PI;
            let (st, ct) = th.sin_cos();
            for j in 0..np {
                let ph = (j as f64 + 0.5) / np as f64 * PI;
                let l = Local {
                    t: st * ph.cos(),
                    b: st * ph.sin(),
                    n: ct,
                };
                sum += sheen_lobe(roughness, &DirectionPair { l, v }) * ct * st;
            }
        }
        // the other half of the azimuths mirrors this one
        *o = 2.0 * sum * (0.5 * PI / nt as f64) * (PI / np as f64);
    }
    out
}

fn table_at(table: &[f64; 33], mu: f64) -> f64 {
    let x = mu.clamp(0.0, 1.0) * 32.0;
    let i = (x as usize).min(31);
    let f = x - i as f64;
    table[i] * (1.0 - f) + table[i + 1] * f
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
    /// The same fit without anisotropy (strength 0, no sheen): what the extension gains.
    pub isotropic_relative_rms_error: f64,
    /// The anisotropic fit without and with a sheen layer (the sheen goes in only when it
    /// gains [`SHEEN_GAIN`]).
    pub without_sheen_relative_rms_error: f64,
    pub with_sheen_relative_rms_error: f64,
    pub directions: usize,
}

/// The fitting set: local pairs, the model's BRDF per channel, and each pair's weight N.l (so
/// residuals are in radiance per unit irradiance, what a preview shows; plain BRDF residuals
/// would be ruled by the 1/N.l growth of fibre BRDFs at grazing light).
struct Targets {
    pairs: Vec<DirectionPair>,
    /// The model's basis (BRDF per unit albedo of each component) at each pair.
    bases: Vec<crate::model::Basis>,
    values: Vec<[f64; 3]>,
    weights: Vec<f64>,
    channels: usize,
}

impl Targets {
    fn new(model: &dyn ShadingModel, albedos: &Albedos, seed: u64) -> Self {
        Self::of(model, albedos, seed, None).expect("the model's own basis")
    }

    /// The targets of `model` with its fibre topology fixed at `height` (one texel); `None` for
    /// a model without a topology.
    fn at_height(
        model: &dyn ShadingModel,
        albedos: &Albedos,
        seed: u64,
        height: f64,
    ) -> Option<Self> {
        Self::of(model, albedos, seed, Some(height))
    }

    fn of(
        model: &dyn ShadingModel,
        albedos: &Albedos,
        seed: u64,
        height: Option<f64>,
    ) -> Option<Self> {
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
        match height {
            None => model.basis_many(&pairs, &mut bases),
            Some(h) => {
                if !model.basis_many_at_height(&pairs, h, &mut bases) {
                    return None;
                }
            }
        }
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
        Some(Self {
            pairs,
            bases,
            values,
            weights,
            channels,
        })
    }

    /// Per pair, the glTF BRDF of a shape as `fixed + diff * base`: the part that does not
    /// scale with the base colour, and the one that does.
    fn terms(&self, shape: &Shape) -> Vec<(f64, f64)> {
        let table = shape.sheen.map(|sh| sheen_albedo_table(sh.roughness));
        self.pairs
            .iter()
            .map(|p| {
                let (spec, diff) = pbr_terms(
                    shape.roughness,
                    shape.strength,
                    shape.rotation,
                    shape.ior,
                    p,
                );
                match (shape.sheen, &table) {
                    (Some(sh), Some(e)) => {
                        let scale = (1.0 - sh.colour * table_at(e, p.v.n))
                            .min(1.0 - sh.colour * table_at(e, p.l.n));
                        (
                            sh.colour * sheen_lobe(sh.roughness, p) + scale * spec,
                            scale * diff,
                        )
                    }
                    _ => (spec, diff),
                }
            })
            .collect()
    }

    /// The least-squares base colour of `shape` as a linear function of the albedos.
    fn base_law(&self, shape: &Shape) -> BaseColourLaw {
        let mut law = BaseColourLaw {
            per_albedo: [0.0; 4],
            fixed: 0.0,
            norm: 0.0,
        };
        for (((fixed, diff), b), w) in self.terms(shape).iter().zip(&self.bases).zip(&self.weights)
        {
            let wd = w * w * diff;
            law.per_albedo[0] += wd * b.diffuse;
            law.per_albedo[1] += wd * b.specular;
            law.per_albedo[2] += wd * b.substrate;
            law.per_albedo[3] += wd * b.fuzz;
            law.fixed += wd * fixed;
            law.norm += wd * diff;
        }
        law
    }

    /// Sum of squared residuals and the best base colour (per channel, least squares, clamped
    /// to [0, 1]) for a shape.
    fn cost(&self, shape: &Shape) -> (f64, [f64; 3]) {
        let terms = self.terms(shape);
        let mut base = [0.0; 3];
        let mut sse = 0.0;
        for c in 0..self.channels {
            let (mut num, mut den) = (0.0, 0.0);
            for (((fixed, diff), y), w) in terms.iter().zip(&self.values).zip(&self.weights) {
                num += w * w * diff * (y[c] - fixed);
                den += w * w * diff * diff;
            }
            let b = if den > 0.0 {
                (num / den).clamp(0.0, 1.0)
            } else {
                0.0
            };
            base[c] = b;
            for (((fixed, diff), y), w) in terms.iter().zip(&self.values).zip(&self.weights) {
                sse += (w * (y[c] - diff * b - fixed)).powi(2);
            }
        }
        for c in self.channels..3 {
            base[c] = base[0];
        }
        (sse, base)
    }
}

/// Everything of a material but its base colour.
#[derive(Clone, Copy, Debug)]
struct Shape {
    roughness: f64,
    strength: f64,
    ior: f64,
    rotation: f64,
    sheen: Option<Sheen>,
}

/// Which parameters a search varies.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Mode {
    /// Strength 0.
    Isotropic,
    Anisotropic,
    /// Anisotropic with a sheen layer.
    Sheen,
}

/// Nelder–Mead's objective: the cost at the clamped parameters, with a penalty outside the
/// ranges so the simplex comes back. x = (roughness, strength, ior[, sheen colour, sheen
/// roughness]).
struct Objective<'a> {
    targets: &'a Targets,
    rotation: f64,
    mode: Mode,
}

impl Objective<'_> {
    fn shape(&self, x: &DVector<f64>) -> (Shape, f64) {
        let clamp = |v: f64, lo: f64, hi: f64| (v.clamp(lo, hi), (v - v.clamp(lo, hi)).abs());
        let (r, o1) = clamp(x[0], ROUGHNESS_RANGE.0, ROUGHNESS_RANGE.1);
        let (s, o2) = if self.mode == Mode::Isotropic {
            (0.0, 0.0)
        } else {
            clamp(x[1], 0.0, 1.0)
        };
        let (i, o3) = clamp(x[2], IOR_RANGE.0, IOR_RANGE.1);
        let (sheen, o4) = if self.mode == Mode::Sheen {
            let (c, a) = clamp(x[3], 0.0, 1.0);
            let (sr, b) = clamp(x[4], 0.05, 1.0);
            (
                Some(Sheen {
                    colour: c,
                    roughness: sr,
                }),
                a + b,
            )
        } else {
            (None, 0.0)
        };
        (
            Shape {
                roughness: r,
                strength: s,
                ior: i,
                rotation: self.rotation,
                sheen,
            },
            o1 + o2 + o3 + o4,
        )
    }
}

impl CostFunction for Objective<'_> {
    type Param = DVector<f64>;
    type Output = f64;
    fn cost(&self, x: &Self::Param) -> Result<f64, ArgminError> {
        let (shape, outside) = self.shape(x);
        let (sse, _) = self.targets.cost(&shape);
        Ok(sse * (1.0 + outside))
    }
}

/// Polish `start` with Nelder–Mead; the better of the two.
fn polish(t: &Targets, mode: Mode, start: (f64, Shape)) -> Result<(f64, Shape)> {
    let s0 = start.1;
    let mut x0 = vec![s0.roughness, s0.strength, s0.ior];
    let mut steps = vec![0.1 * s0.roughness.max(0.05), 0.1, 0.2];
    let mut highs = vec![ROUGHNESS_RANGE.1, 1.0, IOR_RANGE.1];
    if let Some(sh) = s0.sheen {
        x0.extend([sh.colour, sh.roughness]);
        steps.extend([0.1, 0.1]);
        highs.extend([1.0, 1.0]);
    }
    let start_x = DVector::from_vec(x0);
    let mut simplex = vec![start_x.clone()];
    for (k, step) in steps.iter().enumerate() {
        let mut p = start_x.clone();
        p[k] += if p[k] + step > highs[k] { -step } else { *step };
        simplex.push(p);
    }
    let objective = Objective {
        targets: t,
        rotation: s0.rotation,
        mode,
    };
    let solver = NelderMead::new(simplex)
        .with_sd_tolerance(1e-10)
        .map_err(|e| anyhow!("glTF material fit: {e}"))?;
    let res = Executor::new(objective, solver)
        .configure(|c| c.max_iters(if mode == Mode::Sheen { 400 } else { 300 }))
        .run()
        .map_err(|e| anyhow!("glTF material fit: {e}"))?;
    let x = res
        .state()
        .get_best_param()
        .cloned()
        .ok_or_else(|| anyhow!("glTF material fit: no solution"))?;
    let objective = Objective {
        targets: t,
        rotation: s0.rotation,
        mode,
    };
    let (shape, _) = objective.shape(&x);
    let (c, _) = t.cost(&shape);
    Ok(if c <= start.0 { (c, shape) } else { start })
}

/// The best shape and its cost: a grid (roughness, strength, ior, rotation 0 and 90 deg), then
/// Nelder–Mead; with `Mode::Sheen`, from the anisotropic optimum `base` over a grid of sheen
/// colours and roughnesses.
fn search(t: &Targets, mode: Mode, base: Option<Shape>) -> Result<(f64, Shape)> {
    let mut best = (
        f64::INFINITY,
        Shape {
            roughness: 0.5,
            strength: 0.0,
            ior: 1.5,
            rotation: 0.0,
            sheen: None,
        },
    );
    if let (Mode::Sheen, Some(b)) = (mode, base) {
        for colour in [0.1, 0.3, 0.6, 1.0] {
            for roughness in [0.2, 0.4, 0.6, 0.8, 1.0] {
                let shape = Shape {
                    sheen: Some(Sheen { colour, roughness }),
                    ..b
                };
                let (c, _) = t.cost(&shape);
                if c < best.0 {
                    best = (c, shape);
                }
            }
        }
        return polish(t, mode, best);
    }
    let rotations: &[f64] = if mode == Mode::Isotropic {
        &[0.0]
    } else {
        &[0.0, 0.5 * PI]
    };
    let strengths: Vec<f64> = if mode == Mode::Isotropic {
        vec![0.0]
    } else {
        (0..=10).map(|k| k as f64 / 10.0).collect()
    };
    for &rotation in rotations {
        for k in 0..24 {
            // log-spaced roughness
            let roughness =
                ROUGHNESS_RANGE.0 * (ROUGHNESS_RANGE.1 / ROUGHNESS_RANGE.0).powf(k as f64 / 23.0);
            for &strength in &strengths {
                for ior in [1.2, 1.5, 2.0, 2.6, 4.0, 7.0] {
                    let shape = Shape {
                        roughness,
                        strength,
                        ior,
                        rotation,
                        sheen: None,
                    };
                    let (c, _) = t.cost(&shape);
                    if c < best.0 {
                        best = (c, shape);
                    }
                }
            }
        }
    }
    polish(t, mode, best)
}

/// A sheen layer goes into the material only when it lowers the relative RMS error by at least
/// this fraction of itself (it measurably helps), since engines differ most in how they render
/// it (the albedo-scaling tables).
pub const SHEEN_GAIN: f64 = 0.1;

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
    let relative = |c: f64| (c / n).sqrt() / scale;
    let (c, shape) = search(&t, Mode::Anisotropic, None)?;
    let (ci, _) = search(&t, Mode::Isotropic, None)?;
    let (cs, sheen_shape) = search(&t, Mode::Sheen, Some(shape))?;
    let with_sheen = relative(cs) <= (1.0 - SHEEN_GAIN) * relative(c);
    let (cost, chosen) = if with_sheen {
        (cs, sheen_shape)
    } else {
        (c, shape)
    };
    let (_, base) = t.cost(&chosen);
    Ok(FittedMaterial {
        material: PbrMaterial {
            base_color: base,
            roughness: chosen.roughness,
            anisotropy_strength: chosen.strength,
            anisotropy_rotation: chosen.rotation,
            ior: chosen.ior,
            sheen: chosen.sheen,
        },
        rms_error: (cost / n).sqrt(),
        relative_rms_error: relative(cost),
        isotropic_relative_rms_error: relative(ci),
        without_sheen_relative_rms_error: relative(c),
        with_sheen_relative_rms_error: relative(cs),
        directions: t.pairs.len(),
    })
}

/// The least-squares base colour of one shape as a linear function of the albedos. Per pair the
/// glTF BRDF is `fixed + diff * base` and the model's `sum_k a_k basis_k` (k: diffuse, specular,
/// substrate, fuzz), so the base colour minimising the weighted squares is
/// `(sum_k a_k G_k - F) / D`, clamped to [0, 1]: one texel's albedos give its base colour
/// without another pass over the directions.
#[derive(Clone, Copy, Debug)]
struct BaseColourLaw {
    /// G_k = sum w^2 diff basis_k.
    per_albedo: [f64; 4],
    /// F = sum w^2 diff fixed.
    fixed: f64,
    /// D = sum w^2 diff^2.
    norm: f64,
}

impl BaseColourLaw {
    fn base(&self, a: &Albedos) -> [f64; 3] {
        std::array::from_fn(|c| {
            if self.norm > 0.0 {
                let g = &self.per_albedo;
                ((g[0] * a.diffuse[c]
                    + g[1] * a.specular[c]
                    + g[2] * a.substrate[c]
                    + g[3] * a.fuzz[c]
                    - self.fixed)
                    / self.norm)
                    .clamp(0.0, 1.0)
            } else {
                0.0
            }
        })
    }
}

fn shape_of(m: &PbrMaterial) -> Shape {
    Shape {
        roughness: m.roughness,
        strength: m.anisotropy_strength,
        ior: m.ior,
        rotation: m.anisotropy_rotation,
        sheen: m.sheen,
    }
}

/// The least-squares base colour of `m`'s shape (everything but its base colour) for `model`
/// with `albedos`, over the fit's directions (`seed` as in [`fit`]): what [`fit`] gives as the
/// base colour when its shape is `m`'s.
pub fn base_color(
    model: &dyn ShadingModel,
    albedos: &Albedos,
    m: &PbrMaterial,
    seed: u64,
) -> [f64; 3] {
    Targets::new(model, albedos, seed).cost(&shape_of(m)).1
}

/// Height nodes of a [`TexelMaterials`] table at most (over the texels' height range).
pub const HEIGHT_NODES: usize = 9;

/// The glTF shape refitted at one texel height: roughness and anisotropy strength (ior,
/// rotation and sheen kept from the global material).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HeightNode {
    /// H, fibre radii.
    pub height: f64,
    pub roughness: f64,
    pub anisotropy_strength: f64,
    /// Relative RMS error of f N.l against the model at this height (the global albedos).
    pub relative_rms_error: f64,
}

/// One texel's glTF material parameters.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TexelMaterial {
    /// Linear RGB in [0, 1].
    pub base_color: [f64; 3],
    pub roughness: f64,
    pub anisotropy_strength: f64,
}

/// Per-texel glTF parameters from a `fit --maps` result's maps, given the global material:
/// - base colour: the least-squares base colour of the texel's shape for the texel's albedos
///   (its kd and ks maps, the substrate following kd when tied to it), exactly as [`fit`]
///   solves it for the global albedos (so a texel with the global albedos gets the global
///   base colour);
/// - with a height map (rungs with a topology): roughness and anisotropy strength refitted to
///   the model at [`HEIGHT_NODES`] heights across the texels' range (ior, rotation, sheen the
///   global ones), linear between the nodes, and the base colour of the nodes' shapes likewise;
///   a texel without a height takes the global material's shape.
pub struct TexelMaterials {
    global: (TexelMaterial, BaseColourLaw),
    nodes: Vec<(HeightNode, BaseColourLaw)>,
}

/// Nelder–Mead's objective at one height: x = (roughness, strength), the rest of `base` kept.
struct NodeObjective<'a> {
    targets: &'a Targets,
    base: Shape,
}

impl NodeObjective<'_> {
    fn shape(&self, x: &DVector<f64>) -> (Shape, f64) {
        let r = x[0].clamp(ROUGHNESS_RANGE.0, ROUGHNESS_RANGE.1);
        let s = x[1].clamp(0.0, 1.0);
        (
            Shape {
                roughness: r,
                strength: s,
                ..self.base
            },
            (x[0] - r).abs() + (x[1] - s).abs(),
        )
    }
}

impl CostFunction for NodeObjective<'_> {
    type Param = DVector<f64>;
    type Output = f64;
    fn cost(&self, x: &Self::Param) -> Result<f64, ArgminError> {
        let (shape, outside) = self.shape(x);
        Ok(self.targets.cost(&shape).0 * (1.0 + outside))
    }
}

/// Roughness and strength at one height: the grid of [`search`] from the global shape `base`,
/// then Nelder–Mead; the cost too.
fn node_shape(t: &Targets, base: Shape) -> Result<(f64, Shape)> {
    let mut best = (t.cost(&base).0, base);
    for k in 0..24 {
        let roughness =
            ROUGHNESS_RANGE.0 * (ROUGHNESS_RANGE.1 / ROUGHNESS_RANGE.0).powf(k as f64 / 23.0);
        for j in 0..=10 {
            let shape = Shape {
                roughness,
                strength: j as f64 / 10.0,
                ..base
            };
            let c = t.cost(&shape).0;
            if c < best.0 {
                best = (c, shape);
            }
        }
    }
    let s0 = best.1;
    let x0 = DVector::from_vec(vec![s0.roughness, s0.strength]);
    let mut simplex = vec![x0.clone()];
    for (k, step) in [0.1 * s0.roughness.max(0.05), 0.1].into_iter().enumerate() {
        let mut p = x0.clone();
        p[k] += if p[k] + step > 1.0 { -step } else { step };
        simplex.push(p);
    }
    let objective = NodeObjective { targets: t, base };
    let solver = NelderMead::new(simplex)
        .with_sd_tolerance(1e-10)
        .map_err(|e| anyhow!("glTF material fit at a height: {e}"))?;
    let res = Executor::new(objective, solver)
        .configure(|c| c.max_iters(200))
        .run()
        .map_err(|e| anyhow!("glTF material fit at a height: {e}"))?;
    let x = res
        .state()
        .get_best_param()
        .cloned()
        .ok_or_else(|| anyhow!("glTF material fit at a height: no solution"))?;
    let (shape, _) = NodeObjective { targets: t, base }.shape(&x);
    let c = t.cost(&shape).0;
    Ok(if c <= best.0 { (c, shape) } else { best })
}

impl TexelMaterials {
    /// The table for `model` with the global `albedos` and the global material `fitted` (from
    /// [`fit`] with `seed`), with height nodes over `heights` (the texels' least and largest
    /// H) when given and the model has a topology.
    pub fn new(
        model: &dyn ShadingModel,
        albedos: &Albedos,
        fitted: &FittedMaterial,
        heights: Option<(f64, f64)>,
        seed: u64,
    ) -> Result<Self> {
        use rayon::prelude::*;
        let m = &fitted.material;
        let base = shape_of(m);
        let global = (
            TexelMaterial {
                base_color: m.base_color,
                roughness: m.roughness,
                anisotropy_strength: m.anisotropy_strength,
            },
            Targets::new(model, albedos, seed).base_law(&base),
        );
        let mut nodes = Vec::new();
        if let Some((lo, hi)) =
            heights.filter(|_| model.rung().has(crate::model::Ability::Topology))
        {
            let k = if hi - lo > 1e-9 { HEIGHT_NODES } else { 1 };
            let hs: Vec<f64> = (0..k)
                .map(|i| {
                    if k == 1 {
                        lo
                    } else {
                        lo + (hi - lo) * i as f64 / (k - 1) as f64
                    }
                })
                .collect();
            nodes = hs
                .par_iter()
                .map(|&h| -> Result<Option<(HeightNode, BaseColourLaw)>> {
                    let Some(t) = Targets::at_height(model, albedos, seed, h) else {
                        return Ok(None);
                    };
                    let n = (t.values.len() * t.channels) as f64;
                    let mean_sq: f64 = t
                        .values
                        .iter()
                        .zip(&t.weights)
                        .map(|(v, w)| v[..t.channels].iter().map(|x| (w * x).powi(2)).sum::<f64>())
                        .sum::<f64>()
                        / n;
                    let (cost, shape) = node_shape(&t, base)?;
                    Ok(Some((
                        HeightNode {
                            height: h,
                            roughness: shape.roughness,
                            anisotropy_strength: shape.strength,
                            relative_rms_error: (cost / n).sqrt()
                                / mean_sq.sqrt().max(f64::MIN_POSITIVE),
                        },
                        t.base_law(&shape),
                    )))
                })
                .collect::<Result<Vec<_>>>()?
                .into_iter()
                .flatten()
                .collect();
        }
        Ok(Self { global, nodes })
    }

    /// The height nodes (empty without a height map or a topology).
    pub fn nodes(&self) -> Vec<HeightNode> {
        self.nodes.iter().map(|(n, _)| *n).collect()
    }

    /// The material of a texel with `height` (`None`: the model's own topology) and `albedos`.
    pub fn at(&self, height: Option<f64>, albedos: &Albedos) -> TexelMaterial {
        let (Some(h), Some(first)) = (height, self.nodes.first()) else {
            let (g, law) = &self.global;
            return TexelMaterial {
                base_color: law.base(albedos),
                ..*g
            };
        };
        let last = self.nodes.last().expect("non-empty");
        let (a, b, f) = if self.nodes.len() == 1 || h <= first.0.height {
            (first, first, 0.0)
        } else if h >= last.0.height {
            (last, last, 0.0)
        } else {
            let i = self
                .nodes
                .windows(2)
                .position(|w| h <= w[1].0.height)
                .unwrap_or(self.nodes.len() - 2);
            let (a, b) = (&self.nodes[i], &self.nodes[i + 1]);
            (a, b, (h - a.0.height) / (b.0.height - a.0.height))
        };
        let lerp = |x: f64, y: f64| x + (y - x) * f;
        let (ba, bb) = (a.1.base(albedos), b.1.base(albedos));
        TexelMaterial {
            base_color: std::array::from_fn(|c| lerp(ba[c], bb[c]).clamp(0.0, 1.0)),
            roughness: lerp(a.0.roughness, b.0.roughness),
            anisotropy_strength: lerp(a.0.anisotropy_strength, b.0.anisotropy_strength),
        }
    }
}
