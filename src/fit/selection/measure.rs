//! How a candidate is measured: the hold-out plan, warm-started fold fits, held-out errors in
//! the fit's metric and plain units, and the cost of one evaluation.

use super::*;

/// The least-squares problem of `samples` at the fitted outcome `o` (its set and topology map)
/// with the knobs of `cfg`: how a fit is evaluated on other samples.
pub fn problem_at<'a>(o: &FitOutcome, cfg: &FitConfig, samples: &'a Samples) -> FitProblem<'a> {
    FitProblem::new(
        samples.samples.iter().collect(),
        o.set.clone(),
        crate::fit::problem::Settings::of(cfg),
        o.map.clone(),
    )
    .with_azimuth_nodes(cfg.knobs.azimuth_nodes)
}

/// The fitted model's values (per sample and channel) on `samples`, and the problem it used.
pub fn model_values_on<'a>(
    o: &FitOutcome,
    cfg: &FitConfig,
    samples: &'a Samples,
) -> Result<(FitProblem<'a>, Vec<[f64; 3]>)> {
    let p = problem_at(o, cfg, samples);
    let cols = p.columns(&o.set)?;
    let values = p.model_values(&cols, &o.set);
    Ok((p, values))
}

/// Unweighted RMSE, relative RMSE and log error of `values` against the samples `test`
/// (`ch` channels).
pub fn plain_errors(
    values: &[[f64; 3]],
    test: &[&crate::load::samples::Sample],
    ch: usize,
) -> (f64, f64, f64) {
    let raw: Vec<[f64; 3]> = test.iter().map(|s| s.value).collect();
    let floors: Vec<f64> = (0..ch)
        .map(|c| crate::fit::problem::log_floor(&raw, c))
        .collect();
    let (mut se, mut sy, mut sl, mut n) = (0.0, 0.0, 0.0, 0.0);
    for (m, s) in values.iter().zip(test) {
        for (c, (mc, yc)) in m[..ch].iter().zip(&s.value[..ch]).enumerate() {
            se += (mc - yc).powi(2);
            sy += yc.powi(2);
            sl += ((mc.max(0.0) + floors[c]).ln() - (yc.max(0.0) + floors[c]).ln()).powi(2);
            n += 1.0;
        }
    }
    ((se / n).sqrt(), (se / sy).sqrt(), (sl / n).sqrt())
}

/// Per held-out sample of `test`, the mean over channels of the squared log error
/// (ln(m + eps) - ln(y + eps))^2 of the fitted outcome `o` (eps: the `log` metric's floor of
/// `test`): the terms of [`heldout`]'s log error, whose RMS and standard error
/// [`rms_and_se`] gives.
pub fn heldout_log_terms(o: &FitOutcome, cfg: &FitConfig, test: &Samples) -> Result<Vec<f64>> {
    let (_, values) = model_values_on(o, cfg, test)?;
    let ch = o.channels;
    let raw: Vec<[f64; 3]> = test.samples.iter().map(|s| s.value).collect();
    let floors: Vec<f64> = (0..ch)
        .map(|c| crate::fit::problem::log_floor(&raw, c))
        .collect();
    Ok(values
        .iter()
        .zip(&test.samples)
        .map(|(m, s)| {
            (0..ch)
                .map(|c| {
                    ((m[c].max(0.0) + floors[c]).ln() - (s.value[c].max(0.0) + floors[c]).ln())
                        .powi(2)
                })
                .sum::<f64>()
                / ch as f64
        })
        .collect())
}

/// Held-out RMSE, relative RMSE and log error of a fitted outcome, and the single-thread cost
/// per sample.
pub fn heldout(o: &FitOutcome, cfg: &FitConfig, test: &Samples) -> Result<(f64, f64, f64, f64)> {
    let (p, values) = model_values_on(o, cfg, test)?;
    let refs: Vec<&crate::load::samples::Sample> = test.samples.iter().collect();
    let (rmse, rel, log) = plain_errors(&values, &refs, o.channels);
    let ns = ns_per_sample(&p, &o.set, test);
    Ok((rmse, rel, log, ns))
}

/// Single-thread cost (ns per sample) of the model of `p` at `set` on up to 500 of `s`.
pub(super) fn ns_per_sample(p: &FitProblem, set: &ParamSet, s: &Samples) -> f64 {
    let model = p.model_for(set);
    let frame = crate::model::frame::FibreFrame::from_azimuth(0.0);
    let k = s.samples.len().min(500);
    let pairs: Vec<crate::model::DirectionPair> = s.samples[..k]
        .iter()
        .map(|x| crate::model::DirectionPair::new(&frame, &x.l, &x.v))
        .collect();
    let mut bases = vec![crate::model::Basis::default(); k];
    let t = Instant::now();
    model.basis_many(&pairs, &mut bases);
    std::hint::black_box(&bases);
    (t.elapsed().as_nanos() as f64 / k.max(1) as f64).max(1.0)
}

