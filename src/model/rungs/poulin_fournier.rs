//! `poulin-fournier` (Poulin & Fournier 1990): fibres as parallel cylinders on a flat topology
//! (phi = 0), with hiding, shadowing, gaps (spacing d free) and the viewer. MODEL.md §2 evaluated
//! like `varying-topology` at a single flat pattern.

use crate::model::cross_section::Pattern;
use crate::model::parameter::{Ability::*, Param};
use crate::model::rung::{Cost, LobeAlbedo, LobeSampling, Rung, Sampling, ShaderSection};
use crate::model::varying_topology::GaussSection;
use crate::model::{Basis, DirectionPair, ShadingModel};

/// The rung.
pub static RUNG: Rung = Rung {
    name: "poulin-fournier",
    description: "parallel cylinders: hiding, shadowing, gaps between fibres, the viewer",
    abilities: &[
        FibreDiffuse,
        SpecularLobe,
        Fresnel,
        CrossSection,
        FibreDirection,
        DirectionSpread,
    ],
    build: |a| {
        Box::new(PoulinFournier::new(
            a.spacing,
            a.exponent,
            a.quadrature_order,
        ))
    },
    sampling: Sampling {
        lobe: LobeSampling::FibreCone,
        diffuse_tube: 0.0,
        diffuse_cosine: 1.0,
        lobe_albedo: LobeAlbedo::ConeTable,
        cone_from: Some(&RUNG),
    },
    shader: ShaderSection::Sections {
        sections: &["cross_section"],
        body: "    let sp = fibrefit_pair(l, v, p.shape.w);
    let b = fibrefit_pattern(sp, p.shape.y, 0.0, 1.0, p.shape.x);
    return vec4<f32>(b, 0.0);\n",
        material_rows: None,
    },
    cost: Cost::Quadrature,
    auto_rank: Some(4),
    example: &[
        (Param::Kd, 0.3),
        (Param::Ks, 0.6),
        (Param::Exponent, 100.0),
        (Param::Spacing, 2.6),
    ],
    symmetries: &[],
    renderer: None,
    auto_fuzz: true,
};

#[derive(Clone, Debug)]
pub struct PoulinFournier {
    pattern: Pattern,
    section: GaussSection,
}

impl PoulinFournier {
    pub fn new(spacing: f64, exponent: f64, order: usize) -> Self {
        Self {
            pattern: Pattern::flat(spacing),
            section: GaussSection::new(exponent, order),
        }
    }
}

impl ShadingModel for PoulinFournier {
    fn rung(&self) -> &'static Rung {
        &RUNG
    }

    fn basis_above_horizon(&self, pair: &DirectionPair) -> Basis {
        let mut out = [Basis::default()];
        self.basis_many(std::slice::from_ref(pair), &mut out);
        out[0]
    }

    fn basis_many(&self, pairs: &[DirectionPair], out: &mut [Basis]) {
        self.section.bases(pairs, &[(self.pattern, 1.0)], out);
    }
}
