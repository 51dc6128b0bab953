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

use crate::export::atomic::AtomicFile;
use crate::export::images;
use crate::load::capture::{self, Camera, CaptureFile, ImageSpec, Light, Swatch};
use crate::load::image_io::Encoding;
use crate::load::texel_maps::TexelMapsIn as UnitMaps;
use crate::model::frame::{direction_from_angles, FibreFrame};
use crate::model::params::{ModelParams, RawParams};
use crate::model::topology::TopologyMap;
use crate::model::{self, DirectionPair, ModelId, ShadingModel};
use anyhow::{anyhow, bail, Context, Result};
use rand::{Rng, SeedableRng};
use rand_distr::{Distribution, StandardNormal};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::io::Write;
use std::path::{Path, PathBuf};

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
pub fn run(config_path: &Path, out_dir: &Path, quiet: bool) -> Result<SynthInfo> {
    write_set(config_path, out_dir, quiet, false)
}

/// [`run`], with `force`: write into a folder synth did not make, over files it did not write.
pub fn write_set(
    config_path: &Path,
    out_dir: &Path,
    quiet: bool,
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
    let info = render_into(config_path, stage.path(), quiet)?;
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

fn render_into(config_path: &Path, out_dir: &Path, quiet: bool) -> Result<SynthInfo> {
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
    std::fs::create_dir_all(out_dir)
        .with_context(|| format!("{}: cannot create output directory", out_dir.display()))?;
    let mut raw = cfg.params.clone();
    raw.model = Some(id.to_string());
    let mut files = Vec::new();
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
    let (params, warnings) =
        ModelParams::from_raw(&raw, id).map_err(|e| anyhow!("{}: {e:#}", config_path.display()))?;
    if !quiet {
        for w in warnings {
            eprintln!("warning: {}: {w}", config_path.display());
        }
    }
    let shading = model::build(id, &params)?;
    let noise = Noise {
        spec: cfg.noise.clone(),
    };

    let mut gonio_rows = 0;
    if let Some(g) = &cfg.gonio {
        let text = render_gonio(g, shading.as_ref(), &params, &noise)?;
        gonio_rows = text.lines().count() - 1;
        write_file(&out_dir.join("gonio.csv"), text.as_bytes())?;
        files.push("gonio.csv".into());
    }
    let mut n_images = 0;
    if let Some(c) = &cfg.capture {
        let tied = raw.substrate_albedo.is_none();
        let written = render_capture(c, tied, shading.as_ref(), &params, &noise, out_dir, quiet)?;
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

/// Directions as (theta_i, phi_i, theta_o, phi_o) in degrees.
fn gonio_directions(g: &GonioSpec) -> Result<Vec<[f64; 4]>> {
    match (&g.grid, &g.random) {
        (Some(grid), None) => {
            let mut out = Vec::new();
            for &ti in &grid.theta_i {
                for &pi in &grid.phi_i {
                    for &to in &grid.theta_o {
                        for &po in &grid.phi_o {
                            if ti < 90.0 && to < 90.0 && ti >= 0.0 && to >= 0.0 {
                                out.push([ti, pi, to, po]);
                            }
                        }
                    }
                }
            }
            Ok(out)
        }
        (None, Some(r)) => {
            if !(r.max_theta_deg > 0.0 && r.max_theta_deg < 90.0) {
                bail!("gonio.random.max_theta_deg must lie in (0, 90)");
            }
            let mut rng = rand::rngs::StdRng::seed_from_u64(r.seed);
            let cos_max = r.max_theta_deg.to_radians().cos();
            let mut dir = || {
                // uniform in solid angle above theta_max, rounded to 1e-6 degrees so the CSV
                // holds exactly the rendered directions
                let z: f64 = cos_max + (1.0 - cos_max) * rng.random::<f64>();
                let round = |x: f64| (x * 1e6).round() / 1e6;
                (
                    round(z.acos().to_degrees()),
                    round(rng.random::<f64>() * 360.0),
                )
            };
            Ok((0..r.count)
                .map(|_| {
                    let (a, b) = dir();
                    let (c, d) = dir();
                    [a, b, c, d]
                })
                .collect())
        }
        _ => bail!("[gonio] needs exactly one of `grid` or `random`"),
    }
}

fn render_gonio(
    g: &GonioSpec,
    shading: &dyn ShadingModel,
    p: &ModelParams,
    noise: &Noise,
) -> Result<String> {
    let radiance = match g.values.as_str() {
        "brdf" => false,
        "radiance" => true,
        other => bail!("gonio.values = '{other}': expected \"brdf\" or \"radiance\""),
    };
    if radiance && !(g.irradiance > 0.0) {
        bail!("gonio.irradiance must be positive");
    }
    let dirs = gonio_directions(g)?;
    if dirs.is_empty() {
        bail!("[gonio] gives no directions above the horizon");
    }
    let frame = FibreFrame::from_azimuth(p.fibre_azimuth);
    let channels = p.albedos.channels();
    let values: Vec<[f64; 3]> = dirs
        .par_iter()
        .map(|d| {
            let l = direction_from_angles(d[0].to_radians(), d[1].to_radians());
            let v = direction_from_angles(d[2].to_radians(), d[3].to_radians());
            let b = shading.basis(&DirectionPair::new(&frame, &l, &v));
            [
                b.brdf(&p.albedos, 0),
                b.brdf(&p.albedos, 1),
                b.brdf(&p.albedos, 2),
            ]
        })
        .collect();
    let mut rng = rand::rngs::StdRng::seed_from_u64(noise.spec.seed);
    let base = if radiance { "radiance" } else { "brdf" };
    let names = |b: &str| -> Vec<String> {
        if channels == 1 {
            vec![b.to_string()]
        } else {
            ["r", "g", "b"].iter().map(|c| format!("{b}_{c}")).collect()
        }
    };
    let mut header = vec![
        "theta_i".to_string(),
        "phi_i".into(),
        "theta_o".into(),
        "phi_o".into(),
    ];
    header.extend(names(base));
    if radiance {
        header.push("irradiance".into());
    }
    if noise.active() {
        header.extend(names("sigma"));
    }
    let mut out = header.join(",") + "\n";
    for (d, f) in dirs.iter().zip(&values) {
        let to_file = if radiance {
            g.irradiance * d[0].to_radians().cos()
        } else {
            1.0
        };
        let mut row: Vec<String> = d.iter().map(|x| x.to_string()).collect();
        for &fc in &f[..channels] {
            row.push((noise.apply(fc, &mut rng) * to_file).to_string());
        }
        if radiance {
            row.push(g.irradiance.to_string());
        }
        if noise.active() {
            for &fc in &f[..channels] {
                row.push((noise.sigma(fc) * to_file).to_string());
            }
        }
        out += &row.join(",");
        out.push('\n');
    }
    Ok(out)
}

#[allow(clippy::too_many_arguments)]
fn render_capture(
    c: &CaptureSpec,
    substrate_tied: bool,
    shading: &dyn ShadingModel,
    p: &ModelParams,
    noise: &Noise,
    out_dir: &Path,
    quiet: bool,
) -> Result<Vec<String>> {
    let (w, h) = (c.width, c.height);
    if w == 0 || h == 0 || c.images.is_empty() {
        bail!("[capture] needs width, height > 0 and at least one [[capture.images]]");
    }
    let png = match c.format.as_str() {
        "exr" => false,
        "png" => true,
        other => bail!("capture.format = '{other}': expected \"exr\" or \"png\""),
    };
    let encoding = if png {
        Some(c.encoding.unwrap_or(Encoding::Srgb))
    } else {
        None
    };
    let mut files = Vec::new();
    let psi_of = |x: usize| -> f64 {
        match &c.tangent {
            Some(t) => {
                // quantised exactly as the tangent map stores it
                let m = ((x as f64 + 0.5) / w as f64 * 65535.0).round() / 65535.0;
                let deg = t.from_deg + (t.to_deg - t.from_deg) * m;
                deg.to_radians()
            }
            None => p.fibre_azimuth,
        }
    };
    let tangent_file = if let Some(t) = &c.tangent {
        if !(-90.0..=90.0).contains(&t.from_deg) || !(-90.0..=90.0).contains(&t.to_deg) {
            bail!("capture.tangent: angles must lie in [-90, 90] degrees");
        }
        // stored as m with psi = -90 + 180 m
        let values: Vec<f32> = (0..h)
            .flat_map(|_| (0..w).map(|x| ((psi_of(x).to_degrees() + 90.0) / 180.0) as f32))
            .collect();
        images::write_gray16(&out_dir.join("tangent.png"), w, h, &values)?;
        files.push("tangent.png".to_string());
        Some(PathBuf::from("tangent.png"))
    } else {
        None
    };
    // Re-read the tangent map so pixels use exactly the stored angle.
    let tangent_map = match &tangent_file {
        Some(f) => Some(TopologyMap::load(&out_dir.join(f))?),
        None => None,
    };
    let topo_map = p.topology.map.clone();
    if let Some(m) = &topo_map {
        if (m.width, m.height) != (w, h) {
            bail!(
                "the topology map is {}x{} but the capture is {w}x{h}; they must be registered",
                m.width,
                m.height
            );
        }
    }
    let unit_maps = match &c.maps {
        Some(dir) => Some(
            UnitMaps::load(dir, Some((w, h)))
                .map_err(|e| anyhow!("capture.maps = {}: {e:#}", dir.display()))?,
        ),
        None => None,
    };
    if let Some(m) = &unit_maps {
        if m.psi.is_some() && c.tangent.is_some() {
            bail!("give capture.tangent or a fibre_azimuth.exr in capture.maps, not both");
        }
    }
    let mut channels = p.albedos.channels();
    if unit_maps.as_ref().is_some_and(|m| {
        [&m.kd, &m.ks]
            .iter()
            .any(|x| x.as_ref().is_some_and(|i| i.channels == 3))
    }) {
        channels = 3;
    }
    let bar = crate::progress::bar((c.images.len() * h) as u64, "rendering", quiet);
    let mut specs = Vec::new();
    for (k, img) in c.images.iter().enumerate() {
        if matches!(img.camera, Camera::ViewMap { .. }) {
            bail!("[[capture.images]] {k}: synth renders orthographic or pinhole cameras, not view maps");
        }
        // Per pixel: the BRDF per channel and E cos(theta_i), radiance = BRDF x that.
        let pixels: Vec<([f64; 3], f64)> = (0..h)
            .into_par_iter()
            .flat_map_iter(|y| {
                let row: Vec<([f64; 3], f64)> = (0..w)
                    .map(|x| {
                        let pos = capture::pixel_position(c.size_mm, w, h, x, y);
                        let (l, e) = capture::light_at(&img.light, &pos);
                        let v =
                            capture::view_at(&img.camera, &pos).expect("checked: not a view map");
                        let um = unit_maps.as_ref();
                        let psi =
                            match (&tangent_map, um.and_then(|m| UnitMaps::at(&m.psi, x, y, 0))) {
                                (_, Some(deg)) => deg.to_radians(),
                                (Some(t), None) => (-90.0 + 180.0 * t.texel(x, y)).to_radians(),
                                (None, None) => psi_of(x),
                            };
                        let pair = DirectionPair::new(&FibreFrame::from_azimuth(psi), &l, &v);
                        let height = um
                            .and_then(|m| UnitMaps::at(&m.height, x, y, 0))
                            .or(topo_map
                                .as_ref()
                                .map(|m| p.topology.texel_height(m.texel(x, y), p.spacing)));
                        let basis = match height {
                            Some(hh) if shading.rung().has(crate::model::Ability::Topology) => {
                                shading.basis_at_height(&pair, hh).unwrap_or_default()
                            }
                            _ => shading.basis(&pair),
                        };
                        let mut albedos = p.albedos;
                        for ch in 0..3 {
                            if let Some(k) = um.and_then(|m| UnitMaps::at(&m.kd, x, y, ch)) {
                                albedos.diffuse[ch] = k;
                                if substrate_tied {
                                    albedos.substrate[ch] = k;
                                }
                            }
                            if let Some(k) = um.and_then(|m| UnitMaps::at(&m.ks, x, y, ch)) {
                                albedos.specular[ch] = k;
                            }
                        }
                        (
                            [0, 1, 2].map(|ch| basis.brdf(&albedos, ch)),
                            e * l.z.max(0.0),
                        )
                    })
                    .collect();
                bar.inc(1);
                row
            })
            .collect();
        // noise in BRDF units, per pixel and channel, from one seeded stream per image
        let mut rng =
            rand::rngs::StdRng::seed_from_u64(noise.spec.seed.wrapping_add(k as u64 * 7919));
        let mut data: Vec<f32> = Vec::with_capacity(w * h * channels);
        for (brdf, scale) in &pixels {
            for &f in &brdf[..channels] {
                data.push((noise.apply(f, &mut rng) * scale) as f32);
            }
        }
        let exposure = if png {
            let max = data.iter().copied().fold(0.0f32, f32::max).max(1e-30);
            let exposure = (max / 0.8) as f64;
            for v in data.iter_mut() {
                *v = (*v as f64 / exposure) as f32;
            }
            exposure
        } else {
            1.0
        };
        let file = format!("img_{k:03}.{}", if png { "png" } else { "exr" });
        let path = out_dir.join(&file);
        if png {
            images::write_png16(
                &path,
                w,
                h,
                channels,
                &data,
                encoding.expect("png has encoding"),
            )?;
        } else {
            images::write_exr(&path, w, h, channels, &data)?;
        }
        files.push(file.clone());
        specs.push(ImageSpec {
            file: Some(file.into()),
            bracket: vec![],
            encoding,
            exposure,
            saturation: None,
            light: img.light.clone(),
            camera: img.camera.clone(),
        });
    }
    bar.finish_and_clear();
    // recovered maps travel with the capture, as its height and fibre azimuth maps
    let mut copy_map = |name: &str| -> Result<Option<PathBuf>> {
        let Some(dir) = &c.maps else { return Ok(None) };
        let src = dir.join(name);
        if !src.exists() {
            return Ok(None);
        }
        let bytes = crate::load::read_input(&src, crate::load::input::MAX_INPUT_BYTES)?.bytes;
        write_file(&out_dir.join(name), &bytes)?;
        files.push(name.to_string());
        Ok(Some(PathBuf::from(name)))
    };
    let height_map = copy_map("height.exr")?;
    let fibre_azimuth_map = copy_map("fibre_azimuth.exr")?;
    let capture_file = CaptureFile {
        swatch: Swatch {
            size_mm: c.size_mm,
            roi: None,
            mask: None,
            fibre_azimuth_deg: if tangent_file.is_none() && fibre_azimuth_map.is_none() {
                Some(p.fibre_azimuth.to_degrees())
            } else {
                None
            },
            tangent_map: tangent_file,
            topology_map: if height_map.is_none() {
                topo_map.as_ref().map(|m| relative_to(&m.source, out_dir))
            } else {
                None
            },
            height_map,
            fibre_azimuth_map,
        },
        images: specs,
    };
    let text = format!(
        "# Image capture rendered by fibrefit synth ({}). Format: fibrefit docs/formats.md, \"Image captures\".\n{}",
        shading.id(),
        toml::to_string(&capture_file)?
    );
    write_file(&out_dir.join("capture.toml"), text.as_bytes())?;
    files.push("capture.toml".into());
    Ok(files)
}
