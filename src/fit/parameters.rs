//! The fit's parameters: shape parameters (nonlinear: exponent, spacing, height, map scale, fibre
//! azimuth, Ward roughness) and albedos (linear, per channel), each with a start, bounds and
//! whether it varies. Exponent and Ward roughness are fitted in log space.

use super::config::{FitConfig, ParamEntry};
use crate::model::fuzz::{ASYMMETRY_RANGE, DEPTH_RANGE};
use crate::model::params::Albedo;
use crate::model::topology::max_height;
use crate::model::ModelId;
use anyhow::{bail, Result};

#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Shape {
    Exponent,
    Spacing,
    Height,
    MapScale,
    Azimuth,
    AlphaX,
    AlphaY,
    AzimuthSpread,
    FresnelIor,
    FuzzDepth,
    FuzzAsymmetry,
}

impl Shape {
    pub fn name(self) -> &'static str {
        match self {
            Shape::Exponent => "exponent",
            Shape::Spacing => "spacing",
            Shape::Height => "height",
            Shape::MapScale => "map_scale",
            Shape::Azimuth => "fibre_azimuth_deg",
            Shape::AlphaX => "alpha_x",
            Shape::AzimuthSpread => "azimuth_spread_deg",
            Shape::FresnelIor => "fresnel_ior",
            Shape::FuzzDepth => "fuzz_depth",
            Shape::FuzzAsymmetry => "fuzz_asymmetry",
            Shape::AlphaY => "alpha_y",
        }
    }

    /// Fitted as ln(value)?
    pub fn log_space(self) -> bool {
        matches!(
            self,
            Shape::Exponent | Shape::AlphaX | Shape::AlphaY | Shape::FuzzDepth
        )
    }

    pub fn to_internal(self, v: f64) -> f64 {
        if self.log_space() {
            v.ln()
        } else {
            v
        }
    }

    pub fn to_external(self, v: f64) -> f64 {
        if self.log_space() {
            v.exp()
        } else {
            v
        }
    }
}

/// The linear components, in basis order.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Component {
    Diffuse,
    Specular,
    Substrate,
    /// The fuzz layer's weight.
    Fuzz,
}

#[derive(Clone, Debug, PartialEq)]
pub struct ShapeParam {
    pub kind: Shape,
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
}

struct Default3 {
    value: f64,
    min: f64,
    max: f64,
    vary: bool,
}

fn defaults(name: &str, spacing_max: f64, spacing0: f64) -> Default3 {
    let d = |value, min, max, vary| Default3 {
        value,
        min,
        max,
        vary,
    };
    match name {
        "kd" => d(0.5, 0.0, 1.0, true),
        "ks" => d(0.2, 0.0, 1.0, true),
        "substrate_albedo" => d(0.5, 0.0, 1.0, true),
        "rho_d" => d(0.3, 0.0, 1.0, true),
        "rho_s" => d(0.2, 0.0, 1.0, true),
        "exponent" => d(20.0, 1.0, 1e4, true),
        "spacing" => d(2.0, 2.0, 20.0, false),
        "height" => d(
            0.5 * max_height(spacing0),
            0.0,
            max_height(spacing_max),
            true,
        ),
        "map_scale" => d(0.0, 0.0, max_height(spacing_max), false),
        "fibre_azimuth_deg" => d(0.0, -90.0, 90.0, false),
        "azimuth_spread_deg" => d(0.0, 0.0, 180.0, false),
        "fresnel_ior" => d(0.0, 0.0, 10.0, false),
        // the fuzz layer, when listed: a thin forward-scattering layer of unit strength to start
        "fuzz" => d(1.0, 0.0, crate::model::fuzz::WEIGHT_MAX, true),
        "fuzz_depth" => d(0.3, DEPTH_RANGE.0, DEPTH_RANGE.1, true),
        "fuzz_asymmetry" => d(0.5, ASYMMETRY_RANGE.0, ASYMMETRY_RANGE.1, true),
        "alpha_x" | "alpha_y" => d(0.2, 0.0011, 1.0, true),
        _ => unreachable!("names come from ModelId::parameter_names"),
    }
}

