//! The closed-form draws and densities the mixture is made of: the cosine and tube techniques,
//! Ward's half vector, and the turns into a spread node's frame (the fibre lobe's are in
//! `lobe.rs`).

use crate::model::frame::Local;
use std::f64::consts::{FRAC_1_PI, PI, TAU};

/// The Wallis integral int_{-pi/2}^{pi/2} cos^e(x) dx, approximately (2 % at e = 1, exact as
/// e grows): the lobe's width in latitude, for the weights only.
pub(super) fn wallis(e: f64) -> f64 {
    (TAU / (e + 0.5)).sqrt()
}

/// The largest f64 below 1.
pub(super) const ONE_BELOW: f64 = 1.0 - f64::EPSILON / 2.0;

/// (u - lo) / (hi - lo) in [0, 1): a uniform on [lo, hi) rescaled to the unit interval.
pub(super) fn rescale(u: f64, lo: f64, hi: f64) -> f64 {
    if !(hi > lo) {
        return 0.0;
    }
    ((u - lo) / (hi - lo)).clamp(0.0, ONE_BELOW)
}

/// w in the frame of fibres turned by delta (cos c, sin s) about N (as the spread turns them).
#[inline(always)]
pub(super) fn turn(w: &Local, c: f64, s: f64) -> Local {
    Local {
        t: w.t * c + w.b * s,
        b: -w.t * s + w.b * c,
        n: w.n,
    }
}

/// The inverse of [`turn`].
pub(super) fn unturn(w: &Local, c: f64, s: f64) -> Local {
    Local {
        t: w.t * c - w.b * s,
        b: w.t * s + w.b * c,
        n: w.n,
    }
}

/// Cosine-weighted hemisphere direction from two uniforms (Malley: a uniform disk point lifted).
pub(super) fn cosine_direction(u: [f64; 2]) -> Local {
    let r2 = u[0];
    let r = r2.sqrt();
    let (s, c) = (TAU * u[1]).sin_cos();
    Local {
        t: r * c,
        b: r * s,
        n: (1.0 - r2).max(0.0).sqrt(),
    }
}

/// The direction at latitude th (given as sin, cos) about T and longitude phi in (0, pi).
fn about_tangent(sin_th: f64, cos_th: f64, phi: f64) -> Local {
    let (sp, cp) = phi.sin_cos();
    Local {
        t: sin_th,
        b: cos_th * cp,
        n: cos_th * sp,
    }
}

/// y - sin y, accurate for small y.
fn y_minus_sin(y: f64) -> f64 {
    if y < 0.25 {
        let y2 = y * y;
        // y^3/3! - y^5/5! + y^7/7! - y^9/9! + y^11/11!
        y * y2
            * (1.0 / 6.0
                - y2 * (1.0 / 120.0
                    - y2 * (1.0 / 5040.0 - y2 * (1.0 / 362_880.0 - y2 / 39_916_800.0))))
    } else {
        y - y.sin()
    }
}

/// The tube technique: th with density cos^2(th) / (pi/2), phi uniform on (0, pi).
pub(super) fn tube_direction(u: [f64; 2]) -> Local {
    // F(th) = (y - sin y) / (2 pi) with y = 2 th + pi in [0, 2 pi]; solve for y in [0, pi] by
    // symmetry (y -> 2 pi - y is th -> -th)
    let m = TAU * u[0];
    let upper = m > PI;
    let m = if upper { TAU - m } else { m };
    // y - sin y <= y^3 / 6: cbrt(6 m) is at or left of the root; y - sin y is convex on [0, pi],
    // so Newton's first step lands right of it and the iterates fall to it monotonically
    let mut y = (6.0 * m).cbrt().min(PI);
    for _ in 0..40 {
        let slope = 2.0 * (0.5 * y).sin().powi(2); // 1 - cos y
        if !(slope > 0.0) {
            break;
        }
        let step = (y_minus_sin(y) - m) / slope;
        let next = (y - step).clamp(0.0, PI);
        let done = (next - y).abs() <= 4.0 * f64::EPSILON * y.max(f64::MIN_POSITIVE);
        y = next;
        if done {
            break;
        }
    }
    // th = y/2 - pi/2: cos th = sin(y/2), sin th = -cos(y/2)
    let (s, c) = (0.5 * y).sin_cos();
    let sin_th = if upper { c } else { -c };
    about_tangent(sin_th, s, PI * u[1])
}

/// Density of [`tube_direction`] at l (above the horizon, in the fibres' frame).
#[inline(always)]
pub(super) fn tube_pdf(l: &Local) -> f64 {
    2.0 * l.projected_len() * FRAC_1_PI * FRAC_1_PI
}

