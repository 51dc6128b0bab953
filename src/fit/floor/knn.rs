//! The floor's predictor: distance-weighted k-nearest-neighbour interpolation of the data
//! themselves (nothing fitted), through a kd-tree, in one of two embeddings of a direction pair.

use crate::load::samples::Sample;
use serde::Serialize;

/// Points of the kd-tree: a direction pair embedded in six dimensions.
pub type Point = [f64; 6];

/// How a direction pair (l, v) is placed in the predictor's space: a chart of azimuthal
/// equidistant coordinates (a unit vector w at theta, phi is theta (cos phi, sin phi): distances
/// along the sphere are kept near the normal and not squeezed at grazing angles), padded with
/// zeros to six.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Coordinates {
    /// An isotropic material's own coordinates: (theta_i, theta_o cos(phi_o - phi_i),
    /// theta_o |sin(phi_o - phi_i)|), three dimensions: the values depend on theta_i, theta_o and
    /// |phi_i - phi_o| only.
    Isotropic,
    /// [`Coordinates::Isotropic`], each training sample also standing for its reciprocal pair
    /// (light and view swapped).
    IsotropicReciprocal,
    /// The pair as it is (l and v in the swatch frame, the fibres' frame when the samples
    /// carry a fibre direction), four dimensions: anisotropic materials, fibres.
    Directions,
    /// [`Coordinates::Directions`], each training sample also standing for its images under
    /// the symmetries every fibre model has: reciprocity and T -> -T (the pair turned by 180 deg
    /// about the normal), which need no fibre direction.
    DirectionsSymmetric,
}

/// Every embedding, the order the floor tries them in.
pub const ALL: [Coordinates; 4] = [
    Coordinates::Isotropic,
    Coordinates::IsotropicReciprocal,
    Coordinates::Directions,
    Coordinates::DirectionsSymmetric,
];

/// The embeddings whose predictions are reciprocal (each training sample also stands for its
/// pair with light and view swapped): what a material, a reciprocal BRDF, can be compared with.
pub const RECIPROCAL: [Coordinates; 2] = [
    Coordinates::IsotropicReciprocal,
    Coordinates::DirectionsSymmetric,
];

/// The azimuthal equidistant coordinates of a unit vector rotated by -`a` about the normal.
fn chart(w: &crate::model::frame::Vec3, a: f64) -> [f64; 2] {
    let (sa, ca) = a.sin_cos();
    let (x, y) = (ca * w.x + sa * w.y, -sa * w.x + ca * w.y);
    let r = x.hypot(y);
    let theta = r.atan2(w.z);
    let k = if r > 1e-12 { theta / r } else { 1.0 };
    [k * x, k * y]
}

impl Coordinates {
    /// Whether the predictor in these coordinates is reciprocal ([`RECIPROCAL`]).
    pub fn is_reciprocal(self) -> bool {
        RECIPROCAL.contains(&self)
    }

