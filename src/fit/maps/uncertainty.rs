//! The maps' uncertainties: a texel's standard errors from its Jacobian over all its unknowns
//! (scaled by the residual variance), and how much the global parameters' errors widen when the
//! sampled texels' maps are free as well (the Schur complement of the block-arrow normal
//! matrix), with the warning when they trade off.

use super::*;

impl Texel {
    /// Standard errors of the texel's unknowns from its Jacobian over all of them (nonlinear by
    /// differences, albedos analytic), scaled by `variance`.
    pub(super) fn std_errors(&self, g: &Globals, v: &TexelValues, variance: f64) -> TexelValues {
        let mut se = TexelValues::default();
        let (jcols, which) = self.jacobian(g, v);
        let p = jcols.len();
        let mut jtj: DMatrix<f64> = DMatrix::zeros(p, p);
        for a in 0..p {
            for b in 0..p {
                jtj[(a, b)] = jcols[a].iter().zip(&jcols[b]).map(|(x, y)| x * y).sum();
            }
        }
        let cov = jtj.try_inverse();
        for (k, &(kind, c)) in which.iter().enumerate() {
            let s = match &cov {
                Some(m) if m[(k, k)] >= 0.0 => (variance * m[(k, k)]).sqrt(),
                _ => f64::INFINITY,
            };
            match kind {
                0 => se.height = s,
                1 => se.psi = s,
                2 => se.kd[c] = s,
                _ => se.ks[c] = s,
            }
        }
        se
    }

    /// The Jacobian of the texel's residuals (its pixels' rows, then any prior rows) over its
    /// unknowns (nonlinear by differences, albedos analytic), one column each, with what each
    /// column is: (0 height | 1 psi | 2 kd | 3 ks, channel).
    pub(super) fn jacobian(
        &self,
        g: &Globals,
        v: &TexelValues,
    ) -> (Vec<Vec<f64>>, Vec<(u8, usize)>) {
        let cols = self.columns(g, v.height, v.psi);
        let r0 = self.residuals(g, &cols, v);
        let mut jcols: Vec<Vec<f64>> = Vec::new();
        let mut which: Vec<(u8, usize)> = Vec::new();
        let diff = |h: f64, psi: f64, step: f64| -> Vec<f64> {
            let mut w = *v;
            w.height = h;
            w.psi = psi;
            let c = self.columns(g, h, psi);
            let r = self.residuals(g, &c, &w);
            r.iter().zip(&r0).map(|(a, b)| (a - b) / step).collect()
        };
        if self.free.height {
            let step = 1e-5
                * g.h_max.max(1e-3)
                * if v.height + 1e-5 * g.h_max > g.h_max {
                    -1.0
                } else {
                    1.0
                };
            jcols.push(diff(v.height + step, v.psi, step));
            which.push((0, 0));
        }
        if self.free.psi {
            jcols.push(diff(v.height, v.psi + 1e-4, 1e-4));
            which.push((1, 0));
        }
        for (kind, comp, on) in [(2u8, 0usize, self.free.kd), (3, 1, self.free.ks)] {
            if !on {
                continue;
            }
            for c in 0..g.channels {
                let mut col = vec![0.0; r0.len()];
                for (i, (cl, sc)) in cols.iter().zip(&self.scale).enumerate() {
                    col[i * g.channels + c] = sc[c] * cl[comp];
                }
                jcols.push(col);
                which.push((kind, c));
            }
        }
        (jcols, which)
    }
}

