//! The periodic fibre cross-section of MODEL.md §2: exact visible and lit sets.
//!
//! Coordinates in the cross-section plane are (b, n): along B and along N, in fibre radii.
//! Fibre k has its axis at (k h, y_k) with h = d cos(phi), y_k = 0 for even k and
//! H = d sin(phi) for odd k. A flat substrate lies at n = -1. One period has width P = 2 h.
//!
//! A direction w in the plane is written by its angle alpha from N towards B:
//! u = (sin alpha, cos alpha). A point on a fibre is centre + (sin th, cos th) with normal
//! n(th) = B sin th + N cos th, so n.w = |w_p| cos(th - alpha).
//!
//! Occlusion is solved in the coordinate perpendicular to u: s(p) = p . (cos alpha, -sin alpha).
//! On the front arc of a fibre (n.u > 0), s = sin(th - alpha) runs monotonically over (-1, 1).
//! Another fibre with centre offset c blocks exactly the s-interval (s_c - 1, s_c + 1) when it lies
//! ahead along u (c.u > 0): chords of disjoint unit discs along u are ordered like their centres.
//! Every fibre of the infinite pattern lies in one of two rows of step 2h, and within a row the
//! blocking members form a run of consecutive integers; when the row's step in s is <= 2 their
//! shadows overlap, so a whole row is one interval however many fibres it holds (grazing light).
//! This handles ALL occluders in O(1), with no neighbour window.
//!
//! Here: the pattern, its directions and occlusion, and the light/view pair; in `arcs.rs` the
//! sets of arcs, in `gaps.rs` the occlusion problem solved in lanes, in `substrate.rs` the
//! substrate fraction, in `diffuse.rs` the diffuse kernel.

use super::frame::Local;
use super::numerics::elementary::{self, floor};

mod arcs;
mod diffuse;
mod gaps;
mod substrate;
#[cfg(test)]
mod tests;

pub use arcs::{for_each_seen_and_lit, Arcs};
#[cfg_attr(not(feature = "internals"), allow(unused_imports))] // for the tests and benchmarks
pub use diffuse::{diffuse_kernel, DiffuseArc, DiffuseArcs};
#[cfg_attr(not(feature = "internals"), allow(unused_imports))] // for the tests and benchmarks
pub use gaps::{compact_gaps, FibreOcclusion, FibreOcclusions, GapSlots};
pub use substrate::{substrate_fractions, SubstrateProblem};

#[inline(always)]
fn ceil(x: f64) -> f64 {
    -floor(-x)
}

/// x mod p in [0, p) for p > 0, without a libm call.
#[inline]
fn wrap(x: f64, p: f64, inv_p: f64) -> f64 {
    let r = x - p * floor(x * inv_p);
    if r >= p || r < 0.0 {
        0.0
    } else {
        r
    }
}

/// Compare-exchange by start, as selects (vectorisable).
#[inline(always)]
fn sort2(x: &mut [(f64, f64)], i: usize, j: usize) {
    let swap = x[j].0 < x[i].0;
    let (p, q) = (x[i], x[j]);
    x[i] = if swap { q } else { p };
    x[j] = if swap { p } else { q };
}

/// A direction projected into the cross-section plane.
#[derive(Clone, Copy, Debug)]
pub struct Projected {
    /// Angle from N towards B, in (-pi/2, pi/2) above the horizon.
    pub alpha: f64,
    pub sin: f64,
    pub cos: f64,
    /// |w_p| = sqrt(1 - (w.T)^2).
    pub len: f64,
    /// tan(alpha) and 1/cos(alpha), for the substrate's shadows.
    pub tan: f64,
    pub sec: f64,
}

impl Projected {
    /// Requires w.N > 0 (so the projection is non-zero).
    pub fn new(w: &Local) -> Self {
        // |w_p| of a unit vector: sqrt is exact enough here and far cheaper than hypot
        let len = (w.b * w.b + w.n * w.n).sqrt();
        let inv_len = 1.0 / len;
        let inv_n = 1.0 / w.n;
        Self {
            // = w.alpha(), inline: atan2 with w.n > 0
            alpha: elementary::atan2_right_half(w.b, w.n),
            sin: w.b * inv_len,
            cos: w.n * inv_len,
            len,
            tan: w.b * inv_n,
            sec: len * inv_n,
        }
    }

