//! Fibre-direction spread: a fibre rung averaged over a law of fibre azimuths around psi.
//!
//! Real cloth does not hold its fibres parallel: felt and non-wovens scatter them over every
//! direction, woven and brushed materials spread them around a main direction. The fibre rungs
//! (max-normal, hast-diffuse, poulin-fournier, varying-topology, reference) take
//! `azimuth_spread_deg` = s in [0, 180] degrees:
//!
//! ```text
//! f_s(l, v) = int p_s(delta) f(l, v; psi + delta) d delta,
//! ```
//!
//! with p_s the wrapped normal law of standard deviation s on the fibres' period of 180 degrees
//! (T and -T are the same fibres). s = 0 is the aligned rung itself (no averaging, the same bits);
//! s = 180 is the isotropic limit, a uniform law (felt), exactly: there the nodes sit at absolute
//! azimuths, so the result does not depend on psi at all. Between, the integral is a midpoint rule
//! with `azimuth_nodes` (N) nodes over the law's support (+-4 s, or the whole period once that is
//! wider), weights proportional to the density; `reference` integrates the same law adaptively
//! (Gauss–Kronrod, 1e-8 relative). Averaging keeps every property of the rung: reciprocity,
//! invariance under T -> -T (the law is symmetric), non-negativity, finiteness.

use super::frame::DirectionPair;
use super::numerics::quadrature::adaptive_gk15_vec;
use super::{Basis, ShadingModel};
use std::f64::consts::{FRAC_PI_2, PI};

/// The spread at which the law is uniform (isotropic), degrees.
pub const ISOTROPIC_DEG: f64 = super::parameter::ISOTROPIC_SPREAD_DEG;
/// Default node count N of the azimuth quadrature.
pub const DEFAULT_AZIMUTH_NODES: usize = 16;
/// Largest node count any command accepts.
pub const MAX_AZIMUTH_NODES: usize = 1024;

/// Density of the wrapped normal law of standard deviation `sigma` (radians) on period pi at
/// `delta`; uniform (1/pi) in the isotropic limit.
pub fn density(delta: f64, sigma: f64) -> f64 {
    if sigma >= ISOTROPIC_DEG.to_radians() {
        return 1.0 / PI;
    }
    let norm = 1.0 / ((2.0 * PI).sqrt() * sigma);
    (-6..=6)
        .map(|k| {
            let x = delta + k as f64 * PI;
            (-0.5 * x * x / (sigma * sigma)).exp()
        })
        .sum::<f64>()
        * norm
}

/// The nodes of the spread's midpoint rule: (cos delta, sin delta, weight) with delta the turn
/// from the fibre direction psi (radians), weights summing to 1. `nodes` nodes over the law's
/// support (+-4 sigma, or the whole period once that is wider); in the isotropic limit the nodes
/// sit at absolute azimuths, so delta = x - psi.
pub fn spread_nodes(sigma_deg: f64, nodes: usize, psi: f64) -> Vec<(f64, f64, f64)> {
    let sigma = sigma_deg.to_radians();
    let n = nodes.max(1);
    let isotropic = sigma_deg >= ISOTROPIC_DEG;
    let half = if isotropic {
        FRAC_PI_2
    } else {
        (4.0 * sigma).min(FRAC_PI_2)
    };
    let mut raw: Vec<(f64, f64)> = (0..n)
        .map(|j| {
            let x = -half + (j as f64 + 0.5) * 2.0 * half / n as f64;
            // isotropic: absolute azimuths x, i.e. delta = x - psi from the fibres
            let delta = if isotropic { x - psi } else { x };
            (delta, density(x, sigma))
        })
        .collect();
    let total: f64 = raw.iter().map(|r| r.1).sum();
    raw.iter_mut().for_each(|r| r.1 /= total);
    raw.into_iter()
        .map(|(d, w)| (d.cos(), d.sin(), w))
        .collect()
}

pub struct AzimuthSpread {
    inner: Box<dyn ShadingModel>,
    sigma: f64,
    /// (cos delta, sin delta, weight) of each node, delta relative to the fibre direction.
    nodes: Vec<(f64, f64, f64)>,
    /// Integrate adaptively (the reference).
    adaptive: bool,
}

impl AzimuthSpread {
    /// `inner` averaged over the law of spread `sigma_deg` around the fibre direction `psi`
    /// (radians; it fixes the absolute node positions of the isotropic limit) with `nodes` nodes,
    /// or adaptively when `inner` is the reference.
    pub fn new(inner: Box<dyn ShadingModel>, sigma_deg: f64, nodes: usize, psi: f64) -> Self {
        let adaptive = inner.rung().cost == super::rung::Cost::Adaptive;
        Self {
            inner,
            sigma: sigma_deg.to_radians(),
            nodes: spread_nodes(sigma_deg, nodes, psi),
            adaptive,
        }
    }

    /// `out` = the weighted sum over the nodes of `inner_many` (the inner rung's batch
    /// evaluation) at the pairs turned by each node's angle: every node's pairs in one batch
    /// (a cross-section rung fills its lanes), summed node by node in order.
    fn sum_over_nodes(
        &self,
        pairs: &[DirectionPair],
        out: &mut [Basis],
        inner_many: impl Fn(&[DirectionPair], &mut [Basis]),
    ) {
        let n = pairs.len();
        // plain loops into a sized buffer (a flat_map's `next` was a tenth of a sampled
        // max-normal's time with a spread)
        let mut rotated = Vec::with_capacity(self.nodes.len() * n);
        for &(c, s, _) in &self.nodes {
            for p in pairs {
                rotated.push(Self::rotate(p, c, s));
            }
        }
        let mut part = vec![Basis::default(); rotated.len()];
        inner_many(&rotated, &mut part);
        out.iter_mut().for_each(|o| *o = Basis::default());
        for (k, &(_, _, w)) in self.nodes.iter().enumerate() {
            for (o, b) in out.iter_mut().zip(&part[k * n..(k + 1) * n]) {
                *o = *o + b.scaled(w);
            }
        }
    }

