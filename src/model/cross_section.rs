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

use super::frame::Local;
use super::numerics::elementary;

/// Upper bound on disjoint arcs: <= 3 shadow intervals leave <= 4 gaps; the intersection of two
/// such sets has <= 7 intervals.
const MAX_ARCS: usize = 8;

/// A small sorted set of disjoint open intervals, stored inline (no allocation on the hot path).
#[derive(Clone, Copy, Debug)]
pub struct Arcs {
    buf: [(f64, f64); MAX_ARCS],
    len: usize,
}

impl Default for Arcs {
    fn default() -> Self {
        Self {
            buf: [(0.0, 0.0); MAX_ARCS],
            len: 0,
        }
    }
}

impl Arcs {
    pub fn as_slice(&self) -> &[(f64, f64)] {
        &self.buf[..self.len]
    }

    fn push(&mut self, a: f64, b: f64) {
        if b > a {
            debug_assert!(self.len < MAX_ARCS);
            if self.len < MAX_ARCS {
                self.buf[self.len] = (a, b);
                self.len += 1;
            }
        }
    }

    pub fn total_length(&self) -> f64 {
        self.as_slice().iter().map(|(a, b)| b - a).sum()
    }

    /// Intersection of two sorted sets of disjoint intervals.
    pub fn intersect(&self, other: &Arcs) -> Arcs {
        let mut out = Arcs::default();
        let (x, y) = (self.as_slice(), other.as_slice());
        for_each_intersection(
            |i| x[i],
            x.len(),
            |j| y[j],
            y.len(),
            |lo, hi| out.push(lo, hi),
        );
        out
    }
}

/// Calls `f(lo, hi)` for each non-empty intersection of an interval of x with one of y, in
/// order. x and y are sorted sequences of intervals (i -> (lo, hi)), with no overlaps inside each
/// sequence; intervals that are empty are allowed and contribute nothing.
#[inline]
fn for_each_intersection(
    x: impl Fn(usize) -> (f64, f64),
    nx: usize,
    y: impl Fn(usize) -> (f64, f64),
    ny: usize,
    mut f: impl FnMut(f64, f64),
) {
    let (mut i, mut j) = (0, 0);
    while i < nx && j < ny {
        let ((xa, xb), (ya, yb)) = (x(i), y(j));
        let (lo, hi) = (xa.max(ya), xb.min(yb));
        if hi > lo {
            f(lo, hi);
        }
        if xb < yb {
            i += 1;
        } else {
            j += 1;
        }
    }
}

/// The arcs seen along one direction and lit along the other, from both directions' compacted
/// gaps (flattened [lo, hi] pairs) with their asin already taken, so th = alpha + entry:
/// `f(lo, hi)` for each, in order. The same arcs as [`SectionPair::seen_and_lit_with`], without
/// building the sets.
#[inline]
pub fn for_each_seen_and_lit(
    view: &[f64],
    alpha_v: f64,
    light: &[f64],
    alpha_l: f64,
    f: impl FnMut(f64, f64),
) {
    for_each_intersection(
        |i| (alpha_v + view[2 * i], alpha_v + view[2 * i + 1]),
        view.len() / 2,
        |j| (alpha_l + light[2 * j], alpha_l + light[2 * j + 1]),
        light.len() / 2,
        f,
    )
}

/// floor(x) without a libm call or a branch (baseline x86-64 has no rounding instruction, and
/// `x as i64` would add Rust's saturation checks), exact for every f64: adding 2^52 to |x| < 2^52
/// rounds it to an integer, then one step down where that rounded up; larger |x| are integers.
/// Branch-free, so lane loops vectorise it.
#[inline(always)]
fn floor(x: f64) -> f64 {
    const TWO_52: f64 = 4_503_599_627_370_496.0;
    let r = ((x.abs() + TWO_52) - TWO_52).copysign(x);
    let r = r - (r > x) as u8 as f64;
    if x.abs() < TWO_52 {
        r
    } else {
        x
    }
}

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

