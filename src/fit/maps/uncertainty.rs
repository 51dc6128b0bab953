//! The maps' uncertainties. The normal matrix of the globals and every texel's unknowns is
//! block-arrow shaped (each texel's unknowns touch only its own pixels): with A = J_g^T J_g (the
//! free globals), B_t = J_g,t^T J_t (globals x texel t's unknowns, from its pixels) and
//! C_t = J_t^T J_t (texel t's own block; pixel weights 1/sigma), the globals' covariance is S^-1,
//! S = A - sum_t B_t C_t^-1 B_t^T (the Schur complement), and texel t's block of the joint
//! covariance is C_t^-1 + C_t^-1 B_t^T S^-1 B_t C_t^-1: its own noise plus what the globals'
//! uncertainty moves it by. Both are scaled by the residual variance.
//!
//! The global stage sums S over the texels its globals come from (its seeded sample:
//! [`global_schur`]); the texel stage adds the second term for every texel from that texel's own
//! B_t ([`Texel::std_errors`]), so no B_t is stored and the full normal matrix is never formed.
//! For a sampled texel this is exactly its block of the inverse of the full normal matrix; for
//! the others, whose pixels did not enter the globals, it is the exact linear propagation of the
//! globals' covariance S^-1 into a texel fitted given them. Directions the data leave
//! undetermined make every value they reach infinite: C_t or S singular, an eigenvalue at or
//! below [`NULL_EIGENVALUE`] once C_t is scaled to unit diagonal and S by the diagonal of A (S is
//! A less what the maps take, so a global the maps take entirely has S's diagonal at A's rounding
//! level, not 0); near-singular ones give large errors by themselves. Also: how much the globals' own errors widen
//! (diag S^-1 / diag A^-1), with the warning when they trade off with the maps.

use super::*;

/// Eigenvalues of a normal matrix scaled to a unit reference diagonal (its own, or A's for S) at
/// or below this are directions the data leave undetermined; a value whose squared component
/// along them exceeds this fraction of its squared norm is undetermined too.
pub const NULL_EIGENVALUE: f64 = 1e-12;

/// The globals' Schur complement S (before scaling by the residual variance): all the texel
/// stage needs of the global stage for texel errors that include the globals' uncertainty. A
/// result's `maps.method.global_schur` carries it, so tiles fitted from `--map-globals` share it
/// exactly.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct GlobalSchur {
    /// The free globals, in the full Jacobian's order (free shapes, then free albedo channels).
    pub names: Vec<String>,
    /// S, row-major, `names.len()`^2 values.
    pub matrix: Vec<f64>,
    /// The diagonal of A (the globals' normal matrix with the maps held fixed): the scale S's
    /// undetermined directions are judged on.
    pub reference: Vec<f64>,
    /// Texels it sums over (the global stage's sample).
    pub texels: usize,
}

impl GlobalSchur {
    fn to_matrix(&self) -> DMatrix<f64> {
        let n = self.names.len();
        DMatrix::from_fn(n, n, |i, j| self.matrix[i * n + j])
    }
}

/// A symmetric positive semi-definite matrix M ready for quadratic forms a^T M^+ a and solves
/// M^+ a: M = D^-1 M' D^-1 with D = diag(reference)^-1/2, M' eigen-decomposed.
pub(super) struct SymInverse {
    /// D; 0 where the reference is not positive (a value with no effect).
    scale: Vec<f64>,
    values: Vec<f64>,
    /// Eigenvectors of M', one column each.
    vectors: DMatrix<f64>,
}

impl SymInverse {
    /// Scaled by its own diagonal.
    pub(super) fn new(m: &DMatrix<f64>) -> Self {
        let d: Vec<f64> = m.diagonal().iter().copied().collect();
        Self::scaled(m, &d)
    }

