//! A fuzz layer: single scattering by stray fibres above the swatch, the optional component that
//! closes the grazing forward peak of real cloth.
//!
//! Felt, flannel and brushed cloth carry loose fibre ends above the body of the fabric. Light at
//! grazing incidence crosses a long path through them and is scattered forward, towards a viewer
//! on the far side, before it reaches the fibres the rungs describe (Koenderink and Pont's
//! asperity scattering). With `fuzz_depth` = tau > 0, every rung becomes
//!
//! ```text
//! f(l, v) = A f_rung(l, v) + fuzz * P(l, v),
//! A = exp(-tau (1/mu_i + 1/mu_o)),                   mu_i = N.l, mu_o = N.v,
//! P = p_HG(cos a; g) (1 - A) / (4 (mu_i + mu_o)),    cos a = -l.v,
//! p_HG = (1 - g^2) / (4 pi (1 + g^2 - 2 g cos a)^(3/2)),  g = fuzz_asymmetry,
//! ```
//!
//! the single-scattering BRDF of a layer of optical depth tau with a Henyey–Greenstein phase
//! function over the rung it attenuates (Hanrahan and Krueger 1993, first order). `cos a` is the
//! cosine of the scattering angle between the light's travel (-l) and v: g > 0 scatters forward,
//! towards the mirror side at grazing angles. `fuzz` is a linear weight per channel (solved like the
//! albedos); for independent scatterers it would be their single-scattering albedo (<= 1), but
//! fibres are not independent isotropic particles, so fits may exceed 1: read it as the layer's
//! strength. tau = 0 turns the layer off exactly (A = 1, P = 0).
//!
//! Everything is symmetric in l and v (reciprocal) and independent of the fibre direction
//! (T -> -T, the fibre-direction spread and the fibre azimuth commute with it); non-negative; at
//! grazing angles A -> 0 and P stays finite while either direction is above the horizon.

use super::frame::DirectionPair;
use super::{Basis, BasisTransform, ShadingModel, Transformed};
use std::f64::consts::PI;

/// Range of a layer's optical depth tau when it has one (0 turns it off).
pub const DEPTH_RANGE: (f64, f64) = (1e-3, 10.0);
/// Range of the phase asymmetry g.
pub const ASYMMETRY_RANGE: (f64, f64) = (-0.9, 0.95);
/// Largest weight `fuzz`.
pub const WEIGHT_MAX: f64 = 50.0;

/// Henyey–Greenstein phase function (1/sr) at the scattering-angle cosine `cos_a`.
pub fn henyey_greenstein(cos_a: f64, g: f64) -> f64 {
    let d = (1.0 + g * g - 2.0 * g * cos_a).max(1e-300);
    (1.0 - g * g) / (4.0 * PI * d * d.sqrt())
}

/// (attenuation A of the rung, fuzz column P) at a pair above the horizon.
pub fn layer(pair: &DirectionPair, depth: f64, g: f64) -> (f64, f64) {
    let (mi, mo) = (pair.l.n, pair.v.n);
    if !(mi > 0.0 && mo > 0.0) || depth <= 0.0 {
        return (1.0, 0.0);
    }
    let a = (-depth * (1.0 / mi + 1.0 / mo)).exp();
    let cos_a = -(pair.l.t * pair.v.t + pair.l.b * pair.v.b + pair.l.n * pair.v.n);
    let p = henyey_greenstein(cos_a.clamp(-1.0, 1.0), g) * (1.0 - a) / (4.0 * (mi + mo));
    (a, p)
}

/// The layer's attenuation of the rung and its own single-scattering column.
#[derive(Clone)]
pub struct FuzzFactor {
    depth: f64,
    asymmetry: f64,
}

impl FuzzFactor {
    /// The layer of optical depth `depth` and asymmetry `asymmetry`; `None` when `depth` is 0
    /// (no layer, as [`crate::model::with_fuzz`] builds none).
    pub fn of(depth: f64, asymmetry: f64) -> Option<Self> {
        (depth > 0.0).then_some(Self { depth, asymmetry })
    }
}

impl BasisTransform for FuzzFactor {
    fn apply(&self, pair: &DirectionPair, b: Basis) -> Basis {
        let (a, p) = layer(pair, self.depth, self.asymmetry);
        Basis {
            fuzz: b.fuzz * a + p,
            ..b.scaled(a)
        }
    }
}

/// A rung under a fuzz layer.
pub type FuzzLayer = Transformed<FuzzFactor>;

