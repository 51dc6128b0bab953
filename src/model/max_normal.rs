//! `max-normal` (Banks 1994; Heidrich & Seidel 1998): shade with the single brightest normal.
//!
//! I_d = (kd / pi) sqrt(1 - (l.t)^2),
//! I_s = ks max(0, sqrt(1 - (l.t)^2) sqrt(1 - (v.t)^2) - (l.t)(v.t))^e,
//! and f = I / (N.l). No hiding, shadowing or viewer in the diffuse term.

use super::{Basis, DirectionPair, ModelId, ShadingModel};
use std::f64::consts::FRAC_1_PI;

#[derive(Clone, Copy, Debug)]
pub struct MaxNormal {
    exponent: f64,
}

impl MaxNormal {
    pub fn new(exponent: f64) -> Self {
        Self { exponent }
    }
}

impl ShadingModel for MaxNormal {
    fn id(&self) -> ModelId {
        ModelId::MaxNormal
    }

    fn basis_above_horizon(&self, pair: &DirectionPair) -> Basis {
        let (lt, vt) = (pair.l.t, pair.v.t);
        // sqrt(1 - (w.t)^2) computed as |w_p|, exact even when w.t ~ 1.
        let (lp, vp) = (pair.l.projected_len(), pair.v.projected_len());
        let cos_l = pair.l.n;
        let lobe = (lp * vp - lt * vt).max(0.0);
        Basis {
            diffuse: FRAC_1_PI * lp / cos_l,
            specular: lobe.powf(self.exponent) / cos_l,
            substrate: 0.0,
            fuzz: 0.0,
        }
    }
}
