//! The fibre lobe technique: the latitude's sine from a truncated Cauchy law about the mirror's,
//! the longitude uniform or, for a cross-section rung, from the cone table ([`ConeTable`]):
//! tabulated from the rung itself when the sampler is made, then blended, evaluated and drawn
//! per view. Its density needs no trigonometric call but one arc tangent (the law's truncated
//! mass, in lane form): the mixture evaluates it at every spread node of every sample.

use super::directions::{cosine_direction, rescale, wallis};
use super::{CONE_BINS, CONE_ROWS, CONE_UNIFORM};
use crate::model::frame::Local;
use crate::model::numerics::elementary;
use crate::model::params::ModelParams;
use crate::model::rung::Rung;
use crate::model::{Basis, DirectionPair, ModelId};
use std::f64::consts::{FRAC_1_PI, FRAC_PI_2, PI};

/// The Cauchy law of s = l.t about the mirror s_r = -v_t (v_t = v.t), truncated to s in
/// [-1, 1]: (s_r, 1 / gamma_s, W) with the width gamma_s = gamma sqrt(1 - s_r^2 + gamma^2) (the
/// lobe's width gamma in latitude times ds/dth = cos th_r at the mirror, kept above gamma^2
/// where v runs along the fibre) and the truncated mass W = atan(x_B) - atan(x_A) =
/// atan2(2 / gamma_s, 1 + x_A x_B), x_A,B = (-+1 - s_r) / gamma_s: one arc tangent, in
/// (0, pi), by [`elementary`]'s lane form (branch-free: the mixture's node loop vectorises).
/// The draw and the density use this same W, which is all the density's exactness needs.
#[inline(always)]
pub(super) fn fibre_lobe_law(gamma: f64, v_t: f64) -> (f64, f64, f64) {
    let s_r = -v_t;
    let gamma_s = gamma * ((1.0 - s_r * s_r).max(0.0) + gamma * gamma).sqrt();
    // one division: the mixture evaluates this at every node of every sample
    let inv = 1.0 / gamma_s;
    let (x_a, x_b) = ((-1.0 - s_r) * inv, (1.0 - s_r) * inv);
    let x = 1.0 + x_a * x_b;
    let r = elementary::atan2_right_half_lanes(2.0 * inv, x.abs());
    (s_r, inv, if x >= 0.0 { r } else { PI - r })
}

/// The Cauchy law's density of s (see [`fibre_lobe_law`], which gives (s_r, 1 / gamma_s, W)).
#[inline(always)]
pub(super) fn fibre_lobe_density(law: (f64, f64, f64), s: f64) -> f64 {
    let (s_r, inv_gamma_s, width) = law;
    let x = (s - s_r) * inv_gamma_s;
    inv_gamma_s / (width * (1.0 + x * x))
}

/// x = tan(alpha / 2) of a direction's angle alpha in the cross-section plane, from N towards
/// B (above the horizon): b / (|w_p| + n), no arc tangent. The cone table's coordinate.
#[inline(always)]
pub(super) fn half_tangent(b: f64, n: f64) -> f64 {
    b / ((b * b + n * n).sqrt() + n)
}

/// The fibre lobe technique for the view v (fibre frame of the node): the latitude's sine s =
/// l.t from the Cauchy law, the longitude uniform or from the cone table's row. None where the
/// drawn s falls outside [-1, 1] (the law's ends are the arc tangents' to rounding: never more
/// than a few ulp of mass).
pub(super) fn fibre_lobe_direction(
    gamma: f64,
    cone: Option<&ConeTable>,
    v: &Local,
    u: [f64; 2],
) -> Option<Local> {
    let (s_r, inv_gamma_s, width) = fibre_lobe_law(gamma, v.t);
    let a = ((-1.0 - s_r) * inv_gamma_s).atan();
    let s = s_r + (a + u[0] * width).tan() / inv_gamma_s;
    if !(s.abs() <= 1.0) {
        return None;
    }
    let c = (1.0 - s * s).sqrt();
    // the longitude's angle alpha in the cross-section plane from N, by sin and cos
    let (sa, ca) = match cone {
        None => (FRAC_PI_2 - PI * u[1]).sin_cos(),
        Some(table) => {
            let x = table.sample(half_tangent(v.b, v.n), u[1]);
            let d = 1.0 / (1.0 + x * x);
            (2.0 * x * d, (1.0 - x * x) * d)
        }
    };
    Some(Local {
        t: s,
        b: c * sa,
        n: c * ca,
    })
}

