//! The least-squares problem argmin sees: residuals (`Operator`) and their Jacobian (`Jacobian`)
//! as functions of the internal parameter vector theta.
//!
//! Separable mode (variable projection): theta holds only the shape parameters; for every theta
//! the albedos are solved exactly (bounded linear least squares, one small system per channel),
//! so the residual is that of the best albedos for the shape. The Jacobian is taken by forward
//! differences of that reduced residual, columns in parallel. Full mode: theta also holds the
//! albedo channels (needed for the `log` metric, which is not linear in them).

use super::config::Metric;
use super::parameters::{Component, Param, ParamSet, ShapeParam};
use crate::load::samples::Sample;
use crate::model::frame::FibreFrame;
use crate::model::topology::{Topology, TopologyMap};
use crate::model::{self, Basis, DirectionPair, ShadingModel};
use argmin::core::{Error as ArgminError, Jacobian, Operator};
use nalgebra::{DMatrix, DVector};
use rayon::prelude::*;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Arc;

mod albedo_solve;
mod argmin_problem;
mod coordinate;
mod rung_model;
#[cfg(test)]
mod tests;

pub(crate) use albedo_solve::*;
pub use argmin_problem::*;
pub use coordinate::*;
pub use rung_model::*;

/// Model columns per sample: [diffuse (+ substrate when tied), specular, substrate, fuzz].
pub type Columns = [f64; 4];

/// Per-sample values of recovered maps (`src/fit/maps.rs`), in the order of the problem's
/// samples: a texel height H (fibre radii) that replaces the topology (clamped to H_max of the
/// spacing being tried), and per-component albedos (indexed like [`Columns`]) that replace the
/// set's, whose parameter is then held fixed.
#[derive(Clone, Debug, Default)]
pub struct SampleMaps {
    pub height: Option<Vec<f64>>,
    /// Each sample's own lobe (roughness and anisotropy maps: [`ShadingModel::with_lobe`]).
    pub lobe: Option<Vec<crate::model::Lobe>>,
    pub albedo: [Option<Vec<[f64; 3]>>; 4],
}

pub struct FitProblem<'a> {
    pub samples: Vec<&'a Sample>,
    /// Recovered per-texel values, when fitting the globals given maps.
    pub sample_maps: Option<Arc<SampleMaps>>,
    pub template: ParamSet,
    pub metric: Metric,
    pub quadrature_order: usize,
    pub histogram_bins: usize,
    pub map: Option<Arc<TopologyMap>>,
    pub separable: bool,
    /// Nodes of the fibre-direction spread quadrature.
    pub azimuth_nodes: usize,
    /// Residual scale per sample and channel: 1/sigma or sqrt(weight), times cos(theta_i) for
    /// the cosine metric.
    scale: Vec<[f64; 3]>,
    /// The `log` metric's floor eps per channel ([`log_floor`]).
    log_floor: [f64; 3],
    free_shapes: Vec<usize>,
    free_albedos: Vec<(usize, usize)>,
    pub evaluations: AtomicUsize,
    /// The model's bases under the fuzz layer (everything but the layer) at the last point the
    /// optimiser evaluated ([`FitProblem::evaluate_keeping`]), keyed by the shape values the
    /// layer does not read: a Jacobian column of `fuzz_depth` or `fuzz_asymmetry` reuses them
    /// and applies only the layer (the same numbers, bit for bit, at a fraction of the cost).
    under_fuzz: std::sync::Mutex<Option<(Vec<u64>, Arc<Vec<Basis>>)>>,
}

/// The residual scale of sample `s` per channel in `metric`: 1/sigma or sqrt(weight), times
/// cos(theta_i) for the cosine metric.
pub fn residual_scale(metric: Metric, s: &Sample) -> [f64; 3] {
    std::array::from_fn(|c| {
        let base = match s.sigma {
            Some(sig) => 1.0 / sig[c],
            None => s.weight.sqrt(),
        };
        match metric {
            Metric::Cosine => base * s.l.z,
            _ => base,
        }
    })
}

/// The residual of the value `m` predicted for sample `s`, channel `c`, in `metric`:
/// `scale` (the channel's [`residual_scale`]) times m - y, or for the log metric
/// ln(m + eps) - ln(y + eps) (`eps` the channel's [`log_floor`]) weighted by sqrt(weight), or
/// divided by the log value's sigma (sigma / (y + eps)).
pub fn metric_residual(metric: Metric, scale: f64, eps: f64, s: &Sample, c: usize, m: f64) -> f64 {
    let y = s.value[c];
    match metric {
        Metric::Linear | Metric::Cosine => scale * (m - y),
        Metric::Log => {
            let k = match s.sigma {
                Some(sig) => (y.max(0.0) + eps) / sig[c],
                None => s.weight.sqrt(),
            };
            k * ((m.max(0.0) + eps).ln() - (y.max(0.0) + eps).ln())
        }
    }
}

