//! `fit --tile I/N --globals G.json --maps TILES` and `fibrefit merge-maps`: the command line
//! of [`crate::api::tiles`].

use crate::api::tiles::{self, MergeRequest, TileRequest};
use anyhow::{anyhow, Result};
use clap::Args;
use std::path::PathBuf;

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

/// `fit --tile I/N`: the tile request of `args` (a fit's arguments, `req` their fit request).
pub fn run_tile(
    args: &super::fit::FitArgs,
    req: crate::api::fit::FitRequest,
    tile: &str,
    inputs: &[PathBuf],
) -> Result<()> {
    let tile = parse_tile(tile)?;
    let t = tiles::run_tile(
        &TileRequest {
            data: req.data,
            config: req.config,
            load: req.load,
            globals: args.globals.clone().expect("clap: --tile requires --globals"),
            dir: args.maps.clone().expect("clap: --tile requires --maps"),
            tile,
            progress: req.progress,
        },
        inputs,
    )?;
    if !args.quiet {
        eprintln!(
            "wrote {} (rows {}..{}, {} texels)",
            t.file.display(),
            t.rows.0,
            t.rows.1,
            t.tile.part.texels.len()
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
    let m = tiles::merge(&MergeRequest {
        tiles: args.tiles.clone(),
        globals: args.globals.clone(),
        maps: args.maps.clone(),
        out: args.out.clone(),
    })?;
    if !args.quiet {
        eprintln!(
            "merged {} tiles: wrote {} and {}",
            m.tiles,
            args.maps.display(),
            args.out.display()
        );
        for w in m.warnings {
            eprintln!("warning: {w}");
        }
    }
    Ok(())
}
