//! Stage 1: the global parameters on a sample of texels, alternating with those texels' maps;
//! the globals given the maps and the widening of their errors by the maps' uncertainty.

use super::*;
use nalgebra::{Cholesky, Dyn};

/// Stage 1: the globals, from alternating fits on a seeded sample of texels.
pub struct GlobalStage {
    /// The global fit given the sample's maps (uncertainties conditional on them).
    pub outcome: FitOutcome,
    /// Cost over the sampled texels: the plain global fit's, then after each round.
    pub costs: Vec<f64>,
    /// Residual variance per pixel value over the sampled texels, every unknown counted: what
    /// the texel stage expects of the whole capture ([`TexelStageRequest::variance_hint`]).
    pub texel_variance: f64,
    pub warnings: Vec<String>,
    /// Levenberg–Marquardt iterations of the stage: the plain global fit's final run plus the
    /// global fit given the maps in every round (also `outcome.iterations`).
    pub iterations: u64,
    /// Wall time of the stage, seconds (also `outcome.elapsed_seconds`).
    pub seconds: f64,
    /// Texels the stage sampled.
    pub texels: usize,
    /// The globals' Schur complement over the sampled texels: the texel stage's errors include
    /// the globals' uncertainty through it.
    pub schur: GlobalSchur,
}

/// Stage 1 of map recovery: the global parameters, alternating per-texel fits and the global
/// LM on `[maps] global_texels` seeded texels until their cost stops falling.
pub fn global_stage(
    store: &CaptureStore,
    cfg: &FitConfig,
    req: &MapsConfig,
    progress: &crate::progress::Progress,
) -> Result<GlobalStage> {
    let t0 = std::time::Instant::now();
    check_request(cfg, req)?;
    if cfg.metric != crate::fit::config::Metric::Linear {
        bail!("--maps fits captures with the linear metric; set metric = \"linear\"");
    }
    let free = free_of(req);
    // the texels of the global stage, and the plain global fit on their pixels
    let sampled = Sampled::of(store, cfg, req, free)?;
    let first = crate::fit::fit(&sampled.sub, cfg, progress)?;
    let run = sampled.alternate(&first, req, progress)?;
    let mut warnings = Vec::new();
    if !run.converged {
        warnings.push(format!(
            "map recovery: the cost of the global stage was still falling after {} rounds ([maps] rounds); the globals may not be final",
            req.rounds
        ));
    }
    let (sub, layout, set, values) = (&sampled.sub, &sampled.layout, &run.set, &run.values);
    let mut outcome = final_global(sub, cfg, set, values, &layout.members, free)?;
    // the globals' errors with the sampled texels' maps free too
    let (schur, inflation) = global_schur(sub, layout, cfg, set, values, free)?;
    if let Some(w) = inflate_records(&mut outcome, set, &inflation) {
        warnings.push(w);
    }
    // wider errors may leave more of the globals undetermined
    crate::fit::determined::apply(&mut outcome);
    // the stage's own work, not the last (fixed-maps) evaluation's
    outcome.iterations = run.iterations;
    let mut evaluations = first.evaluations;
    evaluations += outcome.evaluations;
    outcome.evaluations = evaluations;
    let seconds = t0.elapsed().as_secs_f64();
    outcome.elapsed_seconds = seconds;
    let st = &outcome.statistics;
    let unknowns =
        per_texel_unknowns(free, sub.channels) * layout.texels.len() + st.free_parameters;
    let texel_variance = st.chi_square / st.n.saturating_sub(unknowns).max(1) as f64;
    outcome.warnings.push(format!(
        "the global parameters come from {} sampled texels ([maps] global_texels) and their maps; their uncertainties include those texels' maps being free (joint covariance)",
        layout.texels.len()
    ));
    Ok(GlobalStage {
        outcome,
        costs: run.costs,
        texel_variance,
        warnings,
        iterations: run.iterations,
        seconds,
        texels: layout.texels.len(),
        schur,
    })
}

/// The texels the global stage samples: their pixels, grouped by texel, and how they are fitted.
struct Sampled<'a> {
    /// The pixels of the sampled texels, texel by texel.
    sub: Samples,
    layout: Layout,
    /// Every sampled texel (their indices in `layout`).
    all: Vec<usize>,
    cfg: &'a FitConfig,
    free: Free,
    /// The capture's direction lattice (pinhole cameras, point lights), whose grid-only
    /// tables serve the texels' grids at every round.
    lattice: Option<DirectionLattice>,
}

