//! Model parameters (MODEL.md §5): read from TOML or JSON, checked against their ranges, and
//! turned into the values models are built from (radians, heights, albedos per channel).

use super::lambert::Preview;
use super::parameter::{Ability, Param};
use super::rungs::gltf::{threejs, GltfVariant};
use super::topology::{max_elevation, max_height, Topology};
use super::{Albedos, ModelId};
use anyhow::{anyhow, bail, Result};
use serde::Deserialize;
use std::path::PathBuf;
use std::sync::Arc;

/// A grey or RGB albedo.
#[derive(Clone, Copy, Debug, Deserialize, PartialEq, serde::Serialize)]
#[serde(untagged)]
pub enum Albedo {
    Grey(f64),
    Rgb([f64; 3]),
}

impl Albedo {
    pub fn channels(&self) -> [f64; 3] {
        match *self {
            Albedo::Grey(v) => [v; 3],
            Albedo::Rgb(c) => c,
        }
    }
    pub fn is_rgb(&self) -> bool {
        matches!(self, Albedo::Rgb(_))
    }
}

/// The parameter file as written by a user (every name of MODEL.md §5 plus the knobs).
#[derive(Clone, Debug, Default, Deserialize, serde::Serialize)]
#[serde(deny_unknown_fields)]
pub struct RawParams {
    /// Model id; optional (the CLI's `--model` wins).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub model: Option<String>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub kd: Option<Albedo>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub ks: Option<Albedo>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub exponent: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub spacing: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub height: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub elevation_deg: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub map_scale: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub fibre_azimuth_deg: Option<f64>,
    /// Spread of the fibre azimuths around psi, degrees (0 aligned, 180 isotropic).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub azimuth_spread_deg: Option<f64>,
    /// Index of refraction of the Fresnel factor on the specular lobe (0: off).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub fresnel_ior: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub substrate_albedo: Option<Albedo>,
    /// Fuzz layer weight per channel (0 to 50; used when `fuzz_depth` > 0).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub fuzz: Option<Albedo>,
    /// Fuzz layer optical depth tau (0: no layer).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub fuzz_depth: Option<f64>,
    /// Fuzz layer Henyey–Greenstein asymmetry g (> 0: forward scattering).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub fuzz_asymmetry: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub alpha_x: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub alpha_y: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub rho_d: Option<Albedo>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub rho_s: Option<Albedo>,
    /// Grayscale PNG/EXR topology map; relative paths are relative to the parameter file.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub topology_map: Option<PathBuf>,
    /// Specular Gauss–Legendre order N (default 16).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub quadrature_order: Option<usize>,
    /// Height histogram bins K (default 16).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub histogram_bins: Option<usize>,
    /// Nodes of the azimuth-spread quadrature (default 16).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub azimuth_nodes: Option<usize>,
    /// `lambert` preview: light both sides (seed 003).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub two_sided: Option<bool>,
    /// `lambert` preview: ambient term (seed 003), irradiance-relative.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub ambient: Option<f64>,
    /// `gltf`: the layers' weight over the base colour's diffuse (1: glTF).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub gltf_layers: Option<Albedo>,
    /// A smooth reciprocal correction of the rung (`model::correction`; a result's
    /// `correction.series`), every rung: the BRDF per channel times its factor.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub correction: Option<super::correction::Correction>,
    /// `gltf`: metallic factor in [0, 1].
    #[serde(skip_serializing_if = "Option::is_none")]
    pub metallic: Option<f64>,
    /// `gltf`: perceptual roughness (alpha = roughness^2).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub roughness: Option<f64>,
    /// `gltf`: KHR_materials_anisotropy strength in [0, 1] (direction: the fibres).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub anisotropy_strength: Option<f64>,
    /// `gltf`: KHR_materials_specular factor in [0, 1].
    #[serde(skip_serializing_if = "Option::is_none")]
    pub specular_factor: Option<f64>,
    /// `gltf`: KHR_materials_ior index of refraction.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub ior: Option<f64>,
    /// `gltf`: KHR_materials_sheen colour (grey) in [0, 1].
    #[serde(skip_serializing_if = "Option::is_none")]
    pub sheen: Option<f64>,
    /// `gltf`: KHR_materials_sheen roughness.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub sheen_roughness: Option<f64>,
    /// `gltf`: whose BRDF (`khronos`, the default, or `threejs`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub gltf_variant: Option<GltfVariant>,
    /// `principled`: the layers' weight over the base colour's diffuse (1: Blender).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub principled_layers: Option<Albedo>,
    /// `principled`: Blender's Anisotropic in [0, 1] (the tangent across the fibres).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub anisotropic: Option<f64>,
    /// `principled`: Blender's Specular IOR Level in [0, 1] (0.5: the IOR's own F0).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub specular_ior_level: Option<f64>,
    /// `principled`: Blender's Specular Tint, grey, in [0, 1].
    #[serde(skip_serializing_if = "Option::is_none")]
    pub specular_tint: Option<f64>,
    /// `principled`: Blender's Sheen Weight in [0, 1] (Sheen Tint white).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub sheen_weight: Option<f64>,
    /// `openpbr`: the layers' weight over the base colour's diffuse (1: OpenPBR).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub openpbr_layers: Option<Albedo>,
    /// `openpbr`: specular_weight in [0, 1] (1: the IOR's own F0).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub specular_weight: Option<f64>,
    /// `openpbr`: specular_roughness in [0, 1].
    #[serde(skip_serializing_if = "Option::is_none")]
    pub specular_roughness: Option<f64>,
    /// `openpbr`: specular_roughness_anisotropy in [0, 1] (the tangent across the fibres).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub specular_roughness_anisotropy: Option<f64>,
    /// `openpbr`: specular_ior.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub specular_ior: Option<f64>,
    /// `openpbr`: fuzz_weight in [0, 1] (fuzz_color white).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub fuzz_weight: Option<f64>,
    /// `openpbr`: fuzz_roughness in [0, 1].
    #[serde(skip_serializing_if = "Option::is_none")]
    pub fuzz_roughness: Option<f64>,
}

