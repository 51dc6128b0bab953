//! The exported shader against the Rust model: the cases (random pairs in random frames, the
//! extremes, texel heights and azimuth offsets) and the comparison.

use super::gpu::Gpu;
pub use super::gpu::{Case, Output};
use crate::model::frame::{DirectionPair, Local, Vec3};
use crate::model::{Albedos, Basis, ShadingModel};
use crate::model::{ModelId, ModelParams};
use anyhow::Result;

/// Deterministic xorshift (the cases are the same on every run).
struct Rng(u64);

impl Rng {
    fn uniform(&mut self) -> f64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        (self.0 >> 11) as f64 / (1u64 << 53) as f64
    }

    fn unit(&mut self) -> Vec3 {
        let z = 2.0 * self.uniform() - 1.0;
        let r = (1.0 - z * z).max(0.0).sqrt();
        let p = std::f64::consts::TAU * self.uniform();
        Vec3::new(r * p.cos(), r * p.sin(), z)
    }
}

fn f32s(v: &Vec3) -> [f32; 3] {
    [v.x as f32, v.y as f32, v.z as f32]
}

/// A random orthonormal frame (n, t).
fn frame(rng: &mut Rng) -> (Vec3, Vec3) {
    let n = rng.unit();
    let a = rng.unit();
    let t = (a - n * a.dot(&n)).normalize();
    (n, t)
}

/// Local (t, b, n) components to world directions of the frame (n, t).
fn world(local: [f64; 3], n: &Vec3, t: &Vec3) -> Vec3 {
    let b = n.cross(t);
    (t * local[0] + b * local[1] + n * local[2]).normalize()
}

/// Local directions at the extremes the Rust tests cover: along and across the fibre, grazing
/// (1e-3 and 1e-6 above the horizon), at and below the horizon, the normal, mirror pairs.
fn extreme_locals() -> Vec<[f64; 3]> {
    let g = |x: f64, y: f64, z: f64| {
        let n = (x * x + y * y + z * z).sqrt();
        [x / n, y / n, z / n]
    };
    vec![
        [0.0, 0.0, 1.0],
        g(1.0, 0.0, 1e-3),
        g(1.0, 0.0, 1e-6),
        g(0.0, 1.0, 1e-3),
        g(0.0, -1.0, 1e-6),
        g(0.0, 1.0, 0.0),
        g(0.6, 0.8, 0.0),
        g(0.3, 0.2, -0.5),
        g(1.0, 0.0, 1.0),
        g(0.0, 1.0, 1.0),
        g(-0.7, 0.1, 0.2),
        g(0.2, -0.9, 0.05),
        g(0.5, 0.5, 0.7),
        g(-0.5, 0.5, 0.3),
    ]
}

/// `random` random pairs (uniform over the upper hemisphere, random frames, a third of them at
/// a random texel height in [0, `max_height`] and azimuth offset) and every pair of the extremes
/// (with their mirrors and their T -> -T twins; some at H_max, some flat), deterministic from
/// `seed`.
pub fn cases(random: usize, seed: u64, max_height: f64) -> Vec<Case> {
    let mut rng = Rng(seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1);
    let mut out = Vec::with_capacity(random + 600);
    for i in 0..random {
        let (n, t) = frame(&mut rng);
        let up = |rng: &mut Rng| {
            let z: f64 = rng.uniform();
            let r = (1.0 - z * z).sqrt();
            let p = std::f64::consts::TAU * rng.uniform();
            [r * p.cos(), r * p.sin(), z]
        };
        let (l, v) = (up(&mut rng), up(&mut rng));
        let at = (i % 3 == 2).then(|| {
            (
                (rng.uniform() * max_height) as f32,
                ((rng.uniform() - 0.5) * std::f64::consts::PI) as f32,
            )
        });
        out.push(Case {
            l: f32s(&world(l, &n, &t)),
            v: f32s(&world(v, &n, &t)),
            n: f32s(&n),
            t: f32s(&t),
            at,
        });
    }
    let ext = extreme_locals();
    let z = Vec3::new(0.0, 0.0, 1.0);
    let x = Vec3::new(1.0, 0.0, 0.0);
    for (k, l) in ext.iter().enumerate() {
        let mirror = [-l[0], -l[1], l[2]];
        for v in ext.iter().chain(std::iter::once(&mirror)) {
            for flip in [false, true] {
                let t = if flip { -x } else { x };
                // both elevation limits of the texel forms: H_max and flat
                let at = match k % 4 {
                    1 => Some((max_height as f32, 0.0)),
                    3 => Some((0.0, 0.0)),
                    _ => None,
                };
                out.push(Case {
                    l: f32s(&world(*l, &z, &x)),
                    v: f32s(&world(*v, &z, &x)),
                    n: f32s(&z),
                    t: f32s(&t),
                    at,
                });
            }
        }
    }
    out
}

