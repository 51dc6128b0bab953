//! Bounded Levenberg–Marquardt as an argmin [`Solver`]: argmin has none.
//!
//! Needs from the problem: [`Operator`] (residuals r(x)) and [`Jacobian`] (J(x)), both on
//! `DVector<f64>`. Each iteration solves (J^T J + lambda diag(J^T J)) delta = -J^T r (Marquardt's
//! scaling, so parameters of different units are treated alike), projects x + delta onto the box
//! [lo, hi], and accepts the step if the cost sum(r^2) falls; otherwise lambda grows and the step
//! is retried. Bounds are honoured by projection, so a parameter whose optimum lies outside
//! ends exactly on its bound.
//!
//! The Jacobian is refreshed from the problem only when needed: after an accepted step it gets a
//! Broyden rank-1 update J += ((dr - J dx) dx^T) / (dx^T dx) (Broyden 1965; as in MINPACK's
//! hybrid methods), and a fresh one is taken after a rejected step, after 4 updates, and before
//! convergence is declared. Each finite-difference Jacobian costs one model evaluation per
//! parameter; a Broyden update costs none.
//!
//! Reference: K. Levenberg (1944), D. W. Marquardt (1963), "An algorithm for least-squares
//! estimation of nonlinear parameters", SIAM J. Appl. Math. 11(2); J. Nocedal & S. J. Wright,
//! Numerical Optimization (2006), ch. 10.

use argmin::core::{
    Error, IterState, Jacobian, Operator, Problem, Solver, State, TerminationReason,
    TerminationStatus, KV,
};
use nalgebra::{DMatrix, DVector};

pub type LmState = IterState<DVector<f64>, (), DMatrix<f64>, (), DVector<f64>, f64>;

#[derive(Clone, Debug)]
pub struct BoundedLm {
    lo: DVector<f64>,
    hi: DVector<f64>,
    lambda: f64,
    /// Stop when an accepted step lowers the cost by less than this fraction.
    tolerance: f64,
    /// Set when no step in this iteration lowered the cost.
    stalled: bool,
    last_relative_decrease: f64,
    /// Broyden updates since the last fresh Jacobian; None: take a fresh one next iteration.
    updates: Option<usize>,
    /// The last iteration's Jacobian was a fresh one.
    fresh: bool,
}

const MAX_BROYDEN_UPDATES: usize = 4;

impl BoundedLm {
    pub fn new(lo: DVector<f64>, hi: DVector<f64>, tolerance: f64) -> Self {
        Self {
            lo,
            hi,
            lambda: 1e-3,
            tolerance,
            stalled: false,
            last_relative_decrease: f64::INFINITY,
            updates: None,
            fresh: false,
        }
    }

    fn project(&self, x: &DVector<f64>) -> DVector<f64> {
        DVector::from_iterator(
            x.len(),
            (0..x.len()).map(|i| x[i].clamp(self.lo[i], self.hi[i])),
        )
    }
}

