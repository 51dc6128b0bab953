//! Which fitted values the data determine, decided once here for every consumer (the report,
//! the result JSON, `fit --json`, Python, the renderer exports).
//!
//! A free value is **undetermined** when the data do not say what it is, so its value is one the
//! fit used, not a measurement:
//! - **at a bound**: the fit ended on a bound of the parameter's range (the data ask for a value
//!   beyond it and the model cannot give it), so it has no standard error;
//! - **held by a degeneracy**: the data do not separate it from another parameter (correlation
//!   within 1 - [`crate::fit::quality::DEGENERATE_CORRELATION`] of +-1), so it was held at its fitted value
//!   ([`crate::fit::quality::degeneracies`]);
//! - **flat cost**: the cost hardly changes along it: no standard error could be computed, or its
//!   +-1 standard error interval, in the fit's own coordinate (ln for the log-scale parameters,
//!   1/d for the spacing), is at least [`FLAT_RANGE_FRACTION`] of its range `[min, max]` wide,
//!   or, for a log-scale parameter (the exponent, Ward's alphas, the fuzz depth: positive by
//!   nature, where only the order of magnitude is a measurement), its relative standard error is
//!   above [`FLAT_RELATIVE_ERROR`] (100 %).
//!
//! - **its component is not in the data**: the weight of the lobe or layer it shapes
//!   ([`SHAPES`]: Ward's `rho_s`, the fibres' `ks`, the fuzz layer's `fuzz`, glTF's `sheen`) is
//!   within [`ABSENT_STANDARD_ERRORS`] standard errors of 0 (or at its lower bound 0) in every
//!   channel: the component may be absent, so the shape the fit gave it (a width, an exponent,
//!   a depth) was never measured. Measured: Ward fitted to a matte surface with 1 % noise
//!   ended with `rho_s` 9.6e-5 +/- 7.9e-5 and widths at 70-77 % relative error, which no other
//!   test catches.
//!
//! A value small beside a small error (an albedo of 0.002 +/- 0.003) is determined: the data
//! bound it to a narrow interval, near zero. Fixed parameters are never undetermined: they were
//! not fitted, and say why (`fixed_reason`).

use super::quality::Degeneracy;
use super::{FitOutcome, ParamRecord};
use crate::model::parameter::{Param, Scale};

/// A value whose +-1 standard error interval (in the fit's coordinate) is at least this fraction
/// of its range wide is undetermined: the data leave most of the range open.
pub const FLAT_RANGE_FRACTION: f64 = 0.5;

/// A log-scale value whose standard error is above this fraction of the value is undetermined:
/// the data do not know its order of magnitude.
pub const FLAT_RELATIVE_ERROR: f64 = 1.0;

/// A component's weight within this many standard errors of 0 may be absent: its shape
/// parameters are undetermined.
pub const ABSENT_STANDARD_ERRORS: f64 = 2.0;

/// Each component's weight and the parameters that only shape it (a fit's lobe, layer or
/// sheen): with the weight indistinguishable from 0 they are not measurements. Ward's azimuth
/// only turns its lobe; a fibre rung's also turns its fibres' diffuse, so it is not listed
/// with `ks`.
pub const SHAPES: [(&str, &[&str]); 4] = [
    ("rho_s", &["alpha_x", "alpha_y", "fibre_azimuth_deg"]),
    ("ks", &["exponent"]),
    ("fuzz", &["fuzz_depth", "fuzz_asymmetry"]),
    ("sheen", &["sheen_roughness"]),
];

/// One undetermined value: its label (`spacing`, `kd[b]`), the value used and why.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct Undetermined {
    /// The parameter's name, with `[r]`, `[g]` or `[b]` for one channel of an RGB albedo.
    pub label: String,
    /// The value the fit ended at, which renderers use.
    pub value: f64,
    /// Why the data do not determine it, in words.
    pub reason: String,
}