/// A case's pair in the fibre frame, from its f32 values (in f64), built as the shader builds
/// it: t made perpendicular to n, B = N x T, turned by the azimuth offset of a texel case.
pub fn local_pair(c: &Case) -> DirectionPair {
    let v3 = |a: [f32; 3]| Vec3::new(a[0] as f64, a[1] as f64, a[2] as f64);
    let (l, v, n, t) = (v3(c.l), v3(c.v), v3(c.n), v3(c.t));
    let tp = (t - n * t.dot(&n)).normalize();
    let mut tt = tp;
    let mut bt = n.cross(&tp);
    if let Some((_, off)) = c.at {
        let (s, co) = (off as f64).sin_cos();
        let t2 = tt * co + bt * s;
        bt = bt * co - tt * s;
        tt = t2;
    }
    let local = |w: &Vec3| Local {
        t: w.dot(&tt),
        b: w.dot(&bt),
        n: w.dot(&n),
    };
    DirectionPair {
        l: local(&l),
        v: local(&v),
    }
}

/// The Rust model's basis at a case ([`local_pair`]; at its height for a texel case).
pub fn rust_basis(model: &dyn ShadingModel, c: &Case) -> Basis {
    let pair = local_pair(c);
    match c.at {
        Some((h, _)) => model
            .basis_at_height(&pair, h as f64)
            .unwrap_or_else(|| model.basis(&pair)),
        None => model.basis(&pair),
    }
}

/// What f32 allows, as a relative error of each value (compared relative to max(|Rust value|,
/// 1e-4 of the largest Rust value of that quantity over the cases)).
///
/// Why these: directions reach the shader as f32, so each carries a rounding of ~6e-8 the Rust
/// model (f64, from the same f32 values) does not add again. The Phong lobe (r.v)^e has relative
/// sensitivity e to r.v, so near its peak one ulp of a direction moves it by ~e x 6e-8 (6e-4 at
/// e = 1e4): no f32 evaluation does better, hence the term in e. Grazing directions divide by
/// N.l (the BRDF's 1/cos) and resolve angles near 90 deg only to ulp(pi/2) = 1.2e-7, so the
/// relative error grows as ~1.2e-7 / min(N.l, N.v): 12 % at N.v = 1e-6 (0.00006 deg above the
/// horizon, where f cos is ~1e-6 of its size), 1e-4 at 1e-3.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Bound {
    /// The 99th percentile over the cases.
    pub p99: f64,
    /// Every case, away from the horizon.
    pub max: f64,
    /// Added to `max` for a case as `grazing / min(N.l, N.v)`.
    pub grazing: f64,
}

impl Bound {
    pub fn for_exponent(e: f64) -> Self {
        Self {
            p99: 5e-5 + 3e-7 * e,
            max: 3e-3 + 5e-7 * e,
            grazing: 2.4e-7,
        }
    }

    /// The tolerance of one case whose smaller cosine to the normal is `min_cos`.
    pub fn case_tolerance(&self, min_cos: f64) -> f64 {
        self.max + self.grazing / min_cos.max(1e-300)
    }

    /// Whether the agreement is within the bound (and the shader gave no non-finite or
    /// negative value).
    pub fn holds(&self, a: &Agreement) -> bool {
        a.p99_relative <= self.p99
            && a.worst_over_tolerance <= 1.0
            && a.non_finite == 0
            && a.negative == 0
    }
}

