//! `ward`: Ward 1992 anisotropic, in the normalised form of MODEL.md §3:
//!
//! ```text
//! f = rho_d / pi + rho_s exp(-tan^2 th_h (cos^2 ph_h / ax^2 + sin^2 ph_h / ay^2))
//!                  / (4 pi ax ay sqrt((N.l)(N.v)))
//! ```
//!
//! with th_h, ph_h the polar and azimuth angles of the half vector h in the (T, B, N) frame
//! (ax along T, ay along B). The exponent is evaluated as ((h.T/ax)^2 + (h.B/ay)^2) / (h.N)^2,
//! which needs no angles. Seed 004's simplified form divides by (v.n) and diverges at grazing
//! view; this one does not.

use super::{Basis, DirectionPair, ModelId, ShadingModel};
use std::f64::consts::{FRAC_1_PI, PI};

#[derive(Clone, Copy, Debug)]
pub struct Ward {
    alpha_x: f64,
    alpha_y: f64,
}

impl Ward {
    pub fn new(alpha_x: f64, alpha_y: f64) -> Self {
        Self { alpha_x, alpha_y }
    }
}

impl ShadingModel for Ward {
    fn id(&self) -> ModelId {
        ModelId::Ward
    }

    fn basis_above_horizon(&self, pair: &DirectionPair) -> Basis {
        let (l, v) = (&pair.l, &pair.v);
        let (ht, hb, hn) = (l.t + v.t, l.b + v.b, l.n + v.n);
        let e = ((ht / self.alpha_x).powi(2) + (hb / self.alpha_y).powi(2)) / (hn * hn);
        let lobe = (-e).exp() / (4.0 * PI * self.alpha_x * self.alpha_y * (l.n * v.n).sqrt());
        Basis {
            diffuse: FRAC_1_PI,
            specular: lobe,
            substrate: 0.0,
            fuzz: 0.0,
        }
    }
}
