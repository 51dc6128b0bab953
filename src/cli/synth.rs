//! `fibrefit synth`: render synthetic measurements from known parameters.

use anyhow::Result;
use clap::Args;
use std::path::PathBuf;

#[derive(Debug, Args)]
#[command(after_help = "\
Writes into OUT (a new or empty folder, or one synth wrote before; its own files are kept): gonio.csv (if [gonio]), capture.toml + img_NNN.exr|png (if [capture]),
topology.png / tangent.png when used, truth.json (the true parameters; usable as
`fibrefit eval --params OUT/truth.json`) and synth_info.json (noise, seeds, files).
The config format is documented in docs/formats.md (\"Synth config\"); examples: configs/synth_*.toml.")]
pub struct SynthArgs {
    /// Synthesis config (TOML)
    #[arg(long, value_name = "FILE")]
    pub config: PathBuf,
    /// Output directory (created if missing)
    #[arg(long, value_name = "DIR")]
    pub out: PathBuf,
    /// Write into a folder synth did not make (no synth_info.json), over files it did not write
    #[arg(long)]
    pub force: bool,
    /// No progress bar or warnings
    #[arg(long, short)]
    pub quiet: bool,
}

pub fn run(args: &SynthArgs) -> Result<()> {
    let info = crate::synth::write_set(
        &args.config,
        &args.out,
        &crate::progress::Progress::new(args.quiet),
        args.force,
    )?;
    if !args.quiet {
        eprintln!(
            "wrote {} ({} gonio rows, {} images) to {}",
            info.files.join(", "),
            info.gonio_rows,
            info.images,
            args.out.display()
        );
    }
    Ok(())
}
