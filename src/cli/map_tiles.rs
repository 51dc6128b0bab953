//! Map recovery past one machine: `fit --tile I/N --globals G.json --maps TILES` fits the texels
//! of one band of rows given the globals of `fit --map-globals`, and `fibrefit merge-maps`
//! assembles the bands into the same maps (bit for bit) as a single `fit --maps` run.

use super::fit::FitArgs;
use crate::export::atomic::Outputs;
use crate::export::maps_out::MapFiles;
use crate::fit::config::FitConfig;
use crate::fit::maps::{self, TexelPart};
use anyhow::{anyhow, bail, Context, Result};
use clap::Args;
use serde::{Deserialize, Serialize};
use std::path::PathBuf;

/// Schema of a tile file.
pub const TILE_SCHEMA: &str = "fibrefit-map-tile/1";

/// A tile file: one band of rows of the maps, before the residual variance scales its errors.
#[derive(Debug, Serialize, Deserialize)]
pub struct TileFile {
    pub schema: String,
    /// [I, N]: tile I of N.
    pub tile: [u32; 2],
    /// SHA-256 of the globals file (`fit --map-globals`) the tile was fitted with.
    pub globals_sha256: String,
    /// SHA-256 of the capture TOML.
    pub capture_sha256: String,
    pub width: usize,
    pub height: usize,
    pub channels: usize,
    /// The maps requested (the config's [maps]).
    pub maps: Vec<String>,
    pub smoothness: f64,
    /// Free global parameters (they count in the residual variance's degrees of freedom).
    pub global_free: usize,
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

fn parse_tile(text: &str) -> Result<(u32, u32)> {
    let bad = || anyhow!("--tile {text}: expected I/N with 0 <= I < N (e.g. 3/16)");
    let (i, n) = text.split_once('/').ok_or_else(bad)?;
    let (i, n): (u32, u32) = (
        i.trim().parse().map_err(|_| bad())?,
        n.trim().parse().map_err(|_| bad())?,
    );
    if n == 0 || i >= n {
        return Err(bad());
    }
    Ok((i, n))
}

/// The `method` block of a result's `maps`.
pub fn method(cfg: &FitConfig, costs: &[f64], texel_variance: f64) -> serde_json::Value {
    serde_json::json!({
        "texel_variance": texel_variance,
        "global_stage_rounds": costs.len().saturating_sub(1),
        "global_stage_cost_per_round": costs,
        "global_texels": cfg.maps.global_texels,
        "smoothness": cfg.maps.smoothness,
        "prior_sweeps": if cfg.maps.smoothness > 0.0 { maps::PRIOR_SWEEPS } else { 0 },
    })
}

/// `fit --tile I/N --globals G.json --maps TILES`.
pub fn run_tile(args: &FitArgs, cfg: FitConfig, tile: &str, inputs: &[PathBuf]) -> Result<()> {
    let (i, n) = parse_tile(tile)?;
    let globals = args
        .globals
        .as_ref()
        .expect("clap: --tile requires --globals");
    let dir = args.maps.as_ref().expect("clap: --tile requires --maps");
    if cfg.model == "auto" {
        bail!("--tile: name a rung (`model` or --model), not auto");
    }
    maps::check_request(&cfg, &cfg.maps)?;
    let (g_text, globals_sha256) = crate::load::input::read_text_hashed(globals, "globals")?;
    let g: serde_json::Value =
        serde_json::from_str(&g_text).map_err(|e| anyhow!("{}: {e}", globals.display()))?;
    if g["maps"]["stage"] != "globals" {
        bail!(
            "{}: not the result of `fibrefit fit --map-globals` (no maps.stage = \"globals\")",
            globals.display()
        );
    }
    if g["model"].as_str() != Some(cfg.model.as_str()) {
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
    let opts = args
        .load
        .options_with(cfg.knobs.stride, cfg.knobs.fraction)?;
    if !crate::load::is_capture(&args.data) {
        bail!("--tile needs an image capture (a capture TOML)");
    }
    let store = crate::load::capture_store::CaptureStore::load(&args.data, opts.subsample)?;
    let channels = store.channels;
    let set =
        crate::fit::score::result_from_value(&g, &globals.display().to_string(), channels)?.set;
    let (w, h) = (store.width, store.height);
    let rows = tile_rows(i, n, h);
    // the global stage's expected residual variance (older globals: none, every minimum kept)
    let hint = g["maps"]["method"]["texel_variance"]
        .as_f64()
        .unwrap_or(f64::INFINITY);
    let part = maps::texel_stage(&store, &cfg, &cfg.maps, &set, rows, hint, args.quiet)?;
    let global_free = g["statistics"]["free_parameters"].as_u64().unwrap_or(0) as usize;
    let t = TileFile {
        schema: TILE_SCHEMA.into(),
        tile: [i, n],
        globals_sha256,
        capture_sha256: crate::load::sha256_read(&args.data)
            .with_context(|| format!("{}: its loader recorded no hash", args.data.display()))?,
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
    if !args.quiet {
        eprintln!(
            "wrote {} (rows {}..{}, {} texels)",
            file.display(),
            rows.0,
            rows.1,
            t.part.texels.len()
        );
    }
    Ok(())
}

#[derive(Debug, Args)]
#[command(after_help = "\
Reads every TILES/tile_I_of_N.json that `fibrefit fit CAPTURE --config C --globals G.json
--tile I/N --maps TILES` wrote, checks that they are all N tiles of one capture fitted with the
same globals, and writes the maps into DIR and the result JSON (G.json with the maps block)
to --out, exactly as a single `fit --maps DIR` run would. Nothing is written if a tile is
missing, duplicated or from other globals. A Slurm job array runs the tiles: README, \"Per-texel
maps past one machine\".")]
pub struct MergeMapsArgs {
    /// Directory holding the tile files
    pub tiles: PathBuf,
    /// The globals the tiles were fitted with (`fit --map-globals --out G.json`)
    #[arg(long, value_name = "FILE")]
    pub globals: PathBuf,
    /// Directory for the maps (EXR)
    #[arg(long, value_name = "DIR")]
    pub maps: PathBuf,
    /// Result JSON: the globals with the maps block
    #[arg(long, value_name = "FILE")]
    pub out: PathBuf,
    #[arg(long, short)]
    pub quiet: bool,
}

pub fn run_merge(args: &MergeMapsArgs) -> Result<()> {
    let mut tiles: Vec<(PathBuf, TileFile)> = Vec::new();
    let entries = std::fs::read_dir(&args.tiles)
        .with_context(|| format!("{}: cannot read the tile directory", args.tiles.display()))?;
    for e in entries {
        let p = e?.path();
        let name = p.file_name().and_then(|n| n.to_str()).unwrap_or("");
        if !(name.starts_with("tile_") && name.ends_with(".json")) {
            continue;
        }
        let t: TileFile = serde_json::from_str(
            &crate::load::input::read_text(&p)?,
        )
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
        bail!("{}: no tile_I_of_N.json files", args.tiles.display());
    }
    tiles.sort_by_key(|t| t.1.tile[0]);
    let (g_text, g_sha) = crate::load::input::read_text_hashed(&args.globals, "globals")?;
    let first = &tiles[0].1;
    let n = first.tile[1];
    for (p, t) in &tiles {
        if t.globals_sha256 != g_sha {
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
    let req = crate::fit::config::MapsConfig {
        height: first.maps.iter().any(|m| m == "height"),
        fibre_azimuth: first.maps.iter().any(|m| m == "fibre_azimuth"),
        kd: first.maps.iter().any(|m| m == "kd"),
        ks: first.maps.iter().any(|m| m == "ks"),
        smoothness: first.smoothness,
        ..Default::default()
    };
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
    let set =
        crate::fit::score::result_from_value(&g, &args.globals.display().to_string(), channels)?
            .set;
    let h_max =
        crate::model::topology::max_height(set.shape_value(crate::fit::parameters::Shape::Spacing));
    let parts: Vec<TexelPart> = tiles.into_iter().map(|t| t.1.part).collect();
    let (maps, variance, warns) =
        maps::finish_maps(parts, width, height, channels, &req, global_free, h_max)?;
    let method = g["maps"]["method"].clone();
    let mut desc = crate::export::maps_out::write(&mut outs, &map_files, &req.requested(), &maps)?;
    desc["method"] = method;
    desc["method"]["residual_variance"] = serde_json::json!(variance);
    desc["method"]["tiles"] = serde_json::json!(n);
    g["maps"] = desc;
    if let Some(w) = g["warnings"].as_array_mut() {
        w.extend(warns.iter().map(|x| serde_json::json!(x)));
    }
    serde_json::to_writer_pretty(outs.writer(json_out), &g)?;
    outs.commit()?;
    if !args.quiet {
        eprintln!(
            "merged {n} tiles: wrote {} and {}",
            args.maps.display(),
            args.out.display()
        );
        for w in warns {
            eprintln!("warning: {w}");
        }
    }
    Ok(())
}
