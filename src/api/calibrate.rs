//! `fibrefit calibrate`: photos of a swatch on a printed board become a capture. The photos are
//! decoded to linear values, the board's markers found, the camera's intrinsics and every
//! photo's pose calibrated (`crate::calibrate`), each photo rectified onto the window's texel
//! grid with absolute values from the reference patch, and `capture.toml` written with the
//! pinhole cameras and the flash's point lights in the board frame, so that `fibrefit fit
//! OUT/capture.toml` runs unchanged.

use crate::board::camera::Intrinsics;
use crate::board::detect;
use crate::calibrate::{self, overlay, rectify, Calibration, Corner, Views};
use crate::export::atomic::Outputs;
use crate::load::board::BoardFile;
use crate::load::capture::{Camera, CaptureFile, ImageSpec, Light, Swatch};
use crate::load::photo::Photo;
use crate::progress::Progress;
use anyhow::{anyhow, bail, Context, Result};
use nalgebra::Vector3;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// What `fibrefit calibrate` is asked.
#[derive(Clone, Debug)]
pub struct CalibrateRequest {
    /// `board.toml` (from `fibrefit board`).
    pub board: PathBuf,
    /// The photos (JPEG or PNG, sRGB), one camera.
    pub photos: Vec<PathBuf>,
    /// The flash's position in the camera frame (mm; x right, y down, z along the view).
    pub flash_offset_mm: [f64; 3],
    /// The rectified images' size in texels [width, height].
    pub texels: [usize; 2],
    /// Intrinsics from a previous run's `cam.toml` (held, not calibrated).
    pub intrinsics: Option<PathBuf>,
}

/// What a calibration found and wrote.
#[derive(Clone, Debug)]
pub struct CalibrateOutcome {
    /// The calibration.
    pub calibration: Calibration,
    /// Markers found in each photo.
    pub markers: Vec<usize>,
    /// The capture file written.
    pub capture: PathBuf,
    /// The report (text) also written to `report/report.txt`.
    pub report: String,
}

/// The markers of `photo`, refused when too few for a pose.
fn corners_of(board: &BoardFile, photo: &Photo) -> Result<(Vec<Corner>, usize)> {
    let found = detect::find(&photo.grey8(), photo.width, photo.height)?;
    let found: Vec<_> = found
        .into_iter()
        .filter(|f| board.marker(f.id).is_some())
        .collect();
    if found.is_empty() {
        bail!(
            "{}: no markers of the board found (is the whole board in the picture, sharp and lit?)",
            photo.path.display()
        );
    }
    if found.len() < 2 {
        bail!(
            "{}: only {} marker of the board found; a pose needs at least 2",
            photo.path.display(),
            found.len()
        );
    }
    let mut corners = Vec::new();
    for f in &found {
        let m = board.marker(f.id).expect("filtered");
        for (c, mm) in f.corners.iter().zip(&m.corners_mm) {
            corners.push(Corner {
                board_mm: *mm,
                pixel: *c,
            });
        }
    }
    Ok((corners, found.len()))
}