/// Where the alternation of the global stage ended.
struct Alternated {
    set: ParamSet,
    values: Vec<TexelValues>,
    /// The plain global fit's cost, then the cost after each round.
    costs: Vec<f64>,
    /// Levenberg–Marquardt iterations: the plain global fit's and every round's.
    iterations: u64,
    /// Whether the cost stopped falling within `[maps] rounds`.
    converged: bool,
}

impl<'a> Sampled<'a> {
    /// The `[maps] global_texels` texels of `store` seeded from `cfg`, with their pixels.
    fn of(store: &CaptureStore, cfg: &'a FitConfig, req: &MapsConfig, free: Free) -> Result<Self> {
        let chosen = store.sample_texels(req.global_texels, cfg.seed ^ 0x6d61_7073);
        // texel by texel (the order the stage was measured with: reports/maps_accuracy.md)
        let mut sub = store.samples_of(&[]);
        sub.samples = chosen
            .iter()
            .flat_map(|&t| store.texel_samples(t))
            .collect();
        let layout = Layout::new(&sub)?;
        let all: Vec<usize> = (0..layout.texels.len()).collect();
        Ok(Self {
            sub,
            layout,
            all,
            cfg,
            free,
            lattice: DirectionLattice::of_store(store, free),
        })
    }

    /// Rounds from the plain global fit `first` (its mapped parameters fixed, the texels at
    /// their starts) until the cost stops falling or `[maps] rounds` are spent.
    fn alternate(
        &self,
        first: &FitOutcome,
        req: &MapsConfig,
        progress: &crate::progress::Progress,
    ) -> Result<Alternated> {
        let set = fix_mapped(&first.set, req);
        let values = self.layout.start_values(&self.sub, &set);
        let mut run = Alternated {
            set,
            values,
            costs: vec![first.statistics.chi_square],
            iterations: first.iterations,
            converged: false,
        };
        let bar = progress.bar(req.rounds as u64, "maps: globals");
        for round in 0..req.rounds {
            let before = *run.costs.last().expect("non-empty");
            let now = self.round(&mut run, req.smoothness)?;
            run.costs.push(now);
            bar.inc(1);
            if round > 0 && before - now <= 1e-6 * before {
                run.converged = true;
                break;
            }
        }
        bar.finish_and_clear();
        Ok(run)
    }

    /// One round: (a) every texel given the globals, (b) the globals given the maps, kept if
    /// the cost falls, then (without the smoothness prior, which couples the texels) both
    /// together along the valleys where they trade off ([`Sampled::joint_refine`]). Returns
    /// the cost after the round.
    fn round(&self, run: &mut Alternated, smoothness: f64) -> Result<f64> {
        let after_texels = self.texels_given(&run.set, &mut run.values, smoothness);
        // the globals given the maps; kept if the cost falls
        let (_, new_set, its) = self.global_given_maps(&run.set, &run.values)?;
        run.iterations += its;
        let (sub, members) = (&self.sub, &self.layout.members);
        let total_new = if new_set != run.set {
            total_cost(sub, self.cfg, &new_set, &run.values, members, self.free)?
        } else {
            f64::INFINITY
        };
        let mut now = if total_new < after_texels {
            run.set = new_set;
            total_new
        } else {
            after_texels
        };
        // then globals and maps together, along the valleys where they trade off (without the
        // smoothness prior, which couples the texels)
        if smoothness == 0.0 {
            let (s2, v2, c2, taken) = self.joint_refine(&run.set, &run.values, now);
            if taken > 0 {
                (run.set, run.values, now) = (s2, v2, c2);
                run.iterations += taken;
            }
        }
        Ok(now)
    }