pub fn component_index(c: Component) -> usize {
    match c {
        Component::Diffuse => 0,
        Component::Specular => 1,
        Component::Substrate => 2,
        Component::Fuzz => 3,
    }
}

/// The c in [lo, hi] minimising g(c) = S_yy - 2 c S_yA - 2 c^2 S_yQ + c^2 S_AA + 2 c^3 S_AQ
/// + c^4 S_QQ (the sums `m` = [S_yA, S_yQ, S_AA, S_AQ, S_QQ]; S_yy drops out): the best of 64
/// points, then Newton on g'(c) = 0 from it, kept when it lowers g within the bounds.
pub fn quartic_argmin(m: [f64; 5], lo: f64, hi: f64) -> f64 {
    let [ya, yq, aa, aq, qq] = m;
    let g = |c: f64| -2.0 * c * ya + c * c * (aa - 2.0 * yq) + 2.0 * c * c * c * aq + c.powi(4) * qq;
    let dg = |c: f64| -2.0 * ya + 2.0 * c * (aa - 2.0 * yq) + 6.0 * c * c * aq + 4.0 * c.powi(3) * qq;
    let ddg = |c: f64| 2.0 * (aa - 2.0 * yq) + 12.0 * c * aq + 12.0 * c * c * qq;
    let mut best = (0..=64)
        .map(|k| lo + (hi - lo) * k as f64 / 64.0)
        .min_by(|a, b| g(*a).total_cmp(&g(*b)))
        .unwrap_or(lo);
    for _ in 0..50 {
        let h = ddg(best);
        if !(h > 0.0) {
            break;
        }
        let next = (best - dg(best) / h).clamp(lo, hi);
        if !(g(next) <= g(best)) {
            break;
        }
        let done = (next - best).abs() <= 1e-15 * best.abs().max(1.0);
        best = next;
        if done {
            break;
        }
    }
    best
}

/// How a problem evaluates its model and residuals: the metric, the knobs, and whether the
/// albedos are solved for each shape (separable; never with the log metric).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Settings {
    pub metric: Metric,
    pub quadrature_order: usize,
    pub histogram_bins: usize,
    pub separable: bool,
}

impl Settings {
    /// The settings a fit configuration asks for.
    pub fn of(cfg: &super::config::FitConfig) -> Self {
        Self {
            metric: cfg.metric,
            quadrature_order: cfg.knobs.quadrature_order,
            histogram_bins: cfg.knobs.histogram_bins,
            separable: cfg.optimizer.separable,
        }
    }
}

impl<'a> FitProblem<'a> {
    /// The problem of `samples` with the parameters of `template` (their free ones fitted),
    /// evaluated as `settings` say, on the topology map `map` if any.
    pub fn new(
        samples: Vec<&'a Sample>,
        template: ParamSet,
        settings: Settings,
        map: Option<Arc<TopologyMap>>,
    ) -> Self {
        let Settings {
            metric,
            quadrature_order,
            histogram_bins,
            separable,
        } = settings;
        let separable = separable && metric != Metric::Log;
        let scale = samples.iter().map(|s| residual_scale(metric, s)).collect();
        let free_shapes = template.free_shapes();
        let free_albedos = template.free_albedos();
        let log_floor = if metric == Metric::Log {
            let values: Vec<[f64; 3]> = samples.iter().map(|s| s.value).collect();
            [0, 1, 2].map(|c| log_floor(&values, c))
        } else {
            [0.0; 3] // unused by the other metrics
        };
        Self {
            sample_maps: None,
            azimuth_nodes: crate::model::azimuth_spread::DEFAULT_AZIMUTH_NODES,
            log_floor,
            samples,
            template,
            metric,
            quadrature_order,
            histogram_bins,
            map,
            separable,
            scale,
            free_shapes,
            free_albedos,
            evaluations: AtomicUsize::new(0),
            under_fuzz: std::sync::Mutex::new(None),
        }
    }

