//! Writing images (used by `fibrefit synth` and reports): float EXR, 16-bit PNG.

use crate::load::image_io::linear_to_srgb;
use anyhow::{anyhow, Result};
use exr::prelude::*;
use std::path::Path;

type ExrImage = Image<Layer<AnyChannels<FlatSamples>>>;

/// Interleaved linear `data` (1, 3 or 4 channels: Y; R, G, B; R, G, B, A) as a float EXR image.
fn exr_image(width: usize, height: usize, channels: usize, data: &[f32]) -> ExrImage {
    let plane = |c: usize| -> Vec<f32> { data.iter().skip(c).step_by(channels).copied().collect() };
    let names: &[&str] = match channels {
        1 => &["Y"],
        3 => &["R", "G", "B"],
        _ => &["R", "G", "B", "A"],
    };
    let list: Vec<AnyChannel<FlatSamples>> = names
        .iter()
        .enumerate()
        .map(|(c, n)| AnyChannel::new(*n, FlatSamples::F32(plane(c))))
        .collect();
    let layer = Layer::new(
        (width, height),
        LayerAttributes::named("fibrefit"),
        exr::prelude::Encoding::FAST_LOSSLESS,
        AnyChannels::sort(list.into()),
    );
    Image::from_layer(layer)
}

/// Write interleaved linear `data` (1, 3 or 4 channels) as a float EXR (channels Y; R, G, B;
/// R, G, B, A).
pub fn write_exr(
    path: &Path,
    width: usize,
    height: usize,
    channels: usize,
    data: &[f32],
) -> Result<()> {
    let mut f = super::atomic::AtomicFile::create(path)?;
    write_exr_into(f.file(), path, width, height, channels, data)?;
    f.commit()
}

/// [`write_exr`] into an open file (an [`super::atomic::AtomicFile`]'s); `name` for errors.
pub fn write_exr_into(
    file: &mut std::fs::File,
    name: &Path,
    width: usize,
    height: usize,
    channels: usize,
    data: &[f32],
) -> Result<()> {
    let mut w = std::io::BufWriter::new(file);
    exr_image(width, height, channels, data)
        .write()
        .to_buffered(&mut w)
        .map_err(|e| anyhow!("{}: cannot write EXR: {e}", name.display()))?;
    std::io::Write::flush(&mut w).map_err(|e| anyhow!("{}: cannot write EXR: {e}", name.display()))
}

/// Write linear values in [0, 1] as a 16-bit PNG with the given encoding (values above 1 clip to
/// the top code, i.e. saturate).
pub fn write_png16(
    path: &Path,
    width: usize,
    height: usize,
    channels: usize,
    data: &[f32],
    encoding: crate::load::image_io::Encoding,
) -> Result<()> {
    let codes: Vec<u16> = data
        .iter()
        .map(|&v| {
            let v = v.clamp(0.0, 1.0);
            let e = match encoding {
                crate::load::image_io::Encoding::Linear => v,
                crate::load::image_io::Encoding::Srgb => linear_to_srgb(v),
            };
            (e * 65535.0).round() as u16
        })
        .collect();
    let (w, h) = (width as u32, height as u32);
    let mut f = super::atomic::AtomicFile::create(path)?;
    let mut out = std::io::BufWriter::new(f.writer());
    let result = if channels == 1 {
        image::ImageBuffer::<image::Luma<u16>, _>::from_raw(w, h, codes)
            .map(|b| b.write_to(&mut out, image::ImageFormat::Png))
    } else {
        image::ImageBuffer::<image::Rgb<u16>, _>::from_raw(w, h, codes)
            .map(|b| b.write_to(&mut out, image::ImageFormat::Png))
    };
    result
        .ok_or_else(|| anyhow!("{}: image buffer size mismatch", path.display()))?
        .map_err(|e| anyhow!("{}: cannot write PNG: {e}", path.display()))?;
    std::io::Write::flush(&mut out)
        .map_err(|e| anyhow!("{}: cannot write PNG: {e}", path.display()))?;
    drop(out);
    f.commit()
}

/// Write values in [0, 1] as a 16-bit grayscale PNG (topology maps, masks).
pub fn write_gray16(path: &Path, width: usize, height: usize, values: &[f32]) -> Result<()> {
    write_png16(
        path,
        width,
        height,
        1,
        values,
        crate::load::image_io::Encoding::Linear,
    )
}