    /// Scaled by the diagonal `reference` (the matrix M is a part of).
    pub(super) fn scaled(m: &DMatrix<f64>, reference: &[f64]) -> Self {
        let n = m.nrows();
        let scale: Vec<f64> = (0..n)
            .map(|k| {
                let d = reference[k];
                if d > 0.0 && d.is_finite() {
                    1.0 / d.sqrt()
                } else {
                    0.0
                }
            })
            .collect();
        let scaled = DMatrix::from_fn(n, n, |i, j| {
            let x = 0.5 * (m[(i, j)] + m[(j, i)]) * scale[i] * scale[j];
            if x.is_finite() {
                x
            } else {
                0.0
            }
        });
        if n == 0 {
            // no free global (every value mapped or held): nothing to invert
            return Self {
                scale,
                values: vec![],
                vectors: DMatrix::zeros(0, 0),
            };
        }
        let eig = scaled.symmetric_eigen();
        Self {
            scale,
            values: eig.eigenvalues.iter().copied().collect(),
            vectors: eig.eigenvectors,
        }
    }

    /// a^T M^+ a; infinity when `a` reaches a direction M leaves undetermined.
    pub(super) fn quadratic(&self, a: &[f64]) -> f64 {
        let n = self.scale.len();
        let norm2: f64 = a.iter().map(|x| x * x).sum();
        if norm2 == 0.0 {
            return 0.0;
        }
        if !norm2.is_finite() {
            return f64::INFINITY;
        }
        // a value with no effect at all
        let dead: f64 = (0..n)
            .filter(|&k| self.scale[k] == 0.0)
            .map(|k| a[k] * a[k])
            .sum();
        if dead > NULL_EIGENVALUE * norm2 {
            return f64::INFINITY;
        }
        let da: Vec<f64> = (0..n).map(|k| a[k] * self.scale[k]).collect();
        let dnorm2: f64 = da.iter().map(|x| x * x).sum();
        let mut q = 0.0;
        for j in 0..n {
            let p: f64 = (0..n).map(|k| self.vectors[(k, j)] * da[k]).sum();
            if self.values[j] > NULL_EIGENVALUE {
                q += p * p / self.values[j];
            } else if p * p > NULL_EIGENVALUE * dnorm2 {
                return f64::INFINITY;
            }
        }
        q
    }

    /// M^+ a, the undetermined directions left out.
    pub(super) fn solve(&self, a: &[f64]) -> Vec<f64> {
        let n = self.scale.len();
        let da: Vec<f64> = (0..n).map(|k| a[k] * self.scale[k]).collect();
        let mut x = vec![0.0; n];
        for j in 0..n {
            if self.values[j] <= NULL_EIGENVALUE {
                continue;
            }
            let p: f64 = (0..n).map(|k| self.vectors[(k, j)] * da[k]).sum::<f64>() / self.values[j];
            for (k, xk) in x.iter_mut().enumerate() {
                *xk += self.vectors[(k, j)] * p;
            }
        }
        for (k, xk) in x.iter_mut().enumerate() {
            *xk *= self.scale[k];
        }
        x
    }
}

/// Variances of one texel's unknowns (unscaled) from its own block `c` (C_t), its cross block
/// `b` with the globals (B_t, globals x unknowns) and the globals' Schur complement inverse
/// `s`: diag(C^-1 + C^-1 B^T S^-1 B C^-1); infinity where C or S leaves a value undetermined.
/// Without `b` and `s`, diag(C^-1) (the globals held fixed).
pub(super) fn texel_variances(
    c: &DMatrix<f64>,
    globals: Option<(&DMatrix<f64>, &SymInverse)>,
) -> Vec<f64> {
    let p = c.nrows();
    let own = SymInverse::new(c);
    (0..p)
        .map(|k| {
            let mut e = vec![0.0; p];
            e[k] = 1.0;
            let var = own.quadratic(&e);
            match globals {
                Some((b, s)) if var.is_finite() && b.nrows() > 0 => {
                    // the globals' shift that moves this value: B C^-1 e_k
                    let y = own.solve(&e);
                    let a: Vec<f64> = (0..b.nrows())
                        .map(|i| (0..p).map(|j| b[(i, j)] * y[j]).sum())
                        .collect();
                    var + s.quadratic(&a)
                }
                _ => var,
            }
        })
        .collect()
}

