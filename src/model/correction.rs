//! A smooth reciprocal correction of a fitted rung: the rung's BRDF per channel times
//! exp(s_c(l, v)), s_c a Legendre series in (2 cos theta_i - 1, 2 cos theta_o - 1,
//! cos(phi_i - phi_o)) symmetric under the swap of light and view, so the corrected BRDF stays
//! reciprocal and non-negative.
//!
//! It stands for structure the rungs miss and the data hold (`reports/correction_study.md`:
//! the shared felt's held-out error 2.44x what a material can reach under auto's rung, 1.11x
//! with a series of degree 6). Its coefficients are not physical; the rung's parameters keep
//! their meaning. The series depends on the directions' polar angles and the difference of
//! their azimuths only, so it needs no fibre frame. Outside the polar angles the data covered
//! it is held at the edge (`cos_range`), and its log factor never leaves the range it took on
//! the data (`log_range`): a renderer's grazing directions see no extrapolated polynomial.

use super::frame::{DirectionPair, Local};
use serde::{Deserialize, Serialize};

/// The highest total degree a correction may have.
pub const MAX_DEGREE: usize = 8;

/// One column of a fit's design: a term of the material's series, or the instrument's term
/// P_k(x_i) - P_k(x_o) of degree k.
#[derive(Clone, Copy)]
enum Column {
    Term(usize, usize, usize),
    Instrument(usize),
}

/// The columns of a fit at total degree `degree`, by total degree: each degree's terms (in
/// [`terms`]' order), then, with `instrument`, that degree's instrument term (k >= 1). A lower
/// degree's columns are the leading ones of a higher's.
/// Coefficients per channel a fit of total degree `degree` solves for: the series' terms and,
/// with `instrument`, the instrument's.
pub fn coefficient_count(degree: usize, instrument: bool) -> usize {
    columns(degree, instrument).len()
}

fn columns(degree: usize, instrument: bool) -> Vec<Column> {
    let mut out = Vec::new();
    for total in 0..=degree {
        for a in 0..=total {
            for b in a..=total - a {
                out.push(Column::Term(a, b, total - a - b));
            }
        }
        if instrument && total >= 1 {
            out.push(Column::Instrument(total));
        }
    }
    out
}

/// A fitted correction (see the module docs).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Correction {
    /// Total degree of the series (0: one constant factor per channel).
    pub degree: usize,
    /// Per term of [`terms`]`(degree)`, the coefficient of each channel (grey repeats one).
    pub coefficients: Vec<[f64; 3]>,
    /// The cosines of polar angles the data covered, [lowest, highest]; outside, the series is
    /// held at the edge.
    pub cos_range: [f64; 2],
    /// The least and largest log factor on the data, per channel; the factor is clamped to it.
    pub log_range: [[f64; 2]; 3],
    /// The measuring instrument's light/view imbalance, fitted beside the series and **not part
    /// of the material**: per k = 1, ..., degree, the coefficient per channel of P_k(x_i) -
    /// P_k(x_o), the data being the material times exp(that sum) (a light and a detector whose
    /// responses differ with their own polar angles; a material is reciprocal, so what of the
    /// data is not is the instrument's). Empty: none fitted. Only the fit's held-out judgement
    /// of the data uses it; a renderer, `eval` and every export get the material.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub instrument: Vec<[f64; 3]>,
}

/// The series' terms at total degree `degree`: (a, b, c) with a <= b and a + b + c <= degree,
/// the term P_a(x_i) P_b(x_o) P_c(y) + P_b(x_i) P_a(x_o) P_c(y) (one product when a = b),
/// by total degree then (a, b, c).
pub fn terms(degree: usize) -> Vec<(usize, usize, usize)> {
    let mut t = Vec::new();
    for_each_term(degree, |a, b, c| t.push((a, b, c)));
    t
}

/// Call `f(a, b, c)` for each term of [`terms`]`(degree)`, in its order (no allocation).
fn for_each_term(degree: usize, mut f: impl FnMut(usize, usize, usize)) {
    for total in 0..=degree {
        for a in 0..=total {
            for b in a..=total - a {
                f(a, b, total - a - b);
            }
        }
    }
}

/// The Legendre values at the three coordinates, up to degree `d`.
type Tables = [[f64; MAX_DEGREE + 1]; 3];

fn tables(d: usize, cos_i: f64, cos_o: f64, cos_dphi: f64) -> Tables {
    let mut t = [[0.0; MAX_DEGREE + 1]; 3];
    legendre(2.0 * cos_i - 1.0, &mut t[0][..=d]);
    legendre(2.0 * cos_o - 1.0, &mut t[1][..=d]);
    legendre(cos_dphi, &mut t[2][..=d]);
    t
}

