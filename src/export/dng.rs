//! A DNG as a camera writes one, for synthetic photos (`fibrefit synth --photos --format dng`):
//! the linear values mosaicked through an RGGB Bayer filter, 16-bit codes over a black level,
//! the DNG tags a RAW decoder needs (CFA pattern, black and white levels, a colour matrix whose
//! camera space is linear sRGB, D65, neutral white balance as shot) and the exposure in an Exif
//! directory. The TIFF container is the `tiff` crate's.

use anyhow::{anyhow, Result};
use std::io::Cursor;
use tiff::encoder::{Rational, SRational, TiffEncoder};
use tiff::tags::Tag;

/// The code of linear value 0 (the sensor's black level).
pub const BLACK: u16 = 512;
/// The code of linear value 1 (the sensor's white level: a 14-bit sensor's top).
pub const WHITE: u16 = 16_383;

/// XYZ (D65) to linear sRGB: DNG's ColorMatrix1 maps XYZ to the camera's space, here linear
/// sRGB (IEC 61966-2-1).
const XYZ_TO_SRGB: [f64; 9] = [
    3.240_454_2,
    -1.537_138_5,
    -0.498_531_4,
    -0.969_266_0,
    1.876_010_8,
    0.041_556_0,
    0.055_643_4,
    -0.204_025_9,
    1.057_225_2,
];

/// The exposure a DNG states (in its Exif directory).
#[derive(Clone, Copy, Debug)]
pub struct DngExposure {
    /// Exposure time (s).
    pub time_s: f64,
    /// ISO speed.
    pub iso: u16,
    /// f-number.
    pub f_number: f64,
}

/// A `width` x `height` DNG of the linear RGB `rgb` (interleaved, row-major, 0 to 1 = black to
/// white level; clipped), each pixel keeping its Bayer filter's channel.
pub fn dng_bytes(width: u32, height: u32, rgb: &[f32], exposure: DngExposure) -> Result<Vec<u8>> {
    let (w, h) = (width as usize, height as usize);
    assert_eq!(rgb.len(), 3 * w * h, "width x height RGB values");
    let span = (WHITE - BLACK) as f32;
    let mut codes = vec![0u16; w * h];
    for y in 0..h {
        for x in 0..w {
            // RGGB: red at (even, even), blue at (odd, odd), green elsewhere
            let c = match (y % 2, x % 2) {
                (0, 0) => 0,
                (1, 1) => 2,
                _ => 1,
            };
            let v = rgb[3 * (y * w + x) + c].clamp(0.0, 1.0);
            codes[y * w + x] = BLACK + (v * span).round() as u16;
        }
    }
    let err = |e: tiff::TiffError| anyhow!("writing a DNG: {e}");
    let mut bytes = Cursor::new(Vec::new());
    let mut tiff = TiffEncoder::new(&mut bytes).map_err(err)?;
    let rational = |v: f64| Rational {
        n: (v * 10_000.0).round() as u32,
        d: 10_000,
    };
    let tag = Tag::Unknown;
    // the Exif directory: ExposureTime, FNumber, ISOSpeedRatings
    let exif = {
        let mut exif = tiff.extra_directory().map_err(err)?;
        exif.write_tag(tag(33_434), rational(exposure.time_s))
            .map_err(err)?;
        exif.write_tag(tag(33_437), rational(exposure.f_number))
            .map_err(err)?;
        exif.write_tag(tag(34_855), exposure.iso).map_err(err)?;
        exif.finish_with_offsets().map_err(err)?
    };
    let mut dir = tiff.image_directory().map_err(err)?;
    let offset = dir.write_data(&codes[..]).map_err(err)?;
    let srational = |v: f64| SRational {
        n: (v * 1_000_000.0).round() as i32,
        d: 1_000_000,
    };
    dir.write_tag(Tag::NewSubfileType, 0u32).map_err(err)?;
    dir.write_tag(Tag::ImageWidth, width).map_err(err)?;
    dir.write_tag(Tag::ImageLength, height).map_err(err)?;
    dir.write_tag(Tag::BitsPerSample, 16u16).map_err(err)?;
    dir.write_tag(Tag::Compression, 1u16).map_err(err)?;
    // CFA
    dir.write_tag(Tag::PhotometricInterpretation, 32_803u16)
        .map_err(err)?;
    dir.write_tag(Tag::Make, "fibrefit").map_err(err)?;
    dir.write_tag(Tag::Model, "synthetic photo").map_err(err)?;
    dir.write_tag(Tag::StripOffsets, offset as u32).map_err(err)?;
    dir.write_tag(Tag::Orientation, 1u16).map_err(err)?;
    dir.write_tag(Tag::SamplesPerPixel, 1u16).map_err(err)?;
    dir.write_tag(Tag::RowsPerStrip, height).map_err(err)?;
    dir.write_tag(Tag::StripByteCounts, (2 * w * h) as u32)
        .map_err(err)?;
    dir.write_tag(Tag::PlanarConfiguration, 1u16).map_err(err)?;
    // ExifIFD
    dir.write_tag(tag(34_665), exif.offset).map_err(err)?;
    // CFARepeatPatternDim, CFAPattern
    dir.write_tag(tag(33_421), &[2u16, 2][..]).map_err(err)?;
    dir.write_tag(tag(33_422), &[0u8, 1, 1, 2][..]).map_err(err)?;
    // DNGVersion, DNGBackwardVersion, UniqueCameraModel
    dir.write_tag(tag(50_706), &[1u8, 4, 0, 0][..]).map_err(err)?;
    dir.write_tag(tag(50_707), &[1u8, 1, 0, 0][..]).map_err(err)?;
    dir.write_tag(tag(50_708), "fibrefit synthetic photo")
        .map_err(err)?;
    // BlackLevelRepeatDim, BlackLevel, WhiteLevel
    dir.write_tag(tag(50_713), &[1u16, 1][..]).map_err(err)?;
    dir.write_tag(tag(50_714), BLACK as u32).map_err(err)?;
    dir.write_tag(tag(50_717), WHITE as u32).map_err(err)?;
    // ColorMatrix1 (XYZ to camera = linear sRGB), AsShotNeutral, CalibrationIlluminant1 = D65
    let matrix: Vec<SRational> = XYZ_TO_SRGB.iter().map(|&v| srational(v)).collect();
    dir.write_tag(tag(50_721), &matrix[..]).map_err(err)?;
    let neutral = [rational(1.0), rational(1.0), rational(1.0)];
    dir.write_tag(tag(50_728), &neutral[..]).map_err(err)?;
    dir.write_tag(tag(50_778), 21u16).map_err(err)?;
    dir.finish().map_err(err)?;
    drop(tiff);
    Ok(bytes.into_inner())
}
