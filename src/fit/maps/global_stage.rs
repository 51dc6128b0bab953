//! Stage 1: the global parameters on a sample of texels, alternating with those texels' maps;
//! the globals given the maps and the widening of their errors by the maps' uncertainty.

use super::*;

/// Stage 1: the globals, from alternating fits on a seeded sample of texels.
pub struct GlobalStage {
    /// The global fit given the sample's maps (uncertainties conditional on them).
    pub outcome: FitOutcome,
    /// Cost over the sampled texels: the plain global fit's, then after each round.
    pub costs: Vec<f64>,
    /// Residual variance per pixel value over the sampled texels, every unknown counted: what
    /// the texel stage expects of the whole capture ([`texel_stage`]'s `variance_hint`).
    pub texel_variance: f64,
    pub warnings: Vec<String>,
    /// Levenberg–Marquardt iterations of the stage: the plain global fit's final run plus the
    /// global fit given the maps in every round (also `outcome.iterations`).
    pub iterations: u64,
    /// Wall time of the stage, seconds (also `outcome.elapsed_seconds`).
    pub seconds: f64,
    /// Texels the stage sampled.
    pub texels: usize,
}

/// Stage 1 of map recovery: the global parameters, alternating per-texel fits and the global
/// LM on `[maps] global_texels` seeded texels until their cost stops falling.
pub fn global_stage(
    store: &CaptureStore,
    cfg: &FitConfig,
    req: &MapsConfig,
    quiet: bool,
) -> Result<GlobalStage> {
    let t0 = std::time::Instant::now();
    check_request(cfg, req)?;
    if cfg.metric != crate::fit::config::Metric::Linear {
        bail!("--maps fits captures with the linear metric; set metric = \"linear\"");
    }
    let free = free_of(req);
    // the texels of the global stage, and the plain global fit on their pixels
    let chosen = store.sample_texels(req.global_texels, cfg.seed ^ 0x6d61_7073);
    // texel by texel (the order the stage was measured with: reports/maps_accuracy.md)
    let mut sub = store.samples_of(&[]);
    sub.samples = chosen
        .iter()
        .flat_map(|&t| store.texel_samples(t))
        .collect();
    let sub_layout = Layout::new(&sub)?;
    let first = crate::fit::fit(&sub, cfg, quiet)?;
    let mut set = fix_mapped(&first.set, req);
    let mut values = sub_layout.start_values(&sub, &set);
    let all: Vec<usize> = (0..sub_layout.texels.len()).collect();
    let bar = crate::progress::bar(req.rounds as u64, "maps: globals", quiet);
    let mut costs = vec![first.statistics.chi_square];
    let mut iterations = first.iterations;
    let mut evaluations = first.evaluations;
    let mut warnings = Vec::new();
    let mut converged = false;
    for round in 0..req.rounds {
        // per texel given the globals
        let model = rung_of(&set, cfg);
        let g = Globals::of(&set, model.as_ref(), sub.channels);
        let problems = sub_layout.problems(&sub, &all, &values, free, req.smoothness);
        let fitted: Vec<(TexelValues, f64)> = problems
            .par_iter()
            .zip(values.par_iter())
            .map(|(p, v)| {
                let r = p.fit(&g, v);
                (r.0, r.1)
            })
            .collect();
        values = fitted.iter().map(|x| x.0).collect();
        let after_texels: f64 = fitted.iter().map(|x| x.1).sum();
        // the globals given the maps; kept if the cost falls
        let (_, new_set, its) =
            global_given_maps(&sub, cfg, &set, &values, &sub_layout.members, &all, free)?;
        iterations += its;
        let total_new = if new_set != set {
            total_cost(&sub, cfg, &new_set, &values, &sub_layout.members, free)?
        } else {
            f64::INFINITY
        };
        let before = *costs.last().expect("non-empty");
        let now = if total_new < after_texels {
            set = new_set;
            total_new
        } else {
            after_texels
        };
        costs.push(now);
        bar.inc(1);
        if round > 0 && before - now <= 1e-6 * before {
            converged = true;
            break;
        }
    }
    bar.finish_and_clear();
    if !converged {
        warnings.push(format!(
            "map recovery: the cost of the global stage was still falling after {} rounds ([maps] rounds); the globals may not be final",
            req.rounds
        ));
    }
    let mut outcome = final_global(&sub, cfg, &set, &values, &sub_layout.members, free)?;
    // the globals' errors with the sampled texels' maps free too
    let inflation = map_inflation(&sub, &sub_layout, cfg, &set, &values, free)?;
    if let Some(w) = inflate_records(&mut outcome, &set, &inflation) {
        warnings.push(w);
    }
    // the stage's own work, not the last (fixed-maps) evaluation's
    outcome.iterations = iterations;
    evaluations += outcome.evaluations;
    outcome.evaluations = evaluations;
    let seconds = t0.elapsed().as_secs_f64();
    outcome.elapsed_seconds = seconds;
    let st = &outcome.statistics;
    let unknowns =
        per_texel_unknowns(free, sub.channels) * sub_layout.texels.len() + st.free_parameters;
    let texel_variance = st.chi_square / st.n.saturating_sub(unknowns).max(1) as f64;
    outcome.warnings.push(format!(
        "the global parameters come from {} sampled texels ([maps] global_texels) and their maps; their uncertainties include those texels' maps being free (joint covariance)",
        sub_layout.texels.len()
    ));
    Ok(GlobalStage {
        outcome,
        costs,
        texel_variance,
        warnings,
        iterations,
        seconds,
        texels: sub_layout.texels.len(),
    })
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
    let (mut hs, mut kd, mut ks) = (Vec::new(), Vec::new(), Vec::new());
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
        }
    }
    let mut maps = SampleMaps::default();
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
        cfg.metric,
        cfg.knobs.quadrature_order,
        cfg.knobs.histogram_bins,
        None,
        cfg.optimizer.separable,
    )
    .with_azimuth_nodes(cfg.knobs.azimuth_nodes)
    .with_sample_maps(Arc::new(maps))
}

/// Stage 2: LM from the current globals on the texels `order`, maps fixed: (cost, globals, LM
/// iterations).
pub(super) fn global_given_maps(
    samples: &Samples,
    cfg: &FitConfig,
    set: &ParamSet,
    values: &[TexelValues],
    members: &[Vec<usize>],
    order: &[usize],
    free: Free,
) -> Result<(f64, ParamSet, u64)> {
    let (subset, maps) = mapped_samples(samples, values, members, order, free);
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
