//! Map recovery past one machine: [`run_tile`] fits the texels of one band of rows given the
//! globals of `fit --map-globals` and writes a tile file; [`merge`] assembles the bands into the
//! same maps (bit for bit) as a single `fit --maps` run.

use crate::export::atomic::Outputs;
use crate::export::maps_out::MapFiles;
use crate::fit::config::FitConfig;
use crate::fit::maps::{self, TexelPart};
use crate::load::LoadOptions;
use anyhow::{anyhow, bail, Context, Result};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// Schema of a tile file.
pub const TILE_SCHEMA: &str = "fibrefit-map-tile/1";

/// A tile file: one band of rows of the maps, before the residual variance scales its errors.
#[derive(Debug, Serialize, Deserialize)]
pub struct TileFile {
    /// The schema name, `fibrefit-map-tile/1`.
    pub schema: String,
    /// [I, N]: tile I of N.
    pub tile: [u32; 2],
    /// SHA-256 of the globals file (`fit --map-globals`) the tile was fitted with.
    pub globals_sha256: String,
    /// SHA-256 of the capture TOML.
    pub capture_sha256: String,
    /// Width of the capture, pixels.
    pub width: usize,
    /// Height of the capture, pixels.
    pub height: usize,
    /// Channels: 1 (grey) or 3 (RGB).
    pub channels: usize,
    /// The maps requested (the config's `[maps]`).
    pub maps: Vec<String>,
    /// Smoothness of the maps' prior (0: none).
    pub smoothness: f64,
    /// Free global parameters (they count in the residual variance's degrees of freedom).
    pub global_free: usize,
    /// The band's fitted texels, before scaling by the residual variance.
    pub part: TexelPart,
}

/// Rows [first, last) of tile `i` of `n` for a capture of `height` rows.
pub fn tile_rows(i: u32, n: u32, height: usize) -> (u32, u32) {
    let h = height as u64;
    (
        (i as u64 * h / n as u64) as u32,
        ((i as u64 + 1) * h / n as u64) as u32,
    )
}

/// One tile to fit.
#[derive(Clone, Debug)]
pub struct TileRequest {
    /// The capture TOML.
    pub data: PathBuf,
    /// The fit's configuration (its `[maps]` request included).
    pub config: FitConfig,
    /// Loading options of the capture.
    pub load: LoadOptions,
    /// The result of `fit --map-globals` that the tiles share.
    pub globals: PathBuf,
    /// Directory of the tile files.
    pub dir: PathBuf,
    /// (I, N): tile I of N, I from 0.
    pub tile: (u32, u32),
    /// Where progress and warnings go.
    pub progress: crate::progress::Progress,
}

/// A written tile.
pub struct TileOutcome {
    /// The tile file written.
    pub file: PathBuf,
    /// Rows [first, last) of the capture.
    pub rows: (u32, u32),
    /// The tile as written.
    pub tile: TileFile,
}

/// Tiles to merge.
#[derive(Clone, Debug)]
pub struct MergeRequest {
    /// Directory holding the tile files.
    pub tiles: PathBuf,
    /// The globals the tiles were fitted with.
    pub globals: PathBuf,
    /// Directory for the maps.
    pub maps: PathBuf,
    /// Result JSON: the globals with the maps block.
    pub out: PathBuf,
}

/// Merged tiles.
pub struct MergeOutcome {
    /// Tiles merged.
    pub tiles: u32,
    /// Warnings of the merge (flagged texels, widened errors).
    pub warnings: Vec<String>,
}

