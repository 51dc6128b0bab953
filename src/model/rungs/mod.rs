//! The registry: what a rung *is*, as one object, and the list of rungs.
//!
//! Each rung's file declares its [`Rung`] (`pub const RUNG`): its id, a one-line description,
//! its abilities (which parameters of [`super::parameter::TABLE`] it reads follow from them),
//! how to build it, how the importance sampler proposes directions for it, its section of the
//! exported shader, its cost class and a typical parameter set. [`ModelId::rung`] is the one
//! place that maps ids to rungs, so adding a rung is: its file, a variant and a line here, its
//! shader section, its tests (ARCHITECTURE.md, "Adding a rung"). Code elsewhere asks the rung
//! (`id.rung().has(Ability::Topology)`), never matches on the id.

pub mod gltf;
pub mod hast_diffuse;
pub mod lambert;
pub mod max_normal;
pub mod poulin_fournier;
pub mod openpbr;
pub mod principled;
pub mod reference;
pub mod varying_topology;
pub mod ward;

use super::parameter::{Ability, Param, Reader};
pub use super::rung::*;
use std::fmt;
use std::str::FromStr;

/// The rungs of the ladder, by the ids the CLI and JSON use.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum ModelId {
    /// Lambert's diffuse (`lambert`).
    Lambert,
    /// The max-normal diffuse (`max-normal`).
    MaxNormal,
    /// Hast et al.'s improved diffuse (`hast-diffuse`).
    HastDiffuse,
    /// Poulin and Fournier's cylinders (`poulin-fournier`).
    PoulinFournier,
    /// Fibres climbing on their neighbours (`varying-topology`).
    VaryingTopology,
    /// The exact reference (`reference`).
    Reference,
    /// Ward's lobe with curvature-aligned tangents (`ward`).
    Ward,
    /// The glTF 2.0 metallic-roughness material with sheen, anisotropy, specular and IOR
    /// (`gltf`).
    Gltf,
    /// Blender 5.0's Principled BSDF as Cycles renders it (`principled`).
    Principled,
    /// OpenPBR Surface as MaterialX 1.39 renders it (`openpbr`).
    OpenPbr,
}

impl fmt::Display for ModelId {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

impl FromStr for ModelId {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        ModelId::ALL
            .iter()
            .copied()
            .find(|m| m.as_str() == s)
            .ok_or_else(|| {
                let ids: Vec<&str> = ModelId::ALL.iter().map(|m| m.as_str()).collect();
                format!(
                    "unknown model id '{s}'; expected one of: {}",
                    ids.join(", ")
                )
            })
    }
}

impl ModelId {
    /// Cheapest first (the exported shader numbers the rungs in this order); `gltf`, added
    /// later, is last so the numbers of the others stay as exported shaders have them.
    pub const ALL: [ModelId; 10] = [
        ModelId::Lambert,
        ModelId::MaxNormal,
        ModelId::HastDiffuse,
        ModelId::Ward,
        ModelId::PoulinFournier,
        ModelId::VaryingTopology,
        ModelId::Reference,
        ModelId::Gltf,
        ModelId::Principled,
        ModelId::OpenPbr,
    ];