/// Density of [`fibre_lobe_direction`] at l (above the horizon): d omega = ds dalpha (s = l.t,
/// alpha the longitude about T), so it is the two laws' product, with no Jacobian. One node at
/// a time (`Sampler`'s lane loop writes the same terms for many).
pub(super) fn fibre_lobe_pdf(gamma: f64, cone: Option<&ConeTable>, v: &Local, l: &Local) -> f64 {
    let g = fibre_lobe_density(fibre_lobe_law(gamma, v.t), l.t);
    g * match cone {
        None => FRAC_1_PI,
        Some(table) => table.density_per_radian(half_tangent(v.b, v.n), half_tangent(l.b, l.n)),
    }
}

/// The longitude law along the highlight cone of a cross-section rung: per row of x_v = tan(alpha_v
/// / 2) (alpha_v the view's angle in the cross-section plane), a piecewise-linear density of x_l
/// = tan(alpha_l / 2) on [-1, 1], tabulated from the rung's own lobe in the cross-section plane
/// (where the cone's latitude is 0). The half tangents, not the angles, so that neither the
/// draw nor the density calls an arc tangent ([`half_tangent`]); per radian of alpha_l the
/// density is the table's times dx/dalpha = (1 + x_l^2) / 2.
#[derive(Clone, Debug)]
pub(super) struct ConeTable {
    /// The density (per unit x_l) at the bin ends x_l = -1 + 2 j / CONE_BINS, per row; linear
    /// between them (continuous), integrating to 1.
    density: Vec<[f64; CONE_BINS + 1]>,
    /// Cumulative masses of the bins per row (the last is 1).
    cumulative: Vec<[f64; CONE_BINS]>,
    /// Per row, for the weights: the lobe's directional albedo per unit ks at latitude 0, and
    /// the diffuse and the substrate directional albedos per unit albedo.
    albedo: Vec<[f64; 3]>,
}