/// The term (a, b, c)'s value from the tables.
fn term(t: &Tables, a: usize, b: usize, c: usize) -> f64 {
    let sym = match a == b {
        true => t[0][a] * t[1][b],
        false => t[0][a] * t[1][b] + t[0][b] * t[1][a],
    };
    sym * t[2][c]
}

/// Legendre polynomials P_0 .. P_n at x into `out` (length n + 1).
fn legendre(x: f64, out: &mut [f64]) {
    if out.is_empty() {
        return;
    }
    out[0] = 1.0;
    if out.len() > 1 {
        out[1] = x;
    }
    for k in 2..out.len() {
        let kf = k as f64;
        out[k] = ((2.0 * kf - 1.0) * x * out[k - 1] - (kf - 1.0) * out[k - 2]) / kf;
    }
}

/// The series' coordinates of a pair: (cos theta_i, cos theta_o, cos(phi_i - phi_o)); the
/// azimuth difference's cosine is 1 where either direction is along the normal.
pub fn coordinates(l: &Local, v: &Local) -> (f64, f64, f64) {
    let ti = (l.t * l.t + l.b * l.b).sqrt();
    let to = (v.t * v.t + v.b * v.b).sqrt();
    let cos_dphi = match ti * to > 1e-12 {
        true => ((l.t * v.t + l.b * v.b) / (ti * to)).clamp(-1.0, 1.0),
        false => 1.0,
    };
    (l.n, v.n, cos_dphi)
}

impl Correction {
    /// The correction with no effect (degree 0, factor 1).
    pub fn identity() -> Self {
        Self {
            degree: 0,
            coefficients: vec![[0.0; 3]],
            cos_range: [0.0, 1.0],
            log_range: [[0.0, 0.0]; 3],
            instrument: Vec::new(),
        }
    }

    /// This correction if it is one [`Correction::fit`] could have made (a file's may not
    /// be): the degree at most [`MAX_DEGREE`], one coefficient triple per term, every number
    /// finite, the ranges ordered and the cosines within [0, 1]; else what is wrong.
    pub fn checked(&self) -> Result<Self, String> {
        if self.degree > MAX_DEGREE {
            return Err(format!("degree {} is above the largest, {MAX_DEGREE}", self.degree));
        }
        let want = terms(self.degree).len();
        if self.coefficients.len() != want {
            return Err(format!(
                "degree {} has {want} terms, but {} coefficient triples are given",
                self.degree,
                self.coefficients.len()
            ));
        }
        if let Some(k) = self.coefficients.iter().position(|c| !c.iter().all(|x| x.is_finite())) {
            return Err(format!("coefficient {k} is not finite"));
        }
        if !self.instrument.is_empty() && self.instrument.len() != self.degree {
            return Err(format!(
                "instrument: degree {} has {} instrument terms (or none), but {} triples are given",
                self.degree,
                self.degree,
                self.instrument.len()
            ));
        }
        if let Some(k) = self.instrument.iter().position(|c| !c.iter().all(|x| x.is_finite())) {
            return Err(format!("instrument coefficient {} is not finite", k + 1));
        }
        let [lo, hi] = self.cos_range;
        if !(0.0..=1.0).contains(&lo) || !(0.0..=1.0).contains(&hi) || lo > hi {
            return Err(format!("cos_range [{lo}, {hi}]: expected 0 <= lowest <= highest <= 1"));
        }
        for (c, [a, b]) in self.log_range.iter().enumerate() {
            if !(a.is_finite() && b.is_finite() && a <= b) {
                return Err(format!("log_range of channel {c}, [{a}, {b}]: expected finite, lowest first"));
            }
        }
        Ok(self.clone())
    }

    /// Number of coefficients per channel.
    pub fn terms(&self) -> usize {
        self.coefficients.len()
    }

    /// The log factor per channel at (cos theta_i, cos theta_o, cos dphi), without the clamps.
    fn raw_log_factor(&self, cos_i: f64, cos_o: f64, cos_dphi: f64) -> [f64; 3] {
        let t = tables(self.degree, cos_i, cos_o, cos_dphi);
        let mut s = [0.0; 3];
        let mut k = 0;
        for_each_term(self.degree, |a, b, c| {
            let x = term(&t, a, b, c);
            let w = &self.coefficients[k];
            for ch in 0..3 {
                s[ch] += x * w[ch];
            }
            k += 1;
        });
        s
    }