/// Single-thread cost (ns per sample) of `rc`'s model at its start values on up to 200 samples
/// of `s`, at least 1 (1000 when the rung cannot be set up for these data).
pub(super) fn probe_ns(s: &Samples, rc: &FitConfig) -> f64 {
    let Ok(st) = crate::fit::setup::setup(s, rc) else {
        return 1000.0;
    };
    let model = crate::fit::problem::model_for(
        &st.template,
        rc.knobs.quadrature_order,
        rc.knobs.histogram_bins,
        rc.knobs.azimuth_nodes,
        st.map.clone(),
    );
    let frame = crate::model::frame::FibreFrame::from_azimuth(0.0);
    let k = s.samples.len().min(200);
    let pairs: Vec<crate::model::DirectionPair> = s.samples[..k]
        .iter()
        .map(|x| crate::model::DirectionPair::new(&frame, &x.l, &x.v))
        .collect();
    let mut bases = vec![crate::model::Basis::default(); k];
    let t = Instant::now();
    model.basis_many(&pairs, &mut bases);
    std::hint::black_box(&bases);
    (t.elapsed().as_nanos() as f64 / k.max(1) as f64).max(1.0)
}

/// The knobs candidates are ranked with: at most 8 quadrature nodes, 4 histogram bins, 8
/// azimuth nodes, 3 starts, 40 iterations and a global subsample of 400. Cheap rungs (lambert,
/// hast-diffuse, ward, max-normal without spread) do not use them and are measured exactly.
pub fn ranking_config(rc: &FitConfig) -> FitConfig {
    let mut c = rc.clone();
    c.knobs.quadrature_order = rc.knobs.quadrature_order.min(8);
    c.knobs.histogram_bins = rc.knobs.histogram_bins.min(4);
    c.knobs.azimuth_nodes = rc.knobs.azimuth_nodes.min(8);
    c.starts = rc.starts.min(3);
    c.optimizer.max_iterations = rc.optimizer.max_iterations.min(40);
    c.optimizer.global_subsample = rc.optimizer.global_subsample.min(400);
    c
}

/// Do the knobs change this fitted model (quadrature, histogram or spread nodes in use)?
pub(super) fn knobs_matter(set: &ParamSet) -> bool {
    let spread = set
        .shapes
        .iter()
        .any(|s| s.kind == Param::AzimuthSpread && (s.vary || s.value > 0.0));
    spread || set.rung.is_cross_section()
}

/// A fit of `train` warm-started at `start` (LM only, at most `iterations`; none: the albedos
/// re-solved at `start`'s shapes), judged on `test`: the set, the per-sample mean squared
/// residuals on `test` in the fit's metric (the training data's log floor) and the model values.
pub(super) fn refit_and_predict(
    train: &Samples,
    test: &Samples,
    rc: &FitConfig,
    start: &ParamSet,
    iterations: u64,
) -> Result<(ParamSet, Vec<f64>, Vec<[f64; 3]>)> {
    let st = crate::fit::setup::setup(train, rc)?;
    fn make<'s>(
        s: &'s Samples,
        template: &ParamSet,
        rc: &FitConfig,
        st: &crate::fit::setup::Setup,
    ) -> FitProblem<'s> {
        FitProblem::new(
            s.samples.iter().collect(),
            template.clone(),
            crate::fit::problem::Settings::of(rc),
            st.map.clone(),
        )
        .with_azimuth_nodes(rc.knobs.azimuth_nodes)
    }
    let train_p = make(train, &st.template, rc, &st);
    let mut begin = st.template.clone();
    for s in begin.shapes.iter_mut() {
        if let Some(x) = start.shapes.iter().find(|x| x.kind == s.kind) {
            s.value = x.value.clamp(s.min, s.max);
        }
    }
    for a in begin.albedos.iter_mut() {
        if let Some(b) = start.albedos.iter().find(|b| b.component == a.component) {
            for c in 0..3 {
                a.value[c] = b.value[c].clamp(a.min, a.max);
            }
        }
    }
    let theta0 = train_p.theta_of(&begin);
    let theta = match iterations > 0 && train_p.dim() > 0 {
        true => {
            let tol = rc.optimizer.tolerance.max(1e-6);
            let bar = indicatif::ProgressBar::hidden();
            crate::fit::polish::run_lm(&train_p, &st.template, theta0, iterations, tol, &bar)?.0
        }
        false => theta0,
    };
    let (_, set) = train_p.evaluate(&theta, &st.template)?;
    let test_p = make(test, &set, rc, &st).with_log_floor_of(&train_p);
    let cols = test_p.columns(&set)?;
    let r = test_p.residuals(&cols, &set);
    let ch = test_p.channels();
    let errors: Vec<f64> = (0..test.samples.len())
        .map(|i| (0..ch).map(|c| r[i * ch + c].powi(2)).sum::<f64>() / ch as f64)
        .collect();
    if errors.iter().any(|e| !e.is_finite()) {
        bail!("a held-out residual is not finite");
    }
    let values = test_p.model_values(&cols, &set);
    Ok((set, errors, values))
}