    /// In words, for the report.
    pub fn text(self) -> &'static str {
        match self {
            Coordinates::Isotropic => "isotropic (theta_i, theta_o, |phi_i - phi_o|)",
            Coordinates::IsotropicReciprocal => {
                "isotropic and reciprocal (theta_i, theta_o, |phi_i - phi_o|; light and view swapped)"
            }
            Coordinates::Directions => "the direction pair as measured (anisotropic)",
            Coordinates::DirectionsSymmetric => {
                "the direction pair with its images under reciprocity and T -> -T (anisotropic, fibres)"
            }
        }
    }

    /// The chart's dimensions.
    pub fn dim(self) -> usize {
        match self {
            Coordinates::Isotropic | Coordinates::IsotropicReciprocal => 3,
            Coordinates::Directions | Coordinates::DirectionsSymmetric => 4,
        }
    }

    /// The point of sample `s`.
    pub fn point(self, s: &Sample) -> Point {
        match self {
            Coordinates::Directions | Coordinates::DirectionsSymmetric => {
                let a = s.fibre_azimuth.unwrap_or(0.0);
                let (l, v) = (chart(&s.l, a), chart(&s.v, a));
                [l[0], l[1], v[0], v[1], 0.0, 0.0]
            }
            Coordinates::Isotropic | Coordinates::IsotropicReciprocal => {
                // rotate by the light's azimuth (the view's when the light is at the normal)
                let a = match s.l.x.hypot(s.l.y) > 1e-9 {
                    true => s.l.y.atan2(s.l.x),
                    false => s.v.y.atan2(s.v.x),
                };
                let (l, v) = (chart(&s.l, a), chart(&s.v, a));
                [l[0], v[0], v[1].abs(), 0.0, 0.0, 0.0]
            }
        }
    }

    /// The points sample `s` stands for in training: its own ([`Coordinates::point`]) first,
    /// then its images under the symmetries the embedding assumes.
    pub fn images(self, s: &Sample) -> Vec<Point> {
        let p = self.point(s);
        match self {
            Coordinates::Isotropic | Coordinates::Directions => vec![p],
            Coordinates::IsotropicReciprocal => {
                let theta_o = p[1].hypot(p[2]);
                let (c, sn) = match theta_o > 1e-12 {
                    true => (p[1] / theta_o, p[2] / theta_o),
                    false => (1.0, 0.0),
                };
                vec![p, [theta_o, p[0] * c, p[0] * sn, 0.0, 0.0, 0.0]]
            }
            Coordinates::DirectionsSymmetric => {
                let swap = [p[2], p[3], p[0], p[1], 0.0, 0.0];
                let turn = |q: Point| [-q[0], -q[1], -q[2], -q[3], 0.0, 0.0];
                vec![p, swap, turn(p), turn(swap)]
            }
        }
    }
}

/// A kd-tree over points (the points reordered into the tree; `index` maps back).
pub struct KdTree {
    points: Vec<Point>,
    index: Vec<usize>,
    /// Per node (the median of its range): the split dimension.
    split: Vec<u8>,
}

impl KdTree {
    /// The tree of `points` (their indices are what a query returns).
    pub fn new(points: &[Point]) -> Self {
        let mut index: Vec<usize> = (0..points.len()).collect();
        let mut split = vec![0u8; points.len()];
        build(points, &mut index, &mut split, 0);
        let ordered = index.iter().map(|&i| points[i]).collect();
        Self {
            points: ordered,
            index,
            split,
        }
    }

    /// The `k` nearest points to `q` (squared distance, index), nearest first; ties by index.
    pub fn nearest(&self, q: &Point, k: usize) -> Vec<(f64, usize)> {
        let mut best: Vec<(f64, usize)> = Vec::with_capacity(k + 1);
        self.search(q, k, 0, self.points.len(), &mut best);
        best.iter().map(|&(d, i)| (d, self.index[i])).collect()
    }

    fn search(&self, q: &Point, k: usize, lo: usize, hi: usize, best: &mut Vec<(f64, usize)>) {
        if lo >= hi || k == 0 {
            return;
        }
        let mid = (lo + hi) / 2;
        let d: f64 = (0..6).map(|j| (self.points[mid][j] - q[j]).powi(2)).sum();
        if best.len() < k || d < best[best.len() - 1].0 {
            let at = best.partition_point(|&(bd, bi)| (bd, self.index[bi]) < (d, self.index[mid]));
            best.insert(at, (d, mid));
            best.truncate(k);
        }
        let dim = self.split[mid] as usize;
        let diff = q[dim] - self.points[mid][dim];
        let (near, far) = match diff < 0.0 {
            true => ((lo, mid), (mid + 1, hi)),
            false => ((mid + 1, hi), (lo, mid)),
        };
        self.search(q, k, near.0, near.1, best);
        if best.len() < k || diff * diff < best[best.len() - 1].0 {
            self.search(q, k, far.0, far.1, best);
        }
    }
}

/// Arrange `index` (a range of the tree) so that each range's median splits it along the
/// dimension of largest spread.
fn build(points: &[Point], index: &mut [usize], split: &mut [u8], offset: usize) {
    let n = index.len();
    if n <= 1 {
        return;
    }
    let dim = (0..6)
        .max_by(|&a, &b| spread(points, index, a).total_cmp(&spread(points, index, b)))
        .unwrap_or(0);
    let mid = n / 2;
    index.select_nth_unstable_by(mid, |&a, &b| {
        points[a][dim].total_cmp(&points[b][dim]).then(a.cmp(&b))
    });
    split[offset + mid] = dim as u8;
    let (left, right) = index.split_at_mut(mid);
    build(points, left, split, offset);
    build(points, &mut right[1..], split, offset + mid + 1);
}

