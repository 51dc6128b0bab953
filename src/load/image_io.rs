//! Reading captured images into linear values: PNG and TIFF (8/16 bit, linear or sRGB encoded;
//! TIFF also 32-bit float) and EXR.
//!
//! Every image (captures, masks, tangent, topology, height and view maps, result maps) is read
//! once through [`super::input`] (at most [`super::input::MAX_INPUT_BYTES`], hashed), its size
//! taken from its header *before* any pixel is decoded: more than [`MAX_IMAGE_PIXELS`] pixels
//! (2^28, e.g. 16384 x 16384), or more memory to read than [`MAX_IMAGE_BYTES`], is refused with
//! the image named and its claimed size, and the decoders are given a memory limit
//! ([`MAX_DECODE_BYTES`]), so that a small file claiming a
//! huge image, or a compressed one that expands without end (a PNG or ZIP-EXR bomb), is an
//! error, not an allocation failure.

use anyhow::{anyhow, bail, Result};
use std::io::Cursor;
use std::path::Path;

/// The most pixels one image may have: 2^28 (268 million; 16384 x 16384), checked from the
/// header before decoding.
pub const MAX_IMAGE_PIXELS: u64 = 1 << 28;

/// The most memory reading one image may take: 1 GiB, counted from the header before any
/// pixel is decoded ([`image_memory`]: the decoded samples, the linear f32 copy, the
/// intermediate codes and the saturation flags). An RGB half-float EXR reaches it at about 56
/// million pixels (7500 x 7500), a grey 8-bit PNG at about 150 million.
pub const MAX_IMAGE_BYTES: u64 = 1 << 30;

/// The most bytes a decoder may allocate for one image's pixels (its limit, as a second
/// guard): [`MAX_IMAGE_BYTES`].
pub const MAX_DECODE_BYTES: u64 = MAX_IMAGE_BYTES;

/// The memory reading a `width` x `height` image takes whose decoded pixels have `channels`
/// channels of `sample_bytes` bytes each: the decoded samples, then per linear channel (1 or
/// 3) an intermediate value (a code, or an EXR plane's f32) and the linear f32, and a
/// saturation flag per pixel. `None` on overflow.
pub fn image_memory(width: u64, height: u64, channels: u64, sample_bytes: u64) -> Option<u64> {
    let linear = if channels >= 3 { 3 } else { 1 };
    let per_pixel = channels
        .checked_mul(sample_bytes)?
        .checked_add(linear * 8 + 1)?;
    width.checked_mul(height)?.checked_mul(per_pixel)
}

/// Refuse an image (at `path`, a `what`) whose reading would take more than
/// [`MAX_IMAGE_BYTES`] ([`image_memory`]), with the estimate.
pub fn check_image_memory(
    path: &Path,
    what: &str,
    (width, height): (u64, u64),
    channels: u64,
    sample_bytes: u64,
) -> Result<()> {
    let bytes = image_memory(width, height, channels, sample_bytes);
    if bytes.is_none_or(|b| b > MAX_IMAGE_BYTES) {
        bail!(
            "{}: {what} claims {width}x{height} pixels of {channels} channels ({sample_bytes} bytes each): reading it would take {} of memory; the most one image may take is {} (docs/safety.md)",
            path.display(),
            bytes.map_or("more than 2^64 bytes".to_string(), |b| format!("{:.2} GiB", b as f64 / (1u64 << 30) as f64)),
            super::input::bytes_text(MAX_IMAGE_BYTES)
        );
    }
    Ok(())
}

/// Refuse a `width` x `height` image (claimed by the header of `path`, a `what`) beyond
/// [`MAX_IMAGE_PIXELS`], or with a zero side.
pub fn check_pixels(path: &Path, what: &str, width: u64, height: u64) -> Result<()> {
    let pixels = width.checked_mul(height);
    if width == 0 || height == 0 {
        bail!(
            "{}: {what} is {width}x{height} pixels: empty",
            path.display()
        );
    }
    if pixels.is_none_or(|p| p > MAX_IMAGE_PIXELS) {
        bail!(
            "{}: {what} claims {width}x{height} pixels; the most an image may have is {MAX_IMAGE_PIXELS} (2^28, e.g. 16384x16384)",
            path.display()
        );
    }
    Ok(())
}

/// The bytes of `path` (a `what`) when they start with `magic`: the signature is read first, so
/// that a device or another kind of file is refused after a few bytes, not after the limit.
fn read_with_magic(path: &Path, what: &str, magic: &[u8], kind: &str) -> Result<Vec<u8>> {
    read_with_any_magic(path, what, &[magic], kind)
}

