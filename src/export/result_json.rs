//! The renderer JSON (schema `fibrefit-result/1`, documented in the README): the fitted model
//! with its conventions, parameters and uncertainties, statistics, knobs, provenance, check
//! values for renderer ports, and a Ward fallback.

use crate::fit::config::FitConfig;
use crate::fit::FitOutcome;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

pub const SCHEMA: &str = crate::fit::RESULT_SCHEMA;

#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct ResultFile {
    pub schema: String,
    pub tool: String,
    pub model: String,
    pub conventions: Conventions,
    pub parameters: BTreeMap<String, ParamOut>,
    pub correlations: Vec<Correlation>,
    pub statistics: serde_json::Value,
    pub knobs: Knobs,
    pub data: Provenance,
    pub check_values: Vec<CheckValue>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub ward_fallback: Option<WardFallback>,
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub model_selection: Vec<serde_json::Value>,
    /// Fit quality: noise verdict, distinct minima, residual structure (absent in files written
    /// before it existed).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub quality: Option<serde_json::Value>,
    /// `fit --maps`: the recovered per-texel maps (files, units, grid) and how they were found.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub maps: Option<serde_json::Value>,
    pub warnings: Vec<String>,
}

#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Conventions {
    pub frame: String,
    pub angles: String,
    pub lengths: String,
    pub brdf: String,
    pub intensity: String,
    pub albedos: String,
}

impl Default for Conventions {
    fn default() -> Self {
        Self {
            frame: "swatch normal N = +z; fibre tangent T = (cos psi, sin psi, 0), psi = fibre_azimuth_deg; B = N x T; T and -T are the same fibres".into(),
            angles: "degrees; theta from N, phi from the swatch x axis towards y; directions point away from the surface".into(),
            lengths: "fibre radii (spacing, height, map_scale)".into(),
            brdf: "f(l, v) in 1/sr; 0 when l or v is at or below the horizon".into(),
            intensity: "I = f cos(theta_i): radiance per unit irradiance perpendicular to the light; a shader's colour per light is E * I (seed 003's Lambert c = pi * I)".into(),
            albedos: "grey: one number; RGB: [r, g, b], linear".into(),
        }
    }
}

#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct ParamOut {
    /// A number, or [r, g, b].
    pub value: serde_json::Value,
    pub std_error: serde_json::Value,
    pub min: f64,
    pub max: f64,
    pub fixed: bool,
    pub at_bound: bool,
}

#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Correlation {
    pub a: String,
    pub b: String,
    pub r: f64,
}

#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Knobs {
    pub metric: String,
    pub quadrature_order: usize,
    pub histogram_bins: usize,
    /// Nodes of the fibre-direction spread quadrature.
    #[serde(default)]
    pub azimuth_nodes: usize,
    pub stride: usize,
    pub fraction: f64,
    /// Image captures: the texels the global fit used at most (0: all).
    #[serde(default)]
    pub fit_texels: usize,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub topology_map: Option<String>,
    pub separable: bool,
    pub starts: usize,
    pub seed: u64,
}

#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Provenance {
    pub file: String,
    pub sha256: String,
    pub kind: String,
    pub samples: usize,
    pub channels: usize,
}

#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct CheckValue {
    pub theta_i: f64,
    pub phi_i: f64,
    pub theta_o: f64,
    pub phi_o: f64,
    /// BRDF per channel, 1/sr (one entry for grey).
    pub brdf: Vec<f64>,
}

#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct WardFallback {
    pub model: String,
    pub parameters: BTreeMap<String, serde_json::Value>,
    /// Over the dense direction set it was fitted on, against the fitted model: 1/sr.
    pub rms_error: f64,
    pub relative_rms_error: f64,
    pub directions: usize,
}

/// Fixed direction pairs (degrees) for check values: in-plane, cross-plane, grazing, mirror.
pub fn check_directions() -> Vec<[f64; 4]> {
    let mut v = Vec::new();
    for &(ti, pi, to, po) in &[
        (0.0, 0.0, 0.0, 0.0),
        (30.0, 90.0, 30.0, 90.0),
        (30.0, 90.0, 30.0, 270.0),
        (45.0, 0.0, 45.0, 180.0),
        (45.0, 0.0, 45.0, 0.0),
        (60.0, 45.0, 20.0, 225.0),
        (60.0, 135.0, 60.0, 315.0),
        (10.0, 200.0, 70.0, 20.0),
        (75.0, 90.0, 75.0, 270.0),
        (75.0, 0.0, 75.0, 180.0),
        (85.0, 30.0, 10.0, 210.0),
        (20.0, 300.0, 50.0, 120.0),
        (40.0, 10.0, 40.0, 100.0),
        (50.0, 250.0, 30.0, 250.0),
        (65.0, 170.0, 35.0, 350.0),
        (5.0, 0.0, 80.0, 90.0),
        (35.0, 60.0, 55.0, 240.0),
        (70.0, 330.0, 45.0, 150.0),
        (25.0, 120.0, 65.0, 300.0),
        (80.0, 270.0, 80.0, 90.0),
    ] {
        v.push([ti, pi, to, po]);
    }
    v
}

/// One number, or [r, g, b].
pub fn number_or_rgb(v: &[f64]) -> serde_json::Value {
    if v.len() == 1 {
        serde_json::json!(v[0])
    } else {
        serde_json::json!(v)
    }
}

pub fn params_out(outcome: &FitOutcome) -> BTreeMap<String, ParamOut> {
    let mut out = BTreeMap::new();
    for r in &outcome.records {
        let se: Vec<serde_json::Value> = r
            .std_error
            .iter()
            .map(|e| e.map_or(serde_json::Value::Null, |x| serde_json::json!(x)))
            .collect();
        out.insert(
            r.name.clone(),
            ParamOut {
                value: number_or_rgb(&r.value),
                std_error: if se.len() == 1 {
                    se[0].clone()
                } else {
                    serde_json::Value::Array(se)
                },
                min: r.min,
                max: r.max,
                fixed: r.fixed,
                at_bound: r.at_bound.iter().any(|&b| b),
            },
        );
    }
    out
}

pub fn knobs(cfg: &FitConfig, stride: usize, fraction: f64) -> Knobs {
    Knobs {
        metric: format!("{:?}", cfg.metric).to_lowercase(),
        quadrature_order: cfg.knobs.quadrature_order,
        histogram_bins: cfg.knobs.histogram_bins,
        azimuth_nodes: cfg.knobs.azimuth_nodes,
        stride,
        fraction,
        fit_texels: cfg.knobs.fit_texels,
        topology_map: cfg
            .knobs
            .topology_map
            .as_ref()
            .map(|p| p.display().to_string()),
        separable: cfg.optimizer.separable,
        starts: cfg.starts,
        seed: cfg.seed,
    }
}
