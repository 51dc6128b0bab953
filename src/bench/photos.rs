//! `fibrefit bench photos`: the photo route's speed and memory. A board and a set of synthetic
//! photos of a lambert swatch on it, as JPEGs and as RAW (Bayer DNGs), side by side (the phone-like camera of `synth --photos` scaled to
//! the size asked, 300 mm away, 20-60 deg all around, a flash), then `fibrefit calibrate` as a
//! child process, its wall time, CPU time and peak resident memory read from `/proc`
//! ([`super::camera::measure`]). Goal (issue 36): 12 photos of 12 Mpx in at most 30 s on 2
//! cores, at most 1.5 GB.

use super::camera::{measure, Cost};
use crate::api::board::{board, BoardRequest};
use crate::board::camera::Intrinsics;
use crate::model::params::{ModelParams, RawParams};
use crate::model::ModelId;
use crate::synth::photo::{set_pose, PhotoFormat, PhotoShot, SwatchOnBoard, SET_CAMERA, SET_FLASH_MM};
use anyhow::{Context, Result};
use nalgebra::Vector3;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::process::Command;

/// The goal: seconds of wall time and MB of peak memory (12 photos of 12 Mpx).
pub const GOAL_SECONDS: f64 = 30.0;
pub const GOAL_MB: f64 = 1536.0;

/// What the study measured.
pub struct PhotoRun {
    /// `jpeg` or `dng`.
    pub format: &'static str,
    pub photos: usize,
    pub size_px: [u32; 2],
    /// The photos' files, MB in all.
    pub files_mb: f64,
    pub cost: Cost,
    /// The calibration's worst camera position error against the truth (mm).
    pub worst_position_mm: f64,
}

/// The set's camera scaled to `width` pixels across (4:3), its field of view kept.
fn camera(width: u32) -> Intrinsics {
    let s = width as f64 / SET_CAMERA.size_px[0] as f64;
    Intrinsics {
        size_px: [width, width * 3 / 4],
        focal_px: SET_CAMERA.focal_px * s,
        principal_px: SET_CAMERA.principal_px.map(|c| c * s),
        k: SET_CAMERA.k,
    }
}

/// Write the board and `n` photos of `width` pixels across into `dir`, as JPEGs (quality 92)
/// or DNGs.
fn shoot(dir: &Path, n: usize, width: u32, format: PhotoFormat) -> Result<(PathBuf, Vec<PathBuf>)> {
    board(&BoardRequest::default(), dir)?;
    let raw: RawParams = toml::from_str("kd = [0.5, 0.4, 0.3]")?;
    let (params, _) = ModelParams::from_raw(&raw, ModelId::Lambert)?;
    let set = SwatchOnBoard::read(&dir.join("board.toml"), ModelId::Lambert, params)?;
    let scene = set.scene();
    let k = camera(width);
    let mut files = Vec::new();
    for i in 0..n {
        let pose = set_pose(i, n);
        let shot = PhotoShot {
            intrinsics: k,
            pose,
            light_mm: pose.position + pose.to_board_direction(&Vector3::from(SET_FLASH_MM)),
            intensity: 1.0,
            room_light: None,
            exposure: 0.5 * std::f64::consts::PI * 0.09,
            noise_gain: 3e-5,
            noise_floor: 0.002,
            seed: i as u64,
            supersample: 1,
            blur_px: 0.0,
        };
        let path = match format {
            PhotoFormat::Jpeg => {
                let photo = scene.render(&shot)?;
                let path = dir.join(format!("photo_{i:02}.jpg"));
                let mut f = std::fs::File::create(&path)?;
                image::codecs::jpeg::JpegEncoder::new_with_quality(&mut f, 92)
                    .encode_image(&photo)
                    .with_context(|| format!("{}", path.display()))?;
                path
            }
            PhotoFormat::Dng => {
                let linear = scene.render_linear(&shot)?;
                let path = dir.join(format!("photo_{i:02}.dng"));
                let exposure = crate::export::dng::DngExposure {
                    time_s: 0.01,
                    iso: 100,
                    f_number: 2.0,
                };
                std::fs::write(
                    &path,
                    crate::export::dng::dng_bytes(k.size_px[0], k.size_px[1], &linear, exposure)?,
                )?;
                path
            }
        };
        files.push(path);
    }
    Ok((dir.join("board.toml"), files))
}

/// Shoot `n` photos `width` pixels across in `scratch`, as JPEGs then as DNGs, and calibrate
/// each set with `exe`.
pub fn run(
    exe: &Path,
    scratch: &Path,
    n: usize,
    width: u32,
    progress: &crate::progress::Progress,
) -> Result<Vec<PhotoRun>> {
    let mut out = Vec::new();
    for (format, name) in [(PhotoFormat::Jpeg, "jpeg"), (PhotoFormat::Dng, "dng")] {
        let dir = scratch.join(name);
        std::fs::create_dir_all(&dir)?;
        out.push(run_one(exe, &dir, n, width, (format, name), progress)?);
        // the set's files go before the next is written (12 DNGs of 12 Mpx are 290 MB)
        std::fs::remove_dir_all(&dir)?;
    }
    Ok(out)
}

