//! `export --blender FILE.py`: a Python script that, run in Blender (Text Editor > Run Script,
//! `blender --python FILE.py`, or `exec` with the `bpy` module), makes a material with a
//! Principled BSDF carrying a `principled` fit's values exactly: the values are the rung's own,
//! which is that node as Cycles evaluates it (`model/rungs/principled.rs`).
//!
//! The material's tangent is the UV map's u axis (a Tangent node, UV Map), so the fibres lie at
//! `fibre_azimuth_deg` from the u axis, anticlockwise seen from the normal; the Principled BSDF's
//! anisotropy lies across them: Anisotropic Rotation = (fibre azimuth + 90 deg) / 360 of a turn.
//! Running the script again rebuilds the material of that name in place (its users keep it),
//! never a second one.
//!
//! A `fit --maps` result's maps become Image Texture nodes (Closest, Non-Color, the UV map)
//! driving Base Color, Roughness, Anisotropic and Anisotropic Rotation texel by texel, read from
//! the EXRs written beside the script ([`MaterialTextures`]); a scalar through a Separate Color
//! node's Red, so the value reaches the socket unchanged.

use super::material_textures::MaterialTextures;
use crate::model::params::PrincipledShape;

/// What the script carries.
#[derive(Clone, Debug, PartialEq)]
pub struct BlenderMaterial {
    /// The material's name in Blender.
    pub name: String,
    /// Base Color, scene-linear RGB (the fit's `kd`).
    pub base_color: [f64; 3],
    /// The rung's shape (Blender's inputs by their own names).
    pub shape: PrincipledShape,
    /// The fibres' angle from the UV u axis, degrees, anticlockwise seen from the normal.
    pub fibre_azimuth_deg: f64,
    /// Lines for the script's header: where the values come from, their error against the data.
    pub provenance: Vec<String>,
    /// The per-texel maps' textures (none for a global fit).
    pub textures: MaterialTextures,
}

impl BlenderMaterial {
    /// Blender's Anisotropic Rotation (a fraction of a turn from the tangent, in [0, 1)): the
    /// anisotropy lies across the fibres.
    pub fn anisotropic_rotation(&self) -> f64 {
        ((self.fibre_azimuth_deg + 90.0) / 360.0).rem_euclid(1.0)
    }

    /// The Principled BSDF's inputs this material sets, by Blender's socket names, with their
    /// values (vectors for colours). Every other input keeps Blender's default, which is the
    /// rung's subset (metallic, transmission, coat, subsurface, emission, thin film 0; alpha 1;
    /// tints white but the specular's).
    pub fn inputs(&self) -> Vec<(&'static str, Vec<f64>)> {
        let s = &self.shape;
        let [r, g, b] = self.base_color;
        let t = s.specular_tint;
        vec![
            ("Base Color", vec![r, g, b, 1.0]),
            ("Metallic", vec![0.0]),
            ("Roughness", vec![s.roughness]),
            ("IOR", vec![s.ior]),
            ("Alpha", vec![1.0]),
            ("Diffuse Roughness", vec![0.0]),
            ("Subsurface Weight", vec![0.0]),
            ("Specular IOR Level", vec![s.specular_ior_level]),
            ("Specular Tint", vec![t, t, t, 1.0]),
            ("Anisotropic", vec![s.anisotropic]),
            ("Anisotropic Rotation", vec![self.anisotropic_rotation()]),
            ("Transmission Weight", vec![0.0]),
            ("Coat Weight", vec![0.0]),
            ("Sheen Weight", vec![s.sheen_weight]),
            ("Sheen Roughness", vec![s.sheen_roughness]),
            ("Sheen Tint", vec![1.0, 1.0, 1.0, 1.0]),
            ("Emission Strength", vec![0.0]),
            ("Thin Film Thickness", vec![0.0]),
        ]
    }

    /// The material with its textures named after the script `out` and written beside it.
    pub fn beside(mut self, out: &std::path::Path) -> Self {
        self.textures = self.textures.beside(out);
        self
    }

    /// The script.
    pub fn script(&self) -> String {
        let mut s = String::new();
        s += "# Blender material written by fibrefit (export --blender): a Principled BSDF with the\n";
        s += "# values of a `principled` fit, which is this node as Cycles evaluates it.\n";
        s += "# Run it in Blender (Text Editor > Run Script, or blender --python THIS.py), or exec it\n";
        s += "# with the bpy module: it makes (or rebuilds in place) the material named below and\n";
        s += "# leaves it in MATERIAL. Assign it to an object with UV coordinates: the fibres lie at\n";
        s += &format!(
            "# {:.4} deg from the UV u axis, anticlockwise seen from the normal (Blender 4.0 or newer).\n",
            self.fibre_azimuth_deg
        );
        s += "#\n";
        for l in self.provenance.iter().chain(&self.textures.lines()) {
            s += &format!("# {l}\n");
        }
        s += "\nimport os\n\nimport bpy\n\n";
        s += &format!("NAME = {}\n", py_str(&self.name));
        s += "# Principled BSDF inputs, by Blender's names (scene-linear colours)\n";
        s += "INPUTS = {\n";
        for (k, v) in self.inputs() {
            let v = if v.len() == 1 {
                py_f(v[0])
            } else {
                format!(
                    "({})",
                    v.iter().map(|x| py_f(*x)).collect::<Vec<_>>().join(", ")
                )
            };
            s += &format!("    {}: {v},\n", py_str(k));
        }
        s += "}\n";
        s += "# Image textures (Closest, Non-Color) driving inputs texel by texel: input -> file,\n";
        s += "# looked for in MAPS_DIR (where they were written), then beside this script\n";
        let dir = self.textures.dir.as_ref().map_or(String::new(), |d| d.display().to_string());
        s += &format!("MAPS_DIR = {}\n", py_str(&dir));
        s += "TEXTURES = {\n";
        for t in &self.textures.textures {
            s += &format!(
                "    {}: {},\n",
                py_str(t.input),
                py_str(&self.textures.file_name(t))
            );
        }
        s += "}\n";
        s += SCRIPT_BODY;
        s
    }
}