/// The free globals of a set as the Jacobian steps them: per free shape the set moved by its
/// step ([`problem::jacobian_step`], as the global fit's own Jacobian) with the rung there, and
/// per free albedo channel its component and channel (analytic columns).
pub(super) struct GlobalSteps {
    shapes: Vec<(ParamSet, f64)>,
    models: Vec<Box<dyn ShadingModel>>,
    /// (component index of the columns, channel) per free albedo channel.
    albedos: Vec<(usize, usize)>,
    /// Labels, in the full Jacobian's order.
    pub(super) names: Vec<String>,
}

impl GlobalSteps {
    pub(super) fn new(set: &ParamSet, cfg: &FitConfig) -> Self {
        let mut out = Self {
            shapes: vec![],
            models: vec![],
            albedos: vec![],
            names: vec![],
        };
        for i in set.free_shapes() {
            let (s2, h) = problem::jacobian_step(set, i);
            out.models.push(rung_of(&s2, cfg));
            out.shapes.push((s2, h));
            out.names.push(set.shapes[i].kind.name().to_string());
        }
        for (a, c) in set.free_albedos() {
            out.albedos
                .push((component_index(set.albedos[a].component), c));
            out.names.push(problem::albedo_label(set, a, c));
        }
        out
    }

    pub(super) fn len(&self) -> usize {
        self.names.len()
    }

    /// The stepped globals, one per free shape, for `channels`.
    pub(super) fn globals(&self, channels: usize) -> Vec<Globals<'_>> {
        self.shapes
            .iter()
            .zip(&self.models)
            .map(|((s, _), m)| Globals::of(s, m.as_ref(), channels))
            .collect()
    }
}

/// What a texel's errors need of the globals: their steps, the stepped globals and the inverse
/// of their Schur complement (none: the globals held fixed).
pub(super) struct GlobalSide<'a> {
    pub(super) steps: &'a GlobalSteps,
    pub(super) stepped: Vec<Globals<'a>>,
    pub(super) schur: Option<SymInverse>,
}

impl<'a> GlobalSide<'a> {
    pub(super) fn new(
        steps: &'a GlobalSteps,
        channels: usize,
        schur: Option<&GlobalSchur>,
    ) -> Self {
        Self {
            steps,
            stepped: steps.globals(channels),
            schur: schur.map(|s| SymInverse::scaled(&s.to_matrix(), &s.reference)),
        }
    }
}

/// J^T J of columns.
fn gram(cols: &[Vec<f64>]) -> DMatrix<f64> {
    let p = cols.len();
    let mut m: DMatrix<f64> = DMatrix::zeros(p, p);
    for a in 0..p {
        for b in a..p {
            let x: f64 = cols[a].iter().zip(&cols[b]).map(|(x, y)| x * y).sum();
            m[(a, b)] = x;
            m[(b, a)] = x;
        }
    }
    m
}

