//! One instance of the material per draw (issue 41 item 2): a fibre direction of the spread and
//! a height of the histogram, drawn with the model's own weights, then sampled and evaluated
//! alone.
//!
//! A rung with a fibre-direction spread or a height histogram is a mixture: the spread averages
//! the aligned rung over N turned fibre directions (weights nu_j,
//! [`crate::model::azimuth_spread`]), `varying-topology` over K heights (weights w_k, the
//! histogram of its topology). Its exact evaluation costs N K cross-section evaluations, which
//! makes a sample cost what N K samples of the aligned rung do (16 to 256 times). A path tracer
//! need not pay that: where the fibres at a shading point are a random draw from the mixture
//! (which is what the spread and the histogram model: fibres of many directions and heights
//! under one pixel), it can draw one instance (j, k) with probability nu_j w_k at each shading
//! point, and then shade that point with the aligned rung turned by the node's angle, at the
//! height h_k:
//!
//! ```text
//! f(l, v) = sum_jk nu_j w_k f_jk(l, v),   f_jk(l, v) = f_aligned(R_j l, R_j v; h_k),
//! ```
//!
//! so E[f_jk] = f exactly (the same nodes and weights as the exact evaluation, not a new
//! quadrature), and every estimate built from one instance per shading point (a sample's weight
//! f_jk cos / pdf_jk, a light's contribution f_jk cos / pdf_light, both at once under multiple
//! importance sampling with the instance's own densities) is an unbiased estimate of the
//! exact material's. The instance's sampler is the aligned rung's mixture in the turned frame
//! (one node), so its density is exact for what it draws and `weight == f_jk cos / pdf_jk`
//! holds as for every sampler here. The price is variance: the instances' albedos differ, and
//! that spread adds to each sample's; `fibrefit bench sampling` measures both, and the cost per
//! unit of variance, side by side with the exact sampler. With a texel's own height (a map),
//! only the direction is drawn. The `reference` has no instances (it integrates the spread and
//! heights adaptively): its one instance is the whole model, sampled by the whole mixture.

use super::directions::{rescale, turn, unturn};
use super::{evaluate_in_groups, Draw, Sample, Sampler, EVAL_PAIRS};
use crate::model::frame::Local;
use crate::model::{Albedos, Basis, DirectionPair, ShadingModel};

/// One instance of a material: its fibres turned by a spread node's angle delta from T, at one
/// height of the histogram.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Instance {
    /// cos delta and sin delta of the turn (1 and 0 without a spread).
    pub cos: f64,
    pub sin: f64,
    /// The fibres' height: a histogram's drawn height, or the texel's own (a map); `None` for
    /// rungs without a topology (and for a topology of one height: the model's own).
    pub height: Option<f64>,
}

impl Instance {
    /// `pair` as the instance's turned fibres see it.
    pub fn turned(&self, pair: &DirectionPair) -> DirectionPair {
        DirectionPair {
            l: turn(&pair.l, self.cos, self.sin),
            v: turn(&pair.v, self.cos, self.sin),
        }
    }

    /// The instance's basis at `pair` (swatch's fibre frame): `aligned` (the model without its
    /// spread, [`crate::model::build_instance`]) at the turned pair and the instance's height.
    pub fn basis(&self, aligned: &dyn ShadingModel, pair: &DirectionPair) -> Basis {
        let turned = self.turned(pair);
        match self.height {
            Some(h) => aligned
                .basis_at_height(&turned, h)
                .unwrap_or_else(|| aligned.basis(&turned)),
            None => aligned.basis(&turned),
        }
    }
}

/// The instances a sampler draws from: the spread's nodes (cos delta, sin delta, weight) and
/// the histogram's (height, weight) bins, each with cumulative weights.
#[derive(Clone, Debug)]
pub(super) struct Instances {
    nodes: Vec<(f64, f64, f64)>,
    node_cumulative: Vec<f64>,
    /// Weights summing to 1; empty where the model has no histogram to draw from (one height,
    /// or none).
    heights: Vec<(f64, f64)>,
    height_cumulative: Vec<f64>,
}

