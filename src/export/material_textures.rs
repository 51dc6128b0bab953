//! The per-texel maps of a renderer material's fit (`fit --maps` of `principled` or `openpbr`)
//! as the image textures its material reads: one RGB float EXR per mapped input, written beside
//! the material (`export --blender`, `--materialx`, `--usd`) as `<stem>_<suffix>.exr`, one
//! pixel per texel, row 0 the maps' top row (the mesh's v = 1, as `render` reads them). A
//! scalar input has equal R, G and B (the material reads R). Texels without a value (NaN in the
//! maps) carry the global value, so the texture holds what the material shows everywhere.

use std::path::{Path, PathBuf};

/// One texture: which input of the material it drives, and its pixels.
#[derive(Clone, Debug, PartialEq)]
pub struct MapTexture {
    /// The file name's suffix after the stem (`base_color`, `roughness`, ...).
    pub suffix: &'static str,
    /// The material's input it drives, by the renderer's own name (Blender's socket names,
    /// OpenPBR's inputs; `amount` is the tangent's rotation).
    pub input: &'static str,
    /// What a pixel holds, with its unit (for the material's header).
    pub meaning: &'static str,
    /// Width in pixels (the maps' texels across).
    pub width: usize,
    /// Height in pixels (the maps' rows).
    pub height: usize,
    /// RGB per pixel, rows from the top.
    pub rgb: Vec<f32>,
}

/// The textures of a material and where they go.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct MaterialTextures {
    /// One per mapped input.
    pub textures: Vec<MapTexture>,
    /// The file names' stem (the material file's own stem; the material's name before an
    /// output is known).
    pub stem: String,
    /// The directory they are written to, absolute where known (a script made in memory looks
    /// beside itself).
    pub dir: Option<PathBuf>,
    /// The maps directory they were made of.
    pub maps: Option<PathBuf>,
}

impl MapTexture {
    /// The texture of per-texel values `value(x, y)` (`None`: the global `global`), each RGB.
    pub fn of(
        (suffix, input, meaning): (&'static str, &'static str, &'static str),
        (width, height): (usize, usize),
        mut value: impl FnMut(usize, usize) -> Option<[f64; 3]>,
        global: [f64; 3],
    ) -> Self {
        let mut rgb = Vec::with_capacity(width * height * 3);
        for y in 0..height {
            for x in 0..width {
                let v = value(x, y).unwrap_or(global);
                rgb.extend(v.map(|c| c as f32));
            }
        }
        Self {
            suffix,
            input,
            meaning,
            width,
            height,
            rgb,
        }
    }
}

impl MaterialTextures {
    /// The file name of `t`.
    pub fn file_name(&self, t: &MapTexture) -> String {
        format!("{}_{}.exr", self.stem, t.suffix)
    }

    /// The textures named after the material file `out` and written beside it.
    pub fn beside(mut self, out: &Path) -> Self {
        self.stem = out
            .file_stem()
            .map_or("material".into(), |s| s.to_string_lossy().into_owned());
        let dir = out
            .parent()
            .filter(|p| !p.as_os_str().is_empty())
            .unwrap_or(Path::new("."));
        self.dir = Some(dir.canonicalize().unwrap_or_else(|_| dir.to_path_buf()));
        self
    }

    /// The texture of `input`, if any.
    pub fn of_input(&self, input: &str) -> Option<&MapTexture> {
        self.textures.iter().find(|t| t.input == input)
    }

    /// (path, texture) of every texture, beside `out`.
    pub fn files(&self, out: &Path) -> Vec<(PathBuf, &MapTexture)> {
        let dir = out.parent().unwrap_or(Path::new(""));
        self.textures
            .iter()
            .map(|t| (dir.join(self.file_name(t)), t))
            .collect()
    }

    /// Reserve every texture's file beside the material file `out` in `outs` (`flag`: the
    /// option writing it), then write them (as RGB float EXRs): committed with the run's other
    /// outputs. Files in `written` (path, input: the same material's textures for another file
    /// beside it, a document and a stage of one stem) are not written twice; those written
    /// join it.
    pub fn write_beside(
        &self,
        outs: &mut super::atomic::Outputs,
        (out, flag): (&Path, &str),
        written: &mut Vec<(PathBuf, &'static str)>,
    ) -> anyhow::Result<()> {
        let mut ids = vec![];
        for (path, t) in self.files(out) {
            if written.iter().any(|(p, _)| *p == path) {
                continue;
            }
            ids.push((outs.file(&path, flag)?, t));
            written.push((path, t.input));
        }
        for (id, t) in ids {
            let (f, name) = outs.file_and_name(id);
            let name = name.to_path_buf();
            super::images::write_exr_into(f, &name, t.width, t.height, 3, &t.rgb)?;
        }
        Ok(())
    }

    /// The header lines that say which inputs the textures drive.
    pub fn lines(&self) -> Vec<String> {
        if self.textures.is_empty() {
            return vec![];
        }
        let mut v = vec![format!(
            "per-texel maps{} as textures beside this file (one pixel per texel, nearest, \
             row 0 = the maps' top row, UV v = 1):",
            self.maps
                .as_ref()
                .map_or(String::new(), |m| format!(" of {}", m.display()))
        )];
        for t in &self.textures {
            v.push(format!(
                "  {} -> {}: {}",
                self.file_name(t),
                t.input,
                t.meaning
            ));
        }
        v
    }
}

/// `value` wrapped into the unit interval (Blender's Anisotropic Rotation, a fraction of a turn).
pub fn turns(deg: f64) -> f64 {
    (deg / 360.0).rem_euclid(1.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_texture_takes_the_global_where_the_map_has_none_and_files_go_beside_the_material() {
        let t = MapTexture::of(
            ("roughness", "Roughness", "r"),
            (2, 2),
            |x, y| (x != y).then(|| [0.5; 3]),
            [0.2; 3],
        );
        assert_eq!(t.rgb[..3], [0.2; 3]);
        assert_eq!(t.rgb[3..6], [0.5; 3]);
        let m = MaterialTextures {
            textures: vec![t],
            ..Default::default()
        }
        .beside(Path::new("out/felt.py"));
        assert_eq!(m.stem, "felt");
        let files = m.files(Path::new("out/felt.py"));
        assert_eq!(files[0].0, Path::new("out/felt_roughness.exr"));
        assert!((turns(-90.0 + 360.0) - 0.75).abs() < 1e-15);
    }
}
