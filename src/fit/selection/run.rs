//! A `--model auto` run: rank every candidate, refine those the decision needs, decide.

use super::*;

/// [`select`], with a progress line per candidate through `progress` (name, elapsed
/// time, an estimate of the time left) and `on_rung` called as each candidate finishes
/// (partial results).
pub fn select_with(
    samples: &Samples,
    cfg: &FitConfig,
    progress: &crate::progress::Progress,
    on_rung: &mut dyn FnMut(&RungDone),
) -> Result<SelectionOutcome> {
    let n = samples.samples.len();
    if n < 10 {
        bail!("--model auto needs at least 10 samples to hold some out; got {n}");
    }
    let plan = plan(n, cfg);
    let mut run = Run {
        anchor_samples: samples.subset(&plan.anchor),
        counts: Counts::of(&plan, n),
        plan,
        samples,
        cfg,
        progress,
        list: candidates_of(cfg)?,
        candidates: Vec::new(),
        anchors: Vec::new(),
        hints: Vec::new(),
    };
    run.rank_all(on_rung);
    if !run.candidates.iter().any(|c| c.error.is_none()) {
        bail!("--model auto: no rung could be fitted");
    }
    run.refine();
    Ok(run.decide())
}

/// A `--model auto` run: the candidates, their measurements so far and their anchor fits.
struct Run<'a> {
    samples: &'a Samples,
    cfg: &'a FitConfig,
    progress: &'a crate::progress::Progress,
    plan: Plan,
    /// The samples every candidate's anchor fit uses.
    anchor_samples: Samples,
    counts: Counts,
    /// (name, rung, fuzz, config) of every candidate, in order.
    list: Vec<(String, ModelId, bool, FitConfig)>,
    candidates: Vec<Candidate>,
    /// Each candidate's optimum on the anchor samples (`None`: it failed).
    anchors: Vec<Option<ParamSet>>,
    /// Every simpler candidate's optimum: starts for the next one.
    hints: Vec<Vec<(Param, f64)>>,
}