    /// The factor per channel at (cos theta_i, cos theta_o, cos dphi): held at the covered
    /// polar angles' edge and within the log range seen on the data.
    pub fn factor_at(&self, cos_i: f64, cos_o: f64, cos_dphi: f64) -> [f64; 3] {
        let [lo, hi] = self.cos_range;
        let s = self.raw_log_factor(cos_i.clamp(lo, hi), cos_o.clamp(lo, hi), cos_dphi);
        [0, 1, 2].map(|c| s[c].clamp(self.log_range[c][0], self.log_range[c][1]).exp())
    }

    /// The instrument's factor per channel at (cos theta_i, cos theta_o), the cosines held at
    /// the covered range's edge: what the data are beside the material (1 where none was fitted).
    pub fn instrument_at(&self, cos_i: f64, cos_o: f64) -> [f64; 3] {
        if self.instrument.is_empty() {
            return [1.0; 3];
        }
        let [lo, hi] = self.cos_range;
        let mut pi = [0.0; MAX_DEGREE + 1];
        let mut po = [0.0; MAX_DEGREE + 1];
        let d = self.instrument.len().min(MAX_DEGREE);
        legendre(2.0 * cos_i.clamp(lo, hi) - 1.0, &mut pi[..=d]);
        legendre(2.0 * cos_o.clamp(lo, hi) - 1.0, &mut po[..=d]);
        let mut s = [0.0; 3];
        for (k, w) in self.instrument.iter().enumerate().take(d) {
            let x = pi[k + 1] - po[k + 1];
            for ch in 0..3 {
                s[ch] += x * w[ch];
            }
        }
        s.map(f64::exp)
    }

    /// What the fit predicts the data to be, per channel, relative to the rung: the material's
    /// factor times the instrument's.
    pub fn measured_factor_at(&self, cos_i: f64, cos_o: f64, cos_dphi: f64) -> [f64; 3] {
        let m = self.factor_at(cos_i, cos_o, cos_dphi);
        let i = self.instrument_at(cos_i, cos_o);
        [0, 1, 2].map(|c| m[c] * i[c])
    }

    /// The factor per channel of a pair (1 where either direction is at or below the horizon:
    /// the rung is zero there).
    pub fn factor(&self, pair: &DirectionPair) -> [f64; 3] {
        if !pair.above_horizon() {
            return [1.0; 3];
        }
        let (ci, co, cd) = coordinates(&pair.l, &pair.v);
        self.factor_at(ci, co, cd)
    }

    /// Fit a series of total degree `degree` to log residuals: `points` (cos theta_i, cos
    /// theta_o, cos dphi), `targets` ln(data) - ln(model) per channel, `weights` per point;
    /// weighted least squares per channel of `channels` (grey data: channel 0, repeated). With
    /// `instrument`, the instrument's terms of degree 1, ..., `degree` beside the series (see
    /// [`Correction::instrument`]). `None` when the normal equations are singular.
    pub fn fit(
        degree: usize,
        points: &[(f64, f64, f64)],
        targets: &[[f64; 3]],
        weights: &[f64],
        channels: usize,
        instrument: bool,
    ) -> Option<Correction> {
        Self::fit_degrees(&[degree], points, targets, weights, channels, instrument)
            .pop()
            .flatten()
    }

