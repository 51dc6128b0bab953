//! glTF 2.0 binary (.glb) output, through the `gltf` crate's JSON schema types and GLB container:
//! a mesh with POSITION, NORMAL, TANGENT (the fibre direction; w the handedness of the
//! bitangent), TEXCOORD_0 where the mesh has texture coordinates, and `_UMBILIC` (1 where the
//! tangent is undefined: an application-specific attribute, as glTF allows), indexed triangles;
//! and, for a material with texture maps, PNG images embedded in the binary buffer (a buffer
//! view and `mimeType` each), one sampler and a texture per image.

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

/// A PNG image for the GLB: texture `i` of the document is image `i`.
pub struct TextureImage {
    pub name: String,
    pub png: Vec<u8>,
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
    write_glb_with_images(out, mesh, frames, material, &[], generator)
}

/// [`write_glb`] with `images` embedded (after the mesh data, 4-byte aligned), a linear,
/// mipmapped, clamped sampler and texture `i` = image `i`, for `material` to refer to.
pub fn write_glb_with_images(
    out: &mut impl Write,
    mesh: &Mesh,
    frames: &VertexFrames,
    material: Option<Value>,
    images: &[TextureImage],
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
    let mut image_json = Vec::new();
    for img in images {
        while b.bin.len() % 4 != 0 {
            b.bin.push(0);
        }
        b.views.push(json!({
            "buffer": 0, "byteOffset": b.bin.len(), "byteLength": img.png.len()
        }));
        b.bin.extend_from_slice(&img.png);
        image_json.push(json!({
            "bufferView": b.views.len() - 1, "mimeType": "image/png", "name": img.name
        }));
    }
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
    if !images.is_empty() {
        // LINEAR, LINEAR_MIPMAP_LINEAR, CLAMP_TO_EDGE: the maps cover the mesh's (u, v) once
        root["samplers"] = json!([{
            "magFilter": 9729, "minFilter": 9987, "wrapS": 33071, "wrapT": 33071
        }]);
        root["textures"] = json!((0..images.len())
            .map(|i| json!({ "sampler": 0, "source": i, "name": images[i].name }))
            .collect::<Vec<_>>());
        root["images"] = json!(image_json);
    }
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
    textured_material(fitted, model, provenance, None)
}

/// The textures a material samples (indices into the document's textures; all TEXCOORD_0),
/// and what they hold (`extras.fibrefit.textures`).
pub struct MaterialTextures {
    /// sRGB base colour: `baseColorFactor` becomes 1.
    pub base_color: Option<usize>,
    /// G = roughness (B = metallic = 0): `roughnessFactor` becomes 1.
    pub metallic_roughness: Option<usize>,
    /// KHR_materials_anisotropy: RG = direction in tangent space, B = strength:
    /// `anisotropyStrength` becomes 1 (`anisotropyRotation` still turns the direction).
    pub anisotropy: Option<usize>,
    pub description: Value,
}

/// [`fitted_material`] sampling `textures` where given.
pub fn textured_material(
    fitted: &crate::fit::gltf_material::FittedMaterial,
    model: crate::model::ModelId,
    provenance: &[String],
    textures: Option<&MaterialTextures>,
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
    if let Some(tx) = textures {
        let pbr = &mut material["pbrMetallicRoughness"];
        if let Some(i) = tx.base_color {
            pbr["baseColorFactor"] = json!([1.0, 1.0, 1.0, 1.0]);
            pbr["baseColorTexture"] = json!({ "index": i, "texCoord": 0 });
        }
        if let Some(i) = tx.metallic_roughness {
            pbr["roughnessFactor"] = json!(1.0);
            pbr["metallicRoughnessTexture"] = json!({ "index": i, "texCoord": 0 });
        }
        if let Some(i) = tx.anisotropy {
            let an = &mut material["extensions"]["KHR_materials_anisotropy"];
            an["anisotropyStrength"] = json!(1.0);
            an["anisotropyTexture"] = json!({ "index": i, "texCoord": 0 });
        }
        material["extras"]["fibrefit"]["textures"] = tx.description.clone();
    }
    if let Some(sh) = m.sheen {
        material["extensions"]["KHR_materials_sheen"] = json!({
            "sheenColorFactor": [sh.colour, sh.colour, sh.colour],
            "sheenRoughnessFactor": sh.roughness,
        });
    }
    material
}

/// Record in `material`'s `extras.fibrefit.undetermined` the values its result's data did not
/// determine (label, value used, reason): the material uses them, but they are not
/// measurements. Nothing is added when there are none.
pub fn mark_undetermined(material: &mut Value, undetermined: &[crate::fit::determined::Undetermined]) {
    if undetermined.is_empty() {
        return;
    }
    material["extras"]["fibrefit"]["undetermined"] = json!(undetermined
        .iter()
        .map(|u| json!({
            "parameter": u.label,
            "value_used": u.value,
            "reason": u.reason,
        }))
        .collect::<Vec<_>>());
}

