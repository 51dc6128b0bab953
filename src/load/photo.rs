//! Photos of a calibration board (`fibrefit calibrate`): JPEG (8-bit sRGB), PNG or TIFF (8 or 16
//! bit, sRGB-encoded or linear: [`Encoding`], as a raw converter writes them), decoded to linear
//! RGB, with the linear grey picture the marker detector reads. A phone's JPEG tone curve is not
//! exactly sRGB: the camera's RAW (DNG and the makers' formats, decoded to linear values by
//! [`super::image_io::decode_raw`]) or a linear 16-bit TIFF from it is better.

use super::image_io::{decode_jpeg, decode_png, decode_raw, decode_tiff, srgb_to_linear, Encoding};
use anyhow::{bail, Result};
use std::path::{Path, PathBuf};

/// Camera RAW files read as photos (lower case): DNG and the makers' own formats.
pub const RAW_EXTENSIONS: [&str; 10] = ["dng", "cr2", "cr3", "nef", "arw", "raf", "rw2", "orf", "pef", "srw"];

/// A decoded photo.
pub struct Photo {
    /// Where it was read.
    pub path: PathBuf,
    /// Size in pixels.
    pub width: usize,
    /// Size in pixels.
    pub height: usize,
    /// Linear RGB, row-major, interleaved.
    pub linear: Vec<f32>,
    /// Largest linear value of any channel of each pixel (clipping shows as 1).
    pub peak: Vec<f32>,
    /// The exposure its EXIF gives, when it has one.
    pub exif: Option<Exposure>,
}

/// What a photo is without its pixels: kept for every photo while only one's pixels are held
/// (12 photos of 12 Mpx as linear f32 would take 2 GB).
#[derive(Clone, Debug)]
pub struct PhotoInfo {
    /// Where it was read.
    pub path: PathBuf,
    /// Size in pixels.
    pub width: usize,
    /// Size in pixels.
    pub height: usize,
    /// The exposure its EXIF gives, when it has one.
    pub exif: Option<Exposure>,
}

/// A photo's exposure from its EXIF.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Exposure {
    /// Exposure time (s).
    pub time_s: Option<f64>,
    /// ISO speed.
    pub iso: Option<f64>,
    /// f-number.
    pub f_number: Option<f64>,
}

impl Exposure {
    /// The relative exposure time x ISO / f-number^2 (None unless all three are known).
    pub fn product(&self) -> Option<f64> {
        Some(self.time_s? * self.iso? / (self.f_number? * self.f_number?))
    }
}

/// The exposure in the EXIF of the photo at `path` (None: no EXIF, or none of its fields).
fn read_exif(path: &Path) -> Result<Option<Exposure>> {
    let bytes = super::input::read_input_as(path, super::MAX_INPUT_BYTES, "photo")?.bytes;
    let Ok(exif) = exif::Reader::new().read_from_container(&mut std::io::Cursor::new(&bytes))
    else {
        return Ok(None);
    };
    let number = |tag: exif::Tag| -> Option<f64> {
        let f = exif.get_field(tag, exif::In::PRIMARY)?;
        let v = match &f.value {
            exif::Value::Rational(r) => r.first()?.to_f64(),
            exif::Value::Short(s) => *s.first()? as f64,
            exif::Value::Long(l) => *l.first()? as f64,
            _ => return None,
        };
        (v.is_finite() && v > 0.0).then_some(v)
    };
    let e = Exposure {
        time_s: number(exif::Tag::ExposureTime),
        iso: number(exif::Tag::PhotographicSensitivity),
        f_number: number(exif::Tag::FNumber),
    };
    Ok((e != Exposure::default()).then_some(e))
}

impl Photo {
    /// Read and decode the photo at `path`, its code values `encoding` (a JPEG is always sRGB;
    /// refused: another format, a corrupt or truncated file, more pixels than a capture image
    /// may have).
    pub fn read(path: &Path, encoding: Encoding) -> Result<Self> {
        let ext = path
            .extension()
            .and_then(|e| e.to_str())
            .map(|e| e.to_ascii_lowercase())
            .unwrap_or_default();
        if RAW_EXTENSIONS.contains(&ext.as_str()) {
            let (width, height, linear) = decode_raw(path, "photo")?;
            return Self::from_linear(path, width, height, linear);
        }
        let (img, encoding) = match ext.as_str() {
            "jpg" | "jpeg" => {
                if encoding == Encoding::Linear {
                    bail!(
                        "{}: a JPEG is sRGB-encoded; --encoding linear is for 16-bit PNG or TIFF",
                        path.display()
                    );
                }
                (decode_jpeg(path, "photo")?, Encoding::Srgb)
            }
            "png" => (decode_png(path, "photo")?, encoding),
            "tif" | "tiff" => (decode_tiff(path, "photo")?, encoding),
            _ => bail!(
                "{}: photos must be .jpg/.jpeg, .png, .tif/.tiff or camera RAW ({})",
                path.display(),
                RAW_EXTENSIONS.map(|e| format!(".{e}")).join(", ")
            ),
        };
        let rgb = img.to_rgb32f();
        let (width, height) = (rgb.width() as usize, rgb.height() as usize);
        let decode = match encoding {
            Encoding::Srgb => srgb_to_linear,
            Encoding::Linear => |c: f32| c,
        };
        let linear: Vec<f32> = rgb.into_raw().into_iter().map(decode).collect();
        Self::from_linear(path, width, height, linear)
    }