/// How the samples are held out: `folds` lists of held-out indices (disjoint; all of them for
/// cross-validation, one list for a single split).
pub(super) struct Plan {
    pub(super) folds: Vec<Vec<usize>>,
    pub(super) cross_validated: bool,
    /// The indices the candidates' anchor fits use (all samples for cross-validation, at most
    /// `rank_samples` of the training split otherwise).
    pub(super) anchor: Vec<usize>,
    /// A single split's training indices (empty for cross-validation).
    pub(super) train: Vec<usize>,
}

pub(super) fn plan(n: usize, cfg: &FitConfig) -> Plan {
    plan_of(n, &cfg.selection, cfg.seed)
}

/// [`plan`] from the selection settings `sel` and the seed.
pub(super) fn plan_of(n: usize, sel: &crate::fit::config::Selection, seed: u64) -> Plan {
    let mut idx: Vec<usize> = (0..n).collect();
    idx.shuffle(&mut rand::rngs::StdRng::seed_from_u64(seed ^ 0x5e1ec7));
    if n < sel.cv_below {
        let k = sel.folds.min(n);
        let folds = (0..k)
            .map(|j| idx.iter().skip(j).step_by(k).copied().collect())
            .collect();
        Plan {
            folds,
            cross_validated: true,
            anchor: (0..n).collect(),
            train: vec![],
        }
    } else {
        let n_test = ((n as f64 * sel.holdout).ceil() as usize).clamp(1, n - 1);
        let (test, train) = idx.split_at(n_test);
        Plan {
            folds: vec![test.to_vec()],
            cross_validated: false,
            anchor: train[..train.len().min(sel.rank_samples)].to_vec(),
            train: train.to_vec(),
        }
    }
}

/// Held-out errors of one candidate at one configuration.
pub(super) struct Measured {
    /// Per-sample mean squared residual (metric), in the order of the plan's folds.
    pub(super) errors: Vec<f64>,
    pub(super) fold_errors: Vec<f64>,
    pub(super) fold_standard_errors: Vec<f64>,
    pub(super) rmse: f64,
    pub(super) rel: f64,
    pub(super) log: f64,
    /// The model's values on the held-out samples, in the order of `errors`.
    pub(super) values: Vec<[f64; 3]>,
}

pub(super) fn complement(n: usize, fold: &[usize]) -> Vec<usize> {
    let mut out = vec![true; n];
    for &i in fold {
        out[i] = false;
    }
    (0..n).filter(|&i| out[i]).collect()
}

/// Measure a candidate whose anchor fit (on the plan's anchor samples) is `anchor`: every
/// fold's fit warm-started there (`iterations` LM steps at most), judged on the fold.
pub(super) fn measure(
    samples: &Samples,
    plan: &Plan,
    rc: &FitConfig,
    anchor: &ParamSet,
    iterations: u64,
    channels: usize,
) -> Result<Measured> {
    let n = samples.samples.len();
    let per_fold: Vec<Result<(Vec<f64>, Vec<[f64; 3]>)>> = plan
        .folds
        .par_iter()
        .map(|fold| {
            let train_idx = match plan.cross_validated {
                true => complement(n, fold),
                false => plan.anchor.clone(),
            };
            let train = samples.subset(&train_idx);
            let test = samples.subset(fold);
            let (_, e, v) = refit_and_predict(&train, &test, rc, anchor, iterations)?;
            Ok((e, v))
        })
        .collect();
    let mut errors = Vec::new();
    let mut values = Vec::new();
    let mut fold_errors = Vec::new();
    let mut fold_standard_errors = Vec::new();
    let mut tested = Vec::new();
    for (fold, r) in plan.folds.iter().zip(per_fold) {
        let (e, v) = r?;
        let (rms, se) = rms_and_se(&e);
        fold_errors.push(rms);
        fold_standard_errors.push(se);
        errors.extend(e);
        values.extend(v);
        tested.extend(fold.iter().map(|&i| &samples.samples[i]));
    }
    let (rmse, rel, log) = plain_errors(&values, &tested, channels);
    Ok(Measured {
        errors,
        fold_errors,
        fold_standard_errors,
        rmse,
        rel,
        log,
        values,
    })
}

/// A candidate's errors from its measurement.
pub(super) fn set_errors(c: &mut Candidate, m: &Measured) {
    let (rms, se) = rms_and_se(&m.errors);
    c.cv_error = rms;
    c.cv_standard_error = se;
    c.fold_errors = m.fold_errors.clone();
    c.fold_standard_errors = m.fold_standard_errors.clone();
    c.heldout_rmse = m.rmse;
    c.heldout_relative_rmse = m.rel;
    c.heldout_log_error = m.log;
    c.heldout_errors = m.errors.clone();
    c.heldout_values = m.values.clone();
}
