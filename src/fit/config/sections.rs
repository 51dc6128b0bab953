//! The sections of a fit configuration besides `[parameters]`: knobs, optimizer, maps,
//! components, selection, and their defaults.

use super::*;
use crate::model::rungs::gltf::GltfVariant;

#[derive(Clone, Debug, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Knobs {
    #[serde(default = "default_order")]
    pub quadrature_order: usize,
    #[serde(default = "default_bins")]
    pub histogram_bins: usize,
    /// Image captures: every `stride`-th pixel in x and y.
    #[serde(default = "one_usize")]
    pub stride: usize,
    /// Image captures: seeded random fraction of pixels kept.
    #[serde(default = "one_f64")]
    pub fraction: f64,
    /// Nodes of the fibre-direction spread quadrature (used when `azimuth_spread_deg` > 0).
    #[serde(default = "default_azimuth_nodes")]
    pub azimuth_nodes: usize,
    /// Image captures: the global fit uses at most this many texels (a seeded sample, every
    /// image's pixel of each), the statistics over every pixel are computed after; 0: every
    /// texel. A capture at camera resolution over-determines the few global parameters many
    /// times over: their standard errors, from the sample, are honest and only wider.
    #[serde(default = "default_fit_texels")]
    pub fit_texels: usize,
    /// Topology map for goniometric spots (the spot averages over its histogram); relative to
    /// the config file. Image captures carry their own.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub topology_map: Option<PathBuf>,
    /// The `gltf` rung's variant: `khronos` (the specification, default) or `threejs` (what
    /// three.js r187 renders; with `[maps]` its fits hold metallic at 0).
    #[serde(default, skip_serializing_if = "GltfVariant::is_khronos")]
    pub gltf_variant: GltfVariant,
}

/// Texels of a capture's global fit by default (8 images: 262 144 pixel values).
pub const DEFAULT_FIT_TEXELS: usize = 32_768;

fn default_fit_texels() -> usize {
    DEFAULT_FIT_TEXELS
}

impl Default for Knobs {
    fn default() -> Self {
        Self {
            quadrature_order: 16,
            histogram_bins: 16,
            stride: 1,
            fraction: 1.0,
            azimuth_nodes: default_azimuth_nodes(),
            fit_texels: default_fit_texels(),
            topology_map: None,
            gltf_variant: GltfVariant::Khronos,
        }
    }
}

#[derive(Clone, Debug, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Optimizer {
    /// Levenberg–Marquardt iterations per start.
    #[serde(default = "default_iterations")]
    pub max_iterations: u64,
    /// Stop when the relative decrease of the cost in an iteration is below this.
    #[serde(default = "default_tolerance")]
    pub tolerance: f64,
    /// Candidates costed by the global stage (a seeded Latin-hypercube design over the shape
    /// parameters); default 32 + 24 per free shape parameter.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub global_candidates: Option<usize>,
    /// Samples (randomly chosen, seeded) the global stage and the start polishing use.
    #[serde(default = "default_subsample")]
    pub global_subsample: usize,
    /// Solve the albedos exactly inside every step (separable least squares). Off: the albedos
    /// are ordinary parameters of the Levenberg–Marquardt iteration.
    #[serde(default = "yes")]
    pub separable: bool,
}

impl Default for Optimizer {
    fn default() -> Self {
        Self {
            max_iterations: default_iterations(),
            tolerance: default_tolerance(),
            global_candidates: None,
            global_subsample: default_subsample(),
            separable: true,
        }
    }
}

fn default_azimuth_nodes() -> usize {
    crate::model::azimuth_spread::DEFAULT_AZIMUTH_NODES
}

fn default_order() -> usize {
    16
}

fn default_bins() -> usize {
    16
}

fn one_usize() -> usize {
    1
}

fn one_f64() -> f64 {
    1.0
}

fn default_iterations() -> u64 {
    100
}

fn default_tolerance() -> f64 {
    1e-9
}

fn default_subsample() -> usize {
    600
}

fn yes() -> bool {
    true
}

pub(super) fn default_starts() -> usize {
    6
}

