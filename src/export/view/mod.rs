//! The viewer page (`fibrefit view`, `fit --report`): one self-contained HTML file, no network,
//! with a hand-written WebGL2 viewer (`viewer.js`, `viewer.css`, inlined). The page shows the
//! fitted material on a swatch, a sphere, the torus and a draped cloth through the exported
//! shader (GLSL ES 3.00: the GLSL export with `#version 300 es` and precision lines in front)
//! beside the glTF route's material (through the `gltf` rung's exported shader), the measured
//! against the fitted BRDF at the light's direction ([`compare`]), and the result's parameter
//! table, verdict and warnings. Everything the page draws is computed here and in `api::view`;
//! the script only draws it.

pub mod compare;

use crate::model::frame::Vec3;
use crate::render::preview_mesh::FramedMesh;
use anyhow::Result;
use serde_json::{json, Value};

/// A BRDF as a function of swatch-frame directions (light, view), per channel, 1/sr.
pub type Brdf<'a> = &'a (dyn Fn(&Vec3, &Vec3) -> Option<[f64; 3]> + Sync);

const VIEWER_JS: &str = include_str!("viewer.js");
const VIEWER_CSS: &str = include_str!("viewer.css");

/// The lines the GLSL export needs in front of it to compile as GLSL ES 3.00 (WebGL2): the export
/// is GLSL 4.50 without a `#version` line, and ES has no default float precision in fragment
/// shaders.
pub const GLSL_ES_PREAMBLE: &str = "#version 300 es\nprecision highp float;\nprecision highp int;\n";

/// An object the page shows.
pub struct ViewMesh {
    /// Its id in the page (`swatch`, `sphere`, `torus`, `cloth`).
    pub name: &'static str,
    /// What it is, in words.
    pub label: String,
    /// The triangles, normals and fibre tangents.
    pub mesh: FramedMesh,
    /// Fibre height H per vertex (the torus's climbing fibres, for rungs with a topology);
    /// none: the model's own height distribution.
    pub heights: Option<Vec<f64>>,
    /// Radius of a sphere about the origin that holds it (the camera's framing).
    pub bound: f64,
}

/// Everything the page shows.
pub struct ViewContent {
    /// The page's title (the result's file name).
    pub title: String,
    /// The rung.
    pub model: String,
    /// The fibre azimuth psi, degrees (the swatch's fibres; the light widget draws it).
    pub fibre_azimuth_deg: f64,
    /// The exact model: the GLSL export (4.50 text, no `#version`).
    pub exact_glsl: String,
    /// The glTF route's material: the `gltf` rung's GLSL export with its values.
    pub gltf_glsl: String,
    /// How the glTF material was made and what it is (`kind`, `text`, `values`,
    /// `azimuth_offset_rad`: the turn from the mesh's fibre tangent to the `gltf` rung's fibre
    /// direction).
    pub gltf_route: Value,
    /// The objects.
    pub meshes: Vec<ViewMesh>,
    /// The result's parameter table, verdict, warnings, statistics ([`result_summary`]).
    pub result: Value,
    /// The measured against the fitted BRDF, or why not.
    pub comparison: compare::Comparison,
    /// The exposure the page opens with.
    pub exposure: f64,
    /// What the viewer leaves out (a topology map, texel maps), in words.
    pub notes: Vec<String>,
}

/// The page: HTML with the script, the style and the data inline.
pub fn page(c: &ViewContent) -> Result<String> {
    let meshes: Vec<Value> = c.meshes.iter().map(mesh_json).collect::<Result<_>>()?;
    let data = json!({
        "title": c.title,
        "tool": format!("fibrefit {}", env!("CARGO_PKG_VERSION")),
        "model": c.model,
        "fibre_azimuth_deg": c.fibre_azimuth_deg,
        "glsl_es_preamble": GLSL_ES_PREAMBLE,
        "shaders": { "exact": c.exact_glsl, "gltf": c.gltf_glsl },
        "gltf_route": c.gltf_route,
        "meshes": meshes,
        "result": c.result,
        "comparison": c.comparison,
        "exposure": c.exposure,
        "fill": crate::render::DEFAULT_FILL,
        "notes": c.notes,
    });
    // inside <script>: no "</" may close the element early
    let data = serde_json::to_string(&data)?.replace("</", "<\\/");
    let title = html_escape(&c.title);
    Ok(format!(
        "<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n\
         <meta name=\"viewport\" content=\"width=device-width, initial-scale=1\">\n\
         <title>fibrefit view: {title}</title>\n<style>\n{VIEWER_CSS}</style>\n</head>\n<body>\n\
         <script type=\"application/json\" id=\"fibrefit-data\">{data}</script>\n\
         <script>\n{VIEWER_JS}</script>\n</body>\n</html>\n"
    ))
}

/// Text safe in HTML or XML text and attribute values.
pub(crate) fn html_escape(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}