    /// (a) of a round: every texel fitted given the globals `set` from its `values`, which it
    /// replaces; returns their summed cost.
    fn texels_given(&self, set: &ParamSet, values: &mut Vec<TexelValues>, smoothness: f64) -> f64 {
        let model = rung_of(set, self.cfg);
        let problems = self
            .layout
            .problems(&self.sub, &self.all, values, self.free, smoothness);
        // tables decided before the texels are fitted, in their order (not the threads'); the
        // texels a lattice serves read none
        let g = Globals::of(set, model.as_ref(), self.sub.channels)
            .with_grid_lattice(self.lattice.as_ref());
        let mut plan = TablePlan::default();
        for (p, v) in problems.iter().zip(values.iter()) {
            if !g.lattice_serves(p) {
                plan.meet(p.grid_key(v));
            }
        }
        let g = g.with_tables(plan);
        let fitted: Vec<(TexelValues, f64)> = problems
            .par_iter()
            .zip(values.par_iter())
            .map(|(p, v)| {
                let r = p.fit(&g, v);
                (r.0, r.1)
            })
            .collect();
        *values = fitted.iter().map(|x| x.0).collect();
        fitted.iter().map(|x| x.1).sum()
    }

    /// (b) of a round: LM from the globals `set` on every sampled texel, maps fixed at
    /// `values`: (cost, globals, LM iterations).
    fn global_given_maps(
        &self,
        set: &ParamSet,
        values: &[TexelValues],
    ) -> Result<(f64, ParamSet, u64)> {
        let (cfg, members) = (self.cfg, &self.layout.members);
        let (subset, maps) = mapped_samples(&self.sub, values, members, &self.all, self.free);
        let p = problem_on(cfg, set, &subset, maps);
        if p.dim() == 0 {
            return Ok((f64::NAN, set.clone(), 0));
        }
        let bar = indicatif::ProgressBar::hidden();
        let (theta, cost, iterations) = polish::run_lm(
            &p,
            set,
            p.theta_of(set),
            cfg.optimizer.max_iterations,
            cfg.optimizer.tolerance,
            &bar,
        )?;
        let mut new = p.set_at(&theta, set);
        if p.separable {
            let cols = p.columns(&new)?;
            p.solve_albedos(&cols, &mut new);
        }
        Ok((cost, new, iterations))
    }
}

/// [`mapped_samples`] of every texel.
pub(super) fn mapped_all(
    samples: &Samples,
    values: &[TexelValues],
    members: &[Vec<usize>],
    free: Free,
) -> (Vec<Sample>, SampleMaps) {
    let all: Vec<usize> = (0..members.len()).collect();
    mapped_samples(samples, values, members, &all, free)
}

/// Copies of the samples of `texel_ids` with each texel's azimuth (when mapped), and the
/// per-sample map values for a [`FitProblem`].
pub(super) fn mapped_samples(
    samples: &Samples,
    values: &[TexelValues],
    members: &[Vec<usize>],
    texel_ids: &[usize],
    free: Free,
) -> (Vec<Sample>, SampleMaps) {
    let mut out = Vec::new();
    let (mut hs, mut kd, mut ks, mut lobes) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    for &t in texel_ids {
        for &i in &members[t] {
            let mut s = samples.samples[i].clone();
            if free.psi {
                s.fibre_azimuth = Some(values[t].psi.to_radians());
            }
            out.push(s);
            hs.push(values[t].height);
            kd.push(values[t].kd);
            ks.push(values[t].ks);
            lobes.push(crate::model::Lobe {
                roughness: values[t].roughness,
                anisotropy: values[t].anisotropy,
            });
        }
    }
    let mut maps = SampleMaps::default();
    if free.lobe() {
        maps.lobe = Some(lobes);
    }
    if free.height {
        maps.height = Some(hs);
    }
    if free.kd {
        maps.albedo[0] = Some(kd);
    }
    if free.ks {
        maps.albedo[1] = Some(ks);
    }
    (out, maps)
}

pub(super) fn problem_on<'a>(
    cfg: &FitConfig,
    set: &ParamSet,
    subset: &'a [Sample],
    maps: SampleMaps,
) -> FitProblem<'a> {
    FitProblem::new(
        subset.iter().collect(),
        set.clone(),
        problem::Settings::of(cfg),
        None,
    )
    .with_azimuth_nodes(cfg.knobs.azimuth_nodes)
    .with_sample_maps(Arc::new(maps))
}

/// Sum of squared weighted residuals over every pixel at `set` and the maps.
pub(super) fn total_cost(
    samples: &Samples,
    cfg: &FitConfig,
    set: &ParamSet,
    values: &[TexelValues],
    members: &[Vec<usize>],
    free: Free,
) -> Result<f64> {
    let (subset, maps) = mapped_all(samples, values, members, free);
    let p = problem_on(cfg, set, &subset, maps);
    let cols = p.columns(set)?;
    Ok(p.residuals(&cols, set).norm_squared())
}