pub const DEFAULT_QUADRATURE_ORDER: usize = 16;
/// Largest specular quadrature order N any command accepts.
pub const MAX_QUADRATURE_ORDER: usize = 1024;
/// Largest number of height histogram bins K any command accepts.
pub const MAX_HISTOGRAM_BINS: usize = 65536;
pub const DEFAULT_HISTOGRAM_BINS: usize = 16;

/// Validated parameters in model units.
#[derive(Clone, Debug)]
pub struct ModelParams {
    pub albedos: Albedos,
    pub exponent: f64,
    pub spacing: f64,
    /// psi, radians.
    pub fibre_azimuth: f64,
    pub topology: Topology,
    pub alpha_x: f64,
    pub alpha_y: f64,
    pub quadrature_order: usize,
    pub histogram_bins: usize,
    /// Spread of the fibre azimuths, degrees (0: aligned).
    pub azimuth_spread_deg: f64,
    /// Fresnel factor's index of refraction (0: off).
    pub fresnel_ior: f64,
    /// Fuzz layer optical depth (0: no layer) and phase asymmetry; its weight is in `albedos`.
    pub fuzz_depth: f64,
    pub fuzz_asymmetry: f64,
    pub azimuth_nodes: usize,
    pub preview: Preview,
    /// The `gltf` rung's material (its defaults for other rungs).
    pub gltf: GltfShape,
    /// The `principled` rung's material (its defaults for other rungs).
    pub principled: PrincipledShape,
    /// The `openpbr` rung's material (its defaults for other rungs).
    pub openpbr: OpenPbrShape,
    /// The smooth reciprocal correction on the rung, if any (`model::correction`): the BRDF
    /// per channel times its factor wherever fibrefit shades (eval, render, `Material`).
    pub correction: Option<super::correction::Correction>,
}

fn check_range(name: Param, v: f64, lo: f64, hi: f64) -> Result<f64> {
    if !v.is_finite() {
        bail!("parameter `{name}` is {v}; it must be a finite number in [{lo}, {hi}]");
    }
    if v < lo || v > hi {
        bail!("parameter `{name}` = {v} is out of range [{lo}, {hi}]");
    }
    Ok(v)
}

fn check_albedo(name: Param, a: &Albedo) -> Result<()> {
    for c in a.channels() {
        check_range(name, c, 0.0, 1.0)?;
    }
    Ok(())
}

/// Which parameters and knobs each model reads (for warnings about ignored ones, and so a
/// fit's result carries only the knobs its model reads); names the table does not know (such as
/// `model`) are read by every rung.
pub fn uses(id: ModelId, name: &str) -> bool {
    Param::from_name(name).is_none_or(|p| id.reads(p))
}

