//! The last stage: at the best minimum, the albedos, residuals, standard errors, correlations,
//! statistics and per-parameter records; the other distinct minima for the quality checks.

use super::parameters::{Param, ParamSet};
use super::problem::{coordinate, height_range, Coordinate, FitProblem};
use super::{quality, uncertainty, wrap_azimuth, FitOutcome, ParamRecord};
use crate::load::samples::Samples;
use anyhow::Result;

/// Is `set`'s free shape `i` on a bound (its effective bound for heights; never for a periodic
/// azimuth)?
fn shape_at_bound(set: &ParamSet, i: usize) -> bool {
    let s = &set.shapes[i];
    let (lo, hi) = match coordinate(s) {
        Coordinate::Periodic => return false,
        Coordinate::UnderMaxHeight => height_range(s, set.shape_value(Param::Spacing)),
        _ => (s.min, s.max),
    };
    near(s.value, lo, s.min, s.max) || near(s.value, hi, s.min, s.max)
}

fn near(v: f64, b: f64, lo: f64, hi: f64) -> bool {
    (v - b).abs() <= 1e-9 * (hi - lo).abs().max(1.0)
}

/// The outcome at `minima[0]` (parameter sets with shapes at the minimum, best first).
pub fn finish(
    full: &FitProblem,
    samples: &Samples,
    ch: usize,
    minima: &[(ParamSet, f64)],
    notes: Vec<String>,
) -> Result<FitOutcome> {
    let mut set = minima[0].0.clone();
    let cols = full.columns(&set)?;
    if full.separable {
        full.solve_albedos(&cols, &mut set);
    }
    let r = full.residuals(&cols, &set);
    let chi2 = r.norm_squared();
    let fitted = full.model_values(&cols, &set);
    let mut model_flat = Vec::with_capacity(fitted.len() * ch);
    let mut data_flat = Vec::with_capacity(fitted.len() * ch);
    for (m, s) in fitted.iter().zip(&samples.samples) {
        model_flat.extend_from_slice(&m[..ch]);
        data_flat.extend_from_slice(&s.value[..ch]);
    }
    let n = r.len();
    let p = full.free_shapes().len() + full.free_albedos().len();
    let sigmas = samples.samples.iter().all(|s| s.sigma.is_some());
    let statistics = uncertainty::statistics(chi2, n, p, sigmas, &model_flat, &data_flat);

    // standard errors over the full parameter vector
    let at_bound = free_at_bound(full, &set);
    let errors = Errors::of(full, &set, &cols, &at_bound, chi2, n)?;
    let mut warnings = notes;
    warnings.extend(errors.cov.warnings.iter().cloned());
    warnings.extend(errors.degeneracies.iter().map(|d| d.note.clone()));
    // values at a bound, held or along which the cost is flat are warned about as undetermined
    // (`determined::apply`, below)
    let mut records = records(full, &set, &errors, &at_bound, ch);
    if let Some(rel) = samples.scale_rel_se {
        include_scale_uncertainty(&mut records, &set, rel);
    }
    let names = &errors.names;
    let correlations = errors
        .cov
        .correlations
        .iter()
        .map(|&(a, b, r)| (names[a].clone(), names[b].clone(), r))
        .collect();
    let minima = named_minima(minima);
    let mut quality = quality::assess(&quality::Inputs {
        samples: &full.samples,
        scale: full.scale(),
        residuals: r.as_slice(),
        channels: ch,
        free_parameters: p,
        sigmas_given: sigmas,
        psi: set.shape_value(Param::Azimuth).to_radians(),
        minima: &minima,
    });
    quality.degeneracies = errors.degeneracies;
    // a PNG capture read with the wrong transfer curve (src/fit/encoding_check.rs)
    quality
        .warnings
        .extend(super::encoding_check::check(samples, &fitted));
    warnings.extend(quality.warnings.iter().cloned());
    let mut outcome = FitOutcome {
        quality,
        set,
        records,
        correlations,
        statistics,
        warnings,
        iterations: 0,
        evaluations: full.evaluations.load(std::sync::atomic::Ordering::Relaxed),
        starts: vec![],
        minima,
        channels: ch,
        elapsed_seconds: 0.0,
        fitted,
        map: None,
        correction: None,
    };
    super::determined::apply(&mut outcome);
    Ok(outcome)
}

/// Add the data's common-scale uncertainty (relative standard error `rel` per channel) to the
/// albedos' standard errors in quadrature: the model is linear in its albedos, so scaling
/// every value by (1 + e) scales every albedo by (1 + e) and leaves the shapes as they are.
fn include_scale_uncertainty(records: &mut [ParamRecord], set: &ParamSet, rel: [f64; 3]) {
    for r in records.iter_mut() {
        if !set.albedos.iter().any(|a| a.name == r.name) {
            continue;
        }
        for (c, se) in r.std_error.iter_mut().enumerate() {
            if let Some(e) = se {
                *e = e.hypot(r.value[c] * rel[c.min(2)]);
            }
        }
    }
}

/// Per free column of the full parameter vector (shapes, then albedos): on a bound?
fn free_at_bound(full: &FitProblem, set: &ParamSet) -> Vec<bool> {
    let mut at_bound: Vec<bool> = full
        .free_shapes()
        .iter()
        .map(|&i| shape_at_bound(set, i))
        .collect();
    for &(i, c) in full.free_albedos() {
        let a = &set.albedos[i];
        at_bound
            .push(near(a.value[c], a.min, a.min, a.max) || near(a.value[c], a.max, a.min, a.max));
    }
    at_bound
}