/// How far the shader is from the Rust model over a set of cases.
#[derive(Clone, Debug, Default)]
pub struct Agreement {
    pub cases: usize,
    /// Largest and 99th-percentile relative error over the cases (each case's worst of its BRDF
    /// channels and basis components; see [`Bound`] for how values are compared).
    pub max_relative: f64,
    pub p99_relative: f64,
    /// The largest ratio of a case's error to its tolerance under the bound used (<= 1 passes).
    pub worst_over_tolerance: f64,
    /// The worst case by that ratio: its index, the Rust and the shader value.
    pub worst: (usize, f64, f64),
    /// Values the shader returned non-finite, or negative where the Rust model is not.
    pub non_finite: usize,
    pub negative: usize,
}

/// The local cosines (N.l, N.v) of a case as the Rust model sees it.
fn cosines(c: &Case) -> (f64, f64) {
    let v3 = |a: [f32; 3]| Vec3::new(a[0] as f64, a[1] as f64, a[2] as f64);
    let n = v3(c.n);
    (v3(c.l).dot(&n), v3(c.v).dot(&n))
}

/// Compare shader `outputs` with the Rust model at `cases` under `bound`.
pub fn compare(
    model: &dyn ShadingModel,
    albedos: &Albedos,
    channels: usize,
    cases: &[Case],
    outputs: &[Output],
    bound: &Bound,
) -> Agreement {
    compare_corrected(model, albedos, channels, None, cases, outputs, bound)
}

/// [`compare`] with the result's smooth correction `correction` on the Rust model's BRDF (the
/// basis compared as it is).
pub fn compare_corrected(
    model: &dyn ShadingModel,
    albedos: &Albedos,
    channels: usize,
    correction: Option<&crate::model::correction::Correction>,
    cases: &[Case],
    outputs: &[Output],
    bound: &Bound,
) -> Agreement {
    const FLOOR: f64 = 1e-4;
    // per case: 3 BRDF channels and 4 basis components (Rust, shader)
    let mut values: Vec<[(f64, f64); 7]> = Vec::with_capacity(cases.len());
    for (c, o) in cases.iter().zip(outputs) {
        let b = rust_basis(model, c);
        let rb = [b.diffuse, b.specular, b.substrate, b.fuzz];
        let factor = match correction {
            Some(k) => k.factor(&local_pair(c)),
            None => [1.0; 3],
        };
        let mut row = [(0.0, 0.0); 7];
        for (ch, (slot, g)) in row[..3].iter_mut().zip(o.brdf).enumerate() {
            *slot = (b.brdf(albedos, ch.min(channels - 1)) * factor[ch.min(channels - 1)], g as f64);
        }
        for ((slot, want), got) in row[3..].iter_mut().zip(rb).zip(o.basis) {
            *slot = (want, got as f64);
        }
        values.push(row);
    }
    let mut peak = [0.0f64; 7];
    for row in &values {
        for k in 0..7 {
            peak[k] = peak[k].max(row[k].0.abs());
        }
    }
    let mut a = Agreement {
        cases: cases.len(),
        ..Default::default()
    };
    let mut errors = Vec::with_capacity(values.len());
    for (i, (row, c)) in values.iter().zip(cases).enumerate() {
        let (cl, cv) = cosines(c);
        let min_cos = cl.min(cv);
        let mut worst: f64 = 0.0;
        let mut worst_pair = (0.0, 0.0);
        for (k, &(r, g)) in row.iter().enumerate() {
            if !g.is_finite() {
                a.non_finite += 1;
                worst = f64::INFINITY;
                worst_pair = (r, g);
                continue;
            }
            // negative where the model is not (MaterialX's fuzz albedo fit dips below zero for
            // fuzz roughness in (0.041, 0.132): the `openpbr` rung and its shader both do)
            if g < 0.0 && r >= 0.0 {
                a.negative += 1;
            }
            let e = if min_cos <= -1e-6 {
                // below a horizon: exactly zero
                if g == 0.0 {
                    0.0
                } else {
                    f64::INFINITY
                }
            } else {
                (g - r).abs() / r.abs().max(FLOOR * peak[k]).max(f64::MIN_POSITIVE)
            };
            if e > worst {
                worst = e;
                worst_pair = (r, g);
            }
        }
        let ratio = if min_cos.abs() < 1e-6 && min_cos <= 0.0 {
            0.0
        } else {
            worst / bound.case_tolerance(min_cos)
        };
        if i == 0 || ratio > a.worst_over_tolerance {
            a.worst_over_tolerance = ratio;
            a.worst = (i, worst_pair.0, worst_pair.1);
        }
        errors.push(worst);
    }
    errors.sort_by(f64::total_cmp);
    if !errors.is_empty() {
        a.p99_relative = errors[(errors.len() * 99 / 100).min(errors.len() - 1)];
        a.max_relative = *errors.last().unwrap_or(&0.0);
    }
    a
}

