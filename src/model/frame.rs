//! Shading frame and directions (MODEL.md §1).
//!
//! Swatch frame: x, y in the swatch plane, macro normal N = +z. The fibre tangent is
//! T = (cos psi, sin psi, 0) and the bi-tangent B = N x T. Directions point away from the surface.

use nalgebra::Vector3;

/// A 3-vector of f64 (directions: unit, swatch frame, z the macro normal).
pub type Vec3 = Vector3<f64>;

/// Unit direction from polar angle `theta` (from N) and azimuth `phi` (from x towards y), radians.
pub fn direction_from_angles(theta: f64, phi: f64) -> Vec3 {
    let (st, ct) = theta.sin_cos();
    // theta = 90 degrees is the horizon (MODEL.md §1: the value there is 0), not cos(pi/2) =
    // 6e-17 above it
    let ct = if (theta.abs() - std::f64::consts::FRAC_PI_2).abs() <= 1e-15 {
        0.0
    } else {
        ct
    };
    let (sp, cp) = phi.sin_cos();
    Vec3::new(st * cp, st * sp, ct)
}

/// The fibre frame (T, B, N) in swatch coordinates.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FibreFrame {
    pub t: Vec3,
    pub b: Vec3,
    pub n: Vec3,
}

impl FibreFrame {
    /// Frame for fibres at azimuth `psi` (radians) in a flat swatch.
    pub fn from_azimuth(psi: f64) -> Self {
        let (s, c) = psi.sin_cos();
        let t = Vec3::new(c, s, 0.0);
        let n = Vec3::new(0.0, 0.0, 1.0);
        Self {
            t,
            b: n.cross(&t),
            n,
        }
    }

    /// Frame from an arbitrary tangent (projected into the swatch plane and normalised).
    /// Returns `None` when the tangent has no component in the plane.
    pub fn from_tangent(t: Vec3) -> Option<Self> {
        let n = Vec3::new(0.0, 0.0, 1.0);
        let tp = t - n * t.dot(&n);
        let len = tp.norm();
        if !(len > 1e-12) {
            return None;
        }
        let t = tp / len;
        Some(Self {
            t,
            b: n.cross(&t),
            n,
        })
    }

    /// The same fibres described by -T (and so -B). Every model must be invariant under this.
    pub fn flipped(&self) -> Self {
        Self {
            t: -self.t,
            b: -self.b,
            n: self.n,
        }
    }

    /// Express a swatch-frame vector in (T, B, N) components.
    pub fn to_local(&self, w: &Vec3) -> Local {
        Local {
            t: w.dot(&self.t),
            b: w.dot(&self.b),
            n: w.dot(&self.n),
        }
    }
}

/// A unit vector in fibre-frame components.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Local {
    pub t: f64,
    pub b: f64,
    pub n: f64,
}

impl Local {
    pub fn dot(&self, o: &Local) -> f64 {
        self.t * o.t + self.b * o.b + self.n * o.n
    }
    /// Length of the projection onto the cross-section (B, N) plane: sqrt(1 - (w.T)^2).
    pub fn projected_len(&self) -> f64 {
        (self.b * self.b + self.n * self.n).sqrt()
    }
    /// Angle of the projection in the cross-section plane, from N towards B (MODEL.md §1).
    pub fn alpha(&self) -> f64 {
        self.b.atan2(self.n)
    }
}

/// A light/view pair in fibre-frame components: what every model evaluates.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DirectionPair {
    pub l: Local,
    pub v: Local,
}

impl DirectionPair {
    pub fn new(frame: &FibreFrame, l: &Vec3, v: &Vec3) -> Self {
        Self {
            l: frame.to_local(l),
            v: frame.to_local(v),
        }
    }

    /// Build directly from local components (normalised here).
    pub fn from_local(l: [f64; 3], v: [f64; 3]) -> Self {
        let norm = |a: [f64; 3]| {
            let n = (a[0] * a[0] + a[1] * a[1] + a[2] * a[2]).sqrt();
            Local {
                t: a[0] / n,
                b: a[1] / n,
                n: a[2] / n,
            }
        };
        Self {
            l: norm(l),
            v: norm(v),
        }
    }

    /// Both directions strictly above the swatch plane: only then is a BRDF non-zero.
    pub fn above_horizon(&self) -> bool {
        self.l.n > 0.0 && self.v.n > 0.0
    }

    pub fn swapped(&self) -> Self {
        Self {
            l: self.v,
            v: self.l,
        }
    }

    /// The pair seen with T -> -T (so B -> -B).
    pub fn flipped_tangent(&self) -> Self {
        let f = |w: Local| Local {
            t: -w.t,
            b: -w.b,
            n: w.n,
        };
        Self {
            l: f(self.l),
            v: f(self.v),
        }
    }

    pub fn cos_lv(&self) -> f64 {
        self.l.dot(&self.v)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frame_is_right_handed_and_orthonormal() {
        for psi in [-1.5, -0.3, 0.0, 0.7, 1.4] {
            let f = FibreFrame::from_azimuth(psi);
            assert!((f.t.cross(&f.b) - f.n).norm() < 1e-15);
            assert!(f.t.dot(&f.b).abs() < 1e-15);
            assert!((f.b.norm() - 1.0).abs() < 1e-15);
        }
    }

    #[test]
    fn t_along_x_gives_b_along_y() {
        let f = FibreFrame::from_azimuth(0.0);
        assert!((f.b - Vec3::new(0.0, 1.0, 0.0)).norm() < 1e-15);
    }

    #[test]
    fn angles_follow_the_model_convention() {
        let w = direction_from_angles(30f64.to_radians(), 90f64.to_radians());
        assert!((w - Vec3::new(0.0, 0.5, 3f64.sqrt() / 2.0)).norm() < 1e-15);
        let f = FibreFrame::from_azimuth(0.0);
        let loc = f.to_local(&w);
        assert!((loc.alpha() - 30f64.to_radians()).abs() < 1e-15);
    }
}