fn spread(points: &[Point], index: &[usize], dim: usize) -> f64 {
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for &i in index {
        lo = lo.min(points[i][dim]);
        hi = hi.max(points[i][dim]);
    }
    hi - lo
}

/// How the neighbours' values are combined.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Method {
    /// A weighted mean, weights 1 / (d + `SOFTEN`)^power.
    Weighted {
        /// The power of the inverse distance.
        power: f64,
    },
    /// A local linear fit (weighted least squares of an affine function of the chart's
    /// coordinates, tricube weights over the neighbours, a touch of ridge), its value at the
    /// query clamped to the neighbours' range: exact for values linear in the coordinates, so
    /// what interpolating between sparse directions loses is second order.
    LocalLinear,
}

impl Method {
    /// In words, for the report.
    pub fn text(self) -> String {
        match self {
            Method::Weighted { power } => format!("a mean weighted 1/d^{power}"),
            Method::LocalLinear => "a local linear fit".into(),
        }
    }
}

/// k-nearest-neighbour interpolation of training values.
pub struct Predictor {
    tree: KdTree,
    points: Vec<Point>,
    /// The training sample each point stands for.
    origin: Vec<usize>,
    /// The training values in the space they are averaged in (one entry per training point).
    values: Vec<[f64; 3]>,
    /// Neighbours per prediction.
    pub k: usize,
    /// How the neighbours' values are combined.
    pub method: Method,
    /// The embedding.
    pub coordinates: Coordinates,
}

/// Added to each distance before it is inverted (about 0.006 deg): a repeated direction takes
/// nearly all the weight without dividing by zero.
const SOFTEN: f64 = 1e-4;

impl Predictor {
    /// A predictor from the training samples' `points` (each with the index of the sample it
    /// stands for, `origin`) and their `values` (already transformed: logs for the log metric).
    pub fn new(
        points: Vec<(Point, usize)>,
        values: Vec<[f64; 3]>,
        k: usize,
        method: Method,
        coordinates: Coordinates,
    ) -> Self {
        let (points, origin): (Vec<Point>, Vec<usize>) = points.into_iter().unzip();
        Self {
            tree: KdTree::new(&points),
            points,
            origin,
            values,
            k,
            method,
            coordinates,
        }
    }

    /// The interpolated (transformed) value at `q` and the sum of its smoother weights'
    /// squares (the share of one sample's noise variance the prediction carries: a mean of k
    /// equal weights has 1/k); `skip`: leave out the points of this training sample
    /// (leave-one-out).
    pub fn predict(&self, q: &Point, skip: Option<usize>) -> ([f64; 3], f64) {
        let extra = match skip {
            Some(_) => 4,
            None => 0,
        };
        let near: Vec<(f64, usize)> = self
            .tree
            .nearest(q, self.k + extra)
            .into_iter()
            .filter(|x| Some(self.origin[x.1]) != skip)
            .take(self.k)
            .collect();
        match self.method {
            Method::Weighted { power } => self.weighted(&near, power),
            Method::LocalLinear => self
                .local_linear(q, &near)
                .unwrap_or_else(|| self.weighted(&near, 2.0)),
        }
    }

    fn weighted(&self, near: &[(f64, usize)], power: f64) -> ([f64; 3], f64) {
        let w: Vec<f64> = near
            .iter()
            .map(|&(d2, _)| (d2.sqrt() + SOFTEN).powf(-power))
            .collect();
        let wsum = w.iter().sum::<f64>().max(f64::MIN_POSITIVE);
        let mut acc = [0.0; 3];
        for (&(_, i), wi) in near.iter().zip(&w) {
            for (a, v) in acc.iter_mut().zip(&self.values[self.origin[i]]) {
                *a += wi * v;
            }
        }
        let leverage = w.iter().map(|x| (x / wsum).powi(2)).sum();
        (acc.map(|a| a / wsum), leverage)
    }

