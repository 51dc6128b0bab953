//! What the maps give back: the whole recovery in one call, the model at every sample given
//! the maps, and the `method` block of a result.

use super::*;

/// Recover the maps `req` asks for, with the globals of `cfg`: [`global_stage`], then
/// [`texel_stage`] over every row and [`finish_maps`].
/// The outcome's `fitted` values are those of the global stage's samples (`global.fitted`
/// follows their order); [`fitted_all`] gives any others.
pub fn recover(
    store: &CaptureStore,
    cfg: &FitConfig,
    req: &MapsConfig,
    progress: &crate::progress::Progress,
) -> Result<MapOutcome> {
    let stage = global_stage(store, cfg, req, progress)?;
    let (w, h) = (store.width, store.height);
    let part = texel_stage(
        &TexelStageRequest {
            store,
            cfg,
            req,
            set: &stage.outcome.set,
            rows: (0, h as u32),
            variance_hint: stage.texel_variance,
            schur: Some(&stage.schur),
        },
        progress,
    )?;
    let global_free = stage.outcome.statistics.free_parameters;
    let h_max = max_height(stage.outcome.set.shape_value(Param::Spacing));
    let assembly = Assembly {
        width: w,
        height: h,
        channels: store.channels,
        req,
        global_free,
        h_max,
    };
    let (maps, variance, mut warnings) = finish_maps(vec![part], &assembly)?;
    warnings.splice(0..0, stage.warnings.iter().cloned());
    let global = stage.outcome;
    Ok(MapOutcome {
        global,
        maps,
        costs: stage.costs,
        residual_variance: variance,
        warnings,
    })
}

/// The model at every pixel (sample order) with its texel's values and the globals `set`.
pub fn fitted_all(
    samples: &Samples,
    cfg: &FitConfig,
    req: &MapsConfig,
    set: &ParamSet,
    maps: &TexelMaps,
) -> Result<Vec<[f64; 3]>> {
    let layout = Layout::new(samples)?;
    let index: HashMap<(u32, u32), usize> = maps
        .texels
        .iter()
        .enumerate()
        .map(|(i, t)| (*t, i))
        .collect();
    let values = layout
        .texels
        .iter()
        .map(|t| match index.get(t) {
            Some(&i) => Ok(maps.values[i]),
            None => bail!(
                "the maps do not belong to these samples (no texel ({}, {}))",
                t.0,
                t.1
            ),
        })
        .collect::<Result<Vec<_>>>()?;
    let set = fix_mapped(set, req);
    let (subset, smaps) = mapped_all(samples, &values, &layout.members, free_of(req));
    let p = problem_on(cfg, &set, &subset, smaps);
    let values = p.model_values(&p.columns(&set)?, &set);
    let mut fitted = vec![[0.0; 3]; samples.samples.len()];
    for (i, v) in layout.members.iter().flatten().zip(values) {
        fitted[*i] = v;
    }
    Ok(fitted)
}

/// The `method` block of a result's `maps`, with the globals' Schur complement `schur` (what
/// tiles need for texel errors that include the globals' uncertainty).
pub fn method(
    cfg: &FitConfig,
    costs: &[f64],
    texel_variance: f64,
    schur: &GlobalSchur,
) -> serde_json::Value {
    serde_json::json!({
        "texel_variance": texel_variance,
        "global_schur": schur,
        "global_stage_rounds": costs.len().saturating_sub(1),
        "global_stage_cost_per_round": costs,
        "global_texels": cfg.maps.global_texels,
        "smoothness": cfg.maps.smoothness,
        "prior_sweeps": if cfg.maps.smoothness > 0.0 { PRIOR_SWEEPS } else { 0 },
    })
}

/// One recovered map in a few numbers: its median and 5-95 % range over the texels, and the
/// fraction of texels flagged (undetermined: a standard error at or above half the value's
/// range, or not finite; or ambiguous: another minimum within [`AMBIGUITY_DELTA`] residual
/// variances).
#[derive(Clone, Debug, serde::Serialize)]
pub struct MapSummary {
    /// The map's name, with its channel for per-channel albedos (`kd[g]`).
    pub name: String,
    pub unit: &'static str,
    pub median: f64,
    pub p5: f64,
    pub p95: f64,
    /// Median standard error over the texels with a finite one.
    pub median_std_error: f64,
    pub flagged_fraction: f64,
    pub texels: usize,
}