impl ConeTable {
    /// The table of rung `id` (a cross-section rung: the reference's is varying-topology's,
    /// which is it to the quadrature error, as its [`crate::model::rung::Sampling::cone_from`] says)
    /// with parameters `p`, from the aligned rung (no spread, Fresnel or fuzz: those the
    /// mixture and the uniform share absorb), for v in the
    /// cross-section plane at the centre of each row with x_v >= 0: the lobe's intensity
    /// f_s (N.l) at l in the plane (latitude 0, the cone of v) at each x_l bin's end, and
    /// the diffuse and substrate directional albedos per unit albedo by an 8 x 8 cosine-weighted
    /// product rule (at most 16 heights and 16 lobe nodes). The rows of x_v < 0 are their
    /// mirror images (T -> -T), exactly. `None` if the rung cannot be built (then the cone's
    /// longitude law is uniform).
    pub(super) fn new(rung: &Rung, p: &ModelParams) -> Option<ConeTable> {
        let mut q = p.clone();
        q.azimuth_spread_deg = 0.0;
        q.fresnel_ior = 0.0;
        q.fuzz_depth = 0.0;
        // the table is a proposal's shape: 16 heights and 16 lobe nodes are plenty, and keep
        // its cost bounded whatever the rung's own knobs (up to 65536 heights)
        q.histogram_bins = q.histogram_bins.min(16);
        q.quadrature_order = q.quadrature_order.min(16);
        let m = crate::model::build(ModelId::of(rung), &q).ok()?;
        const GRID: usize = 8;
        let half = CONE_ROWS / 2;
        let bin = 2.0 / CONE_BINS as f64;
        // the direction in the plane at half tangent x: (sin alpha, cos alpha) rationally
        let in_plane = |x: f64| {
            let d = 1.0 / (1.0 + x * x);
            Local {
                t: 0.0,
                b: 2.0 * x * d,
                n: (1.0 - x * x) * d,
            }
        };
        let per_row = CONE_BINS + 1 + GRID * GRID;
        let mut pairs = Vec::with_capacity(half * per_row);
        for i in 0..half {
            let v = in_plane((i as f64 + 0.5) / half as f64);
            for j in 0..=CONE_BINS {
                pairs.push(DirectionPair {
                    l: in_plane(-1.0 + j as f64 * bin),
                    v,
                });
            }
            for a in 0..GRID {
                for b in 0..GRID {
                    let u = [
                        (a as f64 + 0.5) / GRID as f64,
                        (b as f64 + 0.5) / GRID as f64,
                    ];
                    pairs.push(DirectionPair {
                        l: cosine_direction(u),
                        v,
                    });
                }
            }
        }
        let mut out = vec![Basis::default(); pairs.len()];
        m.basis_many(&pairs, &mut out);
        let finite = |x: f64| if x.is_finite() && x > 0.0 { x } else { 0.0 };
        let w = wallis(p.exponent);
        // per row with x_v >= 0: masses, lobe albedo, diffuse and substrate albedos
        // the uniform law of alpha_l per unit x_l, (1 / pi) dalpha/dx, at the nodes (its
        // linear interpolant's integral, to normalise it)
        let uniform: [f64; CONE_BINS + 1] = std::array::from_fn(|j| {
            let x = -1.0 + j as f64 * bin;
            2.0 / (PI * (1.0 + x * x))
        });
        let uniform_total: f64 = uniform.windows(2).map(|w| 0.5 * (w[0] + w[1]) * bin).sum();
        let mut upper = Vec::with_capacity(half);
        for i in 0..half {
            let row = &out[i * per_row..(i + 1) * per_row];
            let row_pairs = &pairs[i * per_row..(i + 1) * per_row];
            let mut t = [0.0; CONE_BINS + 1];
            // per unit x_l: the intensity times dalpha/dx = 2 / (1 + x^2)
            for (j, tj) in t.iter_mut().enumerate() {
                let x = -1.0 + j as f64 * bin;
                *tj = finite(row[j].specular * row_pairs[j].l.n) * 2.0 / (1.0 + x * x);
            }
            // the integral of the linear interpolant
            let total: f64 = t.windows(2).map(|w| 0.5 * (w[0] + w[1]) * bin).sum();
            let floor = if total > 0.0 { CONE_UNIFORM } else { 1.0 };
            let mut density = t;
            for (j, d) in density.iter_mut().enumerate() {
                let share = if total > 0.0 { *d / total } else { 0.0 };
                *d = (1.0 - floor) * share + floor * uniform[j] / uniform_total;
            }
            // cosine-weighted rule: a(v) = mean of pi f
            let grid = &row[CONE_BINS + 1..];
            let mean = |f: &dyn Fn(&Basis) -> f64| {
                PI * grid.iter().map(|b| finite(f(b))).sum::<f64>() / grid.len() as f64
            };
            upper.push(Row {
                density,
                // the lobe's albedo at latitude 0: its integral over alpha_l (total, by x_l)
                // times its width
                // in latitude (cos^e)
                lobe: total * w,
                diffuse: mean(&|b| b.diffuse),
                substrate: mean(&|b| b.substrate),
            });
        }
        // rows k < half are the mirror images of rows CONE_ROWS - 1 - k
        let rows: Vec<Row> = (0..CONE_ROWS)
            .map(|k| {
                if k < half {
                    let mut r = upper[half - 1 - k].clone();
                    r.density.reverse();
                    r
                } else {
                    upper[k - half].clone()
                }
            })
            .collect();
        let cumulative = rows
            .iter()
            .map(|row| {
                let mut c = [0.0; CONE_BINS];
                let mut acc = 0.0;
                for (j, cj) in c.iter_mut().enumerate() {
                    acc += 0.5 * (row.density[j] + row.density[j + 1]) * bin;
                    *cj = acc;
                }
                // the masses sum to 1 up to rounding
                c.iter_mut().for_each(|x| *x /= acc);
                c[CONE_BINS - 1] = 1.0;
                c
            })
            .collect();
        Some(ConeTable {
            density: rows.iter().map(|r| r.density).collect(),
            cumulative,
            albedo: rows
                .iter()
                .map(|r| [r.lobe, r.diffuse, r.substrate])
                .collect(),
        })
    }
}

/// One row of a [`ConeTable`] while it is built.
#[derive(Clone)]
struct Row {
    density: [f64; CONE_BINS + 1],
    lobe: f64,
    diffuse: f64,
    substrate: f64,
}

impl ConeTable {
    /// The two rows that bracket the view's half tangent `x_v` and the weight of the second:
    /// the law is the blend of the rows at the neighbouring row centres (linear in x_v; the
    /// lobe's edge moves fast with alpha_v at grazing views). Computed from |x_v| and its sign,
    /// so -x_v gives the mirror rows with the same weight.
    fn blend(&self, x_v: f64) -> (usize, usize, f64) {
        let half = CONE_ROWS / 2;
        // position among the row centres (i + 1/2) of the rows with x_v >= 0, in row units;
        // -1 is the mirror of row 0
        let q = x_v.abs().min(1.0) * half as f64 - 0.5;
        let lo = elementary::floor(q).clamp(-1.0, half as f64 - 1.0);
        let w = (q - lo).clamp(0.0, 1.0);
        let lo = lo as isize;
        let hi = (lo + 1).min(half as isize - 1);
        let row = |j: isize| {
            if x_v.is_sign_negative() {
                (half as isize - 1 - j) as usize
            } else {
                (half as isize + j) as usize
            }
        };
        (row(lo), row(hi), w)
    }

