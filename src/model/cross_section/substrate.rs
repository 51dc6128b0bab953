//! The substrate's share of a period that is seen and lit ([`SubstrateProblem`]), one problem at
//! a time or many in lanes.

use super::{sort2, wrap, Pattern, Projected};

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
    crate::model::numerics::lanes::on_widest_lanes(
        #[inline(always)]
        |_| {
            for (p, o) in problems.iter().zip(out.iter_mut()) {
                *o = p.fraction();
            }
        },
    )
}