    /// A unit direction in the cross-section plane at angle `alpha` from N.
    pub fn in_plane(alpha: f64) -> Self {
        let (sin, cos) = alpha.sin_cos();
        Self::new(&Local {
            t: 0.0,
            b: sin,
            n: cos,
        })
    }
}

/// Which fibre of the period.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Fibre {
    /// Resting on the substrate, axis at height 0.
    Even,
    /// Climbing, axis at height H = d sin(phi).
    Odd,
}

/// The periodic pattern for one spacing and elevation.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Pattern {
    /// Centre distance of adjacent fibres, d >= 2.
    pub spacing: f64,
    /// Elevation phi in [0, acos(1/d)], radians.
    pub elevation: f64,
    /// Horizontal distance of adjacent fibres, h = d cos(phi).
    pub step: f64,
    /// Height of the odd fibres' axes, H = d sin(phi).
    pub rise: f64,
    /// Period width P = 2 h.
    pub period: f64,
    /// 1 / P.
    pub inv_period: f64,
}

impl Pattern {
    pub fn new(spacing: f64, elevation: f64) -> Self {
        let (s, c) = elevation.sin_cos();
        let step = spacing * c;
        Self {
            spacing,
            elevation,
            step,
            rise: spacing * s,
            period: 2.0 * step,
            inv_period: 1.0 / (2.0 * step),
        }
    }

    pub fn flat(spacing: f64) -> Self {
        Self::new(spacing, 0.0)
    }

    /// Unoccluded front arc of `fibre` towards direction `dir`: the set of th (radians, same
    /// convention as the normal n(th)) whose ray along `dir` escapes every other fibre.
    pub fn unoccluded_arcs(&self, fibre: Fibre, dir: &Projected) -> Arcs {
        self.occlusion(dir).unoccluded_arcs(fibre)
    }

    /// Occlusion along `dir` in this pattern, for either fibre.
    #[inline]
    pub fn occlusion(&self, dir: &Projected) -> Occlusion {
        Occlusion {
            dir: *dir,
            step: self.step,
            rise: self.rise,
        }
    }

    /// Fraction of the substrate strip of one period that is seen along `v` and lit along `l`.
    ///
    /// A fibre with axis (cx, cy) shadows the substrate points x with
    /// |(x - cx) cos a + (1 + cy) sin a| < 1, i.e. x in cx - (1 + cy) tan a +- 1/cos a.
    /// Each row of fibres repeats with the period, so each row casts one arc on the period circle:
    /// four arcs, two of width 2 sec(alpha_l) and two of width 2 sec(alpha_v). Measured from the
    /// start of a widest arc, no other arc wraps past the period except into that arc, so the
    /// union is that arc plus three intervals cut at P: three compare-exchanges sort them, and
    /// the gaps are summed in one sweep.
    pub fn substrate_fraction(&self, l: &Projected, v: &Projected) -> f64 {
        SubstrateProblem::new(self, l, v).fraction()
    }
}

/// Occlusion along one direction in one pattern (see [`Pattern::occlusion`]).
#[derive(Clone, Copy, Debug)]
pub struct Occlusion {
    dir: Projected,
    step: f64,
    rise: f64,
}

impl Occlusion {
    /// See [`Pattern::unoccluded_arcs`].
    #[inline]
    pub fn unoccluded_arcs(&self, fibre: Fibre) -> Arcs {
        let mut ends = [0.0; 8];
        let n = compact_gaps(&self.of(fibre).gap_slots(), &mut ends);
        let mut arcs = Arcs::default();
        for e in ends[..2 * n].chunks_exact(2) {
            // arcs that rounding made empty are dropped by push
            let alpha = self.dir.alpha;
            arcs.push(
                alpha + elementary::asin(e[0]),
                alpha + elementary::asin(e[1]),
            );
        }
        arcs
    }