    /// The rung this id names: the registry's one `match`.
    pub fn rung(self) -> &'static Rung {
        match self {
            ModelId::Lambert => &lambert::RUNG,
            ModelId::MaxNormal => &max_normal::RUNG,
            ModelId::HastDiffuse => &hast_diffuse::RUNG,
            ModelId::PoulinFournier => &poulin_fournier::RUNG,
            ModelId::VaryingTopology => &varying_topology::RUNG,
            ModelId::Reference => &reference::RUNG,
            ModelId::Ward => &ward::RUNG,
            ModelId::Gltf => &gltf::RUNG,
            ModelId::Principled => &principled::RUNG,
            ModelId::OpenPbr => &openpbr::RUNG,
        }
    }

    /// The id of `rung` (a registered rung's static).
    pub fn of(rung: &Rung) -> ModelId {
        ModelId::ALL
            .into_iter()
            .find(|id| std::ptr::eq(id.rung(), rung))
            .expect("every rung is registered in ModelId::ALL")
    }

    /// The id as the CLI and JSON spell it.
    pub fn as_str(self) -> &'static str {
        self.rung().name
    }

    /// Whether the rung has `ability`.
    pub fn has(self, ability: Ability) -> bool {
        self.rung().has(ability)
    }

    /// Models built on the fibre cross-section of MODEL.md §2 (reciprocal, with hiding and
    /// shadowing).
    pub fn is_cross_section(self) -> bool {
        self.has(Ability::CrossSection)
    }

    /// Models whose elevation comes from the topology (height, map).
    pub fn has_topology(self) -> bool {
        self.has(Ability::Topology)
    }

    /// The fitted parameters of this rung (MODEL.md §5, and the fuzz layer's), in table order.
    pub fn parameters(self) -> Vec<Param> {
        Param::all()
            .filter(|p| p.is_fitted() && self.reads(*p))
            .collect()
    }

    /// Names of the parameters this rung has, as fit configs list them.
    pub fn parameter_names(self) -> Vec<&'static str> {
        self.parameters().into_iter().map(Param::name).collect()
    }

    /// The rung's parameter in lobe role `role` (what a roughness or anisotropy map of its
    /// fit carries, named as the rung names it); `None` for rungs without such a lobe.
    pub fn lobe_param(self, role: crate::model::LobeRole) -> Option<Param> {
        Param::all().find(|p| p.lobe_role() == Some(role) && p.is_fitted() && self.reads(*p))
    }

    /// The rungs with a lobe a texel map can carry, as the CLI names them (for messages).
    pub fn with_lobe_maps() -> String {
        ModelId::ALL
            .into_iter()
            .filter(|m| m.lobe_param(crate::model::LobeRole::Roughness).is_some())
            .map(ModelId::as_str)
            .collect::<Vec<_>>()
            .join(", ")
    }

    /// Whether the rung (or the fuzz layer over it) reads parameter or knob `p`.
    pub fn reads(self, p: Param) -> bool {
        match p.info().reader {
            Reader::Rung(a) => self.has(a),
            Reader::Either(a, b) => self.has(a) || self.has(b),
            Reader::FuzzLayer => true,
        }
    }
}

/// The rungs `--model auto` tries by default, simplest first.
pub fn auto_candidates() -> Vec<ModelId> {
    let mut v: Vec<ModelId> = ModelId::ALL
        .into_iter()
        .filter(|id| id.rung().auto_rank.is_some())
        .collect();
    v.sort_by_key(|id| id.rung().auto_rank);
    v
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_rung_is_registered_under_its_own_id_and_name() {
        for id in ModelId::ALL {
            assert_eq!(ModelId::of(id.rung()), id);
            assert_eq!(id.as_str().parse::<ModelId>(), Ok(id));
        }
    }

    #[test]
    fn every_example_sets_only_the_rungs_parameters() {
        for id in ModelId::ALL {
            for (p, _) in id.rung().example {
                assert!(id.reads(*p), "{id} example sets {p}");
            }
        }
    }

    #[test]
    fn the_ladders_parameter_lists() {
        let names = |id: ModelId| id.parameter_names().join(" ");
        assert_eq!(
            names(ModelId::Ward),
            "rho_d rho_s alpha_x alpha_y fibre_azimuth_deg fuzz fuzz_depth fuzz_asymmetry"
        );
        assert_eq!(
            names(ModelId::VaryingTopology),
            "kd ks substrate_albedo exponent spacing height map_scale fibre_azimuth_deg \
             azimuth_spread_deg fresnel_ior fuzz fuzz_depth fuzz_asymmetry"
        );
        assert_eq!(names(ModelId::Lambert), "kd fuzz fuzz_depth fuzz_asymmetry");
    }
}
