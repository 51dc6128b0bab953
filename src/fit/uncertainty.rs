//! Standard errors, correlations and fit statistics at the solution.
//!
//! cov = s^2 (J^T J)^-1 with s^2 = chi^2 / (n - p), from the SVD of J over the parameters not at a
//! bound; singular values below 1e-10 of the largest are dropped (pseudo-inverse) and the
//! corresponding right singular vector is reported as a non-identifiable combination.

use nalgebra::DMatrix;

#[derive(Clone, Debug)]
pub struct Covariance {
    /// Standard error per column (None: at a bound, or not identifiable).
    pub std_error: Vec<Option<f64>>,
    /// (i, j, r) for |r| > 0.1, sorted by |r| descending.
    pub correlations: Vec<(usize, usize, f64)>,
    /// Human-readable warnings (non-identifiable combinations).
    pub warnings: Vec<String>,
}

/// `j`: n x p Jacobian (taken, and reduced in place: at camera resolution it is the fit's largest
/// array); `names`: its column labels; `at_bound[k]`: column k sits on a bound; `chi2`: sum of
/// squared residuals; `n`: residual count.
pub fn covariance(
    j: DMatrix<f64>,
    names: &[String],
    at_bound: &[bool],
    chi2: f64,
    n: usize,
) -> Covariance {
    covariance_of_r(&reduce(j), names, at_bound, chi2, n)
}

/// The n x p Jacobian `j` reduced to the triangle R of its QR factorisation (min(n, p) x p,
/// factored in place): R^T R = J^T J, its columns have J's norms and any selection of its columns
/// has the singular values and right singular vectors of the same selection of J's, so every
/// covariance of J can be had from R — several (different columns held) without copying J.
pub fn reduce(j: DMatrix<f64>) -> DMatrix<f64> {
    match j.nrows() > j.ncols() {
        true => j.qr().r(),
        false => j,
    }
}

/// [`covariance`] from `r`: the Jacobian or its [`reduce`]d triangle.
pub fn covariance_of_r(
    r: &DMatrix<f64>,
    names: &[String],
    at_bound: &[bool],
    chi2: f64,
    n: usize,
) -> Covariance {
    let j = r;
    let p_all = j.ncols();
    let keep: Vec<usize> = (0..p_all).filter(|&k| !at_bound[k]).collect();
    let mut std_error = vec![None; p_all];
    let mut correlations = Vec::new();
    let mut warnings = Vec::new();
    if keep.is_empty() || n <= keep.len() {
        if n <= keep.len() && !keep.is_empty() {
            warnings.push(format!(
                "{n} residuals for {p_all} free parameters ({} of them off their bounds): no standard errors",
                keep.len()
            ));
        }
        return Covariance {
            std_error,
            correlations,
            warnings,
        };
    }
    let mut scaled = j.select_columns(&keep);
    // column scaling keeps the SVD threshold meaningful across units
    let norms: Vec<f64> = (0..scaled.ncols())
        .map(|k| scaled.column(k).norm().max(1e-300))
        .collect();
    for (k, nk) in norms.iter().enumerate() {
        scaled.column_mut(k).scale_mut(1.0 / nk);
    }
    let svd = scaled.svd(false, true);
    let v_t = svd.v_t.expect("requested V^T");
    let s = &svd.singular_values;
    let s_max = s.max();
    let p = keep.len();
    let s2 = chi2 / (n - p) as f64;
    let mut cov = DMatrix::zeros(p, p);
    for (i, &si) in s.iter().enumerate() {
        let row = v_t.row(i);
        if si > 1e-10 * s_max {
            cov += row.transpose() * row / (si * si);
        } else {
            let mut terms: Vec<(f64, &str)> = (0..p)
                .map(|k| (row[k], names[keep[k]].as_str()))
                .filter(|(c, _)| c.abs() > 0.05)
                .collect();
            terms.sort_by(|a, b| b.0.abs().total_cmp(&a.0.abs()));
            let combo: Vec<String> = terms
                .iter()
                .map(|(c, nm)| format!("{c:+.2} {nm}"))
                .collect();
            warnings.push(format!(
                "rank-deficient Jacobian: the data do not determine {} (scaled units); pseudo-inverse used",
                combo.join(" ")
            ));
        }
    }
    // undo the column scaling
    for a in 0..p {
        for b in 0..p {
            cov[(a, b)] *= s2 / (norms[a] * norms[b]);
        }
    }
    for a in 0..p {
        let var = cov[(a, a)];
        if var > 0.0 && var.is_finite() {
            std_error[keep[a]] = Some(var.sqrt());
        }
    }
    for a in 0..p {
        for b in (a + 1)..p {
            let d = (cov[(a, a)] * cov[(b, b)]).sqrt();
            if d > 0.0 {
                let r = cov[(a, b)] / d;
                if r.abs() > 0.1 {
                    correlations.push((keep[a], keep[b], r));
                }
            }
        }
    }
    correlations.sort_by(|x, y| y.2.abs().total_cmp(&x.2.abs()));
    Covariance {
        std_error,
        correlations,
        warnings,
    }
}

