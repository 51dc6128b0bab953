//! The parameter table: every parameter and knob of every rung, once (MODEL.md §5).
//!
//! A parameter is one row of [`TABLE`]: its name as configs, parameter files and results spell
//! it, its unit and meaning, where a fit starts it, the bounds a fit searches by default, the
//! hard limits no config may widen, the coordinate the optimizer moves it in, and which rungs
//! and components read it (an [`Ability`] a rung declares in its own file, or the fuzz layer).
//! Which parameters a rung has, which knobs it reads, and how a fit treats each follow from this
//! table and the rung's abilities; nothing else lists parameter names.

use super::topology::max_height;

/// The spread at which fibre directions are isotropic, degrees (`azimuth_spread::ISOTROPIC_DEG`
/// is this).
pub const ISOTROPIC_SPREAD_DEG: f64 = 180.0;

/// A parameter or knob, by the name configs use ([`Param::name`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Param {
    RhoD,
    RhoS,
    AlphaX,
    AlphaY,
    Kd,
    Ks,
    SubstrateAlbedo,
    Exponent,
    Spacing,
    Height,
    MapScale,
    Azimuth,
    AzimuthSpread,
    FresnelIor,
    Fuzz,
    FuzzDepth,
    FuzzAsymmetry,
    ElevationDeg,
    TopologyMap,
    QuadratureOrder,
    HistogramBins,
    AzimuthNodes,
    TwoSided,
    Ambient,
    GltfLayers,
    Metallic,
    Roughness,
    AnisotropyStrength,
    SpecularFactor,
    Ior,
    Sheen,
    SheenRoughness,
    GltfVariant,
    PrincipledLayers,
    Anisotropic,
    SpecularIorLevel,
    SpecularTint,
    SheenWeight,
    OpenPbrLayers,
    SpecularWeight,
    SpecularRoughness,
    SpecularRoughnessAnisotropy,
    SpecularIor,
    FuzzWeight,
    FuzzRoughness,
}

/// What a rung can do, declared in its own file ([`super::rung::Rung::abilities`]). A
/// parameter is read by the rungs with its [`Reader`]'s ability.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Ability {
    /// A diffuse fibre albedo `kd`.
    FibreDiffuse,
    /// A specular lobe about the fibres' mirror cone (`ks`, `exponent`).
    SpecularLobe,
    /// The lobe takes a Fresnel factor (`fresnel_ior`).
    Fresnel,
    /// The periodic fibre cross-section (`spacing`, the substrate between fibres, the lobe's
    /// quadrature order).
    CrossSection,
    /// Elevations from a topology (`height`, `map_scale`, a topology map).
    Topology,
    /// The topology's heights discretised into a histogram (`histogram_bins`).
    HeightHistogram,
    /// Shading depends on the fibre direction (`fibre_azimuth_deg`).
    FibreDirection,
    /// Takes a spread of fibre directions (`azimuth_spread_deg`, `azimuth_nodes`).
    DirectionSpread,
    /// Ward's anisotropic lobe (`rho_d`, `rho_s`, `alpha_x`, `alpha_y`).
    WardLobe,
    /// Lambert's preview lighting (`two_sided`, `ambient`).
    PreviewLighting,
    /// The glTF 2.0 metallic-roughness BRDF with KHR_materials_sheen, _anisotropy, _specular
    /// and _ior (`metallic`, `roughness`, `anisotropy_strength`, `specular_factor`, `ior`,
    /// `sheen`, `sheen_roughness`, and the layers' unit weight `gltf_layers`).
    GltfMaterial,
    /// Blender's Principled BSDF as Cycles evaluates it (`roughness`, `anisotropic`, `ior`,
    /// `specular_ior_level`, `specular_tint`, `sheen_weight`, `sheen_roughness`, and the layers'
    /// unit weight `principled_layers`).
    PrincipledMaterial,
    /// OpenPBR Surface as MaterialX 1.39 implements it (`specular_roughness`,
    /// `specular_roughness_anisotropy`, `specular_ior`, `specular_weight`, `fuzz_weight`,
    /// `fuzz_roughness`, and the layers' unit weight `openpbr_layers`).
    OpenPbrMaterial,
}

