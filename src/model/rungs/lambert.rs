//! `lambert` (seed 003): f = kd / pi, the isotropic baseline.
//!
//! Seed 003 writes the shaded colour as c = c_r c_l max(0, n.l). In fibrefit's convention
//! (MODEL.md §1) that is c = pi * E * I with I = f (N.l) and f = c_r / pi. The seed's preview
//! variants (two-sided and ambient) are [`preview_intensity`].

use crate::model::parameter::{Ability::*, Param};
use crate::model::rung::{Cost, LobeAlbedo, LobeSampling, Rung, Sampling, ShaderSection};
use crate::model::{Basis, DirectionPair, ShadingModel};
use std::f64::consts::FRAC_1_PI;

/// The rung.
pub static RUNG: Rung = Rung {
    name: "lambert",
    description: "isotropic baseline, f = kd/pi",
    abilities: &[FibreDiffuse, PreviewLighting],
    build: |_| Box::new(Lambert),
    sampling: Sampling {
        lobe: LobeSampling::None,
        diffuse_tube: 0.0,
        diffuse_cosine: 1.0,
        lobe_albedo: LobeAlbedo::Normalised,
        cone_from: None,
    },
    shader: ShaderSection::Sections {
        sections: &["lambert"],
        body: "    return fibrefit_lambert(l, v);\n",
        material_rows: None,
    },
    cost: Cost::ClosedForm,
    auto_rank: Some(0),
    example: &[(Param::Kd, 0.5)],
    symmetries: &[],
    renderer: None,
    auto_fuzz: true,
};

#[derive(Clone, Copy, Debug, Default)]
pub struct Lambert;

impl ShadingModel for Lambert {
    fn rung(&self) -> &'static Rung {
        &RUNG
    }

    fn basis_above_horizon(&self, _pair: &DirectionPair) -> Basis {
        Basis {
            diffuse: FRAC_1_PI,
            ..Basis::default()
        }
    }
}

/// Seed 003's shading variants for preview, in intensity units (I = f * cosine):
/// one-sided `max(0, N.l)`, two-sided `|N.l|` (lit from both sides), and an ambient term
/// `ambient` (irradiance-relative, added before the albedo: c = c_r (c_a + c_l max(0, n.l))).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Preview {
    pub two_sided: bool,
    pub ambient: f64,
}

/// Preview intensity per unit albedo for light cosine `cos_l` = N.l.
pub fn preview_intensity(preview: &Preview, cos_l: f64) -> f64 {
    let c = if preview.two_sided {
        cos_l.abs()
    } else {
        cos_l.max(0.0)
    };
    FRAC_1_PI * (preview.ambient + c)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn seed_003_colour_is_pi_times_intensity() {
        // c = c_r c_l max(0, n.l) with c_r = 0.8, c_l = 1, n.l = 0.6
        let pair = DirectionPair::from_local([0.0, 0.8, 0.6], [0.0, 0.0, 1.0]);
        let f = Lambert.basis(&pair).diffuse * 0.8;
        let i = crate::model::intensity(f, &pair);
        assert!((std::f64::consts::PI * i - 0.8 * 0.6).abs() < 1e-15);
    }

    #[test]
    fn preview_variants() {
        let one = Preview::default();
        let two = Preview {
            two_sided: true,
            ambient: 0.0,
        };
        let amb = Preview {
            two_sided: false,
            ambient: 0.2,
        };
        assert_eq!(preview_intensity(&one, -0.5), 0.0);
        assert!((preview_intensity(&two, -0.5) - 0.5 / std::f64::consts::PI).abs() < 1e-16);
        assert!((preview_intensity(&amb, -0.5) - 0.2 / std::f64::consts::PI).abs() < 1e-16);
    }
}