    /// This problem with per-sample map values (one entry per sample).
    pub fn with_sample_maps(mut self, maps: Arc<SampleMaps>) -> Self {
        if let Some(h) = &maps.height {
            assert_eq!(h.len(), self.samples.len());
        }
        self.sample_maps = Some(maps);
        self
    }

    /// The albedo of component `k` (a [`Columns`] index) for sample `i`, channel `c`: the map's
    /// when the component is mapped, else `set_value`.
    fn albedo_at(&self, k: usize, i: usize, c: usize, set_value: f64) -> f64 {
        match self.sample_maps.as_ref().and_then(|m| m.albedo[k].as_ref()) {
            Some(v) => v[i][c],
            None => set_value,
        }
    }

    /// This problem with `n` nodes for the fibre-direction spread quadrature.
    pub fn with_azimuth_nodes(mut self, n: usize) -> Self {
        self.azimuth_nodes = n;
        self
    }

    /// This problem with the `log` metric's floors of another sample set (the full data, so a
    /// subsample's cost is the same function).
    pub fn with_log_floor_of(mut self, other: &FitProblem) -> Self {
        self.log_floor = other.log_floor;
        self
    }

    /// This problem with the `log` metric's floors `floor` per channel ([`log_floor`] of the
    /// full data, when this problem holds a piece of them).
    pub fn with_log_floor(mut self, floor: [f64; 3]) -> Self {
        self.log_floor = floor;
        self
    }

    /// Residual scale per sample and channel (1/sigma or sqrt(weight), times cos(theta_i) for
    /// the cosine metric).
    pub fn scale(&self) -> &[[f64; 3]] {
        &self.scale
    }

    pub fn channels(&self) -> usize {
        self.template.channels
    }

    pub fn residual_count(&self) -> usize {
        self.samples.len() * self.channels()
    }

    /// Number of entries of theta.
    pub fn dim(&self) -> usize {
        self.free_shapes.len()
            + if self.separable {
                0
            } else {
                self.free_albedos.len()
            }
    }

    /// Bounds of theta in the optimizer's coordinates (see [`Coordinate`]).
    pub fn bounds(&self) -> (DVector<f64>, DVector<f64>) {
        let mut lo = Vec::new();
        let mut hi = Vec::new();
        for &i in &self.free_shapes {
            let sh = &self.template.shapes[i];
            let (a, b) = coordinate(sh).bounds(sh);
            lo.push(a);
            hi.push(b);
        }
        if !self.separable {
            for &(i, _) in &self.free_albedos {
                lo.push(self.template.albedos[i].min);
                hi.push(self.template.albedos[i].max);
            }
        }
        (DVector::from_vec(lo), DVector::from_vec(hi))
    }

    /// The finite box a space-filling design covers: the bounds, with a periodic azimuth's
    /// one period [-90, 90).
    pub fn design_box(&self) -> (DVector<f64>, DVector<f64>) {
        let (mut lo, mut hi) = self.bounds();
        for k in 0..lo.len() {
            if !lo[k].is_finite() || !hi[k].is_finite() {
                lo[k] = -90.0;
                hi[k] = 90.0;
            }
        }
        (lo, hi)
    }

    /// Period of each theta entry (Some(180) for a periodic azimuth), for distances between
    /// candidates.
    pub fn periods(&self) -> Vec<Option<f64>> {
        let mut v: Vec<Option<f64>> = self
            .free_shapes
            .iter()
            .map(|&i| match coordinate(&self.template.shapes[i]) {
                Coordinate::Periodic => Some(180.0),
                _ => None,
            })
            .collect();
        if !self.separable {
            v.extend(self.free_albedos.iter().map(|_| None));
        }
        v
    }

    /// The theta entry of the spacing, if it is free.
    pub fn spacing_entry(&self) -> Option<usize> {
        self.free_shapes
            .iter()
            .position(|&i| self.template.shapes[i].kind == Param::Spacing)
    }

    /// Which theta entries describe the fibre geometry (spacing, height, map scale).
    pub fn geometric(&self) -> Vec<bool> {
        let mut v: Vec<bool> = self
            .free_shapes
            .iter()
            .map(|&i| {
                matches!(
                    self.template.shapes[i].kind,
                    Param::Spacing | Param::Height | Param::MapScale
                )
            })
            .collect();
        if !self.separable {
            v.extend(self.free_albedos.iter().map(|_| false));
        }
        v
    }

