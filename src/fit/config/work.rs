//! The work a configuration plans: model evaluations, scratch memory, and the limits that
//! refuse a fit before it starts.

use super::*;

/// Most quadrature nodes of one model evaluation (`quadrature_order` x `azimuth_nodes`): 2^16,
/// 256 times the default 16 x 16. Each knob alone may reach its own maximum (1024).
pub const MAX_NODES_PER_EVALUATION: usize = 1 << 16;

/// Most candidates of the global stage (`optimizer.global_candidates`).
pub const MAX_GLOBAL_CANDIDATES: usize = 100_000;

/// Most samples the global stage costs each candidate on (`optimizer.global_subsample`).
pub const MAX_GLOBAL_SUBSAMPLE: usize = 1_000_000;

/// Most polishing starts (`starts`).
pub const MAX_STARTS: usize = 1_000;

/// Most Levenberg-Marquardt iterations per start (`optimizer.max_iterations`).
pub const MAX_ITERATIONS: u64 = 100_000;

/// Most sample evaluations a fit may plan ([`FitConfig::check_work`]): 1e10, about 8 hours on
/// 2 cores at the rate of the shipped silk fit (5.4e5 planned in 1.5 s).
pub const MAX_PLANNED_EVALUATIONS: f64 = 1e10;

/// Samples a worker thread evaluates together (the fit's batches).
pub const EVALUATION_BATCH: usize = 512;

/// Scratch bytes per sample and histogram bin of a batch of varying-topology evaluations (four
/// fibre occlusion problems of twelve f64 each, their gap ends and arcs), rounded up.
pub const SCRATCH_PER_BIN: f64 = 1024.0;

/// Most scratch memory a fit's model evaluations may take per worker thread: 1 GiB.
pub const MAX_SCRATCH_BYTES: u64 = 1 << 30;

/// [`FitConfig::planned_scratch_bytes`] of one rung with `histogram_bins`, for `samples`
/// evaluated in batches (what `score` plans for a result's knobs).
pub fn scratch_bytes(rung: ModelId, histogram_bins: usize, samples: usize) -> f64 {
    if !rung.reads(Param::HistogramBins) {
        return 0.0;
    }
    samples.min(EVALUATION_BATCH) as f64 * histogram_bins as f64 * SCRATCH_PER_BIN
}

/// Refuse evaluating rung `rung` with `histogram_bins` on `samples` samples when its scratch
/// memory per thread ([`scratch_bytes`]) is beyond [`MAX_SCRATCH_BYTES`], with the estimate.
pub fn check_scratch(rung: ModelId, histogram_bins: usize, samples: usize) -> Result<()> {
    let bytes = scratch_bytes(rung, histogram_bins, samples);
    if bytes > MAX_SCRATCH_BYTES as f64 {
        bail!(
            "evaluating `{rung}` with histogram_bins = {histogram_bins} would take about {:.1} GiB \
             of memory per thread ({} samples a batch x {histogram_bins} x {SCRATCH_PER_BIN} bytes): \
             more than the {} GiB allowed per thread",
            bytes / (1u64 << 30) as f64,
            samples.min(EVALUATION_BATCH),
            MAX_SCRATCH_BYTES >> 30
        );
    }
    Ok(())
}

/// Candidates of the global stage when the config does not say: 32 plus 24 per free shape
/// parameter.
pub fn default_candidates(dim: usize) -> usize {
    32 + 24 * dim
}

impl FitConfig {
    /// The work a fit of `samples` samples plans at most, in sample evaluations at the default
    /// quadrature: per rung tried, the global stage (candidates x subsample), the polishing of
    /// every start (starts x iterations x subsample) and the final run on all samples
    /// (iterations x samples), scaled by the quadrature nodes per evaluation over the default's.
    pub fn planned_evaluations(&self, samples: usize) -> f64 {
        let n = samples as f64;
        let sub = (self.optimizer.global_subsample as f64).min(n);
        let candidates = self
            .optimizer
            .global_candidates
            .unwrap_or_else(|| default_candidates(8)) as f64;
        let iterations = self.optimizer.max_iterations as f64;
        if let ModelChoice::Rung(id) = self.model {
            return (candidates * sub + self.starts as f64 * iterations * sub + iterations * n)
                * self.cost_per_evaluation(Some(id));
        }
        // auto: per candidate (each rung, with and without the fuzz layer) a fit on the ranking
        // samples and a warm-started refit per fold, plus the chosen one's fit on all samples
        // (the costliest rung's, as any may be chosen)
        let per_rung = if self.selection.fuzz { 2.0 } else { 1.0 };
        let rungs = self.auto_rungs();
        let tried: f64 = match rungs.is_empty() {
            true => self.cost_per_evaluation(None),
            false => rungs
                .iter()
                .map(|&r| self.cost_per_evaluation(Some(r)))
                .sum(),
        } * per_rung;
        let costliest = rungs
            .iter()
            .map(|&r| self.cost_per_evaluation(Some(r)))
            .fold(self.cost_per_evaluation(None), f64::max);
        let rank = n.min(self.selection.rank_samples as f64);
        let folds = self.selection.folds as f64;
        tried
            * (candidates * sub
                + self.starts as f64 * iterations * sub
                + iterations * rank
                + folds * iterations * rank)
            + (candidates * sub + self.starts as f64 * iterations * sub + iterations * n)
                * costliest
    }