impl Texel {
    /// Standard errors of the texel's unknowns, scaled by `variance`: from its Jacobian over all
    /// of them (nonlinear by differences, albedos analytic) and, with `globals`' Schur
    /// complement, the globals' uncertainty too (C^-1 + C^-1 B^T S^-1 B C^-1); infinity where
    /// the data leave a value undetermined.
    pub(super) fn std_errors(
        &self,
        g: &Globals,
        v: &TexelValues,
        globals: Option<&GlobalSide>,
        variance: f64,
    ) -> TexelValues {
        let mut se = TexelValues::default();
        let (jcols, which) = self.jacobian(g, v);
        let c = gram(&jcols);
        let cross = globals.and_then(|side| {
            let s = side.schur.as_ref()?;
            let jg = self.global_jacobian(g, side, v);
            let n = jg.nrows();
            // the globals touch the pixel rows only (not the prior's)
            let b = DMatrix::from_fn(jg.ncols(), jcols.len(), |i, k| {
                (0..n).map(|r| jg[(r, i)] * jcols[k][r]).sum()
            });
            Some((b, s))
        });
        let vars = texel_variances(&c, cross.as_ref().map(|(b, s)| (b, *s)));
        for (&(kind, ch), var) in which.iter().zip(vars) {
            let s = if var.is_finite() && var >= 0.0 {
                (variance * var).sqrt()
            } else {
                f64::INFINITY
            };
            match kind {
                0 => se.height = s,
                1 => se.psi = s,
                2 => se.kd[ch] = s,
                3 => se.ks[ch] = s,
                4 => se.roughness = s,
                _ => se.anisotropy = s,
            }
        }
        se
    }

    /// The texel's terms of the globals' normal matrix and Schur complement: (J_g,t^T J_g,t,
    /// B_t C_t^-1 B_t^T), the undetermined directions of C_t left out (they are B_t's too).
    pub(super) fn schur_terms(
        &self,
        g: &Globals,
        side: &GlobalSide,
        v: &TexelValues,
    ) -> (DMatrix<f64>, DMatrix<f64>) {
        let jg = self.global_jacobian(g, side, v);
        let (jcols, _) = self.jacobian(g, v);
        let n = jg.nrows();
        let ng = jg.ncols();
        let a = jg.transpose() * &jg;
        let own = SymInverse::new(&gram(&jcols));
        let b: Vec<Vec<f64>> = (0..ng)
            .map(|i| {
                jcols
                    .iter()
                    .map(|col| (0..n).map(|r| jg[(r, i)] * col[r]).sum())
                    .collect()
            })
            .collect();
        let y: Vec<Vec<f64>> = b.iter().map(|bi| own.solve(bi)).collect();
        let bcb = DMatrix::from_fn(ng, ng, |i, j| {
            b[i].iter().zip(&y[j]).map(|(x, z)| x * z).sum::<f64>()
        });
        (a, 0.5 * (&bcb + bcb.transpose()))
    }

    /// The Jacobian of the texel's pixel residuals over the free globals (columns as
    /// [`GlobalSteps`]: shapes by the global fit's own steps, albedos analytic) at `v`. A global
    /// the texel does not map moves the texel's unmapped values with it (as its start does).
    pub(super) fn global_jacobian(
        &self,
        g: &Globals,
        side: &GlobalSide,
        v: &TexelValues,
    ) -> DMatrix<f64> {
        let ch = g.channels;
        let n = self.obs.len() * ch;
        let cols0 = self.columns(g, v);
        let r0 = self.residuals(g, &cols0, v);
        let steps = side.steps;
        let mut j = DMatrix::zeros(n, steps.len());
        for (k, ((set_k, h), gk)) in steps.shapes.iter().zip(&side.stepped).enumerate() {
            let mut w = *v;
            let s = start_value(&self.obs[0], set_k);
            if !self.free.height {
                w.height = s.height;
            }
            if !self.free.psi {
                w.psi = s.psi;
            }
            if !self.free.roughness {
                w.roughness = s.roughness;
            }
            if !self.free.anisotropy {
                w.anisotropy = s.anisotropy;
            }
            let cols = self.columns(gk, &w);
            let r = self.residuals(gk, &cols, &w);
            for i in 0..n {
                j[(i, k)] = (r[i] - r0[i]) / h;
            }
        }
        let off = steps.shapes.len();
        for (a, &(comp, c)) in steps.albedos.iter().enumerate() {
            for (i, (col, sc)) in cols0.iter().zip(&self.scale).enumerate() {
                j[(i * ch + c, off + a)] = sc[c] * col[comp];
            }
        }
        j
    }