/// Quantile `q` of sorted values (linear between ranks); NaN when empty.
fn quantile(sorted: &[f64], q: f64) -> f64 {
    if sorted.is_empty() {
        return f64::NAN;
    }
    let x = q * (sorted.len() - 1) as f64;
    let (i, f) = (x.floor() as usize, x - x.floor());
    let j = (i + 1).min(sorted.len() - 1);
    sorted[i] + f * (sorted[j] - sorted[i])
}

/// [`MapSummary`] of every map `req` asks for (per channel for the albedos); `h_max` is the
/// largest height at the fitted spacing. The fibre azimuth's median and range are taken on the
/// axial circle: centred on the circular mean, so a direction near +-90 deg is not split.
pub fn summary(maps: &TexelMaps, req: &MapsConfig, h_max: f64) -> Vec<MapSummary> {
    let mut out = Vec::new();
    let n = maps.values.len();
    let ch = maps.channels;
    let mut one = |name: String,
                   unit: &'static str,
                   value: &dyn Fn(&TexelValues) -> f64,
                   half_range: f64,
                   centre: f64| {
        let mut v: Vec<f64> = maps
            .values
            .iter()
            .map(|x| match unit == "degrees" {
                // axial: into the half-period around the circular mean
                true => (value(x) - centre + 90.0).rem_euclid(180.0) - 90.0 + centre,
                false => value(x),
            })
            .collect();
        v.sort_by(f64::total_cmp);
        let mut se: Vec<f64> = maps
            .std_errors
            .iter()
            .map(value)
            .filter(|e| e.is_finite())
            .collect();
        se.sort_by(f64::total_cmp);
        let flagged = (0..n)
            .filter(|&k| {
                maps.ambiguous.get(k).copied().unwrap_or(false)
                    || !(value(&maps.std_errors[k]) < half_range)
            })
            .count();
        out.push(MapSummary {
            name,
            unit,
            median: quantile(&v, 0.5),
            p5: quantile(&v, 0.05),
            p95: quantile(&v, 0.95),
            median_std_error: quantile(&se, 0.5),
            flagged_fraction: flagged as f64 / n.max(1) as f64,
            texels: n,
        });
    };
    if req.height {
        one(
            "height".into(),
            "fibre radii",
            &|x| x.height,
            h_max / 2.0,
            0.0,
        );
    }
    if req.fibre_azimuth {
        let (sn, cs) = maps.values.iter().fold((0.0, 0.0), |(a, b), x| {
            let t = (2.0 * x.psi).to_radians();
            (a + t.sin(), b + t.cos())
        });
        let centre = 0.5 * f64::atan2(sn, cs).to_degrees();
        one("fibre_azimuth".into(), "degrees", &|x| x.psi, 45.0, centre);
    }
    let rgb = ["r", "g", "b"];
    for (on, base) in [(req.kd, "kd"), (req.ks, "ks")] {
        if !on {
            continue;
        }
        for c in 0..ch {
            let name = match ch {
                1 => base.to_string(),
                _ => format!("{base}[{}]", rgb[c]),
            };
            match base {
                "kd" => one(name, "albedo", &move |x: &TexelValues| x.kd[c], 0.5, 0.0),
                _ => one(name, "albedo", &move |x: &TexelValues| x.ks[c], 0.5, 0.0),
            }
        }
    }
    out
}

/// The `[[Maps]]` section of a maps fit's report: the work of both stages and each map's
/// summary.
pub fn report_text(
    stage: (usize, usize, u64, f64),
    texel_stage: (usize, usize, f64),
    summaries: &[MapSummary],
) -> String {
    let (rounds, sampled, iterations, g_seconds) = stage;
    let (texels, sweeps, t_seconds) = texel_stage;
    let mut t = String::from(
        "[[Maps]] (per-texel recovery; the statistics above are the global stage's on its sampled texels)\n",
    );
    t += &format!(
        "    global stage       = {rounds} rounds on {sampled} sampled texels, {iterations} LM iterations, {g_seconds:.3} s\n"
    );
    t +=
        &format!("    texel stage        = {texels} texels, {sweeps} sweep(s), {t_seconds:.3} s\n");
    t += &format!("    wall time, maps    = {:.3} s\n", g_seconds + t_seconds);
    t += "    map                 median      5 %       95 %      median se   flagged (undetermined or ambiguous)\n";
    for s in summaries {
        t += &format!(
            "    {:<18} {:>9.4} {:>9.4} {:>9.4} {:>11.4}   {:.1} % of {} texels  ({})\n",
            s.name,
            s.median,
            s.p5,
            s.p95,
            s.median_std_error,
            100.0 * s.flagged_fraction,
            s.texels,
            s.unit
        );
    }
    t
}