/// The label of value `c` of record `r` (a grey albedo is one value for every channel).
pub fn label(r: &ParamRecord, c: usize) -> String {
    if r.value.len() == 1 || r.grey {
        r.name.clone()
    } else {
        format!("{}[{}]", r.name, ["r", "g", "b"][c.min(2)])
    }
}

/// Set `undetermined` of every record (one entry per value; `None`: determined or fixed) from its
/// bounds, standard errors and the `degeneracies` the standard errors held parameters for.
pub fn assess(records: &mut [ParamRecord], degeneracies: &[Degeneracy]) {
    for r in records.iter_mut() {
        let reasons: Vec<Option<String>> = (0..r.value.len())
            .map(|c| if r.fixed { None } else { reason(r, c, degeneracies) })
            .collect();
        r.undetermined = if reasons.iter().any(Option::is_some) {
            reasons
        } else {
            Vec::new()
        };
    }
    absent_components(records);
}

/// The shapes of components whose weight the data do not tell from 0 ([`SHAPES`]), each not
/// yet undetermined for another reason, marked undetermined.
fn absent_components(records: &mut [ParamRecord]) {
    for (weight, shapes) in SHAPES {
        let Some(w) = records.iter().find(|r| r.name == weight && !r.fixed) else {
            continue;
        };
        let absent = (0..w.value.len()).all(|c| {
            let v = w.value[c];
            let at_zero = w.at_bound.get(c).copied().unwrap_or(false) && v <= w.min;
            let within = w.std_error[c].is_some_and(|e| v.abs() <= ABSENT_STANDARD_ERRORS * e);
            at_zero || within
        });
        if !absent {
            continue;
        }
        let c = (0..w.value.len())
            .max_by(|&a, &b| w.value[a].total_cmp(&w.value[b]))
            .unwrap_or(0);
        let stated = match w.std_error[c] {
            Some(e) => format!("{} +/- {}", short(w.value[c]), short(e)),
            None => short(w.value[c]),
        };
        let why = format!(
            "the component it shapes is not in the data: its weight `{weight}` = {stated} is within {ABSENT_STANDARD_ERRORS} standard errors of 0, so its shape was never measured"
        );
        for r in records.iter_mut() {
            if r.fixed || !shapes.contains(&r.name.as_str()) || !r.undetermined.is_empty() {
                continue;
            }
            r.undetermined = vec![Some(why.clone()); r.value.len()];
        }
    }
}

/// Every undetermined value of `records`, in their order (a grey albedo once).
pub fn list(records: &[ParamRecord]) -> Vec<Undetermined> {
    let mut out = Vec::new();
    for r in records {
        for (c, why) in r.undetermined.iter().enumerate() {
            let Some(why) = why else { continue };
            if r.grey && c > 0 {
                continue;
            }
            out.push(Undetermined {
                label: label(r, c),
                value: r.value[c],
                reason: why.clone(),
            });
        }
    }
    out
}

/// One line per undetermined value, as warnings and exports say it:
/// "`spacing` is undetermined (value used: 20): at its upper bound 20: ...".
pub fn warning(u: &Undetermined) -> String {
    format!(
        "`{}` is undetermined (value used: {}): {}",
        u.label,
        short(u.value),
        u.reason
    )
}

/// The outcome's records assessed (again: after its standard errors changed, e.g. widened by
/// the maps' stage), its quality block's list of undetermined values set, and a warning for
/// each one not yet warned about.
pub fn apply(o: &mut FitOutcome) {
    assess(&mut o.records, &o.quality.degeneracies);
    let list = list(&o.records);
    for u in &list {
        let w = warning(u);
        if !o.warnings.contains(&w) {
            o.warnings.push(w);
        }
    }
    o.quality.undetermined = list;
}

/// A value as the reasons write it: up to 6 significant digits, no trailing zeros.
pub fn short(v: f64) -> String {
    if v == 0.0 || !v.is_finite() {
        return format!("{v}");
    }
    let digits = (5 - v.abs().log10().floor() as i32).clamp(0, 12) as usize;
    let s = format!("{v:.digits$}");
    if s.contains('.') {
        s.trim_end_matches('0').trim_end_matches('.').to_string()
    } else {
        s
    }
}

