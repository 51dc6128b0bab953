//! A Fresnel factor on the specular lobe: an optional component for the grazing forward peak of
//! real cloth.
//!
//! With `fresnel_ior` = n > 0, the specular basis of a rung is multiplied by Schlick's
//! approximation at the half-vector angle,
//!
//! ```text
//! F(cos theta_d) = F0 + (1 - F0) (1 - cos theta_d)^5,  F0 = ((n - 1) / (n + 1))^2,
//! cos theta_d = l.h,  h = (l + v) / |l + v|,
//! ```
//!
//! the reflectance of a dielectric fibre surface at the angle between the light and the
//! reflecting normal (l.h = v.h: reciprocal; unchanged when the fibres turn about N, so it
//! commutes with the fibre-direction spread and with T -> -T). It grows towards 1 at grazing
//! forward scattering, where theta_d nears 90 deg. n = 0 gives F0 = 1, F = 1: the component off.
//! `ks` absorbs the overall scale (it is solved linearly).

use super::frame::DirectionPair;
use super::{Basis, BasisTransform, ShadingModel, Transformed};

/// Schlick's Fresnel factor at cos theta_d for index of refraction `ior`.
pub fn schlick(cos_d: f64, ior: f64) -> f64 {
    let f0 = ((ior - 1.0) / (ior + 1.0)).powi(2);
    let m = (1.0 - cos_d.clamp(0.0, 1.0)).powi(5);
    f0 + (1.0 - f0) * m
}

/// cos theta_d = l.h of a pair.
pub fn cos_half(pair: &DirectionPair) -> f64 {
    let (l, v) = (&pair.l, &pair.v);
    let h = [l.t + v.t, l.b + v.b, l.n + v.n];
    let norm = (h[0] * h[0] + h[1] * h[1] + h[2] * h[2]).sqrt();
    if !(norm > 0.0) {
        return 0.0;
    }
    (l.t * h[0] + l.b * h[1] + l.n * h[2]) / norm
}

/// Schlick's factor at l.h on the specular component.
#[derive(Clone)]
pub struct FresnelFactor {
    ior: f64,
}

impl BasisTransform for FresnelFactor {
    fn apply(&self, pair: &DirectionPair, mut b: Basis) -> Basis {
        b.specular *= schlick(cos_half(pair), self.ior);
        b
    }
}

/// A rung with the Fresnel factor on its lobe.
pub type FresnelLobe = Transformed<FresnelFactor>;

impl FresnelLobe {
    pub fn new(inner: Box<dyn ShadingModel>, ior: f64) -> Self {
        Transformed::with(inner, FresnelFactor { ior })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::poulin_fournier::PoulinFournier;

    #[test]
    fn schlick_limits_and_the_lobe_properties() {
        let f0 = (0.5f64 / 2.5).powi(2);
        assert!((schlick(1.0, 1.5) - f0).abs() < 1e-15);
        assert!((schlick(0.0, 1.5) - 1.0).abs() < 1e-15);
        assert_eq!(schlick(0.3, 0.0), 1.0); // ior 0: off
        let m = FresnelLobe::new(Box::new(PoulinFournier::new(2.4, 30.0, 16)), 1.6);
        let plain = PoulinFournier::new(2.4, 30.0, 16);
        let mut seed = 11u64;
        let mut u = || {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            (seed >> 11) as f64 / (1u64 << 53) as f64
        };
        for _ in 0..500 {
            let mut dir = || {
                let z: f64 = 0.02 + 0.98 * u();
                let r = (1.0 - z * z).sqrt();
                let p = std::f64::consts::TAU * u();
                [r * p.cos(), r * p.sin(), z]
            };
            let (l, v) = (dir(), dir());
            let pair = DirectionPair::from_local(l, v);
            let b = m.basis(&pair);
            assert!(b.specular.is_finite() && b.specular >= 0.0);
            // only the lobe changes, by F(l.h) in [F0, 1]
            let p = plain.basis(&pair);
            assert_eq!(b.diffuse, p.diffuse);
            assert!(
                b.specular <= p.specular + 1e-15
                    && b.specular >= f0.min(0.0533) * p.specular - 1e-15
            );
            // reciprocity and T -> -T
            let swapped = m.basis(&DirectionPair::from_local(v, l));
            let flipped = m.basis(&DirectionPair::from_local(
                [-l[0], -l[1], l[2]],
                [-v[0], -v[1], v[2]],
            ));
            for other in [swapped, flipped] {
                assert!((other.specular - b.specular).abs() <= 1e-10 * b.specular.max(1e-12));
            }
        }
    }
}