/// Who reads a parameter.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Reader {
    /// Rungs with this ability.
    Rung(Ability),
    /// Rungs with either ability (one value meaning the same in both: the GGX roughness, the
    /// IOR).
    Either(Ability, Ability),
    /// The fuzz layer, over any rung.
    FuzzLayer,
}

/// The basis column an albedo multiplies ([`super::Basis`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Component {
    Diffuse,
    Specular,
    Substrate,
    /// The fuzz layer's weight.
    Fuzz,
}

/// What kind of value a parameter is.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Kind {
    /// Linear in the model (grey or per channel), solved exactly by a fit.
    Albedo(Component),
    /// A nonlinear shape parameter the optimizer moves.
    Shape,
    /// A knob (discretisation, a file, the preview's lighting): set, never fitted.
    Knob,
}

/// How the optimizer moves a shape parameter (see `fit::problem::Coordinate`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Scale {
    /// Linear within its bounds.
    Linear,
    /// ln(value).
    Log,
    /// 1 / value (the spacing: the optics change like the covered fraction 2/d).
    Reciprocal,
    /// Wrapped with this period (degrees) when its bounds span a whole period.
    Periodic(f64),
    /// A fraction of [min, min(max, H_max(d))] at the current spacing d.
    UnderMaxHeight,
}

/// A level that may depend on the spacing: a number, or the largest height H_max(d) =
/// sqrt(d^2 - 1) at the largest spacing a fit allows, or half of H_max at its starting spacing.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Level {
    At(f64),
    MaxHeight,
    HalfMaxHeightAtStart,
}

impl Level {
    /// The number at the largest spacing `spacing_max` and the starting spacing `spacing0`.
    pub fn at(self, spacing_max: f64, spacing0: f64) -> f64 {
        match self {
            Level::At(v) => v,
            Level::MaxHeight => max_height(spacing_max),
            Level::HalfMaxHeightAtStart => 0.5 * max_height(spacing0),
        }
    }
}

/// One row of the parameter table.
#[derive(Clone, Copy, Debug)]
pub struct ParamInfo {
    pub param: Param,
    /// As configs, parameter files and results spell it.
    pub name: &'static str,
    /// Unit, as reports and `--help` state it.
    pub unit: &'static str,
    /// What it means, in one line.
    pub meaning: &'static str,
    pub kind: Kind,
    pub reader: Reader,
    /// The value the model takes when a parameter file omits it (and a fit's value for a rung
    /// that lacks it).
    pub absent: f64,
    /// A fit's default start.
    pub start: Level,
    /// The bounds a fit searches unless its config gives others.
    pub fit_range: (Level, Level),
    /// Limits no config may widen.
    pub limits: (Level, Level),
    /// Fitted unless the config holds it (when the rung has it and it is not optional).
    pub free: bool,
    /// Switched on only when a config lists it: an optional component (Fresnel, the spread,
    /// the fuzz layer) or an albedo (solved exactly, never a shape a fit frees on its own).
    pub listed_only: bool,
    pub scale: Scale,
}

use Level::{At, HalfMaxHeightAtStart, MaxHeight};

const fn row(
    param: Param,
    name: &'static str,
    unit: &'static str,
    meaning: &'static str,
    kind: Kind,
    reader: Reader,
) -> ParamInfo {
    ParamInfo {
        param,
        name,
        unit,
        meaning,
        kind,
        reader,
        absent: 0.0,
        start: At(0.0),
        fit_range: (At(0.0), At(1.0)),
        limits: (At(0.0), At(1.0)),
        free: true,
        listed_only: false,
        scale: Scale::Linear,
    }
}

impl ParamInfo {
    const fn absent(mut self, v: f64) -> Self {
        self.absent = v;
        self
    }
    const fn start(mut self, v: Level) -> Self {
        self.start = v;
        self
    }
    /// Fit range and hard limits alike.
    const fn range(mut self, lo: Level, hi: Level) -> Self {
        self.fit_range = (lo, hi);
        self.limits = (lo, hi);
        self
    }
    const fn fit_range(mut self, lo: Level, hi: Level) -> Self {
        self.fit_range = (lo, hi);
        self
    }
    const fn held(mut self) -> Self {
        self.free = false;
        self
    }
    const fn listed_only(mut self) -> Self {
        self.listed_only = true;
        self
    }
    const fn scale(mut self, s: Scale) -> Self {
        self.scale = s;
        self
    }
}

