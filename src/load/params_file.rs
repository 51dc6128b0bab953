//! Parameter files: a TOML or JSON file of parameters (MODEL.md §5) read as [`RawParams`]; the
//! model layer itself knows only parameters, not files. A `fibrefit fit` result is read (and
//! written) in one place, `export::result_json`.

use crate::model::params::RawParams;
use anyhow::{anyhow, bail, Result};
use std::path::Path;

impl RawParams {
    /// Read a `.toml` or `.json` parameter file (by extension; otherwise TOML).
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
            if value.get("schema").is_some() {
                bail!(
                    "{}: a result file, not a parameter file: read it with \
                     `export::result_json::read_params`",
                    path.display()
                );
            }
            serde_json::from_value(value).map_err(|e| anyhow!("{}: {e}", path.display()))?
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