/// Hard limits of MODEL.md §5 that no config may widen.
fn hard_limits(name: &str, spacing_max: f64) -> (f64, f64) {
    match name {
        "kd" | "ks" | "substrate_albedo" | "rho_d" | "rho_s" => (0.0, 1.0),
        "exponent" => (1.0, 1e4),
        "spacing" => (2.0, 20.0),
        "height" | "map_scale" => (0.0, max_height(spacing_max)),
        "fibre_azimuth_deg" => (-90.0, 90.0),
        "azimuth_spread_deg" => (0.0, 180.0),
        "fresnel_ior" => (0.0, 10.0),
        "fuzz" => (0.0, crate::model::fuzz::WEIGHT_MAX),
        "fuzz_depth" => DEPTH_RANGE,
        "fuzz_asymmetry" => ASYMMETRY_RANGE,
        "alpha_x" | "alpha_y" => (1e-3, 1.0),
        _ => (f64::NEG_INFINITY, f64::INFINITY),
    }
}

impl ParamSet {
    pub fn from_config(cfg: &FitConfig, channels: usize) -> Result<Self> {
        let rung = cfg.model_id()?;
        // components switch parameters on and off on top of [parameters]
        let mut listed_params = cfg.parameters.clone();
        let comp = &cfg.components;
        if !comp.specular && rung.parameter_names().contains(&"ks") {
            listed_params.insert(
                "ks".into(),
                ParamEntry {
                    value: Some(Albedo::Grey(0.0)),
                    vary: Some(false),
                    ..Default::default()
                },
            );
            // without a lobe the exponent means nothing: fixed (at its start), not fitted
            listed_params.entry("exponent".into()).or_default().vary = Some(false);
        }
        if comp.spacing_free == Some(false) && rung.parameter_names().contains(&"spacing") {
            listed_params.insert(
                "spacing".into(),
                ParamEntry {
                    value: Some(Albedo::Grey(2.0)),
                    vary: Some(false),
                    ..Default::default()
                },
            );
        }
        if comp.spacing_free == Some(true) && rung.parameter_names().contains(&"spacing") {
            listed_params.entry("spacing".into()).or_default().vary = Some(true);
        }
        match comp.substrate.as_deref() {
            Some("off") if rung.parameter_names().contains(&"substrate_albedo") => {
                listed_params.insert(
                    "substrate_albedo".into(),
                    ParamEntry {
                        value: Some(Albedo::Grey(0.0)),
                        vary: Some(false),
                        ..Default::default()
                    },
                );
            }
            Some("free") if rung.parameter_names().contains(&"substrate_albedo") => {
                listed_params.entry("substrate_albedo".into()).or_default();
            }
            Some("tied") => {
                listed_params.remove("substrate_albedo");
            }
            _ => {}
        }
        let cfg = &FitConfig {
            parameters: listed_params,
            ..cfg.clone()
        };
        let empty = ParamEntry::default();
        let entry = |name: &str| cfg.parameters.get(name).unwrap_or(&empty);
        let spacing_entry = entry("spacing");
        let spacing0 = spacing_entry.value.map(|v| v.channels()[0]).unwrap_or(2.0);
        let spacing_max = if rung.is_cross_section() {
            if spacing_entry
                .vary
                .unwrap_or(cfg.parameters.contains_key("spacing"))
            {
                spacing_entry.max.unwrap_or(20.0)
            } else {
                spacing0
            }
        } else {
            2.0
        };
        let mut shapes = Vec::new();
        let mut albedos = Vec::new();
        let fuzz_layer = crate::model::FUZZ_PARAMETERS
            .iter()
            .any(|n| cfg.parameters.contains_key(*n));
        for name in rung.parameter_names() {
            let listed = cfg.parameters.contains_key(name);
            let e = entry(name);
            let def = defaults(name, spacing_max, spacing0);
            let (hard_lo, hard_hi) = hard_limits(name, spacing_max);
            let min = e.min.unwrap_or(def.min);
            let max = e.max.unwrap_or(def.max);
            if min < hard_lo - 1e-12 || max > hard_hi + 1e-12 {
                bail!("parameters.{name}: bounds [{min}, {max}] exceed the model's range [{hard_lo}, {hard_hi}]");
            }
            let vary = e.vary.unwrap_or(listed || def.vary);
            let value = e.value.unwrap_or(Albedo::Grey(def.value.clamp(min, max)));
            let albedo_component = match name {
                "kd" | "rho_d" => Some(Component::Diffuse),
                "ks" | "rho_s" => Some(Component::Specular),
                "substrate_albedo" => Some(Component::Substrate),
                "fuzz" => Some(Component::Fuzz),
                _ => None,
            };
            if crate::model::FUZZ_PARAMETERS.contains(&name) && !fuzz_layer {
                continue; // an optional component, on when any of its parameters is listed
            }
            match albedo_component {
                Some(component) => {
                    if component == Component::Substrate && !listed {
                        continue;
                    }
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
                        && name == super::config::COLOUR_CHOICE
                        && e.colour != Some(true);
                    if grey && value.is_rgb() {
                        bail!("parameters.{name}: an RGB start for a grey `{name}`; give one number or `colour = true`");
                    }
                    albedos.push(AlbedoParam {
                        component,
                        name,
                        value: v,
                        init: v,
                        min,
                        max,
                        vary,
                        grey,
                    });
                }
                None => {
                    if value.is_rgb() {
                        bail!("parameters.{name}: takes one number, not three");
                    }
                    let v = value.channels()[0];
                    let kind = match name {
                        "exponent" => Shape::Exponent,
                        "spacing" => Shape::Spacing,
                        "height" => Shape::Height,
                        "map_scale" => Shape::MapScale,
                        "fibre_azimuth_deg" => Shape::Azimuth,
                        "azimuth_spread_deg" => Shape::AzimuthSpread,
                        "fresnel_ior" => Shape::FresnelIor,
                        "fuzz_depth" => Shape::FuzzDepth,
                        "fuzz_asymmetry" => Shape::FuzzAsymmetry,
                        "alpha_x" => Shape::AlphaX,
                        "alpha_y" => Shape::AlphaY,
                        _ => unreachable!(),
                    };
                    if v < min || v > max {
                        bail!("parameters.{name}.value = {v} is outside its bounds [{min}, {max}]");
                    }
                    shapes.push(ShapeParam {
                        kind,
                        value: v,
                        init: v,
                        min,
                        max,
                        vary: vary && min < max,
                    });
                }
            }
        }
        let substrate_tied =
            rung.is_cross_section() && !cfg.parameters.contains_key("substrate_albedo");
        Ok(ParamSet {
            rung,
            shapes,
            albedos,
            substrate_tied,
            channels,
        })
    }

