//! `poulin-fournier` (Poulin & Fournier 1990): fibres as parallel cylinders on a flat topology
//! (phi = 0), with hiding, shadowing, gaps (spacing d free) and the viewer. MODEL.md §2 evaluated
//! like `varying-topology` at a single flat pattern.

use super::cross_section::Pattern;
use super::varying_topology::GaussSection;
use super::{Basis, DirectionPair, ModelId, ShadingModel};

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
    fn id(&self) -> ModelId {
        ModelId::PoulinFournier
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