/// How much each free global's variance grows when the sampled texels' maps are free as well:
/// the joint normal matrix of globals and texels is block-arrow shaped (each texel's unknowns
/// touch only its own pixels), so the globals' block of the joint covariance is the inverse of
/// the Schur complement S = A - sum_t B_t C_t^-1 B_t^T (A = J_g^T J_g, B_t = J_g,t^T J_t,
/// C_t = J_t^T J_t). Returns diag(S^-1) / diag(A^-1) per column of the global fit's full
/// parameter vector (free shapes, then free albedo channels); infinity where S is singular
/// there (the maps and that global trade off completely).
pub(super) fn map_inflation(
    sub: &Samples,
    layout: &Layout,
    cfg: &FitConfig,
    set: &ParamSet,
    values: &[TexelValues],
    free: Free,
) -> Result<Vec<f64>> {
    let (subset, maps) = mapped_all(sub, values, &layout.members, free);
    let p = problem_on(cfg, set, &subset, maps);
    let cols = p.columns(set)?;
    let jg = p.full_jacobian(set, &cols)?;
    let ch = p.channels();
    let a = jg.transpose() * &jg;
    let mut schur = a.clone();
    let model = rung_of(set, cfg);
    let g = Globals::of(set, model.as_ref(), ch);
    let all: Vec<usize> = (0..layout.texels.len()).collect();
    let mut row = 0;
    for (t, texel) in layout
        .problems(sub, &all, values, free, 0.0)
        .iter()
        .enumerate()
    {
        let rows = texel.obs.len() * ch;
        let (jt, _) = texel.jacobian(&g, &values[t]);
        let jt = DMatrix::from_fn(rows, jt.len(), |i, k| jt[k][i]);
        let b = jg.rows(row, rows).transpose() * &jt;
        if let Some(ci) = (jt.transpose() * &jt).try_inverse() {
            schur -= &b * ci * b.transpose();
        }
        row += rows;
    }
    if row != jg.nrows() {
        bail!(
            "internal: the texels' rows ({row}) do not cover the global fit's ({})",
            jg.nrows()
        );
    }
    let (ai, si) = (a.try_inverse(), schur.try_inverse());
    Ok((0..jg.ncols())
        .map(|k| match (&ai, &si) {
            (Some(ai), Some(si)) if ai[(k, k)] > 0.0 && si[(k, k)] > 0.0 => {
                (si[(k, k)] / ai[(k, k)]).max(1.0)
            }
            _ => f64::INFINITY,
        })
        .collect())
}

/// Widen the global records' standard errors by the square root of `inflation` (per column of
/// the full parameter vector, as [`map_inflation`] gives it); a warning when any grows more than
/// twofold.
pub(super) fn inflate_records(
    outcome: &mut FitOutcome,
    set: &ParamSet,
    inflation: &[f64],
) -> Option<String> {
    let mut col = 0;
    let mut worst: (f64, String) = (1.0, String::new());
    let mut widen = |r: &mut crate::fit::ParamRecord, c: usize, f: f64| {
        // parameters at a bound have no standard error to widen
        if r.std_error[c].is_some() && f > worst.0 {
            worst = (f, r.name.clone());
        }
        r.std_error[c] = if f.is_finite() {
            r.std_error[c].map(|e| e * f.sqrt())
        } else {
            None
        };
    };
    let n_shapes = set.shapes.len();
    for (i, sh) in set.shapes.iter().enumerate() {
        if sh.vary {
            widen(&mut outcome.records[i], 0, inflation[col]);
            col += 1;
        }
    }
    for (i, a) in set.albedos.iter().enumerate() {
        if a.vary {
            // a grey albedo (ks) is one column of the full parameter vector for every channel
            let channels = outcome.records[n_shapes + i].std_error.len();
            for c in 0..channels {
                widen(&mut outcome.records[n_shapes + i], c, inflation[col]);
                if !a.grey || c + 1 == channels {
                    col += 1;
                }
            }
        }
    }
    (worst.0 > 4.0).then(|| {
        let factor = if worst.0.is_finite() {
            format!("{:.0} times", worst.0.sqrt())
        } else {
            "without bound".to_string()
        };
        format!(
            "the global parameters trade off with the maps: with the texels' values free too, the standard error of `{}` grows {factor} (the errors reported include that); per-texel errors do not include the globals' uncertainty, so treat them as too small: add light and view directions that separate the maps from the globals",
            worst.1
        )
    })
}