impl RawParams {
    /// The value the file gives the renderer rungs' shape parameter `p` (None: not given, or
    /// not such a parameter).
    fn shape_value(&self, p: Param) -> Option<f64> {
        match p {
            Param::Metallic => self.metallic,
            Param::Roughness => self.roughness,
            Param::AnisotropyStrength => self.anisotropy_strength,
            Param::SpecularFactor => self.specular_factor,
            Param::Ior => self.ior,
            Param::Sheen => self.sheen,
            Param::SheenRoughness => self.sheen_roughness,
            Param::Anisotropic => self.anisotropic,
            Param::SpecularIorLevel => self.specular_ior_level,
            Param::SpecularTint => self.specular_tint,
            Param::SheenWeight => self.sheen_weight,
            Param::SpecularWeight => self.specular_weight,
            Param::SpecularRoughness => self.specular_roughness,
            Param::SpecularRoughnessAnisotropy => self.specular_roughness_anisotropy,
            Param::SpecularIor => self.specular_ior,
            Param::FuzzWeight => self.fuzz_weight,
            Param::FuzzRoughness => self.fuzz_roughness,
            _ => None,
        }
    }

    /// Whether the file gives parameter or knob `p`.
    pub fn gives(&self, p: Param) -> bool {
        match p {
            Param::RhoD => self.rho_d.is_some(),
            Param::RhoS => self.rho_s.is_some(),
            Param::AlphaX => self.alpha_x.is_some(),
            Param::AlphaY => self.alpha_y.is_some(),
            Param::Kd => self.kd.is_some(),
            Param::Ks => self.ks.is_some(),
            Param::SubstrateAlbedo => self.substrate_albedo.is_some(),
            Param::Exponent => self.exponent.is_some(),
            Param::Spacing => self.spacing.is_some(),
            Param::Height => self.height.is_some(),
            Param::MapScale => self.map_scale.is_some(),
            Param::Azimuth => self.fibre_azimuth_deg.is_some(),
            Param::AzimuthSpread => self.azimuth_spread_deg.is_some(),
            Param::FresnelIor => self.fresnel_ior.is_some(),
            Param::Fuzz => self.fuzz.is_some(),
            Param::FuzzDepth => self.fuzz_depth.is_some(),
            Param::FuzzAsymmetry => self.fuzz_asymmetry.is_some(),
            Param::ElevationDeg => self.elevation_deg.is_some(),
            Param::TopologyMap => self.topology_map.is_some(),
            Param::QuadratureOrder => self.quadrature_order.is_some(),
            Param::HistogramBins => self.histogram_bins.is_some(),
            Param::AzimuthNodes => self.azimuth_nodes.is_some(),
            Param::TwoSided => self.two_sided.is_some(),
            Param::Ambient => self.ambient.is_some(),
            Param::GltfLayers => self.gltf_layers.is_some(),
            Param::Metallic => self.metallic.is_some(),
            Param::Roughness => self.roughness.is_some(),
            Param::AnisotropyStrength => self.anisotropy_strength.is_some(),
            Param::SpecularFactor => self.specular_factor.is_some(),
            Param::Ior => self.ior.is_some(),
            Param::Sheen => self.sheen.is_some(),
            Param::SheenRoughness => self.sheen_roughness.is_some(),
            Param::GltfVariant => self.gltf_variant.is_some(),
            Param::PrincipledLayers => self.principled_layers.is_some(),
            Param::Anisotropic => self.anisotropic.is_some(),
            Param::SpecularIorLevel => self.specular_ior_level.is_some(),
            Param::SpecularTint => self.specular_tint.is_some(),
            Param::SheenWeight => self.sheen_weight.is_some(),
            Param::OpenPbrLayers => self.openpbr_layers.is_some(),
            Param::SpecularWeight => self.specular_weight.is_some(),
            Param::SpecularRoughness => self.specular_roughness.is_some(),
            Param::SpecularRoughnessAnisotropy => self.specular_roughness_anisotropy.is_some(),
            Param::SpecularIor => self.specular_ior.is_some(),
            Param::FuzzWeight => self.fuzz_weight.is_some(),
            Param::FuzzRoughness => self.fuzz_roughness.is_some(),
        }
    }
}

impl ModelParams {
    /// The lobe a texel map's roughness and anisotropy replace, in model `id`'s own units
    /// (`principled`'s, `openpbr`'s; `gltf`'s for every other rung, which has none).
    pub fn lobe(&self, id: ModelId) -> crate::model::Lobe {
        if id.has(Ability::PrincipledMaterial) {
            self.principled.lobe()
        } else if id.has(Ability::OpenPbrMaterial) {
            self.openpbr.lobe()
        } else {
            self.gltf.lobe()
        }
    }