    /// [`Correction::fit`] at each of `degrees` from one pass over the points: the columns are
    /// ordered by total degree, so a lower degree's normal equations are the leading block of
    /// the highest's.
    pub fn fit_degrees(
        degrees: &[usize],
        points: &[(f64, f64, f64)],
        targets: &[[f64; 3]],
        weights: &[f64],
        channels: usize,
        instrument: bool,
    ) -> Vec<Option<Correction>> {
        let top = degrees.iter().copied().max().unwrap_or(0).min(MAX_DEGREE);
        let cols = columns(top, instrument);
        let k = cols.len();
        // the columns of every point (row-major), and the normal equations' upper triangle
        let mut features_all = Vec::with_capacity(points.len() * k);
        for &(ci, co, cd) in points {
            let t = tables(top, ci, co, cd);
            features_all.extend(cols.iter().map(|col| match *col {
                Column::Term(a, b, c) => term(&t, a, b, c),
                Column::Instrument(d) => t[0][d] - t[1][d],
            }));
        }
        let mut ata = vec![0.0; k * k];
        let mut atb = vec![[0.0; 3]; k];
        for ((row, t), &w) in features_all.chunks_exact(k).zip(targets).zip(weights) {
            let y = [0, 1, 2].map(|ch| t[ch.min(channels - 1)]);
            for (r, (&fr, b)) in row.iter().zip(atb.iter_mut()).enumerate() {
                let wr = w * fr;
                for (x, &fc) in ata[r * k + r..(r + 1) * k].iter_mut().zip(&row[r..]) {
                    *x += wr * fc;
                }
                for (bc, yc) in b.iter_mut().zip(y) {
                    *bc += wr * yc;
                }
            }
        }
        let (lo, hi) = points.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), p| {
            (lo.min(p.0.min(p.1)), hi.max(p.0.max(p.1)))
        });
        degrees
            .iter()
            .map(|&degree| {
                let d = degree.min(MAX_DEGREE);
                let n = columns(d, instrument).len();
                let mut a = nalgebra::DMatrix::<f64>::from_fn(n, n, |r, c| {
                    ata[r.min(c) * k + r.max(c)]
                });
                // a whisper of ridge keeps a term the points barely constrain from running away
                let ridge = 1e-9 * a.diagonal().sum() / n as f64;
                for i in 0..n {
                    a[(i, i)] += ridge;
                }
                let b = nalgebra::DMatrix::<f64>::from_fn(n, 3, |r, ch| atb[r][ch]);
                let x = a.cholesky()?.solve(&b);
                let solved: Vec<[f64; 3]> =
                    (0..n).map(|r| [x[(r, 0)], x[(r, 1)], x[(r, 2)]]).collect();
                if solved.iter().flatten().any(|v| !v.is_finite()) || !lo.is_finite() {
                    return None;
                }
                let is_term = |c: &Column| matches!(c, Column::Term(..));
                let (mut coefficients, mut instrument_terms) = (Vec::new(), Vec::new());
                for (col, w) in cols[..n].iter().zip(&solved) {
                    match is_term(col) {
                        true => coefficients.push(*w),
                        false => instrument_terms.push(*w),
                    }
                }
                // the material's log factor's range on the data (the instrument's terms aside)
                let mut log_range = [[f64::INFINITY, f64::NEG_INFINITY]; 3];
                for row in features_all.chunks_exact(k) {
                    let mut s = [0.0; 3];
                    for ((fr, w), col) in row[..n].iter().zip(&solved).zip(&cols) {
                        if is_term(col) {
                            for ch in 0..3 {
                                s[ch] += fr * w[ch];
                            }
                        }
                    }
                    for ch in 0..3 {
                        log_range[ch][0] = log_range[ch][0].min(s[ch]);
                        log_range[ch][1] = log_range[ch][1].max(s[ch]);
                    }
                }
                Some(Correction {
                    degree: d,
                    coefficients,
                    cos_range: [lo.clamp(0.0, 1.0), hi.clamp(0.0, 1.0)],
                    log_range,
                    instrument: instrument_terms,
                })
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};

    fn random_local(rng: &mut rand::rngs::StdRng) -> Local {
        let z: f64 = rng.random_range(0.05..1.0);
        let phi: f64 = rng.random_range(0.0..std::f64::consts::TAU);
        let s = (1.0 - z * z).sqrt();
        Local {
            t: s * phi.cos(),
            b: s * phi.sin(),
            n: z,
        }
    }

    /// 2000 random pairs' coordinates and `target` at each.
    type Points = (Vec<(f64, f64, f64)>, Vec<[f64; 3]>);
    fn random_points(rng: &mut rand::rngs::StdRng, target: impl Fn(f64, f64, f64) -> [f64; 3]) -> Points {
        (0..2000)
            .map(|_| {
                let (l, v) = (random_local(rng), random_local(rng));
                let (ci, co, cd) = coordinates(&l, &v);
                ((ci, co, cd), target(ci, co, cd))
            })
            .unzip()
    }

    #[test]
    fn terms_count_the_symmetric_products() {
        // (a <= b, c) with a + b + c <= d: 1, 3, 7, 13, 22, 34, 50 terms.
        let counts: Vec<usize> = (0..=6).map(|d| terms(d).len()).collect();
        assert_eq!(counts, vec![1, 3, 7, 13, 22, 34, 50]);
        assert_eq!(terms(0), vec![(0, 0, 0)]);
    }

    #[test]
    fn legendre_matches_closed_forms() {
        let mut p = [0.0; 5];
        for &x in &[-1.0, -0.3, 0.0, 0.7, 1.0] {
            legendre(x, &mut p);
            assert!((p[2] - 0.5 * (3.0 * x * x - 1.0)).abs() < 1e-14);
            assert!((p[3] - 0.5 * (5.0 * x * x * x - 3.0 * x)).abs() < 1e-14);
            let p4 = (35.0 * x.powi(4) - 30.0 * x * x + 3.0) / 8.0;
            assert!((p[4] - p4).abs() < 1e-14);
        }
    }

    /// A reciprocal factor exp(s) recovered from its values, and reciprocal: f(l, v) = f(v, l).
    #[test]
    fn a_series_is_recovered_and_the_factor_is_reciprocal() {
        let mut rng = rand::rngs::StdRng::seed_from_u64(3);
        let truth = |ci: f64, co: f64, cd: f64| {
            [
                0.3 * (ci + co) - 0.2 * ci * co + 0.1 * cd * (ci * co),
                -0.1 + 0.05 * cd,
                0.2 * (ci * ci + co * co),
            ]
        };
        let (pts, tg) = random_points(&mut rng, |ci, co, cd| truth(ci, co, cd));
        let w = vec![1.0; pts.len()];
        let corr = Correction::fit(4, &pts, &tg, &w, 3, false).unwrap();
        for _ in 0..200 {
            let (l, v) = (random_local(&mut rng), random_local(&mut rng));
            let p = DirectionPair { l, v };
            let q = DirectionPair { l: v, v: l };
            let (a, b) = (corr.factor(&p), corr.factor(&q));
            let (ci, co, cd) = coordinates(&l, &v);
            let want = truth(ci, co, cd);
            for c in 0..3 {
                assert!((a[c] - b[c]).abs() <= 1e-12 * a[c], "not reciprocal");
                assert!((a[c].ln() - want[c]).abs() < 1e-6, "{} vs {}", a[c].ln(), want[c]);
            }
        }
        // Outside the polar angles covered (cos < 0.05), held at the edge: finite, positive.
        let grazing = DirectionPair::from_local([1.0, 0.0, 1e-6], [0.0, 1.0, 1e-6]);
        assert!(corr.factor(&grazing).iter().all(|f| f.is_finite() && *f > 0.0));
        assert_eq!(Correction::identity().factor(&grazing), [1.0; 3]);
    }

    /// Data that are a reciprocal material times an instrument's imbalance exp(a(theta_i) -
    /// a(theta_o)): the fit splits them, the material's factor reciprocal and the instrument's
    /// the antisymmetric part, 1 where the two polar angles are equal.
    #[test]
    fn an_instruments_imbalance_is_split_from_the_material() {
        let mut rng = rand::rngs::StdRng::seed_from_u64(5);
        let material = |ci: f64, co: f64, cd: f64| 0.3 * (ci + co) - 0.2 * ci * co + 0.1 * cd;
        let a = |c: f64| 0.4 * c - 0.3 * c * c;
        let (pts, tg) = random_points(&mut rng, |ci, co, cd| {
            let y = material(ci, co, cd) + a(ci) - a(co);
            [y, 0.5 * y, -y]
        });
        let w = vec![1.0; pts.len()];
        let corr = Correction::fit(3, &pts, &tg, &w, 3, true).unwrap();
        assert_eq!(corr.instrument.len(), 3);
        assert_eq!(corr.checked().unwrap(), corr);
        for &(ci, co, cd) in pts.iter().take(200) {
            let m = corr.factor_at(ci, co, cd);
            let mirrored = corr.factor_at(co, ci, cd);
            let full = corr.measured_factor_at(ci, co, cd);
            for (c, scale) in [1.0, 0.5, -1.0].into_iter().enumerate() {
                assert!((m[c] - mirrored[c]).abs() <= 1e-12 * m[c], "not reciprocal");
                assert!((m[c].ln() - scale * material(ci, co, cd)).abs() < 1e-6);
                let y = scale * (material(ci, co, cd) + a(ci) - a(co));
                assert!((full[c].ln() - y).abs() < 1e-6, "{} vs {y}", full[c].ln());
            }
            assert!(corr.instrument_at(ci, ci).iter().all(|f| (f - 1.0).abs() < 1e-12));
        }
        // without the instrument's terms the reciprocal series cannot follow the imbalance
        let plain = Correction::fit(3, &pts, &tg, &w, 3, false).unwrap();
        assert!(plain.instrument.is_empty());
        let (ci, co, cd) = pts[0];
        assert!((plain.measured_factor_at(ci, co, cd)[0] - plain.factor_at(ci, co, cd)[0]).abs() < 1e-15);
        // a file's instrument of the wrong length is refused
        let mut bad = corr.clone();
        bad.instrument.pop();
        assert!(bad.checked().unwrap_err().contains("instrument"));
    }
}