    /// The row albedos (lobe, diffuse, substrate; see `albedo`) blended for the view v.
    pub(super) fn albedos(&self, v: &Local) -> [f64; 3] {
        let (a, b, w) = self.blend(half_tangent(v.b, v.n));
        let (x, y) = (self.albedo[a], self.albedo[b]);
        [0, 1, 2].map(|k| (1.0 - w) * x[k] + w * y[k])
    }

    /// The density (per unit x_l) of x_l given x_v.
    pub(super) fn density(&self, x_v: f64, x_l: f64) -> f64 {
        let (a, b, w) = self.blend(x_v);
        // the nodes either side of x_l, from |x_l| and its sign (exact mirror images)
        let half = CONE_BINS / 2;
        let y = x_l.abs().min(1.0) * half as f64;
        let k = (elementary::floor(y) as usize).min(half - 1);
        let f = (y - k as f64).clamp(0.0, 1.0);
        let (n0, n1) = if x_l.is_sign_negative() {
            (half - k, half - k - 1)
        } else {
            (half + k, half + k + 1)
        };
        let at = |d: &[f64; CONE_BINS + 1]| (1.0 - f) * d[n0] + f * d[n1];
        (1.0 - w) * at(&self.density[a]) + w * at(&self.density[b])
    }

    /// The density per radian of alpha_l given the half tangents x_v and x_l.
    pub(super) fn density_per_radian(&self, x_v: f64, x_l: f64) -> f64 {
        self.density(x_v, x_l) * 0.5 * (1.0 + x_l * x_l)
    }

    /// x_l drawn from the blend for x_v with the uniform `u` (the row by its rescaled value,
    /// then the bin by inversion, then the position within the bin by the linear density's
    /// CDF).
    pub(super) fn sample(&self, x_v: f64, u: f64) -> f64 {
        let (a, b, w) = self.blend(x_v);
        let (row, u) = if u < 1.0 - w {
            (a, rescale(u, 0.0, 1.0 - w))
        } else {
            (b, rescale(u, 1.0 - w, 1.0))
        };
        let cumulative = &self.cumulative[row];
        let j = cumulative.partition_point(|&c| c <= u).min(CONE_BINS - 1);
        let lo = if j == 0 { 0.0 } else { cumulative[j - 1] };
        let r = rescale(u, lo, cumulative[j]);
        // within the bin the density runs linearly from a to b: its CDF a x + (b - a) x^2 / 2
        // = r (a + b) / 2 solved in the cancellation-free form
        let (a, b) = (self.density[row][j], self.density[row][j + 1]);
        let root = (a * a * (1.0 - r) + b * b * r).sqrt();
        let x = if a + root > 0.0 {
            (r * (a + b) / (a + root)).clamp(0.0, 1.0)
        } else {
            r
        };
        -1.0 + (j as f64 + x) * (2.0 / CONE_BINS as f64)
    }
}


#[cfg(test)]
mod tests {
    use super::super::Sampler;
    use super::*;

    #[test]
    fn the_cone_law_integrates_to_one_and_its_draws_invert_its_cdf() {
        let raw: crate::model::params::RawParams =
            toml::from_str("kd = 0.3\nks = 0.6\nexponent = 300\nspacing = 2.6\n").unwrap();
        let p = ModelParams::from_raw(&raw, ModelId::PoulinFournier)
            .unwrap()
            .0;
        let sampler = Sampler::new(ModelId::PoulinFournier, &p);
        let table = sampler
            .cone
            .as_ref()
            .expect("a cross-section rung has a table");
        let bin = 2.0 / CONE_BINS as f64;
        for row in 0..CONE_ROWS {
            let d = &table.density[row];
            let total: f64 = d.windows(2).map(|w| 0.5 * (w[0] + w[1]) * bin).sum();
            assert!((total - 1.0).abs() < 1e-12, "row {row}: {total}");
            // the mirror row
            let mut m = table.density[CONE_ROWS - 1 - row];
            m.reverse();
            assert_eq!(&m, d);
        }
        // at a row's centre the law is that row alone: F(draw(u)) = u
        for i in [0usize, 5, 20, 31] {
            let x_v = (i as f64 + 0.5) / (CONE_ROWS / 2) as f64;
            let (lo, hi, w) = table.blend(x_v);
            // one of the two rows, to rounding
            let a = if w < 0.5 { lo } else { hi };
            assert!(w.min(1.0 - w) < 1e-9, "{w}");
            let d = &table.density[a];
            let cdf = |x_l: f64| {
                let x = (x_l + 1.0) / bin;
                let j = (x.floor() as usize).min(CONE_BINS - 1);
                let f = x - j as f64;
                let full: f64 = (0..j).map(|k| 0.5 * (d[k] + d[k + 1]) * bin).sum();
                full + (d[j] * f + 0.5 * (d[j + 1] - d[j]) * f * f) * bin
            };
            for k in 0..200 {
                let u = (k as f64 + 0.5) / 200.0;
                let x_l = table.sample(x_v, u);
                assert!(
                    (cdf(x_l) - u).abs() < 1e-9,
                    "row {a} u {u}: {}",
                    cdf(x_l)
                );
                // the density at the draw is the blend's
                let q = table.density(x_v, x_l);
                assert!(q > 0.0 && q.is_finite());
            }
        }
    }

