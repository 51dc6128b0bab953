//! Sets of arcs on a fibre's cross-section: small sorted sets of disjoint intervals of th, and
//! their intersections.

/// Upper bound on disjoint arcs: <= 3 shadow intervals leave <= 4 gaps; the intersection of two
/// such sets has <= 7 intervals.
const MAX_ARCS: usize = 8;

/// A small sorted set of disjoint open intervals, stored inline (no allocation on the hot path).
#[derive(Clone, Copy, Debug)]
pub struct Arcs {
    buf: [(f64, f64); MAX_ARCS],
    pub(super) len: usize,
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

    pub(super) fn push(&mut self, a: f64, b: f64) {
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
/// `f(lo, hi)` for each, in order. The same arcs as [`super::SectionPair::seen_and_lit_with`], without
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
