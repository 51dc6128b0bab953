//! The fit's coordinates: each shape parameter's internal coordinate (log, periodic, under
//! the largest height, bounded), the Jacobian's step, and the log metric's floor.

#[allow(unused_imports)]
use super::*;

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
            Coordinate::Periodic => crate::fit::wrap_azimuth(x),
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
