//! The model-selection table (markdown) and the metric's name.

use super::*;

pub fn metric_name(m: Metric) -> &'static str {
    match m {
        Metric::Linear => "linear",
        Metric::Log => "log",
        Metric::Cosine => "cosine",
    }
}

/// The selection table in markdown.
pub fn table(s: &SelectionOutcome) -> String {
    let mut t = format!(
        "Model selection by {} ({}; errors in the {} metric)\n\
         Rule: {}.\n\n\
         | candidate | free parameters | held-out error | standard error | per fold | held-out RMSE [1/sr] | held-out relative RMSE | held-out log error | knobs | ns per evaluation | fit time [s] | chosen |\n\
         |---|---|---|---|---|---|---|---|---|---|---|---|\n",
        s.validation,
        s.counts.text(),
        s.metric,
        s.rule
    );
    for c in &s.candidates {
        match &c.error {
            Some(e) => {
                t += &format!(
                    "| {} | - | failed: {e} | | | | | | | | {:.2} | |\n",
                    c.name, c.fit_seconds
                )
            }
            None => {
                t += &format!(
                    "| {} | {} | {:.4} | {:.4} | {} | {:.4e} | {:.2} % | {:.4} | {} | {:.0} | {:.2} | {} |\n",
                    c.name,
                    c.free_parameters,
                    c.cv_error,
                    c.cv_standard_error,
                    c.folds_text(),
                    c.heldout_rmse,
                    100.0 * c.heldout_relative_rmse,
                    c.heldout_log_error,
                    c.knobs,
                    c.ns_per_eval,
                    c.fit_seconds,
                    if c.chosen { "**yes**" } else { "" }
                )
            }
        }
    }
    let routes = renderer_routes(s);
    if !routes.is_empty() {
        t += "\nRenderers' own materials (the best candidate of each, without the fuzz layer):\n";
        for r in routes {
            t += &format!("- {}\n", r.text);
        }
    }
    t
}
