//! `export --usd FILE.usda`: a USD stage (text) with the `openpbr` fit as a Material whose
//! MaterialX render context (`outputs:mtlx:surface`) is the OpenPBR Surface network of
//! `export --materialx` (the same nodes as UsdShade shaders, `info:id` their MaterialX node
//! definitions), and whose universal surface (`outputs:surface`) is a UsdPreviewSurface fallback
//! for viewers without MaterialX; and a 1 x 1 swatch (UVs, normals) bound to it.
//!
//! The fallback is not the fit: UsdPreviewSurface has no fuzz and no anisotropy, so it carries
//! the base colour, the mean roughness and the IOR, and says so in the stage's documentation.

use super::materialx_out::{num, OpenPbrMaterial, Value};

impl OpenPbrMaterial {
    /// The roughness the UsdPreviewSurface fallback gets: the one whose alpha is the geometric
    /// mean of the anisotropic pair (what MaterialX's shadowing and energy terms use).
    pub fn preview_roughness(&self) -> f64 {
        let (ax, ay) = crate::model::rungs::openpbr::alphas(
            self.shape.specular_roughness,
            self.shape.specular_roughness_anisotropy,
        );
        (ax * ay).sqrt().sqrt()
    }

    /// The USD stage.
    pub fn usda(&self) -> String {
        let n = &self.name;
        let m = format!("/fibrefit/Materials/{n}");
        let mut doc = String::from(
            "Written by fibrefit (export --usd): the material of an `openpbr` fit. Its MaterialX \
             render context (outputs:mtlx:surface) is OpenPBR Surface with the fit's values, \
             exactly the model fitted; its universal surface (outputs:surface) is a \
             UsdPreviewSurface fallback for viewers without MaterialX, which is NOT the fit (no \
             fuzz, no anisotropy: base colour, mean roughness, IOR). ",
        );
        doc += &format!(
            "The fibres lie at {:.4} deg from the UV u axis, anticlockwise seen from the normal. ",
            self.fibre_azimuth_deg
        );
        doc += &self.provenance.join(" ");
        let lines = self.textures.lines();
        if !lines.is_empty() {
            doc += " ";
            doc += &lines.join(" ");
        }
        let mut s = String::from("#usda 1.0\n(\n    defaultPrim = \"fibrefit\"\n");
        s += &format!("    doc = {}\n", usd_str(&doc));
        s += "    metersPerUnit = 1\n    upAxis = \"Z\"\n)\n\n";
        s += "def Xform \"fibrefit\" (\n    kind = \"component\"\n)\n{\n";
        s += "    def Scope \"Materials\"\n    {\n";
        s += &format!("        def Material \"{n}\"\n        {{\n");
        s += &format!("            token outputs:mtlx:surface.connect = <{m}/OpenPbrSurface.outputs:out>\n");
        s += &format!("            token outputs:surface.connect = <{m}/PreviewSurface.outputs:surface>\n\n");
        // the MaterialX network, as UsdShade shaders
        s += "            def Shader \"OpenPbrSurface\"\n            {\n";
        s += "                uniform token info:id = \"ND_open_pbr_surface_surfaceshader\"\n";
        for (k, v) in self.inputs() {
            let (ty, v) = match v {
                Value::Float(x) => ("float", num(x)),
                Value::Color(c) => ("color3f", format!("({})", c.map(num).join(", "))),
            };
            s += &match self.textures.of_input(k) {
                Some(t) => format!(
                    "                {ty} inputs:{k}.connect = <{m}/{}.outputs:out>\n",
                    map_prim(t.suffix)
                ),
                None => format!("                {ty} inputs:{k} = {v}\n"),
            };
        }
        s += &format!(
            "                vector3f inputs:geometry_tangent.connect = <{m}/TangentAcrossFibres.outputs:out>\n"
        );
        s += "                token outputs:out\n            }\n\n";
        for (prim, id) in [("UvTangent", "ND_tangent_vector3"), ("Normal", "ND_normal_vector3")] {
            s += &format!("            def Shader \"{prim}\"\n            {{\n");
            s += &format!("                uniform token info:id = \"{id}\"\n");
            s += "                uniform string inputs:space = \"world\"\n";
            s += "                vector3f outputs:out\n            }\n\n";
        }
        s += "            def Shader \"TangentAcrossFibres\"\n            {\n";
        s += "                uniform token info:id = \"ND_rotate3d_vector3\"\n";
        s += &format!("                vector3f inputs:in.connect = <{m}/UvTangent.outputs:out>\n");
        s += &match self.textures.of_input("amount") {
            Some(t) => format!(
                "                float inputs:amount.connect = <{m}/{}.outputs:out>\n",
                map_prim(t.suffix)
            ),
            None => format!(
                "                float inputs:amount = {}\n",
                num(self.tangent_rotation_deg())
            ),
        };
        s += &format!("                vector3f inputs:axis.connect = <{m}/Normal.outputs:out>\n");
        s += "                vector3f outputs:out\n            }\n\n";
        // the per-texel maps: MaterialX image nodes (closest), the files beside the stage
        for t in &self.textures.textures {
            let (id, ty) = match t.input {
                "base_color" => ("ND_image_color3", "color3f"),
                _ => ("ND_image_float", "float"),
            };
            s += &format!("            def Shader \"{}\"\n            {{\n", map_prim(t.suffix));
            s += &format!("                uniform token info:id = \"{id}\"\n");
            s += &format!(
                "                asset inputs:file = @./{}@\n",
                self.textures.file_name(t)
            );
            s += "                string inputs:filtertype = \"closest\"\n";
            s += "                string inputs:uaddressmode = \"clamp\"\n";
            s += "                string inputs:vaddressmode = \"clamp\"\n";
            s += &format!("                {ty} outputs:out\n            }}\n\n");
        }
        let base_map = self.textures.of_input("base_color");
        if let Some(t) = base_map {
            // the fallback's base colour from the same file, through UsdPreviewSurface's nodes
            s += "            def Shader \"PreviewSt\"\n            {\n";
            s += "                uniform token info:id = \"UsdPrimvarReader_float2\"\n";
            s += "                string inputs:varname = \"st\"\n";
            s += "                float2 outputs:result\n            }\n\n";
            s += "            def Shader \"PreviewBaseColor\"\n            {\n";
            s += "                uniform token info:id = \"UsdUVTexture\"\n";
            s += &format!(
                "                asset inputs:file = @./{}@\n",
                self.textures.file_name(t)
            );
            s += "                token inputs:sourceColorSpace = \"raw\"\n";
            s += &format!("                float2 inputs:st.connect = <{m}/PreviewSt.outputs:result>\n");
            s += "                token inputs:wrapS = \"clamp\"\n                token inputs:wrapT = \"clamp\"\n";
            s += "                float3 outputs:rgb\n            }\n\n";
        }
        // the fallback
        let [r, g, b] = self.base_color;
        s += "            def Shader \"PreviewSurface\"\n            {\n";
        s += "                uniform token info:id = \"UsdPreviewSurface\"\n";
        s += &match base_map {
            Some(_) => format!(
                "                color3f inputs:diffuseColor.connect = <{m}/PreviewBaseColor.outputs:rgb>\n"
            ),
            None => format!(
                "                color3f inputs:diffuseColor = ({}, {}, {})\n",
                num(r),
                num(g),
                num(b)
            ),
        };
        s += "                float inputs:metallic = 0.0\n";
        s += &format!(
            "                float inputs:roughness = {}\n",
            num(self.preview_roughness())
        );
        s += &format!("                float inputs:ior = {}\n", num(self.shape.specular_ior));
        s += "                int inputs:useSpecularWorkflow = 0\n";
        s += "                token outputs:surface\n            }\n        }\n    }\n\n";
        // the swatch
        s += "    def Mesh \"Swatch\" (\n        prepend apiSchemas = [\"MaterialBindingAPI\"]\n    )\n    {\n";
        s += "        float3[] extent = [(-0.5, -0.5, 0), (0.5, 0.5, 0)]\n";
        s += "        int[] faceVertexCounts = [4]\n        int[] faceVertexIndices = [0, 1, 2, 3]\n";
        s += &format!("        rel material:binding = <{m}>\n");
        s += "        normal3f[] normals = [(0, 0, 1), (0, 0, 1), (0, 0, 1), (0, 0, 1)] (\n            interpolation = \"vertex\"\n        )\n";
        s += "        point3f[] points = [(-0.5, -0.5, 0), (0.5, -0.5, 0), (0.5, 0.5, 0), (-0.5, 0.5, 0)]\n";
        s += "        texCoord2f[] primvars:st = [(0, 0), (1, 0), (1, 1), (0, 1)] (\n            interpolation = \"vertex\"\n        )\n";
        s += "        uniform token subdivisionScheme = \"none\"\n    }\n}\n";
        s
    }
}

