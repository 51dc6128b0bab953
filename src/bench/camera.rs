//! `fibrefit bench camera`: captures at camera resolution. A synthetic RGB capture of
//! 8 images x N x N pixels (default 1024: 8.4 M pixel values of 3 channels) with known topology and
//! tangent maps, fitted by the `fibrefit` binary as a user runs it, each run a child process
//! whose wall time, CPU time and peak resident memory are read from `/proc`:
//! 1. the global fit given the maps (the capture TOML names them);
//! 2. map recovery, maps + globals (`fit --maps`, the maps left out of the TOML);
//! 3. map recovery of the same swatch seen from the same directions as a capture rig takes it
//!    ([`Rig::Near`]): pinhole cameras and point lights [`RIG_DISTANCE_MM`] from the swatch,
//!    image 0's light a flash beside its lens, so every texel sees its own directions
//!    ([`pinhole_rows`], with how far the direction lattice's blend is from the model).
//!
//! Goals (issues 13 and 24, 2 cores): (1) <= 30 s and <= 1 GB; (2) and (3) <= 3 minutes and
//! <= 1.5 GB, (3) as accurate as (2).

use crate::load::capture_store::CaptureStore;
use crate::model::topology::TopologyMap;
use anyhow::{bail, Context, Result};
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

/// (light theta, phi; camera theta, phi) in degrees, as `bench maps`' 8-image case, but for
/// image 0's light: the flash beside its camera's lens ([`flash_direction`]).
const IMAGES: [[f64; 4]; 8] = super::maps::EIGHT_IMAGES;

/// Distance (mm) of the near rig's pinhole cameras and point lights from the swatch centre
/// (the swatch is 20 mm across: the directions turn by up to ~4 degrees over it).
pub const RIG_DISTANCE_MM: f64 = 300.0;
/// How far (mm) image 0's flash sits beside its camera's lens (the camera looks straight down).
pub const FLASH_OFFSET_MM: f64 = 40.0;

/// Where the lights and cameras are.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Rig {
    /// Directional lights and orthographic cameras: every texel sees the same directions.
    Distant,
    /// Point lights and pinhole cameras [`RIG_DISTANCE_MM`] from the swatch centre in the
    /// same directions (from the centre), image 0's light the flash.
    Near,
}

/// Position (mm, swatch frame) at `RIG_DISTANCE_MM` in direction (theta, phi) degrees.
fn rig_position(theta_deg: f64, phi_deg: f64) -> [f64; 3] {
    let d =
        crate::model::frame::direction_from_angles(theta_deg.to_radians(), phi_deg.to_radians())
            * RIG_DISTANCE_MM;
    [d.x, d.y, d.z]
}

/// The flash of image 0: [`FLASH_OFFSET_MM`] along x beside a camera straight above the swatch
/// centre, as its position (mm) and its direction (theta, phi, degrees) from the centre.
pub fn flash_direction() -> ([f64; 3], [f64; 2]) {
    let p = [FLASH_OFFSET_MM, 0.0, RIG_DISTANCE_MM];
    (
        p,
        [FLASH_OFFSET_MM.atan2(RIG_DISTANCE_MM).to_degrees(), 0.0],
    )
}

/// The truth the capture is rendered from (RGB albedos).
const TRUTH: &str = r#"model = "varying-topology"
[params]
kd = [0.45, 0.35, 0.25]
ks = 0.3
exponent = 40
spacing = 2.0
height = 0.9
map_scale = 0.6
fibre_azimuth_deg = 0
"#;

/// The global fit given the maps.
pub const FIT_GLOBAL: &str = r#"model = "varying-topology"
metric = "linear"
seed = 1
[parameters]
kd = { value = 0.5 }
ks = { value = 0.2 }
exponent = { value = 20, min = 1, max = 1000 }
spacing = { value = 2.0, vary = false }
height = { value = 0.8 }
map_scale = { value = 0.5 }
fibre_azimuth_deg = { value = 0, vary = false }
"#;

/// Map recovery: H and psi per texel.
pub const FIT_MAPS: &str = r#"model = "varying-topology"
metric = "linear"
seed = 1
[parameters]
kd = { value = 0.5 }
ks = { value = 0.2 }
exponent = { value = 20, min = 1, max = 1000 }
spacing = { value = 2.0, vary = false }
height = { value = 0.8 }
fibre_azimuth_deg = { value = 0 }
[maps]
height = true
fibre_azimuth = true
rounds = 25
"#;