    /// The Cauchy law of s: its truncated mass is the arc tangents' difference, its density
    /// integrates to 1 over [-1, 1] (midpoint rule, 2e5 cells), at views from along the fibre
    /// to across it.
    #[test]
    fn the_latitude_law_integrates_to_one_over_the_sines() {
        for e in [1.0, 30.0, 1000.0, 20000.0] {
            let gamma = super::super::LOBE_WIDTH / f64::sqrt(e);
            for v_t in [-1.0, -0.999, -0.7, 0.0, 0.3, 0.95, 1.0] {
                let law = fibre_lobe_law(gamma, v_t);
                let (s_r, inv_gamma_s, width) = law;
                let exact = ((1.0 - s_r) * inv_gamma_s).atan() - ((-1.0 - s_r) * inv_gamma_s).atan();
                assert!((width - exact).abs() < 4e-15, "e {e} v.t {v_t}: {width} vs {exact}");
                let n = 200_000;
                let total: f64 = (0..n)
                    .map(|k| fibre_lobe_density(law, -1.0 + (k as f64 + 0.5) * 2.0 / n as f64))
                    .sum::<f64>()
                    * 2.0
                    / n as f64;
                // the midpoint rule's error on the sharpest law (gamma_s ~ 4e-5) is ~1e-3
                assert!((total - 1.0).abs() < 2e-3, "e {e} v.t {v_t}: {total}");
            }
        }
    }

    /// The mixture's lane loop over a spread's nodes (two blocks, the second padded) is the
    /// node-weighted sum of each node's tube and lobe densities written one node at a time.
    #[test]
    fn the_lane_node_sum_is_the_nodes_sum() {
        for (text, id) in [
            (
                "kd = 0.3\nks = 0.6\nexponent = 300\nspacing = 2.6\nazimuth_spread_deg = 30\nazimuth_nodes = 9\n",
                ModelId::PoulinFournier,
            ),
            (
                "kd = 0.3\nks = 0.6\nexponent = 50\nazimuth_spread_deg = 180\n",
                ModelId::MaxNormal,
            ),
        ] {
            let raw: crate::model::params::RawParams = toml::from_str(text).unwrap();
            let p = ModelParams::from_raw(&raw, id).unwrap().0;
            let sampler = Sampler::new(id, &p);
            let gamma = match sampler.lobe {
                super::super::Lobe::Fibre { gamma } => gamma,
                _ => panic!("a fibre lobe"),
            };
            let w = super::super::Weights {
                cos: 0.2,
                tube: 0.3,
                lobe: 0.5,
            };
            let dir = |t: f64, b: f64| Local {
                t,
                b,
                n: (1.0 - t * t - b * b).sqrt(),
            };
            for (v, l) in [
                (dir(0.3, -0.2), dir(-0.25, 0.4)),
                (dir(0.9, 0.1), dir(-0.7, -0.6)),
                (dir(-0.1, 0.95), dir(0.05, -0.3)),
            ] {
                let lanes = sampler.fibre_nodes_pdf(gamma, &w, &v, &l);
                let one_by_one: f64 = sampler
                    .nodes
                    .iter()
                    .map(|&(c, s, nu)| {
                        let (lj, vj) = (super::super::turn(&l, c, s), super::super::turn(&v, c, s));
                        nu * (w.tube * super::super::tube_pdf(&lj)
                            + w.lobe * fibre_lobe_pdf(gamma, sampler.cone.as_ref(), &vj, &lj))
                    })
                    .sum();
                assert!(
                    (lanes - one_by_one).abs() <= 1e-13 * one_by_one,
                    "{id}: {lanes} vs {one_by_one}"
                );
            }
        }
    }
}