    /// Check `raw` for model `id`. Returns the parameters and warnings about parameters the model
    /// does not use.
    pub fn from_raw(raw: &RawParams, id: ModelId) -> Result<(Self, Vec<String>)> {
        let warnings = unused_warnings(raw, id);
        let spacing = check_range(Param::Spacing, raw.spacing.unwrap_or(2.0), 2.0, 20.0)?;
        let psi_deg = check_range(
            Param::Azimuth,
            raw.fibre_azimuth_deg.unwrap_or(0.0),
            -90.0,
            90.0,
        )?;
        let exponent = check_range(Param::Exponent, raw.exponent.unwrap_or(1.0), 1.0, 1e4)?;
        let components = Components::from_raw(raw)?;
        let (quadrature_order, histogram_bins) = quadrature_knobs(raw)?;
        let topology = checked_topology(raw, id, spacing)?;
        let (mut albedos, alpha_x, alpha_y) = if id.has(Ability::WardLobe) {
            ward_albedos(raw)?
        } else if id.has(Ability::GltfMaterial) {
            (gltf_albedos(raw, raw.gltf_variant.unwrap_or_default())?, 1.0, 1.0)
        } else if id.has(Ability::PrincipledMaterial) {
            (layered_albedos(raw, id, raw.principled_layers, Param::PrincipledLayers)?, 1.0, 1.0)
        } else if id.has(Ability::OpenPbrMaterial) {
            (layered_albedos(raw, id, raw.openpbr_layers, Param::OpenPbrLayers)?, 1.0, 1.0)
        } else {
            (fibre_albedos(raw, id)?, 1.0, 1.0)
        };
        if components.fuzz_depth > 0.0 {
            albedos.fuzz = components.fuzz.channels();
            albedos.rgb |= components.fuzz.is_rgb();
        }
        let ambient = check_range(Param::Ambient, raw.ambient.unwrap_or(0.0), 0.0, 1.0)?;

        Ok((
            Self {
                albedos,
                exponent,
                spacing,
                fibre_azimuth: psi_deg.to_radians(),
                topology,
                alpha_x,
                alpha_y,
                quadrature_order,
                histogram_bins,
                azimuth_spread_deg: components.azimuth_spread_deg,
                azimuth_nodes: components.azimuth_nodes,
                fresnel_ior: components.fresnel_ior,
                fuzz_depth: components.fuzz_depth,
                fuzz_asymmetry: components.fuzz_asymmetry,
                preview: Preview {
                    two_sided: raw.two_sided.unwrap_or(false),
                    ambient,
                },
                gltf: GltfShape::from_raw(raw)?,
                principled: PrincipledShape::from_raw(raw)?,
                openpbr: OpenPbrShape::from_raw(raw)?,
                correction: match &raw.correction {
                    Some(c) => Some(c.checked().map_err(|e| anyhow!("`correction`: {e}"))?),
                    None => None,
                },
            },
            warnings,
        ))
    }
}

/// A warning for every parameter `raw` gives that model `id` does not read.
fn unused_warnings(raw: &RawParams, id: ModelId) -> Vec<String> {
    let mut warnings = Vec::new();
    // in the order users have always been warned in: the optional components first
    use Param::*;
    let order = [
        Fuzz,
        FuzzDepth,
        FuzzAsymmetry,
        FresnelIor,
        AzimuthSpread,
        AzimuthNodes,
        Kd,
        Ks,
        Exponent,
        Spacing,
        Height,
        ElevationDeg,
        MapScale,
        Azimuth,
        SubstrateAlbedo,
        AlphaX,
        AlphaY,
        RhoD,
        RhoS,
        TopologyMap,
        QuadratureOrder,
        HistogramBins,
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
    ];
    for p in order {
        if raw.gives(p) && !id.reads(p) {
            warnings.push(format!("parameter `{p}` is not used by model `{id}`"));
        }
    }
    warnings
}

/// The values of the optional components (azimuth spread, Fresnel factor, fuzz layer), checked.
struct Components {
    azimuth_spread_deg: f64,
    fresnel_ior: f64,
    fuzz_depth: f64,
    fuzz_asymmetry: f64,
    /// The fuzz layer's weight (used when `fuzz_depth` > 0).
    fuzz: Albedo,
    azimuth_nodes: usize,
}

