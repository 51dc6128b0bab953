//! `max-normal` (Banks 1994; Heidrich & Seidel 1998): shade with the single brightest normal.
//!
//! I_d = (kd / pi) sqrt(1 - (l.t)^2),
//! I_s = ks max(0, sqrt(1 - (l.t)^2) sqrt(1 - (v.t)^2) - (l.t)(v.t))^e,
//! and f = I / (N.l). No hiding, shadowing or viewer in the diffuse term.

use crate::model::parameter::{Ability::*, Param};
use crate::model::rung::{Cost, LobeAlbedo, LobeSampling, Rung, Sampling, ShaderSection};
use crate::model::{Basis, DirectionPair, ShadingModel};
use std::f64::consts::FRAC_1_PI;

/// The rung.
pub static RUNG: Rung = Rung {
    name: "max-normal",
    description: "the brightest normal of a fibre only (Banks; Heidrich-Seidel)",
    abilities: &[
        FibreDiffuse,
        SpecularLobe,
        Fresnel,
        FibreDirection,
        DirectionSpread,
    ],
    build: |a| Box::new(MaxNormal::new(a.exponent)),
    sampling: Sampling {
        lobe: LobeSampling::FibreCone,
        diffuse_tube: std::f64::consts::FRAC_PI_2,
        diffuse_cosine: 0.0,
        lobe_albedo: LobeAlbedo::Wallis,
        cone_from: None,
    },
    shader: ShaderSection::Sections {
        sections: &["max_normal"],
        body: "    return fibrefit_max_normal(l, v, p.shape.x);\n",
        material_rows: None,
    },
    cost: Cost::ClosedForm,
    auto_rank: Some(3),
    example: &[(Param::Kd, 0.3), (Param::Ks, 0.6), (Param::Exponent, 100.0)],
    symmetries: &[],
    renderer: None,
    auto_fuzz: true,
};

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
    fn rung(&self) -> &'static Rung {
        &RUNG
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