impl Instances {
    /// The instances of `nodes` (weights summing to 1) times the histogram `bins` (weights in
    /// any scale; fewer than two: none drawn).
    pub fn new(nodes: Vec<(f64, f64, f64)>, bins: Vec<(f64, f64)>) -> Self {
        let node_cumulative = cumulative(nodes.iter().map(|n| n.2));
        let heights: Vec<(f64, f64)> = if bins.len() < 2 {
            Vec::new()
        } else {
            let total: f64 = bins.iter().map(|b| b.1).sum();
            bins.into_iter().map(|(h, w)| (h, w / total)).collect()
        };
        let height_cumulative = cumulative(heights.iter().map(|b| b.1));
        Self {
            nodes,
            node_cumulative,
            heights,
            height_cumulative,
        }
    }

    /// One instance: the whole model (the reference's adaptive spread and heights).
    pub fn whole() -> Self {
        Self::new(vec![(1.0, 0.0, 1.0)], Vec::new())
    }
}

/// The running sums of `weights` (summing to 1), the last set to exactly 1.
pub(super) fn cumulative(weights: impl Iterator<Item = f64>) -> Vec<f64> {
    let mut acc = 0.0;
    let mut sums: Vec<f64> = weights
        .map(|w| {
            acc += w;
            acc
        })
        .collect();
    if let Some(last) = sums.last_mut() {
        *last = 1.0;
    }
    sums
}

/// The index picked by the uniform `u` from `cumulative` weights and `u` rescaled within it.
fn pick(cumulative: &[f64], u: f64) -> (usize, f64) {
    let j = cumulative
        .partition_point(|&c| c <= u)
        .min(cumulative.len() - 1);
    let lo = if j == 0 { 0.0 } else { cumulative[j - 1] };
    (j, rescale(u, lo, cumulative[j]))
}

impl Sampler {
    /// How many instances the material has (spread nodes times histogram heights): 1 where
    /// the exact evaluation is already one instance.
    pub fn instances(&self) -> usize {
        let set = &self.instance_set;
        set.nodes.len() * set.heights.len().max(1)
    }

    /// [`Sampler::instances`] where draws come with a texel's own height (`texel_height`: a
    /// map), which fixes the height: the spread's nodes only.
    pub fn instances_given(&self, texel_height: bool) -> usize {
        if texel_height {
            self.instance_set.nodes.len()
        } else {
            self.instances()
        }
    }

    /// The instance picked by the uniform `u` in [0, 1): a spread node with the node weights,
    /// then (with `u` rescaled within the node) a histogram height with the histogram's
    /// weights, unless `height` (a texel's, from a map) fixes it.
    pub fn instance(&self, u: f64, height: Option<f64>) -> Instance {
        let set = &self.instance_set;
        let (j, r) = pick(&set.node_cumulative, u.clamp(0.0, super::ONE_BELOW));
        let (cos, sin, _) = set.nodes[j];
        let height = height.or_else(|| {
            (!set.heights.is_empty()).then(|| set.heights[pick(&set.height_cumulative, r).0].0)
        });
        Instance { cos, sin, height }
    }

    /// Every instance with its probability among [`Sampler::instance`]'s draws (with no
    /// texel height): the terms of the exact evaluation, in the spread's node order, heights
    /// within a node.
    pub fn instances_with_probabilities(&self) -> Vec<(Instance, f64)> {
        let set = &self.instance_set;
        let mut all = Vec::with_capacity(self.instances());
        for &(cos, sin, nu) in &set.nodes {
            if set.heights.is_empty() {
                all.push((Instance { cos, sin, height: None }, nu));
            }
            for &(h, w) in &set.heights {
                all.push((Instance { cos, sin, height: Some(h) }, nu * w));
            }
        }
        all
    }