impl Components {
    /// The components' values in `raw` (defaults: off), each in its range.
    fn from_raw(raw: &RawParams) -> Result<Self> {
        let azimuth_spread_deg = check_range(
            Param::AzimuthSpread,
            raw.azimuth_spread_deg.unwrap_or(0.0),
            0.0,
            super::azimuth_spread::ISOTROPIC_DEG,
        )?;
        let fresnel_ior =
            check_range(Param::FresnelIor, raw.fresnel_ior.unwrap_or(0.0), 0.0, 10.0)?;
        let (fuzz_lo, fuzz_hi) = super::fuzz::DEPTH_RANGE;
        let fuzz_depth = check_range(
            Param::FuzzDepth,
            raw.fuzz_depth.unwrap_or(0.0),
            0.0,
            fuzz_hi,
        )?;
        if fuzz_depth > 0.0 && fuzz_depth < fuzz_lo {
            bail!("parameter `fuzz_depth` = {fuzz_depth}: give 0 (no layer) or a depth in [{fuzz_lo}, {fuzz_hi}]");
        }
        let (g_lo, g_hi) = super::fuzz::ASYMMETRY_RANGE;
        let fuzz_asymmetry = check_range(
            Param::FuzzAsymmetry,
            raw.fuzz_asymmetry.unwrap_or(0.0),
            g_lo,
            g_hi,
        )?;
        let fuzz = raw.fuzz.unwrap_or(Albedo::Grey(0.0));
        for c in fuzz.channels() {
            check_range(Param::Fuzz, c, 0.0, super::fuzz::WEIGHT_MAX)?;
        }
        if fuzz_depth > 0.0 && raw.fuzz.is_none() {
            bail!("parameter `fuzz_depth` > 0 needs the layer's weight `fuzz`");
        }
        let azimuth_nodes = raw
            .azimuth_nodes
            .unwrap_or(super::azimuth_spread::DEFAULT_AZIMUTH_NODES);
        if !(1..=super::azimuth_spread::MAX_AZIMUTH_NODES).contains(&azimuth_nodes) {
            bail!(
                "parameter `azimuth_nodes` = {azimuth_nodes} is out of range [1, {}]",
                super::azimuth_spread::MAX_AZIMUTH_NODES
            );
        }
        Ok(Self {
            azimuth_spread_deg,
            fresnel_ior,
            fuzz_depth,
            fuzz_asymmetry,
            fuzz,
            azimuth_nodes,
        })
    }
}

/// The specular quadrature order N and the height histogram's bins K, each in its range.
fn quadrature_knobs(raw: &RawParams) -> Result<(usize, usize)> {
    let quadrature_order = raw.quadrature_order.unwrap_or(DEFAULT_QUADRATURE_ORDER);
    if !(1..=MAX_QUADRATURE_ORDER).contains(&quadrature_order) {
        bail!("parameter `quadrature_order` = {quadrature_order} is out of range [1, {MAX_QUADRATURE_ORDER}]");
    }
    let histogram_bins = raw.histogram_bins.unwrap_or(DEFAULT_HISTOGRAM_BINS);
    if !(1..=MAX_HISTOGRAM_BINS).contains(&histogram_bins) {
        bail!("parameter `histogram_bins` = {histogram_bins} is out of range [1, {MAX_HISTOGRAM_BINS}]");
    }
    Ok((quadrature_order, histogram_bins))
}

/// The topology: the height (given as `height` or `elevation_deg`, at most the largest the
/// `spacing` allows), the map's scale and the map itself when model `id` reads one.
fn checked_topology(raw: &RawParams, id: ModelId, spacing: f64) -> Result<Topology> {
    let h_max = max_height(spacing);
    let height = match (raw.height, raw.elevation_deg) {
        (Some(_), Some(_)) => bail!("give either `height` or `elevation_deg`, not both"),
        (Some(h), None) => check_range(Param::Height, h, 0.0, h_max * (1.0 + 1e-9))?.min(h_max),
        (None, Some(e)) => {
            let e_max = max_elevation(spacing).to_degrees();
            let e = check_range(Param::ElevationDeg, e, 0.0, e_max * (1.0 + 1e-9))?.min(e_max);
            spacing * e.to_radians().sin()
        }
        (None, None) => 0.0,
    };
    let map_scale = check_range(Param::MapScale, raw.map_scale.unwrap_or(0.0), 0.0, h_max)?;
    let map = match &raw.topology_map {
        Some(path) if id.reads(Param::TopologyMap) => {
            Some(Arc::new(super::topology::TopologyMap::load(path)?))
        }
        _ => None,
    };
    Ok(Topology {
        height,
        map_scale,
        map,
    })
}

