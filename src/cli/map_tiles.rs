//! `fibrefit merge-maps`: the command line of [`crate::api::tiles::merge`] (the tiles come from
//! `fit --tile`, in `cli/fit.rs`).

use crate::api::tiles::{self, MergeRequest};
use anyhow::Result;
use clap::Args;
use std::path::PathBuf;

#[derive(Debug, Args)]
#[command(after_help = "\
Reads every TILES/tile_I_of_N.json that `fibrefit fit CAPTURE --config C --globals G.json
--tile I/N --maps TILES` wrote, checks that they are all N tiles of one capture fitted with the
same globals, and writes the maps into DIR and the result JSON (G.json with the maps block)
to --out, exactly as a single `fit --maps DIR` run would. Nothing is written if a tile is
missing, duplicated or from other globals. A Slurm job array runs the tiles: docs/guide/fit.md, \"Per-texel
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
    /// No messages on stderr: neither the summary of what was written nor the warnings
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