impl Run<'_> {
    /// The work each candidate is planned to take (its planned evaluations times the cost of
    /// one), for the estimate of the time left; zeros when no progress is shown.
    fn planned_work(&self) -> Vec<f64> {
        match self.progress.shown() {
            false => vec![0.0; self.list.len()],
            true => self
                .list
                .iter()
                .map(|(_, _, _, rc)| {
                    let rc = ranking_config(rc);
                    rc.planned_evaluations(self.anchor_samples.samples.len())
                        * (1.0 + self.plan.folds.len() as f64 * 0.3)
                        * probe_ns(&self.anchor_samples, &rc)
                })
                .collect(),
        }
    }

    /// Fit and measure every candidate in turn (coarse knobs when the config ranks coarsely),
    /// calling `on_rung` as each finishes.
    fn rank_all(&mut self, on_rung: &mut dyn FnMut(&RungDone)) {
        let names: Vec<String> = self.list.iter().map(|c| c.0.clone()).collect();
        let started = Instant::now();
        // the time left, estimated from the seconds per unit of planned work of the candidates
        // done; a candidate's work: its planned evaluations times the cost of one
        let planned = self.planned_work();
        for k in 0..self.list.len() {
            let elapsed = started.elapsed().as_secs_f64();
            let estimate = match planned[..k].iter().sum::<f64>() {
                done if k > 0 && done > 0.0 => format!(
                    "; estimate: {} left",
                    crate::progress::seconds(elapsed / done * planned[k..].iter().sum::<f64>())
                ),
                _ => String::new(),
            };
            self.progress.line(&format!(
                "auto: rung {}/{} {} (elapsed {}{estimate})",
                k + 1,
                self.list.len(),
                self.list[k].0,
                crate::progress::seconds(elapsed)
            ));
            let fitted = self.rank(k);
            on_rung(&RungDone {
                candidates: &self.candidates,
                outcome: fitted.as_ref(),
                rungs: &names,
                counts: self.counts,
            });
            // said after `on_rung` has it: what the line reports done is done for the caller
            // too (an interrupted run's partial result holds every rung said to be fitted)
            if let Some(c) = self.candidates.last() {
                self.progress.line(&done_line(c, self.cfg.metric));
            }
        }
    }

    /// Fit candidate `k` on the anchor samples (every simpler candidate's optimum a start: a
    /// rung nested in a richer one, poulin-fournier is varying-topology at height 0, then never
    /// ends worse than it) and measure its held-out errors; its anchor fit when it succeeded.
    fn rank(&mut self, k: usize) -> Option<FitOutcome> {
        let (name, id, fuzz, rc) = &self.list[k];
        let cfg = self.cfg;
        // a renderer's own material (closed form, cheap) is measured at the config's knobs and
        // starts: its error is reported beside the choice as what that renderer gets
        let mut coarse = match cfg.selection.coarse_ranking && id.rung().renderer.is_none() {
            true => ranking_config(rc),
            false => rc.clone(),
        };
        // ranked as fitted: a spread the data cannot tell from 0 is held in the chosen rung's
        // final fit (`fit::spread_hold`), a speed-up for its users, not a different candidate
        // (held in the anchor, it would also be held in every fold's refit)
        coarse.keep_free_spread = true;
        let t = Instant::now();
        let quiet = crate::progress::Progress::quiet();
        let result =
            fit_with_hints(&self.anchor_samples, &coarse, &quiet, &self.hints).and_then(|o| {
                let iters = match self.plan.cross_validated {
                    true => cfg.optimizer.max_iterations.min(REFINE_ITERATIONS),
                    false => 0,
                };
                let m = measure(self.samples, &self.plan, &coarse, &o.set, iters, o.channels)?;
                let ns = ns_per_sample(
                    &problem_at(&o, &coarse, &self.anchor_samples),
                    &o.set,
                    &self.anchor_samples,
                );
                Ok((m, ns, o))
            });
        let mut c = Candidate {
            name: name.clone(),
            rung: id.to_string(),
            fuzz: *fuzz,
            free_parameters: 0,
            cv_error: f64::NAN,
            cv_standard_error: f64::NAN,
            fold_errors: vec![],
            fold_standard_errors: vec![],
            heldout_rmse: f64::NAN,
            heldout_relative_rmse: f64::NAN,
            heldout_log_error: f64::NAN,
            ns_per_eval: f64::NAN,
            fit_seconds: 0.0,
            knobs: "coarse".into(),
            chosen: false,
            error: None,
            heldout_errors: vec![],
            heldout_values: vec![],
        };
        let fitted = match result {
            Ok((m, ns, o)) => {
                self.hints
                    .push(o.set.shapes.iter().map(|s| (s.kind, s.value)).collect());
                // measured at the config's knobs: a model the knobs do not change, or no
                // coarse ranking asked for (then nothing is refined)
                let exact = !cfg.selection.coarse_ranking || !knobs_matter(&o.set);
                self.anchors.push(Some(o.set.clone()));
                c.free_parameters = o.statistics.free_parameters;
                c.ns_per_eval = ns;
                c.knobs = if exact { "config" } else { "coarse" }.into();
                set_errors(&mut c, &m);
                c.fit_seconds = t.elapsed().as_secs_f64();
                Some(o)
            }
            Err(e) => {
                self.anchors.push(None);
                c.error = Some(format!("{e:#}"));
                c.fit_seconds = t.elapsed().as_secs_f64();
                None
            }
        };
        self.candidates.push(c);
        fitted
    }

    /// Refine what the decision needs: a coarse error may differ from the config's knobs' by
    /// KNOBS_TOLERANCE either way; the candidates whose refinement could change the choice are
    /// refitted at the config's knobs from their coarse optimum, until the choice is certain.
    fn refine(&mut self) {
        let mut tried = vec![false; self.list.len()];
        loop {
            let wanted = undecided(&self.candidates, self.cfg.selection.tolerance);
            let wanted: Vec<usize> = wanted.into_iter().filter(|&k| !tried[k]).collect();
            if wanted.is_empty() {
                break;
            }
            for k in wanted {
                tried[k] = true;
                self.refine_one(k);
            }
        }
    }

    /// Refit candidate `k` at the config's knobs from its coarse optimum; its coarse errors
    /// stand when that fails.
    fn refine_one(&mut self, k: usize) {
        let Some(set) = self.anchors[k].clone() else {
            return;
        };
        let (name, _, _, rc) = &self.list[k];
        self.progress
            .line(&format!("auto: refining {name} at the config's knobs"));
        let t = Instant::now();
        let refined = refit_and_predict(
            &self.anchor_samples,
            &self.anchor_samples,
            rc,
            &set,
            REFINE_ITERATIONS,
        )
        .and_then(|(s, _, _)| {
            let iters = match self.plan.cross_validated {
                true => REFINE_ITERATIONS,
                false => 0,
            };
            let m = measure(self.samples, &self.plan, rc, &s, iters, s.channels)?;
            Ok((s, m))
        });
        match refined {
            Ok((s, m)) => {
                let c = &mut self.candidates[k];
                set_errors(c, &m);
                c.fit_seconds += t.elapsed().as_secs_f64();
                c.knobs = "config".into();
                self.anchors[k] = Some(s);
                self.progress.line(&format!(
                    "auto: {name} refined in {}: held-out error {:.4} +/- {:.4}",
                    crate::progress::seconds(t.elapsed().as_secs_f64()),
                    c.cv_error,
                    c.cv_standard_error
                ));
            }
            Err(e) => self.progress.line(&format!(
                "auto: {name} could not be refined (its coarse errors stand): {e:#}"
            )),
        }
    }

    /// The rule's words, with the best candidate's figures for the one-standard-error rule.
    fn rule_text(&self) -> String {
        let (cfg, candidates) = (self.cfg, &self.candidates);
        let best_k = candidates
            .iter()
            .enumerate()
            .filter(|(_, c)| c.error.is_none())
            .min_by(|a, b| a.1.cv_error.total_cmp(&b.1.cv_error))
            .map(|(k, _)| k)
            .expect("one candidate was measured");
        match cfg.selection.tolerance {
            Some(t) => format!(
                "the simplest candidate (fewest free parameters, cheapest rung, without the fuzz layer \
                 before with it) whose held-out error ({} metric) is within {:.1} % of the best",
                metric_name(cfg.metric),
                100.0 * t
            ),
            None => format!(
                "one-standard-error rule: the simplest candidate (fewest free parameters, cheapest \
                 rung, without the fuzz layer before with it) whose held-out error ({} metric) is at \
                 most the best's plus its standard error ({}: {:.4} + {:.4})",
                metric_name(cfg.metric),
                candidates[best_k].name,
                candidates[best_k].cv_error,
                candidates[best_k].cv_standard_error
            ),
        }
    }

    /// Choose by the rule and say how the candidates were compared.
    fn decide(mut self) -> SelectionOutcome {
        let cfg = self.cfg;
        let rule = self.rule_text();
        let chosen = rule_choice(&self.candidates, None, cfg.selection.tolerance)
            .expect("the best candidate is within its own noise");
        self.candidates[chosen].chosen = true;
        // the final fit starts (besides its own search) from the chosen candidate's optimum,
        // which began from every simpler candidate's
        let ordered_hints = vec![hints_for(&self.anchors[chosen])];
        let plan = &self.plan;
        let validation = heldout::validation_text(plan, cfg, self.samples.samples.len());
        let (_, id, fuzz, mut chosen_config) = self.list.swap_remove(chosen);
        // the final fit's global stage searches at the knobs the candidates were ranked at (the
        // chosen one's anchor was found there); its basins are polished at the config's knobs
        if cfg.selection.coarse_ranking && id.rung().renderer.is_none() {
            chosen_config.search_knobs = Some(ranking_config(&chosen_config).knobs);
        }
        SelectionOutcome {
            chosen: self.candidates[chosen].name.clone(),
            chosen_rung: id.to_string(),
            chosen_fuzz: fuzz,
            rule,
            validation,
            folds: plan.folds.len(),
            metric: metric_name(cfg.metric).into(),
            counts: self.counts,
            candidates: self.candidates,
            hints: ordered_hints,
            chosen_config: Some(chosen_config),
            splits: heldout::splits_of(plan, self.samples.samples.len()),
        }
    }
}

fn hints_for(a: &Option<ParamSet>) -> Vec<(Param, f64)> {
    a.as_ref()
        .map(|s| s.shapes.iter().map(|s| (s.kind, s.value)).collect())
        .unwrap_or_default()
}

/// The progress line of a finished candidate.
fn done_line(c: &Candidate, metric: Metric) -> String {
    match &c.error {
        None => format!(
            "auto: {} fitted in {}: held-out error {:.4} +/- {:.4} ({} metric{})",
            c.name,
            crate::progress::seconds(c.fit_seconds),
            c.cv_error,
            c.cv_standard_error,
            metric_name(metric),
            if c.knobs == "coarse" {
                ", coarse knobs"
            } else {
                ""
            }
        ),
        Some(e) => format!(
            "auto: {} failed after {}: {e}",
            c.name,
            crate::progress::seconds(c.fit_seconds)
        ),
    }
}
