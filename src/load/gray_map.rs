//! Grayscale maps from files (topology maps, masks, tangent maps): an 8/16-bit grayscale PNG
//! or a float EXR read as a [`TopologyMap`] of values in [0, 1]. The model layer holds the map;
//! reading it from a file is the loaders' job.

use super::image_io::{decode_exr, decode_png};
use crate::model::topology::TopologyMap;
use anyhow::{bail, Result};
use std::path::Path;

impl TopologyMap {
    /// Load an 8/16-bit grayscale PNG or a float EXR (channel `Y`, else `R`, else the only one).
    pub fn load(path: &Path) -> Result<Self> {
        Self::load_as(path, "topology map")
    }

    /// As [`TopologyMap::load`], for any grayscale map in [0, 1]; errors call it `what` (e.g.
    /// "mask", "tangent map").
    pub fn load_as(path: &Path, what: &str) -> Result<Self> {
        let ext = path
            .extension()
            .and_then(|e| e.to_str())
            .map(str::to_ascii_lowercase);
        let (width, height, values) = match ext.as_deref() {
            Some("png") => load_png_gray(path, what)?,
            Some("exr") => load_exr_gray(path, what)?,
            _ => bail!("{}: {what} must be a .png or .exr file", path.display()),
        };
        for (i, v) in values.iter().enumerate() {
            if !(v.is_finite() && (0.0..=1.0).contains(v)) {
                bail!(
                    "{}: texel ({}, {}) has value {v}; {what} values must lie in [0, 1]",
                    path.display(),
                    i % width,
                    i / width
                );
            }
        }
        if values.is_empty() {
            bail!("{}: {what} has no texels", path.display());
        }
        Ok(Self {
            width,
            height,
            values,
            source: path.to_path_buf(),
        })
    }
}

fn load_png_gray(path: &Path, what: &str) -> Result<(usize, usize, Vec<f32>)> {
    let img = decode_png(path, what)?;
    let (w, h) = (img.width() as usize, img.height() as usize);
    let values: Vec<f32> = match img {
        image::DynamicImage::ImageLuma8(b) => {
            b.into_raw().into_iter().map(|v| v as f32 / 255.0).collect()
        }
        image::DynamicImage::ImageLumaA8(b) => b
            .into_raw()
            .chunks_exact(2)
            .map(|p| p[0] as f32 / 255.0)
            .collect(),
        image::DynamicImage::ImageLuma16(b) => b
            .into_raw()
            .into_iter()
            .map(|v| v as f32 / 65535.0)
            .collect(),
        image::DynamicImage::ImageLumaA16(b) => b
            .into_raw()
            .chunks_exact(2)
            .map(|p| p[0] as f32 / 65535.0)
            .collect(),
        other => bail!(
            "{}: {what} must be a grayscale PNG (8 or 16 bit), found {:?}",
            path.display(),
            other.color()
        ),
    };
    Ok((w, h, values))
}

fn load_exr_gray(path: &Path, what: &str) -> Result<(usize, usize, Vec<f32>)> {
    let layer = decode_exr(path, what)?;
    let (w, h) = (layer.size.width(), layer.size.height());
    let channels = &layer.channel_data.list;
    let pick = ["Y", "R"]
        .iter()
        .find_map(|want| channels.iter().find(|c| c.name.to_string() == *want))
        .or(if channels.len() == 1 {
            channels.first()
        } else {
            None
        });
    let Some(channel) = pick else {
        let names: Vec<String> = channels.iter().map(|c| c.name.to_string()).collect();
        bail!(
            "{}: EXR {what} needs a `Y` or `R` channel (or exactly one channel); found {}",
            path.display(),
            names.join(", ")
        );
    };
    let values: Vec<f32> = channel.sample_data.values_as_f32().collect();
    Ok((w, h, values))
}