/// The `gltf` rung's fitted values as they go into a glTF document, unchanged: the rung is
/// glTF 2.0's metallic-roughness BRDF with KHR_materials_sheen, _anisotropy, _specular and _ior
/// (`model/rungs/gltf.rs`), so each value has its field.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RungValues {
    /// baseColorFactor (linear RGB): the fit's `kd`.
    pub base_color: [f64; 3],
    /// The rung's shape: metallic, roughness, anisotropy strength, specular factor, IOR, sheen
    /// colour (grey) and roughness.
    pub shape: crate::model::params::GltfShape,
    /// anisotropyRotation, radians from the TANGENT towards the bitangent: the anisotropy
    /// direction lies across the fibres (the fibre direction from the TANGENT + 90 deg).
    pub anisotropy_rotation: f64,
}

/// The textures of a `gltf` fit's maps (indices into the document's textures, all TEXCOORD_0).
pub struct RungTextures {
    /// sRGB base colour, the `kd` map: `baseColorFactor` becomes 1.
    pub base_color: Option<usize>,
    /// The metallic-roughness texture, the `roughness` map: G = roughness, B = 1
    /// (`roughnessFactor` becomes 1, `metallicFactor` stays the fit's).
    pub metallic_roughness: Option<usize>,
    /// KHR_materials_anisotropy's texture: RG the fibre map's direction relative to the global
    /// one, B = 1 (`anisotropyStrength` stays the fit's) or, with `strength_mapped`, the
    /// `anisotropy_strength` map (`anisotropyStrength` becomes 1).
    pub anisotropy: Option<usize>,
    pub strength_mapped: bool,
    pub description: Value,
}

/// The glTF material of a `gltf` fit: its values exactly ([`RungValues`]), the textures of its
/// maps where given, and `extras` (`extras.fibrefit`: the route, the error against the data,
/// provenance). KHR_materials_sheen is written when the sheen colour is above 0 (0 is the
/// extension's absence).
pub fn gltf_rung_material(v: &RungValues, textures: Option<&RungTextures>, extras: Value) -> Value {
    let (c, g) = (v.base_color, &v.shape);
    let mut material = json!({
        "name": "fibrefit gltf",
        "pbrMetallicRoughness": {
            "baseColorFactor": [c[0], c[1], c[2], 1.0],
            "metallicFactor": g.metallic,
            "roughnessFactor": g.roughness,
        },
        "extensions": {
            "KHR_materials_anisotropy": {
                "anisotropyStrength": g.anisotropy,
                "anisotropyRotation": v.anisotropy_rotation,
            },
            "KHR_materials_specular": {
                "specularFactor": g.specular,
                "specularColorFactor": [1.0, 1.0, 1.0],
            },
            "KHR_materials_ior": { "ior": g.ior },
        },
        "extras": { "fibrefit": extras },
    });
    if g.sheen > 0.0 {
        material["extensions"]["KHR_materials_sheen"] = json!({
            "sheenColorFactor": [g.sheen, g.sheen, g.sheen],
            "sheenRoughnessFactor": g.sheen_roughness,
        });
    }
    if let Some(tx) = textures {
        if let Some(i) = tx.base_color {
            material["pbrMetallicRoughness"]["baseColorFactor"] = json!([1.0, 1.0, 1.0, 1.0]);
            material["pbrMetallicRoughness"]["baseColorTexture"] =
                json!({ "index": i, "texCoord": 0 });
        }
        if let Some(i) = tx.metallic_roughness {
            material["pbrMetallicRoughness"]["roughnessFactor"] = json!(1.0);
            material["pbrMetallicRoughness"]["metallicRoughnessTexture"] =
                json!({ "index": i, "texCoord": 0 });
        }
        if let Some(i) = tx.anisotropy {
            material["extensions"]["KHR_materials_anisotropy"]["anisotropyTexture"] =
                json!({ "index": i, "texCoord": 0 });
            if tx.strength_mapped {
                material["extensions"]["KHR_materials_anisotropy"]["anisotropyStrength"] =
                    json!(1.0);
            }
        }
        material["extras"]["fibrefit"]["textures"] = tx.description.clone();
    }
    material
}

/// sRGB encoding (IEC 61966-2-1) of a linear value in [0, 1] to 8 bits, rounded.
pub fn srgb8(linear: f64) -> u8 {
    let c = linear.clamp(0.0, 1.0);
    let e = if c <= 0.003_130_8 {
        12.92 * c
    } else {
        1.055 * c.powf(1.0 / 2.4) - 0.055
    };
    (e * 255.0).round().clamp(0.0, 255.0) as u8
}

/// A linear value in [0, 1] to 8 bits, rounded.
pub fn unorm8(v: f64) -> u8 {
    (v.clamp(0.0, 1.0) * 255.0).round() as u8
}

/// An 8-bit RGB image (`width` x `height`, rows from the top) as PNG bytes.
pub fn png_rgb8(width: usize, height: usize, rgb: &[u8]) -> Result<Vec<u8>> {
    use image::ImageEncoder;
    let (w, h) = (
        u32::try_from(width).map_err(|_| anyhow!("a texture {width} pixels wide"))?,
        u32::try_from(height).map_err(|_| anyhow!("a texture {height} pixels high"))?,
    );
    let mut png = Vec::new();
    image::codecs::png::PngEncoder::new(&mut png)
        .write_image(rgb, w, h, image::ExtendedColorType::Rgb8)
        .map_err(|e| anyhow!("cannot encode a {width}x{height} PNG texture: {e}"))?;
    Ok(png)
}
