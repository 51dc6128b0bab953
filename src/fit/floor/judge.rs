//! The floor in a fit: the model's held-out error (auto's chosen candidate's, or a named rung's
//! measured on the same kind of folds) against the floor, and the verdict it gives data
//! without sigmas.

use super::{FloorCheck, ReciprocalFloor};
use crate::fit::config::FitConfig;
use crate::fit::quality::Quality;
use crate::fit::selection::{self, SelectionOutcome};
use crate::fit::FitOutcome;
use crate::load::samples::Samples;

/// Measure the floor of a fit of `samples` with `cfg` (`selection`: auto's, whose chosen
/// candidate's held-out errors are the model's) and judge `outcome` by it ([`apply`]). A
/// floor that cannot be measured is a warning, never the loss of the fit.
pub fn fit_stage(
    samples: &Samples,
    cfg: &FitConfig,
    outcome: &mut FitOutcome,
    selection: Option<&SelectionOutcome>,
    progress: &crate::progress::Progress,
) {
    progress.line("fit: the floor (what the data themselves allow, held out)");
    let heldout = match selection.and_then(selection::of_selection) {
        Some(h) => Ok(h),
        None => selection::of_fit(samples, cfg, &outcome.set),
    };
    let measured = heldout.and_then(|h| Ok((super::Measured::run(samples, cfg.metric, &h, cfg.seed)?, h)));
    match measured {
        Ok((m, h)) => {
            let sigmas = outcome.statistics.sigmas_given;
            let c = m.check(samples, &h);
            let c = match correct(samples, cfg, outcome, &c, &h, &m, progress) {
                Some(corrected) => corrected,
                None => c,
            };
            apply(&mut outcome.quality, &mut outcome.warnings, c, sigmas);
        }
        Err(e) => outcome.warnings.push(format!(
            "the floor (what the data themselves allow) could not be measured: {e:#}"
        )),
    }
}

/// The correction stage ([`crate::fit::correction`]) where the rung misses what data judged
/// by the floor hold (`log` metric, the correction not switched off, the rung not a renderer's
/// own material without the fuzz layer): a kept correction goes into `outcome`, and the floor
/// check of the corrected model is returned.
fn correct(
    samples: &Samples,
    cfg: &FitConfig,
    outcome: &mut FitOutcome,
    c: &FloorCheck,
    h: &crate::fit::selection::HeldOut,
    measured: &super::Measured,
    progress: &crate::progress::Progress,
) -> Option<FloorCheck> {
    // a renderer's own material without the fuzz layer is fitted to go to that renderer as it
    // is, and the renderer could not show a correction: judged as it will be seen
    let fuzz = outcome
        .set
        .albedos
        .iter()
        .any(|a| a.component == crate::model::parameter::Component::Fuzz);
    let renderers_own = outcome.set.rung.rung().renderer.is_some() && !fuzz;
    let wanted = cfg.components.correction
        && !renderers_own
        && cfg.metric == crate::fit::config::Metric::Log
        && !c.within
        && judged_by_floor(&outcome.quality, outcome.statistics.sigmas_given);
    if !wanted {
        return None;
    }
    progress.line("fit: a smooth correction of the rung (held out, kept only where it pays)");
    let full = match selection::model_values_on(outcome, cfg, samples) {
        Ok((_, v)) => v,
        Err(e) => {
            outcome.warnings.push(format!("the correction could not be tried: {e:#}"));
            return None;
        }
    };
    match crate::fit::correction::choose(samples, h, &full, outcome.channels) {
        crate::fit::correction::Decision::NotKept(_) => None,
        crate::fit::correction::Decision::Kept(mut fit, corrected) => {
            fit.reciprocal_floor = measured.reciprocal().map(|f| f.error);
            let instrument = !fit.correction.instrument.is_empty();
            let checked = measured.check_with(samples, &corrected, instrument.then_some(fit.material_error));
            rebin(samples, outcome, &full, &fit.correction);
            outcome.correction = Some(fit);
            Some(checked)
        }
    }
}

