//! The fit's parameters: shape parameters (nonlinear: exponent, spacing, height, map scale, fibre
//! azimuth, Ward roughness) and albedos (linear, per channel), each with a start, bounds and
//! whether it varies. Exponent and Ward roughness are fitted in log space.

use super::config::{FitConfig, ParamEntry};
use crate::model::params::Albedo;
use crate::model::ModelId;
use anyhow::{bail, Result};

pub use crate::model::parameter::{Component, Param};

#[derive(Clone, Debug, PartialEq)]
pub struct ShapeParam {
    pub kind: Param,
    /// External units (degrees for the azimuth).
    pub value: f64,
    pub init: f64,
    pub min: f64,
    pub max: f64,
    pub vary: bool,
}

#[derive(Clone, Debug, PartialEq)]
pub struct AlbedoParam {
    pub component: Component,
    pub name: &'static str,
    /// Per channel (grey data uses channel 0).
    pub value: [f64; 3],
    pub init: [f64; 3],
    pub min: f64,
    pub max: f64,
    pub vary: bool,
    /// One value shared by the channels of RGB data, fitted as one free parameter (`ks` unless
    /// the config asks for `colour = true`); `value` holds it in every channel. Always false for
    /// grey data and for a fixed parameter.
    pub grey: bool,
}

/// All parameters of one fit.
#[derive(Clone, Debug, PartialEq)]
pub struct ParamSet {
    pub rung: ModelId,
    pub shapes: Vec<ShapeParam>,
    pub albedos: Vec<AlbedoParam>,
    /// No `substrate_albedo` listed: the substrate shares `kd` (the model default).
    pub substrate_tied: bool,
    pub channels: usize,
    /// The `gltf` rung's variant (`knobs.gltf_variant`; the default for other rungs).
    pub gltf_variant: crate::model::rungs::gltf::GltfVariant,
}

impl ParamSet {
    /// The parameters of `cfg`'s rung for data with `channels` channels: each listed one as
    /// `[parameters]` gives it (after the `[components]` switches), the others at the table's
    /// start, fit range and default freedom.
    pub fn from_config(cfg: &FitConfig, channels: usize) -> Result<Self> {
        let rung = cfg.model_id()?;
        // components switch parameters on and off on top of [parameters]
        let cfg = &FitConfig {
            parameters: with_components(cfg, rung),
            ..cfg.clone()
        };
        let (spacing0, spacing_max) = spacing_levels(cfg, rung);
        let mut shapes = Vec::new();
        let mut albedos = Vec::new();
        let fuzz_layer = crate::model::parameter::fuzz_parameters()
            .any(|p| cfg.parameters.contains_key(p.name()));
        for param in rung.parameters() {
            let r = Resolved::of(cfg, param, spacing0, spacing_max)?;
            if param.is_fuzz() && !fuzz_layer {
                continue; // an optional component, on when any of its parameters is listed
            }
            match param.component() {
                Some(component) => {
                    if component == Component::Substrate && !r.listed {
                        continue;
                    }
                    albedos.push(r.albedo(param, component, channels)?);
                }
                None => shapes.push(r.shape(param)?),
            }
        }
        let substrate_tied =
            rung.is_cross_section() && !cfg.parameters.contains_key(Param::SubstrateAlbedo.name());
        Ok(ParamSet {
            rung,
            shapes,
            albedos,
            substrate_tied,
            channels,
            gltf_variant: cfg.knobs.gltf_variant,
        })
    }

    pub fn shape(&self, kind: Param) -> Option<&ShapeParam> {
        self.shapes.iter().find(|s| s.kind == kind)
    }

    /// External value of a shape parameter, or the model default when the rung lacks it.
    pub fn shape_value(&self, kind: Param) -> f64 {
        self.shape(kind)
            .map(|s| s.value)
            .unwrap_or(kind.info().absent)
    }

    /// The rung's parameter in lobe role `role` with its value (`None`: the rung has no lobe
    /// a texel map can carry).
    pub fn lobe_shape(&self, role: crate::model::LobeRole) -> Option<&ShapeParam> {
        self.rung.lobe_param(role).and_then(|p| self.shape(p))
    }

    /// The value in lobe role `role` (the gltf table's absent value where the rung has none).
    pub fn lobe_value(&self, role: crate::model::LobeRole) -> f64 {
        use crate::model::LobeRole;
        match self.lobe_shape(role) {
            Some(s) => s.value,
            None => match role {
                LobeRole::Roughness => Param::Roughness.info().absent,
                LobeRole::Anisotropy => Param::AnisotropyStrength.info().absent,
            },
        }
    }