/// The Ward rung's albedos (rho_d, rho_s) and roughnesses (alpha_x, alpha_y).
fn ward_albedos(raw: &RawParams) -> Result<(Albedos, f64, f64)> {
    let ax = raw
        .alpha_x
        .ok_or_else(|| anyhow!("model `ward` needs `alpha_x`"))?;
    let ay = raw
        .alpha_y
        .ok_or_else(|| anyhow!("model `ward` needs `alpha_y`"))?;
    check_range(Param::AlphaX, ax, 1e-3, 1.0)?;
    check_range(Param::AlphaY, ay, 1e-3, 1.0)?;
    if ax <= 1e-3 || ay <= 1e-3 {
        bail!("parameters `alpha_x`, `alpha_y` must lie in (0.001, 1]");
    }
    let rho_d = raw.rho_d.unwrap_or(Albedo::Grey(0.0));
    let rho_s = raw
        .rho_s
        .ok_or_else(|| anyhow!("model `ward` needs `rho_s`"))?;
    check_albedo(Param::RhoD, &rho_d)?;
    check_albedo(Param::RhoS, &rho_s)?;
    let a = Albedos {
        diffuse: rho_d.channels(),
        specular: rho_s.channels(),
        substrate: [0.0; 3],
        fuzz: [0.0; 3],
        rgb: rho_d.is_rgb() || rho_s.is_rgb(),
    };
    Ok((a, ax, ay))
}

/// The `gltf` rung's albedos: the base colour `kd` (diffuse column) and the layers' weight
/// (specular column), 1 as glTF defines the material; for the `threejs` variant, the substrate
/// column (its c^2 term, `rungs::gltf::threejs`) takes kd^2.
fn gltf_albedos(raw: &RawParams, variant: GltfVariant) -> Result<Albedos> {
    let kd = raw
        .kd
        .ok_or_else(|| anyhow!("model `gltf` needs `kd` (the base colour)"))?;
    check_albedo(Param::Kd, &kd)?;
    let layers = raw.gltf_layers.unwrap_or(Albedo::Grey(1.0));
    for c in layers.channels() {
        check_range(Param::GltfLayers, c, 1.0, 1.0)?;
    }
    let substrate = match variant {
        GltfVariant::Khronos => [0.0; 3],
        GltfVariant::Threejs => kd.channels().map(|c| c * c),
    };
    Ok(Albedos {
        diffuse: kd.channels(),
        specular: [1.0; 3],
        substrate,
        fuzz: [0.0; 3],
        rgb: kd.is_rgb(),
    })
}

/// The `gltf` rung's shape parameters (MODEL.md's ladder, `model/rungs/gltf.rs`), as a
/// parameter file or a fit gives them.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GltfShape {
    /// metallic factor in [0, 1].
    pub metallic: f64,
    /// Perceptual roughness r (alpha = r^2).
    pub roughness: f64,
    /// KHR_materials_anisotropy strength in [0, 1] along the fibres.
    pub anisotropy: f64,
    /// KHR_materials_specular factor in [0, 1].
    pub specular: f64,
    /// KHR_materials_ior index of refraction.
    pub ior: f64,
    /// KHR_materials_sheen colour, grey.
    pub sheen: f64,
    /// KHR_materials_sheen roughness.
    pub sheen_roughness: f64,
    /// Whose BRDF (`gltf_variant`).
    pub variant: GltfVariant,
}

impl Default for GltfShape {
    /// The parameter table's values for a rung (or file) without them.
    fn default() -> Self {
        Self::of(|p| p.info().absent)
    }
}

impl GltfShape {
    /// The shape with each parameter's value from `value`.
    pub fn of(mut value: impl FnMut(Param) -> f64) -> Self {
        Self {
            metallic: value(Param::Metallic),
            roughness: value(Param::Roughness),
            anisotropy: value(Param::AnisotropyStrength),
            specular: value(Param::SpecularFactor),
            ior: value(Param::Ior),
            sheen: value(Param::Sheen),
            sheen_roughness: value(Param::SheenRoughness),
            variant: GltfVariant::Khronos,
        }
    }

    /// This shape with variant `v`.
    pub fn with_variant(self, variant: GltfVariant) -> Self {
        Self { variant, ..self }
    }

    /// The lobe's roughness and anisotropy strength as given.
    pub fn lobe(&self) -> crate::model::Lobe {
        crate::model::Lobe {
            roughness: self.roughness,
            anisotropy: self.anisotropy,
        }
    }

    /// The roughness and sheen roughness the variant evaluates with: as given (Khronos), or
    /// three.js's (`lights_physical_fragment`): max(roughness, 0.045) (a flat mesh adds no
    /// normal variation) and clamp(sheen roughness, 1e-4, 1).
    pub fn evaluated_roughnesses(&self) -> (f64, f64) {
        match self.variant {
            GltfVariant::Khronos => (self.roughness, self.sheen_roughness),
            GltfVariant::Threejs => (
                self.roughness.clamp(threejs::ROUGHNESS_FLOOR, 1.0),
                self.sheen_roughness
                    .clamp(threejs::SHEEN_ROUGHNESS_FLOOR, 1.0),
            ),
        }
    }

