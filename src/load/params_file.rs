//! Parameter files: a TOML or JSON file of parameters (MODEL.md §5) or a `fibrefit fit` result
//! (schema [`RESULT_SCHEMA`]) read as [`RawParams`]; the model layer itself knows only
//! parameters, not files.

use crate::model::params::RawParams;
use anyhow::{anyhow, bail, Result};
use std::path::Path;

/// Schema of the result JSON a fit is exported as (and `score`, `eval`, `render` read back).
pub const RESULT_SCHEMA: &str = "fibrefit-result/1";

impl RawParams {
    /// Read a `.toml` or `.json` file (by extension; otherwise TOML, then JSON).
    pub fn load(path: &Path) -> Result<Self> {
        let text = super::input::read_text_as(path, "parameter file")?;
        let ext = path
            .extension()
            .and_then(|e| e.to_str())
            .unwrap_or("")
            .to_ascii_lowercase();
        let mut raw: RawParams = if ext == "json" {
            let value: serde_json::Value =
                serde_json::from_str(&text).map_err(|e| anyhow!("{}: {e}", path.display()))?;
            if value
                .get("schema")
                .and_then(|s| s.as_str())
                .is_some_and(|s| s.starts_with("fibrefit-result/"))
            {
                from_result_json(&value).map_err(|e| anyhow!("{}: {e}", path.display()))?
            } else {
                serde_json::from_value(value).map_err(|e| anyhow!("{}: {e}", path.display()))?
            }
        } else {
            toml::from_str(&text)
                .map_err(|e| anyhow!("{}: {}", path.display(), e.to_string().trim_end()))?
        };
        if let Some(map) = &raw.topology_map {
            if map.is_relative() {
                raw.topology_map = Some(path.parent().unwrap_or(Path::new(".")).join(map));
            }
        }
        Ok(raw)
    }
}

/// The parameters of a `fibrefit fit` result (schema `fibrefit-result/1`).
fn from_result_json(v: &serde_json::Value) -> Result<RawParams> {
    let schema = v.get("schema").and_then(|s| s.as_str()).unwrap_or_default();
    if schema != RESULT_SCHEMA {
        bail!(
            "result schema `{schema}` is not one this fibrefit ({}) reads: it reads `{}`; \
             a newer fibrefit wrote this file",
            env!("CARGO_PKG_VERSION"),
            RESULT_SCHEMA
        );
    }
    let params = v
        .get("parameters")
        .and_then(|p| p.as_object())
        .ok_or_else(|| anyhow!("result file has no `parameters`"))?;
    let mut flat = serde_json::Map::new();
    flat.insert(
        "model".into(),
        v.get("model")
            .cloned()
            .ok_or_else(|| anyhow!("result file has no `model`"))?,
    );
    for (name, entry) in params {
        let value = entry
            .get("value")
            .cloned()
            .ok_or_else(|| anyhow!("parameter `{name}` has no value"))?;
        flat.insert(name.clone(), value);
    }
    if let Some(k) = v.get("knobs") {
        for key in [
            "quadrature_order",
            "histogram_bins",
            "azimuth_nodes",
            "topology_map",
        ] {
            if let Some(x) = k.get(key) {
                flat.insert(key.into(), x.clone());
            }
        }
    }
    serde_json::from_value(serde_json::Value::Object(flat)).map_err(|e| anyhow!("{e}"))
}
