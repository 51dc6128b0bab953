//! `fit --maps DIR`: the recovered per-texel maps as float EXRs registered to the capture (one
//! texel per pixel, the capture's size; texels without usable pixels are NaN), with a standard
//! error map for each and the residual map; a description for the result JSON.
//!
//! Files: `height.exr` (H, fibre radii), `fibre_azimuth.exr` (psi, degrees in [-90, 90)),
//! `kd.exr`, `ks.exr` (albedos, one channel per colour channel), `<name>_std_error.exr`, and
//! `residual.exr` (RMS relative residual per texel). All are written into a staging directory
//! first and moved into DIR only when every one is complete.

use super::atomic::Staging;
use super::images::write_exr;
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
        _ => ("weight of the specular lobe (ks)", channels, |v, c| v.ks[c]),
    }
}

/// File names `write` produces for `names` (for refusing outputs that are inputs).
pub fn file_names(names: &[&str]) -> Vec<String> {
    let mut v: Vec<String> = names
        .iter()
        .flat_map(|n| [format!("{n}.exr"), format!("{n}_std_error.exr")])
        .collect();
    v.push("residual.exr".into());
    v
}

/// Write the maps `names` into `dir` (created if missing); returns the JSON description.
pub fn write(dir: &Path, names: &[&str], maps: &TexelMaps) -> Result<serde_json::Value> {
    let parent = match dir.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
        _ => std::path::PathBuf::from("."),
    };
    std::fs::create_dir_all(&parent)
        .with_context(|| format!("{}: cannot create directory", parent.display()))?;
    let stage = Staging::new(&parent, "maps")?;
    let (w, h) = (maps.width, maps.height);
    let mut files = serde_json::Map::new();
    let grid = |channels: usize, get: &dyn Fn(usize, usize) -> f64| -> Vec<f32> {
        let mut data = vec![f32::NAN; w * h * channels];
        for (t, &(x, y)) in maps.texels.iter().enumerate() {
            let px = (y as usize * w + x as usize) * channels;
            for c in 0..channels {
                data[px + c] = get(t, c) as f32;
            }
        }
        data
    };
    for &name in names {
        let (unit, channels, get) = layout(name, maps.channels);
        let values = grid(channels, &|t, c| get(&maps.values[t], c));
        let errors = grid(channels, &|t, c| get(&maps.std_errors[t], c));
        write_exr(
            &stage.path().join(format!("{name}.exr")),
            w,
            h,
            channels,
            &values,
        )?;
        write_exr(
            &stage.path().join(format!("{name}_std_error.exr")),
            w,
            h,
            channels,
            &errors,
        )?;
        files.insert(
            name.into(),
            serde_json::json!({
                "file": format!("{name}.exr"),
                "std_error_file": format!("{name}_std_error.exr"),
                "unit": unit,
                "channels": if channels == 1 { "Y" } else { "R, G, B" },
            }),
        );
    }
    let residual = grid(1, &|t, _| maps.residual[t]);
    write_exr(&stage.path().join("residual.exr"), w, h, 1, &residual)?;
    files.insert(
        "residual".into(),
        serde_json::json!({
            "file": "residual.exr",
            "unit": "RMS relative residual (model - data) / data over the texel's pixels and channels",
            "channels": "Y",
        }),
    );
    std::fs::create_dir_all(dir)
        .with_context(|| format!("{}: cannot create the maps directory", dir.display()))?;
    for entry in std::fs::read_dir(stage.path())? {
        let entry = entry?;
        std::fs::rename(entry.path(), dir.join(entry.file_name()))
            .with_context(|| format!("{}: cannot put the maps in place", dir.display()))?;
    }
    drop(stage);
    Ok(serde_json::json!({
        "directory": dir.display().to_string(),
        "width": w,
        "height": h,
        "texels": maps.texels.len(),
        "registration": "one texel per capture pixel (x right, y down from the top-left); NaN where no usable pixel",
        "maps": files,
    }))
}
