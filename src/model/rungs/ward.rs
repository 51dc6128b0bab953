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

use crate::model::parameter::{Ability::*, Param};
use crate::model::rung::{
    Cost, LobeAlbedo, LobeSampling, Rung, Sampling, ShaderSection, Symmetry,
};
use crate::model::{Basis, DirectionPair, ShadingModel};
use std::f64::consts::{FRAC_1_PI, PI};

/// The rung.
pub static RUNG: Rung = Rung {
    name: "ward",
    description: "Ward's anisotropic lobe: what most renderers already have",
    abilities: &[WardLobe, FibreDirection],
    build: |a| Box::new(Ward::new(a.alpha_x, a.alpha_y)),
    sampling: Sampling {
        lobe: LobeSampling::Ward,
        diffuse_tube: 0.0,
        diffuse_cosine: 1.0,
        lobe_albedo: LobeAlbedo::Normalised,
        cone_from: None,
    },
    shader: ShaderSection::Sections {
        sections: &["ward"],
        body: "    return fibrefit_ward(l, v, p.extra.x, p.extra.y);\n",
        material_rows: None,
    },
    cost: Cost::ClosedForm,
    auto_rank: Some(2),
    example: &[
        (Param::RhoD, 0.3),
        (Param::RhoS, 0.6),
        (Param::AlphaX, 0.05),
        (Param::AlphaY, 0.2),
    ],
    symmetries: &[Symmetry::SwapAxes {
        along: Param::AlphaX,
        across: Param::AlphaY,
    }],
    renderer: None,
    auto_fuzz: true,
};

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
    fn rung(&self) -> &'static Rung {
        &RUNG
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