/// Why value `c` of the free record `r` is undetermined, or `None` when the data determine it.
fn reason(r: &ParamRecord, c: usize, degeneracies: &[Degeneracy]) -> Option<String> {
    let lab = label(r, c);
    let v = r.value[c];
    // the degeneracy this value is held by, and its partner
    let held_by = degeneracies.iter().find(|d| d.held == lab);
    let partner = |d: &Degeneracy| if d.a == lab { d.b.clone() } else { d.a.clone() };
    if r.at_bound.get(c).copied().unwrap_or(false) {
        let tol = 1e-9 * (r.max - r.min).abs().max(1.0);
        let mut why = if (v - r.min).abs() <= tol {
            format!(
                "at its lower bound {}: the data ask for less and the model cannot give it",
                short(r.min)
            )
        } else if (v - r.max).abs() <= tol {
            format!(
                "at its upper bound {}: the data ask for more and the model cannot give it",
                short(r.max)
            )
        } else {
            // a height's bound is the largest the spacing allows
            format!(
                "at its upper bound {} (the largest the spacing allows): the data ask for more and the model cannot give it",
                short(v)
            )
        };
        if let Some(d) = held_by {
            why += &format!(
                "; `{}` takes its role (correlation {:+.4})",
                partner(d),
                d.correlation
            );
        }
        return Some(why);
    }
    if let Some(d) = held_by {
        return Some(format!(
            "not separable from `{}` (correlation {:+.4}): the data fit a line of values of the two equally well, and this one is held at its fitted value",
            partner(d),
            d.correlation
        ));
    }
    let Some(e) = r.std_error.get(c).copied().flatten() else {
        return Some(
            "the cost is flat along it: no standard error could be computed (the data do not constrain it)"
                .into(),
        );
    };
    flat(r, v, e)
}