/// Run the exported `wgsl` of rung `id` with parameters `p` on `gpu` at `cases` and compare it
/// with the Rust model under the bound for its exponent.
pub fn on_gpu(
    gpu: &Gpu,
    wgsl: &str,
    id: ModelId,
    p: &ModelParams,
    cases: &[Case],
) -> Result<(Agreement, Bound)> {
    let model = crate::model::build(id, p)?;
    let outputs = gpu.evaluate(wgsl, cases)?;
    let bound = Bound::for_exponent(p.exponent);
    let a = compare_corrected(
        model.as_ref(),
        &p.albedos,
        p.albedos.channels(),
        p.correction.as_ref(),
        cases,
        &outputs,
        &bound,
    );
    Ok((a, bound))
}

/// The check values a fitted result states (`check_values`, or with a smooth correction
/// `correction.check_values`: directions in degrees in the swatch
/// frame, the BRDF per channel, one number for grey), as cases in that frame (n = +z, t at the
/// fibre azimuth `psi`, radians) with the stated values. Empty when the file has none.
pub fn stated_check_values(result: &serde_json::Value, psi: f64) -> Vec<(Case, Vec<f64>)> {
    use crate::model::frame::direction_from_angles;
    // with a smooth correction, the corrected BRDF's (what the shader evaluates)
    let list = match result.get("correction") {
        Some(c) => c.get("check_values"),
        None => result.get("check_values"),
    };
    let Some(list) = list.and_then(|c| c.as_array()) else {
        return vec![];
    };
    let f32s3 = |v: Vec3| [v.x as f32, v.y as f32, v.z as f32];
    list.iter()
        .filter_map(|c| {
            let angle = |k: &str| c.get(k).and_then(|x| x.as_f64()).map(f64::to_radians);
            let (ti, pi, to, po) = (
                angle("theta_i")?,
                angle("phi_i")?,
                angle("theta_o")?,
                angle("phi_o")?,
            );
            let brdf = match c.get("brdf")? {
                serde_json::Value::Array(a) => {
                    a.iter().map(|x| x.as_f64()).collect::<Option<_>>()?
                }
                x => vec![x.as_f64()?],
            };
            Some((
                Case {
                    l: f32s3(direction_from_angles(ti, pi)),
                    v: f32s3(direction_from_angles(to, po)),
                    n: [0.0, 0.0, 1.0],
                    t: [psi.cos() as f32, psi.sin() as f32, 0.0],
                    at: None,
                },
                brdf,
            ))
        })
        .collect()
}

/// The shader's `outputs` at stated check values: (largest relative error, largest ratio of an
/// error to its case's tolerance under `bound`). Values compared relative to max(|value|, 1e-4 of
/// the largest stated value).
pub fn compare_stated(
    stated: &[(Case, Vec<f64>)],
    outputs: &[Output],
    bound: &Bound,
) -> (f64, f64) {
    let peak = stated
        .iter()
        .flat_map(|(_, v)| v.iter().map(|x| x.abs()))
        .fold(0.0f64, f64::max);
    let (mut max_rel, mut worst) = (0.0f64, 0.0f64);
    for ((case, want), o) in stated.iter().zip(outputs) {
        let (cl, cv) = cosines(case);
        for (c, g) in o.brdf.iter().enumerate() {
            let r = want[c.min(want.len() - 1)];
            let e = (*g as f64 - r).abs() / r.abs().max(1e-4 * peak).max(f64::MIN_POSITIVE);
            max_rel = max_rel.max(e);
            if cl.min(cv) > 0.0 {
                worst = worst.max(e / bound.case_tolerance(cl.min(cv)));
            } else if *g != 0.0 {
                worst = f64::INFINITY;
            }
        }
    }
    (max_rel, worst)
}
