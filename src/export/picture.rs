//! Rendered pictures as files: `.exr` linear RGBA, `.png` 8-bit sRGB of radiance x exposure
//! with alpha, and the AOVs (normal, tangent, position, height) as EXRs, all through the run's
//! reserved outputs.

use super::atomic::{OutputId, Outputs};
use crate::render::Picture;
use anyhow::{anyhow, bail, Result};
use std::path::Path;

/// Write `pic` to `path` (.exr linear RGBA, .png sRGB RGBA with `exposure`); returns the
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
            let e = match exposure {
                "auto" => {
                    let mut lum: Vec<f32> = pic
                        .radiance
                        .iter()
                        .zip(&pic.alpha)
                        .filter(|(_, a)| **a > 0.0)
                        .map(|(c, a)| c[0].max(c[1]).max(c[2]) / a)
                        .collect();
                    lum.sort_by(f32::total_cmp);
                    let p99 = lum.get(lum.len() * 99 / 100).copied().unwrap_or(0.0);
                    if p99 > 0.0 {
                        0.9 / p99 as f64
                    } else {
                        1.0
                    }
                }
                t => t
                    .parse::<f64>()
                    .ok()
                    .filter(|e| e.is_finite() && *e > 0.0)
                    .ok_or_else(|| anyhow!("--exposure {t}: expected a positive number or auto"))?,
            };
            let bytes: Vec<u8> = pic
                .radiance
                .iter()
                .zip(&pic.alpha)
                .flat_map(|(c, a)| {
                    // premultiplied by coverage in the sum: undo it for the colour
                    let un = |v: f32| if *a > 0.0 { v / a } else { 0.0 };
                    let code = |v: f32| {
                        (crate::load::image_io::linear_to_srgb(
                            (un(v) as f64 * e).clamp(0.0, 1.0) as f32
                        ) * 255.0)
                            .round() as u8
                    };
                    [
                        code(c[0]),
                        code(c[1]),
                        code(c[2]),
                        (a * 255.0).round() as u8,
                    ]
                })
                .collect();
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