    /// theta of a parameter set.
    pub fn theta_of(&self, set: &ParamSet) -> DVector<f64> {
        let d = set.shape_value(Param::Spacing);
        let mut v: Vec<f64> = self
            .free_shapes
            .iter()
            .map(|&i| coordinate(&set.shapes[i]).from_value(&set.shapes[i], d))
            .collect();
        if !self.separable {
            v.extend(
                self.free_albedos
                    .iter()
                    .map(|&(i, c)| set.albedos[i].value[c]),
            );
        }
        DVector::from_vec(v)
    }

    /// The parameter set at theta (albedos as in `base` when separable). Every theta inside the
    /// bounds gives a valid set: heights and map scales within [min, min(max, H_max(d))] of the
    /// spacing d at theta, the azimuth wrapped into [-90, 90).
    pub fn set_at(&self, theta: &DVector<f64>, base: &ParamSet) -> ParamSet {
        let mut set = base.clone();
        // spacing first: the height coordinates are relative to H_max(d)
        for pass in [false, true] {
            for (k, &i) in self.free_shapes.iter().enumerate() {
                let c = coordinate(&set.shapes[i]);
                if matches!(c, Coordinate::UnderMaxHeight) == pass {
                    let d = set.shape_value(Param::Spacing);
                    let s = &mut set.shapes[i];
                    s.value = c.to_value(s, theta[k], d);
                }
            }
        }
        if !self.separable {
            let off = self.free_shapes.len();
            for (k, &(i, c)) in self.free_albedos.iter().enumerate() {
                if set.albedos[i].grey {
                    set.albedos[i].value = [theta[off + k]; 3];
                } else {
                    set.albedos[i].value[c] = theta[off + k];
                }
            }
        }
        set
    }

    /// Names of theta's entries.
    pub fn theta_names(&self) -> Vec<String> {
        let mut v: Vec<String> = self
            .free_shapes
            .iter()
            .map(|&i| {
                let s = &self.template.shapes[i];
                let n = s.kind.name();
                match coordinate(s) {
                    Coordinate::Log => format!("ln({n})"),
                    Coordinate::Reciprocal => format!("1/{n}"),
                    Coordinate::UnderMaxHeight => format!("{n} (fraction of its range)"),
                    _ => n.to_string(),
                }
            })
            .collect();
        if !self.separable {
            v.extend(
                self.free_albedos
                    .iter()
                    .map(|&(i, c)| albedo_label(&self.template, i, c)),
            );
        }
        v
    }

    /// Build the rung at the shape parameters of `set`.
    pub fn model_for(&self, set: &ParamSet) -> Box<dyn ShadingModel> {
        model_for(
            set,
            self.quadrature_order,
            self.histogram_bins,
            self.azimuth_nodes,
            self.map.clone(),
        )
    }

    /// Model columns of every sample at `set`'s shape parameters.
    pub fn columns(&self, set: &ParamSet) -> Result<Vec<Columns>, anyhow::Error> {
        self.columns_keeping(set, false)
    }

    /// [`FitProblem::columns`]; `keep`: remember the bases under the fuzz layer for the
    /// Jacobian columns of the layer's parameters at this point.
    fn columns_keeping(&self, set: &ParamSet, keep: bool) -> Result<Vec<Columns>, anyhow::Error> {
        self.evaluations.fetch_add(1, Ordering::Relaxed);
        let key: Vec<u64> = set
            .shapes
            .iter()
            .filter(|s| !matches!(s.kind, Param::FuzzDepth | Param::FuzzAsymmetry))
            .map(|s| s.value.to_bits())
            .collect();
        let cached = self
            .under_fuzz
            .lock()
            .expect("not poisoned")
            .as_ref()
            .filter(|(k, _)| *k == key)
            .map(|(_, b)| b.clone());
        let bases = match cached {
            Some(b) => b,
            None => {
                let b = Arc::new(self.bases_under_fuzz(set)?);
                if keep {
                    *self.under_fuzz.lock().expect("not poisoned") = Some((key, b.clone()));
                }
                b
            }
        };
        let psi = set.shape_value(Param::Azimuth).to_radians();
        let layer = model::fuzz::FuzzFactor::of(
            set.shape_value(Param::FuzzDepth),
            set.shape_value(Param::FuzzAsymmetry),
        );
        let tied = set.substrate_tied;
        let cols: Vec<Columns> = self
            .samples
            .par_iter()
            .zip(bases.par_iter())
            .map(|(s, b)| {
                let mut b = *b;
                if let Some(layer) = &layer {
                    // the layer as `FuzzLayer` applies it, at the pair the bases were made at
                    let frame = FibreFrame::from_azimuth(s.fibre_azimuth.unwrap_or(psi));
                    let pair = DirectionPair::new(&frame, &s.l, &s.v);
                    b = if pair.above_horizon() {
                        model::BasisTransform::apply(layer, &pair, b)
                    } else {
                        Basis::default()
                    };
                }
                if tied {
                    [b.diffuse + b.substrate, b.specular, 0.0, b.fuzz]
                } else {
                    [b.diffuse, b.specular, b.substrate, b.fuzz]
                }
            })
            .collect();
        if let Some(i) = cols.iter().position(|c| c.iter().any(|x| !x.is_finite())) {
            anyhow::bail!(
                "the model gave a non-finite value for sample {} ({:?}) at {}",
                i,
                self.samples[i].origin,
                describe(set)
            );
        }
        Ok(cols)
    }

