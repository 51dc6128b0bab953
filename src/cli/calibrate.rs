//! `fibrefit calibrate`: photos of a swatch on the printed board become a capture
//! ([`crate::api::calibrate`]).

use anyhow::{bail, Result};
use clap::Args;
use std::path::PathBuf;

#[derive(Debug, Args)]
#[command(after_help = "\
Writes into DIR: capture.toml (pinhole cameras and the flash's point lights in the board frame,
mm; `fibrefit fit DIR/capture.toml` runs on it unchanged), img_NNN.exr (each photo rectified
onto the window's texel grid, linear, absolute from the reference patch), mask.png (texels every
photo sees well), cam.toml (the intrinsics: reuse with --intrinsics) and report/ (report.txt:
intrinsics, per photo markers, reprojection RMS, camera position and its standard error, the
patch's light x exposure; overlay_NNN.png: detected corners green, reprojected red, window
blue). Photos: JPEG or PNG (sRGB), one camera and zoom, the whole board in each, flash on.
Nothing is written when a photo is refused. docs/guide/photograph.md")]
pub struct CalibrateArgs {
    /// The board's description (board.toml from `fibrefit board`)
    #[arg(long, value_name = "FILE")]
    pub board: PathBuf,
    /// Output folder (created if missing)
    #[arg(long, value_name = "DIR")]
    pub out: PathBuf,
    /// The flash's position in the camera frame, mm (x right, y down, z along the view)
    #[arg(long, default_value = "10,0,0", value_name = "X,Y,Z")]
    pub flash_offset_mm: String,
    /// The rectified images' size in texels
    #[arg(long, num_args = 2, value_names = ["W", "H"], default_values = ["128", "128"])]
    pub texels: Vec<usize>,
    /// Intrinsics from a previous run (cam.toml): held, not calibrated
    #[arg(long, value_name = "FILE")]
    pub intrinsics: Option<PathBuf>,
    /// The photos
    #[arg(value_name = "PHOTO", required = true)]
    pub photos: Vec<PathBuf>,
    /// No progress lines
    #[arg(long, short)]
    pub quiet: bool,
}

fn flash_offset(text: &str) -> Result<[f64; 3]> {
    let v: Vec<f64> = text
        .split(',')
        .map(|s| s.trim().parse::<f64>())
        .collect::<Result<_, _>>()
        .map_err(|_| anyhow::anyhow!("--flash-offset-mm {text}: expected X,Y,Z in mm"))?;
    match v[..] {
        [x, y, z] if v.iter().all(|c| c.is_finite() && c.abs() < 1000.0) => Ok([x, y, z]),
        _ => bail!("--flash-offset-mm {text}: expected X,Y,Z in mm (each under 1 m)"),
    }
}

pub fn run(args: &CalibrateArgs) -> Result<()> {
    let req = crate::api::calibrate::CalibrateRequest {
        board: args.board.clone(),
        photos: args.photos.clone(),
        flash_offset_mm: flash_offset(&args.flash_offset_mm)?,
        texels: [args.texels[0], args.texels[1]],
        intrinsics: args.intrinsics.clone(),
    };
    let progress = crate::progress::Progress::new(args.quiet);
    let outcome = crate::api::calibrate::calibrate(&req, &args.out, &progress)?;
    if !args.quiet {
        eprint!("{}", outcome.report);
        eprintln!("wrote {}", outcome.capture.display());
    }
    Ok(())
}