/// The global outcome at `set` given the maps of the texels `members` (held fixed); refused when
/// their pixels cannot determine every texel's unknowns and the globals.
pub(super) fn final_global(
    samples: &Samples,
    cfg: &FitConfig,
    set: &ParamSet,
    values: &[TexelValues],
    members: &[Vec<usize>],
    free: Free,
) -> Result<FitOutcome> {
    let (subset, maps) = mapped_all(samples, values, members, free);
    let p = problem_on(cfg, set, &subset, maps);
    let view = Samples {
        samples: subset.clone(),
        channels: samples.channels,
        kind: samples.kind,
        source: samples.source.clone(),
        dropped: samples.dropped.clone(),
        skipped_examples: samples.skipped_examples.clone(),
        image_size: samples.image_size,
        scale_rel_se: samples.scale_rel_se,
    };
    let cost = {
        let cols = p.columns(set)?;
        p.residuals(&cols, set).norm_squared()
    };
    let mut outcome =
        crate::fit::finish::finish(&p, &view, set.channels, &[(set.clone(), cost)], vec![])?;
    let per_texel = usize::from(free.height)
        + usize::from(free.psi)
        + set.channels * (usize::from(free.kd) + usize::from(free.ks));
    let n = p.residual_count();
    let params = per_texel * members.len() + p.dim();
    if n <= params {
        bail!(
            "--maps: {n} pixel values cannot determine {params} unknowns ({per_texel} per texel and {} globals); use more images",
            p.dim()
        );
    }
    // the outcome's fitted values follow the subset order; put them back in sample order
    let mut fitted = vec![[0.0; 3]; samples.samples.len()];
    let mut k = 0;
    for m in members {
        for &i in m {
            fitted[i] = outcome.fitted[k];
            k += 1;
        }
    }
    outcome.fitted = fitted;
    Ok(outcome)
}

/// Joint Gauss–Newton iterations of the global stage per round at most.
pub const JOINT_ITERATIONS: usize = 20;

/// Per texel, the sum of squared weighted residuals of its pixels at the globals `g` and each
/// of `candidates` (values per texel).
fn texel_costs(problems: &[Texel], g: &Globals, candidates: &[&[TexelValues]]) -> Vec<Vec<f64>> {
    problems
        .par_iter()
        .enumerate()
        .map(|(t, p)| {
            candidates
                .iter()
                .map(|vs| {
                    let v = &vs[t];
                    let cols = p.columns(g, v);
                    p.residuals(g, &cols, v).iter().map(|x| x * x).sum()
                })
                .collect()
        })
        .collect()
}

/// `set` with its free globals moved by `delta` (columns as [`GlobalSteps`]: shapes in the
/// optimizer's internal units, then albedo channels), kept within their bounds.
fn moved_globals(set: &ParamSet, delta: &[f64]) -> ParamSet {
    let mut s = set.clone();
    let d = set.shape_value(Param::Spacing);
    let shapes = set.free_shapes();
    for (j, &i) in shapes.iter().enumerate() {
        let sh = &mut s.shapes[i];
        let v = sh
            .kind
            .to_external(sh.kind.to_internal(sh.value) + delta[j]);
        sh.value = match problem::coordinate(sh) {
            problem::Coordinate::Periodic => wrap_azimuth(v),
            problem::Coordinate::UnderMaxHeight => v.clamp(sh.min, problem::height_range(sh, d).1),
            _ => v.clamp(sh.min, sh.max),
        };
    }
    for (k, (a, c)) in set.free_albedos().into_iter().enumerate() {
        let al = &mut s.albedos[a];
        al.value[c] = (al.value[c] + delta[shapes.len() + k]).clamp(al.min, al.max);
    }
    s
}