/// The flat-cost test of a value `v` with standard error `e` (see the module docs).
fn flat(r: &ParamRecord, v: f64, e: f64) -> Option<String> {
    let scale = Param::from_name(&r.name).map(|p| p.info().scale);
    let pct = |x: f64| 100.0 * x;
    if scale == Some(Scale::Log) && v > 0.0 && e / v > FLAT_RELATIVE_ERROR {
        return Some(format!(
            "the cost is flat along it: +/- {} ({:.0} %), a relative standard error above {:.0} %: the data do not know its order of magnitude",
            short(e),
            pct(e / v),
            pct(FLAT_RELATIVE_ERROR)
        ));
    }
    // the interval's width and the range's, in the fit's coordinate
    let (width, range) = match scale {
        Some(Scale::Log) if v > 0.0 && r.min > 0.0 => (2.0 * e / v, (r.max / r.min).ln()),
        Some(Scale::Reciprocal) if v > 0.0 && r.min > 0.0 => {
            (2.0 * e / (v * v), 1.0 / r.min - 1.0 / r.max)
        }
        _ => (2.0 * e, r.max - r.min),
    };
    if !(range.is_finite() && range > 0.0) {
        return None;
    }
    let covered = width / range;
    (covered >= FLAT_RANGE_FRACTION).then(|| {
        format!(
            "the cost is flat along it: +/- {} ({:.0} % of the value) spans {:.0} % of its range [{}, {}]",
            short(e),
            pct(e / v.abs().max(f64::MIN_POSITIVE)),
            pct(covered.min(9.99)),
            short(r.min),
            short(r.max)
        )
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn record(name: &str, value: Vec<f64>, se: Vec<Option<f64>>, min: f64, max: f64) -> ParamRecord {
        let n = value.len();
        ParamRecord {
            name: name.into(),
            at_bound: value
                .iter()
                .map(|&v| (v - min).abs() < 1e-12 || (v - max).abs() < 1e-12)
                .collect(),
            value,
            std_error: se,
            init: vec![0.5; n],
            min,
            max,
            fixed: false,
            fixed_reason: None,
            grey: false,
            held: None,
            undetermined: Vec::new(),
        }
    }

    #[test]
    fn at_a_bound_held_flat_and_determined() {
        let mut rs = vec![
            record("spacing", vec![20.0], vec![None], 2.0, 20.0),
            record("kd", vec![0.4, 0.3, 0.0], vec![Some(0.01), Some(0.01), None], 0.0, 1.0),
            record("exponent", vec![30.0], vec![Some(45.0)], 1.0, 1e4),
            record("fuzz_asymmetry", vec![0.2], vec![Some(0.5)], -0.9, 0.9),
            record("ks", vec![0.002], vec![Some(0.003)], 0.0, 1.0),
            record("alpha_x", vec![0.2], vec![None], 0.0011, 1.0),
            record("alpha_y", vec![0.3], vec![Some(0.01)], 0.0011, 1.0),
        ];
        let d = Degeneracy {
            a: "alpha_x".into(),
            b: "alpha_y".into(),
            correlation: 0.998,
            held: "alpha_x".into(),
            held_at: "at its fitted value".into(),
            note: String::new(),
        };
        assess(&mut rs, &[d]);
        let l = list(&rs);
        let labels: Vec<&str> = l.iter().map(|u| u.label.as_str()).collect();
        assert_eq!(
            labels,
            ["spacing", "kd[b]", "exponent", "fuzz_asymmetry", "alpha_x"]
        );
        assert!(l[0].reason.starts_with("at its upper bound 20: the data ask for more"));
        assert!(l[1].reason.starts_with("at its lower bound 0: the data ask for less"));
        assert!(l[2].reason.contains("150 %"), "{}", l[2].reason);
        assert!(l[3].reason.contains("56 % of its range"), "{}", l[3].reason);
        assert!(l[4].reason.starts_with("not separable from `alpha_y` (correlation +0.9980)"));
        assert_eq!(
            warning(&l[0]),
            "`spacing` is undetermined (value used: 20): at its upper bound 20: the data ask for more and the model cannot give it"
        );
        // a small value with a small error (ks) and a fixed one are determined
        assert!(rs[4].undetermined.is_empty());
        // the shape of a lobe whose weight may be 0 is not measured, the weight itself is
        let mut ward = vec![
            record("rho_d", vec![0.3], vec![Some(1.4e-4)], 0.0, 1.0),
            record("rho_s", vec![9.6e-5], vec![Some(7.9e-5)], 0.0, 1.0),
            record("alpha_x", vec![0.65], vec![Some(0.5)], 0.0011, 1.0),
            record("alpha_y", vec![0.011], vec![Some(0.0077)], 0.0011, 1.0),
            record("fibre_azimuth_deg", vec![1.4], vec![Some(1.3)], -90.0, 90.0),
        ];
        assess(&mut ward, &[]);
        let l = list(&ward);
        let labels: Vec<&str> = l.iter().map(|u| u.label.as_str()).collect();
        assert_eq!(labels, ["alpha_x", "alpha_y", "fibre_azimuth_deg"]);
        assert!(l[0].reason.contains("`rho_s` = 0.000096 +/- 0.000079 is within 2 standard errors of 0"), "{}", l[0].reason);
        // a lobe the data show (4 standard errors) keeps its measured shape
        ward[1].std_error = vec![Some(2.4e-5)];
        assess(&mut ward, &[]);
        assert!(list(&ward).is_empty());
        rs[0].fixed = true;
        assess(&mut rs, &[]);
        assert!(rs[0].undetermined.is_empty());
    }

    #[test]
    fn values_are_written_short() {
        assert_eq!(short(20.0), "20");
        assert_eq!(short(0.0), "0");
        assert_eq!(short(0.123456789), "0.123457");
        assert_eq!(short(1e4), "10000");
        assert_eq!(short(-3.5), "-3.5");
    }
}
