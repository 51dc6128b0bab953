//! Checks of a configuration that name the key: parameters of the rung, bounds, starts,
//! knobs and sections within their limits.

use super::*;

impl FitConfig {
    /// Checks that need no data: names, bounds, starts, knob ranges.
    pub fn validate(&self) -> Result<()> {
        if !self.model.is_auto() {
            return self.validate_rung();
        }
        // `auto`: each rung sees only its own parameters, so check the names against all rungs
        // here, or a misspelt one would be dropped silently
        let rungs: Vec<ModelId> = self
            .selection
            .rungs
            .iter()
            .map(|r| {
                r.parse()
                    .map_err(|e: String| anyhow!("selection.rungs: {e}"))
            })
            .collect::<Result<_>>()?;
        for name in self.parameters.keys() {
            if !rungs
                .iter()
                .any(|&r| r.parameter_names().contains(&name.as_str()))
            {
                let ids: Vec<&str> = rungs.iter().map(|r| r.as_str()).collect();
                bail!(
                    "parameters.{name}: not a parameter of any rung in selection.rungs ({})",
                    ids.join(", ")
                );
            }
        }
        for &r in &rungs {
            self.for_rung(r).validate_rung()?;
        }
        Ok(())
    }

    /// The rung's checks: every listed parameter ([`check_parameter`]), then the knobs and
    /// sections within their limits ([`FitConfig::check_limits`]).
    fn validate_rung(&self) -> Result<()> {
        let id = self.model_id()?;
        let allowed = id.parameter_names();
        for (name, e) in &self.parameters {
            check_parameter(id, &allowed, name, e)?;
        }
        self.check_limits()
    }

    /// Knobs, optimizer, components and selection within their limits.
    fn check_limits(&self) -> Result<()> {
        use crate::model::params::{MAX_HISTOGRAM_BINS, MAX_QUADRATURE_ORDER};
        if !(1..=MAX_QUADRATURE_ORDER).contains(&self.knobs.quadrature_order) {
            bail!(
                "knobs.quadrature_order = {} must lie in [1, {MAX_QUADRATURE_ORDER}]",
                self.knobs.quadrature_order
            );
        }
        if !(1..=MAX_HISTOGRAM_BINS).contains(&self.knobs.histogram_bins) {
            bail!(
                "knobs.histogram_bins = {} must lie in [1, {MAX_HISTOGRAM_BINS}]",
                self.knobs.histogram_bins
            );
        }
        let max_nodes = crate::model::azimuth_spread::MAX_AZIMUTH_NODES;
        if !(1..=max_nodes).contains(&self.knobs.azimuth_nodes) {
            bail!(
                "knobs.azimuth_nodes = {} must lie in [1, {max_nodes}]",
                self.knobs.azimuth_nodes
            );
        }
        let nodes = self.knobs.quadrature_order * self.knobs.azimuth_nodes;
        if nodes > MAX_NODES_PER_EVALUATION {
            bail!(
                "knobs.quadrature_order = {} x knobs.azimuth_nodes = {} = {nodes} quadrature nodes per model \
                 evaluation, {}x the default's: more than the {MAX_NODES_PER_EVALUATION} a fit may take \
                 (its time grows with the product); lower one of them",
                self.knobs.quadrature_order,
                self.knobs.azimuth_nodes,
                nodes / 256
            );
        }
        if let Some(c) = self.optimizer.global_candidates {
            if !(1..=MAX_GLOBAL_CANDIDATES).contains(&c) {
                bail!("optimizer.global_candidates = {c} must lie in [1, {MAX_GLOBAL_CANDIDATES}]");
            }
        }
        if !(1..=MAX_GLOBAL_SUBSAMPLE).contains(&self.optimizer.global_subsample) {
            bail!(
                "optimizer.global_subsample = {} must lie in [1, {MAX_GLOBAL_SUBSAMPLE}]",
                self.optimizer.global_subsample
            );
        }
        if self.starts > MAX_STARTS {
            bail!("starts = {} must lie in [1, {MAX_STARTS}]", self.starts);
        }
        if self.optimizer.max_iterations > MAX_ITERATIONS {
            bail!(
                "optimizer.max_iterations = {} must lie in [1, {MAX_ITERATIONS}]",
                self.optimizer.max_iterations
            );
        }
        if self.knobs.stride == 0 || !(self.knobs.fraction > 0.0 && self.knobs.fraction <= 1.0) {
            bail!("knobs.stride must be >= 1 and knobs.fraction in (0, 1]");
        }
        if let Some(sub) = &self.components.substrate {
            if !["tied", "free", "off"].contains(&sub.as_str()) {
                bail!("components.substrate = '{sub}': expected \"tied\", \"free\" or \"off\"");
            }
        }
        if !(2..=100).contains(&self.selection.folds) {
            bail!(
                "selection.folds = {} must lie in [2, 100]",
                self.selection.folds
            );
        }
        if self.selection.rank_samples < 10 {
            bail!(
                "selection.rank_samples = {} must be at least 10",
                self.selection.rank_samples
            );
        }
        if !(self.selection.holdout > 0.0 && self.selection.holdout < 1.0) {
            bail!(
                "selection.holdout = {} must lie in (0, 1)",
                self.selection.holdout
            );
        }
        for r in &self.selection.rungs {
            r.parse::<ModelId>()
                .map_err(|e| anyhow!("selection.rungs: {e}"))?;
        }
        if self.starts == 0 {
            bail!("starts must be at least 1");
        }
        if !(self.optimizer.tolerance > 0.0) || self.optimizer.max_iterations == 0 {
            bail!("optimizer.tolerance must be > 0 and optimizer.max_iterations >= 1");
        }
        Ok(())
    }
}