/// Fit tile `req.tile` and write it as `tile_I_of_N.json` into `req.dir`; `inputs`: every file
/// the fit reads (none may be an output). Returns the tile, its file and its rows.
pub fn run_tile(req: &TileRequest, inputs: &[PathBuf]) -> Result<TileOutcome> {
    let (i, n) = req.tile;
    let cfg = &req.config;
    let globals = &req.globals;
    let dir = &req.dir;
    if cfg.model.is_auto() {
        bail!("--tile: name a rung (`model` or --model), not auto");
    }
    maps::check_request(cfg, &cfg.maps)?;
    let (g_text, globals_sha256) = crate::load::input::read_text_hashed(globals, "globals")?;
    let g: serde_json::Value =
        serde_json::from_str(&g_text).map_err(|e| anyhow!("{}: {e}", globals.display()))?;
    if g["maps"]["stage"] != "globals" {
        bail!(
            "{}: not the result of `fibrefit fit --map-globals` (no maps.stage = \"globals\")",
            globals.display()
        );
    }
    if g["model"].as_str() != Some(cfg.model.to_string().as_str()) {
        bail!(
            "{}: globals of model `{}`, but the config fits `{}`",
            globals.display(),
            g["model"].as_str().unwrap_or("?"),
            cfg.model
        );
    }
    let file = dir.join(format!("tile_{i}_of_{n}.json"));
    let mut inputs = inputs.to_vec();
    inputs.push(globals.clone());
    let mut outs = Outputs::new(&inputs);
    outs.dir(dir, "--maps")?;
    let tile_out = outs.file(&file, "--maps")?;
    if !crate::load::is_capture(&req.data) {
        bail!("--tile needs an image capture (a capture TOML)");
    }
    let store = crate::load::capture_store::CaptureStore::load(&req.data, req.load.subsample)?;
    let channels = store.channels;
    let set = crate::export::result_json::result_from_value(
        &g,
        &globals.display().to_string(),
        channels,
    )?
    .set;
    let (w, h) = (store.width, store.height);
    let rows = tile_rows(i, n, h);
    // the global stage's expected residual variance (older globals: none, every minimum kept)
    let hint = g["maps"]["method"]["texel_variance"]
        .as_f64()
        .unwrap_or(f64::INFINITY);
    // the globals' Schur complement (older globals: none, the texel errors conditional on them)
    let schur: Option<maps::GlobalSchur> = match &g["maps"]["method"]["global_schur"] {
        serde_json::Value::Null => None,
        v => Some(
            serde_json::from_value(v.clone())
                .map_err(|e| anyhow!("{}: maps.method.global_schur: {e}", globals.display()))?,
        ),
    };
    let part = maps::texel_stage(
        &maps::TexelStageRequest {
            store: &store,
            cfg,
            req: &cfg.maps,
            set: &set,
            rows,
            variance_hint: hint,
            schur: schur.as_ref(),
        },
        &req.progress,
    )?;
    let global_free = g["statistics"]["free_parameters"].as_u64().unwrap_or(0) as usize;
    let t = TileFile {
        schema: TILE_SCHEMA.into(),
        tile: [i, n],
        globals_sha256,
        capture_sha256: crate::load::sha256_read(&req.data)
            .with_context(|| format!("{}: its loader recorded no hash", req.data.display()))?,
        width: w,
        height: h,
        channels,
        maps: cfg.maps.requested().into_iter().map(String::from).collect(),
        smoothness: cfg.maps.smoothness,
        global_free,
        part,
    };
    serde_json::to_writer(outs.writer(tile_out), &t)?;
    outs.commit()?;
    Ok(TileOutcome {
        file,
        rows,
        tile: t,
    })
}

/// Assemble the tiles in `req.tiles` into the maps (written into `req.maps`) and the result JSON
/// (`req.out`): exactly what a single `fit --maps` run writes.
pub fn merge(req: &MergeRequest) -> Result<MergeOutcome> {
    let args = req;
    let tiles = read_tiles(&args.tiles)?;
    let (g_text, g_sha) = crate::load::input::read_text_hashed(&args.globals, "globals")?;
    let n = check_one_run(&tiles, args, &g_sha)?;
    let first = &tiles[0].1;
    let req = maps_config(first);
    let inputs: Vec<PathBuf> = std::iter::once(args.globals.clone())
        .chain(tiles.iter().map(|t| t.0.clone()))
        .collect();
    let mut outs = Outputs::new(&inputs);
    let json_out = outs.file(&args.out, "--out")?;
    let map_files = MapFiles::reserve(&mut outs, &args.maps, &req.requested())?;
    let mut g: serde_json::Value =
        serde_json::from_str(&g_text).map_err(|e| anyhow!("{}: {e}", args.globals.display()))?;
    let (width, height, channels, global_free) =
        (first.width, first.height, first.channels, first.global_free);
    let set = crate::export::result_json::result_from_value(
        &g,
        &args.globals.display().to_string(),
        channels,
    )?
    .set;
    let h_max =
        crate::model::topology::max_height(set.shape_value(crate::fit::parameters::Param::Spacing));
    let parts: Vec<TexelPart> = tiles.into_iter().map(|t| t.1.part).collect();
    let (maps, variance, warns) = maps::finish_maps(
        parts,
        &maps::Assembly {
            width,
            height,
            channels,
            req: &req,
            global_free,
            h_max,
        },
    )?;
    let method = g["maps"]["method"].clone();
    crate::export::maps_out::write(&mut outs, &map_files, &req.requested(), &maps)?;
    let mut desc = crate::export::maps_out::describe(&args.maps, &req.requested(), &maps);
    desc["method"] = method;
    desc["method"]["residual_variance"] = serde_json::json!(variance);
    desc["method"]["tiles"] = serde_json::json!(n);
    desc["summary"] = serde_json::to_value(maps::summary(&maps, &req, h_max))?;
    desc["sha256"] = serde_json::to_value(map_files.exr_hashes(&mut outs)?)?;
    g["maps"] = desc;
    if let Some(w) = g["warnings"].as_array_mut() {
        w.extend(warns.iter().map(|x| serde_json::json!(x)));
    }
    relocate_paths(&mut g, args);
    serde_json::to_writer_pretty(outs.writer(json_out), &g)?;
    outs.commit()?;
    Ok(MergeOutcome {
        tiles: n,
        warnings: warns,
    })
}

