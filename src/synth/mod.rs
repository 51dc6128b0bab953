//! Synthetic measurements rendered from a chosen rung and known parameters: goniometric CSVs and
//! image captures (EXR or 16-bit PNG + capture TOML + topology map), with seeded noise, and the
//! truth written beside them. Everything fibrefit fits can be validated against these.
//!
//! Config (example: `configs/synth_silk.toml`):
//! - `model`: rung id; `[params]`: parameter names of MODEL.md §5 (relative paths resolve against
//!   the config file), or `params_file`: a parameter file or a fit's result JSON;
//! - `[topology_map]`: a generated map (`width`, `height`, `seed`, `waves`) written as
//!   `topology.png`; it becomes the params' `topology_map`;
//! - `[gonio]`: `grid` (lists of `theta_i`, `phi_i`, `theta_o`, `phi_o` in degrees, all
//!   combinations with both thetas < 90) or `random` (`count`, `seed`, `max_theta_deg`);
//!   `values = "brdf"` (default) or `"radiance"` with `irradiance`;
//! - `[capture]`: `width`, `height`, `size_mm`, `format = "exr" | "png"` (PNG: 16-bit with
//!   `encoding`), optional `tangent` (psi varying linearly across x from `from_deg` to `to_deg`,
//!   written as `tangent.png`), optional `maps`: a directory of per-texel maps as `fit --maps`
//!   writes them (`height.exr`, `fibre_azimuth.exr`, `kd.exr`, `ks.exr`; copied beside the
//!   capture as its height and fibre azimuth maps), and `[[capture.images]]` with a `light` and a
//!   `camera` as in capture files;
//! - `[noise]`: `relative` (Gaussian, times the value), `floor` (additive Gaussian, 1/sr), `seed`.
//!
//! Here: the config, the noise, and writing the set into its folder all or nothing; the
//! goniometric CSV is rendered in `gonio.rs`, the capture in `capture.rs`.

use crate::export::atomic::AtomicFile;
use crate::export::images;
use crate::load::capture::{Camera, Light};
use crate::load::image_io::Encoding;
use crate::model::params::{ModelParams, RawParams};
use crate::model::{self, ModelId};
use anyhow::{anyhow, bail, Context, Result};
use rand::{Rng, SeedableRng};
use rand_distr::{Distribution, StandardNormal};
use serde::{Deserialize, Serialize};
use std::io::Write;
use std::path::{Path, PathBuf};

mod capture;
pub mod photo;
mod gonio;

#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SynthConfig {
    pub model: String,
    /// The parameters inline, or (`params_file`) from a parameter file or a fit's result JSON.
    #[serde(default)]
    pub params: RawParams,
    pub params_file: Option<PathBuf>,
    pub topology_map: Option<MapSpec>,
    pub gonio: Option<GonioSpec>,
    pub capture: Option<CaptureSpec>,
    #[serde(default)]
    pub noise: NoiseSpec,
}

#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MapSpec {
    pub width: usize,
    pub height: usize,
    #[serde(default)]
    pub seed: u64,
    /// Number of random plane waves summed (default 6).
    #[serde(default = "default_waves")]
    pub waves: usize,
}

fn default_waves() -> usize {
    6
}

#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GonioSpec {
    pub grid: Option<Grid>,
    pub random: Option<RandomDirections>,
    #[serde(default = "default_values")]
    pub values: String,
    #[serde(default = "one")]
    pub irradiance: f64,
}

fn default_values() -> String {
    "brdf".into()
}
fn one() -> f64 {
    1.0
}

#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Grid {
    pub theta_i: Vec<f64>,
    pub phi_i: Vec<f64>,
    pub theta_o: Vec<f64>,
    pub phi_o: Vec<f64>,
}

#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RandomDirections {
    pub count: usize,
    #[serde(default)]
    pub seed: u64,
    #[serde(default = "default_max_theta")]
    pub max_theta_deg: f64,
}

fn default_max_theta() -> f64 {
    85.0
}

#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CaptureSpec {
    pub width: usize,
    pub height: usize,
    pub size_mm: [f64; 2],
    #[serde(default = "default_format")]
    pub format: String,
    pub encoding: Option<Encoding>,
    pub tangent: Option<TangentSpec>,
    /// A directory of per-texel maps as `fit --maps` writes them (`height.exr` in fibre radii,
    /// `fibre_azimuth.exr` in degrees, `kd.exr`, `ks.exr`; those present are used, NaN texels
    /// take the global value), registered to the capture's pixels.
    pub maps: Option<PathBuf>,
    pub images: Vec<SynthImage>,
}