impl<O> Solver<O, LmState> for BoundedLm
where
    O: Operator<Param = DVector<f64>, Output = DVector<f64>>
        + Jacobian<Param = DVector<f64>, Jacobian = DMatrix<f64>>,
{
    fn name(&self) -> &str {
        "bounded Levenberg-Marquardt"
    }

    fn init(
        &mut self,
        problem: &mut Problem<O>,
        mut state: LmState,
    ) -> Result<(LmState, Option<KV>), Error> {
        let x0 = state
            .take_param()
            .ok_or_else(|| anyhow::anyhow!("bounded LM needs a start vector"))?;
        let x0 = self.project(&x0);
        let r = problem.apply(&x0)?;
        let cost = r.norm_squared();
        Ok((state.param(x0).residuals(r).cost(cost), None))
    }

    fn next_iter(
        &mut self,
        problem: &mut Problem<O>,
        state: LmState,
    ) -> Result<(LmState, Option<KV>), Error> {
        let x = state
            .get_param()
            .ok_or_else(|| anyhow::anyhow!("bounded LM: no parameter"))?
            .clone();
        let r = state
            .get_residuals()
            .ok_or_else(|| anyhow::anyhow!("bounded LM: no residuals"))?
            .clone();
        let cost = state.get_cost();
        let (j, fresh) = match (self.updates, state.get_jacobian()) {
            (Some(_), Some(j)) => (j.clone(), false),
            _ => (problem.jacobian(&x)?, true),
        };
        self.fresh = fresh;
        if fresh {
            self.updates = Some(0);
        }
        let jt = j.transpose();
        let a = &jt * &j;
        let g = &jt * &r;
        let n = x.len();
        // variables pinned at a bound with the gradient pushing outwards do not move
        let pinned: Vec<bool> = (0..n)
            .map(|i| (x[i] <= self.lo[i] && g[i] > 0.0) || (x[i] >= self.hi[i] && g[i] < 0.0))
            .collect();
        let diag_max = a.diagonal().amax();
        for _ in 0..12 {
            let mut m = a.clone();
            let mut rhs = -&g;
            for i in 0..n {
                let d = a[(i, i)].max(1e-12 * (1.0 + diag_max));
                m[(i, i)] += self.lambda * d;
            }
            for i in (0..n).filter(|&i| pinned[i]) {
                for k in 0..n {
                    m[(i, k)] = 0.0;
                    m[(k, i)] = 0.0;
                }
                m[(i, i)] = 1.0;
                rhs[i] = 0.0;
            }
            let Some(delta) = m.cholesky().map(|c| c.solve(&rhs)) else {
                self.lambda *= 10.0;
                continue;
            };
            let x_new = self.project(&(&x + &delta));
            let r_new = problem.apply(&x_new)?;
            let cost_new = r_new.norm_squared();
            if cost_new.is_finite() && cost_new < cost {
                self.lambda = (self.lambda / 3.0).max(1e-10);
                self.stalled = false;
                self.last_relative_decrease = (cost - cost_new) / cost.max(f64::MIN_POSITIVE);
                // Broyden rank-1 update with the step actually taken (after projection)
                let dx = &x_new - &x;
                let dxx = dx.norm_squared();
                let mut j_next = j;
                let n_up = self.updates.unwrap_or(0) + 1;
                if dxx > 0.0 && n_up <= MAX_BROYDEN_UPDATES {
                    let err = (&r_new - &r) - &j_next * &dx;
                    j_next += err * dx.transpose() / dxx;
                    self.updates = Some(n_up);
                } else {
                    self.updates = None;
                }
                let kv = argmin::kv!("lambda" => self.lambda; "cost" => cost_new; "fresh_jacobian" => fresh;);
                return Ok((
                    state
                        .param(x_new)
                        .residuals(r_new)
                        .cost(cost_new)
                        .jacobian(j_next),
                    Some(kv),
                ));
            }
            self.lambda *= 4.0;
            if !fresh {
                // the updated Jacobian may be what failed: retry with a fresh one
                self.updates = None;
                return Ok((state.param(x).residuals(r).cost(cost).jacobian(j), None));
            }
        }
        self.stalled = true;
        self.last_relative_decrease = 0.0;
        Ok((state.param(x).residuals(r).cost(cost).jacobian(j), None))
    }

    fn terminate(&mut self, state: &LmState) -> TerminationStatus {
        if self.stalled {
            return TerminationStatus::Terminated(TerminationReason::SolverConverged);
        }
        if state.get_iter() > 0 && self.last_relative_decrease < self.tolerance {
            if self.fresh {
                return TerminationStatus::Terminated(TerminationReason::SolverConverged);
            }
            // small progress on an updated Jacobian: confirm with a fresh one first
            self.updates = None;
        }
        if state.get_cost() == 0.0 {
            return TerminationStatus::Terminated(TerminationReason::TargetCostReached);
        }
        TerminationStatus::NotTerminated
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use argmin::core::Executor;

    /// Rosenbrock as least squares: r = (10 (y - x^2), 1 - x), minimum (1, 1).
    struct Rosen;
    impl Operator for Rosen {
        type Param = DVector<f64>;
        type Output = DVector<f64>;
        fn apply(&self, p: &DVector<f64>) -> Result<DVector<f64>, Error> {
            Ok(DVector::from_vec(vec![
                10.0 * (p[1] - p[0] * p[0]),
                1.0 - p[0],
            ]))
        }
    }
    impl Jacobian for Rosen {
        type Param = DVector<f64>;
        type Jacobian = DMatrix<f64>;
        fn jacobian(&self, p: &DVector<f64>) -> Result<DMatrix<f64>, Error> {
            Ok(DMatrix::from_row_slice(
                2,
                2,
                &[-20.0 * p[0], 10.0, -1.0, 0.0],
            ))
        }
    }

    #[test]
    fn finds_the_rosenbrock_minimum_and_respects_bounds() {
        let run = |lo: [f64; 2], hi: [f64; 2]| {
            let solver = BoundedLm::new(
                DVector::from_vec(lo.to_vec()),
                DVector::from_vec(hi.to_vec()),
                1e-15,
            );
            Executor::new(Rosen, solver)
                .configure(|c| c.param(DVector::from_vec(vec![-1.2, 1.0])).max_iters(200))
                .run()
                .unwrap()
                .state
        };
        let s = run([-5.0, -5.0], [5.0, 5.0]);
        let p = s.get_best_param().unwrap();
        assert!(
            (p[0] - 1.0).abs() < 1e-6 && (p[1] - 1.0).abs() < 1e-6,
            "{p}"
        );
        // optimum outside the box: ends on the bound x = 0.5, and y = x^2 there
        let s = run([-5.0, -5.0], [0.5, 5.0]);
        let p = s.get_best_param().unwrap();
        assert!(
            (p[0] - 0.5).abs() < 1e-12 && (p[1] - 0.25).abs() < 1e-6,
            "{p}"
        );
    }
}