/// A mesh as the page reads it, base64: positions, normals and tangents as little-endian i16
/// times each array's `scale` / 32767 (the largest magnitude maps to 32767: 1.5e-5 of it at
/// worst; a unit normal along an axis stays exact), heights as f32, triangle indices as u16 or
/// u32.
fn mesh_json(m: &ViewMesh) -> Result<Value> {
    let i16s = |v: &[Vec3]| -> Value {
        let scale = v
            .iter()
            .flat_map(|p| [p.x, p.y, p.z])
            .fold(0.0f64, |a, x| a.max(x.abs()))
            .max(1e-30);
        let bytes: Vec<u8> = v
            .iter()
            .flat_map(|p| [p.x, p.y, p.z])
            .flat_map(|x| (((x / scale) * 32767.0).round() as i16).to_le_bytes())
            .collect();
        json!({ "scale": scale, "data": base64(&bytes) })
    };
    let mesh = &m.mesh;
    let n = mesh.mesh.positions.len();
    let wide = n > usize::from(u16::MAX);
    let indices: Vec<u8> = mesh
        .mesh
        .triangles
        .iter()
        .flatten()
        .flat_map(|&i| {
            if wide {
                (i as u32).to_le_bytes().to_vec()
            } else {
                (i as u16).to_le_bytes().to_vec()
            }
        })
        .collect();
    let heights = m.heights.as_ref().map(|h| {
        let bytes: Vec<u8> = h.iter().flat_map(|&x| (x as f32).to_le_bytes()).collect();
        base64(&bytes)
    });
    Ok(json!({
        "name": m.name,
        "label": m.label,
        "bound": m.bound,
        "vertices": n,
        "positions": i16s(&mesh.mesh.positions),
        "normals": i16s(&mesh.normals),
        "tangents": i16s(&mesh.tangents),
        "heights": heights,
        "index_bytes": if wide { 4 } else { 2 },
        "indices": base64(&indices),
    }))
}

/// Standard base64 with padding.
fn base64(bytes: &[u8]) -> String {
    const A: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let mut out = String::with_capacity(bytes.len().div_ceil(3) * 4);
    for c in bytes.chunks(3) {
        let b = [c[0], *c.get(1).unwrap_or(&0), *c.get(2).unwrap_or(&0)];
        let n = (u32::from(b[0]) << 16) | (u32::from(b[1]) << 8) | u32::from(b[2]);
        for k in 0..4 {
            if k <= c.len() {
                out.push(char::from(A[((n >> (18 - 6 * k)) & 63) as usize]));
            } else {
                out.push('=');
            }
        }
    }
    out
}

/// What the page's table shows of a result file (schema fibrefit-result/1, as JSON): per
/// parameter its value, standard error and state (fixed and why, held, at a bound, not
/// determined and why), the verdict, the warnings, the headline statistics and the data. A
/// parameter file (not a fit) gives its values without errors, and says so.
pub fn result_summary(v: &Value) -> Value {
    let Some(params) = v["parameters"].as_object() else {
        return json!({
            "fitted": false,
            "note": "a parameter file, not a fitted result: no standard errors, verdict, warnings or data",
        });
    };
    let rows: Vec<Value> = params
        .iter()
        .map(|(name, p)| {
            let mut state = Vec::new();
            if p["fixed"].as_bool() == Some(true) {
                state.push(format!(
                    "fixed{}",
                    p["fixed_reason"]
                        .as_str()
                        .map_or(String::new(), |r| format!(": {r}"))
                ));
            }
            if let Some(h) = p["held"].as_str() {
                state.push(format!("held: {h}"));
            }
            if p["at_bound"].as_bool() == Some(true) {
                state.push("at a bound".into());
            }
            let undetermined = match &p["determined"] {
                Value::Bool(false) => true,
                Value::Array(a) => a.iter().any(|d| d.as_bool() == Some(false)),
                _ => false,
            };
            if undetermined {
                let why = match &p["undetermined_reason"] {
                    Value::String(s) => s.clone(),
                    Value::Array(a) => a
                        .iter()
                        .filter_map(Value::as_str)
                        .collect::<Vec<_>>()
                        .join("; "),
                    _ => String::new(),
                };
                state.push(format!("NOT DETERMINED by the data: {why}"));
            }
            json!({
                "name": name,
                "value": p["value"],
                "std_error": p["std_error"],
                "state": state.join("; "),
                "undetermined": undetermined,
            })
        })
        .collect();
    let stats = &v["statistics"];
    json!({
        "fitted": true,
        "parameters": rows,
        "verdict": v["quality"]["verdict"],
        "warnings": v["warnings"],
        "statistics": {
            "rmse": stats["rmse"],
            "relative_rmse": stats["relative_rmse"],
            "reduced_chi_square": stats["reduced_chi_square"],
            "residual_variance": stats["residual_variance"],
        },
        "data": v["data"],
        "floor": v["quality"]["floor"],
    })
}

#[cfg(test)]
mod tests {
    #[test]
    fn base64_matches_the_standard_alphabet_and_padding() {
        assert_eq!(super::base64(b""), "");
        assert_eq!(super::base64(b"f"), "Zg==");
        assert_eq!(super::base64(b"fo"), "Zm8=");
        assert_eq!(super::base64(b"foo"), "Zm9v");
        assert_eq!(super::base64(b"foobar"), "Zm9vYmFy");
        assert_eq!(super::base64(&[255, 254, 253]), "//79");
    }
}