/// What the global stage leaves for the texel stage and the result: [`GlobalStage`] without
/// its outcome and warnings ([`GlobalStage::split`]).
pub struct GlobalWork {
    /// Cost over the sampled texels: the plain global fit's, then after each round.
    pub costs: Vec<f64>,
    /// Residual variance per pixel value the texel stage expects ([`GlobalStage`]).
    pub texel_variance: f64,
    /// Levenberg–Marquardt iterations of the stage.
    pub iterations: u64,
    /// Wall time of the stage, seconds.
    pub seconds: f64,
    /// Texels the stage sampled.
    pub texels: usize,
    /// The globals' Schur complement over the sampled texels.
    pub schur: GlobalSchur,
}

impl GlobalStage {
    /// The global fit (its warnings added to the outcome's) and the stage's work.
    pub fn split(self) -> (FitOutcome, GlobalWork) {
        let mut outcome = self.outcome;
        outcome.warnings.extend(self.warnings);
        let work = GlobalWork {
            costs: self.costs,
            texel_variance: self.texel_variance,
            iterations: self.iterations,
            seconds: self.seconds,
            texels: self.texels,
            schur: self.schur,
        };
        (outcome, work)
    }
}

impl GlobalWork {
    /// The `method` block of a result's `maps` ([`method`]).
    pub fn method(&self, cfg: &FitConfig) -> serde_json::Value {
        method(cfg, &self.costs, self.texel_variance, &self.schur)
    }
}

/// The texel stage over a whole capture, with what the result and report say of it.
pub struct TexelRun {
    pub maps: TexelMaps,
    /// Residual variance per pixel value over every texel.
    pub variance: f64,
    pub warnings: Vec<String>,
    /// Wall time of the texel stage and the assembly, seconds.
    pub seconds: f64,
    pub summaries: Vec<MapSummary>,
    /// Sweeps over the texels (1, or 1 + [`PRIOR_SWEEPS`] with the smoothness prior).
    pub sweeps: usize,
}

/// Stage 2 over every row of `store` given the globals `globals` (as the result states them,
/// as tiles take them) and the global stage's `work`; `global_free` globals were fitted.
pub fn texel_run(
    store: &CaptureStore,
    cfg: &FitConfig,
    globals: &ParamSet,
    work: &GlobalWork,
    global_free: usize,
    progress: &crate::progress::Progress,
) -> Result<TexelRun> {
    let (w, h) = (store.width, store.height);
    progress.line(&format!("maps: texel stage ({w}x{h} texels)"));
    let t0 = std::time::Instant::now();
    let part = texel_stage(
        &TexelStageRequest {
            store,
            cfg,
            req: &cfg.maps,
            set: globals,
            rows: (0, h as u32),
            variance_hint: work.texel_variance,
            schur: Some(&work.schur),
        },
        progress,
    )?;
    progress.line("maps: standard errors and flags");
    let h_max = max_height(globals.shape_value(Param::Spacing));
    let assembly = Assembly {
        width: w,
        height: h,
        channels: store.channels,
        req: &cfg.maps,
        global_free,
        h_max,
    };
    let (maps, variance, warnings) = finish_maps(vec![part], &assembly)?;
    let seconds = t0.elapsed().as_secs_f64();
    let summaries = summary(&maps, &cfg.maps, h_max);
    let sweeps = sweeps_of(&cfg.maps);
    Ok(TexelRun {
        maps,
        variance,
        warnings,
        seconds,
        summaries,
        sweeps,
    })
}

impl TexelRun {
    /// The `[[Maps]]` section of the report ([`report_text`]).
    pub fn report_text(&self, work: &GlobalWork) -> String {
        report_text(
            (
                work.costs.len().saturating_sub(1),
                work.texels,
                work.iterations,
                work.seconds,
            ),
            (self.maps.values.len(), self.sweeps, self.seconds),
            &self.summaries,
        )
    }
}