impl FuzzLayer {
    pub fn new(inner: Box<dyn ShadingModel>, depth: f64, asymmetry: f64) -> Self {
        Transformed::with(inner, FuzzFactor { depth, asymmetry })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::poulin_fournier::PoulinFournier;

    fn dirs(seed: &mut u64) -> [f64; 3] {
        let mut u = || {
            *seed ^= *seed << 13;
            *seed ^= *seed >> 7;
            *seed ^= *seed << 17;
            (*seed >> 11) as f64 / (1u64 << 53) as f64
        };
        let z: f64 = 1e-6 + (1.0 - 1e-6) * u();
        let r = (1.0 - z * z).sqrt();
        let p = std::f64::consts::TAU * u();
        [r * p.cos(), r * p.sin(), z]
    }

    #[test]
    fn the_phase_function_is_normalised() {
        for g in [-0.9, -0.3, 0.0, 0.5, 0.9] {
            // int p d omega = 2 pi int_{-1}^{1} p(mu) d mu, midpoint rule
            let n = 200_000;
            let s: f64 = (0..n)
                .map(|k| {
                    let mu = -1.0 + (k as f64 + 0.5) * 2.0 / n as f64;
                    henyey_greenstein(mu, g) * 2.0 / n as f64
                })
                .sum::<f64>()
                * 2.0
                * PI;
            assert!((s - 1.0).abs() < 1e-4, "g {g}: {s}");
        }
    }

    #[test]
    fn the_layer_is_reciprocal_fibre_blind_finite_and_off_at_zero_depth() {
        let m = FuzzLayer::new(Box::new(PoulinFournier::new(2.4, 30.0, 16)), 0.3, 0.6);
        let off = FuzzLayer::new(Box::new(PoulinFournier::new(2.4, 30.0, 16)), 0.0, 0.6);
        let plain = PoulinFournier::new(2.4, 30.0, 16);
        let mut seed = 7u64;
        for _ in 0..2000 {
            let (l, v) = (dirs(&mut seed), dirs(&mut seed));
            let pair = DirectionPair::from_local(l, v);
            let b = m.basis(&pair);
            assert!(b.is_finite() && b.fuzz >= 0.0 && b.diffuse >= 0.0 && b.specular >= 0.0);
            assert_eq!(off.basis(&pair), plain.basis(&pair));
            let swapped = m.basis(&DirectionPair::from_local(v, l));
            let flipped = m.basis(&DirectionPair::from_local(
                [-l[0], -l[1], l[2]],
                [-v[0], -v[1], v[2]],
            ));
            for o in [swapped, flipped] {
                for (x, y) in [
                    (o.fuzz, b.fuzz),
                    (o.diffuse, b.diffuse),
                    (o.specular, b.specular),
                ] {
                    assert!((x - y).abs() <= 1e-10 * y.abs().max(1e-12), "{x} {y}");
                }
            }
            // the fuzz column does not see the fibres: turning them changes nothing
            let turned = layer(
                &DirectionPair::from_local([l[1], -l[0], l[2]], [v[1], -v[0], v[2]]),
                0.3,
                0.6,
            );
            assert!((turned.1 - b.fuzz).abs() <= 1e-12 * b.fuzz.max(1e-12));
        }
        // forward scattering: with g > 0 the grazing mirror side outshines the grazing back side
        let t = 75f64.to_radians();
        let l = [t.sin(), 0.0, t.cos()];
        let fwd = layer(&DirectionPair::from_local(l, [-l[0], 0.0, l[2]]), 0.3, 0.6).1;
        let back = layer(&DirectionPair::from_local(l, l), 0.3, 0.6).1;
        assert!(fwd > 10.0 * back, "{fwd} {back}");
        // at the horizon: zero, never NaN
        let h = DirectionPair::from_local([1.0, 0.0, 0.0], [0.0, 0.0, 1.0]);
        assert_eq!(m.basis(&h), Basis::default());
    }

    #[test]
    fn a_thin_layer_is_the_first_order_term() {
        // tau -> 0: P -> tau p / (4 mu_i mu_o)
        let pair = DirectionPair::from_local([0.6, 0.0, 0.8], [-0.8, 0.0, 0.6]);
        let tau = 1e-6;
        let (_, p) = layer(&pair, tau, 0.4);
        let first = tau * henyey_greenstein(-(-0.48 + 0.48), 0.4) / (4.0 * 0.8 * 0.6);
        assert!((p / first - 1.0).abs() < 1e-5, "{p} {first}");
    }
}