    /// The occlusion problem of one fibre.
    #[inline]
    pub fn of(&self, fibre: Fibre) -> FibreOcclusion {
        FibreOcclusion {
            sin: self.dir.sin,
            cos: self.dir.cos,
            step: self.step,
            // the other row's axis height above this fibre's
            other_row: match fibre {
                Fibre::Even => self.rise,
                Fibre::Odd => -self.rise,
            },
        }
    }
}

/// A light/view pair as the cross-section sees it.
#[derive(Clone, Copy, Debug)]
pub struct SectionPair {
    pub l: Projected,
    pub v: Projected,
    /// l . v in 3D.
    pub cos_lv: f64,
}

impl SectionPair {
    /// Requires both directions above the horizon.
    pub fn new(l: &Local, v: &Local) -> Self {
        Self {
            l: Projected::new(l),
            v: Projected::new(v),
            cos_lv: l.dot(v),
        }
    }

    /// The (B, N)-plane factor (N.l)(N.v) / (|l_p| |v_p|) = cos(alpha_l) cos(alpha_v).
    pub fn cos_alpha_product(&self) -> f64 {
        self.l.cos * self.v.cos
    }

    /// cos(alpha_l - alpha_v), from the projections' sines and cosines.
    #[inline]
    pub fn cos_delta(&self) -> f64 {
        self.l.cos * self.v.cos + self.l.sin * self.v.sin
    }

    /// r . v as a function of th: K [cos(dl - dv) + cos(2 th - al - av)] - l.v with
    /// K = |l_p||v_p| (r = 2 (n.l) n - l).
    #[inline]
    pub fn mirror_cosine(&self, th: f64) -> f64 {
        let k = self.l.len * self.v.len;
        k * (self.cos_delta() + (2.0 * th - self.l.alpha - self.v.alpha).cos()) - self.cos_lv
    }

    /// The th-window (centred on the peak at (al + av)/2) where r.v > `fraction` of its peak
    /// value; `None` when r.v never exceeds it on the front arcs.
    pub fn lobe_window(&self, fraction: f64) -> Option<(f64, f64)> {
        let (half, some) = lobe_half_width(
            self.l.len * self.v.len,
            self.cos_delta(),
            self.cos_lv,
            fraction,
            elementary::atan2_right_half,
        );
        let centre = 0.5 * (self.l.alpha + self.v.alpha);
        some.then_some((centre - half, centre + half))
    }

    /// The arcs of `fibre` that are both visible and lit.
    pub fn seen_and_lit(&self, pattern: &Pattern, fibre: Fibre) -> Arcs {
        Self::seen_and_lit_with(
            &pattern.occlusion(&self.v),
            &pattern.occlusion(&self.l),
            fibre,
        )
    }

    /// [`SectionPair::seen_and_lit`] with the view's and the light's occlusion computed once for
    /// both fibres.
    #[inline]
    pub fn seen_and_lit_with(view: &Occlusion, light: &Occlusion, fibre: Fibre) -> Arcs {
        let vis = view.unoccluded_arcs(fibre);
        if vis.len == 0 {
            return vis;
        }
        vis.intersect(&light.unoccluded_arcs(fibre))
    }
}

/// Half-width of the lobe window of [`SectionPair::lobe_window`] and whether there is one, from
/// k = |l_p||v_p|, cos(alpha_l - alpha_v) and l.v, without branches so lane loops can use it.
/// `atan2` is [`elementary::atan2_right_half`] or its lane form (the same values).
#[inline(always)]
pub fn lobe_half_width(
    k: f64,
    cos_delta: f64,
    cos_lv: f64,
    fraction: f64,
    atan2: impl Fn(f64, f64) -> f64,
) -> (f64, bool) {
    let peak = k * (cos_delta + 1.0) - cos_lv;
    // the window is where cos(2 th - al - av) > c; all of the front arc when c <= -1
    let c = (fraction * peak + cos_lv) / k - cos_delta;
    let cc = c.clamp(-1.0, 1.0);
    // acos(c) / 2 = atan2(sqrt(1 - c), sqrt(1 + c))
    let half = atan2((1.0 - cc).sqrt(), (1.0 + cc).sqrt());
    (half, (peak > 0.0) & (k > 0.0) & (c < 1.0))
}
