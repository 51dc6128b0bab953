//! `fit --maps DIR`: the recovered per-texel maps as float EXRs registered to the capture (one
//! texel per pixel, the capture's size; texels without usable pixels are NaN), with a standard
//! error map for each and the residual map; a description for the result JSON.
//!
//! Files: `height.exr` (H, fibre radii), `fibre_azimuth.exr` (psi, degrees in [-90, 90)),
//! `kd.exr`, `ks.exr` (albedos, one channel per colour channel), the lobe of a renderer's
//! material by the rung's own names (`gltf`: `roughness.exr`, `anisotropy_strength.exr`;
//! `principled`: `roughness.exr`, `anisotropic.exr`; `openpbr`: `specular_roughness.exr`,
//! `specular_roughness_anisotropy.exr`), `<name>_std_error.exr`, and
//! `residual.exr` (RMS relative residual per texel), and a picture of each (`<name>.png`,
//! `<name>_std_error.png`, `residual.png`: the map at the capture's resolution, one panel per
//! channel, with a colour bar; grey where no texel is). All are reserved in the run's outputs
//! before the work and put in place with its other outputs when every one is complete.

use super::atomic::{OutputId, Outputs};
use super::images::write_exr_into;
use crate::fit::maps::{TexelMaps, TexelValues};
use anyhow::{Context, Result};
use std::path::Path;

/// (file stem, unit, channels, value getter) of each map.
type Getter = fn(&TexelValues, usize) -> f64;

fn layout(name: &str, channels: usize) -> (&'static str, usize, Getter) {
    match name {
        "height" => ("fibre radii (texel height H)", 1, |v, _| v.height),
        "fibre_azimuth" => (
            "degrees (fibre azimuth psi from the swatch x axis)",
            1,
            |v, _| v.psi,
        ),
        "kd" => (
            "albedo (diffuse, 1/pi of the Lambert lobe)",
            channels,
            |v, c| v.kd[c],
        ),
        "ks" => ("weight of the specular lobe (ks)", channels, |v, c| v.ks[c]),
        "roughness" => (
            "unitless (the lobe's roughness: glTF's, Blender's)",
            1,
            |v, _| v.roughness,
        ),
        "specular_roughness" => (
            "unitless (OpenPBR's specular_roughness)",
            1,
            |v, _| v.roughness,
        ),
        "anisotropy_strength" => (
            "unitless in [0, 1] (KHR_materials_anisotropy's strength)",
            1,
            |v, _| v.anisotropy,
        ),
        "anisotropic" => (
            "unitless in [0, 1] (Blender's Anisotropic)",
            1,
            |v, _| v.anisotropy,
        ),
        "specular_roughness_anisotropy" => (
            "unitless in [0, 1] (OpenPBR's specular_roughness_anisotropy)",
            1,
            |v, _| v.anisotropy,
        ),
        other => unreachable!("no map `{other}`"),
    }
}

/// The map files of a run, reserved in its outputs before the work (`file_names` in `dir`).
pub struct MapFiles {
    dir: std::path::PathBuf,
    ids: Vec<(String, OutputId)>,
}

impl MapFiles {
    /// Reserve the files of the maps `names` in `dir` (created if missing).
    pub fn reserve(outs: &mut Outputs, dir: &Path, names: &[&str]) -> Result<Self> {
        outs.dir(dir, "--maps")?;
        let mut ids = vec![];
        for f in file_names(names) {
            let id = outs.file(&dir.join(&f), "--maps")?;
            ids.push((f, id));
        }
        Ok(Self {
            dir: dir.to_path_buf(),
            ids,
        })
    }