    /// The bases of every sample at `set`'s shape parameters under the fuzz layer (the rung
    /// with its Fresnel factor and spread; the layer is applied by the caller).
    fn bases_under_fuzz(&self, set: &ParamSet) -> Result<Vec<Basis>, anyhow::Error> {
        let m = model_under_fuzz(
            set,
            self.quadrature_order,
            self.histogram_bins,
            self.azimuth_nodes,
            self.map.clone(),
        );
        let psi = set.shape_value(Param::Azimuth).to_radians();
        let d = set.shape_value(Param::Spacing);
        let topology = Topology {
            height: set.shape_value(Param::Height),
            map_scale: set.shape_value(Param::MapScale),
            map: None,
        };
        let has_topology = set.rung.has_topology();
        // Chunks of samples go through `basis_many` (the cross-section rungs batch their lobe
        // quadrature); samples with a topology texel are evaluated at their own height.
        let heights = self
            .sample_maps
            .as_ref()
            .and_then(|m| m.height.as_deref())
            .filter(|_| has_topology);
        let lobes = self.sample_maps.as_ref().and_then(|m| m.lobe.as_deref());
        let h_max = crate::model::topology::max_height(d);
        let index: Vec<usize> = (0..self.samples.len()).collect();
        let bases: Vec<Basis> = self
            .samples
            .par_chunks(512)
            .zip(index.par_chunks(512))
            .flat_map_iter(|(chunk, ids)| {
                let pairs: Vec<DirectionPair> = chunk
                    .iter()
                    .map(|s| {
                        let frame = FibreFrame::from_azimuth(s.fibre_azimuth.unwrap_or(psi));
                        DirectionPair::new(&frame, &s.l, &s.v)
                    })
                    .collect();
                let mut bases = vec![Basis::default(); chunk.len()];
                if let Some(ls) = lobes {
                    // each sample at its texel's lobe
                    for ((b, p), &i) in bases.iter_mut().zip(&pairs).zip(ids) {
                        *b = m
                            .with_lobe(ls[i])
                            .expect("checked by the maps' request: the rung has a lobe")
                            .basis(p);
                    }
                } else if let Some(hs) = heights {
                    let hts: Vec<f64> = ids.iter().map(|&i| hs[i].clamp(0.0, h_max)).collect();
                    model::bases_at_heights(m.as_ref(), &pairs, &hts, &mut bases);
                } else if has_topology
                    && chunk
                        .iter()
                        .any(|s| s.map_value.is_some() || s.texel_height.is_some())
                {
                    // samples with a texel at their texel's height, batched by height; the
                    // others (a spot over the whole map) through the model's topology
                    let hts: Vec<Option<f64>> = chunk
                        .iter()
                        .map(|s| match (s.texel_height, s.map_value) {
                            (Some(h), _) => Some(h.clamp(0.0, h_max)),
                            (None, Some(mv)) => Some(topology.texel_height(mv, d)),
                            _ => None,
                        })
                        .collect();
                    let (with, without): (Vec<usize>, Vec<usize>) =
                        (0..chunk.len()).partition(|&k| hts[k].is_some());
                    for (ks, at_height) in [(with, true), (without, false)] {
                        let sub: Vec<DirectionPair> = ks.iter().map(|&k| pairs[k]).collect();
                        let mut out = vec![Basis::default(); ks.len()];
                        if at_height {
                            let h: Vec<f64> =
                                ks.iter().map(|&k| hts[k].expect("partitioned")).collect();
                            model::bases_at_heights(m.as_ref(), &sub, &h, &mut out);
                        } else {
                            m.basis_many(&sub, &mut out);
                        }
                        for (&k, b) in ks.iter().zip(out) {
                            bases[k] = b;
                        }
                    }
                } else {
                    m.basis_many(&pairs, &mut bases);
                }
                bases
            })
            .collect();
        Ok(bases)
    }