    /// The pair seen by fibres turned by delta (cos c, sin s) about N: a rotation, so unit
    /// vectors stay unit to rounding and are not normalised again (two square roots and six
    /// divisions per pair were a tenth of a sampled max-normal's time with a spread). l and v
    /// turn alike, so swapping them swaps the turned pair: reciprocity holds exactly.
    #[inline(always)]
    fn rotate(pair: &DirectionPair, c: f64, s: f64) -> DirectionPair {
        let r = |d: &super::frame::Local| super::frame::Local {
            t: d.t * c + d.b * s,
            b: -d.t * s + d.b * c,
            n: d.n,
        };
        DirectionPair {
            l: r(&pair.l),
            v: r(&pair.v),
        }
    }

    fn exact(&self, pair: &DirectionPair, f: impl Fn(&DirectionPair) -> Basis) -> Basis {
        let half = if self.sigma >= ISOTROPIC_DEG.to_radians() {
            FRAC_PI_2
        } else {
            (8.0 * self.sigma).min(FRAC_PI_2)
        };
        let r = adaptive_gk15_vec(&[-half, 0.0, half], 1e-8, 1e-300, |d| {
            let b = f(&Self::rotate(pair, d.cos(), d.sin()));
            let w = density(d, self.sigma);
            [b.diffuse * w, b.specular * w, b.substrate * w, b.fuzz * w]
        });
        // the law's mass inside the window (1 up to 1e-15 for +-8 sigma or a whole period)
        let mass = adaptive_gk15_vec(&[-half, 0.0, half], 1e-12, 1e-300, |d| {
            [density(d, self.sigma)]
        });
        Basis {
            diffuse: r.value[0] / mass.value[0],
            specular: r.value[1] / mass.value[0],
            substrate: r.value[2] / mass.value[0],
            fuzz: r.value[3] / mass.value[0],
        }
    }
}

impl ShadingModel for AzimuthSpread {
    fn rung(&self) -> &'static super::Rung {
        self.inner.rung()
    }

    fn with_lobe(&self, lobe: super::Lobe) -> Option<Box<dyn ShadingModel>> {
        Some(Box::new(Self {
            inner: self.inner.with_lobe(lobe)?,
            sigma: self.sigma,
            nodes: self.nodes.clone(),
            adaptive: self.adaptive,
        }))
    }

    fn basis_above_horizon(&self, pair: &DirectionPair) -> Basis {
        if self.adaptive {
            return self.exact(pair, |p| self.inner.basis(p));
        }
        // the nodes' pairs as one batch: one pair at a time left a cross-section rung's lanes
        // almost empty
        let mut out = [Basis::default()];
        self.sum_over_nodes(std::slice::from_ref(pair), &mut out, |rotated, part| {
            self.inner.basis_many(rotated, part)
        });
        out[0]
    }

    fn basis_at_height_above_horizon(&self, pair: &DirectionPair, height: f64) -> Option<Basis> {
        if !self.inner.rung().has(crate::model::Ability::Topology) {
            return None;
        }
        if self.adaptive {
            return Some(self.exact(pair, |p| {
                self.inner.basis_at_height(p, height).unwrap_or_default()
            }));
        }
        let mut out = [Basis::default()];
        self.sum_over_nodes(std::slice::from_ref(pair), &mut out, |rotated, part| {
            self.inner.basis_many_at_height(rotated, height, part);
        });
        Some(out[0])
    }

    fn basis_many_at_height(
        &self,
        pairs: &[DirectionPair],
        height: f64,
        out: &mut [Basis],
    ) -> bool {
        if !self.inner.rung().has(crate::model::Ability::Topology) {
            return false;
        }
        if self.adaptive {
            for (p, o) in pairs.iter().zip(out.iter_mut()) {
                *o = self.basis_at_height(p, height).unwrap_or_default();
            }
            return true;
        }
        self.sum_over_nodes(pairs, out, |rotated, part| {
            self.inner.basis_many_at_height(rotated, height, part);
        });
        true
    }

    fn basis_many_at_each_height(
        &self,
        pairs: &[DirectionPair],
        heights: &[f64],
        out: &mut [Basis],
    ) -> bool {
        if !self.inner.rung().has(crate::model::Ability::Topology) {
            return false;
        }
        if self.adaptive {
            for ((p, &h), o) in pairs.iter().zip(heights).zip(out.iter_mut()) {
                *o = self.basis_at_height(p, h).unwrap_or_default();
            }
            return true;
        }
        // the turned pairs are node by node, each node's in the order of `pairs`
        let each: Vec<f64> = heights.repeat(self.nodes.len());
        self.sum_over_nodes(pairs, out, |rotated, part| {
            self.inner.basis_many_at_each_height(rotated, &each, part);
        });
        true
    }

    fn basis_many(&self, pairs: &[DirectionPair], out: &mut [Basis]) {
        if self.adaptive {
            for (p, o) in pairs.iter().zip(out.iter_mut()) {
                *o = self.basis(p);
            }
            return;
        }
        self.sum_over_nodes(pairs, out, |rotated, part| {
            self.inner.basis_many(rotated, part)
        });
    }
}