/// The gaps of a fibre's unoccluded front arc in s: four slots [lo0, hi0, .., lo3, hi3] in
/// increasing order, each either a gap (hi > lo, ends in [-1, 1]) or empty (hi <= lo).
pub type GapSlots = [f64; 8];

/// A shadow slot that holds no shadow: it sorts after every real one (real starts are <= 1) and
/// closes the sweep.
const NO_SHADOW: (f64, f64) = (3.0, 3.0);

/// The gaps that three shadow slots (in s = sin(th - alpha), real or [`NO_SHADOW`]) leave in
/// (-1, 1), without branches: a sorting network by start, then one sweep with a cursor. A
/// slot's gap runs from the cursor to the next start and is empty when that start is not
/// beyond the cursor, or the cursor already passed 1.
#[inline(always)]
fn complement_s(mut x: [(f64, f64); 3]) -> GapSlots {
    sort2(&mut x, 1, 2);
    sort2(&mut x, 0, 1);
    sort2(&mut x, 1, 2);
    let mut out = [0.0; 8];
    let mut cursor = -1.0;
    for (k, &(a, b)) in x.iter().enumerate() {
        (out[2 * k], out[2 * k + 1]) = (cursor, a.min(1.0));
        cursor = f64::max(cursor, b);
    }
    (out[6], out[7]) = (cursor, 1.0);
    out
}