    /// Solve the albedos exactly for fixed columns: bounded linear least squares per channel,
    /// or, with a grey albedo (one value shared by the channels, `AlbedoParam::grey`), the
    /// joint problem of all channels (`solve_with_shared`).
    pub fn solve_albedos(&self, cols: &[Columns], set: &mut ParamSet) {
        let m = set.albedos.len();
        let comp: Vec<usize> = set
            .albedos
            .iter()
            .map(|a| component_index(a.component))
            .collect();
        let free: Vec<usize> = (0..m).filter(|&a| set.albedos[a].vary).collect();
        let bounds: Vec<(f64, f64)> = free
            .iter()
            .map(|&a| (set.albedos[a].min, set.albedos[a].max))
            .collect();
        let ch = self.channels();
        // Gram matrix and right-hand side per channel, with fixed albedos moved to the data side
        let mut grams = [([[0.0f64; 4]; 4], [0.0f64; 4]); 3];
        for (c, (g, h)) in grams.iter_mut().enumerate().take(ch) {
            for (i, (s, (col, sc))) in self
                .samples
                .iter()
                .zip(cols.iter().zip(&self.scale))
                .enumerate()
            {
                let w2 = sc[c] * sc[c];
                let mut y = s.value[c];
                for (k, alb) in set.albedos.iter().enumerate() {
                    if !alb.vary {
                        y -= self.albedo_at(comp[k], i, c, alb.value[c]) * col[comp[k]];
                    }
                }
                for &a in &free {
                    h[a] += w2 * col[comp[a]] * y;
                    for &b in &free {
                        g[a][b] += w2 * col[comp[a]] * col[comp[b]];
                    }
                }
            }
        }
        let grey: Vec<usize> = (0..free.len())
            .filter(|&k| ch > 1 && set.albedos[free[k]].grey)
            .collect();
        let per_channel: Vec<Vec<f64>> = if grey.is_empty() {
            (0..ch)
                .map(|c| bounded_small_lsq(&grams[c].0, &grams[c].1, &free, &bounds))
                .collect()
        } else if grey.len() == free.len() {
            // every free albedo grey: one system, the channels' normal equations summed
            let (mut g, mut h) = ([[0.0f64; 4]; 4], [0.0f64; 4]);
            for (gc, hc) in &grams[..ch] {
                for a in 0..4 {
                    h[a] += hc[a];
                    for b in 0..4 {
                        g[a][b] += gc[a][b];
                    }
                }
            }
            vec![bounded_small_lsq(&g, &h, &free, &bounds); ch]
        } else {
            assert_eq!(
                grey.len(),
                1,
                "at most one grey albedo beside coloured ones (only ks has the choice)"
            );
            solve_with_shared(&grams[..ch], &free, &bounds, grey[0])
        };
        for (c, sol) in per_channel.iter().enumerate() {
            for (k, &a) in free.iter().enumerate() {
                set.albedos[a].value[c] = sol[k];
            }
        }
        // a grey albedo holds its one value in every channel, also for grey data's unused ones
        for a in set.albedos.iter_mut().filter(|a| a.grey && a.vary) {
            a.value = [a.value[0]; 3];
        }
        self.solve_threejs_base_colour(cols, set);
    }