use super::fuzz::{ASYMMETRY_RANGE, DEPTH_RANGE, WEIGHT_MAX};
use Ability::*;
use Component as C;
use Kind::{Albedo as A, Knob, Shape};
use Reader::{Either, FuzzLayer, Rung as R};

/// Every parameter and knob, in the order rungs list them (a fit's parameters keep this order).
pub const TABLE: [ParamInfo; 45] = [
    row(
        Param::RhoD,
        "rho_d",
        "1",
        "Ward's diffuse albedo",
        A(C::Diffuse),
        R(WardLobe),
    )
    .start(At(0.3))
    .listed_only(),
    row(
        Param::RhoS,
        "rho_s",
        "1",
        "Ward's specular albedo",
        A(C::Specular),
        R(WardLobe),
    )
    .start(At(0.2))
    .listed_only(),
    row(
        Param::AlphaX,
        "alpha_x",
        "1",
        "Ward's roughness along the fibres",
        Shape,
        R(WardLobe),
    )
    .absent(0.2)
    .start(At(0.2))
    .range(At(1e-3), At(1.0))
    .fit_range(At(0.0011), At(1.0))
    .scale(Scale::Log),
    row(
        Param::AlphaY,
        "alpha_y",
        "1",
        "Ward's roughness across the fibres",
        Shape,
        R(WardLobe),
    )
    .absent(0.2)
    .start(At(0.2))
    .range(At(1e-3), At(1.0))
    .fit_range(At(0.0011), At(1.0))
    .scale(Scale::Log),
    row(
        Param::Kd,
        "kd",
        "1",
        "diffuse albedo of the fibres",
        A(C::Diffuse),
        R(FibreDiffuse),
    )
    .start(At(0.5))
    .listed_only(),
    row(
        Param::Ks,
        "ks",
        "1",
        "specular albedo of the fibres' lobe",
        A(C::Specular),
        R(SpecularLobe),
    )
    .start(At(0.2))
    .listed_only(),
    row(
        Param::SubstrateAlbedo,
        "substrate_albedo",
        "1",
        "diffuse albedo of the substrate seen between the fibres (default: kd)",
        A(C::Substrate),
        R(CrossSection),
    )
    .start(At(0.5))
    .listed_only(),
    row(
        Param::Exponent,
        "exponent",
        "1",
        "Phong exponent of the specular lobe",
        Shape,
        R(SpecularLobe),
    )
    .absent(1.0)
    .start(At(20.0))
    .range(At(1.0), At(1e4))
    .scale(Scale::Log),
    row(
        Param::Spacing,
        "spacing",
        "fibre radii",
        "distance between fibre axes d",
        Shape,
        R(CrossSection),
    )
    .absent(2.0)
    .start(At(2.0))
    .range(At(2.0), At(20.0))
    .held()
    .scale(Scale::Reciprocal),
    row(
        Param::Height,
        "height",
        "fibre radii",
        "base height H0 of the climbing fibres",
        Shape,
        R(Topology),
    )
    .start(HalfMaxHeightAtStart)
    .range(At(0.0), MaxHeight)
    .scale(Scale::UnderMaxHeight),
    row(
        Param::MapScale,
        "map_scale",
        "fibre radii",
        "topology map scale s: H = H0 + s (2 m - 1)",
        Shape,
        R(Topology),
    )
    .range(At(0.0), MaxHeight)
    .held()
    .scale(Scale::UnderMaxHeight),
    row(
        Param::Azimuth,
        "fibre_azimuth_deg",
        "degrees",
        "fibre direction psi from the swatch's x axis",
        Shape,
        R(FibreDirection),
    )
    .range(At(-90.0), At(90.0))
    .held()
    .scale(Scale::Periodic(180.0)),
    row(
        Param::AzimuthSpread,
        "azimuth_spread_deg",
        "degrees",
        "spread of the fibre directions about psi (0 aligned, 180 isotropic)",
        Shape,
        R(DirectionSpread),
    )
    .range(At(0.0), At(ISOTROPIC_SPREAD_DEG))
    .held(),
    row(
        Param::FresnelIor,
        "fresnel_ior",
        "1",
        "index of refraction of the lobe's Fresnel factor (0: none)",
        Shape,
        R(Fresnel),
    )
    .range(At(0.0), At(10.0))
    .held()
    .listed_only(),
    row(
        Param::Fuzz,
        "fuzz",
        "1",
        "weight of the fuzz layer per channel",
        A(C::Fuzz),
        FuzzLayer,
    )
    .start(At(1.0))
    .range(At(0.0), At(WEIGHT_MAX))
    .listed_only(),
    row(
        Param::FuzzDepth,
        "fuzz_depth",
        "1",
        "optical depth tau of the fuzz layer (0: none)",
        Shape,
        FuzzLayer,
    )
    .start(At(0.3))
    .range(At(DEPTH_RANGE.0), At(DEPTH_RANGE.1))
    .listed_only()
    .scale(Scale::Log),
    row(
        Param::FuzzAsymmetry,
        "fuzz_asymmetry",
        "1",
        "Henyey-Greenstein asymmetry g of the fuzz layer (> 0 forward)",
        Shape,
        FuzzLayer,
    )
    .start(At(0.5))
    .range(At(ASYMMETRY_RANGE.0), At(ASYMMETRY_RANGE.1))
    .listed_only(),
    row(
        Param::ElevationDeg,
        "elevation_deg",
        "degrees",
        "base elevation of the climbing fibres (instead of height)",
        Knob,
        R(Topology),
    ),
    row(
        Param::TopologyMap,
        "topology_map",
        "file",
        "grayscale topology map m in [0, 1]",
        Knob,
        R(Topology),
    ),
    row(
        Param::QuadratureOrder,
        "quadrature_order",
        "nodes",
        "Gauss-Legendre order N of the specular lobe",
        Knob,
        R(CrossSection),
    ),
    row(
        Param::HistogramBins,
        "histogram_bins",
        "bins",
        "height histogram bins K of a topology",
        Knob,
        R(HeightHistogram),
    ),
    row(
        Param::AzimuthNodes,
        "azimuth_nodes",
        "nodes",
        "quadrature nodes of the fibre-direction spread",
        Knob,
        R(DirectionSpread),
    ),
    row(
        Param::TwoSided,
        "two_sided",
        "bool",
        "preview: light both sides",
        Knob,
        R(PreviewLighting),
    ),
    row(
        Param::Ambient,
        "ambient",
        "1",
        "preview: ambient term, irradiance-relative",
        Knob,
        R(PreviewLighting),
    ),
    // the glTF rung (model/rungs/gltf.rs): base colour is `kd`; everything over the base
    // colour's diffuse (the specular lobes, the sheen) is one column whose weight is 1 in glTF
    row(
        Param::GltfLayers,
        "gltf_layers",
        "1",
        "weight of the glTF layers over the base colour's diffuse (specular lobes, sheen): 1 in glTF",
        A(C::Specular),
        R(GltfMaterial),
    )
    .absent(1.0)
    .start(At(1.0))
    .range(At(1.0), At(1.0))
    .held()
    .listed_only(),
    row(
        Param::Metallic,
        "metallic",
        "1",
        "glTF metallic factor: 0 dielectric, 1 metal (the base colour is then F0)",
        Shape,
        R(GltfMaterial),
    )
    .start(At(0.1)),
    row(
        Param::Roughness,
        "roughness",
        "1",
        "perceptual roughness r (GGX alpha = r^2): glTF's roughness, Blender's Roughness",
        Shape,
        Either(GltfMaterial, PrincipledMaterial),
    )
    .absent(0.5)
    .start(At(0.5))
    .range(At(0.03), At(1.0)),
    row(
        Param::AnisotropyStrength,
        "anisotropy_strength",
        "1",
        "KHR_materials_anisotropy strength: alpha along the fibres = mix(alpha, 1, strength^2)",
        Shape,
        R(GltfMaterial),
    )
    .start(At(0.5)),
    row(
        Param::SpecularFactor,
        "specular_factor",
        "1",
        "KHR_materials_specular factor: scales the dielectric Fresnel (F0 and F90)",
        Shape,
        R(GltfMaterial),
    )
    .absent(1.0)
    .start(At(1.0)),
    row(
        Param::Ior,
        "ior",
        "1",
        "index of refraction, dielectric F0 = ((ior - 1) / (ior + 1))^2: KHR_materials_ior, Blender's IOR",
        Shape,
        Either(GltfMaterial, PrincipledMaterial),
    )
    .absent(1.5)
    .start(At(1.5))
    .range(At(1.01), At(3.0)),
    row(
        Param::Sheen,
        "sheen",
        "1",
        "KHR_materials_sheen colour, grey (one value for every channel)",
        Shape,
        R(GltfMaterial),
    )
    .start(At(0.2)),
    row(
        Param::SheenRoughness,
        "sheen_roughness",
        "1",
        "sheen roughness: glTF's (Charlie alpha = roughness^2), Blender's Sheen Roughness (its LTC table)",
        Shape,
        Either(GltfMaterial, PrincipledMaterial),
    )
    .absent(0.5)
    .start(At(0.5))
    .range(At(0.3), At(1.0)),
    row(
        Param::GltfVariant,
        "gltf_variant",
        "name",
        "whose BRDF: khronos (the specification, default) or threejs (three.js r187)",
        Knob,
        R(GltfMaterial),
    ),
    // Blender's Principled BSDF (model/rungs/principled.rs): base colour is `kd`, the layers over
    // its diffuse (specular, sheen) one column of weight 1; names and ranges are Blender's
    row(
        Param::PrincipledLayers,
        "principled_layers",
        "1",
        "weight of the Principled BSDF's layers over the base colour's diffuse (specular, sheen): 1 in Blender",
        A(C::Specular),
        R(PrincipledMaterial),
    )
    .absent(1.0)
    .start(At(1.0))
    .range(At(1.0), At(1.0))
    .held()
    .listed_only(),
    row(
        Param::Anisotropic,
        "anisotropic",
        "1",
        "Blender's Anisotropic: alpha / aspect across the fibres, alpha aspect along, aspect = sqrt(1 - 0.9 a)",
        Shape,
        R(PrincipledMaterial),
    )
    .start(At(0.5)),
    row(
        Param::SpecularIorLevel,
        "specular_ior_level",
        "1",
        "Blender's Specular IOR Level: F0 x 2 level (0.5: the IOR's own; fitted only when listed: with ior it sets one F0)",
        Shape,
        R(PrincipledMaterial),
    )
    .absent(0.5)
    .start(At(0.5))
    .held()
    .listed_only(),
    row(
        Param::SpecularTint,
        "specular_tint",
        "1",
        "Blender's Specular Tint, grey: scales F0, not the grazing reflectance (fitted only when listed)",
        Shape,
        R(PrincipledMaterial),
    )
    .absent(1.0)
    .start(At(1.0))
    .held()
    .listed_only(),
    row(
        Param::SheenWeight,
        "sheen_weight",
        "1",
        "Blender's Sheen Weight (Sheen Tint white)",
        Shape,
        R(PrincipledMaterial),
    )
    .start(At(0.5)),
    // OpenPBR Surface (model/rungs/openpbr.rs): base colour is `kd`, the layers over its diffuse
    // (specular, fuzz) one column of weight 1; names and ranges are OpenPBR's
    row(
        Param::OpenPbrLayers,
        "openpbr_layers",
        "1",
        "weight of OpenPBR's layers over the base colour's diffuse (specular, fuzz): 1 in OpenPBR",
        A(C::Specular),
        R(OpenPbrMaterial),
    )
    .absent(1.0)
    .start(At(1.0))
    .range(At(1.0), At(1.0))
    .held()
    .listed_only(),
    row(
        Param::SpecularWeight,
        "specular_weight",
        "1",
        "OpenPBR's specular_weight: F0 x weight (1: the IOR's own; fitted only when listed: with specular_ior it sets one F0)",
        Shape,
        R(OpenPbrMaterial),
    )
    .absent(1.0)
    .start(At(1.0))
    .held()
    .listed_only(),
    row(
        Param::SpecularRoughness,
        "specular_roughness",
        "1",
        "OpenPBR's specular_roughness r (GGX alpha = r^2, before the anisotropy)",
        Shape,
        R(OpenPbrMaterial),
    )
    .absent(0.3)
    .start(At(0.5))
    .range(At(0.0), At(1.0))
    .fit_range(At(0.03), At(1.0)),
    row(
        Param::SpecularRoughnessAnisotropy,
        "specular_roughness_anisotropy",
        "1",
        "OpenPBR's specular_roughness_anisotropy a: alpha across the fibres r^2 sqrt(2 / (1 + (1 - a)^2)), along (1 - a) times that",
        Shape,
        R(OpenPbrMaterial),
    )
    .start(At(0.5)),
    row(
        Param::SpecularIor,
        "specular_ior",
        "1",
        "OpenPBR's specular_ior (dielectric F0 = ((ior - 1) / (ior + 1))^2)",
        Shape,
        R(OpenPbrMaterial),
    )
    .absent(1.5)
    .start(At(1.5))
    .range(At(1.01), At(3.0)),
    row(
        Param::FuzzWeight,
        "fuzz_weight",
        "1",
        "OpenPBR's fuzz_weight (fuzz_color white): Zeltner et al.'s sheen over the specular and base",
        Shape,
        R(OpenPbrMaterial),
    )
    .start(At(0.5)),
    row(
        Param::FuzzRoughness,
        "fuzz_roughness",
        "1",
        "OpenPBR's fuzz_roughness (MaterialX clamps it to [0.01, 1])",
        Shape,
        R(OpenPbrMaterial),
    )
    .absent(0.5)
    .start(At(0.5)),
];