/// A texel's values moved by `delta` (its unknowns in [`Texel::jacobian`]'s order), within
/// their bounds (H in [0, `h_max`], psi wrapped, albedos and anisotropy strength in [0, 1],
/// roughness in `roughness`).
fn moved_texel(
    v: &TexelValues,
    which: &[(u8, usize)],
    delta: &[f64],
    (h_max, roughness): (f64, [f64; 2]),
) -> TexelValues {
    let mut w = *v;
    for (&(kind, c), d) in which.iter().zip(delta) {
        match kind {
            0 => w.height = (w.height + d).clamp(0.0, h_max),
            1 => w.psi = wrap_azimuth(w.psi + d),
            2 => w.kd[c] = (w.kd[c] + d).clamp(0.0, 1.0),
            3 => w.ks[c] = (w.ks[c] + d).clamp(0.0, 1.0),
            4 => w.roughness = (w.roughness + d).clamp(roughness[0], roughness[1]),
            _ => w.anisotropy = (w.anisotropy + d).clamp(0.0, 1.0),
        }
    }
    w
}

/// One texel's part of the joint normal equations: C_t, B_t (globals x unknowns), J_t^T r_t,
/// what its unknowns are, and its part of A and J_g^T r.
struct JointTerms {
    c: DMatrix<f64>,
    b: DMatrix<f64>,
    gt: DVector<f64>,
    which: Vec<(u8, usize)>,
    a: DMatrix<f64>,
    gg: DVector<f64>,
}

/// `m` with `lambda` times its diagonal added (Levenberg–Marquardt damping).
fn damped(m: &DMatrix<f64>, lambda: f64) -> DMatrix<f64> {
    let mut d = m.clone();
    let top = (0..m.nrows()).map(|k| m[(k, k)]).fold(0.0f64, f64::max);
    for k in 0..m.nrows() {
        d[(k, k)] += lambda * m[(k, k)].max(1e-12 * top).max(1e-300);
    }
    d
}

/// A damped step of the joint iterations: the globals' step `dg` from their Schur complement,
/// and the texels' damped blocks factored, for their own steps.
struct JointStep {
    dg: DVector<f64>,
    factored: Vec<Cholesky<f64, Dyn>>,
}

/// The joint normal equations at the globals and the sampled texels' values: every texel's
/// terms, and the globals' A and J_g^T r summed over them.
struct JointSystem {
    terms: Vec<JointTerms>,
    a: DMatrix<f64>,
    gg: DVector<f64>,
}

impl JointSystem {
    /// The system of `problems` at their `values` and the globals `g` (`side`: the globals'
    /// columns, `ng` of them).
    fn at(
        problems: &[Texel],
        values: &[TexelValues],
        g: &Globals,
        side: &GlobalSide,
        ng: usize,
    ) -> Self {
        let terms: Vec<JointTerms> = problems
            .par_iter()
            .zip(values.par_iter())
            .map(|(p, v)| {
                let jg = p.global_jacobian(g, side, v);
                let n = jg.nrows();
                let cols = p.columns(g, v);
                let r = DVector::from_vec(p.residuals(g, &cols, v)[..n].to_vec());
                let (jcols, which) = p.jacobian(g, v);
                let jt = DMatrix::from_fn(n, jcols.len(), |i, k| jcols[k][i]);
                JointTerms {
                    c: jt.transpose() * &jt,
                    b: jg.transpose() * &jt,
                    gt: jt.transpose() * &r,
                    which,
                    a: jg.transpose() * &jg,
                    gg: jg.transpose() * &r,
                }
            })
            .collect();
        let mut a = DMatrix::zeros(ng, ng);
        let mut gg = DVector::zeros(ng);
        for t in &terms {
            a += &t.a;
            gg += &t.gg;
        }
        Self { terms, a, gg }
    }

    /// The step damped by `lambda`; none where a damped matrix is not positive definite.
    fn solve(&self, lambda: f64) -> Option<JointStep> {
        // the texels' blocks, damped and factored, then the globals' step
        let factored: Vec<_> = self
            .terms
            .iter()
            .map(|t| damped(&t.c, lambda).cholesky())
            .collect::<Option<_>>()?;
        let mut s = damped(&self.a, lambda);
        let mut rhs = -&self.gg;
        for (t, f) in self.terms.iter().zip(&factored) {
            let cib = f.solve(&t.b.transpose());
            s -= &t.b * &cib;
            rhs += &t.b * f.solve(&t.gt);
        }
        let dg = (0.5 * (&s + s.transpose()))
            .cholesky()
            .map(|f| f.solve(&rhs))?;
        Some(JointStep { dg, factored })
    }