    /// The photo at `path` from its decoded linear RGB.
    fn from_linear(path: &Path, width: usize, height: usize, linear: Vec<f32>) -> Result<Self> {
        let peak = linear
            .chunks_exact(3)
            .map(|p| p[0].max(p[1]).max(p[2]))
            .collect();
        Ok(Self {
            path: path.to_path_buf(),
            width,
            height,
            linear,
            peak,
            exif: read_exif(path)?,
        })
    }

    /// This photo less `ambient` (the same pose with its light off), pixel by pixel, at least
    /// 0; `peak` stays the lit photo's (clipping is the sensor's). Refused when the sizes
    /// differ, or the EXIF exposures (when both have them) by more than 2 %.
    pub fn less_ambient(mut self, ambient: &Photo) -> Result<Self> {
        if (ambient.width, ambient.height) != (self.width, self.height) {
            bail!(
                "{}: {}x{} pixels, but its photo {} is {}x{}: an ambient frame is the same pose and camera with the light off",
                ambient.path.display(),
                ambient.width,
                ambient.height,
                self.path.display(),
                self.width,
                self.height
            );
        }
        let products = self.exif.and_then(|e| e.product()).zip(ambient.exif.and_then(|e| e.product()));
        if let Some((lit, off)) = products.filter(|(lit, off)| (off / lit - 1.0).abs() > 0.02) {
            bail!(
                "{}: its EXIF exposure (time x ISO / f-number^2) is {:.3} times its photo {}'s: an ambient frame must be taken at the photo's exposure to be subtracted",
                ambient.path.display(),
                off / lit,
                self.path.display()
            );
        }
        for (v, a) in self.linear.iter_mut().zip(&ambient.linear) {
            *v = (*v - a).max(0.0);
        }
        Ok(self)
    }

    /// The photo without its pixels.
    pub fn info(&self) -> PhotoInfo {
        PhotoInfo {
            path: self.path.clone(),
            width: self.width,
            height: self.height,
            exif: self.exif,
        }
    }

    /// The linear luminance (Rec. 709 weights) as 8 bits: what the marker detector reads.
    pub fn grey8(&self) -> Vec<u8> {
        self.linear
            .chunks_exact(3)
            .map(|p| {
                let y = 0.2126 * p[0] + 0.7152 * p[1] + 0.0722 * p[2];
                (y * 255.0).round().clamp(0.0, 255.0) as u8
            })
            .collect()
    }

    /// The largest [`Photo::peak`] of the pixels [`Photo::sample`] blends at `(u, v)` (the lit
    /// photo's, before any ambient frame is taken off); None outside the picture.
    pub fn peak_near(&self, u: f64, v: f64) -> Option<f32> {
        let (x, y) = (u - 0.5, v - 0.5);
        if x < 0.0 || y < 0.0 || x > (self.width - 1) as f64 || y > (self.height - 1) as f64 {
            return None;
        }
        let (x0, y0) = (x.floor() as usize, y.floor() as usize);
        let (x1, y1) = ((x0 + 1).min(self.width - 1), (y0 + 1).min(self.height - 1));
        let at = |xx: usize, yy: usize| self.peak[yy * self.width + xx];
        Some(at(x0, y0).max(at(x1, y0)).max(at(x0, y1)).max(at(x1, y1)))
    }

    /// The linear RGB at pixel position `(u, v)` (pixel edges at integers), bilinear; None
    /// outside the picture.
    pub fn sample(&self, u: f64, v: f64) -> Option<[f32; 3]> {
        let (x, y) = (u - 0.5, v - 0.5);
        if x < 0.0 || y < 0.0 || x > (self.width - 1) as f64 || y > (self.height - 1) as f64 {
            return None;
        }
        let (x0, y0) = (x.floor() as usize, y.floor() as usize);
        let (x1, y1) = ((x0 + 1).min(self.width - 1), (y0 + 1).min(self.height - 1));
        let (a, b) = ((x - x0 as f64) as f32, (y - y0 as f64) as f32);
        let at = |xx: usize, yy: usize, c: usize| self.linear[3 * (yy * self.width + xx) + c];
        Some([0, 1, 2].map(|c| {
            (1.0 - b) * ((1.0 - a) * at(x0, y0, c) + a * at(x1, y0, c))
                + b * ((1.0 - a) * at(x0, y1, c) + a * at(x1, y1, c))
        }))
    }
}
