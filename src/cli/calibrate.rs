//! `fibrefit calibrate`: photos of a swatch on the printed board become a capture
//! ([`crate::api::calibrate`]).

use anyhow::{bail, Result};
use clap::Args;
use crate::load::image_io::Encoding;
use std::path::PathBuf;

#[derive(Debug, Args)]
#[command(after_help = "\
Writes into DIR: capture.toml (pinhole cameras and the lights as point lights in the board
frame, mm; `fibrefit fit DIR/capture.toml` runs on it unchanged), img_NNN.exr (each photo
rectified onto the window's texel grid, linear, absolute from the reference patch; NaN where
that photo does not see a texel well: out of frame, too oblique, clipped), mask.png (texels some
photo sees well), cam.toml (the intrinsics: reuse with --intrinsics) and report/ (report.txt:
intrinsics, per photo markers, reprojection RMS, camera position and its standard error, the
patch's light x exposure, the light; overlay_NNN.png: detected corners green, reprojected red,
window blue). Photos: camera RAW (DNG, CR2, CR3, NEF, ARW, RAF, RW2, ORF, PEF, SRW: linear, best),
JPEG (sRGB), PNG or TIFF (8/16-bit, --encoding), one camera and zoom, the whole board in each.
The camera's noise is estimated from the board's flat stretches (each image's `noise` in
capture.toml: the fit's sigmas); with EXIF exposures the patch is pooled over the photos of one
light (`scale_rel_se`: the albedos' standard errors include it). The flash lights every photo unless --lights says a lamp at a measured
position did, and gives ambient frames (same pose, light off) to subtract:

  lamp_mm = [150, -100, 400]          # optional: photos not listed are lit by this lamp (mm)
  [[photo]]
  file = \"IMG_0003.jpg\"               # one of the photos
  lamp_mm = [0, 200, 300]             # or flash = true
  ambient = \"IMG_0003_off.jpg\"        # optional, relative to the lights file

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
    /// The rectified images' size in texels [default: 128 128]
    #[arg(long, num_args = 2, value_names = ["W", "H"], conflicts_with = "px_per_mm")]
    pub texels: Option<Vec<usize>>,
    /// Texels per millimetre of the window instead of --texels (the grid is the window's size
    /// in mm times it)
    #[arg(long, value_name = "N")]
    pub px_per_mm: Option<f64>,
    /// Which photos a lamp lit (its position in the board frame, mm) and their ambient frames:
    /// a TOML file (below); without it the flash lit every photo
    #[arg(long, value_name = "FILE")]
    pub lights: Option<PathBuf>,
    /// How PNG and TIFF photos' code values relate to light: srgb, or linear (a raw
    /// converter's linear 16-bit TIFF); JPEGs are sRGB, RAW files linear
    #[arg(long, value_name = "ENC", default_value = "srgb", value_parser = ["srgb", "linear"])]
    pub encoding: String,
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
    let texels = args.texels.as_deref().unwrap_or(&[128, 128]);
    let req = crate::api::calibrate::CalibrateRequest {
        flash_offset_mm: flash_offset(&args.flash_offset_mm)?,
        texels: [texels[0], texels[1]],
        px_per_mm: args.px_per_mm,
        intrinsics: args.intrinsics.clone(),
        lights: args.lights.clone(),
        encoding: match args.encoding.as_str() {
            "linear" => Encoding::Linear,
            _ => Encoding::Srgb,
        },
        ..crate::api::calibrate::CalibrateRequest::new(args.board.clone(), args.photos.clone())
    };
    let progress = crate::progress::Progress::new(args.quiet);
    let outcome = crate::api::calibrate::calibrate(&req, &args.out, &progress)?;
    if !args.quiet {
        eprint!("{}", outcome.report);
        eprintln!("wrote {}", outcome.capture.display());
    }
    Ok(())
}