fn default_format() -> String {
    "exr".into()
}

#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TangentSpec {
    pub from_deg: f64,
    pub to_deg: f64,
}

#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SynthImage {
    pub light: Light,
    pub camera: Camera,
}

#[derive(Clone, Debug, Default, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct NoiseSpec {
    #[serde(default)]
    pub relative: f64,
    #[serde(default)]
    pub floor: f64,
    #[serde(default)]
    pub seed: u64,
}

/// What `run` wrote.
#[derive(Clone, Debug, Serialize)]
pub struct SynthInfo {
    pub tool: String,
    pub model: String,
    pub noise: NoiseSpec,
    pub gonio_rows: usize,
    pub images: usize,
    pub files: Vec<String>,
}

impl SynthConfig {
    pub fn load(path: &Path) -> Result<Self> {
        let text = crate::load::input::read_text_as(path, "synth config")?;
        let mut cfg: SynthConfig = toml::from_str(&text)
            .map_err(|e| anyhow!("{}: {}", path.display(), e.to_string().trim_end()))?;
        let base = path.parent().unwrap_or(Path::new("."));
        if let Some(file) = cfg.params_file.clone() {
            if toml::to_string(&cfg.params).map(|t| !t.trim().is_empty())? {
                bail!("{}: give [params] or params_file, not both", path.display());
            }
            let file = if file.is_relative() {
                base.join(file)
            } else {
                file
            };
            cfg.params = crate::export::result_json::read_params(&file)
                .with_context(|| format!("{}: params_file", path.display()))?;
            cfg.params.model = None;
            // a fit's knobs carry the map it used, resolved already
        }
        if let Some(c) = &mut cfg.capture {
            if let Some(m) = &c.maps {
                if m.is_relative() {
                    c.maps = Some(base.join(m));
                }
            }
        }
        if let Some(map) = &cfg.params.topology_map {
            if map.is_relative() {
                cfg.params.topology_map = Some(path.parent().unwrap_or(Path::new(".")).join(map));
            }
        }
        Ok(cfg)
    }
}

/// A smooth map in [0, 1]: a seeded sum of plane waves, normalised.
pub fn generate_map(spec: &MapSpec) -> Vec<f32> {
    let mut rng = rand::rngs::StdRng::seed_from_u64(spec.seed);
    let waves: Vec<(f64, f64, f64, f64)> = (0..spec.waves.max(1))
        .map(|k| {
            let angle = rng.random::<f64>() * std::f64::consts::TAU;
            let wavelength = 6.0 + 30.0 * rng.random::<f64>();
            let amplitude = 1.0 / (1.0 + k as f64 * 0.5);
            (
                angle,
                wavelength,
                rng.random::<f64>() * std::f64::consts::TAU,
                amplitude,
            )
        })
        .collect();
    let raw: Vec<f64> = (0..spec.height)
        .flat_map(|y| (0..spec.width).map(move |x| (x as f64, y as f64)))
        .map(|(x, y)| {
            waves
                .iter()
                .map(|&(a, wl, ph, amp)| {
                    amp * ((x * a.cos() + y * a.sin()) * std::f64::consts::TAU / wl + ph).sin()
                })
                .sum()
        })
        .collect();
    let (lo, hi) = raw
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), &v| {
            (l.min(v), h.max(v))
        });
    // quantise to 16 bits so the PNG holds exactly these values
    raw.iter()
        .map(|v| (((v - lo) / (hi - lo).max(1e-300)) * 65535.0).round() as f32 / 65535.0)
        .collect()
}

struct Noise {
    spec: NoiseSpec,
}

impl Noise {
    fn apply(&self, f: f64, rng: &mut impl Rng) -> f64 {
        if self.spec.relative == 0.0 && self.spec.floor == 0.0 {
            return f;
        }
        let a: f64 = StandardNormal.sample(rng);
        let b: f64 = StandardNormal.sample(rng);
        f * (1.0 + self.spec.relative * a) + self.spec.floor * b
    }
    fn sigma(&self, f: f64) -> f64 {
        ((self.spec.relative * f).powi(2) + self.spec.floor.powi(2)).sqrt()
    }
    fn active(&self) -> bool {
        self.spec.relative > 0.0 || self.spec.floor > 0.0
    }
}