    pub fn shape(&self, kind: Shape) -> Option<&ShapeParam> {
        self.shapes.iter().find(|s| s.kind == kind)
    }

    /// External value of a shape parameter, or the model default when the rung lacks it.
    pub fn shape_value(&self, kind: Shape) -> f64 {
        self.shape(kind).map(|s| s.value).unwrap_or(match kind {
            Shape::Exponent => 1.0,
            Shape::Spacing => 2.0,
            Shape::Height | Shape::MapScale | Shape::Azimuth => 0.0,
            Shape::AlphaX | Shape::AlphaY => 0.2,
            Shape::AzimuthSpread | Shape::FresnelIor => 0.0,
            Shape::FuzzDepth | Shape::FuzzAsymmetry => 0.0, // no layer
        })
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
        let why = if per_texel.contains(&name) {
            PER_TEXEL.to_string()
        } else if name == "fibre_azimuth_deg" && data_azimuth {
            "the data give the fibre direction (every sample carries it)".to_string()
        } else if !comp.specular && matches!(name, "ks" | "exponent") {
            match name {
                "ks" => "components.specular = false (no specular lobe)".to_string(),
                _ => "components.specular = false: without a lobe the exponent means nothing"
                    .to_string(),
            }
        } else if name == "spacing" && comp.spacing_free == Some(false) {
            "components.spacing_free = false (touching fibres, d = 2)".to_string()
        } else if name == "substrate_albedo" && comp.substrate.as_deref() == Some("off") {
            "components.substrate = \"off\"".to_string()
        } else if entry.is_some_and(|e| e.vary == Some(false)) {
            "vary = false in the config".to_string()
        } else if r.min >= r.max {
            format!("its bounds are equal ([{}, {}])", r.min, r.max)
        } else if matches!(name, "fresnel_ior" | "azimuth_spread_deg") && entry.is_none() {
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
