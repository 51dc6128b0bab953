//! Fitting: bounded least squares on argmin, with uncertainties.
//!
//! Pipeline, one module per stage: [`setup`] (parameters from the config and the data) ->
//! [`global`] (a space-filling design over the shape space on a subsample, the distinct best
//! candidates polished and clustered into basins) -> [`polish`] (every competitive basin
//! polished on all samples; the best is the fit, the others are reported when the data do not
//! decide between them) -> [`finish`] (standard errors, correlations, statistics, quality).
//! The fibre models are linear in their albedos, which are solved exactly inside every step
//! (see [`problem`]).

pub mod all_pixels;
pub mod basins;
pub mod config;
pub mod correction;
pub mod determined;
pub mod encoding_check;
pub mod finish;
pub mod floor;
pub mod global;
pub mod gltf_material;
pub mod lm;
pub mod maps;
pub mod parameters;
pub mod polish;
pub mod problem;
pub mod quality;
pub mod score;
pub mod selection;
pub mod setup;
pub mod spread_hold;
pub mod uncertainty;

use crate::load::samples::Samples;
use crate::model::topology::TopologyMap;
use anyhow::Result;
use config::FitConfig;
use nalgebra::DVector;
use parameters::{Param, ParamSet};
use problem::FitProblem;
use rand::seq::SliceRandom;
use rand::SeedableRng;
use std::sync::Arc;
use std::time::Instant;

/// One parameter after the fit, in external units.
#[derive(Clone, Debug, serde::Serialize)]
pub struct ParamRecord {
    /// The parameter's name (as the config and result name it).
    pub name: String,
    /// One value (shapes, grey albedos) or three (RGB albedos).
    pub value: Vec<f64>,
    /// Standard error per value (`None`: fixed, held, at a bound, or not computable).
    pub std_error: Vec<Option<f64>>,
    /// The start value(s).
    pub init: Vec<f64>,
    /// Lower bound of the fit.
    pub min: f64,
    /// Upper bound of the fit.
    pub max: f64,
    /// Fixed (not fitted).
    pub fixed: bool,
    /// Per value: ended on a bound (no standard error).
    pub at_bound: Vec<bool>,
    /// Why a fixed parameter is fixed (the config, the data, a component, per texel), for the
    /// report and the result (`explain_fixed`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub fixed_reason: Option<String>,
    /// One value fitted for all channels of RGB data (`value` repeats it per channel): `ks`
    /// unless the config asks for `colour = true`.
    #[serde(skip_serializing_if = "std::ops::Not::not")]
    pub grey: bool,
    /// Why a free parameter is held at its value for the standard errors: the data do not
    /// separate it from another one (correlation near +-1, or at a bound where a free one
    /// would take its role); see `Degeneracy`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub held: Option<String>,
    /// Per value, why the data do not determine it (at a bound, held, flat cost), or `None`
    /// when they do; empty when every value is determined or the parameter is fixed. The value
    /// is still the one used. Set by the fit (`fit::determined::assess`).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub undetermined: Vec<Option<String>>,
}

impl ParamRecord {
    /// Why the data do not determine value `c`, or `None` when they do (or it is fixed).
    pub fn undetermined(&self, c: usize) -> Option<&str> {
        self.undetermined.get(c).and_then(|x| x.as_deref())
    }
}

