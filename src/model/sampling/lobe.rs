//! The fibre lobe technique: the latitude from a truncated Cauchy law about the mirror latitude,
//! the longitude uniform or, for a cross-section rung, from the cone table ([`ConeTable`]):
//! tabulated from the rung itself when the sampler is made, then blended, evaluated and drawn
//! per view.

use super::directions::{cosine_direction, rescale, wallis};
use super::{CONE_BINS, CONE_ROWS, CONE_UNIFORM};
use crate::model::frame::Local;
use crate::model::params::ModelParams;
use crate::model::rung::Rung;
use crate::model::{Basis, DirectionPair, ModelId};
use std::f64::consts::{FRAC_1_PI, FRAC_PI_2, PI};

/// The mirror latitude th_r = -asin(v.t) and the Cauchy law's truncation (A, B - A).
fn fibre_lobe_law(gamma: f64, v: &Local) -> (f64, f64, f64) {
    let th_r = -v.t.atan2(v.projected_len());
    let a = ((-FRAC_PI_2 - th_r) / gamma).atan();
    let b = ((FRAC_PI_2 - th_r) / gamma).atan();
    (th_r, a, b - a)
}

/// The fibre lobe technique for the view v (fibre frame of the node): the latitude from the
/// Cauchy law, the longitude uniform or from the cone table's row `row`.
pub(super) fn fibre_lobe_direction(
    gamma: f64,
    cone: Option<&ConeTable>,
    v: &Local,
    u: [f64; 2],
) -> Local {
    let (th_r, a, width) = fibre_lobe_law(gamma, v);
    let delta = gamma * (a + u[0] * width).tan();
    let th = (th_r + delta).clamp(-FRAC_PI_2, FRAC_PI_2);
    let (s, c) = th.sin_cos();
    // alpha_l = pi/2 - phi, the longitude's angle in the cross-section plane from N
    // alpha_l = pi/2 - phi, the longitude's angle in the cross-section plane from N
    let alpha = match cone {
        None => FRAC_PI_2 - PI * u[1],
        Some(table) => table.sample(v.b.atan2(v.n), u[1]),
    };
    let (sa, ca) = alpha.sin_cos();
    Local {
        t: s,
        b: c * sa,
        n: c * ca,
    }
}

/// Density of [`fibre_lobe_direction`] at l (above the horizon).
pub(super) fn fibre_lobe_pdf(gamma: f64, cone: Option<&ConeTable>, v: &Local, l: &Local) -> f64 {
    let (th_r, _, width) = fibre_lobe_law(gamma, v);
    let lp = l.projected_len();
    let th = l.t.atan2(lp);
    let x = (th - th_r) / gamma;
    let g = 1.0 / (width * gamma * (1.0 + x * x));
    // the longitude's density per radian
    let longitude = match cone {
        None => FRAC_1_PI,
        Some(table) => table.density(v.b.atan2(v.n), l.b.atan2(l.n)),
    };
    g * longitude / lp
}

