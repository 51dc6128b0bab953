//! `export --materialx FILE.mtlx`: a MaterialX 1.39 document with an OpenPBR Surface
//! (`open_pbr_surface`) carrying an `openpbr` fit's values exactly: the values are the rung's
//! own, which is that node as MaterialX implements it (`model/rungs/openpbr.rs`). Every input the
//! rung's subset fixes is written too, so the document means the same in any renderer whatever
//! its defaults.
//!
//! The surface's tangent is the geometry's world tangent (the UV u axis) turned about the normal
//! so that the anisotropy lies across the fibres, which lie at `fibre_azimuth_deg` from u,
//! anticlockwise seen from the normal. MaterialX's `rotate3d` turns clockwise seen from its axis
//! (`mx_rotate_vector3`: `v cos + (v x axis) sin + ...`), so its amount is `-(azimuth + 90)`.

use super::material_textures::MaterialTextures;
use crate::model::params::OpenPbrShape;

/// What the document carries.
#[derive(Clone, Debug, PartialEq)]
pub struct OpenPbrMaterial {
    /// The material's name (a valid MaterialX name: letters, digits and `_`).
    pub name: String,
    /// base_color, linear RGB (the fit's `kd`).
    pub base_color: [f64; 3],
    /// The rung's shape (OpenPBR's inputs by their own names).
    pub shape: OpenPbrShape,
    /// The fibres' angle from the UV u axis, degrees, anticlockwise seen from the normal.
    pub fibre_azimuth_deg: f64,
    /// Lines for the document's header: where the values come from, their error against the
    /// data.
    pub provenance: Vec<String>,
    /// The per-texel maps' textures (none for a global fit): image nodes (closest, the UV
    /// set) driving base_color, specular_roughness, specular_roughness_anisotropy and the
    /// tangent's rotation (`amount`) texel by texel.
    pub textures: MaterialTextures,
}

/// An input's value: a float or a colour.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Value {
    /// A `float` input.
    Float(f64),
    /// A `color3` input, linear RGB.
    Color([f64; 3]),
}

impl OpenPbrMaterial {
    /// `name` made a valid MaterialX (and USD) name: every character but ASCII letters, digits
    /// and `_` becomes `_`, and a leading digit gets a `_` before it.
    pub fn valid_name(name: &str) -> String {
        let mut s: String = name
            .chars()
            .map(|c| if c.is_ascii_alphanumeric() || c == '_' { c } else { '_' })
            .collect();
        if s.is_empty() || s.starts_with(|c: char| c.is_ascii_digit()) {
            s.insert(0, '_');
        }
        s
    }

    /// The material with its textures named after the file `out` (a document or a stage) and
    /// written beside it.
    pub fn beside(mut self, out: &std::path::Path) -> Self {
        self.textures = self.textures.beside(out);
        self
    }

    /// `rotate3d`'s amount turning the UV tangent across the fibres, degrees in (-180, 180].
    pub fn tangent_rotation_deg(&self) -> f64 {
        rotation_amount(self.fibre_azimuth_deg)
    }

    /// The OpenPBR Surface inputs this material sets, by OpenPBR's names, with their values:
    /// the fit's, and every input the rung's subset fixes at its value.
    pub fn inputs(&self) -> Vec<(&'static str, Value)> {
        use Value::{Color, Float};
        let s = &self.shape;
        vec![
            ("base_weight", Float(1.0)),
            ("base_color", Color(self.base_color)),
            ("base_diffuse_roughness", Float(0.0)),
            ("base_metalness", Float(0.0)),
            ("specular_weight", Float(s.specular_weight)),
            ("specular_color", Color([1.0; 3])),
            ("specular_roughness", Float(s.specular_roughness)),
            ("specular_ior", Float(s.specular_ior)),
            (
                "specular_roughness_anisotropy",
                Float(s.specular_roughness_anisotropy),
            ),
            ("transmission_weight", Float(0.0)),
            ("subsurface_weight", Float(0.0)),
            ("fuzz_weight", Float(s.fuzz_weight)),
            ("fuzz_color", Color([1.0; 3])),
            ("fuzz_roughness", Float(s.fuzz_roughness)),
            ("coat_weight", Float(0.0)),
            ("thin_film_weight", Float(0.0)),
            ("emission_luminance", Float(0.0)),
            ("geometry_opacity", Float(1.0)),
        ]
    }