/// Calibrate the photos of `req` and write the capture into `out`: `capture.toml`,
/// `img_NNN.exr`, `mask.png`, `cam.toml` and `report/` (overlays, `report.txt`); all or
/// nothing.
pub fn calibrate(
    req: &CalibrateRequest,
    out: &Path,
    progress: &Progress,
) -> Result<CalibrateOutcome> {
    if req.photos.is_empty() {
        bail!("no photos given");
    }
    if req.texels[0] < 2 || req.texels[1] < 2 || req.texels[0] * req.texels[1] > 4096 * 4096 {
        bail!(
            "--texels {} {}: expected 2 to 4096 each",
            req.texels[0],
            req.texels[1]
        );
    }
    let board = BoardFile::read(&req.board)?;
    let fixed =
        match &req.intrinsics {
            Some(p) => {
                let text = crate::load::input::read_text_as(p, "intrinsics file")?;
                Some(toml::from_str::<Intrinsics>(&text).with_context(|| {
                    format!("{}: not an intrinsics file (cam.toml)", p.display())
                })?)
            }
            None => None,
        };
    let mut inputs = vec![req.board.clone()];
    inputs.extend(req.photos.iter().cloned());
    inputs.extend(req.intrinsics.iter().cloned());
    let mut outs = Outputs::new(&inputs);
    let dir = outs.dir(out, "--out")?;
    let report_dir = outs.dir(&dir.join("report"), "--out")?;
    let n = req.photos.len();
    let capture_id = outs.file(&dir.join("capture.toml"), "--out")?;
    let mask_id = outs.file(&dir.join("mask.png"), "--out")?;
    let cam_id = outs.file(&dir.join("cam.toml"), "--out")?;
    let report_id = outs.file(&report_dir.join("report.txt"), "--out")?;
    let img_ids = (0..n)
        .map(|k| outs.file(&dir.join(format!("img_{k:03}.exr")), "--out"))
        .collect::<Result<Vec<_>>>()?;
    let overlay_ids = (0..n)
        .map(|k| outs.file(&report_dir.join(format!("overlay_{k:03}.png")), "--out"))
        .collect::<Result<Vec<_>>>()?;

    // decode and find the markers, every photo of one size
    let mut photos: Vec<Photo> = Vec::new();
    let (mut corners, mut markers) = (Vec::new(), Vec::new());
    for path in &req.photos {
        let photo = Photo::read(path)?;
        if let Some(first) = photos.first() {
            if (photo.width, photo.height) != (first.width, first.height) {
                bail!(
                    "{}: {}x{} pixels, but {} is {}x{}: one set of intrinsics needs photos of one size (one camera, one zoom)",
                    path.display(),
                    photo.width,
                    photo.height,
                    first.path.display(),
                    first.width,
                    first.height
                );
            }
        }
        let (c, m) = corners_of(&board, &photo)?;
        corners.push(c);
        markers.push(m);
        photos.push(photo);
    }
    let size_px = [photos[0].width as u32, photos[0].height as u32];
    if let Some(k) = &fixed {
        if k.size_px != size_px {
            bail!(
                "--intrinsics: calibrated for {}x{} photos, these are {}x{}",
                k.size_px[0],
                k.size_px[1],
                size_px[0],
                size_px[1]
            );
        }
    }
    progress.line(&format!("{n} photos: markers found {markers:?}"));
    let views = Views { size_px, corners };
    let cal = calibrate::calibrate(&views, fixed.as_ref())
        .map_err(|e| anyhow!("calibrating {n} photos: {e:#}"))?;
    let offset = Vector3::from(req.flash_offset_mm);
    let lights: Vec<Vector3<f64>> = cal
        .poses
        .iter()
        .map(|p| p.position + p.to_board_direction(&offset))
        .collect();
    let rect = rectify::rectify(&board, &cal, &photos, &lights, req.texels)?;

    // write
    let w = board.window_mm;
    let mut images = Vec::new();
    for k in 0..n {
        let name = format!("img_{k:03}.exr");
        images.push(ImageSpec {
            file: Some(PathBuf::from(&name)),
            bracket: vec![],
            encoding: None,
            exposure: 1.0,
            saturation: None,
            light: Light::Point {
                position_mm: lights[k].into(),
                intensity: 1.0,
            },
            camera: Camera::Pinhole {
                position_mm: cal.poses[k].position.into(),
            },
        });
        let (file, name) = outs.file_and_name(img_ids[k]);
        crate::export::images::write_exr_into(
            file,
            name,
            req.texels[0],
            req.texels[1],
            3,
            &rect.images[k],
        )?;
        let pic = overlay::overlay(&board, &cal, k, &photos[k], &corner_pixels(&views, k));
        outs.put(
            overlay_ids[k],
            &png_bytes(image::DynamicImage::ImageRgb8(pic))?,
        )?;
    }
    let capture = CaptureFile {
        swatch: Swatch {
            size_mm: [w[2] - w[0], w[3] - w[1]],
            roi: None,
            mask: Some(PathBuf::from("mask.png")),
            fibre_azimuth_deg: None,
            tangent_map: None,
            topology_map: None,
            height_map: None,
            fibre_azimuth_map: None,
        },
        images,
    };
    let text = format!(
        "# written by fibrefit calibrate from {n} photos of {} (board frame = swatch frame, mm)\n{}",
        req.board.display(),
        toml::to_string(&capture).context("capture.toml")?
    );
    outs.put(capture_id, text.as_bytes())?;
    let mask = image::GrayImage::from_raw(
        req.texels[0] as u32,
        req.texels[1] as u32,
        rect.mask.clone(),
    )
    .expect("texels");
    outs.put(mask_id, &png_bytes(image::DynamicImage::ImageLuma8(mask))?)?;
    let cam = format!(
        "# fibrefit calibrate's intrinsics: reuse with --intrinsics (same camera, zoom, focus)\n{}",
        toml::to_string(&cal.intrinsics).context("cam.toml")?
    );
    outs.put(cam_id, cam.as_bytes())?;
    let report = report_text(&req.photos, &cal, &markers, &rect);
    outs.put(report_id, report.as_bytes())?;
    outs.commit()?;
    Ok(CalibrateOutcome {
        calibration: cal,
        markers,
        capture: dir.join("capture.toml"),
        report,
    })
}