/// `[maps]`: which per-texel maps `fit --maps` recovers beside the global parameters, and how.
#[derive(Clone, Debug, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct MapsConfig {
    /// Per-texel height H (the topology map), fibre radii (varying-topology, reference).
    #[serde(default)]
    pub height: bool,
    /// Per-texel fibre azimuth psi (the tangent map), degrees (every rung but lambert).
    #[serde(default)]
    pub fibre_azimuth: bool,
    /// Per-texel diffuse albedo kd (Ward: rho_d), per channel.
    #[serde(default)]
    pub kd: bool,
    /// Per-texel specular weight ks (Ward: rho_s), per channel.
    #[serde(default)]
    pub ks: bool,
    /// Per-texel lobe roughness (`gltf`: glTF's roughness; `principled`: Blender's
    /// Roughness), unitless.
    #[serde(default)]
    pub roughness: bool,
    /// Per-texel anisotropy strength (`gltf`: KHR_materials_anisotropy's), unitless in [0, 1].
    #[serde(default)]
    pub anisotropy_strength: bool,
    /// Per-texel Anisotropic (`principled`: Blender's), unitless in [0, 1].
    #[serde(default)]
    pub anisotropic: bool,
    /// Per-texel specular_roughness (`openpbr`), unitless.
    #[serde(default)]
    pub specular_roughness: bool,
    /// Per-texel specular_roughness_anisotropy (`openpbr`), unitless in [0, 1].
    #[serde(default)]
    pub specular_roughness_anisotropy: bool,
    /// Alternations of (global fit given the maps, per-texel fits given the globals) at most;
    /// they stop earlier when the total cost falls by less than 1e-6 of itself.
    #[serde(default = "default_map_rounds")]
    pub rounds: usize,
    /// Texels (seeded sample) the global fit given the maps uses.
    #[serde(default = "default_global_texels")]
    pub global_texels: usize,
    /// Weight of the optional smoothness prior (0: off): per texel, w * (u - mean of its 4
    /// neighbours)^2 per nonlinear map value u (H in fibre radii, psi in units of 10 degrees),
    /// added to the texel's cost, for texels the images leave undetermined.
    #[serde(default)]
    pub smoothness: f64,
}

fn default_map_rounds() -> usize {
    20
}

fn default_global_texels() -> usize {
    512
}

impl Default for MapsConfig {
    fn default() -> Self {
        Self {
            height: false,
            fibre_azimuth: false,
            kd: false,
            ks: false,
            roughness: false,
            anisotropy_strength: false,
            anisotropic: false,
            specular_roughness: false,
            specular_roughness_anisotropy: false,
            rounds: default_map_rounds(),
            global_texels: default_global_texels(),
            smoothness: 0.0,
        }
    }
}

impl MapsConfig {
    /// Names of the maps requested, in output order.
    pub fn requested(&self) -> Vec<&'static str> {
        [
            ("height", self.height),
            ("fibre_azimuth", self.fibre_azimuth),
            ("kd", self.kd),
            ("ks", self.ks),
            ("roughness", self.roughness),
            ("specular_roughness", self.specular_roughness),
            ("anisotropy_strength", self.anisotropy_strength),
            ("anisotropic", self.anisotropic),
            (
                "specular_roughness_anisotropy",
                self.specular_roughness_anisotropy,
            ),
        ]
        .into_iter()
        .filter(|x| x.1)
        .map(|x| x.0)
        .collect()
    }

    /// The lobe maps requested, each by the name the request gives it (a rung's own parameter
    /// name: `check_request` refuses another rung's), with its role.
    pub fn lobe_maps(&self) -> Vec<(crate::model::LobeRole, &'static str)> {
        use crate::model::LobeRole::{Anisotropy, Roughness};
        [
            (Roughness, "roughness", self.roughness),
            (Roughness, "specular_roughness", self.specular_roughness),
            (Anisotropy, "anisotropy_strength", self.anisotropy_strength),
            (Anisotropy, "anisotropic", self.anisotropic),
            (
                Anisotropy,
                "specular_roughness_anisotropy",
                self.specular_roughness_anisotropy,
            ),
        ]
        .into_iter()
        .filter(|x| x.2)
        .map(|x| (x.0, x.1))
        .collect()
    }

    /// Whether a map of the lobe's value in `role` is requested (by whichever name).
    pub fn lobe(&self, role: crate::model::LobeRole) -> bool {
        self.lobe_maps().iter().any(|m| m.0 == role)
    }

    /// The request with the lobe map in `role` switched on by `name` (a lobe map's name, as
    /// [`MapsConfig::lobe_maps`] gives them).
    pub fn with_lobe_map(mut self, name: &str) -> Self {
        match name {
            "roughness" => self.roughness = true,
            "specular_roughness" => self.specular_roughness = true,
            "anisotropy_strength" => self.anisotropy_strength = true,
            "anisotropic" => self.anisotropic = true,
            "specular_roughness_anisotropy" => self.specular_roughness_anisotropy = true,
            _ => {}
        }
        self
    }
}