/// The tile files `tile_*.json` in `dir`, each of schema [`TILE_SCHEMA`], by tile index; at
/// least one.
fn read_tiles(dir: &Path) -> Result<Vec<(PathBuf, TileFile)>> {
    let mut tiles: Vec<(PathBuf, TileFile)> = Vec::new();
    let entries = std::fs::read_dir(dir)
        .with_context(|| format!("{}: cannot read the tile directory", dir.display()))?;
    for e in entries {
        let p = e?.path();
        let name = p.file_name().and_then(|n| n.to_str()).unwrap_or("");
        if !(name.starts_with("tile_") && name.ends_with(".json")) {
            continue;
        }
        let t: TileFile = serde_json::from_str(&crate::load::input::read_text(&p)?)
            .map_err(|e| anyhow!("{}: not a tile file: {e}", p.display()))?;
        if t.schema != TILE_SCHEMA {
            bail!(
                "{}: schema `{}` is not {TILE_SCHEMA}",
                p.display(),
                t.schema
            );
        }
        tiles.push((p, t));
    }
    if tiles.is_empty() {
        bail!("{}: no tile_I_of_N.json files", dir.display());
    }
    tiles.sort_by_key(|t| t.1.tile[0]);
    Ok(tiles)
}

/// Check that `tiles` (sorted, at least one) are the whole of one run: fitted with the globals
/// whose SHA-256 is `globals_sha`, the same tile count, capture, maps and settings, each tile
/// once and none missing. Returns the tile count.
fn check_one_run(
    tiles: &[(PathBuf, TileFile)],
    args: &MergeRequest,
    globals_sha: &str,
) -> Result<u32> {
    let first = &tiles[0].1;
    let n = first.tile[1];
    for (p, t) in tiles {
        if t.globals_sha256 != globals_sha {
            bail!(
                "{}: fitted with other globals than {} (sha256 differs)",
                p.display(),
                args.globals.display()
            );
        }
        let same = t.tile[1] == n
            && t.capture_sha256 == first.capture_sha256
            && (t.width, t.height, t.channels) == (first.width, first.height, first.channels)
            && t.maps == first.maps
            && t.smoothness == first.smoothness
            && t.global_free == first.global_free;
        if !same {
            bail!(
                "{}: not a tile of the same run as {} (tile count, capture, maps or settings differ)",
                p.display(),
                tiles[0].0.display()
            );
        }
    }
    let have: Vec<u32> = tiles.iter().map(|t| t.1.tile[0]).collect();
    if let Some(dup) = have.windows(2).find(|w| w[0] == w[1]) {
        bail!("{}: tile {} appears twice", args.tiles.display(), dup[0]);
    }
    if have.len() as u32 != n {
        let missing: Vec<String> = (0..n)
            .filter(|i| !have.contains(i))
            .map(|i| i.to_string())
            .collect();
        bail!(
            "{}: tiles {} of {n} are missing",
            args.tiles.display(),
            missing.join(", ")
        );
    }
    Ok(n)
}

/// The maps request the tiles were fitted with (their maps and smoothness).
fn maps_config(tile: &TileFile) -> crate::fit::config::MapsConfig {
    let req = crate::fit::config::MapsConfig {
        height: tile.maps.iter().any(|m| m == "height"),
        fibre_azimuth: tile.maps.iter().any(|m| m == "fibre_azimuth"),
        kd: tile.maps.iter().any(|m| m == "kd"),
        ks: tile.maps.iter().any(|m| m == "ks"),
        smoothness: tile.smoothness,
        ..Default::default()
    };
    tile.maps.iter().fold(req, |r, m| r.with_lobe_map(m))
}

/// Name the paths in the result `g` relative to its folder (`args.out`'s): the topology map
/// (named relative to the globals' folder in `g`) and the maps directory.
fn relocate_paths(g: &mut serde_json::Value, args: &MergeRequest) {
    let folder = |p: &Path| match p.parent() {
        Some(d) if !d.as_os_str().is_empty() => d.to_path_buf(),
        _ => PathBuf::from("."),
    };
    let out_folder = folder(&args.out);
    if let Some(map) = g["knobs"]["topology_map"].as_str().map(PathBuf::from) {
        let at = match map.is_relative() {
            true => folder(&args.globals).join(map),
            false => map,
        };
        if let Some(rel) = crate::api::fit::relative_to(&at, &out_folder) {
            g["knobs"]["topology_map"] = serde_json::json!(rel.display().to_string());
        }
    }
    if let Some(rel) = crate::api::fit::relative_to(&args.maps, &out_folder) {
        g["maps"]["directory"] = serde_json::json!(rel.display().to_string());
    }
}
