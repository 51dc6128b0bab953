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

/// Model columns per sample: [diffuse (+ substrate when tied), specular, substrate, fuzz].
pub type Columns = [f64; 4];

/// Per-sample values of recovered maps (`src/fit/maps.rs`), in the order of the problem's
/// samples: a texel height H (fibre radii) that replaces the topology (clamped to H_max of the
/// spacing being tried), and per-component albedos (indexed like [`Columns`]) that replace the
/// set's, whose parameter is then held fixed.
#[derive(Clone, Debug, Default)]
pub struct SampleMaps {
    pub height: Option<Vec<f64>>,
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
}

pub fn component_index(c: Component) -> usize {
    match c {
        Component::Diffuse => 0,
        Component::Specular => 1,
        Component::Substrate => 2,
        Component::Fuzz => 3,
    }
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
        let scale = samples
            .iter()
            .map(|s| {
                let mut k = [0.0; 3];
                for (c, kc) in k.iter_mut().enumerate() {
                    let base = match s.sigma {
                        Some(sig) => 1.0 / sig[c],
                        None => s.weight.sqrt(),
                    };
                    *kc = if metric == Metric::Cosine {
                        base * s.l.z
                    } else {
                        base
                    };
                }
                k
            })
            .collect();
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
        self.evaluations.fetch_add(1, Ordering::Relaxed);
        let m = self.model_for(set);
        let psi = set.shape_value(Param::Azimuth).to_radians();
        let d = set.shape_value(Param::Spacing);
        let topology = Topology {
            height: set.shape_value(Param::Height),
            map_scale: set.shape_value(Param::MapScale),
            map: None,
        };
        let has_topology = set.rung.has_topology();
        let tied = set.substrate_tied;
        // Chunks of samples go through `basis_many` (the cross-section rungs batch their lobe
        // quadrature); samples with a topology texel are evaluated at their own height.
        let heights = self
            .sample_maps
            .as_ref()
            .and_then(|m| m.height.as_deref())
            .filter(|_| has_topology);
        let h_max = crate::model::topology::max_height(d);
        let index: Vec<usize> = (0..self.samples.len()).collect();
        let cols: Vec<Columns> = self
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
                if let Some(hs) = heights {
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
                bases.into_iter().map(move |b| {
                    if tied {
                        [b.diffuse + b.substrate, b.specular, 0.0, b.fuzz]
                    } else {
                        [b.diffuse, b.specular, b.substrate, b.fuzz]
                    }
                })
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
                    .sum();
                let y = s.value[c];
                r[i * ch + c] = match self.metric {
                    Metric::Linear | Metric::Cosine => sc[c] * (m - y),
                    Metric::Log => {
                        let eps = self.log_floor[c];
                        let k = match s.sigma {
                            Some(sig) => (y.max(0.0) + eps) / sig[c],
                            None => s.weight.sqrt(),
                        };
                        k * ((m.max(0.0) + eps).ln() - (y.max(0.0) + eps).ln())
                    }
                };
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
                        .sum();
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
        let mut set = self.set_at(theta, base);
        let cols = self.columns(&set)?;
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
                    j[(i * ch + c, off + k)] = match self.metric {
                        Metric::Linear | Metric::Cosine => sc * col[comp],
                        Metric::Log => {
                            let eps = self.log_floor[c];
                            let kk = match s.sigma {
                                Some(sig) => (s.value[c].max(0.0) + eps) / sig[c],
                                None => s.weight.sqrt(),
                            };
                            kk * col[comp] / (values[i][c].max(0.0) + eps)
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

/// The forward-difference step of shape `index` of `set` for a Jacobian column, in the
/// optimizer's coordinates (internal units, ln for log-space parameters), stepping into the
/// valid range: the set with that shape moved by the step, and the step.
pub fn jacobian_step(set: &ParamSet, index: usize) -> (ParamSet, f64) {
    let d = set.shape_value(Param::Spacing);
    let sh = &set.shapes[index];
    let x = sh.kind.to_internal(sh.value);
    let top = match coordinate(sh) {
        Coordinate::Periodic => f64::INFINITY,
        Coordinate::UnderMaxHeight => height_range(sh, d).1,
        _ => sh.kind.to_internal(sh.max),
    };
    let h = 1e-6 * x.abs().max(1.0);
    let h = if x + h > top { -h } else { h };
    let mut s2 = set.clone();
    let sh = &mut s2.shapes[index];
    sh.value = sh.kind.to_external(x + h);
    (s2, h)
}

/// How a shape parameter appears to the optimizer, so that every point it can reach is a valid
/// model: the exponent and Ward's roughness in log space; the spacing as its reciprocal 1/d (the
/// optics change like the covered fraction 2/d, so a design uniform in 1/d samples touching and
/// nearly touching fibres as densely as wide gaps); the fibre azimuth periodic (period 180
/// degrees, unbounded, wrapped) when its bounds span the whole period; height and map scale as a
/// fraction u in [0, 1] of [min, min(max, H_max(d))] at the current spacing d, so that they never
/// exceed H_max(d) = sqrt(d^2 - 1); everything else linear within its bounds.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Coordinate {
    Linear,
    Log,
    Reciprocal,
    Periodic,
    UnderMaxHeight,
}

pub fn coordinate(s: &ShapeParam) -> Coordinate {
    use crate::model::parameter::Scale;
    match s.kind.info().scale {
        Scale::Log => Coordinate::Log,
        Scale::Periodic(period) if s.max - s.min >= period - 1e-9 => Coordinate::Periodic,
        Scale::UnderMaxHeight => Coordinate::UnderMaxHeight,
        Scale::Reciprocal => Coordinate::Reciprocal,
        Scale::Linear | Scale::Periodic(_) => Coordinate::Linear,
    }
}

/// [min, top] of a height-like parameter at spacing d: top = min(max, H_max(d)), never below min
/// unless H_max(d) itself is.
pub fn height_range(s: &ShapeParam, d: f64) -> (f64, f64) {
    let h_max = crate::model::topology::max_height(d);
    let top = s.max.min(h_max);
    (s.min.min(top), top)
}

impl Coordinate {
    /// Bounds of the coordinate of `s`.
    pub fn bounds(self, s: &ShapeParam) -> (f64, f64) {
        match self {
            Coordinate::Linear => (s.min, s.max),
            Coordinate::Log => (s.min.ln(), s.max.ln()),
            Coordinate::Reciprocal => (1.0 / s.max, 1.0 / s.min),
            Coordinate::Periodic => (f64::NEG_INFINITY, f64::INFINITY),
            Coordinate::UnderMaxHeight => (0.0, 1.0),
        }
    }

    /// The coordinate of `s`'s value at spacing d.
    pub fn from_value(self, s: &ShapeParam, d: f64) -> f64 {
        match self {
            Coordinate::Linear | Coordinate::Periodic => s.value,
            Coordinate::Log => s.value.ln(),
            Coordinate::Reciprocal => 1.0 / s.value,
            Coordinate::UnderMaxHeight => {
                let (lo, top) = height_range(s, d);
                if top > lo {
                    ((s.value - lo) / (top - lo)).clamp(0.0, 1.0)
                } else {
                    0.0
                }
            }
        }
    }

    /// The value of `s` at coordinate x and spacing d: always inside the valid range.
    pub fn to_value(self, s: &ShapeParam, x: f64, d: f64) -> f64 {
        match self {
            Coordinate::Linear => x.clamp(s.min, s.max),
            Coordinate::Log => x.exp().clamp(s.min, s.max),
            Coordinate::Reciprocal => (1.0 / x).clamp(s.min, s.max),
            Coordinate::Periodic => super::wrap_azimuth(x),
            Coordinate::UnderMaxHeight => {
                let (lo, top) = height_range(s, d);
                (lo + x.clamp(0.0, 1.0) * (top - lo)).min(top)
            }
        }
    }
}

/// The `log` metric's floor for channel `c`: 1 % of the median |value| (at least 1e-12), so
/// ln(f + eps) weighs relative errors alike over the data's range while values near zero (noise)
/// do not dominate.
pub fn log_floor(values: &[[f64; 3]], c: usize) -> f64 {
    log_floor_of_magnitudes(values.iter().map(|x| x[c].abs()).collect())
}

/// [`log_floor`] of one channel's |values| (any order).
pub fn log_floor_of_magnitudes(mut v: Vec<f64>) -> f64 {
    if v.is_empty() {
        return 1e-12;
    }
    let mid = v.len() / 2;
    let (_, median, _) = v.select_nth_unstable_by(mid, f64::total_cmp);
    (0.01 * *median).max(1e-12)
}

/// Build the rung at the shape parameters of `set` with the given knobs.
pub fn model_for(
    set: &ParamSet,
    quadrature_order: usize,
    histogram_bins: usize,
    azimuth_nodes: usize,
    map: Option<Arc<TopologyMap>>,
) -> Box<dyn ShadingModel> {
    model::with_fuzz(
        model::with_spread(
            model::with_fresnel(
                aligned_model_for(set, quadrature_order, histogram_bins, map),
                set.shape_value(Param::FresnelIor),
            ),
            set.shape_value(Param::AzimuthSpread),
            azimuth_nodes,
            set.shape_value(Param::Azimuth).to_radians(),
        ),
        set.shape_value(Param::FuzzDepth),
        set.shape_value(Param::FuzzAsymmetry),
    )
}

fn aligned_model_for(
    set: &ParamSet,
    quadrature_order: usize,
    histogram_bins: usize,
    map: Option<Arc<TopologyMap>>,
) -> Box<dyn ShadingModel> {
    let topology = Topology {
        height: set.shape_value(Param::Height),
        map_scale: set.shape_value(Param::MapScale),
        map,
    };
    (set.rung.rung().build)(&model::AlignedInputs {
        exponent: set.shape_value(Param::Exponent),
        spacing: set.shape_value(Param::Spacing),
        alpha_x: set.shape_value(Param::AlphaX),
        alpha_y: set.shape_value(Param::AlphaY),
        quadrature_order,
        histogram_bins,
        topology: &topology,
    })
}

/// The albedos of `set` as the model takes them (a tied substrate shares kd).
pub fn albedos_of(set: &ParamSet) -> model::Albedos {
    let mut a = model::Albedos::grey(0.0, 0.0, 0.0);
    a.rgb = set.channels == 3;
    for p in &set.albedos {
        match p.component {
            Component::Diffuse => {
                a.diffuse = p.value;
                if set.substrate_tied {
                    a.substrate = p.value;
                }
            }
            Component::Specular => a.specular = p.value,
            Component::Substrate => a.substrate = p.value,
            Component::Fuzz => a.fuzz = p.value,
        }
    }
    a
}

pub fn albedo_label(set: &ParamSet, i: usize, c: usize) -> String {
    if set.channels == 1 || set.albedos[i].grey {
        set.albedos[i].name.to_string()
    } else {
        format!("{}[{}]", set.albedos[i].name, ["r", "g", "b"][c])
    }
}

/// "name = value, ..." of a parameter set, for error messages.
pub fn describe(set: &ParamSet) -> String {
    let mut parts: Vec<String> = set
        .shapes
        .iter()
        .map(|s| format!("{} = {}", s.kind.name(), s.value))
        .collect();
    for a in &set.albedos {
        parts.push(format!("{} = {:?}", a.name, &a.value[..set.channels]));
    }
    parts.join(", ")
}

/// The albedos of every channel when one of them, `free[shared]`, is a single value for all
/// channels (a grey `ks` beside per-channel `kd`): min over s and a_c of
/// sum_c [a_c s]^T G_c [a_c s] - 2 [a_c s]^T h_c, all within bounds. For a fixed s each channel's
/// a_c is a small bounded problem ([`bounded_small_lsq`] with s moved to the data side); the cost
/// F(s) minimised over them is convex, with derivative (envelope theorem)
/// F'(s) = 2 sum_c (G_c[s,s] s - h_c[s] + G_c[s,.] a_c(s)), nondecreasing, so s is the root of F'
/// in its bounds (or the bound where F' does not change sign), found by bisection and made exact
/// by one secant step on the linear piece where both ends share the channels' active sets.
/// Returns per channel the values of `free`, in its order (the shared one equal in all).
pub(crate) fn solve_with_shared(
    grams: &[([[f64; 4]; 4], [f64; 4])],
    free: &[usize],
    bounds: &[(f64, f64)],
    shared: usize,
) -> Vec<Vec<f64>> {
    let sk = free[shared];
    let others: Vec<usize> = (0..free.len()).filter(|&k| k != shared).collect();
    let other_free: Vec<usize> = others.iter().map(|&k| free[k]).collect();
    let other_bounds: Vec<(f64, f64)> = others.iter().map(|&k| bounds[k]).collect();
    // the other albedos of every channel at s, and F'(s) / 2
    let inner = |s: f64| -> (Vec<Vec<f64>>, f64) {
        let mut d = 0.0;
        let sols = grams
            .iter()
            .map(|(g, h)| {
                let mut h2 = *h;
                for &a in &other_free {
                    h2[a] -= g[a][sk] * s;
                }
                let sol = bounded_small_lsq(g, &h2, &other_free, &other_bounds);
                d += g[sk][sk] * s - h[sk];
                for (k, &a) in other_free.iter().enumerate() {
                    d += g[sk][a] * sol[k];
                }
                sol
            })
            .collect();
        (sols, d)
    };
    let active = |sols: &[Vec<f64>]| -> Vec<Vec<i8>> {
        sols.iter()
            .map(|sol| {
                sol.iter()
                    .zip(&other_bounds)
                    .map(|(&v, &(lo, hi))| {
                        if v <= lo {
                            -1
                        } else if v >= hi {
                            1
                        } else {
                            0
                        }
                    })
                    .collect()
            })
            .collect()
    };
    let (lo, hi) = bounds[shared];
    let (sol_lo, d_lo) = inner(lo);
    let s = if d_lo >= 0.0 {
        lo
    } else {
        let (sol_hi, d_hi) = inner(hi);
        if d_hi <= 0.0 {
            hi
        } else {
            let (mut a, mut b) = (lo, hi);
            let (mut da, mut db) = (d_lo, d_hi);
            let (mut act_a, mut act_b) = (active(&sol_lo), active(&sol_hi));
            let mut root = None;
            for _ in 0..200 {
                // F' is linear between a and b when both share the active sets (and the point
                // the secant gives does too): its root, exactly; else bisect
                let m = if act_a == act_b {
                    (a - da * (b - a) / (db - da)).clamp(a, b)
                } else {
                    0.5 * (a + b)
                };
                if !(m > a && m < b) {
                    break; // the bracket is as narrow as f64 allows
                }
                let (sol_m, dm) = inner(m);
                if act_a == act_b && active(&sol_m) == act_a {
                    root = Some(m);
                    break;
                }
                if dm == 0.0 {
                    root = Some(m);
                    break;
                }
                if dm < 0.0 {
                    (a, da, act_a) = (m, dm, active(&sol_m));
                } else {
                    (b, db, act_b) = (m, dm, active(&sol_m));
                }
            }
            root.unwrap_or(0.5 * (a + b))
        }
    };
    let (sols, _) = inner(s);
    sols.into_iter()
        .map(|sol| {
            let mut out = vec![0.0; free.len()];
            out[shared] = s;
            for (k, &o) in others.iter().enumerate() {
                out[o] = sol[k];
            }
            out
        })
        .collect()
}

/// min over a of a^T G a - 2 a^T h with a_k in bounds, for the `free` indices (at most 3):
/// every assignment of each variable to {free, lower, upper} is tried and the best feasible kept.
pub(crate) fn bounded_small_lsq(
    g: &[[f64; 4]; 4],
    h: &[f64; 4],
    free: &[usize],
    bounds: &[(f64, f64)],
) -> Vec<f64> {
    let m = free.len();
    if m == 0 {
        return vec![];
    }
    let objective = |a: &[f64]| -> f64 {
        let mut v = 0.0;
        for i in 0..m {
            v -= 2.0 * a[i] * h[free[i]];
            for j in 0..m {
                v += a[i] * a[j] * g[free[i]][free[j]];
            }
        }
        v
    };
    let mut best: Option<(f64, Vec<f64>)> = None;
    for code in 0..3usize.pow(m as u32) {
        let mut state = [0usize; 4];
        let mut x = code;
        for s in state.iter_mut().take(m) {
            *s = x % 3;
            x /= 3;
        }
        let mut a = vec![0.0; m];
        let open: Vec<usize> = (0..m).filter(|&i| state[i] == 0).collect();
        for i in 0..m {
            a[i] = match state[i] {
                1 => bounds[i].0,
                2 => bounds[i].1,
                _ => 0.0,
            };
        }
        if !open.is_empty() {
            let k = open.len();
            let mut mat = DMatrix::zeros(k, k);
            let mut rhs = DVector::zeros(k);
            for (p, &i) in open.iter().enumerate() {
                rhs[p] = h[free[i]];
                for (q, &j) in open.iter().enumerate() {
                    mat[(p, q)] = g[free[i]][free[j]];
                }
                for j in 0..m {
                    if state[j] != 0 {
                        rhs[p] -= g[free[i]][free[j]] * a[j];
                    }
                }
            }
            let Some(sol) = mat.lu().solve(&rhs) else {
                continue;
            };
            let mut feasible = true;
            for (p, &i) in open.iter().enumerate() {
                let v = sol[p];
                if !v.is_finite() || v < bounds[i].0 - 1e-12 || v > bounds[i].1 + 1e-12 {
                    feasible = false;
                }
                a[i] = v.clamp(bounds[i].0, bounds[i].1);
            }
            if !feasible {
                continue;
            }
        }
        let f = objective(&a);
        if best.as_ref().is_none_or(|(bf, _)| f < *bf) {
            best = Some((f, a));
        }
    }
    best.map(|b| b.1)
        .unwrap_or_else(|| bounds.iter().map(|b| b.0).collect())
}

/// argmin's view: theta -> residuals, with the template's fixed values.
pub struct ArgminProblem<'p, 'a> {
    pub inner: &'p FitProblem<'a>,
    pub base: ParamSet,
    /// The last (theta, residuals), so the Jacobian does not evaluate the base point again.
    last: std::sync::Mutex<Option<(DVector<f64>, DVector<f64>)>>,
}

impl<'p, 'a> ArgminProblem<'p, 'a> {
    pub fn new(inner: &'p FitProblem<'a>, base: ParamSet) -> Self {
        Self {
            inner,
            base,
            last: std::sync::Mutex::new(None),
        }
    }

    fn residuals_at(&self, theta: &DVector<f64>) -> Result<DVector<f64>, anyhow::Error> {
        if let Some((t, r)) = self.last.lock().expect("not poisoned").as_ref() {
            if t == theta {
                return Ok(r.clone());
            }
        }
        let r = self.inner.evaluate(theta, &self.base)?.0;
        *self.last.lock().expect("not poisoned") = Some((theta.clone(), r.clone()));
        Ok(r)
    }
}

impl Operator for ArgminProblem<'_, '_> {
    type Param = DVector<f64>;
    type Output = DVector<f64>;

    fn apply(&self, theta: &Self::Param) -> Result<Self::Output, ArgminError> {
        self.residuals_at(theta)
    }
}

impl Jacobian for ArgminProblem<'_, '_> {
    type Param = DVector<f64>;
    type Jacobian = DMatrix<f64>;

    /// Forward differences of the (reduced) residual, columns in parallel.
    fn jacobian(&self, theta: &Self::Param) -> Result<Self::Jacobian, ArgminError> {
        let r0 = self.residuals_at(theta)?;
        let (_, hi) = self.inner.bounds();
        let cols: Vec<DVector<f64>> = (0..theta.len())
            .into_par_iter()
            .map(|k| {
                let h = self.inner.step(theta, k, &hi);
                let mut t = theta.clone();
                t[k] += h;
                let (r, _) = self.inner.evaluate(&t, &self.base)?;
                Ok((r - &r0) / h)
            })
            .collect::<Result<_, anyhow::Error>>()?;
        let mut j = DMatrix::zeros(r0.len(), theta.len());
        for (k, c) in cols.iter().enumerate() {
            j.set_column(k, c);
        }
        Ok(j)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_log_floor_is_relative_to_the_data() {
        let v: Vec<[f64; 3]> = (1..=101).map(|k| [k as f64 * 0.01, 5.0, 0.0]).collect();
        // median 0.51 -> 1 % of it; a constant channel; an all-zero channel keeps a tiny floor
        assert!((log_floor(&v, 0) - 0.0051).abs() < 1e-15);
        assert!((log_floor(&v, 1) - 0.05).abs() < 1e-15);
        assert_eq!(log_floor(&v, 2), 1e-12);
        // scaling the data scales the floor: the metric is relative
        let w: Vec<[f64; 3]> = v.iter().map(|x| [1e3 * x[0], 0.0, 0.0]).collect();
        assert!((log_floor(&w, 0) / log_floor(&v, 0) - 1e3).abs() < 1e-9);
    }

    #[test]
    fn bounded_lsq_matches_unconstrained_inside_and_clips_outside() {
        // G = I, h = (0.3, 0.7): unconstrained a = h
        let mut g = [[0.0; 4]; 4];
        (0..4).for_each(|i| g[i][i] = 1.0);
        let a = bounded_small_lsq(
            &g,
            &[0.3, 0.7, 0.0, 0.0],
            &[0, 1],
            &[(0.0, 1.0), (0.0, 1.0)],
        );
        assert!((a[0] - 0.3).abs() < 1e-15 && (a[1] - 0.7).abs() < 1e-15);
        let a = bounded_small_lsq(
            &g,
            &[-0.3, 1.7, 0.0, 0.0],
            &[0, 1],
            &[(0.0, 1.0), (0.0, 1.0)],
        );
        assert_eq!(a, vec![0.0, 1.0]);
        // correlated columns: optimum with one at its bound re-solves the other
        let g = [
            [2.0, 1.0, 0.0, 0.0],
            [1.0, 2.0, 0.0, 0.0],
            [0.0, 0.0, 1.0, 0.0],
            [0.0, 0.0, 0.0, 1.0],
        ];
        let a = bounded_small_lsq(
            &g,
            &[2.0, -1.0, 0.0, 0.0],
            &[0, 1],
            &[(0.0, 1.0), (0.0, 1.0)],
        );
        // with a1 = 0: 2 a0 = 2 -> a0 = 1
        assert!((a[0] - 1.0).abs() < 1e-12 && a[1].abs() < 1e-12, "{a:?}");
    }
}

#[cfg(test)]
mod shared_albedo_tests {
    use super::*;
    use rand::{Rng, SeedableRng};

    /// sum_c of the joint objective and its gradient for per-channel values `x[c]` (in `free`'s
    /// order).
    fn objective(
        grams: &[([[f64; 4]; 4], [f64; 4])],
        free: &[usize],
        x: &[Vec<f64>],
    ) -> (f64, Vec<Vec<f64>>) {
        let mut f = 0.0;
        let mut grad = Vec::new();
        for ((g, h), xc) in grams.iter().zip(x) {
            let mut gc = vec![0.0; free.len()];
            for (i, &a) in free.iter().enumerate() {
                f -= 2.0 * xc[i] * h[a];
                gc[i] -= 2.0 * h[a];
                for (j, &b) in free.iter().enumerate() {
                    f += xc[i] * xc[j] * g[a][b];
                    gc[i] += 2.0 * g[a][b] * xc[j];
                }
            }
            grad.push(gc);
        }
        (f, grad)
    }

    /// Gram matrices of random columns (kd, ks, fuzz) and data of three channels.
    fn grams(seed: u64, truth: &[[f64; 3]; 3], correlated: f64) -> Vec<([[f64; 4]; 4], [f64; 4])> {
        let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
        let cols: Vec<[f64; 4]> = (0..200)
            .map(|_| {
                let d: f64 = rng.random_range(0.1..1.0);
                let s: f64 = correlated * d + (1.0 - correlated) * rng.random_range(0.0..2.0);
                [d, s, 0.0, rng.random_range(0.0..0.5)]
            })
            .collect();
        (0..3)
            .map(|c| {
                let mut g = [[0.0; 4]; 4];
                let mut h = [0.0; 4];
                for col in &cols {
                    let noise: f64 = rng.random_range(-0.01..0.01);
                    let y =
                        truth[0][c] * col[0] + truth[1][c] * col[1] + truth[2][c] * col[3] + noise;
                    for a in [0, 1, 3] {
                        h[a] += col[a] * y;
                        for b in [0, 1, 3] {
                            g[a][b] += col[a] * col[b];
                        }
                    }
                }
                (g, h)
            })
            .collect()
    }

    #[test]
    fn a_shared_albedo_meets_the_joint_optimality_conditions() {
        let free = [0usize, 1, 3];
        let bounds = [(0.0, 1.0), (0.0, 1.0), (0.0, 1.0)];
        // kd per channel, ks (grey truth or not), fuzz per channel; the last case pushes kd[b]
        // and the fuzz to their bounds and has a ks whose best grey value is inside
        let cases: [([[f64; 3]; 3], f64); 4] = [
            ([[0.5, 0.1, 0.05], [0.3, 0.3, 0.3], [0.2, 0.1, 0.3]], 0.0),
            ([[0.5, 0.1, 0.05], [0.6, 0.2, 0.1], [0.2, 0.1, 0.3]], 0.0),
            ([[0.5, 0.1, 0.02], [0.3, 0.3, 0.3], [0.0, 0.1, 0.0]], 0.9),
            ([[0.6, 0.2, -0.3], [0.5, 0.4, 0.6], [-0.2, 0.4, 1.4]], 0.5),
        ];
        for (k, (truth, corr)) in cases.iter().enumerate() {
            let g = grams(k as u64, truth, *corr);
            let x = solve_with_shared(&g, &free, &bounds, 1);
            assert!(
                x.iter().all(|xc| xc[1] == x[0][1]),
                "case {k}: shared value differs"
            );
            let (f, grad) = objective(&g, &free, &x);
            let scale: f64 = g.iter().map(|(gc, _)| gc[0][0]).sum::<f64>();
            let tol = 1e-9 * scale;
            // KKT: per-channel variables and the shared one (its gradient summed over channels)
            let check = |v: f64, d: f64, (lo, hi): (f64, f64), what: &str| {
                if v <= lo {
                    assert!(
                        d >= -tol,
                        "case {k}: {what} at its lower bound with gradient {d}"
                    );
                } else if v >= hi {
                    assert!(
                        d <= tol,
                        "case {k}: {what} at its upper bound with gradient {d}"
                    );
                } else {
                    assert!(
                        d.abs() <= tol,
                        "case {k}: {what} = {v} inside with gradient {d}"
                    );
                }
            };
            for c in 0..3 {
                for i in [0usize, 2] {
                    check(
                        x[c][i],
                        grad[c][i],
                        bounds[i],
                        &format!("channel {c} albedo {i}"),
                    );
                }
            }
            let d_shared: f64 = grad.iter().map(|gc| gc[1]).sum();
            check(x[0][1], d_shared, bounds[1], "the shared albedo");
            // and no nearby feasible point is better (a coarse scan of the shared value)
            for t in 0..=40 {
                let s = t as f64 / 40.0;
                let mut y = x.clone();
                for (c, (gc, hc)) in g.iter().enumerate() {
                    let mut h2 = *hc;
                    for a in [0usize, 3] {
                        h2[a] -= gc[a][1] * s;
                    }
                    let sol = bounded_small_lsq(gc, &h2, &[0, 3], &[bounds[0], bounds[2]]);
                    y[c] = vec![sol[0], s, sol[1]];
                }
                assert!(
                    objective(&g, &free, &y).0 >= f - tol,
                    "case {k}: s = {s} beats the solution"
                );
            }
        }
        // the grey truth is recovered where the data allow
        let g = grams(0, &cases[0].0, 0.0);
        let x = solve_with_shared(&g, &free, &bounds, 1);
        assert!((x[0][1] - 0.3).abs() < 0.01, "{}", x[0][1]);
    }
}

#[cfg(test)]
mod nan_tests {
    use super::*;
    use crate::fit::config::FitConfig;
    use crate::load::samples::Origin;
    use crate::model::frame::direction_from_angles;

    #[test]
    fn a_nan_residual_is_an_error_naming_the_parameters() {
        let s = Sample {
            l: direction_from_angles(0.3, 0.0),
            v: direction_from_angles(0.5, 2.0),
            fibre_azimuth: None,
            map_value: None,
            texel_height: None,
            value: [f64::NAN; 3],
            sigma: None,
            weight: 1.0,
            origin: Origin::Line(7),
        };
        let cfg: FitConfig = toml::from_str(
            "model = \"poulin-fournier\"\n[parameters]\nexponent = { value = 12 }\n",
        )
        .unwrap();
        let set = ParamSet::from_config(&cfg, 1).unwrap();
        let p = FitProblem::new(
            vec![&s],
            set.clone(),
            Settings {
                metric: Metric::Linear,
                quadrature_order: 16,
                histogram_bins: 16,
                separable: false,
            },
            None,
        );
        let theta = p.theta_of(&set);
        let err = p.evaluate(&theta, &set).unwrap_err().to_string();
        assert!(
            err.contains("not finite") && err.contains("exponent = 12"),
            "{err}"
        );
        // and through the whole fit: an error, not a result
        let data = crate::load::samples::Samples {
            samples: vec![s.clone(); 12],
            channels: 1,
            kind: crate::load::samples::DataKind::Gonio,
            source: "nan".into(),
            dropped: Default::default(),
            skipped_examples: vec![],
            image_size: None,
        };
        assert!(crate::fit::fit(&data, &cfg, &crate::progress::Progress::quiet()).is_err());
    }
}