/// Everything a fit produced.
#[derive(Clone, Debug)]
pub struct FitOutcome {
    /// The fitted parameter set (internal form).
    pub set: ParamSet,
    /// Every parameter in external units.
    pub records: Vec<ParamRecord>,
    /// Correlations above 0.1 between free parameters (names, r).
    pub correlations: Vec<(String, String, f64)>,
    /// Fit statistics (chi-square, RMSE in 1/sr, AIC, BIC ...).
    pub statistics: uncertainty::Statistics,
    /// Every warning of the fit.
    pub warnings: Vec<String>,
    /// LM iterations of the final (all-sample) run.
    pub iterations: u64,
    /// Model evaluations over the samples, all stages.
    pub evaluations: usize,
    /// Basins of the global stage: free shape values (external units) and cost on the subsample.
    pub starts: Vec<(Vec<f64>, f64)>,
    /// Distinct minima on all samples, best first (the first is the fit): free shape values
    /// (external units) with their names, and the cost.
    pub minima: Vec<(Vec<(String, f64)>, f64)>,
    /// Channels fitted (1 for grey data, also when stored as RGB).
    pub channels: usize,
    /// Does the fit fit within the noise, is it the only minimum, are residuals structured?
    pub quality: quality::Quality,
    /// Wall time of the fit, seconds.
    pub elapsed_seconds: f64,
    /// Model value per sample and channel at the solution.
    pub fitted: Vec<[f64; 3]>,
    /// The topology map fitted with, if any.
    pub map: Option<Arc<TopologyMap>>,
    /// The smooth reciprocal correction kept on the rung (`fit::correction`), if any.
    pub correction: Option<correction::CorrectionFit>,
}

/// Fit `samples` as `cfg` says.
pub fn fit(
    samples: &Samples,
    cfg: &FitConfig,
    progress: &crate::progress::Progress,
) -> Result<FitOutcome> {
    fit_with_hints(samples, cfg, progress, &[])
}