impl Param {
    /// Every parameter and knob, in table order.
    pub fn all() -> impl Iterator<Item = Param> {
        TABLE.iter().map(|r| r.param)
    }

    /// The lobe value this parameter is, when a texel map can carry it per texel.
    pub fn lobe_role(self) -> Option<crate::model::LobeRole> {
        use crate::model::LobeRole;
        match self {
            Param::Roughness | Param::SpecularRoughness => Some(LobeRole::Roughness),
            Param::AnisotropyStrength | Param::Anisotropic | Param::SpecularRoughnessAnisotropy => {
                Some(LobeRole::Anisotropy)
            }
            _ => None,
        }
    }

    /// Its row of [`TABLE`].
    pub fn info(self) -> &'static ParamInfo {
        let row = &TABLE[self as usize];
        debug_assert_eq!(row.param, self);
        row
    }

    /// As configs, parameter files and results spell it.
    pub fn name(self) -> &'static str {
        self.info().name
    }

    /// The parameter or knob called `name`.
    pub fn from_name(name: &str) -> Option<Param> {
        TABLE.iter().find(|r| r.name == name).map(|r| r.param)
    }

    pub fn kind(self) -> Kind {
        self.info().kind
    }

    /// A fitted parameter (an albedo or a shape), not a knob.
    pub fn is_fitted(self) -> bool {
        self.kind() != Knob
    }

    /// The albedo's basis column, for albedos.
    pub fn component(self) -> Option<Component> {
        match self.kind() {
            A(c) => Some(c),
            _ => None,
        }
    }

    /// Part of the fuzz layer.
    pub fn is_fuzz(self) -> bool {
        self.info().reader == FuzzLayer
    }

    /// Fitted as ln(value)?
    pub fn log_space(self) -> bool {
        self.info().scale == Scale::Log
    }

    /// The optimizer's internal value (ln for log-space parameters).
    pub fn to_internal(self, v: f64) -> f64 {
        if self.log_space() {
            v.ln()
        } else {
            v
        }
    }

    /// The external value of an internal one.
    pub fn to_external(self, v: f64) -> f64 {
        if self.log_space() {
            v.exp()
        } else {
            v
        }
    }
}

/// The fuzz layer's parameters (its weight, optical depth and phase asymmetry), in table order.
pub fn fuzz_parameters() -> impl Iterator<Item = Param> {
    Param::all().filter(|p| p.is_fuzz())
}

impl std::fmt::Display for Param {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_table_is_indexed_by_the_enum_and_names_are_unique() {
        for (i, r) in TABLE.iter().enumerate() {
            assert_eq!(r.param as usize, i, "{}", r.name);
            assert_eq!(Param::from_name(r.name), Some(r.param));
        }
    }

    #[test]
    fn fit_ranges_lie_within_the_limits() {
        for r in &TABLE {
            let (lo, hi) = (r.limits.0.at(20.0, 2.0), r.limits.1.at(20.0, 2.0));
            let (a, b) = (r.fit_range.0.at(20.0, 2.0), r.fit_range.1.at(20.0, 2.0));
            assert!(lo <= a && b <= hi && a <= b, "{}", r.name);
            if r.kind != Knob {
                let s = r.start.at(20.0, 2.0);
                assert!(a <= s && s <= b, "{} starts outside its range", r.name);
            }
        }
    }
}