/// One set of photos, calibrated.
fn run_one(
    exe: &Path,
    scratch: &Path,
    n: usize,
    width: u32,
    (format, name): (PhotoFormat, &'static str),
    progress: &crate::progress::Progress,
) -> Result<PhotoRun> {
    progress.line(&format!("rendering {n} {name} photos of {width} px across"));
    let (board_toml, files) = shoot(scratch, n, width, format)?;
    let files_mb = files
        .iter()
        .map(|f| std::fs::metadata(f).map(|m| m.len()).unwrap_or(0) as f64)
        .sum::<f64>()
        / 1e6;
    progress.line(&format!("calibrating the {name} photos"));
    let mut cmd = Command::new(exe);
    cmd.arg("calibrate")
        .arg("--board")
        .arg(&board_toml)
        .arg("--out")
        .arg(scratch.join("cal"))
        .arg("-q")
        .args(&files);
    let cost = measure(cmd, &scratch.join("calibrate.log"))?;
    // the cameras against the truth, from the capture written
    let text = std::fs::read_to_string(scratch.join("cal/capture.toml"))?;
    let cap: toml::Value = toml::from_str(&text)?;
    let mut worst: f64 = 0.0;
    for (i, img) in cap["images"].as_array().into_iter().flatten().enumerate() {
        let at: Vec<f64> = img["camera"]["position_mm"]
            .as_array()
            .into_iter()
            .flatten()
            .filter_map(|v| v.as_float())
            .collect();
        let truth = set_pose(i, n).position;
        let err = (0..3).map(|c| (at[c] - truth[c]).powi(2)).sum::<f64>().sqrt();
        worst = worst.max(err);
    }
    Ok(PhotoRun {
        format: name,
        photos: n,
        size_px: camera(width).size_px,
        files_mb,
        cost,
        worst_position_mm: worst,
    })
}

/// Write `out/photo_speed.md` and `.csv`.
pub fn write(out: &Path, runs: &[PhotoRun], command: &str, total_s: f64) -> Result<()> {
    std::fs::create_dir_all(out)?;
    let r = &runs[0];
    let mpx = r.size_px[0] as f64 * r.size_px[1] as f64 / 1e6;
    let mut md = String::new();
    writeln!(md, "# The photo route's speed and memory (`fibrefit calibrate`)\n")?;
    writeln!(
        md,
        "Generated by `{command}` in {total_s:.0} s (CSV: `photo_speed.csv`). {} synthetic photos of {} x {} pixels ({mpx:.1} Mpx) of the default board with a lambert swatch, taken by `synth --photos`'s camera scaled to that size (the same field of view and distortion) from 300 mm at 20-60 deg all around with a flash, written as JPEGs (quality 92) and as RAW (Bayer DNGs, 16-bit, uncompressed); `fibrefit calibrate --board board.toml --out cal PHOTO...` (128 x 128 texels) runs as a child process on each set, its wall and CPU time and peak resident memory (VmHWM) read from /proc. Each photo is decoded three times (markers; the patch, the board's noise, the blur and the overlay; rectification) so that only one photo's pixels are held. Goal (issue 36): 12 photos of 12 Mpx in at most {GOAL_SECONDS:.0} s on 2 cores and {:.1} GB.\n",
        r.photos,
        r.size_px[0],
        r.size_px[1],
        GOAL_MB / 1024.0
    )?;
    writeln!(
        md,
        "Build: {}.\n",
        if cfg!(debug_assertions) {
            "with debug assertions (cargo's dev or test profile); regenerate from a release build for the report"
        } else {
            "release"
        }
    )?;
    writeln!(md, "| photos | format | files [MB] | size | wall [s] | CPU [s] | peak [MB] | worst camera position error [mm] | goal |")?;
    writeln!(md, "|---|---|---|---|---|---|---|---|---|")?;
    let mut csv = String::from(
        "photos,format,files_mb,width_px,height_px,wall_s,cpu_s,peak_mb,worst_position_mm,goal_met\n",
    );
    for r in runs {
        let full = r.photos >= 12 && mpx >= 11.9;
        let met = r.cost.wall_seconds <= GOAL_SECONDS && r.cost.peak_mb <= GOAL_MB;
        let goal = match (full, met) {
            (false, _) => "- (not the goal's size)",
            (true, true) => "met",
            (true, false) => "**missed**",
        };
        writeln!(
            md,
            "| {} | {} | {:.1} | {} x {} | {:.1} | {:.1} | {:.0} | {:.3} | {goal} |",
            r.photos,
            r.format,
            r.files_mb,
            r.size_px[0],
            r.size_px[1],
            r.cost.wall_seconds,
            r.cost.cpu_seconds,
            r.cost.peak_mb,
            r.worst_position_mm
        )?;
        writeln!(
            csv,
            "{},{},{:.2},{},{},{:.3},{:.3},{:.1},{:.4},{}",
            r.photos,
            r.format,
            r.files_mb,
            r.size_px[0],
            r.size_px[1],
            r.cost.wall_seconds,
            r.cost.cpu_seconds,
            r.cost.peak_mb,
            r.worst_position_mm,
            full && met
        )?;
    }
    if runs.len() == 2 {
        writeln!(
            md,
            "\nRAW against JPEG, same photos: wall {:.2}x, peak memory {:.2}x.",
            runs[1].cost.wall_seconds / runs[0].cost.wall_seconds,
            runs[1].cost.peak_mb / runs[0].cost.peak_mb
        )?;
    }
    std::fs::write(out.join("photo_speed.md"), md)?;
    std::fs::write(out.join("photo_speed.csv"), csv)?;
    Ok(())
}