    /// The local linear fit's value at `q` and its smoother weights' sum of squares (`None`
    /// when its normal equations are singular).
    fn local_linear(&self, q: &Point, near: &[(f64, usize)]) -> Option<([f64; 3], f64)> {
        let dim = self.coordinates.dim();
        let p = dim + 1;
        let h = near.last()?.0.sqrt() * 1.2 + SOFTEN;
        let mut a = nalgebra::DMatrix::<f64>::zeros(p, p);
        let mut b = nalgebra::DMatrix::<f64>::zeros(p, 3);
        let (mut lo, mut hi) = ([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]);
        let mut rows = Vec::with_capacity(near.len());
        for &(d2, i) in near {
            let w = (1.0 - (d2.sqrt() / h).powi(3)).powi(3).max(1e-6);
            let mut x = nalgebra::DVector::<f64>::from_element(p, 1.0);
            for j in 0..dim {
                x[j + 1] = self.points[i][j] - q[j];
            }
            let y = &self.values[self.origin[i]];
            a += w * &x * x.transpose();
            for ch in 0..3 {
                b.column_mut(ch).axpy(w * y[ch], &x, 1.0);
                lo[ch] = lo[ch].min(y[ch]);
                hi[ch] = hi[ch].max(y[ch]);
            }
            rows.push((w, x));
        }
        // a touch of ridge on the slopes: neighbours on a line still give an answer
        let ridge = 1e-4 * (1..p).map(|r| a[(r, r)]).sum::<f64>() / dim as f64;
        for r in 1..p {
            a[(r, r)] += ridge.max(1e-12);
        }
        let chol = a.cholesky()?;
        let beta = chol.solve(&b);
        // the smoother's weights: L_j = w_j x_j . A^-1 e_1
        let mut e1 = nalgebra::DVector::<f64>::zeros(p);
        e1[0] = 1.0;
        let u = chol.solve(&e1);
        let leverage = rows.iter().map(|(w, x)| (w * x.dot(&u)).powi(2)).sum();
        let value = std::array::from_fn(|ch| beta[(0, ch)].clamp(lo[ch], hi[ch]));
        Some((value, leverage))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};

    #[test]
    fn a_local_linear_fit_is_exact_for_values_linear_in_the_chart_and_a_mean_has_leverage_1_over_k(
    ) {
        let mut rng = rand::rngs::StdRng::seed_from_u64(3);
        let f = |p: &Point| 1.0 + 2.0 * p[0] - p[1] + 0.5 * p[3];
        let pts: Vec<(Point, usize)> = (0..400)
            .map(|i| {
                let mut p = [0.0; 6];
                for x in p.iter_mut().take(4) {
                    *x = rng.random::<f64>();
                }
                (p, i)
            })
            .collect();
        let values = pts.iter().map(|(p, _)| [f(p); 3]).collect::<Vec<_>>();
        let c = Coordinates::Directions;
        let ll = Predictor::new(pts.clone(), values.clone(), 12, Method::LocalLinear, c);
        let q = [0.4, 0.6, 0.5, 0.3, 0.0, 0.0];
        let (v, leverage) = ll.predict(&q, None);
        assert!((v[0] - f(&q)).abs() < 1e-3, "{} against {}", v[0], f(&q));
        assert!(leverage > 1.0 / 12.0 && leverage < 1.0, "{leverage}");
        let mean = Predictor::new(pts, values, 8, Method::Weighted { power: 0.0 }, c);
        assert!((mean.predict(&q, None).1 - 1.0 / 8.0).abs() < 1e-12);
    }

    #[test]
    fn the_tree_finds_what_a_scan_finds() {
        let mut rng = rand::rngs::StdRng::seed_from_u64(7);
        let pts: Vec<Point> = (0..500)
            .map(|_| std::array::from_fn(|_| rng.random::<f64>()))
            .collect();
        let tree = KdTree::new(&pts);
        for _ in 0..50 {
            let q: Point = std::array::from_fn(|_| rng.random::<f64>());
            let mut scan: Vec<(f64, usize)> = pts
                .iter()
                .enumerate()
                .map(|(i, p)| ((0..6).map(|j| (p[j] - q[j]).powi(2)).sum(), i))
                .collect();
            scan.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
            let got = tree.nearest(&q, 8);
            assert_eq!(
                got.iter().map(|x| x.1).collect::<Vec<_>>(),
                scan[..8].iter().map(|x| x.1).collect::<Vec<_>>()
            );
        }
    }
}
