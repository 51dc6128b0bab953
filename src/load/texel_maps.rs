//! Per-texel maps as `fit --maps` writes them, read back as inputs (`synth` renders a capture
//! from them, `render` shows them on an object): `height.exr` (fibre radii),
//! `fibre_azimuth.exr` (degrees), `kd.exr`, `ks.exr` (grey or R, G, B); those present are used,
//! NaN texels take the global value.

use super::image_io::{self, LinearImage};
use anyhow::{bail, Result};
use std::path::Path;

pub struct TexelMapsIn {
    pub height: Option<LinearImage>,
    pub psi: Option<LinearImage>,
    pub kd: Option<LinearImage>,
    pub ks: Option<LinearImage>,
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
        let Some((width, rows)) =
            want.filter(|_| height.is_some() || psi.is_some() || kd.is_some() || ks.is_some())
        else {
            bail!(
                "{}: no height.exr, fibre_azimuth.exr, kd.exr or ks.exr in it",
                dir.display()
            );
        };
        Ok(Self {
            height,
            psi,
            kd,
            ks,
            width,
            rows,
        })
    }

    /// The map's value at (x, y), channel c (clamped to its channels), unless NaN.
    pub fn at(m: &Option<LinearImage>, x: usize, y: usize, c: usize) -> Option<f64> {
        let m = m.as_ref()?;
        let px = m.pixel(x, y);
        let v = px[c.min(px.len() - 1)] as f64;
        (!v.is_nan()).then_some(v)
    }

    /// The texel under surface coordinates (u, v) in [0, 1] (v up the image).
    pub fn texel(&self, uv: [f64; 2]) -> (usize, usize) {
        (
            ((uv[0] * self.width as f64) as usize).min(self.width - 1),
            (((1.0 - uv[1]) * self.rows as f64) as usize).min(self.rows - 1),
        )
    }
}