    /// The values in `raw` (the table's absent values where it gives none), each within its
    /// hard limits.
    fn from_raw(raw: &RawParams) -> Result<Self> {
        let shape = checked_shape(raw, |value| Self::of(value))?;
        Ok(shape.with_variant(raw.gltf_variant.unwrap_or_default()))
    }
}

/// A rung's shape made `of` the values in `raw` (the table's absent value where it gives none),
/// each within its hard limits; the first out of range is the error.
fn checked_shape<T>(raw: &RawParams, of: impl FnOnce(&mut dyn FnMut(Param) -> f64) -> T) -> Result<T> {
    let mut err = None;
    let shape = of(&mut |p| {
        let info = p.info();
        let v = raw.shape_value(p).unwrap_or(info.absent);
        let (lo, hi) = (info.limits.0.at(2.0, 2.0), info.limits.1.at(2.0, 2.0));
        match check_range(p, v, lo, hi) {
            Ok(v) => v,
            Err(e) => {
                err.get_or_insert(e);
                info.absent
            }
        }
    });
    match err {
        Some(e) => Err(e),
        None => Ok(shape),
    }
}

/// A renderer material's albedos (`principled`, `openpbr`): the base colour `kd` (diffuse
/// column) and the layers' weight `layers` (specular column), 1 as the renderer defines the
/// material.
fn layered_albedos(raw: &RawParams, id: ModelId, layers: Option<Albedo>, name: Param) -> Result<Albedos> {
    let kd = raw
        .kd
        .ok_or_else(|| anyhow!("model `{id}` needs `kd` (the base colour)"))?;
    check_albedo(Param::Kd, &kd)?;
    for c in layers.unwrap_or(Albedo::Grey(1.0)).channels() {
        check_range(name, c, 1.0, 1.0)?;
    }
    Ok(Albedos {
        diffuse: kd.channels(),
        specular: [1.0; 3],
        substrate: [0.0; 3],
        fuzz: [0.0; 3],
        rgb: kd.is_rgb(),
    })
}

/// The `principled` rung's shape parameters (`model/rungs/principled.rs`), as Blender's
/// Principled BSDF names them, as a parameter file or a fit gives them.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PrincipledShape {
    /// Roughness r (alpha = r^2).
    pub roughness: f64,
    /// Anisotropic in [0, 1], the tangent across the fibres.
    pub anisotropic: f64,
    /// IOR.
    pub ior: f64,
    /// Specular IOR Level (0.5: the IOR's own F0).
    pub specular_ior_level: f64,
    /// Specular Tint, grey.
    pub specular_tint: f64,
    /// Sheen Weight (Sheen Tint white).
    pub sheen_weight: f64,
    /// Sheen Roughness.
    pub sheen_roughness: f64,
}

impl Default for PrincipledShape {
    /// The parameter table's values for a rung (or file) without them.
    fn default() -> Self {
        Self::of(|p| p.info().absent)
    }
}

impl PrincipledShape {
    /// The shape with each parameter's value from `value`.
    pub fn of(mut value: impl FnMut(Param) -> f64) -> Self {
        Self {
            roughness: value(Param::Roughness),
            anisotropic: value(Param::Anisotropic),
            ior: value(Param::Ior),
            specular_ior_level: value(Param::SpecularIorLevel),
            specular_tint: value(Param::SpecularTint),
            sheen_weight: value(Param::SheenWeight),
            sheen_roughness: value(Param::SheenRoughness),
        }
    }

    /// The lobe's roughness and anisotropic as given.
    pub fn lobe(&self) -> crate::model::Lobe {
        crate::model::Lobe {
            roughness: self.roughness,
            anisotropy: self.anisotropic,
        }
    }

    /// The values in `raw` (the table's absent values where it gives none), each within its
    /// hard limits.
    fn from_raw(raw: &RawParams) -> Result<Self> {
        checked_shape(raw, |value| Self::of(value))
    }
}

/// The `openpbr` rung's shape parameters (`model/rungs/openpbr.rs`), as OpenPBR Surface names
/// them, as a parameter file or a fit gives them.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct OpenPbrShape {
    /// specular_weight (1: the IOR's own F0).
    pub specular_weight: f64,
    /// specular_roughness r.
    pub specular_roughness: f64,
    /// specular_roughness_anisotropy in [0, 1], the tangent across the fibres.
    pub specular_roughness_anisotropy: f64,
    /// specular_ior.
    pub specular_ior: f64,
    /// fuzz_weight (fuzz_color white).
    pub fuzz_weight: f64,
    /// fuzz_roughness.
    pub fuzz_roughness: f64,
}

