//! The CUReT BRDF samples (Dana, van Ginneken, Nayar and Koenderink, "Reflectance and texture of
//! real-world surfaces", ACM TOG 18(1), 1999) as its distribution lays them out: a folder with
//! `table.txt` (the 205 measurement geometries, `index theta_v phi_v theta_i phi_i` in radians,
//! the sample's frame with z the normal) and `abrdf_subset.dat` (one row per sample: its number,
//! then one BRDF value per geometry in the table's order, R, G and B averaged: grey). A value of
//! 0 means "not measured" and is left out, as are the few slightly negative values of dark
//! geometries (noise around 0), counted as dropped.

use super::samples::{DataKind, Dropped, Origin, Sample, Samples};
use crate::model::frame::direction_from_angles;
use anyhow::{bail, Context, Result};
use std::path::Path;

/// The folder's geometry table.
pub const TABLE: &str = "table.txt";
/// The folder's values, one row per sample.
pub const VALUES: &str = "abrdf_subset.dat";

/// CUReT's names of its samples (the database's sample list), for the ones studies meet.
pub fn sample_name(number: u32) -> Option<&'static str> {
    Some(match number {
        2 => "polyester",
        3 => "terrycloth",
        4 => "rough plastic",
        15 => "aluminium foil",
        24 => "rabbit fur",
        42 => "corduroy",
        _ => return None,
    })
}

/// Whether `dir` is a CUReT folder (it holds both files).
pub fn is_curet_dir(dir: &Path) -> bool {
    dir.join(TABLE).is_file() && dir.join(VALUES).is_file()
}

/// Every sample of the CUReT folder `dir`: (sample number, its measured directions).
pub fn load_dir(dir: &Path) -> Result<Vec<(u32, Samples)>> {
    let table = read_table(&dir.join(TABLE))?;
    let path = dir.join(VALUES);
    let text = super::input::read_text(&path)?;
    let mut out = Vec::new();
    for (k, line) in text.lines().enumerate() {
        let fields: Vec<&str> = line.split_whitespace().collect();
        if fields.is_empty() {
            continue;
        }
        let at = || format!("{}, line {}", path.display(), k + 1);
        let number: u32 = fields[0]
            .parse()
            .with_context(|| format!("{}: the sample number '{}' is not a whole number", at(), fields[0]))?;
        if fields.len() - 1 != table.len() {
            bail!(
                "{}: sample {number} has {} values; {} has {} geometries",
                at(),
                fields.len() - 1,
                TABLE,
                table.len()
            );
        }
        let mut samples = Vec::new();
        let mut dropped = Dropped::default();
        for (&(l, v), f) in table.iter().zip(&fields[1..]) {
            let value: f64 = f
                .parse()
                .ok()
                .filter(|x: &f64| x.is_finite())
                .with_context(|| format!("{}: '{f}' is not a BRDF value (a finite number)", at()))?;
            // 0: not measured; below 0: a dark measurement's noise (CUReT's are down to -0.01),
            // which neither metric can take as a value
            if value <= 0.0 {
                dropped.invalid += 1;
            } else if l.z <= 0.0 || v.z <= 0.0 {
                dropped.below_horizon += 1;
            } else {
                samples.push(Sample {
                    l,
                    v,
                    fibre_azimuth: None,
                    map_value: None,
                    texel_height: None,
                    value: [value; 3],
                    sigma: None,
                    weight: 1.0,
                    origin: Origin::Line(k as u64 + 1),
                });
            }
        }
        out.push((
            number,
            Samples {
                samples,
                channels: 1,
                kind: DataKind::Gonio,
                source: path.clone(),
                dropped,
                skipped_examples: Vec::new(),
                image_size: None,
                scale_rel_se: None,
            },
        ));
    }
    if out.is_empty() {
        bail!("{}: no samples", path.display());
    }
    Ok(out)
}

/// The geometries of `table.txt`: (light, view) per row, in the file's order.
fn read_table(path: &Path) -> Result<Vec<(crate::model::frame::Vec3, crate::model::frame::Vec3)>> {
    let text = super::input::read_text(path)?;
    let mut rows = Vec::new();
    for (k, line) in text.lines().enumerate() {
        if line.trim().is_empty() {
            continue;
        }
        let x: Vec<f64> = line
            .split_whitespace()
            .map(str::parse)
            .collect::<Result<_, _>>()
            .ok()
            .filter(|x: &Vec<f64>| x.len() == 5 && x.iter().all(|a| a.is_finite()))
            .with_context(|| {
                format!(
                    "{}, line {}: expected 'index theta_v phi_v theta_i phi_i' (five numbers, radians), got '{}'",
                    path.display(),
                    k + 1,
                    line.trim()
                )
            })?;
        rows.push((direction_from_angles(x[3], x[4]), direction_from_angles(x[1], x[2])));
    }
    Ok(rows)
}
