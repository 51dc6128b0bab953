//! Basins of the cost: points the polishing reached, and when two of them are one (a distance
//! as a fraction of the parameter box, between the points or between their canonical
//! representatives: a symmetry of the rung's parameters is one solution). Shared by the global
//! stage and the polishing.

use super::parameters::ParamSet;
use super::problem::FitProblem;
use nalgebra::DVector;

/// A basin found on the subsample: its polished point and cost there.
#[derive(Clone, Debug)]
pub struct Basin {
    pub theta: DVector<f64>,
    pub cost: f64,
}

/// Polished points closer than this are one basin.
pub const BASIN_SEPARATION: f64 = 0.02;

/// Distance between two points as a fraction of the box, RMS over the coordinates; periodic
/// coordinates (the azimuth) take the shorter way round.
pub fn box_distance(
    a: &DVector<f64>,
    b: &DVector<f64>,
    lo: &DVector<f64>,
    hi: &DVector<f64>,
    periods: &[Option<f64>],
) -> f64 {
    let n = a.len().max(1) as f64;
    let sum: f64 = (0..a.len())
        .map(|i| {
            let mut d = (a[i] - b[i]).abs();
            if let Some(p) = periods[i] {
                d = d.rem_euclid(p);
                d = d.min(p - d);
            }
            (d / (hi[i] - lo[i]).max(1e-12)).powi(2)
        })
        .sum();
    (sum / n).sqrt()
}

/// How far apart two points of one problem are: [`box_distance`] between the points or between
/// their canonical representatives ([`crate::model::Rung::canonicalise`] over the free shapes),
/// whichever is nearer, so points a symmetry of the rung maps onto each other are one basin.
pub struct Metric<'p, 'a> {
    problem: &'p FitProblem<'a>,
    template: &'p ParamSet,
    lo: DVector<f64>,
    hi: DVector<f64>,
    periods: Vec<Option<f64>>,
}

impl<'p, 'a> Metric<'p, 'a> {
    /// The metric of `problem`'s design box, its sets built on `template`.
    pub fn of(problem: &'p FitProblem<'a>, template: &'p ParamSet) -> Self {
        let (lo, hi) = problem.design_box();
        Self {
            problem,
            template,
            lo,
            hi,
            periods: problem.periods(),
        }
    }

    /// theta of the canonical representative of the set at `theta`.
    pub fn canonical(&self, theta: &DVector<f64>) -> DVector<f64> {
        let mut set = self.problem.set_at(theta, self.template);
        let mut values: Vec<(crate::model::parameter::Param, f64)> = set
            .shapes
            .iter()
            .filter(|s| s.vary)
            .map(|s| (s.kind, s.value))
            .collect();
        set.rung.rung().canonicalise(&mut values);
        for (s, (_, v)) in set.shapes.iter_mut().filter(|s| s.vary).zip(values) {
            s.value = v;
        }
        self.problem.theta_of(&set)
    }

    /// A point with its canonical representative, for [`Metric::distance`].
    pub fn keyed(&self, theta: DVector<f64>) -> Keyed {
        Keyed {
            canonical: self.canonical(&theta),
            theta,
        }
    }

    /// The distance between `a` and `b` as a fraction of the box: the nearer of the points'
    /// and their canonical representatives' (near the canonical boundary, e.g. Ward's
    /// `alpha_x = alpha_y`, two close points may have far representatives).
    pub fn distance(&self, a: &Keyed, b: &Keyed) -> f64 {
        let d = |x: &DVector<f64>, y: &DVector<f64>| {
            box_distance(x, y, &self.lo, &self.hi, &self.periods)
        };
        d(&a.theta, &b.theta).min(d(&a.canonical, &b.canonical))
    }
}

/// A point and its canonical representative ([`Metric::keyed`]).
pub struct Keyed {
    /// The point.
    pub theta: DVector<f64>,
    /// Its canonical representative.
    pub canonical: DVector<f64>,
}