impl Default for OpenPbrShape {
    /// The parameter table's values for a rung (or file) without them.
    fn default() -> Self {
        Self::of(|p| p.info().absent)
    }
}

impl OpenPbrShape {
    /// The shape with each parameter's value from `value`.
    pub fn of(mut value: impl FnMut(Param) -> f64) -> Self {
        Self {
            specular_weight: value(Param::SpecularWeight),
            specular_roughness: value(Param::SpecularRoughness),
            specular_roughness_anisotropy: value(Param::SpecularRoughnessAnisotropy),
            specular_ior: value(Param::SpecularIor),
            fuzz_weight: value(Param::FuzzWeight),
            fuzz_roughness: value(Param::FuzzRoughness),
        }
    }

    /// The lobe's roughness and anisotropy as given.
    pub fn lobe(&self) -> crate::model::Lobe {
        crate::model::Lobe {
            roughness: self.specular_roughness,
            anisotropy: self.specular_roughness_anisotropy,
        }
    }

    /// The values in `raw` (the table's absent values where it gives none), each within its
    /// hard limits.
    fn from_raw(raw: &RawParams) -> Result<Self> {
        checked_shape(raw, |value| Self::of(value))
    }
}

/// A fibre rung's albedos (kd, ks, substrate), those model `id` does not read zero.
fn fibre_albedos(raw: &RawParams, id: ModelId) -> Result<Albedos> {
    let kd = raw
        .kd
        .ok_or_else(|| anyhow!("model `{id}` needs `kd` (fibre diffuse albedo)"))?;
    check_albedo(Param::Kd, &kd)?;
    let ks = raw.ks.unwrap_or(Albedo::Grey(0.0));
    check_albedo(Param::Ks, &ks)?;
    let sub = raw.substrate_albedo.unwrap_or(kd);
    check_albedo(Param::SubstrateAlbedo, &sub)?;
    let uses_spec = id.reads(Param::Ks);
    let ks_c = if uses_spec { ks.channels() } else { [0.0; 3] };
    let sub_c = if id.reads(Param::SubstrateAlbedo) {
        sub.channels()
    } else {
        [0.0; 3]
    };
    Ok(Albedos {
        diffuse: kd.channels(),
        specular: ks_c,
        substrate: sub_c,
        fuzz: [0.0; 3],
        rgb: kd.is_rgb()
            || (uses_spec && ks.is_rgb())
            || (id.reads(Param::SubstrateAlbedo) && sub.is_rgb()),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(text: &str) -> Result<RawParams> {
        toml::from_str(text).map_err(|e| anyhow!("{e}"))
    }

    #[test]
    fn unknown_key_is_named() {
        let err = parse("kd = 0.5\nspacng = 3").unwrap_err().to_string();
        assert!(err.contains("spacng"), "{err}");
    }

    #[test]
    fn out_of_range_is_named() {
        let raw = parse("kd = 0.5\nspacing = 1.5").unwrap();
        let err = ModelParams::from_raw(&raw, ModelId::PoulinFournier)
            .unwrap_err()
            .to_string();
        assert!(err.contains("spacing") && err.contains("1.5"), "{err}");
        let raw = parse("kd = [0.5, 1.2, 0.1]").unwrap();
        let err = ModelParams::from_raw(&raw, ModelId::Lambert)
            .unwrap_err()
            .to_string();
        assert!(err.contains("kd"), "{err}");
    }

    #[test]
    fn elevation_and_height_agree() {
        let raw = parse("kd = 0.5\nelevation_deg = 60").unwrap();
        let (p, _) = ModelParams::from_raw(&raw, ModelId::VaryingTopology).unwrap();
        assert!((p.topology.height - 3f64.sqrt()).abs() < 1e-12);
        let raw = parse("kd = 0.5\nelevation_deg = 61").unwrap();
        assert!(ModelParams::from_raw(&raw, ModelId::VaryingTopology).is_err());
    }

    #[test]
    fn unused_parameters_warn() {
        let raw = parse("kd = 0.5\nalpha_x = 0.2").unwrap();
        let (_, w) = ModelParams::from_raw(&raw, ModelId::Lambert).unwrap();
        assert!(w.iter().any(|s| s.contains("alpha_x")));
    }
}