    /// The MaterialX document.
    pub fn document(&self) -> String {
        let n = &self.name;
        let mut s = String::from("<?xml version=\"1.0\"?>\n<materialx version=\"1.39\">\n");
        s += "  <!--\n";
        s += "    Written by fibrefit (the export command's MaterialX option): an OpenPBR Surface with the\n";
        s += "    values of an `openpbr` fit, which is this node as MaterialX 1.39 implements it. Assign the\n";
        s += &format!(
            "    material `{}` to geometry with UV coordinates and tangents: the fibres lie at\n",
            xml_comment(n)
        );
        s += &format!(
            "    {:.4} deg from the UV u axis, anticlockwise seen from the normal.\n",
            self.fibre_azimuth_deg
        );
        for l in self.provenance.iter().chain(&self.textures.lines()) {
            s += &format!("    {}\n", xml_comment(l));
        }
        s += "  -->\n";
        for t in &self.textures.textures {
            let ty = if t.input == "base_color" { "color3" } else { "float" };
            s += &format!("  <image name=\"{n}_{}_map\" type=\"{ty}\">\n", t.suffix);
            s += &format!(
                "    <input name=\"file\" type=\"filename\" value=\"{}\" />\n",
                super::view::html_escape(&self.textures.file_name(t))
            );
            s += "    <input name=\"filtertype\" type=\"string\" value=\"closest\" />\n";
            s += "    <input name=\"uaddressmode\" type=\"string\" value=\"clamp\" />\n";
            s += "    <input name=\"vaddressmode\" type=\"string\" value=\"clamp\" />\n";
            s += "  </image>\n";
        }
        s += &format!("  <tangent name=\"{n}_uv_tangent\" type=\"vector3\">\n");
        s += "    <input name=\"space\" type=\"string\" value=\"world\" />\n";
        s += &format!("  </tangent>\n  <normal name=\"{n}_normal\" type=\"vector3\">\n");
        s += "    <input name=\"space\" type=\"string\" value=\"world\" />\n  </normal>\n";
        s += &format!("  <rotate3d name=\"{n}_tangent_across_fibres\" type=\"vector3\">\n");
        s += &format!("    <input name=\"in\" type=\"vector3\" nodename=\"{n}_uv_tangent\" />\n");
        s += &match self.textures.of_input("amount") {
            Some(t) => format!(
                "    <input name=\"amount\" type=\"float\" nodename=\"{n}_{}_map\" />\n",
                t.suffix
            ),
            None => format!(
                "    <input name=\"amount\" type=\"float\" value=\"{}\" />\n",
                num(self.tangent_rotation_deg())
            ),
        };
        s += &format!("    <input name=\"axis\" type=\"vector3\" nodename=\"{n}_normal\" />\n");
        s += "  </rotate3d>\n";
        s += &format!("  <open_pbr_surface name=\"{n}_surface\" type=\"surfaceshader\">\n");
        for (k, v) in self.inputs() {
            let (ty, v) = match v {
                Value::Float(x) => ("float", num(x)),
                Value::Color(c) => ("color3", c.map(num).join(", ")),
            };
            s += &match self.textures.of_input(k) {
                Some(t) => format!(
                    "    <input name=\"{k}\" type=\"{ty}\" nodename=\"{n}_{}_map\" />\n",
                    t.suffix
                ),
                None => format!("    <input name=\"{k}\" type=\"{ty}\" value=\"{v}\" />\n"),
            };
        }
        s += &format!(
            "    <input name=\"geometry_tangent\" type=\"vector3\" nodename=\"{n}_tangent_across_fibres\" />\n"
        );
        s += "  </open_pbr_surface>\n";
        s += &format!("  <surfacematerial name=\"{n}\" type=\"material\">\n");
        s += &format!(
            "    <input name=\"surfaceshader\" type=\"surfaceshader\" nodename=\"{n}_surface\" />\n"
        );
        s += "  </surfacematerial>\n</materialx>\n";
        s
    }
}

/// `rotate3d`'s amount turning the UV tangent across fibres at `fibre_azimuth_deg` from it,
/// degrees in (-180, 180].
pub fn rotation_amount(fibre_azimuth_deg: f64) -> f64 {
    let a = (-(fibre_azimuth_deg + 90.0)).rem_euclid(360.0);
    if a > 180.0 {
        a - 360.0
    } else {
        a
    }
}

/// A number as MaterialX reads it back to the same f64 (finite: the values are checked).
pub fn num(x: f64) -> String {
    format!("{x:?}")
}

/// Text safe inside an XML comment (no `--`, no markup surprises).
fn xml_comment(s: &str) -> String {
    let mut o = s.replace("--", "- -");
    if o.ends_with('-') {
        o.push(' ');
    }
    o
}

#[cfg(test)]
mod tests {
    use super::*;

    fn material() -> OpenPbrMaterial {
        OpenPbrMaterial {
            name: "felt".into(),
            base_color: [0.1, 0.2, 0.3],
            shape: OpenPbrShape::default(),
            fibre_azimuth_deg: 20.0,
            provenance: vec!["fit of a -- b".into()],
            textures: MaterialTextures::default(),
        }
    }

    #[test]
    fn names_become_valid_and_the_tangent_turns_across_the_fibres() {
        assert_eq!(OpenPbrMaterial::valid_name("green felt #2"), "green_felt__2");
        assert_eq!(OpenPbrMaterial::valid_name("2x"), "_2x");
        assert_eq!(OpenPbrMaterial::valid_name(""), "_");
        // fibres at 20 deg: the anisotropy at 110 deg anticlockwise = rotate3d by -110
        assert_eq!(material().tangent_rotation_deg(), -110.0);
        let m = OpenPbrMaterial {
            fibre_azimuth_deg: -90.0,
            ..material()
        };
        assert_eq!(m.tangent_rotation_deg(), 0.0);
        let m = OpenPbrMaterial {
            fibre_azimuth_deg: 89.0,
            ..material()
        };
        assert_eq!(m.tangent_rotation_deg(), 181.0 - 360.0);
    }

    #[test]
    fn the_document_carries_the_values_and_no_double_dash_in_comments() {
        let d = material().document();
        assert!(d.contains("<input name=\"base_color\" type=\"color3\" value=\"0.1, 0.2, 0.3\" />"));
        assert!(d.contains("<input name=\"amount\" type=\"float\" value=\"-110.0\" />"));
        assert!(d.contains("fit of a - - b"));
        let body = &d[d.find("-->").unwrap()..];
        assert_eq!(d.matches("--").count(), 2, "{}", &d[..d.len() - body.len()]);
    }
}