/// Photo `k`'s detected corners (px).
fn corner_pixels(views: &Views, k: usize) -> Vec<[f64; 2]> {
    views.corners[k].iter().map(|c| c.pixel).collect()
}

fn png_bytes(img: image::DynamicImage) -> Result<Vec<u8>> {
    let mut bytes = Vec::new();
    img.write_with_encoder(image::codecs::png::PngEncoder::new(&mut bytes))
        .map_err(|e| anyhow!("PNG: {e}"))?;
    Ok(bytes)
}

/// The report: intrinsics, per photo markers, RMS, position and its standard error, scale.
fn report_text(
    photos: &[PathBuf],
    cal: &Calibration,
    markers: &[usize],
    rect: &rectify::Rectified,
) -> String {
    let k = &cal.intrinsics;
    let mut s = String::new();
    let _ = writeln!(
        s,
        "intrinsics: {}x{} px, focal {:.2} px, principal point ({:.2}, {:.2}) px, k1 {:.5}, k2 {:.5}",
        k.size_px[0], k.size_px[1], k.focal_px, k.principal_px[0], k.principal_px[1], k.k[0], k.k[1]
    );
    let _ = writeln!(
        s,
        "note: 8-bit photos are decoded as sRGB; a phone's JPEG tone curve is not exactly sRGB (RAW is better, and not read yet)"
    );
    let _ = writeln!(s, "photo\tmarkers\trms_px\tx_mm\ty_mm\tz_mm\tse_x_mm\tse_y_mm\tse_z_mm\tscale_r\tscale_g\tscale_b\tseen");
    for (i, p) in photos.iter().enumerate() {
        let (c, se, sc) = (cal.poses[i].position, cal.position_se_mm[i], rect.scale[i]);
        let _ = writeln!(
            s,
            "{}\t{}\t{:.3}\t{:.2}\t{:.2}\t{:.2}\t{:.3}\t{:.3}\t{:.3}\t{:.4}\t{:.4}\t{:.4}\t{:.2}",
            p.display(),
            markers[i],
            cal.rms_px[i],
            c.x,
            c.y,
            c.z,
            se[0],
            se[1],
            se[2],
            sc[0],
            sc[1],
            sc[2],
            rect.seen[i]
        );
    }
    let masked = rect.mask.iter().filter(|&&m| m == 0).count();
    let _ = writeln!(
        s,
        "mask: {masked} of {} texels left out (out of frame, too oblique, clipped or at the window's edge in some photo)",
        rect.mask.len()
    );
    s
}