/// Moves the non-empty gaps of `slots` to the front of `out`, in order, without branches;
/// returns how many there are.
#[inline(always)]
pub fn compact_gaps(slots: &GapSlots, out: &mut [f64; 8]) -> usize {
    let mut n = 0;
    for k in 0..4 {
        let (lo, hi) = (slots[2 * k], slots[2 * k + 1]);
        (out[2 * n], out[2 * n + 1]) = (lo, hi);
        n += (hi > lo) as usize;
    }
    n
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

/// What [`Pattern::substrate_fraction`] depends on.
#[derive(Clone, Copy, Debug, Default)]
pub struct SubstrateProblem {
    /// tan and 1/cos of the light's and the view's angle alpha.
    pub l_tan: f64,
    pub l_sec: f64,
    pub v_tan: f64,
    pub v_sec: f64,
    /// The pattern's h, H, P and 1/P.
    pub step: f64,
    pub rise: f64,
    pub period: f64,
    pub inv_period: f64,
}

impl SubstrateProblem {
    pub fn new(pattern: &Pattern, l: &Projected, v: &Projected) -> Self {
        Self {
            l_tan: l.tan,
            l_sec: l.sec,
            v_tan: v.tan,
            v_sec: v.sec,
            step: pattern.step,
            rise: pattern.rise,
            period: pattern.period,
            inv_period: pattern.inv_period,
        }
    }

    /// See [`Pattern::substrate_fraction`]; branch-free, so [`substrate_fractions`] runs
    /// it in lanes.
    #[inline(always)]
    pub fn fraction(&self) -> f64 {
        let p = self.period;
        let (wl, wv) = (2.0 * self.l_sec, 2.0 * self.v_sec);
        // arc starts before wrapping: the even row (0, 0) and the odd row (h, H)
        let start = |tan: f64, sec: f64, cx: f64, cy: f64| cx - (1.0 + cy) * tan - sec;
        let (h, rise) = (self.step, self.rise);
        let arcs = [
            (start(self.l_tan, self.l_sec, 0.0, 0.0), wl),
            (start(self.l_tan, self.l_sec, h, rise), wl),
            (start(self.v_tan, self.v_sec, 0.0, 0.0), wv),
            (start(self.v_tan, self.v_sec, h, rise), wv),
        ];
        // the widest arc is the origin; the other three follow it
        let light_wider = wl >= wv;
        let origin = if light_wider { arcs[0].0 } else { arcs[2].0 };
        let width = if light_wider { wl } else { wv };
        let first = if light_wider { arcs[1] } else { arcs[0] };
        let second = if light_wider { arcs[2] } else { arcs[1] };
        let cut = |(s, w): (f64, f64)| {
            let r = wrap(s - origin, p, self.inv_period);
            (r, (r + w).min(p))
        };
        let mut x = [cut(first), cut(second), cut(arcs[3])];
        sort2(&mut x, 1, 2);
        sort2(&mut x, 0, 1);
        sort2(&mut x, 1, 2);
        let mut cursor = width;
        let mut open = 0.0;
        for (a, b) in x {
            open += (a - cursor).max(0.0);
            cursor = cursor.max(b);
        }
        open += (p - cursor).max(0.0);
        // an arc as wide as the period covers the substrate
        if wl.max(wv) >= p {
            0.0
        } else {
            open * self.inv_period
        }
    }
}

/// [`SubstrateProblem::fraction`] of every problem, bit for bit, in lanes.
pub fn substrate_fractions(problems: &[SubstrateProblem], out: &mut [f64]) {
    assert_eq!(problems.len(), out.len());
    super::numerics::lanes::on_widest_lanes(
        #[inline(always)]
        |_| {
            for (p, o) in problems.iter().zip(out.iter_mut()) {
                *o = p.fraction();
            }
        },
    )
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

/// One fibre of a pattern seen along one direction (above the horizon): what its unoccluded
/// front arc depends on.
#[derive(Clone, Copy, Debug, Default)]
pub struct FibreOcclusion {
    /// sin and cos of the direction's angle alpha from N (cos > 0).
    pub sin: f64,
    pub cos: f64,
    /// The pattern's h = d cos(phi).
    pub step: f64,
    /// Height of the other row's axes above this fibre's: +H for the even fibre, -H for the odd.
    pub other_row: f64,
}

impl FibreOcclusion {
    /// The gaps in s = sin(th - alpha) that every occluder of the infinite pattern leaves on the
    /// fibre's front arc (th = alpha + asin(s)). Branch-free (both sides of each case computed,
    /// one kept), so [`FibreOcclusions::solve`] runs it in lanes.
    #[inline(always)]
    pub fn gap_slots(&self) -> GapSlots {
        let (sa, ca) = (self.sin, self.cos);
        // row steps in s (> 0 above the horizon) and along the ray
        let ds = 2.0 * self.step * ca;
        let da = 2.0 * self.step * sa;
        let inv_ds = 1.0 / ds;
        let inv_da = if da != 0.0 { 1.0 / da } else { 0.0 };
        // Own row: member m != 0 sits at s = m ds, a = m da, so the members ahead are those with
        // sign(m) = sign(da). The nearest shadows (ds - 1, ds + 1) (or its mirror); when ds < 2
        // the farther ones continue the run past s = +-1, and when ds >= 2 none reaches (-1, 1).
        let own = if da > 0.0 {
            (ds - 1.0, 1.0)
        } else {
            (-1.0, 1.0 - ds)
        };
        let own = if ds < 2.0 && da != 0.0 {
            own
        } else {
            NO_SHADOW
        };
        // Other row: offset (h, y0) from this fibre's axis, members m at s0 + m ds, a0 + m da.
        let y0 = self.other_row;
        let s0 = self.step * ca - y0 * sa;
        let a0 = self.step * sa + y0 * ca;
        // Members whose shadow can reach (-1, 1): |s_m| < 2 (boundary members cast empty
        // shadows, so including them is harmless) ...
        let lo = ceil((-2.0 - s0) * inv_ds);
        let hi = floor((2.0 - s0) * inv_ds);
        // ... and that lie ahead along the ray: a0 + m da > 0.
        let lo = if da > 0.0 {
            lo.max(floor(-a0 * inv_da) + 1.0)
        } else {
            lo
        };
        let hi = if da < 0.0 {
            hi.min(ceil(-a0 * inv_da) - 1.0)
        } else {
            hi
        };
        let some = (da != 0.0 || a0 > 0.0) && lo <= hi;
        // ds <= 2: consecutive shadows overlap, the run is one interval; ds > 2 leaves at most
        // two members inside the window of width 4.
        let s = s0 + lo * ds;
        let (first, second) = if ds <= 2.0 {
            ((s - 1.0, s0 + hi * ds + 1.0), NO_SHADOW)
        } else {
            let second = if hi > lo {
                (s + ds - 1.0, s + ds + 1.0)
            } else {
                NO_SHADOW
            };
            ((s - 1.0, s + 1.0), second)
        };
        let (first, second) = if some {
            (first, second)
        } else {
            (NO_SHADOW, NO_SHADOW)
        };
        complement_s([own, first, second])
    }
}

/// Many [`FibreOcclusion`]s, stored by field (each field contiguous, so lane loops load eight
/// values with one instruction), with room for their gap slots, also by field.
#[derive(Clone, Debug, Default)]
pub struct FibreOcclusions {
    sin: Vec<f64>,
    cos: Vec<f64>,
    step: Vec<f64>,
    other_row: Vec<f64>,
    /// slots[k][i] = [`FibreOcclusion::gap_slots`] of problem i, entry k (after `solve`).
    slots: [Vec<f64>; 8],
}

impl FibreOcclusions {
    pub fn clear(&mut self) {
        for v in [
            &mut self.sin,
            &mut self.cos,
            &mut self.step,
            &mut self.other_row,
        ] {
            v.clear();
        }
    }

    pub fn len(&self) -> usize {
        self.sin.len()
    }

    pub fn is_empty(&self) -> bool {
        self.sin.is_empty()
    }

    pub fn extend(&mut self, ps: &[FibreOcclusion]) {
        self.sin.extend(ps.iter().map(|p| p.sin));
        self.cos.extend(ps.iter().map(|p| p.cos));
        self.step.extend(ps.iter().map(|p| p.step));
        self.other_row.extend(ps.iter().map(|p| p.other_row));
    }

    /// The gap slots of problem `i` (after [`FibreOcclusions::solve`]).
    #[inline]
    pub fn slots(&self, i: usize) -> GapSlots {
        std::array::from_fn(|k| self.slots[k][i])
    }

    /// [`FibreOcclusion::gap_slots`] of every problem, bit for bit, in lanes (AVX-512 or AVX2
    /// when the CPU has it). One problem at a time, its case analysis cost about six
    /// mispredicted branches per light/view pair.
    pub fn solve(&mut self) {
        let n = self.len();
        for slot in self.slots.iter_mut() {
            // every entry below n is written; only growth needs filling
            if slot.len() < n {
                slot.resize(n, 0.0);
            }
        }
        super::numerics::lanes::on_widest_lanes(
            #[inline(always)]
            |_| self.solve_lanes(),
        )
    }

    #[inline(always)]
    fn solve_lanes(&mut self) {
        let n = self.len();
        let [s0, s1, s2, s3, s4, s5, s6, s7] = &mut self.slots;
        let (sin, cos, step, other_row) = (
            &self.sin[..n],
            &self.cos[..n],
            &self.step[..n],
            &self.other_row[..n],
        );
        let outs = [
            &mut s0[..n],
            &mut s1[..n],
            &mut s2[..n],
            &mut s3[..n],
            &mut s4[..n],
            &mut s5[..n],
            &mut s6[..n],
            &mut s7[..n],
        ];
        for i in 0..n {
            let p = FibreOcclusion {
                sin: sin[i],
                cos: cos[i],
                step: step[i],
                other_row: other_row[i],
            };
            let r = p.gap_slots();
            for k in 0..8 {
                outs[k][i] = r[k];
            }
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

/// Integral over [t0, t1] of cos(th - a) cos(th - b) dth, the diffuse kernel.
///
/// Long arcs: 1/2 [D cos(a - b) + cos(t0 + t1 - a - b) sin D], D = t1 - t0. On short arcs next to
/// the terminator (integrand ~ 0) that form cancels catastrophically, so there, with m the
/// midpoint and g(m) = cos(m - a) cos(m - b) computed as a product,
///     I = D g(m) - 1/2 cos(2m - a - b) (D - sin D),
/// the same identity regrouped, with D - sin D from its series: no cancellation in g, and the
/// correction is O(D^3).
/// `cos_ab` is cos(a - b), which the caller has from the directions' sines and cosines.
///
/// Both forms are computed and one kept (no branch), so [`DiffuseArcs::kernels`] runs it in
/// lanes: twice the trigonometry of a branch, but no misprediction and eight arcs per
/// instruction.
#[inline(always)]
pub fn diffuse_kernel(t0: f64, t1: f64, a: f64, b: f64, cos_ab: f64) -> f64 {
    let arc = DiffuseArc {
        t0,
        t1,
        a,
        b,
        cos_ab,
    };
    let (long, short) = (arc.long_form(), arc.short_form());
    if t1 - t0 > 0.5 {
        long
    } else {
        short
    }
}

/// The arguments of one [`diffuse_kernel`], for [`DiffuseArcs::kernels`].
#[derive(Clone, Copy, Debug, Default)]
pub struct DiffuseArc {
    pub t0: f64,
    pub t1: f64,
    pub a: f64,
    pub b: f64,
    pub cos_ab: f64,
}

impl DiffuseArc {
    #[inline(always)]
    fn long_form(&self) -> f64 {
        let d = self.t1 - self.t0;
        // t0 + t1 - a - b = 2m - a - b exactly (2 (0.5 x) = x)
        let u = self.t0 + self.t1 - self.a - self.b;
        0.5 * (d * self.cos_ab + elementary::cos(u) * elementary::sin(d))
    }

    #[inline(always)]
    fn short_form(&self) -> f64 {
        let d = self.t1 - self.t0;
        let u = self.t0 + self.t1 - self.a - self.b;
        let m = 0.5 * (self.t0 + self.t1);
        let d2 = d * d;
        // D - sin D = D^3/6 - D^5/120 + ... (relative error < 1e-16 for D <= 0.5)
        let d_minus_sin = d
            * d2
            * (1.0 / 6.0
                - d2 * (1.0 / 120.0
                    - d2 * (1.0 / 5040.0
                        - d2 * (1.0 / 362_880.0
                            - d2 * (1.0 / 39_916_800.0 - d2 / 6_227_020_800.0)))));
        (d * elementary::cos(m - self.a) * elementary::cos(m - self.b)
            - 0.5 * elementary::cos(u) * d_minus_sin)
            .max(0.0)
    }
}

/// Many [`DiffuseArc`]s, stored by field (each field contiguous, so lane loops load eight
/// values with one instruction).
#[derive(Clone, Debug, Default)]
pub struct DiffuseArcs {
    t0: Vec<f64>,
    t1: Vec<f64>,
    a: Vec<f64>,
    b: Vec<f64>,
    cos_ab: Vec<f64>,
}

impl DiffuseArcs {
    pub fn clear(&mut self) {
        for v in [
            &mut self.t0,
            &mut self.t1,
            &mut self.a,
            &mut self.b,
            &mut self.cos_ab,
        ] {
            v.clear();
        }
    }

    pub fn len(&self) -> usize {
        self.t0.len()
    }

    pub fn is_empty(&self) -> bool {
        self.t0.is_empty()
    }

    pub fn push(&mut self, arc: DiffuseArc) {
        self.t0.push(arc.t0);
        self.t1.push(arc.t1);
        self.a.push(arc.a);
        self.b.push(arc.b);
        self.cos_ab.push(arc.cos_ab);
    }

    /// [`diffuse_kernel`] of every arc, bit for bit, written to `out`, in lanes.
    pub fn kernels(&self, out: &mut [f64]) {
        assert_eq!(self.len(), out.len());
        super::numerics::lanes::on_widest_lanes(
            #[inline(always)]
            |_| self.kernels_lanes(out),
        )
    }

    #[inline(always)]
    fn kernels_lanes(&self, out: &mut [f64]) {
        let n = out.len();
        let (t0, t1, a, b, cos_ab) = (
            &self.t0[..n],
            &self.t1[..n],
            &self.a[..n],
            &self.b[..n],
            &self.cos_ab[..n],
        );
        for i in 0..n {
            out[i] = diffuse_kernel(t0[i], t1[i], a[i], b[i], cos_ab[i]);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::numerics::quadrature::adaptive_gk15;

    /// Sort intervals and return the complement of their union within (lo, hi).
    fn complement_within(shadows: &mut [(f64, f64)], lo: f64, hi: f64) -> Arcs {
        shadows.sort_unstable_by(|p, q| p.0.total_cmp(&q.0));
        let mut out = Arcs::default();
        let mut cursor = lo;
        for &(a, b) in shadows.iter() {
            if a > cursor {
                out.push(cursor, a.min(hi));
            }
            cursor = cursor.max(b);
            if cursor >= hi {
                return out;
            }
        }
        out.push(cursor, hi);
        out
    }

    /// The i-th pattern of a random test set: every fifth touching (d = 2), spacings up to
    /// 2 + `spread` weighted towards 2, and every seventh at each elevation limit.
    fn random_pattern(i: usize, spread: f64, u: &mut impl FnMut() -> f64) -> Pattern {
        let d = if i % 5 == 0 {
            2.0
        } else {
            2.0 + spread * u() * u()
        };
        let phi_max = (1.0 / d).acos();
        let phi = match i % 7 {
            0 => 0.0,
            1 => phi_max,
            _ => phi_max * u(),
        };
        Pattern::new(d, phi)
    }

    /// The previous form of [`Pattern::substrate_fraction`]: each row's arc cut at the period
    /// boundary into up to two pieces, all pieces sorted, the gaps of their union summed.
    fn substrate_fraction_by_pieces(pat: &Pattern, l: &Projected, v: &Projected) -> f64 {
        let p = pat.period;
        let mut pieces = vec![];
        for dir in [l, v] {
            let half = dir.sec;
            if 2.0 * half >= p {
                return 0.0;
            }
            for (cx, cy) in [(0.0, 0.0), (pat.step, pat.rise)] {
                let start = (cx - (1.0 + cy) * dir.tan - half).rem_euclid(p);
                let end = start + 2.0 * half;
                if end <= p {
                    pieces.push((start, end));
                } else {
                    pieces.push((start, p));
                    pieces.push((0.0, end - p));
                }
            }
        }
        complement_within(&mut pieces, 0.0, p).total_length() / p
    }

    #[test]
    fn substrate_fraction_matches_the_piecewise_form() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand::rngs::StdRng::seed_from_u64(11);
        let mut u = move || rng.random::<f64>();
        let mut open = 0;
        let mut problems = vec![];
        for i in 0..40_000 {
            let p = random_pattern(i, 10.0, &mut u);
            let (d, phi) = (p.spacing, p.elevation);
            let mut angle = || match i % 13 {
                0 => 0.0,
                _ => (u() - 0.5) * std::f64::consts::PI * 0.999,
            };
            let (l, v) = (Projected::in_plane(angle()), Projected::in_plane(angle()));
            let got = p.substrate_fraction(&l, &v);
            let want = substrate_fraction_by_pieces(&p, &l, &v);
            assert!(
                (got - want).abs() < 1e-13,
                "d {d} phi {phi} l {} v {}: {got} vs {want}",
                l.alpha,
                v.alpha
            );
            open += (want > 0.0) as usize;
            problems.push(SubstrateProblem::new(&p, &l, &v));
        }
        // the lane pass gives the same bits
        let mut lanes = vec![0.0; problems.len()];
        substrate_fractions(&problems, &mut lanes);
        for (p, got) in problems.iter().zip(&lanes) {
            assert_eq!(got.to_bits(), p.fraction().to_bits(), "{p:?}");
        }
        // about a quarter of the cases see some substrate (the comparison is not all zeros)
        assert!(open > 8_000, "{open}");
    }

    /// The previous, row-generic form of [`Pattern::unoccluded_arcs`] (both rows through the same
    /// member-window code, std floor/ceil, a general sort): the specialised one must agree.
    fn unoccluded_arcs_by_rows(p: &Pattern, fibre: Fibre, dir: &Projected) -> Arcs {
        let (sa, ca) = (dir.sin, dir.cos);
        let ds = 2.0 * p.step * ca;
        let da = 2.0 * p.step * sa;
        let rows = match fibre {
            Fibre::Even => [(0.0, 0.0), (p.step, p.rise)],
            Fibre::Odd => [(0.0, 0.0), (p.step, -p.rise)],
        };
        let mut shadows = vec![];
        for (x0, y0) in rows {
            let s0 = x0 * ca - y0 * sa;
            let a0 = x0 * sa + y0 * ca;
            let mut lo = ((-2.0 - s0) / ds).ceil();
            let mut hi = ((2.0 - s0) / ds).floor();
            if da > 0.0 {
                lo = lo.max((-a0 / da).floor() + 1.0);
            } else if da < 0.0 {
                hi = hi.min((-a0 / da).ceil() - 1.0);
            } else if a0 <= 0.0 {
                continue;
            }
            if !(lo <= hi) {
                continue;
            }
            if ds <= 2.0 {
                shadows.push((s0 + lo * ds - 1.0, s0 + hi * ds + 1.0));
            } else {
                let mut m = lo;
                while m <= hi {
                    shadows.push((s0 + m * ds - 1.0, s0 + m * ds + 1.0));
                    m += 1.0;
                }
            }
        }
        let gaps = complement_within(&mut shadows, -1.0, 1.0);
        let mut arcs = Arcs::default();
        for &(a, b) in gaps.as_slice() {
            arcs.push(
                dir.alpha + a.clamp(-1.0, 1.0).asin(),
                dir.alpha + b.clamp(-1.0, 1.0).asin(),
            );
        }
        arcs
    }

    #[test]
    fn specialised_occlusion_matches_the_row_generic_form() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand::rngs::StdRng::seed_from_u64(7);
        let mut u = move || rng.random::<f64>();
        let mut compared = 0;
        let mut problems = vec![];
        for i in 0..20_000 {
            let p = random_pattern(i, 6.0, &mut u);
            let (d, phi) = (p.spacing, p.elevation);
            let alpha = match i % 11 {
                0 => 0.0,
                1 => std::f64::consts::FRAC_PI_2 * (1.0 - 1e-9),
                _ => (u() - 0.5) * std::f64::consts::PI * 0.999_999,
            };
            let dir = Projected::in_plane(alpha);
            for fibre in [Fibre::Even, Fibre::Odd] {
                problems.push(p.occlusion(&dir).of(fibre));
                let got = p.unoccluded_arcs(fibre, &dir);
                let want = unoccluded_arcs_by_rows(&p, fibre, &dir);
                // intervals shorter than 1e-12 may appear on one side only (touching shadows)
                let keep = |a: &Arcs| -> Vec<(f64, f64)> {
                    a.as_slice()
                        .iter()
                        .copied()
                        .filter(|(x, y)| y - x > 1e-12)
                        .collect()
                };
                let (g, w) = (keep(&got), keep(&want));
                assert_eq!(
                    g.len(),
                    w.len(),
                    "d {d} phi {phi} alpha {alpha} {fibre:?}: {g:?} vs {w:?}"
                );
                for (x, y) in g.iter().zip(&w) {
                    assert!(
                        (x.0 - y.0).abs() < 1e-12 && (x.1 - y.1).abs() < 1e-12,
                        "d {d} phi {phi} alpha {alpha} {fibre:?}: {g:?} vs {w:?}"
                    );
                }
                compared += 1;
            }
        }
        assert_eq!(compared, 40_000);
        // the lane pass gives the same gap slots, bit for bit
        let mut many = FibreOcclusions::default();
        many.extend(&problems);
        many.solve();
        for (i, p) in problems.iter().enumerate() {
            assert_eq!(
                many.slots(i).map(f64::to_bits),
                p.gap_slots().map(f64::to_bits)
            );
        }
    }

    #[test]
    fn floor_ceil_wrap_match_std() {
        for x in [
            -3.5,
            -3.0,
            -0.2,
            -0.0,
            0.0,
            0.7,
            2.0,
            2.9999999,
            1e17,
            -1e17,
            4.4e15 + 0.5,
            2_251_799_813_685_247.5,
            -2_251_799_813_685_247.5,
            2_251_799_813_685_248.5,
            0.5,
            -0.5,
            1.5,
            -2.5,
            1e-300,
            -1e-300,
        ] {
            assert_eq!(floor(x), x.floor(), "{x}");
            assert_eq!(ceil(x), x.ceil(), "{x}");
        }
        for (x, p) in [
            (-0.5, 4.0),
            (9.0, 4.0),
            (3.999999, 4.0),
            (-8.0, 4.0),
            (1e6 + 0.25, 2.0),
        ] {
            assert!(
                (wrap(x, p, 1.0 / p) - f64::rem_euclid(x, p)).abs() < 1e-9,
                "{x} {p}"
            );
        }
    }

    #[test]
    fn diffuse_kernel_matches_quadrature_on_long_and_short_arcs() {
        for &(t0, t1, a, b) in &[
            (-1.2, 1.3, 0.2, -0.4),
            (0.0, 0.05, 0.3, 0.3),
            (-1.5, -1.49, 0.07, 0.0),
            (0.3, 0.3 + 1e-6, 0.1, 0.2),
            (0.2, 0.69, -0.5, 0.4),
            (1.0, 1.51, 0.0, 0.0),
            (-1.5706, -1.5, 0.0, 0.0),
            (1.07, 1.0707963, -0.5, 0.5),
        ] {
            let want = adaptive_gk15(&[t0, t1], 1e-14, 0.0, |t: f64| {
                (t - a).cos() * (t - b).cos()
            })
            .value[0];
            let got = diffuse_kernel(t0, t1, a, b, (a - b).cos());
            assert!(
                (got - want).abs() <= 1e-13 * want.abs().max(1e-300),
                "{got} vs {want}"
            );
        }
    }

    #[test]
    fn lane_diffuse_kernels_equal_the_scalar_kernel_bit_for_bit() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand::rngs::StdRng::seed_from_u64(3);
        let mut arcs = vec![];
        for i in 0..10_003 {
            let t0 = rng.random_range(-3.1..3.1);
            // long and short arcs, down to slivers
            let d = match i % 3 {
                0 => rng.random_range(0.0..3.0),
                1 => rng.random_range(0.4..0.6),
                _ => 10f64.powf(rng.random_range(-12.0..0.0)),
            };
            let (a, b) = (rng.random_range(-1.57..1.57), rng.random_range(-1.57..1.57));
            arcs.push(DiffuseArc {
                t0,
                t1: t0 + d,
                a,
                b,
                cos_ab: (a - b).cos(),
            });
        }
        let mut many = DiffuseArcs::default();
        for arc in &arcs {
            many.push(*arc);
        }
        let mut out = vec![0.0; arcs.len()];
        many.kernels(&mut out);
        for (arc, got) in arcs.iter().zip(&out) {
            let want = diffuse_kernel(arc.t0, arc.t1, arc.a, arc.b, arc.cos_ab);
            assert_eq!(got.to_bits(), want.to_bits(), "{arc:?}");
        }
    }

    #[test]
    fn vertical_light_on_touching_flat_fibres_sees_upper_halves() {
        let p = Pattern::flat(2.0);
        let dir = Projected::in_plane(0.0);
        let arcs = p.unoccluded_arcs(Fibre::Even, &dir);
        assert_eq!(arcs.as_slice().len(), 1);
        let (a, b) = arcs.as_slice()[0];
        assert!(
            (a + std::f64::consts::FRAC_PI_2).abs() < 1e-12
                && (b - std::f64::consts::FRAC_PI_2).abs() < 1e-12
        );
        assert_eq!(p.substrate_fraction(&dir, &dir), 0.0);
    }

    #[test]
    fn gapped_fibres_show_substrate_from_above() {
        // d = 4, flat: fibres of width 2 every 4 radii, so half the substrate shows.
        let p = Pattern::flat(4.0);
        let dir = Projected::in_plane(0.0);
        assert!((p.substrate_fraction(&dir, &dir) - 0.5).abs() < 1e-15);
    }

    #[test]
    fn grazing_light_lights_only_a_sliver_and_stays_finite() {
        let p = Pattern::flat(2.0);
        let a: f64 = std::f64::consts::FRAC_PI_2 - 3e-8;
        let dir = Projected::in_plane(a);
        let arcs = p.unoccluded_arcs(Fibre::Even, &dir);
        let len = arcs.total_length();
        assert!(len > 0.0 && len < 1e-3, "{len}");
    }
}