fn write_file(path: &Path, bytes: &[u8]) -> Result<()> {
    let mut f = AtomicFile::create(path)?;
    f.writer().write_all(bytes)?;
    f.commit()
}

/// Render everything `config` asks for into `out_dir`. Returns what was written.
///
/// The set is rendered into a staging directory inside `out_dir` and its files put in place
/// together (see [`crate::export::atomic::Outputs`]), so a dataset is always all old or all new:
/// a failed or interrupted run leaves `out_dir` as it was. A linked `out_dir` stays a link (the
/// set goes into its target). Files synth did not write are kept: a folder that is neither
/// empty nor synth's own (no `synth_info.json`) is refused, and so is a new file of the set
/// whose name a user's own file in a synth folder has; `force` writes over both.
pub fn run(config_path: &Path, out_dir: &Path, progress: &crate::progress::Progress) -> Result<SynthInfo> {
    write_set(config_path, out_dir, progress, false)
}

/// [`run`], with `force`: write into a folder synth did not make, over files it did not write.
pub fn write_set(
    config_path: &Path,
    out_dir: &Path,
    progress: &crate::progress::Progress,
    force: bool,
) -> Result<SynthInfo> {
    use crate::export::atomic::Outputs;
    let mut outs = Outputs::new(&[config_path.to_path_buf()]);
    let dir = outs.dir(out_dir, "--out")?;
    // one synth run at a time writes into a folder: a second waits for the first to finish, so
    // the set is always one run's (held until the old set's leftovers are removed)
    let _lock = lock_folder(&dir, out_dir)?;
    let marker = dir.join("synth_info.json");
    let has_marker = marker.is_file();
    // the files of the old set, as its synth_info.json lists them
    let old_set: Vec<String> = has_marker
        .then(|| crate::load::input::read_text(&marker))
        .and_then(Result::ok)
        .and_then(|t| serde_json::from_str::<serde_json::Value>(&t).ok())
        .and_then(|v| v.get("files").cloned())
        .and_then(|f| serde_json::from_value(f).ok())
        .unwrap_or_default();
    let foreign: Vec<String> = std::fs::read_dir(&dir)
        .with_context(|| format!("--out {}: cannot read the folder", out_dir.display()))?
        .flatten()
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .filter(|n| !n.starts_with(".fibrefit-") && n != "synth_info.json" && !old_set.contains(n))
        .collect();
    if !has_marker && !foreign.is_empty() && !force {
        bail!(
            "--out {}: not empty and not a folder synth wrote (no synth_info.json): its files \
             ({}{}) would be mixed with or replaced by the set; give a new or empty folder, or --force",
            out_dir.display(),
            foreign.iter().take(3).cloned().collect::<Vec<_>>().join(", "),
            if foreign.len() > 3 { ", ..." } else { "" }
        );
    }
    let stage = crate::export::atomic::Staging::new(&dir, "synth")?;
    let info = render_into(config_path, stage.path(), progress)?;
    let mut staged: Vec<String> = std::fs::read_dir(stage.path())
        .with_context(|| format!("{}: cannot read the staged set", stage.path().display()))?
        .flatten()
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .collect();
    staged.sort();
    if !force {
        if let Some(mine) = staged.iter().find(|n| foreign.contains(n)) {
            bail!(
                "--out {}: {mine} is not a file synth wrote (not in synth_info.json's list), and the new \
                 set has a file of that name; move it away, or give --force to replace it; nothing was written",
                out_dir.display()
            );
        }
    }
    for name in &staged {
        let id = outs.file(&out_dir.join(name), "--out")?;
        let src = stage.path().join(name);
        let mut from = std::fs::File::open(&src)
            .with_context(|| format!("{}: cannot read the staged file", src.display()))?;
        std::io::copy(&mut from, &mut outs.writer(id))?;
    }
    outs.commit()?;
    drop(stage);
    // files of the old set that the new one no longer has go (a user's own never do)
    for f in old_set.iter().filter(|f| !info.files.contains(f)) {
        let p = dir.join(f);
        if std::fs::symlink_metadata(&p).is_ok_and(|m| m.is_file()) && !f.contains('/') {
            let _ = std::fs::remove_file(p);
        }
    }
    Ok(info)
}