/// Fit with extra starts: each hint gives values of some shape parameters (e.g. the optimum of a
/// simpler rung nested in this one); height and map scale missing from a hint start at their
/// minimum (a rung without them is this one without climbing), the rest at the config's start.
pub fn fit_with_hints(
    samples: &Samples,
    cfg: &FitConfig,
    progress: &crate::progress::Progress,
    hints: &[Vec<(Param, f64)>],
) -> Result<FitOutcome> {
    let t0 = Instant::now();
    let setup::Setup {
        template,
        channels,
        map,
        notes,
    } = setup::setup(samples, cfg)?;
    let opt = &cfg.optimizer;
    let all: Vec<_> = samples.samples.iter().collect();
    // a problem evaluated at the knobs of `at` (the config, or the global stage's search knobs)
    let problem_at = |subset: Vec<_>, template: ParamSet, at: &FitConfig| {
        FitProblem::new(subset, template, problem::Settings::of(at), map.clone())
            .with_azimuth_nodes(at.knobs.azimuth_nodes)
    };
    let problem_of = |subset: Vec<_>, template: ParamSet| problem_at(subset, template, cfg);
    let make = |subset: Vec<_>| problem_of(subset, template.clone());
    let full = make(all.clone());
    let mut rng = rand::rngs::StdRng::seed_from_u64(cfg.seed);
    let bar = progress.bar(0, "fit");
    let mut evaluations = 0;
    let mut starts = Vec::new();
    let mut iterations = 0;
    let mut minima_theta = Vec::new();
    if full.dim() == 0 {
        minima_theta.push((DVector::zeros(0), f64::NAN));
    } else {
        let mut idx: Vec<usize> = (0..all.len()).collect();
        idx.shuffle(&mut rng);
        idx.truncate(opt.global_subsample.max(full.dim() * 4).min(all.len()));
        // the global stage at `FitConfig::search_knobs` where they are given
        let search = cfg.search_knobs.as_ref().map(|k| FitConfig {
            knobs: k.clone(),
            ..cfg.clone()
        });
        let subset = idx.iter().map(|&i| all[i]).collect();
        let sub = problem_at(subset, template.clone(), search.as_ref().unwrap_or(cfg))
            .with_log_floor_of(&full);
        let mut forced = vec![sub.theta_of(&template)];
        for h in hints {
            let mut set = template.clone();
            for s in set.shapes.iter_mut().filter(|s| s.vary) {
                match h.iter().find(|x| x.0 == s.kind) {
                    Some(&(_, v)) => s.value = v.clamp(s.min, s.max),
                    // a simpler rung is this one with no climbing and no spread of heights
                    None if matches!(s.kind, Param::Height | Param::MapScale) => s.value = s.min,
                    None => {}
                }
            }
            forced.push(sub.theta_of(&set));
        }
        let stage = |what: String| {
            let took = crate::progress::seconds(t0.elapsed().as_secs_f64());
            progress.line_above(&bar, &format!("fit: {what} (at {took})"));
        };
        stage(format!(
            "global search over {} free parameters on {} of {} samples",
            full.dim(),
            idx.len(),
            all.len()
        ));
        let basins = global::search(
            global::Stage {
                sub: &sub,
                template: &template,
                bar: &bar,
            },
            forced,
            opt,
            cfg.starts,
            &mut rng,
        )?;
        stage(format!(
            "polishing {} basin{} on all {} samples",
            basins.len(),
            if basins.len() == 1 { "" } else { "s" },
            all.len()
        ));
        for b in &basins {
            starts.push((free_values(&sub.set_at(&b.theta, &template)), b.cost));
        }
        evaluations += sub.evaluations.load(std::sync::atomic::Ordering::Relaxed);
        let minima = polish::final_stage(
            &full,
            &template,
            &basins,
            opt.max_iterations,
            opt.tolerance,
            &bar,
        )?;
        iterations = minima[0].iterations;
        minima_theta = minima.into_iter().map(|m| (m.theta, m.cost)).collect();
    }
    bar.finish_and_clear();
    progress.line(&format!(
        "fit: standard errors and quality checks (at {})",
        crate::progress::seconds(t0.elapsed().as_secs_f64())
    ));
    let minima: Vec<(ParamSet, f64)> = minima_theta
        .iter()
        .map(|(th, c)| (full.set_at(th, &template), *c))
        .collect();
    let free = finish::finish(&full, samples, channels, &minima, notes.clone())?;
    let held = spread_hold::try_hold(
        spread_hold::Free {
            full: &full,
            template: &template,
            minima: &minima_theta,
            outcome: &free,
        },
        &|held_template| problem_of(all.clone(), held_template),
        samples,
        cfg,
        notes,
        &bar,
    )?;
    let (mut outcome, held_why) = match held {
        Some((mut o, why)) => {
            o.evaluations += free.evaluations;
            (o, Some(why))
        }
        None => (free, None),
    };
    parameters::explain_fixed(&mut outcome.records, cfg, samples, &[]);
    if let Some(why) = held_why {
        progress.line(&format!("fit: the fibre-direction spread is {why}"));
        let name = Param::AzimuthSpread.name();
        if let Some(r) = outcome.records.iter_mut().find(|r| r.name == name) {
            r.fixed_reason = Some(why);
        }
    }
    outcome.iterations = iterations;
    outcome.evaluations += evaluations;
    outcome.starts = starts;
    outcome.elapsed_seconds = t0.elapsed().as_secs_f64();
    outcome.map = map;
    Ok(outcome)
}

/// Values of the free shape parameters of `set`, external units.
fn free_values(set: &ParamSet) -> Vec<f64> {
    set.shapes
        .iter()
        .filter(|s| s.vary)
        .map(|s| s.value)
        .collect()
}

/// Samples the checks after a fit read at most (the floor, with the model refitted on its
/// split, and each renderer's own material fitted to the same data): a capture's global fit
/// holds 262 144 pixel values, on which those took ~57 s beside a 1.4 s fit (8 x 512 x 512,
/// `fibrefit bench camera`), where 20 000 measure the floor's and the materials' errors to a
/// few percent.
pub const CHECK_SAMPLES: usize = 20_000;