    /// Each texel's `values` moved by its own part of `step`, within its bounds (H_max and the
    /// roughness's: `bounds`).
    fn moved_values(
        &self,
        values: &[TexelValues],
        step: &JointStep,
        bounds: (f64, [f64; 2]),
    ) -> Vec<TexelValues> {
        let dg = &step.dg;
        self.terms
            .iter()
            .zip(&step.factored)
            .zip(values)
            .map(|((t, f), v)| {
                let dx = -f.solve(&(&t.gt + t.b.transpose() * dg));
                moved_texel(v, &t.which, dx.as_slice(), bounds)
            })
            .collect()
    }
}

impl Sampled<'_> {
    /// Damped Gauss–Newton (Levenberg–Marquardt) iterations over the globals and every sampled
    /// texel's unknowns at once, from (`set`, `values`) at `cost`: the block-arrow normal
    /// equations solved through the globals' Schur complement, as bundle adjustment does (the
    /// globals' step from S dg = -J_g^T r + sum_t B_t C_t^-1 J_t^T r_t, then each texel's from
    /// its own block). Alternating fits crawl along the valleys where the globals and the maps
    /// trade off (light and view near the normal: kd, ks, the exponent and the heights); these
    /// steps go along them. The result is never worse than the start: (globals, maps, cost,
    /// iterations taken).
    fn joint_refine(
        &self,
        set: &ParamSet,
        values: &[TexelValues],
        cost: f64,
    ) -> (ParamSet, Vec<TexelValues>, f64, u64) {
        let ch = self.sub.channels;
        let (mut set, mut values, mut cost) = (set.clone(), values.to_vec(), cost);
        let mut lambda = 1e-3;
        let mut taken = 0;
        for _ in 0..JOINT_ITERATIONS {
            let model = rung_of(&set, self.cfg);
            let g = Globals::of(&set, model.as_ref(), ch);
            let steps = GlobalSteps::new(&set, self.cfg);
            let side = GlobalSide::new(&steps, ch, None);
            let ng = steps.len();
            let problems = self
                .layout
                .problems(&self.sub, &self.all, &values, self.free, 0.0);
            let system = JointSystem::at(&problems, &values, &g, &side, ng);
            let mut improved = None;
            for _ in 0..10 {
                let Some(step) = system.solve(lambda) else {
                    lambda *= 10.0;
                    continue;
                };
                let new_set = moved_globals(&set, step.dg.as_slice());
                let h_max = max_height(new_set.shape_value(Param::Spacing));
                let bounds = (h_max, roughness_range(&new_set));
                let new_values = system.moved_values(&values, &step, bounds);
                let (new_values, new_cost) =
                    self.better_of(&problems, &new_set, new_values, &values);
                if new_cost < cost {
                    improved = Some((new_set, new_values, new_cost));
                    lambda = (lambda * 0.3).max(1e-9);
                    break;
                }
                lambda *= 10.0;
            }
            let Some((s2, v2, c2)) = improved else {
                break;
            };
            let gain = (cost - c2) / cost.max(1e-300);
            (set, values, cost) = (s2, v2, c2);
            taken += 1;
            if gain < 1e-9 {
                break;
            }
        }
        (set, values, cost, taken)
    }

    /// Per texel, its `stepped` values or its `old` ones, whichever fits better at the new
    /// globals `new_set`, and the summed cost. The cost is a sum over texels given the globals,
    /// so a texel whose cost is kinked in H, where occlusion changes, cannot spoil the step of
    /// all the others.
    fn better_of(
        &self,
        problems: &[Texel],
        new_set: &ParamSet,
        stepped: Vec<TexelValues>,
        old: &[TexelValues],
    ) -> (Vec<TexelValues>, f64) {
        let new_model = rung_of(new_set, self.cfg);
        let new_g = Globals::of(new_set, new_model.as_ref(), self.sub.channels);
        let each = texel_costs(problems, &new_g, &[&stepped, old]);
        let mut new_cost = 0.0;
        let kept: Vec<TexelValues> = each
            .iter()
            .enumerate()
            .map(|(t, c)| {
                new_cost += c[0].min(c[1]);
                if c[0] <= c[1] {
                    stepped[t]
                } else {
                    old[t]
                }
            })
            .collect();
        (kept, new_cost)
    }
}