/// An exclusive lock on the folder `dir` (`shown` as the user gave it), waited for while
/// another synth run holds it; a signal stops the wait. Released when the handle is dropped.
fn lock_folder(dir: &Path, shown: &Path) -> Result<std::fs::File> {
    use std::os::fd::AsRawFd;
    let f = std::fs::File::open(dir)
        .with_context(|| format!("--out {}: cannot open the folder", shown.display()))?;
    loop {
        // SAFETY: flock on a descriptor we own
        if unsafe { libc::flock(f.as_raw_fd(), libc::LOCK_EX | libc::LOCK_NB) } == 0 {
            return Ok(f);
        }
        let e = std::io::Error::last_os_error();
        if e.kind() != std::io::ErrorKind::WouldBlock && e.kind() != std::io::ErrorKind::Interrupted
        {
            bail!("--out {}: cannot lock the folder: {e}", shown.display());
        }
        if crate::load::input::interrupted() {
            bail!(
                "--out {}: {}",
                shown.display(),
                crate::load::input::INTERRUPTED_MESSAGE
            );
        }
        std::thread::sleep(std::time::Duration::from_millis(50));
    }
}

/// Render the set `config_path` describes into `out_dir` (the staging folder): the topology
/// map, the goniometric CSV and the capture it asks for, the truth and `synth_info.json`.
fn render_into(config_path: &Path, out_dir: &Path, progress: &crate::progress::Progress) -> Result<SynthInfo> {
    let (cfg, id) = load_checked(config_path)?;
    std::fs::create_dir_all(out_dir)
        .with_context(|| format!("{}: cannot create output directory", out_dir.display()))?;
    let mut raw = cfg.params.clone();
    raw.model = Some(id.to_string());
    let mut files = Vec::new();
    topology_into(&cfg, config_path, out_dir, &mut raw, &mut files)?;
    let (params, warnings) =
        ModelParams::from_raw(&raw, id).map_err(|e| anyhow!("{}: {e:#}", config_path.display()))?;
    for w in warnings {
        progress.warn(&format!("{}: {w}", config_path.display()));
    }
    let shading = model::build(id, &params)?;
    let noise = Noise {
        spec: cfg.noise.clone(),
    };

    let mut gonio_rows = 0;
    if let Some(g) = &cfg.gonio {
        let text = gonio::render_gonio(g, shading.as_ref(), &params, &noise)?;
        gonio_rows = text.lines().count() - 1;
        write_file(&out_dir.join("gonio.csv"), text.as_bytes())?;
        files.push("gonio.csv".into());
    }
    let mut n_images = 0;
    if let Some(c) = &cfg.capture {
        let written = capture::render_capture(&capture::CaptureRequest {
            spec: c,
            substrate_tied: raw.substrate_albedo.is_none(),
            shading: shading.as_ref(),
            params: &params,
            noise: &noise,
            out_dir,
            progress,
        })?;
        n_images = c.images.len();
        files.extend(written);
    }

    // The truth, usable as `fibrefit eval --params truth.json`.
    let mut truth = raw.clone();
    if let Some(map) = &truth.topology_map {
        truth.topology_map = Some(relative_to(map, out_dir));
    }
    write_file(
        &out_dir.join("truth.json"),
        serde_json::to_string_pretty(&truth)?.as_bytes(),
    )?;
    files.push("truth.json".into());
    let info = SynthInfo {
        tool: format!("fibrefit {}", env!("CARGO_PKG_VERSION")),
        model: id.to_string(),
        noise: cfg.noise.clone(),
        gonio_rows,
        images: n_images,
        files: files.clone(),
    };
    write_file(
        &out_dir.join("synth_info.json"),
        serde_json::to_string_pretty(&info)?.as_bytes(),
    )?;
    Ok(info)
}

/// The config at `config_path` and its rung, refused when it renders nothing, has negative
/// noise or asks for more than synth's budget.
fn load_checked(config_path: &Path) -> Result<(SynthConfig, ModelId)> {
    let cfg = SynthConfig::load(config_path)?;
    let id: ModelId = cfg
        .model
        .parse()
        .map_err(|e: String| anyhow!("{}: {e}", config_path.display()))?;
    if cfg.gonio.is_none() && cfg.capture.is_none() {
        bail!(
            "{}: nothing to render: add [gonio] and/or [capture]",
            config_path.display()
        );
    }
    if cfg.noise.relative < 0.0 || cfg.noise.floor < 0.0 {
        bail!("{}: noise levels must be >= 0", config_path.display());
    }
    check_budget(&cfg).map_err(|e| anyhow!("{}: {e}", config_path.display()))?;
    Ok((cfg, id))
}

