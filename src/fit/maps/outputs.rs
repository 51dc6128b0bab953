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
    quiet: bool,
) -> Result<MapOutcome> {
    let stage = global_stage(store, cfg, req, quiet)?;
    let (w, h) = (store.width, store.height);
    let part = texel_stage(
        store,
        cfg,
        req,
        &stage.outcome.set,
        (0, h as u32),
        stage.texel_variance,
        quiet,
    )?;
    let global_free = stage.outcome.statistics.free_parameters;
    let h_max = max_height(stage.outcome.set.shape_value(Shape::Spacing));
    let (maps, variance, mut warnings) =
        finish_maps(vec![part], w, h, store.channels, req, global_free, h_max)?;
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

/// The `method` block of a result's `maps`.
pub fn method(cfg: &FitConfig, costs: &[f64], texel_variance: f64) -> serde_json::Value {
    serde_json::json!({
        "texel_variance": texel_variance,
        "global_stage_rounds": costs.len().saturating_sub(1),
        "global_stage_cost_per_round": costs,
        "global_texels": cfg.maps.global_texels,
        "smoothness": cfg.maps.smoothness,
        "prior_sweeps": if cfg.maps.smoothness > 0.0 { PRIOR_SWEEPS } else { 0 },
    })
}
