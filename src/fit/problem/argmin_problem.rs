//! The problem as argmin sees it: residuals (`Operator`) and their Jacobian (`Jacobian`) of
//! the internal vector theta.

#[allow(unused_imports)]
use super::*;

/// argmin's view: theta -> residuals, with the template's fixed values.
pub struct ArgminProblem<'p, 'a> {
    pub inner: &'p FitProblem<'a>,
    pub base: ParamSet,
    /// The last (theta, residuals), so the Jacobian does not evaluate the base point again.
    last: std::sync::Mutex<Option<(DVector<f64>, DVector<f64>)>>,
}

impl<'p, 'a> ArgminProblem<'p, 'a> {
    pub fn new(inner: &'p FitProblem<'a>, base: ParamSet) -> Self {
        Self {
            inner,
            base,
            last: std::sync::Mutex::new(None),
        }
    }

    fn residuals_at(&self, theta: &DVector<f64>) -> Result<DVector<f64>, anyhow::Error> {
        if let Some((t, r)) = self.last.lock().expect("not poisoned").as_ref() {
            if t == theta {
                return Ok(r.clone());
            }
        }
        let r = self.inner.evaluate_keeping(theta, &self.base, true)?.0;
        *self.last.lock().expect("not poisoned") = Some((theta.clone(), r.clone()));
        Ok(r)
    }
}

impl Operator for ArgminProblem<'_, '_> {
    type Param = DVector<f64>;
    type Output = DVector<f64>;

    fn apply(&self, theta: &Self::Param) -> Result<Self::Output, ArgminError> {
        self.residuals_at(theta)
    }
}

impl Jacobian for ArgminProblem<'_, '_> {
    type Param = DVector<f64>;
    type Jacobian = DMatrix<f64>;

    /// Forward differences of the (reduced) residual, columns in parallel.
    fn jacobian(&self, theta: &Self::Param) -> Result<Self::Jacobian, ArgminError> {
        let r0 = self.residuals_at(theta)?;
        let (_, hi) = self.inner.bounds();
        let cols: Vec<DVector<f64>> = (0..theta.len())
            .into_par_iter()
            .map(|k| {
                let h = self.inner.step(theta, k, &hi);
                let mut t = theta.clone();
                t[k] += h;
                let (r, _) = self.inner.evaluate(&t, &self.base)?;
                Ok((r - &r0) / h)
            })
            .collect::<Result<_, anyhow::Error>>()?;
        let mut j = DMatrix::zeros(r0.len(), theta.len());
        for (k, c) in cols.iter().enumerate() {
            j.set_column(k, c);
        }
        Ok(j)
    }
}
