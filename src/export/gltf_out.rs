//! glTF 2.0 binary (.glb) output, through the `gltf` crate's JSON schema types and GLB container:
//! a mesh with POSITION, NORMAL, TANGENT (the fibre direction; w the handedness of the
//! bitangent), TEXCOORD_0 where the mesh has texture coordinates, and `_UMBILIC` (1 where the
//! tangent is undefined: an application-specific attribute, as glTF allows), indexed triangles.

use crate::load::mesh::Mesh;
use crate::model::frame::Vec3;
use anyhow::{anyhow, Result};
use serde_json::{json, Value};
use std::io::Write;

/// Per-vertex attributes of the mesh written.
pub struct VertexFrames<'a> {
    pub normals: &'a [Vec3],
    /// Unit tangents (fibre directions) perpendicular to the normals.
    pub tangents: &'a [Vec3],
    /// Unit bitangents: the TANGENT's w is the sign of (N x T) . B.
    pub bitangents: &'a [Vec3],
    /// Vertices whose tangent is undefined (written as 1 in `_UMBILIC`).
    pub undefined: &'a [bool],
}

/// Accumulates the binary buffer and its views and accessors.
#[derive(Default)]
struct Builder {
    bin: Vec<u8>,
    views: Vec<Value>,
    accessors: Vec<Value>,
}

impl Builder {
    /// Append f32 data (`width` per element) as a view and an accessor; returns its index.
    fn floats(&mut self, data: &[f32], width: usize, kind: &str, bounds: bool) -> usize {
        while self.bin.len() % 4 != 0 {
            self.bin.push(0);
        }
        let offset = self.bin.len();
        for v in data {
            self.bin.extend_from_slice(&v.to_le_bytes());
        }
        self.views.push(json!({
            "buffer": 0, "byteOffset": offset, "byteLength": data.len() * 4, "target": 34962
        }));
        let mut acc = json!({
            "bufferView": self.views.len() - 1,
            "componentType": 5126,
            "count": data.len() / width,
            "type": kind,
        });
        if bounds {
            let (mut lo, mut hi) = (vec![f32::INFINITY; width], vec![f32::NEG_INFINITY; width]);
            for el in data.chunks_exact(width) {
                for c in 0..width {
                    lo[c] = lo[c].min(el[c]);
                    hi[c] = hi[c].max(el[c]);
                }
            }
            acc["min"] = json!(lo);
            acc["max"] = json!(hi);
        }
        self.accessors.push(acc);
        self.accessors.len() - 1
    }

    fn indices(&mut self, data: &[u32]) -> usize {
        while self.bin.len() % 4 != 0 {
            self.bin.push(0);
        }
        let offset = self.bin.len();
        for v in data {
            self.bin.extend_from_slice(&v.to_le_bytes());
        }
        self.views.push(json!({
            "buffer": 0, "byteOffset": offset, "byteLength": data.len() * 4, "target": 34963
        }));
        self.accessors.push(json!({
            "bufferView": self.views.len() - 1,
            "componentType": 5125,
            "count": data.len(),
            "type": "SCALAR",
        }));
        self.accessors.len() - 1
    }
}

fn flat(v: &[Vec3]) -> Vec<f32> {
    v.iter()
        .flat_map(|p| [p.x as f32, p.y as f32, p.z as f32])
        .collect()
}

