//! Reading captured images into linear values: PNG (8/16 bit, linear or sRGB encoded) and EXR.

use anyhow::{anyhow, bail, Context, Result};
use std::path::Path;

/// How a PNG's code values relate to light.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Deserialize, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Encoding {
    Linear,
    Srgb,
}

/// A linear image, channels interleaved (1 = grey, 3 = RGB), row 0 at the top.
#[derive(Clone, Debug, PartialEq)]
pub struct LinearImage {
    pub width: usize,
    pub height: usize,
    pub channels: usize,
    pub data: Vec<f32>,
    /// Per pixel: a channel hit the sensor's top code (PNG) or the given saturation level (EXR).
    pub saturated: Vec<bool>,
}

impl LinearImage {
    pub fn pixel(&self, x: usize, y: usize) -> &[f32] {
        let i = (y * self.width + x) * self.channels;
        &self.data[i..i + self.channels]
    }
}

/// sRGB decoding (IEC 61966-2-1).
pub fn srgb_to_linear(c: f32) -> f32 {
    if c <= 0.04045 {
        c / 12.92
    } else {
        ((c + 0.055) / 1.055).powf(2.4)
    }
}

pub fn linear_to_srgb(c: f32) -> f32 {
    if c <= 0.003_130_8 {
        c * 12.92
    } else {
        1.055 * c.powf(1.0 / 2.4) - 0.055
    }
}

/// Read `path`. PNGs need their `encoding`; `saturation` (EXR only) marks values at or above it.
pub fn read(
    path: &Path,
    encoding: Option<Encoding>,
    saturation: Option<f32>,
) -> Result<LinearImage> {
    match path
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase)
        .as_deref()
    {
        Some("png") => {
            let encoding = encoding.ok_or_else(|| {
                anyhow!(
                    "{}: PNG images need `encoding = \"linear\"` or `\"srgb\"`",
                    path.display()
                )
            })?;
            read_png(path, encoding)
        }
        Some("exr") => {
            if encoding == Some(Encoding::Srgb) {
                bail!(
                    "{}: EXR images are linear; `encoding = \"srgb\"` does not apply",
                    path.display()
                );
            }
            read_exr(path, saturation)
        }
        _ => bail!("{}: images must be .png or .exr", path.display()),
    }
}

fn read_png(path: &Path, encoding: Encoding) -> Result<LinearImage> {
    let img = image::ImageReader::open(path)
        .with_context(|| format!("{}: cannot open image", path.display()))?
        .with_guessed_format()
        .with_context(|| format!("{}: cannot read image", path.display()))?
        .decode()
        .with_context(|| format!("{}: cannot decode image", path.display()))?;
    let (width, height) = (img.width() as usize, img.height() as usize);
    let (channels, codes, top): (usize, Vec<u16>, u16) = match img {
        image::DynamicImage::ImageLuma8(b) => {
            (1, b.into_raw().into_iter().map(u16::from).collect(), 255)
        }
        image::DynamicImage::ImageLumaA8(b) => (
            1,
            b.into_raw().chunks_exact(2).map(|p| p[0] as u16).collect(),
            255,
        ),
        image::DynamicImage::ImageRgb8(b) => {
            (3, b.into_raw().into_iter().map(u16::from).collect(), 255)
        }
        image::DynamicImage::ImageRgba8(b) => (
            3,
            b.into_raw()
                .chunks_exact(4)
                .flat_map(|p| [p[0], p[1], p[2]])
                .map(u16::from)
                .collect(),
            255,
        ),
        image::DynamicImage::ImageLuma16(b) => (1, b.into_raw(), 65535),
        image::DynamicImage::ImageLumaA16(b) => (
            1,
            b.into_raw().chunks_exact(2).map(|p| p[0]).collect(),
            65535,
        ),
        image::DynamicImage::ImageRgb16(b) => (3, b.into_raw(), 65535),
        image::DynamicImage::ImageRgba16(b) => (
            3,
            b.into_raw()
                .chunks_exact(4)
                .flat_map(|p| [p[0], p[1], p[2]])
                .collect(),
            65535,
        ),
        other => bail!(
            "{}: unsupported PNG pixel format {:?}",
            path.display(),
            other.color()
        ),
    };
    let scale = 1.0 / top as f32;
    let data: Vec<f32> = codes
        .iter()
        .map(|&c| {
            let v = c as f32 * scale;
            match encoding {
                Encoding::Linear => v,
                Encoding::Srgb => srgb_to_linear(v),
            }
        })
        .collect();
    let saturated = codes
        .chunks_exact(channels)
        .map(|p| p.contains(&top))
        .collect();
    Ok(LinearImage {
        width,
        height,
        channels,
        data,
        saturated,
    })
}

fn read_exr(path: &Path, saturation: Option<f32>) -> Result<LinearImage> {
    let image = exr::prelude::read_first_flat_layer_from_file(path)
        .map_err(|e| anyhow!("{}: cannot read EXR image: {e}", path.display()))?;
    let layer = image.layer_data;
    let (width, height) = (layer.size.width(), layer.size.height());
    let list = &layer.channel_data.list;
    let get = |name: &str| list.iter().find(|c| c.name.to_string() == name);
    let planes: Vec<Vec<f32>> = if let (Some(r), Some(g), Some(b)) = (get("R"), get("G"), get("B"))
    {
        [r, g, b]
            .iter()
            .map(|c| c.sample_data.values_as_f32().collect())
            .collect()
    } else if let Some(y) = get("Y").or(if list.len() == 1 { list.first() } else { None }) {
        vec![y.sample_data.values_as_f32().collect()]
    } else {
        let names: Vec<String> = list.iter().map(|c| c.name.to_string()).collect();
        bail!(
            "{}: EXR needs channels R, G, B or Y; found {}",
            path.display(),
            names.join(", ")
        );
    };
    let channels = planes.len();
    let n = width * height;
    let mut data = Vec::with_capacity(n * channels);
    for i in 0..n {
        for p in &planes {
            data.push(p[i]);
        }
    }
    let saturated = match saturation {
        Some(level) => data
            .chunks_exact(channels)
            .map(|p| p.iter().any(|&v| v >= level))
            .collect(),
        None => vec![false; n],
    };
    Ok(LinearImage {
        width,
        height,
        channels,
        data,
        saturated,
    })
}
