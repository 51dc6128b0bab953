//! `fibrefit board`: a printable calibration board ([`crate::api::board`]).

use anyhow::Result;
use clap::Args;
use std::path::PathBuf;

#[derive(Debug, Args)]
#[command(after_help = "\
Writes DIR/board.png and DIR/board.pdf (the same picture, the page its printed size: print
either at 100 % / actual size, no scaling, and check the 100 mm scale bar with a ruler) and
DIR/board.toml: in mm in the board frame (origin at the window's centre, x right, y up
the page, z out of the paper), the paper's and the window's rectangles, every tag36h11 marker's
id and corners, the reference patch (rectangle and linear reflectance: edit it after measuring
the print) and the scale bar. Lay the swatch in the window; `fibrefit calibrate` reads the
photos. docs/guide/photograph.md")]
pub struct BoardArgs {
    /// Output folder (created if missing)
    #[arg(long, value_name = "DIR")]
    pub out: PathBuf,
    /// Paper: a4, letter or a3
    #[arg(long, default_value = "a4", value_name = "PAPER")]
    pub paper: String,
    /// The window's side in mm (square)
    #[arg(long, default_value_t = 60.0, value_name = "W")]
    pub window_mm: f64,
    /// Resolution of board.png (pixels per inch)
    #[arg(long, default_value_t = 300, value_name = "N")]
    pub dpi: u32,
    /// The reference patch's linear reflectance (printed as its sRGB grey)
    #[arg(long, default_value_t = 0.5, value_name = "R")]
    pub patch_reflectance: f64,
    /// No summary line
    #[arg(long, short)]
    pub quiet: bool,
}

pub fn run(args: &BoardArgs) -> Result<()> {
    let req = crate::api::board::BoardRequest {
        paper: args.paper.clone(),
        window_mm: args.window_mm,
        dpi: args.dpi,
        patch_reflectance: args.patch_reflectance,
    };
    let outcome = crate::api::board::board(&req, &args.out)?;
    if !args.quiet {
        let w = outcome.window_mm;
        eprintln!(
            "wrote {} ({} markers, window {:.1} x {:.1} mm): print board.pdf or board.png at 100 %",
            outcome
                .files
                .iter()
                .map(|p| p.display().to_string())
                .collect::<Vec<_>>()
                .join(", "),
            outcome.markers,
            w[2] - w[0],
            w[3] - w[1]
        );
    }
    Ok(())
}