/// What every script does with NAME and INPUTS.
const SCRIPT_BODY: &str = r#"

def texture_path(file_name, maps_dir=MAPS_DIR):
    """A texture's file: in maps_dir, else beside this script, else in the working directory."""
    here = globals().get("__file__")
    dirs = [maps_dir] + ([os.path.dirname(os.path.abspath(here))] if here else []) + [os.getcwd()]
    for d in dirs:
        p = os.path.join(d, file_name)
        if d and os.path.isfile(p):
            return p
    raise FileNotFoundError(
        f"fibrefit material {NAME}: texture {file_name} is in none of {dirs}; keep the "
        "textures beside the script, or set MAPS_DIR"
    )


def fibrefit_material(name=NAME, inputs=INPUTS, textures=TEXTURES):
    """The material `name`: made, or rebuilt in place (its users keep it)."""
    m = bpy.data.materials.get(name)
    if m is None:
        m = bpy.data.materials.new(name)
    if bpy.app.version < (5, 0, 0) or m.node_tree is None:
        m.use_nodes = True  # Blender 5 materials always have nodes (use_nodes is deprecated)
    nodes, links = m.node_tree.nodes, m.node_tree.links
    nodes.clear()
    out = nodes.new("ShaderNodeOutputMaterial")
    out.location = (300, 0)
    bsdf = nodes.new("ShaderNodeBsdfPrincipled")
    bsdf.location = (0, 0)
    bsdf.distribution = "MULTI_GGX"
    bsdf.subsurface_method = "RANDOM_WALK"
    for key, value in inputs.items():
        bsdf.inputs[key].default_value = value
    # the tangent: the UV map's u axis; the fibres at their azimuth from it, the anisotropy
    # across them (Anisotropic Rotation)
    tangent = nodes.new("ShaderNodeTangent")
    tangent.location = (-250, -300)
    tangent.direction_type = "UV_MAP"
    links.new(tangent.outputs["Tangent"], bsdf.inputs["Tangent"])
    links.new(bsdf.outputs["BSDF"], out.inputs["Surface"])
    # the per-texel maps: one pixel per texel, read as they are (Non-Color, Closest)
    for i, (key, file_name) in enumerate(textures.items()):
        path = texture_path(file_name)
        image = bpy.data.images.load(path, check_existing=True)
        image.reload()
        image.colorspace_settings.name = "Non-Color"
        tex = nodes.new("ShaderNodeTexImage")
        tex.location = (-650, 300 - 280 * i)
        tex.image = image
        tex.interpolation = "Closest"
        tex.extension = "EXTEND"
        if key == "Base Color":
            links.new(tex.outputs["Color"], bsdf.inputs[key])
        else:  # a scalar: R (G and B are equal), unchanged by a colour-to-float conversion
            rgb = nodes.new("ShaderNodeSeparateColor")
            rgb.location = (-350, 300 - 280 * i)
            links.new(tex.outputs["Color"], rgb.inputs["Color"])
            links.new(rgb.outputs["Red"], bsdf.inputs[key])
    m["fibrefit"] = {
        "inputs": {k: list(v) if isinstance(v, tuple) else v for k, v in inputs.items()},
        "textures": dict(textures),
    }
    return m


MATERIAL = fibrefit_material()
"#;

/// A Python string literal.
fn py_str(s: &str) -> String {
    let mut o = String::from("\"");
    for c in s.chars() {
        match c {
            '"' => o += "\\\"",
            '\\' => o += "\\\\",
            '\n' => o += "\\n",
            c if (c as u32) < 0x20 => o += &format!("\\x{:02x}", c as u32),
            c => o.push(c),
        }
    }
    o + "\""
}

/// A Python float literal that reads back as the same f64 (finite: the values are checked).
fn py_f(x: f64) -> String {
    let s = format!("{x:?}");
    if s.contains(['.', 'e']) {
        s
    } else {
        s + ".0"
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_are_python_strings_and_floats_round_trip() {
        assert_eq!(py_str("felt \"green\"\\"), "\"felt \\\"green\\\"\\\\\"");
        assert_eq!(py_f(0.1), "0.1");
        assert_eq!(py_f(1.0), "1.0");
        assert_eq!(py_f(1e-20), "1e-20");
        let m = BlenderMaterial {
            name: "x".into(),
            base_color: [0.1, 0.2, 0.3],
            shape: PrincipledShape::default(),
            fibre_azimuth_deg: 300.0,
            provenance: vec![],
            textures: MaterialTextures::default(),
        };
        assert!((m.anisotropic_rotation() - (390.0 / 360.0 - 1.0)).abs() < 1e-15);
        assert!(m.script().contains("\"Anisotropic Rotation\": 0.0833"));
    }
}