/// [`read_with_magic`] for formats with several signatures (TIFF: little or big endian).
fn read_with_any_magic(path: &Path, what: &str, magics: &[&[u8]], kind: &str) -> Result<Vec<u8>> {
    use std::io::Read;
    let mut input = super::input::open_as(path, super::input::MAX_INPUT_BYTES, what)?;
    let mut bytes = Vec::new();
    (&mut input)
        .take(magics[0].len() as u64)
        .read_to_end(&mut bytes)
        .map_err(|e| super::input::io_error(path, e))?;
    if !magics.contains(&&bytes[..]) {
        bail!(
            "{}: cannot read {kind} {what}: not a{} {kind} file (no {kind} signature)",
            path.display(),
            if kind == "EXR" { "n" } else { "" }
        );
    }
    input.read_rest(&mut bytes)?;
    input.finish()?;
    Ok(bytes)
}

/// A PNG at `path` (a `what`), its size checked from the header before decoding, decoded with
/// [`MAX_DECODE_BYTES`] as the limit.
pub fn decode_png(path: &Path, what: &str) -> Result<image::DynamicImage> {
    let bytes = read_with_magic(path, what, b"\x89PNG\r\n\x1a\n", "PNG")?;
    decode_limited(path, what, bytes)
}

/// A JPEG at `path` (a `what`: a photo), its size checked from the header before decoding,
/// decoded with [`MAX_DECODE_BYTES`] as the limit.
pub fn decode_jpeg(path: &Path, what: &str) -> Result<image::DynamicImage> {
    let bytes = read_with_magic(path, what, b"\xff\xd8\xff", "JPEG")?;
    decode_limited(path, what, bytes)
}

/// A TIFF at `path` (a `what`; little- or big-endian, uncompressed, LZW or Deflate as raw
/// converters write them), its size checked from the header before decoding, decoded with
/// [`MAX_DECODE_BYTES`] as the limit.
pub fn decode_tiff(path: &Path, what: &str) -> Result<image::DynamicImage> {
    let bytes = read_with_any_magic(path, what, &[b"II*\0", b"MM\0*"], "TIFF")?;
    decode_limited(path, what, bytes)
}

/// A camera RAW / DNG at `path` (a `what`) decoded by `flashraw` to linear RGB (sRGB
/// primaries, f32 interleaved, sensor orientation): black and white levels applied, demosaiced
/// (bilinear), white-balanced as shot and converted by the file's colour matrix; negative
/// values (noise about the black level) clamped to 0 as a camera's JPEG would. Its size is
/// checked from the header before decoding; a truncated or corrupt file is refused, not
/// patched. Returns (width, height, values).
pub fn decode_raw(path: &Path, what: &str) -> Result<(usize, usize, Vec<f32>)> {
    let name = path.display();
    let bytes = super::input::read_input_as(path, super::input::MAX_INPUT_BYTES, what)?.bytes;
    let limits = flashraw::Limits::default()
        .with_max_samples(3 * MAX_IMAGE_PIXELS)
        .with_max_dimension(1 << 20);
    let raw = flashraw::FlashRaw::open_with(&bytes[..], limits)
        .map_err(|e| anyhow!("{name}: cannot read {what} as camera RAW / DNG: {e}"))?;
    let info = raw.frame_info();
    let (w, h) = (info.width as u64, info.height as u64);
    check_pixels(path, what, w, h)?;
    check_image_memory(path, what, (w, h), 3, 4)?;
    let mut opts = flashraw::DecodeOptions::default();
    opts.output = flashraw::OutputFormat::LinearRgbF32;
    opts.limits = limits;
    opts.corruption_policy = flashraw::CorruptionPolicy::Strict;
    let frame = raw
        .decode(opts)
        .map_err(|e| anyhow!("{name}: cannot decode {what} (camera RAW / DNG): {e}"))?;
    if frame.is_incomplete() {
        bail!(
            "{name}: {what} is incomplete (camera RAW / DNG): {:?}",
            frame.warnings()
        );
    }
    let (fw, fh) = (frame.width() as usize, frame.height() as usize);
    let Some(values) = frame.as_f32() else {
        bail!("{name}: {what}: the RAW decoder gave no linear RGB");
    };
    if values.len() != 3 * fw * fh {
        bail!(
            "{name}: {what}: the RAW decoder gave {} values for {fw}x{fh} RGB pixels",
            values.len()
        );
    }
    let values = values
        .iter()
        .map(|&v| if v.is_finite() { v.max(0.0) } else { 0.0 })
        .collect();
    Ok((fw, fh, values))
}