/// The samples of the checks after a fit ([`CHECK_SAMPLES`]): all of them up to that many, else
/// a subset of that many seeded from `seed`, in their order.
pub fn check_subset(samples: &Samples, seed: u64) -> std::borrow::Cow<'_, Samples> {
    let n = samples.samples.len();
    if n <= CHECK_SAMPLES {
        return std::borrow::Cow::Borrowed(samples);
    }
    let mut idx: Vec<usize> = (0..n).collect();
    idx.shuffle(&mut rand::rngs::StdRng::seed_from_u64(seed ^ 0x6368_6563_6b73));
    idx.truncate(CHECK_SAMPLES);
    idx.sort_unstable();
    std::borrow::Cow::Owned(samples.subset(&idx))
}

/// Azimuths are defined modulo 180 degrees: report them in [-90, 90).
pub fn wrap_azimuth(deg: f64) -> f64 {
    (deg + 90.0).rem_euclid(180.0) - 90.0
}

/// The fitted BRDF (1/sr per channel) of an outcome as a function of the swatch-frame directions,
/// at the fitted fibre azimuth and with the knobs of `cfg` (for plots and comparisons), times
/// its smooth correction where it keeps one.
pub fn fitted_brdf(o: &FitOutcome, cfg: &FitConfig) -> crate::model::BrdfFn {
    let m = problem::model_for(
        &o.set,
        cfg.knobs.quadrature_order,
        cfg.knobs.histogram_bins,
        cfg.knobs.azimuth_nodes,
        o.map.clone(),
    );
    let albedos = problem::albedos_of(&o.set);
    let frame =
        crate::model::FibreFrame::from_azimuth(o.set.shape_value(Param::Azimuth).to_radians());
    let channels = o.channels;
    let correction = o.correction.as_ref().map(|c| c.correction.clone());
    Box::new(move |l, v| {
        let pair = crate::model::DirectionPair::new(&frame, l, v);
        let b = m.basis(&pair);
        let f = correction.as_ref().map_or([1.0; 3], |k| k.factor(&pair));
        let mut out = [0.0; 3];
        for (c, x) in out.iter_mut().enumerate() {
            *x = b.brdf(&albedos, c.min(channels - 1)) * f[c.min(channels - 1)];
        }
        Some(out)
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::load::samples::{DataKind, Dropped, Origin, Sample};
    use crate::model::frame::Vec3;

    fn samples(n: usize) -> Samples {
        let samples = (0..n)
            .map(|k| Sample {
                l: Vec3::z(),
                v: Vec3::z(),
                fibre_azimuth: None,
                map_value: None,
                texel_height: None,
                value: [k as f64; 3],
                sigma: None,
                weight: 1.0,
                origin: Origin::Line(k as u64 + 1),
            })
            .collect();
        Samples {
            samples,
            channels: 1,
            kind: DataKind::Gonio,
            source: "test".into(),
            dropped: Dropped::default(),
            skipped_examples: Vec::new(),
            image_size: None,
            scale_rel_se: None,
        }
    }

    #[test]
    fn the_checks_after_a_fit_read_all_samples_up_to_their_cap_and_a_seeded_subset_beyond() {
        let small = samples(CHECK_SAMPLES);
        assert!(matches!(check_subset(&small, 1), std::borrow::Cow::Borrowed(_)));
        let large = samples(3 * CHECK_SAMPLES + 7);
        let (a, b, c) = (
            check_subset(&large, 1),
            check_subset(&large, 1),
            check_subset(&large, 2),
        );
        assert_eq!(a.samples.len(), CHECK_SAMPLES);
        let lines = |s: &Samples| s.samples.iter().map(|x| x.value[0]).collect::<Vec<_>>();
        // the same subset for a seed, another for another; in the data's order, no repeats
        assert_eq!(lines(&a), lines(&b));
        assert_ne!(lines(&a), lines(&c));
        assert!(lines(&a).windows(2).all(|w| w[0] < w[1]));
        // drawn from the whole range
        assert!(lines(&a)[CHECK_SAMPLES - 1] > (2 * CHECK_SAMPLES) as f64);
        assert_eq!((a.channels, a.source.clone()), (1, "test".into()));
    }
}
