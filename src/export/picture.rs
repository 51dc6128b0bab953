//! Rendered pictures as files: `.exr` linear RGBA, `.png` 8-bit sRGB of radiance x exposure
//! with alpha, and the AOVs (normal, tangent, position, height) as EXRs, all through the run's
//! reserved outputs.

use super::atomic::{OutputId, Outputs};
use crate::render::Picture;
use anyhow::{anyhow, bail, Result};
use std::path::Path;

/// Lit pixels' value (the largest channel, coverage undone) that `auto` exposure puts at the
/// shoulder's knee: this percentile of the object's pixels.
pub const AUTO_PERCENTILE: f64 = 99.5;
/// The tone curve of `auto` exposure: linear up to this display value, then a shoulder that
/// approaches 1 without reaching it (highlights compressed, never clipped).
pub const KNEE: f64 = 0.8;

/// The tone curve of `auto` exposure on a display value x >= 0 (linear radiance x exposure):
/// x below [`KNEE`], then KNEE + (1 - KNEE) (1 - exp(-(x - KNEE) / (1 - KNEE))) (C1 at the
/// knee, rising towards 1: 0.998 at x = 1.7; 1 only in rounding, past x ~ 8).
pub fn shoulder(x: f64) -> f64 {
    if x <= KNEE {
        x.max(0.0)
    } else {
        let w = 1.0 - KNEE;
        KNEE + w * (1.0 - (-(x - KNEE) / w).exp())
    }
}

/// `auto` exposure of a picture: the [`AUTO_PERCENTILE`] of its lit pixels' largest channel
/// (coverage undone) to [`KNEE`]; 1 when nothing is lit.
pub fn auto_exposure(pic: &Picture) -> f64 {
    let mut lum: Vec<f32> = pic
        .radiance
        .iter()
        .zip(&pic.alpha)
        .filter(|(_, a)| **a > 0.0)
        .map(|(c, a)| c[0].max(c[1]).max(c[2]) / a)
        .filter(|v| *v > 0.0 && v.is_finite())
        .collect();
    lum.sort_by(f32::total_cmp);
    let k = ((lum.len() as f64 * AUTO_PERCENTILE / 100.0) as usize).min(lum.len().max(1) - 1);
    match lum.get(k) {
        Some(&p) if p > 0.0 => KNEE / p as f64,
        _ => 1.0,
    }
}

/// 8-bit sRGB RGBA of `pic` x `exposure`: clipped at 1, or with `shoulder` through
/// [`shoulder`] applied to each pixel's largest channel (the channels scaled together, so the
/// hue stays); alpha is the coverage.
pub fn srgb_rgba(pic: &Picture, exposure: f64, with_shoulder: bool) -> Vec<u8> {
    pic.radiance
        .iter()
        .zip(&pic.alpha)
        .flat_map(|(c, a)| {
            // premultiplied by coverage in the sum: undo it for the colour
            let un = |v: f32| if *a > 0.0 { v as f64 / *a as f64 } else { 0.0 };
            let rgb = [
                un(c[0]) * exposure,
                un(c[1]) * exposure,
                un(c[2]) * exposure,
            ];
            let scale = if with_shoulder {
                let m = rgb[0].max(rgb[1]).max(rgb[2]);
                if m > 0.0 {
                    shoulder(m) / m
                } else {
                    1.0
                }
            } else {
                1.0
            };
            let code = |v: f64| {
                (crate::load::image_io::linear_to_srgb((v * scale).clamp(0.0, 1.0) as f32) * 255.0)
                    .round() as u8
            };
            [
                code(rgb[0]),
                code(rgb[1]),
                code(rgb[2]),
                (a * 255.0).round() as u8,
            ]
        })
        .collect()
}

/// Write `pic` to `path` (.exr linear RGBA, .png sRGB RGBA with `exposure`: a number, radiance
/// times it clipped at 1, or `auto`, [`auto_exposure`] with the [`shoulder`]); returns the
/// exposure used.
pub fn write_picture(
    outs: &mut Outputs,
    id: OutputId,
    pic: &Picture,
    exposure: &str,
) -> Result<Option<f64>> {
    let path = &outs.name(id).to_path_buf();
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase);
    let out = &mut *outs;
    let used = match ext.as_deref() {
        Some("exr") => {
            let data: Vec<f32> = pic
                .radiance
                .iter()
                .zip(&pic.alpha)
                .flat_map(|(c, a)| [c[0], c[1], c[2], *a])
                .collect();
            super::images::write_exr_into(
                out.file_and_name(id).0,
                path,
                pic.width,
                pic.height,
                4,
                &data,
            )?;
            None
        }
        Some("png") => {
            let (e, tone) = match exposure {
                "auto" => (auto_exposure(pic), true),
                t => (
                    t.parse::<f64>()
                        .ok()
                        .filter(|e| e.is_finite() && *e > 0.0)
                        .ok_or_else(|| {
                            anyhow!("--exposure {t}: expected a positive number or auto")
                        })?,
                    false,
                ),
            };
            let bytes = srgb_rgba(pic, e, tone);
            let mut w = std::io::BufWriter::new(out.writer(id));
            image::RgbaImage::from_raw(pic.width as u32, pic.height as u32, bytes)
                .ok_or_else(|| anyhow!("image buffer size"))?
                .write_to(&mut w, image::ImageFormat::Png)
                .and_then(|_| std::io::Write::flush(&mut w).map_err(image::ImageError::IoError))
                .map_err(|e| anyhow!("{}: cannot write PNG: {e}", path.display()))?;
            Some(e)
        }
        _ => bail!(
            "--out {}: expected a .exr or .png file name",
            path.display()
        ),
    };
    Ok(used)
}

