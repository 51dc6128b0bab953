//! Per-texel maps as `fit --maps` writes them, read back as inputs (`synth` renders a capture
//! from them, `render` shows them on an object): `height.exr` (fibre radii),
//! `fibre_azimuth.exr` (degrees), `kd.exr`, `ks.exr` (grey or R, G, B), and for the renderers'
//! materials their lobe by the rung's own names (`gltf`: `roughness.exr`,
//! `anisotropy_strength.exr`; `principled`: `roughness.exr`, `anisotropic.exr`; `openpbr`:
//! `specular_roughness.exr`, `specular_roughness_anisotropy.exr`); those present are used, NaN
//! texels take the global value.

use super::image_io::{self, LinearImage};
use crate::model::{LobeRole, ModelId, Param};
use anyhow::{bail, Result};
use std::path::Path;

/// The files of a maps directory, in the order `fit --maps` lists them.
pub const MAP_FILES: [&str; 9] = [
    "height.exr",
    "fibre_azimuth.exr",
    "kd.exr",
    "ks.exr",
    "roughness.exr",
    "specular_roughness.exr",
    "anisotropy_strength.exr",
    "anisotropic.exr",
    "specular_roughness_anisotropy.exr",
];

pub struct TexelMapsIn {
    pub height: Option<LinearImage>,
    pub psi: Option<LinearImage>,
    pub kd: Option<LinearImage>,
    pub ks: Option<LinearImage>,
    /// The lobe's roughness (`gltf`: glTF's roughness).
    pub roughness: Option<LinearImage>,
    /// The lobe's anisotropy strength (`gltf`: KHR_materials_anisotropy's).
    pub anisotropy: Option<LinearImage>,
    /// The parameters whose lobe maps were found (`<name>.exr`), roughness first: which rung's
    /// they are.
    pub lobe_params: Vec<Param>,
    pub width: usize,
    pub rows: usize,
}

impl TexelMapsIn {
    /// The maps in `dir`, all of one size (`size` when given: registered to a capture).
    pub fn load(dir: &Path, size: Option<(usize, usize)>) -> Result<Self> {
        if !dir.is_dir() {
            bail!("{}: not a directory of maps", dir.display());
        }
        let mut want = size;
        let mut read = |name: &str| -> Result<Option<LinearImage>> {
            let p = dir.join(name);
            if !p.exists() {
                return Ok(None);
            }
            let m = image_io::read(&p, None, None)?;
            match want {
                Some((w, h)) if (m.width, m.height) != (w, h) => bail!(
                    "{}: is {}x{} but the maps are {w}x{h}; maps must be registered to one grid",
                    p.display(),
                    m.width,
                    m.height
                ),
                _ => want = Some((m.width, m.height)),
            }
            Ok(Some(m))
        };
        let (height, psi, kd, ks) = (
            read("height.exr")?,
            read("fibre_azimuth.exr")?,
            read("kd.exr")?,
            read("ks.exr")?,
        );
        // a lobe map is named as its rung names the parameter (the table's lobe roles)
        let mut lobe = [None, None];
        let mut lobe_params: Vec<Param> = vec![];
        for role in LobeRole::BOTH {
            for p in Param::all().filter(|p| p.lobe_role() == Some(role)) {
                let Some(m) = read(&format!("{}.exr", p.name()))? else {
                    continue;
                };
                if let Some(first) = lobe_params.iter().find(|q| q.lobe_role() == Some(role)) {
                    bail!(
                        "{}: holds both {}.exr and {}.exr, maps of one lobe value for two \
                         rungs; keep the one of the fit's rung",
                        dir.display(),
                        first.name(),
                        p.name()
                    );
                }
                lobe_params.push(p);
                lobe[role as usize] = Some(m);
            }
        }
        let [roughness, anisotropy] = lobe;
        let Some((width, rows)) = want.filter(|_| {
            [&height, &psi, &kd, &ks, &roughness, &anisotropy]
                .iter()
                .any(|m| m.is_some())
        }) else {
            bail!(
                "{}: no map in it ({})",
                dir.display(),
                MAP_FILES.join(", ")
            );
        };
        Ok(Self {
            height,
            psi,
            kd,
            ks,
            roughness,
            anisotropy,
            lobe_params,
            width,
            rows,
        })
    }

    /// Check that the maps' lobe maps (if any) are model `id`'s: named as it names those
    /// parameters (`dir`: where they came from).
    pub fn lobe_for(&self, id: ModelId, dir: &Path) -> Result<()> {
        for &found in &self.lobe_params {
            let name = found.name();
            match found.lobe_role().and_then(|role| id.lobe_param(role)) {
                Some(p) if p == found => {}
                Some(p) => bail!(
                    "{}: {name}.exr is another rung's lobe map; model `{id}` calls this value \
                     `{}` ({}.exr)",
                    dir.display(),
                    p.name(),
                    p.name()
                ),
                None => bail!(
                    "{}: {name}.exr is a lobe map, but model `{id}` has no such lobe (the \
                     renderers' materials have: {})",
                    dir.display(),
                    ModelId::with_lobe_maps()
                ),
            }
        }
        Ok(())
    }

    /// The map's value at (x, y), channel c (clamped to its channels), unless NaN.
    pub fn at(m: &Option<LinearImage>, x: usize, y: usize, c: usize) -> Option<f64> {
        let m = m.as_ref()?;
        let px = m.pixel(x, y);
        let v = px[c.min(px.len() - 1)] as f64;
        (!v.is_nan()).then_some(v)
    }

    /// The lobe a model at the global `lobe` has at texel (x, y): the maps' roughness and
    /// anisotropy strength where they give them. `None` where neither map does.
    pub fn lobe_at(&self, x: usize, y: usize, lobe: crate::model::Lobe) -> Option<crate::model::Lobe> {
        let r = Self::at(&self.roughness, x, y, 0);
        let a = Self::at(&self.anisotropy, x, y, 0);
        (r.is_some() || a.is_some()).then(|| crate::model::Lobe {
            roughness: r.unwrap_or(lobe.roughness),
            anisotropy: a.unwrap_or(lobe.anisotropy),
        })
    }

    /// The texel under surface coordinates (u, v) in [0, 1] (v up the image).
    pub fn texel(&self, uv: [f64; 2]) -> (usize, usize) {
        (
            ((uv[0] * self.width as f64) as usize).min(self.width - 1),
            (((1.0 - uv[1]) * self.rows as f64) as usize).min(self.rows - 1),
        )
    }
}