/// The residual-structure bins of `outcome` (and their "systematic residuals" warning) again,
/// of the rung's values `full` times the kept correction `k` (with the instrument's terms: the
/// model of the measurement the floor judges).
fn rebin(
    samples: &Samples,
    outcome: &mut FitOutcome,
    full: &[[f64; 3]],
    k: &crate::model::correction::Correction,
) {
    use crate::fit::config::Metric;
    let ch = outcome.channels;
    let raw: Vec<[f64; 3]> = samples.samples.iter().map(|s| s.value).collect();
    let eps = [0, 1, 2].map(|c| crate::fit::problem::log_floor(&raw, c));
    let mut residuals = Vec::with_capacity(samples.samples.len() * ch);
    for (s, m) in samples.samples.iter().zip(full) {
        let (ci, co, cd) = crate::fit::correction::sample_point(s);
        // the measurement model's: the material's factor and the instrument's
        let f = k.measured_factor_at(ci, co, cd);
        let scale = crate::fit::problem::residual_scale(Metric::Log, s);
        for c in 0..ch {
            residuals.push(crate::fit::problem::metric_residual(
                Metric::Log,
                scale[c],
                eps[c],
                s,
                c,
                m[c] * f[c],
            ));
        }
    }
    let refs: Vec<&crate::load::samples::Sample> = samples.samples.iter().collect();
    let psi = outcome
        .set
        .shape_value(crate::fit::parameters::Param::Azimuth)
        .to_radians();
    let mut sums = crate::fit::quality::Sums::new(false);
    sums.add(&refs, &residuals, ch, psi);
    let free = outcome.statistics.free_parameters;
    let q = crate::fit::quality::assess_sums(&sums, free, false, || None, &[]);
    let systematic = |w: &String| w.starts_with("systematic residuals");
    outcome.quality.warnings.retain(|w| !systematic(w));
    outcome.warnings.retain(|w| !systematic(w));
    for w in q.warnings.iter().filter(|w| systematic(w)) {
        let w = format!("{w} (with the smooth correction)");
        outcome.quality.warnings.push(w.clone());
        outcome.warnings.push(w);
    }
    outcome.quality.residual_bins = q.residual_bins;
}

/// Does the verdict of data with these noise sources follow the floor? Without sigmas, unless
/// neighbouring pixels of a capture measured the noise.
pub fn judged_by_floor(q: &Quality, sigmas_given: bool) -> bool {
    !sigmas_given && q.noise.source != "neighbouring pixels"
}

/// Put the floor check `c` into the quality block `q`; for data judged by the floor
/// ([`judged_by_floor`]) its verdict replaces "noise unknown" (whose warning goes from `q` and
/// `warnings`), and a model that misses structure the data hold is a warning in both (the FIT
/// QUALITY banner).
pub fn apply(q: &mut Quality, warnings: &mut Vec<String>, c: FloorCheck, sigmas_given: bool) {
    if judged_by_floor(q, sigmas_given) {
        if q.noise.source == "none" {
            let note = q.noise.note.clone();
            q.warnings.retain(|w| *w != note);
            warnings.retain(|w| *w != note);
            q.noise.note = "no sigmas, no repeated directions and no neighbouring pixels to \
                            estimate the noise from: the fit is judged against the floor, what \
                            the data themselves allow"
                .into();
        }
        q.verdict = c.verdict.clone();
        if !c.within {
            let w = misses_warning(&c);
            q.warnings.push(w.clone());
            warnings.push(w);
        }
    }
    q.floor = Some(c);
}

/// The warning of a model beyond the floor's limit: one that misses structure the data hold,
/// or, where the data are not reciprocal and the model is within the limit of a reciprocal
/// predictor's floor, what no material can follow.
pub fn misses_warning(c: &FloorCheck) -> String {
    let not_reciprocal = c.reciprocal.as_ref().filter(|r| r.data_not_reciprocal());
    match not_reciprocal {
        Some(r @ ReciprocalFloor { within: true, material_error: Some(material), .. }) => format!(
            "the data are not reciprocal: the model of the measurement (the material and the \
             instrument's light/view imbalance) has held-out error {:.4}, {:.2}x the floor {:.4} \
             ({} on the same {}); the material delivered, {:.4}, is {:.2}x the floor of the same \
             predictor made reciprocal ({:.4}), what any material (a reciprocal BRDF) can reach: \
             within {}x of that",
            c.heldout_error,
            c.ratio,
            c.floor,
            c.estimate.predictor,
            c.estimate.validation,
            material,
            r.ratio,
            r.floor,
            c.limit
        ),
        Some(r) if r.within => format!(
            "the data are not reciprocal: the model's held-out error {:.4} is {:.2}x the floor \
             {:.4} ({} on the same {}), but {:.2}x the floor of the same predictor made \
             reciprocal ({:.4}), what any material (a reciprocal BRDF) can reach: within {}x \
             of that. The rest is the measurement's own asymmetry between light and view",
            c.heldout_error,
            c.ratio,
            c.floor,
            c.estimate.predictor,
            c.estimate.validation,
            r.ratio,
            r.floor,
            c.limit
        ),
        _ => format!(
            "the model misses structure the data hold: its held-out error {:.4} is {:.2}x the floor \
             {:.4} ({} on the same {}; within {}x is what the data allow{}): {}",
            c.heldout_error,
            c.ratio,
            c.floor,
            c.estimate.predictor,
            c.estimate.validation,
            c.limit,
            match not_reciprocal {
                Some(r) => format!(
                    "; the data are not reciprocal, and {:.2}x the floor of the same predictor \
                     made reciprocal ({:.4}: what any material can reach)",
                    r.ratio, r.floor
                ),
                None => String::new(),
            },
            c.where_text
        ),
    }
}