    /// The `gltf` rung's `threejs` variant with metallic > 0: f = kd A + B + kd^2 Q
    /// (`model::rungs::gltf::threejs`), so the base colour's least squares is a quartic in kd
    /// per channel (grey: over every channel), g(c) = sum w (y - c A - c^2 Q)^2 with y the data
    /// less the fixed albedos' terms; minimised over its bounds exactly: the best of a grid of
    /// 64, then Newton on g' = 0, against the bounds. A no-op for every other set (Q = 0).
    fn solve_threejs_base_colour(&self, cols: &[Columns], set: &mut ParamSet) {
        use crate::model::rungs::gltf::GltfVariant;
        let (d, q) = (
            component_index(Component::Diffuse),
            component_index(Component::Substrate),
        );
        let Some(kd) = set
            .albedos
            .iter()
            .position(|a| a.component == Component::Diffuse && a.vary)
        else {
            return;
        };
        if set.gltf_variant != GltfVariant::Threejs
            || self.sample_maps.is_some()
            || cols.iter().all(|c| c[q] == 0.0)
        {
            return;
        }
        let ch = self.channels();
        // sums per channel: [yA, yQ, AA, AQ, QQ]
        let mut sums = [[0.0f64; 5]; 3];
        for (i, (s, (col, sc))) in self.samples.iter().zip(cols.iter().zip(&self.scale)).enumerate() {
            for (c, m) in sums.iter_mut().enumerate().take(ch) {
                let w = sc[c] * sc[c];
                let mut y = s.value[c];
                for (k, alb) in set.albedos.iter().enumerate() {
                    if k != kd {
                        y -= self.albedo_at(component_index(alb.component), i, c, alb.value[c])
                            * col[component_index(alb.component)];
                    }
                }
                let (a, qq) = (col[d], col[q]);
                for (j, v) in [y * a, y * qq, a * a, a * qq, qq * qq].into_iter().enumerate() {
                    m[j] += w * v;
                }
            }
        }
        let (lo, hi) = (set.albedos[kd].min, set.albedos[kd].max);
        let solve = |m: [f64; 5]| quartic_argmin(m, lo, hi);
        if set.albedos[kd].grey || ch == 1 {
            let mut total = [0.0; 5];
            for m in &sums[..ch] {
                for j in 0..5 {
                    total[j] += m[j];
                }
            }
            set.albedos[kd].value = [solve(total); 3];
        } else {
            for (c, m) in sums.iter().enumerate().take(ch) {
                set.albedos[kd].value[c] = solve(*m);
            }
        }
    }

    /// The `gltf` rung's `threejs` variant's term in the base colour squared, kd^2 times the
    /// substrate column (`model::rungs::gltf::threejs`), for sample `i`, channel `c`; 0 for
    /// every other set.
    fn base_colour_squared(&self, set: &ParamSet, i: usize, c: usize, col: &Columns) -> f64 {
        if set.gltf_variant != crate::model::rungs::gltf::GltfVariant::Threejs {
            return 0.0;
        }
        let k = component_index(Component::Diffuse);
        set.albedos
            .iter()
            .find(|a| a.component == Component::Diffuse)
            .map_or(0.0, |a| {
                let kd = self.albedo_at(k, i, c, a.value[c]);
                kd * kd * col[component_index(Component::Substrate)]
            })
    }

    /// d/d kd of [`FitProblem::base_colour_squared`] for albedo `ai`: 2 kd Q when `ai` is the
    /// threejs variant's base colour, else 0.
    fn base_colour_squared_slope(
        &self,
        set: &ParamSet,
        ai: usize,
        i: usize,
        c: usize,
        col: &Columns,
    ) -> f64 {
        let a = &set.albedos[ai];
        if set.gltf_variant != crate::model::rungs::gltf::GltfVariant::Threejs
            || a.component != Component::Diffuse
        {
            return 0.0;
        }
        let kd = self.albedo_at(component_index(Component::Diffuse), i, c, a.value[c]);
        2.0 * kd * col[component_index(Component::Substrate)]
    }

    /// Residual vector (sample-major, channel-minor) for columns and albedos.
    pub fn residuals(&self, cols: &[Columns], set: &ParamSet) -> DVector<f64> {
        let ch = self.channels();
        let comps: Vec<(usize, [f64; 3])> = set
            .albedos
            .iter()
            .map(|a| (component_index(a.component), a.value))
            .collect();
        let mut r = DVector::zeros(self.samples.len() * ch);
        for (i, (s, (col, sc))) in self
            .samples
            .iter()
            .zip(cols.iter().zip(&self.scale))
            .enumerate()
        {
            for c in 0..ch {
                let m: f64 = comps
                    .iter()
                    .map(|(k, a)| self.albedo_at(*k, i, c, a[c]) * col[*k])
                    .sum::<f64>()
                    + self.base_colour_squared(set, i, c, col);
                r[i * ch + c] = metric_residual(self.metric, sc[c], self.log_floor[c], s, c, m);
            }
        }
        r
    }

    /// Model values (unweighted) per sample and channel.
    pub fn model_values(&self, cols: &[Columns], set: &ParamSet) -> Vec<[f64; 3]> {
        cols.iter()
            .enumerate()
            .map(|(i, col)| {
                let mut v = [0.0; 3];
                for (c, vc) in v.iter_mut().enumerate().take(self.channels()) {
                    *vc = set
                        .albedos
                        .iter()
                        .map(|a| {
                            let k = component_index(a.component);
                            self.albedo_at(k, i, c, a.value[c]) * col[k]
                        })
                        .sum::<f64>()
                        + self.base_colour_squared(set, i, c, col);
                }
                v
            })
            .collect()
    }