    /// The sampler of one instance: this one's mixture with the single node of the turned
    /// fibres (itself without a spread).
    fn one_node(&self) -> &Sampler {
        self.aligned.as_deref().unwrap_or(self)
    }

    /// Sample l for the view v (fibre frame) from the instance's own mixture (the aligned
    /// sampler in the turned frame), two uniforms u in [0, 1)^2; weight[c] = f_c(l, v) l.n /
    /// pdf with f the instance's ([`Instance::basis`] of `aligned`) and pdf
    /// [`Sampler::pdf_instance`]. `None` as [`Sampler::sample`].
    pub fn sample_instance(
        &self,
        aligned: &dyn ShadingModel,
        albedos: &Albedos,
        instance: &Instance,
        v: &Local,
        u: [f64; 2],
    ) -> Option<Sample> {
        let (l, pdf) = self.instance_direction(albedos, instance, v, u)?;
        let basis = instance.basis(aligned, &DirectionPair { l, v: *v });
        Some(Sample::weighed(l, pdf, &basis, albedos))
    }

    /// The exact density (1/sr) of [`Sampler::sample_instance`] producing l given v (0 below
    /// the horizon): the aligned mixture's at the turned directions (a turn keeps solid angle).
    pub fn pdf_instance(&self, albedos: &Albedos, instance: &Instance, v: &Local, l: &Local) -> f64 {
        let (c, s) = (instance.cos, instance.sin);
        self.one_node().pdf(albedos, &turn(v, c, s), &turn(l, c, s))
    }

    /// The instance's direction and density, without evaluating a model.
    fn instance_direction(
        &self,
        albedos: &Albedos,
        instance: &Instance,
        v: &Local,
        u: [f64; 2],
    ) -> Option<(Local, f64)> {
        let (c, s) = (instance.cos, instance.sin);
        let (l, pdf) = self
            .one_node()
            .sample_direction(albedos, &turn(v, c, s), u)?;
        Some((unturn(&l, c, s), pdf))
    }

    /// [`Sampler::sample_instance`] of every draw with its instance, into `out` (same
    /// lengths), bit for bit: the directions one by one, then `aligned` evaluated at all of
    /// them at once (in lanes; draws with a height through `basis_many_at_each_height`).
    pub fn sample_many_instances(
        &self,
        aligned: &dyn ShadingModel,
        draws: &[Draw],
        instances: &[Instance],
        out: &mut [Option<Sample>],
    ) {
        assert_eq!(draws.len(), out.len());
        assert_eq!(draws.len(), instances.len());
        let topology = aligned.rung().has(crate::model::Ability::Topology);
        let (mut plain, mut high) = (Vec::new(), Vec::new());
        let (mut plain_pairs, mut high_pairs, mut heights) = (Vec::new(), Vec::new(), Vec::new());
        for (i, ((d, inst), o)) in draws.iter().zip(instances).zip(out.iter_mut()).enumerate() {
            *o = None;
            let Some((l, pdf)) = self.instance_direction(&d.albedos, inst, &d.v, d.u) else {
                continue;
            };
            let turned = inst.turned(&DirectionPair { l, v: d.v });
            match inst.height {
                Some(h) if topology => {
                    high.push((i, l, pdf));
                    high_pairs.push(turned);
                    heights.push(h);
                }
                _ => {
                    plain.push((i, l, pdf));
                    plain_pairs.push(turned);
                }
            }
        }
        let (bases, high_bases) =
            evaluate_in_groups(aligned, &plain_pairs, &high_pairs, &heights, EVAL_PAIRS);
        let done = plain.iter().zip(&bases).chain(high.iter().zip(&high_bases));
        for (&(i, l, pdf), basis) in done {
            out[i] = Some(Sample::weighed(l, pdf, basis, &draws[i].albedos));
        }
    }
}