/// The standard errors of the free columns: the pairs the data do not separate (one of each
/// held), and the covariance with those and the columns at a bound excluded.
struct Errors {
    /// The full-Jacobian columns' names.
    names: Vec<String>,
    degeneracies: Vec<quality::Degeneracy>,
    cov: uncertainty::Covariance,
}

impl Errors {
    fn of(
        full: &FitProblem,
        set: &ParamSet,
        cols: &[[f64; 4]],
        at_bound: &[bool],
        chi2: f64,
        n: usize,
    ) -> Result<Self> {
        let names = full.full_names();
        let jac = full.full_jacobian(set, cols)?;
        // pairs the data do not separate, from the covariance with every column free (one at a
        // bound too: its partner took its role); one of each is held, the others' errors
        // conditional; the Jacobian reduced to its p x p triangle once (QR, in place): both
        // covariances from it
        let jac = uncertainty::reduce(jac);
        let cov_free =
            uncertainty::covariance_of_r(&jac, &names, &vec![false; names.len()], chi2, n);
        let ranges = free_ranges(full, set);
        let relative_se: Vec<Option<f64>> = cov_free
            .std_error
            .iter()
            .zip(&ranges)
            .map(|(e, r)| e.map(|e| e / r.max(f64::MIN_POSITIVE)))
            .collect();
        let (degeneracies, held_cols) =
            quality::degeneracies(&names, &cov_free.correlations, at_bound, &relative_se);
        let mut excluded = at_bound.to_vec();
        for &k in &held_cols {
            excluded[k] = true;
        }
        let cov = uncertainty::covariance_of_r(&jac, &names, &excluded, chi2, n);
        Ok(Self {
            names,
            degeneracies,
            cov,
        })
    }

    /// The note of the pair whose held parameter is full-Jacobian column `k`.
    fn held_note(&self, k: usize) -> Option<String> {
        self.degeneracies
            .iter()
            .find(|d| d.held == self.names[k])
            .map(|d| d.note.clone())
    }
}

/// The width of each free column's range in the fit's coordinate (180 for an unbounded one).
fn free_ranges(full: &FitProblem, set: &ParamSet) -> Vec<f64> {
    full.free_shapes()
        .iter()
        .map(|&i| {
            let s = &set.shapes[i];
            let (lo, hi) = (s.kind.to_internal(s.min), s.kind.to_internal(s.max));
            if (hi - lo).is_finite() {
                hi - lo
            } else {
                180.0
            }
        })
        .chain(
            full.free_albedos()
                .iter()
                .map(|&(i, _)| set.albedos[i].max - set.albedos[i].min),
        )
        .collect()
}

/// Per-parameter records in external units: the shapes, then the albedos per channel.
fn records(
    full: &FitProblem,
    set: &ParamSet,
    errors: &Errors,
    at_bound: &[bool],
    ch: usize,
) -> Vec<ParamRecord> {
    let cov = &errors.cov;
    let mut records = Vec::new();
    let mut col = 0;
    for s in set.shapes.iter() {
        let (se, ab, held) = if s.vary {
            let se = cov.std_error[col].map(|e| if s.kind.log_space() { e * s.value } else { e });
            let ab = at_bound[col];
            let held = errors.held_note(col);
            col += 1;
            (se, ab, held)
        } else {
            (None, false, None)
        };
        let value = if s.kind == Param::Azimuth {
            wrap_azimuth(s.value)
        } else {
            s.value
        };
        records.push(ParamRecord {
            name: s.kind.name().to_string(),
            value: vec![value],
            std_error: vec![se],
            init: vec![s.init],
            min: s.min,
            max: s.max,
            fixed: !s.vary,
            at_bound: vec![ab],
            fixed_reason: None,
            grey: false,
            held,
            undetermined: Vec::new(),
        });
    }
    for (i, a) in set.albedos.iter().enumerate() {
        let mut se = vec![None; ch];
        let mut ab = vec![false; ch];
        let mut held: Vec<String> = Vec::new();
        if a.vary {
            for c in 0..ch {
                // a grey albedo is one column (channel 0) for every channel
                let cc = if a.grey { 0 } else { c };
                let k = full
                    .free_albedos()
                    .iter()
                    .position(|&(ii, x)| ii == i && x == cc)
                    .expect("free albedo");
                let colk = full.free_shapes().len() + k;
                se[c] = cov.std_error[colk];
                ab[c] = at_bound[colk];
                if let Some(h) = errors.held_note(colk).filter(|h| !held.contains(h)) {
                    held.push(h);
                }
            }
        }
        records.push(ParamRecord {
            name: a.name.to_string(),
            value: a.value[..ch].to_vec(),
            std_error: se,
            init: a.init[..ch].to_vec(),
            min: a.min,
            max: a.max,
            fixed: !a.vary,
            at_bound: ab,
            fixed_reason: None,
            grey: a.grey && a.vary,
            held: (!held.is_empty()).then(|| held.join("; ")),
            undetermined: Vec::new(),
        });
    }
    records
}

/// The minima with their free shapes named, for the quality checks and the outcome: as fitted,
/// periodic ones wrapped into their period (as the records give them). The polishing merged
/// those a symmetry of the rung maps onto each other (`basins::Metric`).
fn named_minima(minima: &[(ParamSet, f64)]) -> Vec<(Vec<(String, f64)>, f64)> {
    minima
        .iter()
        .map(|(s, c)| {
            let mut values: Vec<(Param, f64)> = s
                .shapes
                .iter()
                .filter(|x| x.vary)
                .map(|x| (x.kind, x.value))
                .collect();
            crate::model::rung::wrap_periodic(&mut values);
            let named = values
                .into_iter()
                .map(|(p, v)| (p.name().to_string(), v))
                .collect();
            (named, *c)
        })
        .collect()
}