    /// Whether the rung, or a rung `auto` tries, integrates over a height histogram.
    fn histogram_rungs(&self) -> bool {
        let rungs = match self.model {
            ModelChoice::Auto => self.auto_rungs(),
            ModelChoice::Rung(id) => vec![id],
        };
        rungs.iter().any(|&r| r.reads(Param::HistogramBins))
    }

    /// The rungs an `auto` fit tries (those of `selection.rungs` that parse).
    fn auto_rungs(&self) -> Vec<ModelId> {
        self.selection
            .rungs
            .iter()
            .filter_map(|r| r.parse().ok())
            .collect()
    }

    /// The cost of one sample evaluation of rung `id` (`None`: one that reads no histogram)
    /// over the default's: the quadrature nodes (`quadrature_order` x `azimuth_nodes`), times
    /// `histogram_bins` / 16 for a rung that integrates over a height histogram; at least 1.
    fn cost_per_evaluation(&self, id: Option<ModelId>) -> f64 {
        let nodes = (self.knobs.quadrature_order * self.knobs.azimuth_nodes) as f64 / 256.0;
        let bins = match id {
            Some(id) if id.reads(Param::HistogramBins) => self.knobs.histogram_bins as f64 / 16.0,
            _ => 1.0,
        };
        (nodes * bins.max(1.0)).max(1.0)
    }

    /// The scratch memory one worker thread's model evaluations take at most, in bytes, for a
    /// fit of `samples` samples: a rung that integrates over a height histogram (the varying
    /// topology) solves, per batch of up to `EVALUATION_BATCH` samples, every fibre of every
    /// bin at once, `SCRATCH_PER_BIN` bytes per sample and bin; other rungs take little.
    pub fn planned_scratch_bytes(&self, samples: usize) -> f64 {
        if !self.histogram_rungs() {
            return 0.0;
        }
        samples.min(EVALUATION_BATCH) as f64 * self.knobs.histogram_bins as f64 * SCRATCH_PER_BIN
    }

    /// Refuse, before the fit (and before any allocation), a plan beyond
    /// `MAX_PLANNED_EVALUATIONS` or `MAX_SCRATCH_BYTES`, with the estimate; for a named
    /// rung and for `auto` (every rung it tries) alike.
    pub fn check_work(&self, samples: usize) -> Result<()> {
        let planned = self.planned_evaluations(samples);
        if planned > MAX_PLANNED_EVALUATIONS {
            bail!(
                "this fit plans up to {planned:.2e} sample evaluations ({samples} samples; starts = {}, \
                 optimizer.max_iterations = {}, global_candidates = {}, global_subsample = {}, \
                 quadrature_order x azimuth_nodes = {}{}{}): more than the {MAX_PLANNED_EVALUATIONS:.0e} \
                 a fit may take (about 8 hours on 2 cores); lower them or subsample the data",
                self.starts,
                self.optimizer.max_iterations,
                self.optimizer
                    .global_candidates
                    .map_or("default".to_string(), |c| c.to_string()),
                self.optimizer.global_subsample,
                self.knobs.quadrature_order * self.knobs.azimuth_nodes,
                if self.model.is_auto() {
                    format!(", {} rungs tried", self.selection.rungs.len())
                } else {
                    String::new()
                },
                if self.histogram_rungs() {
                    format!(", histogram_bins = {}", self.knobs.histogram_bins)
                } else {
                    String::new()
                }
            );
        }
        let scratch = self.planned_scratch_bytes(samples);
        if scratch > MAX_SCRATCH_BYTES as f64 {
            bail!(
                "this fit's model evaluations would take about {:.1} GiB of memory per thread \
                 ({} samples a batch x knobs.histogram_bins = {} x {SCRATCH_PER_BIN} bytes{}): more \
                 than the {} GiB a fit may take per thread; lower knobs.histogram_bins",
                scratch / (1u64 << 30) as f64,
                samples.min(EVALUATION_BATCH),
                self.knobs.histogram_bins,
                if self.model.is_auto() {
                    " for the varying-topology candidate"
                } else {
                    ""
                },
                MAX_SCRATCH_BYTES >> 30
            );
        }
        Ok(())
    }
}