/// The longitude law along the highlight cone of a cross-section rung: per row of alpha_v (the
/// view's angle in the cross-section plane), a piecewise-constant law of alpha_l, tabulated from
/// the rung's own lobe in the cross-section plane (where the cone's latitude is 0).
#[derive(Clone, Debug)]
pub(super) struct ConeTable {
    /// Probability of each alpha_l bin, per row (each row sums to 1).
    /// The density (per radian) of alpha_l at the bin ends -pi/2 + j pi / CONE_BINS, per row;
    /// linear between them (continuous), integrating to 1.
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
    /// cross-section plane at the centre of each row with alpha_v >= 0: the lobe's intensity
    /// f_s (N.l) at l in the plane (latitude 0, the cone of v) at each alpha_l bin's centre, and
    /// the diffuse and substrate directional albedos per unit albedo by an 8 x 8 cosine-weighted
    /// product rule (at most 16 heights and 16 lobe nodes). The rows of alpha_v < 0 are their
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
        let bin = PI / CONE_BINS as f64;
        let in_plane = |alpha: f64| {
            let (s, c) = alpha.sin_cos();
            Local { t: 0.0, b: s, n: c }
        };
        let per_row = CONE_BINS + 1 + GRID * GRID;
        let mut pairs = Vec::with_capacity(half * per_row);
        for i in 0..half {
            let v = in_plane((i as f64 + 0.5) * FRAC_PI_2 / half as f64);
            for j in 0..=CONE_BINS {
                let alpha = -FRAC_PI_2 + j as f64 * bin;
                pairs.push(DirectionPair {
                    l: in_plane(alpha),
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
        // per row with alpha_v >= 0: masses, lobe albedo, diffuse and substrate albedos
        let mut upper = Vec::with_capacity(half);
        for i in 0..half {
            let row = &out[i * per_row..(i + 1) * per_row];
            let row_pairs = &pairs[i * per_row..(i + 1) * per_row];
            let mut t = [0.0; CONE_BINS + 1];
            for (j, tj) in t.iter_mut().enumerate() {
                *tj = finite(row[j].specular * row_pairs[j].l.n);
            }
            // the integral of the linear interpolant
            let total: f64 = t.windows(2).map(|w| 0.5 * (w[0] + w[1]) * bin).sum();
            let floor = if total > 0.0 { CONE_UNIFORM } else { 1.0 };
            let density = t.map(|tj| {
                let share = if total > 0.0 { tj / total } else { 0.0 };
                (1.0 - floor) * share + floor * FRAC_1_PI
            });
            // cosine-weighted rule: a(v) = mean of pi f
            let grid = &row[CONE_BINS + 1..];
            let mean = |f: &dyn Fn(&Basis) -> f64| {
                PI * grid.iter().map(|b| finite(f(b))).sum::<f64>() / grid.len() as f64
            };
            upper.push(Row {
                density,
                // the lobe's albedo at latitude 0: its integral over alpha_l times its width
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
    /// The two rows that bracket the view's cross-section angle `alpha_v` and the weight of the
    /// second: the law is the blend of the rows at the neighbouring row centres (linear in
    /// alpha_v; the lobe's edge moves fast with alpha_v at grazing views). Computed from
    /// |alpha_v| and its sign, so -alpha_v gives the mirror rows with the same weight.
    fn blend(&self, alpha_v: f64) -> (usize, usize, f64) {
        let half = CONE_ROWS / 2;
        // position among the row centres (i + 1/2) of the rows with alpha_v >= 0, in row units;
        // -1 is the mirror of row 0
        let q = alpha_v.abs() / FRAC_PI_2 * half as f64 - 0.5;
        let lo = q.floor().clamp(-1.0, half as f64 - 1.0);
        let w = (q - lo).clamp(0.0, 1.0);
        let lo = lo as isize;
        let hi = (lo + 1).min(half as isize - 1);
        let row = |j: isize| {
            if alpha_v.is_sign_negative() {
                (half as isize - 1 - j) as usize
            } else {
                (half as isize + j) as usize
            }
        };
        (row(lo), row(hi), w)
    }

    /// The row albedos (lobe, diffuse, substrate; see `albedo`) blended for the view v.
    pub(super) fn albedos(&self, v: &Local) -> [f64; 3] {
        let (a, b, w) = self.blend(v.b.atan2(v.n));
        let (x, y) = (self.albedo[a], self.albedo[b]);
        [0, 1, 2].map(|k| (1.0 - w) * x[k] + w * y[k])
    }

    /// The density (per radian) of alpha_l given alpha_v.
    pub(super) fn density(&self, alpha_v: f64, alpha_l: f64) -> f64 {
        let (a, b, w) = self.blend(alpha_v);
        // the nodes either side of alpha_l, from |alpha_l| and its sign (exact mirror images)
        let half = CONE_BINS / 2;
        let y = alpha_l.abs() / PI * CONE_BINS as f64;
        let k = (y.floor() as usize).min(half - 1);
        let f = (y - k as f64).clamp(0.0, 1.0);
        let (n0, n1) = if alpha_l.is_sign_negative() {
            (half - k, half - k - 1)
        } else {
            (half + k, half + k + 1)
        };
        let at = |d: &[f64; CONE_BINS + 1]| (1.0 - f) * d[n0] + f * d[n1];
        (1.0 - w) * at(&self.density[a]) + w * at(&self.density[b])
    }

    /// alpha_l drawn from the blend for alpha_v with the uniform `u` (the row by its rescaled
    /// value, then the bin by inversion, uniform within the bin).
    pub(super) fn sample(&self, alpha_v: f64, u: f64) -> f64 {
        let (a, b, w) = self.blend(alpha_v);
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
        -FRAC_PI_2 + (j as f64 + x) * (PI / CONE_BINS as f64)
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
        let bin = PI / CONE_BINS as f64;
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
            let alpha_v = (i as f64 + 0.5) * FRAC_PI_2 / (CONE_ROWS / 2) as f64;
            let (lo, hi, w) = table.blend(alpha_v);
            // one of the two rows, to rounding
            let a = if w < 0.5 { lo } else { hi };
            assert!(w.min(1.0 - w) < 1e-9, "{w}");
            let d = &table.density[a];
            let cdf = |alpha: f64| {
                let x = (alpha + FRAC_PI_2) / bin;
                let j = (x.floor() as usize).min(CONE_BINS - 1);
                let f = x - j as f64;
                let full: f64 = (0..j).map(|k| 0.5 * (d[k] + d[k + 1]) * bin).sum();
                full + (d[j] * f + 0.5 * (d[j + 1] - d[j]) * f * f) * bin
            };
            for k in 0..200 {
                let u = (k as f64 + 0.5) / 200.0;
                let alpha = table.sample(alpha_v, u);
                assert!(
                    (cdf(alpha) - u).abs() < 1e-9,
                    "row {a} u {u}: {}",
                    cdf(alpha)
                );
                // the density at the draw is the blend's
                let q = table.density(alpha_v, alpha);
                assert!(q > 0.0 && q.is_finite());
            }
        }
    }
}