    /// The SHA-256 (hex) of each EXR staged by [`write`], by file name: what a result records
    /// in `maps.sha256` so that readers can tell its maps from others.
    pub fn exr_hashes(
        &self,
        outs: &mut Outputs,
    ) -> Result<std::collections::BTreeMap<String, String>> {
        use sha2::{Digest, Sha256};
        use std::io::{Seek, SeekFrom};
        let mut out = std::collections::BTreeMap::new();
        for (file, id) in self.ids.iter().filter(|(f, _)| f.ends_with(".exr")) {
            let (f, name) = outs.file_and_name(*id);
            let mut hash = Sha256::new();
            f.seek(SeekFrom::Start(0))
                .and_then(|_| std::io::copy(f, &mut hash))
                .and_then(|_| f.seek(SeekFrom::End(0)))
                .with_context(|| format!("{}: cannot read back the map", name.display()))?;
            let hex: String = hash.finalize().iter().map(|b| format!("{b:02x}")).collect();
            out.insert(file.clone(), hex);
        }
        Ok(out)
    }

    fn id(&self, file: &str) -> Result<OutputId> {
        self.ids
            .iter()
            .find(|(f, _)| f == file)
            .map(|(_, id)| *id)
            .with_context(|| format!("{}: {file} was not reserved", self.dir.display()))
    }
}

/// File names `write` produces for `names`.
pub fn file_names(names: &[&str]) -> Vec<String> {
    let mut v: Vec<String> = names
        .iter()
        .flat_map(|n| {
            [
                format!("{n}.exr"),
                format!("{n}_std_error.exr"),
                format!("{n}.png"),
                format!("{n}_std_error.png"),
            ]
        })
        .collect();
    v.push("residual.exr".into());
    v.push("residual.png".into());
    v
}

/// The short name and unit of a map on its colour bar.
fn bar_label(name: &str) -> (&'static str, &'static str) {
    match name {
        "height" => ("height H", "fibre radii"),
        "fibre_azimuth" => ("fibre azimuth psi", "deg"),
        "kd" => ("kd", "albedo"),
        "roughness" => ("roughness", "unitless"),
        "specular_roughness" => ("specular roughness", "unitless"),
        "anisotropy_strength" => ("anisotropy strength", "unitless"),
        "anisotropic" => ("anisotropic", "unitless"),
        "specular_roughness_anisotropy" => ("specular roughness anisotropy", "unitless"),
        _ => ("ks", "weight"),
    }
}

/// Draw a map (`channels` interleaved values per texel, NaN: none) as a picture with a colour
/// bar: `azimuth` on a hue circle over [-90, 90] deg, others on a sequential scale over the 1st
/// to 99th percentile (from 0 for errors and residuals).
fn picture(
    sink: super::atomic::Sink,
    title: &str,
    maps: &TexelMaps,
    channels: usize,
    data: &[f32],
    kind: (&str, bool, String),
) -> Result<super::plots::Drawn> {
    use super::plots::{image_panels, percentiles, ColourMap, MapScale};
    let (name, from_zero, label) = kind;
    let panels: Vec<(String, Vec<f32>)> = (0..channels)
        .map(|c| {
            let v = data.iter().skip(c).step_by(channels).copied().collect();
            let title = match channels {
                1 => name.to_string(),
                _ => format!("{name} {}", ["R", "G", "B"][c]),
            };
            (title, v)
        })
        .collect();
    let finite = data.iter().filter(|x| x.is_finite()).map(|&x| x as f64);
    let scale = if name == "fibre azimuth psi" {
        MapScale {
            lo: -90.0,
            hi: 90.0,
            log: false,
            map: ColourMap::Cyclic,
            label,
        }
    } else {
        let (lo, hi) = percentiles(finite, 1.0, 99.0).unwrap_or((0.0, 1.0));
        let lo = if from_zero { 0.0 } else { lo };
        MapScale {
            lo,
            hi: if hi > lo {
                hi
            } else {
                lo + 1e-9_f64.max(lo.abs() * 1e-6)
            },
            log: false,
            map: ColourMap::Sequential,
            label,
        }
    };
    image_panels(sink, title, maps.width, maps.height, &panels, &scale)
}