/// Write `mesh` with `frames` as a GLB to `out`, with `material` (a glTF material object) when
/// given; `generator` names the tool.
pub fn write_glb(
    out: &mut impl Write,
    mesh: &Mesh,
    frames: &VertexFrames,
    material: Option<Value>,
    generator: &str,
) -> Result<()> {
    let mut b = Builder::default();
    let pos = b.floats(&flat(&mesh.positions), 3, "VEC3", true);
    let nor = b.floats(&flat(frames.normals), 3, "VEC3", false);
    let tan: Vec<f32> = frames
        .tangents
        .iter()
        .zip(frames.normals)
        .zip(frames.bitangents)
        .flat_map(|((t, n), bt)| {
            let w = if n.cross(t).dot(bt) < 0.0 { -1.0 } else { 1.0 };
            [t.x as f32, t.y as f32, t.z as f32, w]
        })
        .collect();
    let tan = b.floats(&tan, 4, "VEC4", false);
    let und: Vec<f32> = frames
        .undefined
        .iter()
        .map(|&u| f32::from(u8::from(u)))
        .collect();
    let und = b.floats(&und, 1, "SCALAR", false);
    let mut attributes = json!({ "POSITION": pos, "NORMAL": nor, "TANGENT": tan, "_UMBILIC": und });
    if let Some(uv) = &mesh.uvs {
        let data: Vec<f32> = uv
            .iter()
            .flat_map(|t| [t[0] as f32, 1.0 - t[1] as f32])
            .collect();
        attributes["TEXCOORD_0"] = json!(b.floats(&data, 2, "VEC2", false));
    }
    let idx: Vec<u32> = mesh
        .triangles
        .iter()
        .flat_map(|t| t.map(|i| i as u32))
        .collect();
    let idx = b.indices(&idx);
    let mut primitive = json!({ "attributes": attributes, "indices": idx, "mode": 4 });
    let mut root = json!({
        "asset": { "version": "2.0", "generator": generator },
        "scene": 0,
        "scenes": [{ "nodes": [0] }],
        "nodes": [{ "mesh": 0, "name": "fibrefit" }],
        "buffers": [{ "byteLength": b.bin.len() }],
        "bufferViews": b.views,
        "accessors": b.accessors,
    });
    if let Some(m) = material {
        let mut used = Vec::new();
        if let Some(ext) = m.get("extensions").and_then(Value::as_object) {
            used.extend(ext.keys().cloned());
        }
        root["materials"] = json!([m]);
        primitive["material"] = json!(0);
        if !used.is_empty() {
            root["extensionsUsed"] = json!(used);
        }
    }
    root["meshes"] = json!([{ "primitives": [primitive], "name": "fibrefit" }]);
    // through the crate's schema and validator: a document it does not accept is not written
    let parsed: gltf::json::Root = serde_json::from_value(root.clone())
        .map_err(|e| anyhow!("internal: the glTF document does not fit the schema: {e}"))?;
    let mut problems = Vec::new();
    gltf::json::validation::Validate::validate(
        &parsed,
        &parsed,
        gltf::json::Path::new,
        &mut |path: &dyn Fn() -> gltf::json::Path, err| {
            problems.push(format!("{}: {err:?}", path()))
        },
    );
    if !problems.is_empty() {
        return Err(anyhow!(
            "internal: the glTF document is not valid: {}",
            problems.join("; ")
        ));
    }
    let json_bytes = serde_json::to_vec(&root)?;
    let glb = gltf::binary::Glb {
        header: gltf::binary::Header {
            magic: *b"glTF",
            version: 2,
            // set by to_writer
            length: 0,
        },
        json: std::borrow::Cow::Owned(json_bytes),
        bin: Some(std::borrow::Cow::Owned(b.bin)),
    };
    glb.to_writer(out)
        .map_err(|e| anyhow!("cannot write the GLB: {e}"))
}

/// The glTF material object of a fitted [`FittedMaterial`]: metallic-roughness (metallic 0),
/// KHR_materials_anisotropy along the TANGENT (the fibre direction), KHR_materials_ior and, when
/// the fit chose one, KHR_materials_sheen, with the fit's errors and provenance in
/// `extras.fibrefit`.
pub fn fitted_material(
    fitted: &crate::fit::gltf_material::FittedMaterial,
    model: crate::model::ModelId,
    provenance: &[String],
) -> Value {
    let m = &fitted.material;
    let c = m.base_color;
    let mut material = json!({
        "name": format!("fibrefit {model}"),
        "pbrMetallicRoughness": {
            "baseColorFactor": [c[0], c[1], c[2], 1.0],
            "metallicFactor": 0.0,
            "roughnessFactor": m.roughness,
        },
        "extensions": {
            "KHR_materials_anisotropy": {
                "anisotropyStrength": m.anisotropy_strength,
                "anisotropyRotation": m.anisotropy_rotation,
            },
            "KHR_materials_ior": { "ior": m.ior },
        },
        "extras": { "fibrefit": {
            "model": model.as_str(),
            "fitted_to": "the fibre model's BRDF (1/sr) over light and view directions uniform in solid angle up to 80 deg, the fibre direction along TANGENT",
            "directions": fitted.directions,
            "rms_error_per_sr": fitted.rms_error,
            "relative_rms_error": fitted.relative_rms_error,
            "relative_rms_error_without_anisotropy": fitted.isotropic_relative_rms_error,
            "relative_rms_error_without_sheen": fitted.without_sheen_relative_rms_error,
            "relative_rms_error_with_sheen": fitted.with_sheen_relative_rms_error,
            "sheen_rule": format!(
                "KHR_materials_sheen is included only when it lowers the relative error by {:.0} % of itself",
                100.0 * crate::fit::gltf_material::SHEEN_GAIN
            ),
            "source": provenance,
        }},
    });
    if let Some(sh) = m.sheen {
        material["extensions"]["KHR_materials_sheen"] = json!({
            "sheenColorFactor": [sh.colour, sh.colour, sh.colour],
            "sheenRoughnessFactor": sh.roughness,
        });
    }
    material
}