/// `[data]`: how a lab's goniometric tables are written, so that it is said once (the column
/// names are `[columns]`). A command-line flag overrides it.
#[derive(Clone, Debug, Default, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct DataSection {
    /// The unit of the angle columns, `"deg"` (the default) or `"rad"` (as `--angles`).
    #[serde(default)]
    pub angles: crate::load::gonio::AngleUnit,
}

impl DataSection {
    /// Whether nothing is set (the section is then not written).
    pub fn is_default(&self) -> bool {
        *self == Self::default()
    }
}

/// Model components (applied on top of `[parameters]`).
#[derive(Clone, Debug, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Components {
    /// false: ks fixed at 0 (no specular lobe).
    #[serde(default = "yes")]
    pub specular: bool,
    /// false: ignore `knobs.topology_map` (spots see a uniform height spread).
    #[serde(default = "yes")]
    pub topology_map: bool,
    /// "tied" (shares kd, the default unless `substrate_albedo` is listed), "free", or "off"
    /// (albedo 0).
    #[serde(default)]
    pub substrate: Option<String>,
    /// false: spacing fixed at 2 (touching fibres).
    #[serde(default)]
    pub spacing_free: Option<bool>,
    /// false (`--no-correction`): never a smooth correction on the rung (`fit::correction`);
    /// true (the default) keeps one where the rung misses what data without sigmas hold and
    /// the correction pays held out.
    #[serde(default = "yes")]
    pub correction: bool,
}

impl Default for Components {
    fn default() -> Self {
        Self {
            specular: true,
            topology_map: true,
            substrate: None,
            spacing_free: None,
            correction: true,
        }
    }
}

#[derive(Clone, Debug, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Selection {
    /// Rungs tried by `--model auto`, cheapest first.
    #[serde(default = "default_rungs")]
    pub rungs: Vec<String>,
    /// Fraction of samples held out (seeded split) when the data are many (at least
    /// `cv_below` samples); fewer are cross-validated instead.
    #[serde(default = "default_holdout")]
    pub holdout: f64,
    /// Relative tolerance on the cross-validated error: with it, the simplest candidate within
    /// this fraction of the best error is chosen instead of the one within one standard error.
    pub tolerance: Option<f64>,
    /// Folds of the k-fold cross-validation (every sample held out once) used below `cv_below`
    /// samples.
    #[serde(default = "default_folds")]
    pub folds: usize,
    /// Data with fewer samples than this are cross-validated in `folds` folds; from this many
    /// on, one seeded split holds out `holdout` of them.
    #[serde(default = "default_cv_below")]
    pub cv_below: usize,
    /// Try every rung with and without the fuzz layer (false, or `--no-fuzz`: only without,
    /// unless `--fuzz` or `[parameters]` asks for the layer, which then goes over every rung).
    #[serde(default = "yes")]
    pub fuzz: bool,
    /// The candidates are ranked on at most this many samples (seeded) with coarse knobs; those
    /// within reach of the best are refined at the config's knobs.
    #[serde(default = "default_rank_samples")]
    pub rank_samples: usize,
    /// Rank with coarse knobs first ([`crate::fit::selection::ranking_config`]); false: every
    /// candidate is measured at the config's knobs (slower, for comparison).
    #[serde(default = "yes")]
    pub coarse_ranking: bool,
}

impl Default for Selection {
    fn default() -> Self {
        Self {
            rungs: default_rungs(),
            holdout: default_holdout(),
            tolerance: None,
            folds: default_folds(),
            cv_below: default_cv_below(),
            fuzz: true,
            rank_samples: default_rank_samples(),
            coarse_ranking: true,
        }
    }
}

fn default_folds() -> usize {
    5
}

fn default_cv_below() -> usize {
    2000
}

fn default_rank_samples() -> usize {
    1000
}

fn default_rungs() -> Vec<String> {
    crate::model::rungs::auto_candidates()
        .iter()
        .map(|id| id.to_string())
        .collect()
}

fn default_holdout() -> f64 {
    0.2
}

pub(super) fn default_metric() -> Metric {
    Metric::Linear
}