/// Walter's half vector for Ward, reflected: l (may be below the horizon).
pub(super) fn ward_direction(ax: f64, ay: f64, v: &Local, u: [f64; 2]) -> Local {
    let (s, c) = (TAU * u[1]).sin_cos();
    let phi = (ay * s).atan2(ax * c);
    let (sp, cp) = phi.sin_cos();
    let q = cp * cp / (ax * ax) + sp * sp / (ay * ay);
    let tan2 = -(-u[0]).ln_1p() / q;
    let cos_h = 1.0 / (1.0 + tan2).sqrt();
    let sin_h = (tan2 / (1.0 + tan2)).sqrt();
    let h = Local {
        t: sin_h * cp,
        b: sin_h * sp,
        n: cos_h,
    };
    let vh = v.dot(&h);
    Local {
        t: 2.0 * vh * h.t - v.t,
        b: 2.0 * vh * h.b - v.b,
        n: 2.0 * vh * h.n - v.n,
    }
}

/// Density of [`ward_direction`] at l (both above the horizon).
pub(super) fn ward_pdf(ax: f64, ay: f64, v: &Local, l: &Local) -> f64 {
    let (ht, hb, hn) = (l.t + v.t, l.b + v.b, l.n + v.n);
    let norm = (ht * ht + hb * hb + hn * hn).sqrt();
    if !(norm > 0.0 && hn > 0.0) {
        return 0.0;
    }
    let (ht, hb, hn) = (ht / norm, hb / norm, hn / norm);
    let e = ((ht / ax).powi(2) + (hb / ay).powi(2)) / (hn * hn);
    let p_h = (-e).exp() / (PI * ax * ay * hn * hn * hn);
    // l.h = |l + v| / 2
    p_h / (2.0 * norm)
}

/// The anisotropic GGX's visible normal for the view v (Heitz 2018), reflected: l (may be
/// below the horizon).
pub(super) fn ggx_direction(at: f64, ab: f64, v: &Local, u: [f64; 2]) -> Local {
    // the view in the stretched configuration
    let (vt, vb, vn) = (at * v.t, ab * v.b, v.n);
    let len = (vt * vt + vb * vb + vn * vn).sqrt();
    let (vt, vb, vn) = (vt / len, vb / len, vn / len);
    let lensq = vt * vt + vb * vb;
    // T1 = (-vb, vt, 0) / |.|, T2 = V x T1
    let (t1t, t1b) = if lensq > 0.0 {
        let r = lensq.sqrt();
        (-vb / r, vt / r)
    } else {
        (1.0, 0.0)
    };
    let (t2t, t2b, t2n) = (-vn * t1b, vn * t1t, vt * t1b - vb * t1t);
    let r = u[0].sqrt();
    let (s, c) = (TAU * u[1]).sin_cos();
    let p1 = r * c;
    let mut p2 = r * s;
    let blend = 0.5 * (1.0 + vn);
    p2 = (1.0 - blend) * (1.0 - p1 * p1).max(0.0).sqrt() + blend * p2;
    let p3 = (1.0 - p1 * p1 - p2 * p2).max(0.0).sqrt();
    let nt = p1 * t1t + p2 * t2t + p3 * vt;
    let nb = p1 * t1b + p2 * t2b + p3 * vb;
    let nn = p2 * t2n + p3 * vn;
    // unstretched
    let (ht, hb, hn) = (at * nt, ab * nb, nn.max(0.0));
    let hl = (ht * ht + hb * hb + hn * hn).sqrt();
    let h = Local {
        t: ht / hl,
        b: hb / hl,
        n: hn / hl,
    };
    let vh = v.dot(&h);
    Local {
        t: 2.0 * vh * h.t - v.t,
        b: 2.0 * vh * h.b - v.b,
        n: 2.0 * vh * h.n - v.n,
    }
}

/// Density of [`ggx_direction`] at l (both above the horizon): G1(v) D(h) / (4 N.v).
pub(super) fn ggx_pdf(at: f64, ab: f64, v: &Local, l: &Local) -> f64 {
    use crate::model::rungs::gltf::{ggx_d, ggx_lambda, half_vector};
    let h = half_vector(l, v);
    if !(h.n > 0.0 && v.n > 0.0) {
        return 0.0;
    }
    ggx_d(at, ab, &h) / ((1.0 + ggx_lambda(at, ab, v)) * 4.0 * v.n)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tube_inversion_reaches_the_cdf() {
        for k in 0..=1000 {
            let u = k as f64 / 1000.0 * ONE_BELOW;
            let l = tube_direction([u, 0.3]);
            let th = l.t.atan2(l.projected_len());
            let y = 2.0 * th + PI;
            let f = y_minus_sin(y) / TAU;
            assert!((f - u).abs() < 1e-13, "u {u}: F {f}");
            assert!(((l.t * l.t + l.b * l.b + l.n * l.n) - 1.0).abs() < 1e-14);
        }
    }

    #[test]
    fn turning_is_undone() {
        let w = Local {
            t: 0.3,
            b: -0.5,
            n: 0.81f64.sqrt(),
        };
        let (s, c) = 0.7f64.sin_cos();
        let back = unturn(&turn(&w, c, s), c, s);
        assert!((back.t - w.t).abs() < 1e-15 && (back.b - w.b).abs() < 1e-15);
    }
}
