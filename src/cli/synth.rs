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
    #[arg(long, value_name = "FILE", required_unless_present = "photos")]
    pub config: Option<PathBuf>,
    /// Photos of a printed board (`fibrefit board`) with a swatch of --params in its window
    /// instead: OUT/photo_NNN.jpg or .dng (1600x1200, f 1000 px, k1 -0.08, k2 0.02, 300 mm
    /// away at 20-60 degrees all around, a flash 10 mm beside the lens, camera noise:
    /// variance 0.002^2 + 3e-5 x linear value) and OUT/truth.json
    #[arg(long, requires_all = ["board", "params"], conflicts_with = "config")]
    pub photos: bool,
    /// With --photos: the board (board.toml; board.png beside it)
    #[arg(long, value_name = "FILE")]
    pub board: Option<PathBuf>,
    /// With --photos: the swatch's parameters (TOML, JSON or a fitted result)
    #[arg(long, value_name = "FILE")]
    pub params: Option<PathBuf>,
    /// With --photos: the rung [default: the parameter file's `model`]
    #[arg(long, value_name = "ID")]
    pub model: Option<String>,
    /// With --photos: how many photos
    #[arg(long, default_value_t = 8, value_name = "N")]
    pub count: usize,
    /// With --photos: the noise's seed
    #[arg(long, default_value_t = 0, value_name = "SEED")]
    pub seed: u64,
    /// With --photos: jpeg (8-bit sRGB, as a phone's camera app writes) or dng (a Bayer
    /// mosaic with black and white levels, as a camera's RAW mode writes)
    #[arg(long, default_value = "jpeg", value_name = "FORMAT", value_parser = ["jpeg", "dng"])]
    pub format: String,
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
    let progress = crate::progress::Progress::new(args.quiet);
    let (Some(config), false) = (&args.config, args.photos) else {
        let req = crate::synth::photo::PhotoSetRequest {
            board: args.board.clone().expect("clap: --photos requires --board"),
            params: args.params.clone().expect("clap: --photos requires --params"),
            model: args.model.clone(),
            count: args.count,
            seed: args.seed,
            format: match args.format.as_str() {
                "dng" => crate::synth::photo::PhotoFormat::Dng,
                _ => crate::synth::photo::PhotoFormat::Jpeg,
            },
        };
        let files = crate::synth::photo::write_photo_set(&req, &args.out, &progress)?;
        if !args.quiet {
            eprintln!("wrote {} photos and truth.json to {}", files.len() - 1, args.out.display());
        }
        return Ok(());
    };
    let info = crate::synth::write_set(
        config,
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
