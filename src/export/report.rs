//! The fit report in the style of a lab notebook (after lmfit's fit_report): statistics, each
//! parameter as `value +/- stderr (pct) (init)`, and correlations above 0.1 sorted by size.

use crate::fit::FitOutcome;
use std::fmt::Write;

pub fn text(outcome: &FitOutcome, model: &str, data: &str) -> String {
    let s = &outcome.statistics;
    let mut t = String::new();
    let _ = writeln!(t, "[[Model]]\n    {model}\n    data: {data}");
    let _ = writeln!(t, "[[Fit Statistics]]");
    let _ = writeln!(t, "    # data points      = {}", s.n);
    let _ = writeln!(t, "    # variables        = {}", s.free_parameters);
    let _ = writeln!(
        t,
        "    # iterations       = {} (final start), {} model evaluations",
        outcome.iterations, outcome.evaluations
    );
    if s.sigmas_given {
        let _ = writeln!(t, "    chi-square         = {:.6e}", s.chi_square);
        let _ = writeln!(t, "    reduced chi-square = {:.6}", s.reduced_chi_square);
    } else {
        let _ = writeln!(
            t,
            "    sum of squares     = {:.6e}  (no sigmas: chi-square not defined)",
            s.chi_square
        );
    }
    let _ = writeln!(t, "    RMSE               = {:.6e} 1/sr", s.rmse);
    let _ = writeln!(
        t,
        "    relative RMSE      = {:.4} %",
        100.0 * s.relative_rmse
    );
    let _ = writeln!(t, "    Akaike info crit   = {:.3}", s.aic);
    let _ = writeln!(t, "    Bayesian info crit = {:.3}", s.bic);
    let _ = writeln!(
        t,
        "    wall time          = {:.3} s",
        outcome.elapsed_seconds
    );
    let _ = writeln!(t, "[[Variables]]");
    for r in &outcome.records {
        for (c, v) in r.value.iter().enumerate() {
            let name = if r.value.len() == 1 {
                r.name.clone()
            } else {
                format!("{}[{}]", r.name, ["r", "g", "b"][c])
            };
            let line = if r.fixed {
                format!("{v:.6} (fixed)")
            } else if r.at_bound[c] {
                format!(
                    "{v:.6} (init = {:.6}) at a bound of [{}, {}]: no standard error",
                    r.init[c], r.min, r.max
                )
            } else {
                match r.std_error[c] {
                    Some(e) => format!(
                        "{v:.6} +/- {e:.6} ({:.2}%) (init = {:.6})",
                        100.0 * e / v.abs().max(f64::MIN_POSITIVE),
                        r.init[c]
                    ),
                    None => format!("{v:.6} +/- not determined (init = {:.6})", r.init[c]),
                }
            };
            let _ = writeln!(t, "    {name:<20} {line}");
        }
    }
    if !outcome.correlations.is_empty() {
        let _ = writeln!(t, "[[Correlations]] (unreported correlations are < 0.100)");
        for (a, b, r) in &outcome.correlations {
            let _ = writeln!(t, "    C({a}, {b}) = {r:+.4}");
        }
    }
    if !outcome.starts.is_empty() {
        let _ = writeln!(
            t,
            "[[Starts]] (shape parameters after polishing on the subsample, cost)"
        );
        for (s, c) in &outcome.starts {
            let vals: Vec<String> = s.iter().map(|v| format!("{v:.4}")).collect();
            let _ = writeln!(t, "    [{}] cost {c:.6e}", vals.join(", "));
        }
    }
    if !outcome.warnings.is_empty() {
        let _ = writeln!(t, "[[Warnings]]");
        for w in &outcome.warnings {
            let _ = writeln!(t, "    {w}");
        }
    }
    t
}
