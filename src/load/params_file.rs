//! Parameter files: a TOML or JSON file of parameters (MODEL.md §5) read as [`RawParams`]; the
//! model layer itself knows only parameters, not files. A `fibrefit fit` result is read (and
//! written) in one place, `export::result_json`.

use crate::model::params::RawParams;
use anyhow::{anyhow, bail, Result};
use std::path::Path;

impl RawParams {
    /// Read a `.toml` or `.json` parameter file (by extension; otherwise TOML).
    pub fn load(path: &Path) -> Result<Self> {
        if path.is_dir() {
            bail!(
                "{}: is a directory; expected a result JSON written by `fibrefit fit` or a \
                 parameter TOML",
                path.display()
            );
        }
        let ext = path
            .extension()
            .and_then(|e| e.to_str())
            .unwrap_or("")
            .to_ascii_lowercase();
        // measurements are not parameters: say what is expected, not a TOML parse error
        if let Some(kind) = match ext.as_str() {
            "csv" | "tsv" => Some("a goniometric data file (CSV or TSV)"),
            "bsdf" | "binary" => Some("a measured-BRDF file"),
            "exr" | "png" | "jpg" | "jpeg" | "tif" | "tiff" => Some("an image"),
            _ => None,
        } {
            bail!(
                "{}: {kind}, not parameters: expected a result JSON written by `fibrefit fit` \
                 or a parameter TOML (MODEL.md §5); to get one from these data, fit them first: \
                 fibrefit fit {} --model auto --out result.json",
                path.display(),
                path.display()
            );
        }
        let text = super::input::read_text_as(path, "parameter file")?;
        let mut raw: RawParams = if ext == "json" {
            let value: serde_json::Value =
                serde_json::from_str(&text).map_err(|e| anyhow!("{}: {e}", path.display()))?;
            if value.get("partial").and_then(|p| p.as_bool()) == Some(true) {
                bail!(
                    "{}: a partial result of an interrupted `fit --model auto` (it lists the rungs \
                     finished, but no fitted model): run the fit again to finish it",
                    path.display()
                );
            }
            if value.get("schema").is_some() {
                bail!(
                    "{}: a result file, not a parameter file: read it with \
                     `export::result_json::read_params`",
                    path.display()
                );
            }
            serde_json::from_value(value).map_err(|e| anyhow!("{}: {e}", path.display()))?
        } else {
            toml::from_str(&text).map_err(|e| {
                let capture = text.contains("[swatch]") || text.contains("[[images]]");
                anyhow!(
                    "{}: {}{}",
                    path.display(),
                    e.to_string().trim_end(),
                    if capture {
                        "\n(this is an image capture description, not parameters: expected a \
                         result JSON written by `fibrefit fit` or a parameter TOML)"
                    } else {
                        ""
                    }
                )
            })?
        };
        if let Some(map) = &raw.topology_map {
            if map.is_relative() {
                raw.topology_map = Some(path.parent().unwrap_or(Path::new(".")).join(map));
            }
        }
        Ok(raw)
    }
}