    /// Residuals and the parameter set (albedos solved when separable) at theta.
    pub fn evaluate(
        &self,
        theta: &DVector<f64>,
        base: &ParamSet,
    ) -> Result<(DVector<f64>, ParamSet), anyhow::Error> {
        self.evaluate_keeping(theta, base, false)
    }

    /// [`FitProblem::evaluate`]; `keep`: a point the optimiser may take the Jacobian at next
    /// (its bases under the fuzz layer are kept for the layer's columns).
    pub fn evaluate_keeping(
        &self,
        theta: &DVector<f64>,
        base: &ParamSet,
        keep: bool,
    ) -> Result<(DVector<f64>, ParamSet), anyhow::Error> {
        let mut set = self.set_at(theta, base);
        let cols = self.columns_keeping(&set, keep)?;
        if self.separable {
            self.solve_albedos(&cols, &mut set);
        }
        let r = self.residuals(&cols, &set);
        if r.iter().any(|x| !x.is_finite()) {
            anyhow::bail!("a residual is not finite at {}", describe(&set));
        }
        Ok((r, set))
    }

    /// Forward-difference step for entry k of theta, pointing into the bounds.
    fn step(&self, theta: &DVector<f64>, k: usize, hi: &DVector<f64>) -> f64 {
        let h = 1e-6 * theta[k].abs().max(1.0);
        if theta[k] + h > hi[k] {
            -h
        } else {
            h
        }
    }

    /// The Jacobian of the full problem at `set` (shape columns at fixed albedos, albedo columns
    /// analytic), for standard errors. Column order: free shapes, then free albedo channels.
    pub fn full_jacobian(
        &self,
        set: &ParamSet,
        cols: &[Columns],
    ) -> Result<DMatrix<f64>, anyhow::Error> {
        let r0 = self.residuals(cols, set);
        let n = r0.len();
        let ch = self.channels();
        // derivatives in external units (ln for log-space parameters), stepping into the
        // valid range
        let shape_cols: Vec<DVector<f64>> = (0..self.free_shapes.len())
            .into_par_iter()
            .map(|k| {
                let (s2, h) = jacobian_step(set, self.free_shapes[k]);
                let c2 = self.columns(&s2)?;
                Ok((self.residuals(&c2, &s2) - &r0) / h)
            })
            .collect::<Result<_, anyhow::Error>>()?;
        let mut j = DMatrix::zeros(n, self.free_shapes.len() + self.free_albedos.len());
        for (k, col) in shape_cols.iter().enumerate() {
            j.set_column(k, col);
        }
        let off = self.free_shapes.len();
        let values = self.model_values(cols, set);
        for (k, &(ai, c0)) in self.free_albedos.iter().enumerate() {
            let comp = component_index(set.albedos[ai].component);
            // a grey albedo is one column over every channel's rows
            let channels = if set.albedos[ai].grey {
                0..ch
            } else {
                c0..c0 + 1
            };
            for (i, (s, col)) in self.samples.iter().zip(cols).enumerate() {
                for c in channels.clone() {
                    let sc = self.scale[i][c];
                    let col_c = col[comp] + self.base_colour_squared_slope(set, ai, i, c, col);
                    j[(i * ch + c, off + k)] = match self.metric {
                        Metric::Linear | Metric::Cosine => sc * col_c,
                        Metric::Log => {
                            let eps = self.log_floor[c];
                            let kk = match s.sigma {
                                Some(sig) => (s.value[c].max(0.0) + eps) / sig[c],
                                None => s.weight.sqrt(),
                            };
                            kk * col_c / (values[i][c].max(0.0) + eps)
                        }
                    };
                }
            }
        }
        Ok(j)
    }

    /// Labels of the full Jacobian's columns (external names).
    pub fn full_names(&self) -> Vec<String> {
        let mut v: Vec<String> = self
            .free_shapes
            .iter()
            .map(|&i| self.template.shapes[i].kind.name().to_string())
            .collect();
        v.extend(
            self.free_albedos
                .iter()
                .map(|&(i, c)| albedo_label(&self.template, i, c)),
        );
        v
    }

    pub fn free_shapes(&self) -> &[usize] {
        &self.free_shapes
    }

    pub fn free_albedos(&self) -> &[(usize, usize)] {
        &self.free_albedos
    }
}