    /// Varying shape parameters, in order.
    pub fn free_shapes(&self) -> Vec<usize> {
        (0..self.shapes.len())
            .filter(|&i| self.shapes[i].vary)
            .collect()
    }

    /// (albedo index, channel) of every varying albedo channel; a grey albedo of RGB data is
    /// one free parameter, listed as channel 0 (its value is every channel's).
    pub fn free_albedos(&self) -> Vec<(usize, usize)> {
        let mut out = Vec::new();
        for (i, a) in self.albedos.iter().enumerate() {
            if a.vary {
                let channels = if a.grey { 1 } else { self.channels };
                for c in 0..channels {
                    out.push((i, c));
                }
            }
        }
        out
    }

    /// Names of the albedos fitted as one grey value for RGB data.
    pub fn grey_albedos(&self) -> Vec<&'static str> {
        self.albedos
            .iter()
            .filter(|a| a.vary && a.grey)
            .map(|a| a.name)
            .collect()
    }
}

/// Per texel: the parameters a `[maps]` request recovers per texel (their global value is only
/// the maps' start).
pub const PER_TEXEL: &str = "per texel (recovered as a map: see [[Maps]])";

/// Set each fixed record's `fixed_reason`: recovered per texel (`per_texel` names), the data give
/// the fibre direction, a `[components]` switch, `vary = false` or equal bounds in the config,
/// an optional component off unless listed, or not listed in a config (held at its default).
pub fn explain_fixed(
    records: &mut [super::ParamRecord],
    cfg: &FitConfig,
    samples: &crate::load::samples::Samples,
    per_texel: &[&str],
) {
    let data_azimuth = samples.samples.iter().all(|s| s.fibre_azimuth.is_some());
    let comp = &cfg.components;
    for r in records.iter_mut() {
        if !r.fixed {
            r.fixed_reason = None;
            continue;
        }
        let name = r.name.as_str();
        let entry = cfg.parameters.get(name);
        let param = Param::from_name(name);
        let is = |p: Param| param == Some(p);
        let why = if per_texel.contains(&name) {
            PER_TEXEL.to_string()
        } else if is(Param::Azimuth) && data_azimuth {
            "the data give the fibre direction (every sample carries it)".to_string()
        } else if !comp.specular && is(Param::Ks) {
            "components.specular = false (no specular lobe)".to_string()
        } else if !comp.specular && is(Param::Exponent) {
            "components.specular = false: without a lobe the exponent means nothing".to_string()
        } else if is(Param::Spacing) && comp.spacing_free == Some(false) {
            "components.spacing_free = false (touching fibres, d = 2)".to_string()
        } else if is(Param::SubstrateAlbedo) && comp.substrate.as_deref() == Some("off") {
            "components.substrate = \"off\"".to_string()
        } else if entry.is_some_and(|e| e.vary == Some(false)) {
            "vary = false in the config".to_string()
        } else if r.min >= r.max {
            format!("its bounds are equal ([{}, {}])", r.min, r.max)
        } else if (is(Param::FresnelIor) || is(Param::AzimuthSpread)) && entry.is_none() {
            format!("an optional component, off unless [parameters] lists `{name}`")
        } else if entry.is_none() {
            format!(
                "not listed in the config's [parameters]: held at its default (list `{name}` to fit it)"
            )
        } else {
            "held fixed".to_string()
        };
        r.fixed_reason = Some(why);
    }
}

/// `cfg`'s `[parameters]` with its `[components]` switches applied: no specular lobe (ks 0,
/// the exponent fixed), a fixed or free spacing, the substrate off, free or tied.
fn with_components(
    cfg: &FitConfig,
    rung: ModelId,
) -> std::collections::BTreeMap<String, ParamEntry> {
    let mut listed_params = cfg.parameters.clone();
    let comp = &cfg.components;
    let (ks, exponent, spacing, substrate) = (
        Param::Ks.name(),
        Param::Exponent.name(),
        Param::Spacing.name(),
        Param::SubstrateAlbedo.name(),
    );
    let fixed_at = |v: f64| ParamEntry {
        value: Some(Albedo::Grey(v)),
        vary: Some(false),
        ..Default::default()
    };
    if !comp.specular && rung.reads(Param::Ks) {
        listed_params.insert(ks.into(), fixed_at(0.0));
        // without a lobe the exponent means nothing: fixed (at its start), not fitted
        listed_params.entry(exponent.into()).or_default().vary = Some(false);
    }
    if comp.spacing_free == Some(false) && rung.reads(Param::Spacing) {
        listed_params.insert(spacing.into(), fixed_at(2.0));
    }
    if comp.spacing_free == Some(true) && rung.reads(Param::Spacing) {
        listed_params.entry(spacing.into()).or_default().vary = Some(true);
    }
    match comp.substrate.as_deref() {
        Some("off") if rung.reads(Param::SubstrateAlbedo) => {
            listed_params.insert(substrate.into(), fixed_at(0.0));
        }
        Some("free") if rung.reads(Param::SubstrateAlbedo) => {
            listed_params.entry(substrate.into()).or_default();
        }
        Some("tied") => {
            listed_params.remove(substrate);
        }
        _ => {}
    }
    listed_params
}