/// What one child run cost.
#[derive(Clone, Debug, serde::Serialize)]
pub struct Cost {
    pub wall_seconds: f64,
    pub cpu_seconds: f64,
    pub peak_mb: f64,
}

#[derive(Clone, Debug, serde::Serialize)]
pub struct CameraRow {
    pub job: String,
    pub texels: usize,
    pub pixel_values: usize,
    pub wall_seconds: f64,
    pub cpu_seconds: f64,
    pub peak_mb: f64,
    pub bytes_per_pixel_value: f64,
    /// Peak resident memory over the pixel values (the process's fixed overhead included).
    pub peak_bytes_per_pixel_value: f64,
    /// Infinite: no time goal (the memory rows).
    pub goal_seconds: f64,
    pub goal_mb: f64,
    /// The goal in peak bytes per pixel value (issue 24: 150 at 8 x 512 x 512), where there is
    /// one.
    pub goal_bytes_per_pixel_value: Option<f64>,
    pub met: bool,
    /// What came out, against the truth.
    pub accuracy: String,
}

pub struct CameraRun {
    pub size: usize,
    pub rows: Vec<CameraRow>,
    /// Bytes the compact store holds per pixel value.
    pub store_bytes_per_value: f64,
    pub synth_seconds: f64,
    /// The near rig's capture ([`pinhole_rows`]): its rendering time and how far the direction
    /// lattice's blend lies from the model.
    pub pinhole: Option<PinholeRun>,
    /// Map recovery with pinhole cameras against orthographic ones, size by size (issue 41:
    /// at most [`PINHOLE_RATIO_GOAL`] times the time, as accurate).
    pub ratios: Vec<SizeRatio>,
}

/// The pinhole capture's map recovery may take at most this many times the orthographic one's.
pub const PINHOLE_RATIO_GOAL: f64 = 1.5;

/// Map recovery of one size's two captures (orthographic, pinhole), side by side.
#[derive(Clone, Debug, serde::Serialize)]
pub struct SizeRatio {
    pub size: usize,
    pub orthographic: Cost,
    pub pinhole: Cost,
    pub orthographic_accuracy: String,
    pub pinhole_accuracy: String,
    /// Lattice nodes of the pinhole capture (columns, rows; 0 when its texels are evaluated
    /// directly).
    pub lattice: (usize, usize),
}

impl SizeRatio {
    /// Pinhole wall time over orthographic.
    pub fn ratio(&self) -> f64 {
        self.pinhole.wall_seconds / self.orthographic.wall_seconds
    }
}

/// Map recovery (maps + globals) of the benchmark's swatch at `size` x `size` pixels with
/// orthographic cameras and directional lights, then with the near rig, one after the other.
pub fn size_ratio(exe: &Path, scratch: &Path, size: usize) -> Result<SizeRatio> {
    let mut out = Vec::new();
    let mut lattice = (0, 0);
    for rig in [Rig::Distant, Rig::Near] {
        let dir = scratch.join(format!("ratio_{size}_{rig:?}"));
        std::fs::create_dir_all(&dir)?;
        let d = dir.join("d");
        std::fs::write(dir.join("synth.toml"), synth_config(size, rig))?;
        crate::synth::run(&dir.join("synth.toml"), &d, &crate::progress::Progress::quiet())?;
        let blind = super::maps::write_blind(&d)?;
        std::fs::write(dir.join("maps.toml"), FIT_MAPS)?;
        if rig == Rig::Near {
            let store = CaptureStore::load(&blind, Default::default())?;
            let cfg: crate::fit::config::FitConfig = toml::from_str(FIT_MAPS)?;
            lattice = crate::fit::maps::lattice_nodes(&store, &cfg.maps).unwrap_or((0, 0));
        }
        let cmd = fit_command(
            exe,
            &blind,
            (&dir.join("maps.toml"), &dir.join("maps.json")),
            Some(&dir.join("maps")),
        );
        let cost = measure(cmd, &dir.join("maps.log"))?;
        let accuracy = map_accuracy(&d, &dir.join("maps"))?;
        std::fs::remove_dir_all(&dir)?;
        out.push((cost, accuracy));
    }
    let (pinhole, pinhole_accuracy) = out.pop().expect("two runs");
    let (orthographic, orthographic_accuracy) = out.pop().expect("two runs");
    Ok(SizeRatio {
        size,
        orthographic,
        pinhole,
        orthographic_accuracy,
        pinhole_accuracy,
        lattice,
    })
}