/// Fit statistics in lmfit's definitions. With sigmas the weighted sum of squares is a
/// chi-square; without, it is only a sum of squares, and the JSON names it so
/// (`sum_of_squares`, `residual_variance` instead of `chi_square`, `reduced_chi_square`).
#[derive(Clone, Debug)]
pub struct Statistics {
    /// Residuals (samples x channels).
    pub n: usize,
    pub free_parameters: usize,
    /// Sum of squared weighted residuals (a chi-square when sigmas are given).
    pub chi_square: f64,
    /// chi^2 / (n - p): the reduced chi-square with sigmas, the residual variance without.
    pub reduced_chi_square: f64,
    pub sigmas_given: bool,
    /// Unweighted root-mean-square of model - data, 1/sr.
    pub rmse: f64,
    /// RMSE / RMS(data).
    pub relative_rmse: f64,
    pub aic: f64,
    pub bic: f64,
}

impl Statistics {
    /// The names of `chi_square` and `reduced_chi_square` as they are: ("chi_square",
    /// "reduced_chi_square") with sigmas; without, chi-square is not defined: ("sum_of_squares",
    /// "residual_variance").
    pub fn names(&self) -> (&'static str, &'static str) {
        if self.sigmas_given {
            ("chi_square", "reduced_chi_square")
        } else {
            ("sum_of_squares", "residual_variance")
        }
    }
}

impl serde::Serialize for Statistics {
    fn serialize<S: serde::Serializer>(&self, ser: S) -> Result<S::Ok, S::Error> {
        use serde::ser::SerializeMap;
        let mut m = ser.serialize_map(Some(9))?;
        m.serialize_entry("n", &self.n)?;
        m.serialize_entry("free_parameters", &self.free_parameters)?;
        let (sum, reduced) = self.names();
        m.serialize_entry(sum, &self.chi_square)?;
        m.serialize_entry(reduced, &self.reduced_chi_square)?;
        m.serialize_entry("sigmas_given", &self.sigmas_given)?;
        m.serialize_entry("rmse", &self.rmse)?;
        m.serialize_entry("relative_rmse", &self.relative_rmse)?;
        m.serialize_entry("aic", &self.aic)?;
        m.serialize_entry("bic", &self.bic)?;
        m.end()
    }
}

pub fn statistics(
    chi2: f64,
    n: usize,
    p: usize,
    sigmas_given: bool,
    model: &[f64],
    data: &[f64],
) -> Statistics {
    let sq: f64 = model.iter().zip(data).map(|(m, y)| (m - y) * (m - y)).sum();
    let yy: f64 = data.iter().map(|y| y * y).sum();
    statistics_of_sums(chi2, n, p, sigmas_given, (sq, yy, model.len()))
}

/// [`statistics`] from sums over the values (data read a piece at a time): `(sq, yy, count)`
/// = the sum of (model - data)^2, the sum of data^2 and the number of values.
pub fn statistics_of_sums(
    chi2: f64,
    n: usize,
    p: usize,
    sigmas_given: bool,
    (sq, yy, count): (f64, f64, usize),
) -> Statistics {
    let nn = count.max(1) as f64;
    let rms_data = (yy / nn).sqrt();
    let rmse = (sq / nn).sqrt();
    let nf = n as f64;
    let chi_n = (chi2 / nf).max(f64::MIN_POSITIVE);
    Statistics {
        n,
        free_parameters: p,
        chi_square: chi2,
        reduced_chi_square: if n > p {
            chi2 / (n - p) as f64
        } else {
            f64::NAN
        },
        sigmas_given,
        rmse,
        relative_rmse: rmse / rms_data.max(f64::MIN_POSITIVE),
        aic: nf * chi_n.ln() + 2.0 * p as f64,
        bic: nf * chi_n.ln() + nf.ln() * p as f64,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn straight_line_errors_match_the_textbook() {
        // y = a + b x at x = 0..4 with residual scale 1: cov = s^2 (X^T X)^-1
        let x = [0.0, 1.0, 2.0, 3.0, 4.0];
        let j = DMatrix::from_fn(5, 2, |i, k| if k == 0 { 1.0 } else { x[i] });
        let chi2 = 3.0; // n - p = 3 -> s^2 = 1
        let c = covariance(j, &["a".into(), "b".into()], &[false, false], chi2, 5);
        // (X^T X)^-1 = [[0.6, -0.2], [-0.2, 0.1]]
        assert!((c.std_error[0].unwrap() - 0.6f64.sqrt()).abs() < 1e-12);
        assert!((c.std_error[1].unwrap() - 0.1f64.sqrt()).abs() < 1e-12);
        let r = c.correlations[0].2;
        assert!((r - (-0.2 / (0.06f64).sqrt())).abs() < 1e-12);
    }

    #[test]
    fn duplicated_column_is_named_as_non_identifiable() {
        let j = DMatrix::from_fn(6, 2, |i, _| i as f64 + 1.0);
        let c = covariance(
            j,
            &["spacing".into(), "height".into()],
            &[false, false],
            1.0,
            6,
        );
        assert!(
            c.warnings
                .iter()
                .any(|w| w.contains("spacing") && w.contains("height")),
            "{:?}",
            c.warnings
        );
    }
}