/// The spacing's start and the largest spacing the fit may reach (what levels relative to
/// the spacing are taken at): its bound when free, its value when fixed, 2 for a rung
/// without a cross-section.
fn spacing_levels(cfg: &FitConfig, rung: ModelId) -> (f64, f64) {
    let spacing = Param::Spacing.name();
    let empty = ParamEntry::default();
    let spacing_entry = cfg.parameters.get(spacing).unwrap_or(&empty);
    let spacing0 = spacing_entry.value.map(|v| v.channels()[0]).unwrap_or(2.0);
    let spacing_max = if rung.is_cross_section() {
        if spacing_entry
            .vary
            .unwrap_or(cfg.parameters.contains_key(spacing))
        {
            spacing_entry.max.unwrap_or(20.0)
        } else {
            spacing0
        }
    } else {
        2.0
    };
    (spacing0, spacing_max)
}

/// One parameter as the config gives it (or the table's defaults): bounds checked against
/// the model's limits.
struct Resolved {
    name: &'static str,
    /// The entry's colour choice (`ks` only).
    colour: Option<bool>,
    listed: bool,
    min: f64,
    max: f64,
    vary: bool,
    value: Albedo,
}

impl Resolved {
    fn of(cfg: &FitConfig, param: Param, spacing0: f64, spacing_max: f64) -> Result<Self> {
        let info = param.info();
        let name = info.name;
        let listed = cfg.parameters.contains_key(name);
        let empty = ParamEntry::default();
        let e = cfg.parameters.get(name).unwrap_or(&empty);
        let level = |l: crate::model::parameter::Level| l.at(spacing_max, spacing0);
        let (hard_lo, hard_hi) = (level(info.limits.0), level(info.limits.1));
        let min = e.min.unwrap_or(level(info.fit_range.0));
        let max = e.max.unwrap_or(level(info.fit_range.1));
        if min < hard_lo - 1e-12 || max > hard_hi + 1e-12 {
            bail!("parameters.{name}: bounds [{min}, {max}] exceed the model's range [{hard_lo}, {hard_hi}]");
        }
        let vary = e.vary.unwrap_or(listed || info.free);
        let value = e
            .value
            .unwrap_or(Albedo::Grey(level(info.start).clamp(min, max)));
        Ok(Self {
            name,
            colour: e.colour,
            listed,
            min,
            max,
            vary,
            value,
        })
    }

    /// The albedo of `component`, its start within bounds; grey (one value for every
    /// channel) for the colourless specular weight unless the config asks for colour.
    fn albedo(&self, param: Param, component: Component, channels: usize) -> Result<AlbedoParam> {
        let Self {
            name,
            min,
            max,
            vary,
            value,
            ..
        } = *self;
        if value.is_rgb() && channels == 1 {
            bail!("parameters.{name}: an RGB value for grey data");
        }
        let v = value.channels();
        for x in v {
            if x < min || x > max {
                bail!("parameters.{name}.value = {x} is outside its bounds [{min}, {max}]");
            }
        }
        // the specular weight of dielectric fibres is colourless: one value for all
        // channels unless the config asks for colour (FitConfig::validate refuses an
        // RGB start for it)
        let grey = channels > 1
            && vary
            && param == super::config::COLOUR_CHOICE
            && self.colour != Some(true);
        if grey && value.is_rgb() {
            bail!("parameters.{name}: an RGB start for a grey `{name}`; give one number or `colour = true`");
        }
        Ok(AlbedoParam {
            component,
            name,
            value: v,
            init: v,
            min,
            max,
            vary,
            grey,
        })
    }

    /// The shape parameter, one number within its bounds (fixed when its bounds meet).
    fn shape(&self, param: Param) -> Result<ShapeParam> {
        let Self {
            name,
            min,
            max,
            vary,
            value,
            ..
        } = *self;
        if value.is_rgb() {
            bail!("parameters.{name}: takes one number, not three");
        }
        let v = value.channels()[0];
        if v < min || v > max {
            bail!("parameters.{name}.value = {v} is outside its bounds [{min}, {max}]");
        }
        Ok(ShapeParam {
            kind: param,
            value: v,
            init: v,
            min,
            max,
            vary: vary && min < max,
        })
    }
}