/// What [`pinhole_rows`] measured besides its row.
pub struct PinholeRun {
    pub synth_seconds: f64,
    pub blend: crate::fit::maps::BlendError,
}

/// Run `cmd` to its end, reading its peak resident memory (VmHWM) and CPU time (utime + stime
/// of every thread) from `/proc` while it runs and as it exits.
pub fn measure(mut cmd: Command, log: &Path) -> Result<Cost> {
    let err = std::fs::File::create(log)?;
    let t = Instant::now();
    let mut child = cmd
        .stdout(Stdio::null())
        .stderr(err)
        .spawn()
        .context("starting fibrefit")?;
    let pid = child.id();
    let (mut peak_kb, mut cpu) = (0u64, f64::NAN);
    loop {
        if let Ok(s) = std::fs::read_to_string(format!("/proc/{pid}/status")) {
            if let Some(kb) = s
                .lines()
                .find_map(|l| l.strip_prefix("VmHWM:"))
                .and_then(|v| v.trim().trim_end_matches("kB").trim().parse::<u64>().ok())
            {
                peak_kb = peak_kb.max(kb);
            }
        }
        let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).unwrap_or_default();
        // fields after the command's closing parenthesis: state, ppid, ... utime (12th),
        // stime (13th), in clock ticks of 1/100 s (USER_HZ)
        let fields: Vec<&str> = stat
            .rsplit_once(')')
            .map(|(_, rest)| rest.split_whitespace().collect())
            .unwrap_or_default();
        if fields.len() > 12 {
            let ticks = |i: usize| fields[i].parse::<f64>().unwrap_or(f64::NAN);
            cpu = (ticks(11) + ticks(12)) / 100.0;
            if fields[0] == "Z" {
                break;
            }
        }
        if child.try_wait()?.is_some() {
            break;
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    let status = child.wait()?;
    let wall = t.elapsed().as_secs_f64();
    if !status.success() {
        bail!(
            "fibrefit failed ({status}): {}",
            std::fs::read_to_string(log).unwrap_or_default()
        );
    }
    Ok(Cost {
        wall_seconds: wall,
        cpu_seconds: cpu,
        peak_mb: peak_kb as f64 / 1024.0,
    })
}

/// The synth config of the benchmark's capture, `size` x `size` pixels of a 20 mm swatch, seen
/// by `rig`.
pub fn synth_config(size: usize, rig: Rig) -> String {
    synth_config_of(size, 20.0, rig)
}

/// [`synth_config`] of a swatch `size_mm` across (a smaller one at the same distance sees
/// directions that turn less across it).
pub fn synth_config_of(size: usize, size_mm: f64, rig: Rig) -> String {
    let mut s = format!(
        "{TRUTH}[topology_map]\nwidth = {size}\nheight = {size}\nseed = 3\n[capture]\nwidth = {size}\nheight = {size}\nsize_mm = [{size_mm:?}, {size_mm:?}]\nformat = \"exr\"\ntangent = {{ from_deg = -30, to_deg = 40 }}\n"
    );
    let (flash_at, [flash_theta, flash_phi]) = flash_direction();
    let point = |p: [f64; 3]| {
        // irradiance 1 at the swatch centre, as the directional lights'
        let r_m = (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt() / 1000.0;
        format!(
            "{{ type = \"point\", position_mm = [{:.6}, {:.6}, {:.6}], intensity = {:.9} }}",
            p[0],
            p[1],
            p[2],
            r_m * r_m
        )
    };
    for (k, [lt, lp, vt, vp]) in IMAGES.into_iter().enumerate() {
        let flash = k == 0;
        let (light, camera) = match rig {
            Rig::Distant => {
                let (lt, lp) = if flash {
                    (flash_theta, flash_phi)
                } else {
                    (lt, lp)
                };
                (
                    format!("{{ type = \"directional\", theta_deg = {lt}, phi_deg = {lp}, irradiance = 1.0 }}"),
                    format!("{{ type = \"orthographic\", theta_deg = {vt}, phi_deg = {vp} }}"),
                )
            }
            Rig::Near => {
                let c = rig_position(vt, vp);
                (
                    point(if flash {
                        flash_at
                    } else {
                        rig_position(lt, lp)
                    }),
                    format!(
                        "{{ type = \"pinhole\", position_mm = [{:.6}, {:.6}, {:.6}] }}",
                        c[0], c[1], c[2]
                    ),
                )
            }
        };
        s += &format!("[[capture.images]]\nlight = {light}\ncamera = {camera}\n");
    }
    s + "[noise]\nrelative = 0.01\nseed = 5\n"
}

/// The benchmark on an `size` x `size` capture in `scratch`, with the binary `exe`.
pub fn run(
    exe: &Path,
    scratch: &Path,
    size: usize,
    bar: &indicatif::ProgressBar,
) -> Result<CameraRun> {
    let d = scratch.join("d");
    std::fs::write(scratch.join("synth.toml"), synth_config(size, Rig::Distant))?;
    bar.set_message("camera: rendering the capture");
    let t = Instant::now();
    crate::synth::run(&scratch.join("synth.toml"), &d, &crate::progress::Progress::quiet())?;
    let synth_seconds = t.elapsed().as_secs_f64();
    super::maps::write_blind(&d)?;
    std::fs::write(scratch.join("global.toml"), FIT_GLOBAL)?;
    std::fs::write(scratch.join("maps.toml"), FIT_MAPS)?;
    let counted = Counted::of(&d.join("capture.toml"))?;
    let mut rows = Vec::new();

    bar.set_message("camera: global fit");
    rows.push(global_row(exe, scratch, &counted)?);
    bar.inc(1);

    bar.set_message("camera: maps + globals");
    let cmd = fit_command(
        exe,
        &d.join("blind.toml"),
        (&scratch.join("maps.toml"), &scratch.join("maps.json")),
        Some(&scratch.join("maps")),
    );
    let cost = measure(cmd, &scratch.join("maps.log"))?;
    rows.push(row(
        "maps (H, psi) + globals: directional lights, orthographic cameras",
        &counted,
        &cost,
        (180.0, 1536.0),
        map_accuracy(&d, &scratch.join("maps"))?,
    ));
    bar.inc(1);
    let fit_peak = rows
        .iter()
        .find(|r| r.job == "global fit given the maps")
        .map_or(f64::INFINITY, |r| r.peak_mb);
    rows.extend(memory_rows(exe, scratch, size, fit_peak, bar)?);
    // the orthographic capture's files are not needed any more (8 x 1 Mpx: 100 MB of EXRs)
    std::fs::remove_dir_all(&d)?;
    let (pinhole_row, pinhole) = pinhole_rows(exe, scratch, size, bar)?;
    rows.push(pinhole_row);
    Ok(CameraRun {
        size,
        rows,
        store_bytes_per_value: counted.store_bytes,
        synth_seconds,
        pinhole: Some(pinhole),
        ratios: vec![],
    })
}

/// `fibrefit fit CAPTURE --config CONFIG --out OUT [--maps MAPS] -q`.
fn fit_command(
    exe: &Path,
    capture: &Path,
    (config, out): (&Path, &Path),
    maps: Option<&Path>,
) -> Command {
    let mut cmd = Command::new(exe);
    cmd.arg("fit")
        .arg(capture)
        .arg("--config")
        .arg(config)
        .arg("--out")
        .arg(out);
    if let Some(maps) = maps {
        cmd.arg("--maps").arg(maps);
    }
    cmd.arg("-q");
    cmd
}

/// The global fit given the maps of `scratch/d`'s capture, judged against issue 13's goal
/// (30 s, 1 GB), with its parameters against the truth.
fn global_row(exe: &Path, scratch: &Path, counted: &Counted) -> Result<CameraRow> {
    let d = scratch.join("d");
    let cmd = fit_command(
        exe,
        &d.join("capture.toml"),
        (&scratch.join("global.toml"), &scratch.join("global.json")),
        None,
    );
    let cost = measure(cmd, &scratch.join("global.log"))?;
    let g: serde_json::Value =
        serde_json::from_slice(&std::fs::read(scratch.join("global.json"))?)?;
    Ok(row(
        "global fit given the maps",
        counted,
        &cost,
        (30.0, 1024.0),
        global_accuracy(&g),
    ))
}

/// The global fit's result `g` against the truth: each parameter's value, standard error and
/// z per channel, and the fit over every pixel.
fn global_accuracy(g: &serde_json::Value) -> String {
    let mut acc = Vec::new();
    // per channel where the result has channels (kd here; ks is fitted per channel too)
    use crate::model::Param;
    for (param, truth) in [
        (Param::Kd, [0.45, 0.35, 0.25]),
        (Param::Ks, [0.3; 3]),
        (Param::Exponent, [40.0; 3]),
        (Param::Height, [0.9; 3]),
        (Param::MapScale, [0.6; 3]),
    ] {
        let name = param.name();
        let p = &g["parameters"][name];
        let list = |x: &serde_json::Value| -> Vec<f64> {
            match x {
                serde_json::Value::Array(a) => a.iter().filter_map(|v| v.as_f64()).collect(),
                v => v.as_f64().into_iter().collect(),
            }
        };
        let (v, se) = (list(&p["value"]), list(&p["std_error"]));
        let z: Vec<String> = v
            .iter()
            .zip(&se)
            .zip(truth)
            .map(|((v, se), t)| format!("{:.1}", (v - t) / se))
            .collect();
        let show = |x: &[f64]| {
            x.iter()
                .map(|v| format!("{v:.4e}"))
                .collect::<Vec<_>>()
                .join(", ")
        };
        acc.push(format!(
            "{name} {} +- {} (z {})",
            show(&v),
            show(&se),
            z.join(", ")
        ));
    }
    let all = &g["statistics"]["all_pixels"];
    acc.push(format!(
        "every pixel: relative RMSE {:.4}, residual variance {:.3e} (sample {:.3e})",
        all["relative_rmse"].as_f64().unwrap_or(f64::NAN),
        all["residual_variance"].as_f64().unwrap_or(f64::NAN),
        g["statistics"]["residual_variance"]
            .as_f64()
            .unwrap_or(f64::NAN)
    ));
    acc.join("; ")
}

/// Map recovery of the near rig's capture ([`Rig::Near`]: point lights and pinhole cameras,
/// image 0's light a flash beside its lens) in `scratch/near`, as the orthographic row's, and
/// the direction lattice's blend against the model at 256 of its texels.
pub fn pinhole_rows(
    exe: &Path,
    scratch: &Path,
    size: usize,
    bar: &indicatif::ProgressBar,
) -> Result<(CameraRow, PinholeRun)> {
    let dir = scratch.join("near");
    std::fs::create_dir_all(&dir)?;
    let d = dir.join("d");
    std::fs::write(dir.join("synth.toml"), synth_config(size, Rig::Near))?;
    bar.set_message("camera: rendering the pinhole capture");
    let t = Instant::now();
    crate::synth::run(&dir.join("synth.toml"), &d, &crate::progress::Progress::quiet())?;
    let synth_seconds = t.elapsed().as_secs_f64();
    let blind = super::maps::write_blind(&d)?;
    std::fs::write(dir.join("maps.toml"), FIT_MAPS)?;
    let store = CaptureStore::load(&blind, Default::default())?;
    let counted = Counted::from_store(&store);
    // the blend at the truth's exponent (a sharper lobe than the fit's start)
    let cfg: crate::fit::config::FitConfig =
        toml::from_str(&FIT_MAPS.replace("exponent = { value = 20,", "exponent = { value = 40,"))?;
    let blend = crate::fit::maps::blend_error(&store, &cfg, 256, 8, 11)?;
    drop(store);
    bar.set_message("camera: pinhole maps + globals");
    let cmd = fit_command(
        exe,
        &blind,
        (&dir.join("maps.toml"), &dir.join("maps.json")),
        Some(&dir.join("maps")),
    );
    let cost = measure(cmd, &dir.join("maps.log"))?;
    let (flash, _) = flash_direction();
    let row = row(
        &format!(
            "maps (H, psi) + globals: point lights, pinhole cameras {RIG_DISTANCE_MM:.0} mm away (image 0 lit by a flash {:.0} mm beside its lens)",
            flash[0]
        ),
        &counted,
        &cost,
        (180.0, 1536.0),
        map_accuracy(&d, &dir.join("maps"))?,
    );
    bar.inc(1);
    Ok((
        row,
        PinholeRun {
            synth_seconds,
            blend,
        },
    ))
}

/// What a capture holds: its texels, its pixel values and the bytes its compact store holds
/// per pixel value.
#[derive(Clone, Copy, Debug)]
struct Counted {
    texels: usize,
    values: usize,
    store_bytes: f64,
}

impl Counted {
    /// The capture at `capture`, loaded into its store to be counted.
    fn of(capture: &Path) -> Result<Self> {
        Ok(Self::from_store(&CaptureStore::load(
            capture,
            Default::default(),
        )?))
    }

    fn from_store(store: &CaptureStore) -> Self {
        let values = store.sample_count();
        Self {
            texels: store.texels().len(),
            values,
            store_bytes: store.bytes() as f64 / values as f64,
        }
    }
}

/// The row of `job` on a capture `counted`, which cost `cost`, against its goal in wall time
/// and peak memory (seconds, MB).
fn row(
    job: &str,
    counted: &Counted,
    cost: &Cost,
    (goal_seconds, goal_mb): (f64, f64),
    accuracy: String,
) -> CameraRow {
    let values = counted.values;
    CameraRow {
        job: job.into(),
        texels: counted.texels,
        pixel_values: values,
        wall_seconds: cost.wall_seconds,
        cpu_seconds: cost.cpu_seconds,
        peak_mb: cost.peak_mb,
        bytes_per_pixel_value: counted.store_bytes,
        peak_bytes_per_pixel_value: peak_bytes_per_value(cost, values),
        goal_seconds,
        goal_mb,
        goal_bytes_per_pixel_value: None,
        met: cost.wall_seconds <= goal_seconds && cost.peak_mb <= goal_mb,
        accuracy,
    }
}

fn peak_bytes_per_value(cost: &Cost, values: usize) -> f64 {
    cost.peak_mb * 1024.0 * 1024.0 / values.max(1) as f64
}

/// The capture side of issue 24's memory goal: `fit`, `score` and `inspect` of an RGB capture
/// of 8 x 512 x 512 pixels each peak at <= [`MEMORY_GOAL_BYTES`] per pixel value, the process's
/// fixed overhead included.
pub const MEMORY_SIZE: usize = 512;
pub const MEMORY_GOAL_BYTES: f64 = 150.0;

/// A goal on peak memory alone: at most `mb`, and at most `bytes_per_value` per pixel value
/// where given.
#[derive(Clone, Copy, Debug)]
struct MemoryGoal {
    mb: f64,
    bytes_per_value: Option<f64>,
}

/// A row of a job judged by its peak memory alone, against `goal`.
fn memory_row(
    job: &str,
    counted: &Counted,
    cost: &Cost,
    goal: MemoryGoal,
    accuracy: String,
) -> CameraRow {
    let mut r = row(job, counted, cost, (f64::INFINITY, goal.mb), accuracy);
    r.goal_bytes_per_pixel_value = goal.bytes_per_value;
    r.met = cost.peak_mb <= goal.mb
        && goal
            .bytes_per_value
            .is_none_or(|b| r.peak_bytes_per_pixel_value <= b);
    r
}

/// `fibrefit score RESULT CAPTURE` and `fibrefit inspect CAPTURE` as child processes, each
/// judged against `goal`; `label` names the capture.
fn score_and_inspect(
    exe: &Path,
    scratch: &Path,
    (capture, result): (&Path, &Path),
    label: &str,
    counted: &Counted,
    goal: MemoryGoal,
) -> Result<Vec<CameraRow>> {
    let mut rows = Vec::new();
    let mut cmd = Command::new(exe);
    cmd.arg("score").arg(result).arg(capture).arg("--json");
    let cost = measure(cmd, &scratch.join("score.log"))?;
    rows.push(memory_row(
        &format!("score of the global fit{label}"),
        counted,
        &cost,
        goal,
        "every pixel, a piece of whole image rows at a time".into(),
    ));
    let mut cmd = Command::new(exe);
    cmd.arg("inspect").arg(capture).arg("--json");
    let cost = measure(cmd, &scratch.join("inspect.log"))?;
    rows.push(memory_row(
        &format!("inspect{label}"),
        counted,
        &cost,
        goal,
        "every pixel counted from the store".into(),
    ));
    Ok(rows)
}

/// The memory rows of issue 24 item 4: `score` and `inspect` of this capture (`data/capture.toml`
/// and its global fit `result`) within the global fit's peak `fit_peak_mb`; and `fit`, `score`
/// and `inspect` of an 8 x [`MEMORY_SIZE`]^2 capture at <= [`MEMORY_GOAL_BYTES`] per pixel value
/// (rendered here unless this capture is that size).
pub fn memory_rows(
    exe: &Path,
    scratch: &Path,
    size: usize,
    fit_peak_mb: f64,
    bar: &indicatif::ProgressBar,
) -> Result<Vec<CameraRow>> {
    let d = scratch.join("d");
    let capture = d.join("capture.toml");
    let here = Counted::of(&capture)?;
    let goal_bytes = (size == MEMORY_SIZE).then_some(MEMORY_GOAL_BYTES);
    bar.set_message("camera: score and inspect");
    let mut rows = score_and_inspect(
        exe,
        scratch,
        (&capture, &scratch.join("global.json")),
        "",
        &here,
        MemoryGoal {
            mb: fit_peak_mb,
            bytes_per_value: goal_bytes,
        },
    )?;
    if size == MEMORY_SIZE {
        return Ok(rows);
    }
    // the goal's own capture: 8 x 512 x 512
    bar.set_message("camera: fit, score and inspect at 512 x 512");
    let m = scratch.join("m");
    std::fs::create_dir_all(&m)?;
    std::fs::write(
        m.join("synth.toml"),
        synth_config(MEMORY_SIZE, Rig::Distant),
    )?;
    crate::synth::run(&m.join("synth.toml"), &m.join("d"), &crate::progress::Progress::quiet())?;
    let capture = m.join("d/capture.toml");
    let there = Counted::of(&capture)?;
    let goal = MemoryGoal {
        mb: MEMORY_GOAL_BYTES * there.values as f64 / (1024.0 * 1024.0),
        bytes_per_value: Some(MEMORY_GOAL_BYTES),
    };
    let label = format!(", 8 x {MEMORY_SIZE} x {MEMORY_SIZE}");
    let cmd = fit_command(
        exe,
        &capture,
        (&scratch.join("global.toml"), &m.join("global.json")),
        None,
    );
    let cost = measure(cmd, &m.join("global.log"))?;
    rows.push(memory_row(
        &format!("global fit given the maps{label}"),
        &there,
        &cost,
        goal,
        format!(
            "sample of {} texels",
            crate::fit::config::Knobs::default().fit_texels
        ),
    ));
    rows.extend(score_and_inspect(
        exe,
        &m,
        (&capture, &m.join("global.json")),
        &label,
        &there,
        goal,
    )?);
    Ok(rows)
}

/// RMS and largest error of the recovered H and psi against the truth, how the errors compare
/// with the reported standard errors, and the share of texels flagged (from the result
/// `maps.json` beside the maps folder).
fn map_accuracy(data: &Path, maps: &Path) -> Result<String> {
    let read = |name: &str| crate::load::image_io::read(&maps.join(name), None, None);
    let (h, hse, p, pse) = (
        read("height.exr")?,
        read("height_std_error.exr")?,
        read("fibre_azimuth.exr")?,
        read("fibre_azimuth_std_error.exr")?,
    );
    let topo = TopologyMap::load(&data.join("topology.png"))?;
    let tan = TopologyMap::load_as(&data.join("tangent.png"), "tangent map")?;
    let (mut eh, mut ep, mut zh, mut zp) = (vec![], vec![], vec![], vec![]);
    for y in 0..h.height {
        for x in 0..h.width {
            let i = y * h.width + x;
            if h.data[i].is_nan() {
                continue;
            }
            let dh = h.data[i] as f64 - (0.9 + 0.6 * (2.0 * topo.texel(x, y) - 1.0));
            let dp = crate::fit::wrap_azimuth(p.data[i] as f64 - (-90.0 + 180.0 * tan.texel(x, y)));
            eh.push(dh);
            ep.push(dp);
            zh.push(dh / hse.data[i] as f64);
            zp.push(dp / pse.data[i] as f64);
        }
    }
    let (rh, _, mzh, wh) = super::maps::stats(&eh, &zh);
    let (rp, _, mzp, wp) = super::maps::stats(&ep, &zp);
    let largest = |e: &[f64]| e.iter().fold(0.0f64, |m, x| m.max(x.abs()));
    let result: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(maps.with_extension("json"))?)?;
    let flagged = result["maps"]["summary"]
        .as_array()
        .and_then(|s| s.iter().find_map(|m| m["flagged_fraction"].as_f64()))
        .unwrap_or(f64::NAN);
    Ok(format!(
        "RMS error H {rh:.4} radii (largest {:.3}; median |z| {mzh:.2}, {:.1} % within 3 se), psi {rp:.3} deg (largest {:.2}; median |z| {mzp:.2}, {:.1} % within 3 se); {:.1} % of texels flagged",
        largest(&eh),
        100.0 * wh,
        largest(&ep),
        100.0 * wp,
        100.0 * flagged
    ))
}
