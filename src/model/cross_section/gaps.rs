//! The occlusion problem of one fibre along one direction, solved without branches: the gaps
//! every occluder of the infinite pattern leaves on its front arc (in s = sin(th - alpha)), one
//! problem at a time or many in lanes ([`FibreOcclusions`]).

use super::{ceil, floor, sort2};

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
        crate::model::numerics::lanes::on_widest_lanes(
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
