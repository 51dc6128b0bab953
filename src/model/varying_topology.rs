//! `varying-topology` (seeds 001/002): MODEL.md §2 with the elevation phi from the topology,
//! closed-form diffuse over the exact visible-and-lit arcs, and N-point Gauss–Legendre for the
//! specular lobe.
//!
//! f(l, v) = [ sum over the period's 2 fibres of int_{vis & lit} f_fib (n.l)(n.v) dth
//!             + int_{vis & lit substrate} f_sub (N.l)(N.v) dx ] / (P (N.l)(N.v))
//!
//! With n.l = |l_p| cos(th - alpha_l) the |l_p||v_p| factors cancel against (N.l)(N.v), leaving
//! cos(alpha_l) cos(alpha_v) in the denominator. Using cos(th - a) cos(th - b) =
//! 1/2 [cos(a - b) + cos(2 th - a - b)] and r.v = 2 (n.l)(n.v) - l.v, each specular node costs
//! one cosine and one power. The specular integrand depends on th only, not on which fibre the
//! point lies on, so the lobe is integrated once over its window (where r.v > exp(ln(1e-15)/e) of
//! its peak, so (r.v)^e < 1e-15 of the peak outside), each piece weighted by how many of the two
//! fibres see and light it. The knob N is the number of Gauss–Legendre nodes per lobe window:
//! a piece of length L gets ceil(N L / W) nodes, so the cost is about N per evaluation.

use super::cross_section::{diffuse_kernel, Arcs, Fibre, Pattern, SectionPair};
use super::quadrature::GaussLegendre;
use super::topology::elevation_from_height;
use super::{Basis, DirectionPair, ModelId, ShadingModel};
use std::f64::consts::{FRAC_1_PI, PI};

/// Closed-form diffuse + Gauss–Legendre specular over one pattern.
#[derive(Clone, Debug)]
pub struct GaussSection {
    /// Gauss–Legendre rules of orders 1..=N.
    rules: Vec<GaussLegendre>,
    exponent: f64,
    /// Phong normalisation (e + 2) / (2 pi).
    norm: f64,
    /// Fraction of the peak of r.v where the specular window ends.
    lobe_floor: f64,
}

impl GaussSection {
    pub fn new(exponent: f64, order: usize) -> Self {
        Self {
            rules: (1..=order).map(GaussLegendre::new).collect(),
            exponent,
            norm: (exponent + 2.0) / (2.0 * PI),
            lobe_floor: (1e-15f64.ln() / exponent).exp(),
        }
    }

    pub fn order(&self) -> usize {
        self.rules.len()
    }

    pub fn basis(&self, pattern: &Pattern, sp: &SectionPair) -> Basis {
        let denom = pattern.period * sp.cos_alpha_product();
        if !(denom > 0.0) {
            return Basis::default();
        }
        let (al, av) = (sp.l.alpha, sp.v.alpha);
        let cos_delta = (al - av).cos();
        let sigma = al + av;
        let k2 = 2.0 * sp.l.len * sp.v.len;
        let even = sp.seen_and_lit(pattern, Fibre::Even);
        let odd = sp.seen_and_lit(pattern, Fibre::Odd);
        let mut diffuse = 0.0;
        for &(a, b) in even.as_slice().iter().chain(odd.as_slice()) {
            diffuse += diffuse_kernel(a, b, al, av);
        }
        let mut specular = 0.0;
        if let Some((w0, w1)) = sp.lobe_window(self.lobe_floor) {
            let (e, o) = (even.clip(w0, w1), odd.clip(w0, w1));
            let n = self.rules.len() as f64;
            let density = n / (w1 - w0);
            for_each_piece(&e, &o, |a, b, multiplicity| {
                let nodes = ((density * (b - a)).ceil() as usize).clamp(1, self.rules.len());
                specular += multiplicity
                    * self.rules[nodes - 1].integrate(a, b, |th| {
                        let cc = 0.5 * (cos_delta + (2.0 * th - sigma).cos());
                        let rv = k2 * cc - sp.cos_lv;
                        if rv > 0.0 {
                            // exp(e ln x) instead of powf: glibc's pow takes a slow exact
                            // path, and with x in (0, 1] the relative error is ~ e |ln x| ulp.
                            (self.exponent * rv.ln()).exp() * cc
                        } else {
                            0.0
                        }
                    });
            });
        }
        Basis {
            diffuse: FRAC_1_PI * diffuse / denom,
            specular: self.norm * specular / denom,
            substrate: FRAC_1_PI * pattern.substrate_fraction(&sp.l, &sp.v),
        }
    }
}

/// Calls `f(a, b, multiplicity)` for the pieces of the union of two sets of disjoint intervals,
/// with multiplicity 1 or 2 (covered by one or both sets).
fn for_each_piece(x: &Arcs, y: &Arcs, mut f: impl FnMut(f64, f64, f64)) {
    let mut cuts = [0.0f64; 48];
    let mut n = 0;
    for &(a, b) in x.as_slice().iter().chain(y.as_slice()) {
        cuts[n] = a;
        cuts[n + 1] = b;
        n += 2;
    }
    let cuts = &mut cuts[..n];
    cuts.sort_unstable_by(f64::total_cmp);
    let inside = |set: &Arcs, t: f64| set.as_slice().iter().any(|&(a, b)| a < t && t < b);
    for w in cuts.windows(2) {
        if w[1] > w[0] {
            let mid = 0.5 * (w[0] + w[1]);
            let m = inside(x, mid) as u8 + inside(y, mid) as u8;
            if m > 0 {
                f(w[0], w[1], m as f64);
            }
        }
    }
}

/// The `varying-topology` rung: the mean over a discretised height distribution.
#[derive(Clone, Debug)]
pub struct VaryingTopology {
    spacing: f64,
    section: GaussSection,
    /// (pattern, weight) per histogram node.
    nodes: Vec<(Pattern, f64)>,
}

impl VaryingTopology {
    /// `heights`: (H, weight) pairs from [`super::topology::Topology::discretise`].
    pub fn new(spacing: f64, exponent: f64, order: usize, heights: Vec<(f64, f64)>) -> Self {
        let nodes = heights
            .into_iter()
            .map(|(h, w)| (Pattern::new(spacing, elevation_from_height(h, spacing)), w))
            .collect();
        Self {
            spacing,
            section: GaussSection::new(exponent, order),
            nodes,
        }
    }

    pub fn nodes(&self) -> usize {
        self.nodes.len()
    }
}

impl ShadingModel for VaryingTopology {
    fn id(&self) -> ModelId {
        ModelId::VaryingTopology
    }

    fn basis_above_horizon(&self, pair: &DirectionPair) -> Basis {
        let sp = SectionPair::new(&pair.l, &pair.v);
        self.nodes.iter().fold(Basis::default(), |acc, (p, w)| {
            acc + (self.section.basis(p, &sp).scaled(*w))
        })
    }

    fn basis_at_height_above_horizon(&self, pair: &DirectionPair, height: f64) -> Option<Basis> {
        let sp = SectionPair::new(&pair.l, &pair.v);
        let pattern = Pattern::new(self.spacing, elevation_from_height(height, self.spacing));
        Some(self.section.basis(&pattern, &sp))
    }
}