/// `bytes` of an image (a `what` at `path`) decoded by the `image` crate, its size taken from
/// the header first.
fn decode_limited(path: &Path, what: &str, bytes: Vec<u8>) -> Result<image::DynamicImage> {
    let name = path.display();
    let reader = || {
        image::ImageReader::new(Cursor::new(&bytes[..]))
            .with_guessed_format()
            .map_err(|e| anyhow!("{name}: cannot read {what}: {e}"))
    };
    use image::ImageDecoder;
    let decoder = reader()?
        .into_decoder()
        .map_err(|e| anyhow!("{name}: cannot decode {what}: {e}"))?;
    let (w, h) = decoder.dimensions();
    let colour = decoder.color_type();
    drop(decoder);
    check_pixels(path, what, w as u64, h as u64)?;
    let channels = colour.channel_count() as u64;
    check_image_memory(
        path,
        what,
        (w as u64, h as u64),
        channels,
        colour.bytes_per_pixel() as u64 / channels.max(1),
    )?;
    let mut r = reader()?;
    let mut limits = image::Limits::default();
    limits.max_alloc = Some(MAX_DECODE_BYTES);
    r.limits(limits);
    r.decode()
        .map_err(|e| anyhow!("{name}: cannot decode {what}: {e}"))
}

/// The first layer of the EXR at `path` (a `what`): the header read first and every layer's
/// size and decoded bytes checked before any pixel is read.
pub fn decode_exr(
    path: &Path,
    what: &str,
) -> Result<exr::image::Layer<exr::image::AnyChannels<exr::image::FlatSamples>>> {
    let bytes = read_with_magic(path, what, &[0x76, 0x2f, 0x31, 0x01], "EXR")?;
    let name = path.display();
    let meta = exr::meta::MetaData::read_from_buffered(Cursor::new(&bytes[..]), false)
        .map_err(|e| anyhow!("{name}: cannot read EXR {what}: {e}"))?;
    for header in meta.headers.iter() {
        let size = header.layer_size;
        check_pixels(path, what, size.0 as u64, size.1 as u64)?;
        let per_pixel: u64 = header
            .channels
            .list
            .iter()
            .map(|c| c.sample_type.bytes_per_sample() as u64)
            .sum();
        let channels = header.channels.list.len() as u64;
        check_image_memory(
            path,
            what,
            (size.0 as u64, size.1 as u64),
            channels,
            per_pixel.div_ceil(channels.max(1)),
        )?;
    }
    use exr::prelude::traits::{ReadChannels, ReadLayers};
    let image = exr::prelude::read()
        .no_deep_data()
        .largest_resolution_level()
        .all_channels()
        .first_valid_layer()
        .all_attributes()
        .from_buffered(Cursor::new(bytes))
        .map_err(|e| anyhow!("{name}: cannot read EXR {what}: {e}"))?;
    Ok(image.layer_data)
}

/// The size of the image at `path` and the channels it reads as (1 grey or 3 RGB), from its
/// header alone (nothing decoded), with the per-image checks ([`check_pixels`],
/// [`check_image_memory`]) made: what a capture's memory is planned from.
pub fn header(path: &Path) -> Result<(usize, usize, usize)> {
    let name = path.display();
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase);
    let (w, h, channels) = match ext.as_deref() {
        Some("exr") => {
            let bytes = read_with_magic(path, "image", &[0x76, 0x2f, 0x31, 0x01], "EXR")?;
            let meta = exr::meta::MetaData::read_from_buffered(Cursor::new(&bytes[..]), false)
                .map_err(|e| anyhow!("{name}: cannot read EXR image: {e}"))?;
            let Some(header) = meta.headers.first() else {
                bail!("{name}: cannot read EXR image: no layer");
            };
            let size = header.layer_size;
            let per_pixel: u64 = header
                .channels
                .list
                .iter()
                .map(|c| c.sample_type.bytes_per_sample() as u64)
                .sum();
            let c = header.channels.list.len() as u64;
            check_pixels(path, "image", size.0 as u64, size.1 as u64)?;
            check_image_memory(
                path,
                "image",
                (size.0 as u64, size.1 as u64),
                c,
                per_pixel.div_ceil(c.max(1)),
            )?;
            (size.0, size.1, c as usize)
        }
        Some(kind @ ("png" | "tif" | "tiff")) => {
            let bytes = match kind {
                "png" => read_with_magic(path, "image", b"\x89PNG\r\n\x1a\n", "PNG")?,
                _ => read_with_any_magic(path, "image", &[b"II*\0", b"MM\0*"], "TIFF")?,
            };
            use image::ImageDecoder;
            let decoder = image::ImageReader::new(Cursor::new(&bytes[..]))
                .with_guessed_format()
                .map_err(|e| anyhow!("{name}: cannot read image: {e}"))?
                .into_decoder()
                .map_err(|e| anyhow!("{name}: cannot decode image: {e}"))?;
            let (w, h) = decoder.dimensions();
            let colour = decoder.color_type();
            let c = colour.channel_count() as u64;
            check_pixels(path, "image", w as u64, h as u64)?;
            check_image_memory(
                path,
                "image",
                (w as u64, h as u64),
                c,
                colour.bytes_per_pixel() as u64 / c.max(1),
            )?;
            (w as usize, h as usize, c as usize)
        }
        _ => bail!("{name}: images must be .png, .exr or .tif/.tiff"),
    };
    Ok((w, h, if channels >= 3 { 3 } else { 1 }))
}