/// One `[parameters]` entry of rung `id` (whose parameters are `allowed`): a parameter of the
/// rung, a colour choice only for the specular weight, finite bounds in order and a finite
/// start within them.
fn check_parameter(id: ModelId, allowed: &[&str], name: &str, e: &ParamEntry) -> Result<()> {
    if !allowed.contains(&name) {
        bail!(
            "parameters.{name}: not a parameter of `{id}`; its parameters are {}",
            allowed.join(", ")
        );
    }
    if e.colour.is_some() && name != COLOUR_CHOICE.name() {
        bail!(
            "parameters.{name}.colour: only `{COLOUR_CHOICE}` has a colour choice (the \
                 albedos kd, substrate_albedo and fuzz are always fitted per channel: the dye's \
                 colour lives there; shape parameters have no colour)"
        );
    }
    // a fixed `ks` may be RGB (it is not fitted): a result's values read back, say
    if name == COLOUR_CHOICE.name() && e.colour != Some(true) && e.vary != Some(false) {
        if let Some(v) = e.value.filter(|v| v.is_rgb()) {
            bail!(
                "parameters.{name}.value = {:?}: an RGB start for a grey `{name}` (fitted as \
                     one value shared by the channels unless `colour = true`); give one number, \
                     or add `colour = true` to fit `{name}` per channel",
                v.channels()
            );
        }
    }
    if let (Some(lo), Some(hi)) = (e.min, e.max) {
        if !(lo <= hi) {
            bail!("parameters.{name}: min = {lo} is greater than max = {hi}");
        }
    }
    for (what, v) in [("min", e.min), ("max", e.max)] {
        if let Some(v) = v {
            if !v.is_finite() {
                bail!("parameters.{name}.{what} = {v} is not finite");
            }
        }
    }
    if let Some(v) = &e.value {
        for x in v.channels() {
            if !x.is_finite() {
                bail!("parameters.{name}.value = {x} is not finite");
            }
            if e.min.is_some_and(|lo| x < lo) || e.max.is_some_and(|hi| x > hi) {
                bail!(
                    "parameters.{name}.value = {x} is outside its bounds [{}, {}]",
                    e.min.map_or("-inf".into(), |v| v.to_string()),
                    e.max.map_or("inf".into(), |v| v.to_string())
                );
            }
        }
    }
    Ok(())
}