/// The AOV files of a render (`height.exr` only for rungs with a topology), reserved in `dir`.
pub fn reserve_aovs(outs: &mut Outputs, dir: &Path, with_height: bool) -> Result<Vec<OutputId>> {
    outs.dir(dir, "--aovs")?;
    let mut names = vec!["normal.exr", "tangent.exr", "position.exr"];
    if with_height {
        names.push("height.exr");
    }
    names
        .into_iter()
        .map(|f| outs.file(&dir.join(f), "--aovs"))
        .collect()
}

/// Write the AOVs of `pic` into their reserved files (committed with the picture).
pub fn write_aovs(outs: &mut Outputs, ids: &[OutputId], pic: &Picture) -> Result<()> {
    let layers: [(&[[f32; 3]], usize); 3] =
        [(&pic.normal, 3), (&pic.tangent, 3), (&pic.position, 3)];
    for (k, &id) in ids.iter().enumerate() {
        let data: Vec<f32> = match layers.get(k) {
            Some((v, _)) => v.iter().flatten().copied().collect(),
            None => pic.fibre_height.clone(),
        };
        let channels = layers.get(k).map_or(1, |l| l.1);
        let (f, name) = outs.file_and_name(id);
        super::images::write_exr_into(f, name, pic.width, pic.height, channels, &data)?;
    }
    Ok(())
}

/// What a labelled grid drew: its size and its labels (for tests and messages).
#[derive(Clone, Debug, PartialEq)]
pub struct GridDrawn {
    pub width: usize,
    pub height: usize,
    pub rows: Vec<String>,
    pub columns: Vec<String>,
    pub exposure: f64,
}

fn grid_err<E: std::fmt::Debug>(e: E) -> anyhow::Error {
    anyhow!("grid labels: {e:?}")
}

/// Left margin (row labels) and top margin (column labels) of a labelled grid, pixels.
const GRID_LEFT: usize = 200;
const GRID_TOP: usize = 44;

/// A grid of `tile` x `tile` renders (`pic`, rows x columns of tiles) as an sRGB PNG on white
/// with a label left of each row and above each column, at `auto` exposure (with the shoulder)
/// over the whole grid. EXR names get the bare grid (linear, no labels).
pub fn write_labelled_grid(
    outs: &mut Outputs,
    id: OutputId,
    pic: &Picture,
    tile: usize,
    rows: &[String],
    columns: &[String],
) -> Result<GridDrawn> {
    use plotters::prelude::*;
    let path = outs.name(id).to_path_buf();
    let is_png = path
        .extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| e.eq_ignore_ascii_case("png"));
    let e = auto_exposure(pic);
    if !is_png {
        write_picture(outs, id, pic, "auto")?;
        return Ok(GridDrawn {
            width: pic.width,
            height: pic.height,
            rows: vec![],
            columns: vec![],
            exposure: e,
        });
    }
    let rgba = srgb_rgba(pic, e, true);
    let (w, h) = (pic.width + GRID_LEFT, pic.height + GRID_TOP);
    let mut buf = vec![255u8; w * h * 3];
    for y in 0..pic.height {
        for x in 0..pic.width {
            let s = &rgba[(y * pic.width + x) * 4..][..4];
            let a = s[3] as f64 / 255.0;
            let d = ((y + GRID_TOP) * w + x + GRID_LEFT) * 3;
            for c in 0..3 {
                buf[d + c] = (s[c] as f64 * a + 255.0 * (1.0 - a)).round() as u8;
            }
        }
    }
    super::plots::font();
    {
        let root = BitMapBackend::with_buffer(&mut buf, (w as u32, h as u32)).into_drawing_area();
        let style = ("sans-serif", 15).into_font().color(&BLACK);
        for (r, label) in rows.iter().enumerate() {
            let y = (GRID_TOP + r * tile + tile / 2) as i32;
            root.draw(&Text::new(label.clone(), (8, y - 8), style.clone()))
                .map_err(grid_err)?;
        }
        for (c, label) in columns.iter().enumerate() {
            let x = (GRID_LEFT + c * tile + 8) as i32;
            root.draw(&Text::new(label.clone(), (x, 14), style.clone()))
                .map_err(grid_err)?;
        }
        root.present().map_err(grid_err)?;
    }
    let img = image::RgbImage::from_raw(w as u32, h as u32, buf)
        .ok_or_else(|| anyhow!("grid buffer size"))?;
    super::atomic::Sink::Staged(outs, id).png(&img)?;
    Ok(GridDrawn {
        width: w,
        height: h,
        rows: rows.to_vec(),
        columns: columns.to_vec(),
        exposure: e,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_shoulder_is_linear_below_the_knee_smooth_and_below_one() {
        assert_eq!(shoulder(0.5), 0.5);
        assert!((shoulder(KNEE) - KNEE).abs() < 1e-15);
        // slope 1 at the knee
        let d = (shoulder(KNEE + 1e-7) - shoulder(KNEE)) / 1e-7;
        assert!((d - 1.0).abs() < 1e-5, "{d}");
        // rising, below 1 over any radiance a render makes (1 in f64 only past x ~ 8)
        assert!(shoulder(2.0) > shoulder(1.5) && shoulder(5.0) < 1.0 && shoulder(1e6) <= 1.0);
    }
}