/// The set's topology map into `out_dir`: the parameters' own map copied (the capture stays
/// self-contained), or `[topology_map]` generated; `raw` then names the copy.
fn topology_into(
    cfg: &SynthConfig,
    config_path: &Path,
    out_dir: &Path,
    raw: &mut RawParams,
    files: &mut Vec<String>,
) -> Result<()> {
    if let Some(src) = raw.topology_map.clone() {
        if cfg.topology_map.is_some() {
            bail!(
                "{}: give [topology_map] or params.topology_map, not both",
                config_path.display()
            );
        }
        // keep the capture self-contained: the map travels with the data
        let ext = src
            .extension()
            .and_then(|e| e.to_str())
            .unwrap_or("png")
            .to_ascii_lowercase();
        let name = format!("topology.{ext}");
        let dest = out_dir.join(&name);
        if std::fs::canonicalize(&src).ok() != std::fs::canonicalize(&dest).ok() {
            let bytes = crate::load::input::read_input_as(
                &src,
                crate::load::input::MAX_INPUT_BYTES,
                "topology map",
            )?
            .bytes;
            write_file(&dest, &bytes)?;
        }
        files.push(name);
        raw.topology_map = Some(dest);
    }
    if let Some(spec) = &cfg.topology_map {
        if raw.topology_map.is_some() {
            bail!(
                "{}: give [topology_map] or params.topology_map, not both",
                config_path.display()
            );
        }
        if let Some(c) = &cfg.capture {
            if (c.width, c.height) != (spec.width, spec.height) {
                bail!(
                    "{}: [topology_map] must match the capture's {}x{} pixels",
                    config_path.display(),
                    c.width,
                    c.height
                );
            }
        }
        let values = generate_map(spec);
        let path = out_dir.join("topology.png");
        images::write_gray16(&path, spec.width, spec.height, &values)?;
        files.push("topology.png".into());
        raw.topology_map = Some(path);
    }
    Ok(())
}

fn relative_to(path: &Path, dir: &Path) -> PathBuf {
    path.strip_prefix(dir)
        .map(Path::to_path_buf)
        .unwrap_or_else(|_| std::path::absolute(path).unwrap_or(path.to_path_buf()))
}

/// Most goniometric rows synth writes: 10 million (about 1 GB of CSV).
pub const MAX_GONIO_ROWS: usize = 10_000_000;
/// Most pixels of one synthetic image or generated map: 16 M (4096 x 4096; 200 MB as RGB f32).
pub const MAX_IMAGE_PIXELS: usize = 1 << 24;
/// Most images of one synthetic capture.
pub const MAX_IMAGES: usize = 1024;

/// Refuse, before any work, a set larger than [`MAX_GONIO_ROWS`], [`MAX_IMAGE_PIXELS`] or
/// [`MAX_IMAGES`] (sizes multiplied without overflow).
fn check_budget(cfg: &SynthConfig) -> Result<()> {
    if let Some(g) = &cfg.gonio {
        let rows = match (&g.grid, &g.random) {
            (Some(grid), _) => [&grid.theta_i, &grid.phi_i, &grid.theta_o, &grid.phi_o]
                .iter()
                .try_fold(1usize, |n, l| n.checked_mul(l.len())),
            (None, Some(r)) => Some(r.count),
            _ => Some(0),
        };
        match rows {
            Some(n) if n <= MAX_GONIO_ROWS => {}
            _ => bail!(
                "[gonio] asks for {} rows, more than the {MAX_GONIO_ROWS} synth writes",
                rows.map_or("over 2^64".to_string(), |n| n.to_string())
            ),
        }
    }
    let pixels = |what: &str, w: usize, h: usize| -> Result<()> {
        match w.checked_mul(h) {
            Some(n) if n <= MAX_IMAGE_PIXELS => Ok(()),
            _ => bail!(
                "{what}: {w} x {h} pixels, more than the {} M pixels synth renders per image",
                MAX_IMAGE_PIXELS >> 20
            ),
        }
    };
    if let Some(c) = &cfg.capture {
        pixels("[capture]", c.width, c.height)?;
        if c.images.len() > MAX_IMAGES {
            bail!(
                "[capture]: {} images, more than the {MAX_IMAGES} synth renders",
                c.images.len()
            );
        }
    }
    if let Some(m) = &cfg.topology_map {
        pixels("[topology_map]", m.width, m.height)?;
    }
    Ok(())
}