/// The grid of one map: texel values at their pixels, NaN where no texel is.
fn grid(maps: &TexelMaps, channels: usize, get: &dyn Fn(usize, usize) -> f64) -> Vec<f32> {
    let w = maps.width;
    let mut data = vec![f32::NAN; w * maps.height * channels];
    for (t, &(x, y)) in maps.texels.iter().enumerate() {
        let px = (y as usize * w + x as usize) * channels;
        for c in 0..channels {
            data[px + c] = get(t, c) as f32;
        }
    }
    data
}

/// The result JSON's description of the maps `names` written into `dir`.
pub fn describe(dir: &Path, names: &[&str], maps: &TexelMaps) -> serde_json::Value {
    let mut json = serde_json::Map::new();
    for &name in names {
        let (unit, channels, _) = layout(name, maps.channels);
        json.insert(
            name.into(),
            serde_json::json!({
                "file": format!("{name}.exr"),
                "std_error_file": format!("{name}_std_error.exr"),
                "unit": unit,
                "channels": if channels == 1 { "Y" } else { "R, G, B" },
                "picture": format!("{name}.png"),
                "std_error_picture": format!("{name}_std_error.png"),
            }),
        );
    }
    json.insert(
        "residual".into(),
        serde_json::json!({
            "file": "residual.exr",
            "picture": "residual.png",
            "unit": "RMS relative residual (model - data) / data over the texel's pixels and channels",
            "channels": "Y",
        }),
    );
    serde_json::json!({
        "directory": dir.display().to_string(),
        "width": maps.width,
        "height": maps.height,
        "texels": maps.texels.len(),
        "registration": "one texel per capture pixel (x right, y down from the top-left); NaN where no usable pixel",
        "maps": json,
    })
}

/// Write the maps `names` into their reserved files (committed with the run's other outputs).
pub fn write(outs: &mut Outputs, files: &MapFiles, names: &[&str], maps: &TexelMaps) -> Result<()> {
    let (w, h) = (maps.width, maps.height);
    let mut put = |file: &str, channels: usize, data: &[f32]| -> Result<()> {
        let (f, name) = outs.file_and_name(files.id(file)?);
        write_exr_into(f, name, w, h, channels, data)
    };
    for &name in names {
        let (_, channels, get) = layout(name, maps.channels);
        let values = grid(maps, channels, &|t, c| get(&maps.values[t], c));
        let errors = grid(maps, channels, &|t, c| get(&maps.std_errors[t], c));
        put(&format!("{name}.exr"), channels, &values)?;
        put(&format!("{name}_std_error.exr"), channels, &errors)?;
    }
    let residual = grid(maps, 1, &|t, _| maps.residual[t]);
    put("residual.exr", 1, &residual)?;
    drop(put);
    // the pictures
    for &name in names {
        let (_, channels, get) = layout(name, maps.channels);
        let (short, unit) = bar_label(name);
        let values = grid(maps, channels, &|t, c| get(&maps.values[t], c));
        let errors = grid(maps, channels, &|t, c| get(&maps.std_errors[t], c));
        let sink = super::atomic::Sink::Staged(outs, files.id(&format!("{name}.png"))?);
        let title = format!("Recovered {short} per texel ({unit})");
        picture(
            sink,
            &title,
            maps,
            channels,
            &values,
            (short, false, format!("{short} [{unit}]")),
        )?;
        let sink = super::atomic::Sink::Staged(outs, files.id(&format!("{name}_std_error.png"))?);
        let title = format!("Standard error of {short} per texel ({unit})");
        let label = format!("std error of {short} [{unit}]");
        picture(
            sink,
            &title,
            maps,
            channels,
            &errors,
            ("standard error", true, label),
        )?;
    }
    let pct: Vec<f32> = residual.iter().map(|r| 100.0 * r).collect();
    let sink = super::atomic::Sink::Staged(outs, files.id("residual.png")?);
    let title = "RMS relative residual per texel";
    picture(
        sink,
        title,
        maps,
        1,
        &pct,
        ("residual", true, "RMS residual [%]".into()),
    )?;
    Ok(())
}