    /// The Jacobian of the texel's residuals (its pixels' rows, then any prior rows) over its
    /// unknowns (nonlinear by differences, albedos analytic), one column each, with what each
    /// column is: (0 height | 1 psi | 2 kd | 3 ks | 4 roughness | 5 anisotropy, channel).
    pub(super) fn jacobian(
        &self,
        g: &Globals,
        v: &TexelValues,
    ) -> (Vec<Vec<f64>>, Vec<(u8, usize)>) {
        let cols = self.columns(g, v);
        let r0 = self.residuals(g, &cols, v);
        let mut jcols: Vec<Vec<f64>> = Vec::new();
        let mut which: Vec<(u8, usize)> = Vec::new();
        let diff_of = |w: TexelValues, step: f64| -> Vec<f64> {
            let c = self.columns(g, &w);
            let r = self.residuals(g, &c, &w);
            r.iter().zip(&r0).map(|(a, b)| (a - b) / step).collect()
        };
        let diff = |h: f64, psi: f64, step: f64| -> Vec<f64> {
            diff_of(
                TexelValues {
                    height: h,
                    psi,
                    ..*v
                },
                step,
            )
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
        // the lobe's values one-sided inside their bounds
        let inside = |x: f64, hi: f64| if x + 1e-5 > hi { -1e-5 } else { 1e-5 };
        if self.free.roughness {
            let step = inside(v.roughness, g.roughness_range[1]);
            let w = TexelValues {
                roughness: v.roughness + step,
                ..*v
            };
            jcols.push(diff_of(w, step));
            which.push((4, 0));
        }
        if self.free.anisotropy {
            let step = inside(v.anisotropy, 1.0);
            let w = TexelValues {
                anisotropy: v.anisotropy + step,
                ..*v
            };
            jcols.push(diff_of(w, step));
            which.push((5, 0));
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

/// Texels per chunk of the sums over texels (fixed, so the sums' bits do not depend on the
/// thread count).
const SUM_CHUNK: usize = 64;

/// The globals' Schur complement over the sampled texels (their maps at `values`), and how much
/// each free global's variance grows when those maps are free as well: diag(S^-1) / diag(A^-1)
/// per column of the full parameter vector (free shapes, then free albedo channels), infinity
/// where S leaves it undetermined (the maps and that global trade off completely).
pub(super) fn global_schur(
    sub: &Samples,
    layout: &Layout,
    cfg: &FitConfig,
    set: &ParamSet,
    values: &[TexelValues],
    free: Free,
) -> Result<(GlobalSchur, Vec<f64>)> {
    let ch = sub.channels;
    let model = rung_of(set, cfg);
    let g = Globals::of(set, model.as_ref(), ch);
    let steps = GlobalSteps::new(set, cfg);
    let side = GlobalSide::new(&steps, ch, None);
    let ng = steps.len();
    let all: Vec<usize> = (0..layout.texels.len()).collect();
    let texels = layout.problems(sub, &all, values, free, 0.0);
    let rows: usize = texels.iter().map(|t| t.obs.len() * ch).sum();
    if rows != sub.samples.len() * ch {
        bail!(
            "internal: the texels' rows ({rows}) do not cover the global fit's ({})",
            sub.samples.len() * ch
        );
    }
    let chunks: Vec<(DMatrix<f64>, DMatrix<f64>)> = texels
        .par_chunks(SUM_CHUNK)
        .zip(values.par_chunks(SUM_CHUNK))
        .map(|(ts, vs)| {
            let mut a = DMatrix::zeros(ng, ng);
            let mut bcb = DMatrix::zeros(ng, ng);
            for (t, v) in ts.iter().zip(vs) {
                let (at, bt) = t.schur_terms(&g, &side, v);
                a += at;
                bcb += bt;
            }
            (a, bcb)
        })
        .collect();
    let mut a = DMatrix::zeros(ng, ng);
    let mut bcb = DMatrix::zeros(ng, ng);
    for (at, bt) in chunks {
        a += at;
        bcb += bt;
    }
    let s = &a - bcb;
    let reference: Vec<f64> = a.diagonal().iter().copied().collect();
    let (ai, si) = (SymInverse::new(&a), SymInverse::scaled(&s, &reference));
    let inflation = (0..ng)
        .map(|k| {
            let mut e = vec![0.0; ng];
            e[k] = 1.0;
            let (va, vs) = (ai.quadratic(&e), si.quadratic(&e));
            if va > 0.0 && va.is_finite() && vs > 0.0 && vs.is_finite() {
                (vs / va).max(1.0)
            } else {
                f64::INFINITY
            }
        })
        .collect();
    Ok((
        GlobalSchur {
            names: steps.names.clone(),
            matrix: s.transpose().iter().copied().collect(),
            reference,
            texels: texels.len(),
        },
        inflation,
    ))
}

/// Widen the global records' standard errors by the square root of `inflation` (per column of
/// the full parameter vector, as [`global_schur`] gives it); a warning when any grows more than
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
            "the global parameters trade off with the maps: with the texels' values free too, the standard error of `{}` grows {factor} (the errors reported include that, and so do the per-texel errors, which widen with it): add light and view directions that separate the maps from the globals",
            worst.1
        )
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};

    /// A tiny block-arrow least-squares problem: the full Jacobian (every texel's rows; the
    /// globals' columns first, then each texel's own) and its parts.
    struct Tiny {
        full: DMatrix<f64>,
        globals: usize,
        unknowns: usize,
        rows: usize,
        texels: usize,
    }

    impl Tiny {
        fn new(globals: usize, texels: usize, unknowns: usize, rows: usize, seed: u64) -> Self {
            let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
            let mut full = DMatrix::zeros(texels * rows, globals + texels * unknowns);
            for t in 0..texels {
                for r in t * rows..(t + 1) * rows {
                    for g in 0..globals {
                        full[(r, g)] = rng.random_range(-1.0..1.0);
                    }
                    for k in 0..unknowns {
                        full[(r, globals + t * unknowns + k)] = rng.random_range(-1.0..1.0);
                    }
                }
            }
            Self {
                full,
                globals,
                unknowns,
                rows,
                texels,
            }
        }

        fn jg(&self, t: usize) -> DMatrix<f64> {
            self.full
                .view((t * self.rows, 0), (self.rows, self.globals))
                .into_owned()
        }

        fn jt(&self, t: usize) -> DMatrix<f64> {
            self.full
                .view(
                    (t * self.rows, self.globals + t * self.unknowns),
                    (self.rows, self.unknowns),
                )
                .into_owned()
        }

        /// S = A - sum_t B_t C_t^+ B_t^T, as [`global_schur`] sums it.
        fn schur(&self) -> DMatrix<f64> {
            let mut s = DMatrix::zeros(self.globals, self.globals);
            for t in 0..self.texels {
                let (jg, jt) = (self.jg(t), self.jt(t));
                let own = SymInverse::new(&(jt.transpose() * &jt));
                let b = jg.transpose() * &jt;
                let y: Vec<Vec<f64>> = (0..self.globals)
                    .map(|i| own.solve(&b.row(i).iter().copied().collect::<Vec<_>>()))
                    .collect();
                s += jg.transpose() * &jg;
                for i in 0..self.globals {
                    for j in 0..self.globals {
                        s[(i, j)] -= (0..self.unknowns).map(|k| b[(i, k)] * y[j][k]).sum::<f64>();
                    }
                }
            }
            s
        }

        /// The diagonal of A.
        fn reference(&self) -> Vec<f64> {
            let g = self.full.columns(0, self.globals);
            (0..self.globals)
                .map(|k| g.column(k).norm_squared())
                .collect()
        }

        /// Texel t's variances by the Schur-complement formula.
        fn texel(&self, t: usize, s: &SymInverse) -> Vec<f64> {
            let (jg, jt) = (self.jg(t), self.jt(t));
            texel_variances(&(jt.transpose() * &jt), Some((&(jg.transpose() * &jt), s)))
        }
    }

    fn close(a: f64, b: f64) -> bool {
        (a - b).abs() <= 1e-9 * b.abs().max(1e-300)
    }

    #[test]
    fn texel_errors_are_the_texel_block_of_the_dense_inverse() {
        let p = Tiny::new(3, 5, 2, 6, 7);
        let dense = (p.full.transpose() * &p.full)
            .try_inverse()
            .expect("a well-posed tiny problem");
        let s = SymInverse::scaled(&p.schur(), &p.reference());
        let mut grew = false;
        for t in 0..p.texels {
            let vars = p.texel(t, &s);
            let (jt, jg) = (p.jt(t), p.jg(t));
            let alone = texel_variances(&(jt.transpose() * &jt), None);
            for k in 0..p.unknowns {
                let i = p.globals + t * p.unknowns + k;
                assert!(
                    close(vars[k], dense[(i, i)]),
                    "texel {t} unknown {k}: {} vs {}",
                    vars[k],
                    dense[(i, i)]
                );
                // the globals' uncertainty only ever adds
                assert!(alone[k] <= vars[k] * (1.0 + 1e-12));
                grew |= vars[k] > 1.01 * alone[k];
            }
            let _ = jg;
        }
        assert!(grew, "the globals' term should matter in this problem");
        // the globals' block of the inverse is S^-1
        for g in 0..p.globals {
            let mut e = vec![0.0; p.globals];
            e[g] = 1.0;
            assert!(close(s.quadratic(&e), dense[(g, g)]));
        }
    }

    #[test]
    fn an_undetermined_texel_value_is_infinite_and_the_others_are_not() {
        // texel 0's second unknown has no effect on any pixel: C_0 is singular
        let mut p = Tiny::new(2, 4, 2, 5, 11);
        let col = p.globals + 1;
        for r in 0..p.rows {
            p.full[(r, col)] = 0.0;
        }
        let m = p.full.transpose() * &p.full;
        let pinv = m.clone().pseudo_inverse(1e-12).unwrap();
        let s = SymInverse::scaled(&p.schur(), &p.reference());
        let v0 = p.texel(0, &s);
        assert!(v0[1].is_infinite(), "{v0:?}");
        assert!(close(v0[0], pinv[(p.globals, p.globals)]), "{v0:?}");
        for t in 1..p.texels {
            let v = p.texel(t, &s);
            for k in 0..p.unknowns {
                let i = p.globals + t * p.unknowns + k;
                assert!(close(v[k], pinv[(i, i)]), "texel {t}: {v:?}");
            }
        }
    }

    #[test]
    fn a_texel_value_traded_off_with_a_global_is_infinite() {
        // global 0 acts only on texel 0's pixels, exactly as its first unknown does: S is
        // singular, and only that unknown (and the global) is undetermined
        let mut p = Tiny::new(2, 4, 2, 5, 3);
        for r in 0..p.texels * p.rows {
            p.full[(r, 0)] = if r < p.rows {
                p.full[(r, p.globals)]
            } else {
                0.0
            };
        }
        let schur = p.schur();
        let s = SymInverse::scaled(&schur, &p.reference());
        assert!(s.quadratic(&[1.0, 0.0]).is_infinite());
        let v0 = p.texel(0, &s);
        assert!(v0[0].is_infinite(), "{v0:?}");
        let pinv = (p.full.transpose() * &p.full)
            .pseudo_inverse(1e-12)
            .unwrap();
        let i = p.globals + 1;
        assert!(close(v0[1], pinv[(i, i)]), "{v0:?} vs {}", pinv[(i, i)]);
        for t in 1..p.texels {
            assert!(p.texel(t, &s).iter().all(|v| v.is_finite()));
        }
    }
}