/// The prim of the image node of a texture.
fn map_prim(suffix: &str) -> String {
    let camel: String = suffix
        .split('_')
        .map(|w| {
            let mut c = w.chars();
            c.next()
                .map_or(String::new(), |f| f.to_ascii_uppercase().to_string() + c.as_str())
        })
        .collect();
    format!("{camel}Map")
}

/// A USD string literal (triple-quoted where it has quotes or newlines).
fn usd_str(s: &str) -> String {
    let mut o = String::from("\"");
    for c in s.chars() {
        match c {
            '"' => o += "\\\"",
            '\\' => o += "\\\\",
            '\n' => o += "\\n",
            c if (c as u32) < 0x20 => o.push(' '),
            c => o.push(c),
        }
    }
    o + "\""
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::params::OpenPbrShape;

    #[test]
    fn the_stage_binds_both_surfaces_and_quotes_its_doc() {
        let m = OpenPbrMaterial {
            name: "felt".into(),
            base_color: [0.1, 0.2, 0.3],
            shape: OpenPbrShape::default(),
            fibre_azimuth_deg: 20.0,
            provenance: vec!["from \"a.json\"".into()],
            textures: Default::default(),
        };
        let s = m.usda();
        assert!(s.contains("outputs:mtlx:surface.connect = </fibrefit/Materials/felt/OpenPbrSurface.outputs:out>"));
        assert!(s.contains("info:id = \"UsdPreviewSurface\""));
        assert!(s.contains("from \\\"a.json\\\""));
        assert!(s.contains("color3f inputs:base_color = (0.1, 0.2, 0.3)"));
        // isotropic default: the preview's roughness is the specular roughness
        assert!((m.preview_roughness() - 0.3).abs() < 1e-12);
    }
}