/// How a PNG's code values relate to light.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Deserialize, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Encoding {
    /// Code values proportional to light (a raw converter's linear output).
    Linear,
    /// sRGB-encoded code values (IEC 61966-2-1), decoded to linear.
    Srgb,
}

/// A linear image, channels interleaved (1 = grey, 3 = RGB), row 0 at the top.
#[derive(Clone, Debug, PartialEq)]
pub struct LinearImage {
    /// Width, pixels.
    pub width: usize,
    /// Height, pixels.
    pub height: usize,
    /// Channels: 1 (grey) or 3 (RGB).
    pub channels: usize,
    /// Values, linear, row by row from the top, channels interleaved.
    pub data: Vec<f32>,
    /// Per pixel: a channel hit the sensor's top code (PNG) or the given saturation level (EXR).
    pub saturated: Vec<bool>,
    /// The value at which a pixel saturates: 1 (the top code of an 8/16-bit image, linear or
    /// sRGB), a float image's `saturation` level, or infinity.
    pub clip: f32,
}

impl LinearImage {
    /// The channels of pixel (`x`, `y`), `y` from the top.
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
        Some("tif" | "tiff") => {
            let img = decode_tiff(path, "image")?;
            if matches!(
                img,
                image::DynamicImage::ImageRgb32F(_) | image::DynamicImage::ImageRgba32F(_)
            ) {
                if encoding == Some(Encoding::Srgb) {
                    bail!(
                        "{}: a floating-point TIFF is linear; `encoding = \"srgb\"` does not apply",
                        path.display()
                    );
                }
                return from_float(path, img, saturation);
            }
            let encoding = encoding.ok_or_else(|| {
                anyhow!(
                    "{}: 8/16-bit TIFF images need `encoding = \"linear\"` (raw converters' linear output) or `\"srgb\"`",
                    path.display()
                )
            })?;
            if saturation.is_some() {
                bail!(
                    "{}: `saturation` applies to floating-point images only (8/16-bit images saturate at their largest code)",
                    path.display()
                );
            }
            from_codes(path, img, encoding, "TIFF")
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
        _ => bail!(
            "{}: images must be .png, .exr or .tif/.tiff",
            path.display()
        ),
    }
}

fn read_png(path: &Path, encoding: Encoding) -> Result<LinearImage> {
    from_codes(path, decode_png(path, "image")?, encoding, "PNG")
}

/// A 32-bit float image (TIFF) as linear values; `saturation` marks values at or above it.
fn from_float(
    path: &Path,
    img: image::DynamicImage,
    saturation: Option<f32>,
) -> Result<LinearImage> {
    let (width, height) = (img.width() as usize, img.height() as usize);
    let data: Vec<f32> = match img {
        image::DynamicImage::ImageRgb32F(b) => b.into_raw(),
        image::DynamicImage::ImageRgba32F(b) => b
            .into_raw()
            .chunks_exact(4)
            .flat_map(|p| [p[0], p[1], p[2]])
            .collect(),
        other => bail!(
            "{}: unsupported floating-point pixel format {:?}",
            path.display(),
            other.color()
        ),
    };
    let saturated = data
        .chunks_exact(3)
        .map(|p| saturation.is_some_and(|level| p.iter().any(|&v| v >= level)))
        .collect();
    Ok(LinearImage {
        width,
        height,
        channels: 3,
        data,
        saturated,
        clip: saturation.unwrap_or(f32::INFINITY),
    })
}

/// An 8/16-bit image's codes as linear values in [0, 1] (`encoding`: how the codes relate to
/// light); a pixel with a channel at the top code is saturated.
fn from_codes(
    path: &Path,
    img: image::DynamicImage,
    encoding: Encoding,
    kind: &str,
) -> Result<LinearImage> {
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
            "{}: unsupported {kind} pixel format {:?}",
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
        clip: 1.0,
    })
}

fn read_exr(path: &Path, saturation: Option<f32>) -> Result<LinearImage> {
    let layer = decode_exr(path, "image")?;
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
        clip: saturation.unwrap_or(f32::INFINITY),
    })
}
