//! `fibrefit calibrate`: photos of a swatch on a printed board become a capture. The photos are
//! decoded to linear values, the board's markers found, the camera's intrinsics and every
//! photo's pose calibrated (`crate::calibrate`), each photo rectified onto the window's texel
//! grid with absolute values from the reference patch, and `capture.toml` written with the
//! pinhole cameras and the point lights (the flash, or lamps from `--lights`) in the board
//! frame, so that `fibrefit fit OUT/capture.toml` runs unchanged.

use crate::board::camera::Intrinsics;
use crate::board::detect;
use crate::calibrate::{self, blur, coverage, noise, overlay, rectify, Calibration, Corner, Views};
use crate::export::atomic::{OutputId, Outputs};
use crate::load::board::BoardFile;
use crate::load::capture::{Camera, CaptureFile, ImageSpec, Light, NoiseSpec, Swatch};
pub use crate::load::image_io::Encoding;
use crate::load::photo::{Photo, PhotoInfo};
use crate::load::photo_lights::{PhotoLight, PhotoLights};
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
    /// The photos (JPEG, PNG or TIFF), one camera.
    pub photos: Vec<PathBuf>,
    /// The flash's position in the camera frame (mm; x right, y down, z along the view).
    pub flash_offset_mm: [f64; 3],
    /// The rectified images' size in texels [width, height] (unless `px_per_mm`).
    pub texels: [usize; 2],
    /// Texels per millimetre of the window instead of `texels`: the grid is the window's size
    /// times it, rounded.
    pub px_per_mm: Option<f64>,
    /// Intrinsics from a previous run's `cam.toml` (held, not calibrated).
    pub intrinsics: Option<PathBuf>,
    /// The lights file (which photos a lamp lit, ambient frames: `crate::load::photo_lights`); without it
    /// the flash lit every photo.
    pub lights: Option<PathBuf>,
    /// How PNG and TIFF photos' code values relate to light (JPEGs are sRGB).
    pub encoding: Encoding,
}

impl CalibrateRequest {
    /// The request with its defaults: the flash 10 mm beside the lens, 128 x 128 texels, sRGB.
    pub fn new(board: PathBuf, photos: Vec<PathBuf>) -> Self {
        Self {
            board,
            photos,
            flash_offset_mm: [10.0, 0.0, 0.0],
            texels: [128, 128],
            px_per_mm: None,
            intrinsics: None,
            lights: None,
            encoding: Encoding::Srgb,
        }
    }
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
    /// The camera's noise estimated from the board's flat stretches (photo value units); None
    /// when the photos show too little of them.
    pub noise: Option<noise::CameraNoise>,
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
    let board = BoardFile::read(&req.board)?;
    let texels = texel_grid(req, &board)?;
    let fixed = read_intrinsics(req)?;
    let lights = match &req.lights {
        Some(p) => PhotoLights::read(p, &req.photos)?,
        None => PhotoLights::flash(req.photos.len()),
    };
    let mut inputs = vec![req.board.clone()];
    inputs.extend(req.photos.iter().cloned());
    inputs.extend(req.intrinsics.iter().cloned());
    inputs.extend(req.lights.iter().cloned());
    inputs.extend(lights.ambient.iter().flatten().cloned());
    let mut outs = Outputs::new(&inputs);
    let n = req.photos.len();
    let t = Targets::reserve(&mut outs, out, n)?;

    let (photos, corners, markers) = read_photos(&board, req, &lights)?;
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
    let lights_file = lights;
    let kinds = lights_file.light.clone();
    let lights: Vec<Vector3<f64>> = cal
        .poses
        .iter()
        .zip(&kinds)
        .map(|(p, l)| match l {
            PhotoLight::Flash => p.position + p.to_board_direction(&offset),
            PhotoLight::Lamp(at) => Vector3::from(*at),
        })
        .collect();
    // each photo decoded again: its overlay, its patch's reading, the board's flat stretches
    // (the camera's noise)
    let mut flat = noise::FlatBlocks::default();
    let w = board.window_mm;
    let step_mm = [
        (w[2] - w[0]) / texels[0] as f64,
        (w[3] - w[1]) / texels[1] as f64,
    ];
    let mut patch = Vec::with_capacity(n);
    let mut blur = Vec::with_capacity(n);
    // the board as printed (board.png beside board.toml): what the photos' blur is measured
    // against; without it, blur is not measured (the report says so)
    let picture = req
        .board
        .parent()
        .map(|d| d.join("board.png"))
        .filter(|p| p.is_file())
        .and_then(|p| crate::load::image_io::decode_png(&p, "board picture").ok())
        .map(|i| i.to_luma8());
    for k in 0..n {
        progress.line(&format!(
            "reading the patch and the board in {}",
            req.photos[k].display()
        ));
        let photo = lit_photo(req, &lights_file, k)?;
        patch.push(rectify::patch_scale(&board, &cal, k, &photo, &lights[k])?);
        flat.add(&board, &cal, k, &photo, step_mm);
        blur.push(match &picture {
            Some(pic) => blur::BlurField::measure(&board, pic, &cal, k, &photo, &lights[k]),
            None => blur::BlurField::default(),
        });
        let pic = overlay::overlay(&board, &cal, k, &photo, &corner_pixels(&views, k));
        outs.put(
            t.overlays[k],
            &png_bytes(image::DynamicImage::ImageRgb8(pic))?,
        )?;
    }
    let readings: Vec<[f64; 3]> = patch.iter().map(|p| p.scale).collect();
    let disagree = exif_disagreements(&photos, &readings);
    let apart: Vec<bool> = (0..n)
        .map(|k| disagree.iter().any(|(j, _)| *j == k))
        .collect();
    let group: Vec<u64> = kinds
        .iter()
        .map(|l| match l {
            PhotoLight::Flash => 0,
            PhotoLight::Lamp(at) => {
                1 + at
                    .iter()
                    .fold(17u64, |h, v| h.wrapping_mul(31) ^ v.to_bits())
            }
        })
        .collect();
    let exposure: Vec<Option<f64>> = photos
        .iter()
        .map(|p| p.exif.and_then(|e| e.product()))
        .collect();
    let (scales, scale_rel_se, pooled) = rectify::pool_scales(&patch, &exposure, &group, &apart);
    // each photo decoded once more, rectified and written, one at a time
    let mut rectifier = rectify::Rectifier::new(&board, &cal, texels);
    for k in 0..n {
        progress.line(&format!("rectifying {}", req.photos[k].display()));
        let photo = lit_photo(req, &lights_file, k)?;
        let img = rectifier.photo(k, &photo, scales[k], &blur[k])?;
        let (file, name) = outs.file_and_name(t.images[k]);
        crate::export::images::write_exr_into(file, name, texels[0], texels[1], 3, &img)?;
    }
    let rect = rectifier.finish();
    let camera_noise = flat.fit();
    let mut capture = capture_file(&board, &cal, &lights, camera_noise.as_ref(), &rect.scale);
    capture.scale_rel_se = Some(scale_rel_se);
    let text = format!(
        "# written by fibrefit calibrate from {n} photos of {} (board frame = swatch frame, mm)\n{}",
        req.board.display(),
        toml::to_string(&capture).context("capture.toml")?
    );
    outs.put(t.capture, text.as_bytes())?;
    let mask = image::GrayImage::from_raw(texels[0] as u32, texels[1] as u32, rect.mask.clone())
        .expect("texels");
    outs.put(t.mask, &png_bytes(image::DynamicImage::ImageLuma8(mask))?)?;
    let cam = format!(
        "# fibrefit calibrate's intrinsics: reuse with --intrinsics (same camera, zoom, focus)\n{}",
        toml::to_string(&cal.intrinsics).context("cam.toml")?
    );
    outs.put(t.cam, cam.as_bytes())?;
    let cameras: Vec<Vector3<f64>> = cal.poses.iter().map(|p| p.position).collect();
    let dirs = coverage::directions(&cameras, &lights);
    let mut warnings = coverage::warnings(&dirs);
    if picture.is_none() {
        warnings.push(format!(
            "no board.png beside {}: the photos' blur was not measured (blurred texels are not left out)",
            req.board.display()
        ));
    }
    for (k, &b) in rect.blurred.iter().enumerate() {
        if b > 0.0 {
            warnings.push(format!(
                "{}: blurred (a Gaussian of {:.1} px at its median marker, up to {:.1} px; a sharp photo's is 0.3-1 px): {:.0} % of the window's texels left out where the blur spans more than a texel; refocus, steady the camera, or use fewer texels",
                req.photos[k].display(),
                blur[k].median(),
                blur[k].worst(),
                100.0 * b
            ));
        }
    }
    for (k, &c) in rect.clipped.iter().enumerate() {
        if c > CLIPPED_WARNING {
            warnings.push(format!(
                "{}: {:.0} % of the window's texels are clipped (left out): a glint the exposure cannot hold; lower the exposure or the flash, or add a darker photo of that pose",
                req.photos[k].display(),
                100.0 * c
            ));
        }
    }
    if camera_noise.is_none() {
        warnings.push(format!(
            "too few flat stretches of board outside the window (at least {} blocks of 5 x 5 texels per channel, unclipped) to estimate the camera's noise: the capture gives the fit no sigmas",
            noise::MIN_BLOCKS
        ));
    }
    warnings.extend(rms_outliers(&photos, &cal));
    warnings.extend(disagree.into_iter().map(|(_, w)| w));
    crate::export::coverage_plot::coverage(
        crate::export::atomic::Sink::Staged(&mut outs, t.coverage),
        &dirs,
        &warnings,
    )?;
    let report = report_text(
        (&photos, req.encoding),
        &cal,
        &markers,
        (&rect, camera_noise.as_ref(), (&patch, scale_rel_se, pooled)),
        (&lights_of(&kinds, &req.lights), &dirs),
        &warnings,
    );
    outs.put(t.report, report.as_bytes())?;
    outs.commit()?;
    Ok(CalibrateOutcome {
        calibration: cal,
        markers,
        capture: t.dir.join("capture.toml"),
        report,
        noise: camera_noise,
    })
}

/// A photo showing more of the window clipped than this is warned about.
const CLIPPED_WARNING: f64 = 0.05;

/// The rectified grid: `texels`, or the window's size times `px_per_mm`; 2 to 4096 a side.
fn texel_grid(req: &CalibrateRequest, board: &BoardFile) -> Result<[usize; 2]> {
    let w = board.window_mm;
    let (texels, what) = match req.px_per_mm {
        Some(d) if d.is_finite() && d > 0.0 => (
            [(w[2] - w[0]) * d, (w[3] - w[1]) * d].map(|x| x.round().max(0.0) as usize),
            format!(
                "--px-per-mm {d} (the window is {} x {} mm)",
                w[2] - w[0],
                w[3] - w[1]
            ),
        ),
        Some(d) => bail!("--px-per-mm {d}: expected texels per millimetre > 0"),
        None => (
            req.texels,
            format!("--texels {} {}", req.texels[0], req.texels[1]),
        ),
    };
    if texels.iter().any(|&x| !(2..=4096).contains(&x)) {
        bail!(
            "{what}: gives {} x {} texels; expected 2 to 4096 a side",
            texels[0],
            texels[1]
        );
    }
    Ok(texels)
}

/// Each photo's light in words, for the report.
fn lights_of(kinds: &[PhotoLight], file: &Option<PathBuf>) -> Vec<String> {
    kinds
        .iter()
        .map(|l| match (l, file) {
            (PhotoLight::Flash, _) => "flash".to_string(),
            (PhotoLight::Lamp(p), Some(f)) => {
                format!(
                    "lamp at ({}, {}, {}) mm ({})",
                    p[0],
                    p[1],
                    p[2],
                    f.display()
                )
            }
            (PhotoLight::Lamp(p), None) => format!("lamp at ({}, {}, {}) mm", p[0], p[1], p[2]),
        })
        .collect()
}

/// The intrinsics file `--intrinsics` names, read.
fn read_intrinsics(req: &CalibrateRequest) -> Result<Option<Intrinsics>> {
    let Some(p) = &req.intrinsics else {
        return Ok(None);
    };
    let text = crate::load::input::read_text_as(p, "intrinsics file")?;
    let k: Intrinsics = toml::from_str(&text)
        .with_context(|| format!("{}: not an intrinsics file (cam.toml)", p.display()))?;
    if !(k.focal_px > 0.0 && k.focal_px.is_finite()) {
        bail!("{}: focal_px = {}: expected > 0", p.display(), k.focal_px);
    }
    Ok(Some(k))
}

/// The outputs of a calibration, reserved before the work.
struct Targets {
    dir: PathBuf,
    capture: OutputId,
    mask: OutputId,
    cam: OutputId,
    report: OutputId,
    coverage: OutputId,
    images: Vec<OutputId>,
    overlays: Vec<OutputId>,
}

impl Targets {
    fn reserve(outs: &mut Outputs, out: &Path, n: usize) -> Result<Self> {
        let dir = outs.dir(out, "--out")?;
        let report_dir = outs.dir(&dir.join("report"), "--out")?;
        let mut file = |p: PathBuf| outs.file(&p, "--out");
        Ok(Self {
            capture: file(dir.join("capture.toml"))?,
            mask: file(dir.join("mask.png"))?,
            cam: file(dir.join("cam.toml"))?,
            report: file(report_dir.join("report.txt"))?,
            coverage: file(report_dir.join("coverage.png"))?,
            images: (0..n)
                .map(|k| file(dir.join(format!("img_{k:03}.exr"))))
                .collect::<Result<_>>()?,
            overlays: (0..n)
                .map(|k| file(report_dir.join(format!("overlay_{k:03}.png"))))
                .collect::<Result<_>>()?,
            dir,
        })
    }
}

/// Photo `k` decoded, less its ambient frame where `lights` gives one.
fn lit_photo(req: &CalibrateRequest, lights: &PhotoLights, k: usize) -> Result<Photo> {
    let photo = Photo::read(&req.photos[k], req.encoding)?;
    match &lights.ambient[k] {
        Some(a) => photo.less_ambient(&Photo::read(a, req.encoding)?),
        None => Ok(photo),
    }
}

/// Every photo decoded in turn (its pixels dropped once read), all of one size, with its
/// markers' corners (found in the lit photo) and how many markers; its ambient frame, where
/// `lights` gives one, checked against it.
fn read_photos(
    board: &BoardFile,
    req: &CalibrateRequest,
    lights: &PhotoLights,
) -> Result<(Vec<PhotoInfo>, Vec<Vec<Corner>>, Vec<usize>)> {
    let mut photos: Vec<PhotoInfo> = Vec::new();
    let (mut corners, mut markers) = (Vec::new(), Vec::new());
    for (path, ambient) in req.photos.iter().zip(&lights.ambient) {
        let photo = Photo::read(path, req.encoding)?;
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
        let (c, m) = corners_of(board, &photo)?;
        let info = photo.info();
        if let Some(a) = ambient {
            photo.less_ambient(&Photo::read(a, req.encoding)?)?;
        }
        corners.push(c);
        markers.push(m);
        photos.push(info);
    }
    Ok((photos, corners, markers))
}

/// The capture: the window as the swatch, each photo's image with its pinhole camera and its
/// light (the flash or a lamp) as a point light of intensity 1 (the images are divided by the
/// light x exposure, `scale`), and the camera's noise in each image's units when known.
fn capture_file(
    board: &BoardFile,
    cal: &Calibration,
    lights: &[Vector3<f64>],
    noise: Option<&noise::CameraNoise>,
    scale: &[[f64; 3]],
) -> CaptureFile {
    let w = board.window_mm;
    let images = (0..lights.len())
        .map(|k| ImageSpec {
            // a texel is the photo's value over the scale s: variance var0 / s^2 + gain / s x t
            noise: noise.map(|n| NoiseSpec {
                var0: [0, 1, 2].map(|c| n.var0[c] / (scale[k][c] * scale[k][c])),
                gain: [0, 1, 2].map(|c| n.gain[c] / scale[k][c]),
            }),
            file: Some(PathBuf::from(format!("img_{k:03}.exr"))),
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
        })
        .collect();
    CaptureFile {
        scale_rel_se: None,
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
    }
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
    (photos, encoding): (&[PhotoInfo], Encoding),
    cal: &Calibration,
    markers: &[usize],
    (rect, camera_noise, (patch, scale_rel_se, pooled)): (
        &rectify::Rectified,
        Option<&noise::CameraNoise>,
        (&[rectify::PatchScale], [f64; 3], usize),
    ),
    (lights, dirs): (&[String], &[[[f64; 2]; 3]]),
    warnings: &[String],
) -> String {
    let k = &cal.intrinsics;
    let mut s = String::new();
    let _ = writeln!(
        s,
        "intrinsics: {}x{} px, focal {:.2} px, principal point ({:.2}, {:.2}) px, k1 {:.5}, k2 {:.5}",
        k.size_px[0], k.size_px[1], k.focal_px, k.principal_px[0], k.principal_px[1], k.k[0], k.k[1]
    );
    let srgb = photos.iter().any(|p| {
        let ext = p
            .path
            .extension()
            .and_then(|e| e.to_str())
            .unwrap_or("")
            .to_ascii_lowercase();
        ext == "jpg" || ext == "jpeg" || (encoding == Encoding::Srgb && ext != "dng")
    });
    if srgb {
        let _ = writeln!(
            s,
            "note: JPEGs (and PNG/TIFF under --encoding srgb) are decoded as sRGB; a phone's JPEG tone curve is not exactly sRGB (the RAW/DNG itself, or a linear 16-bit TIFF from it with --encoding linear, is better)"
        );
    }
    let _ = writeln!(
        s,
        "radiometry: {}; the common scale's relative standard error is {:.2} % / {:.2} % / {:.2} % (R / G / B): the fitted albedos' standard errors include it",
        match pooled {
            0 => "each photo's light x exposure from its own view of the reference patch (no EXIF exposure to pool them by)".to_string(),
            p if p == patch.len() => format!("the reference patch pooled over all {p} photos by their EXIF exposure (one light, one scale)"),
            p => format!("the reference patch pooled over the {p} photos whose EXIF exposure is known, by light; the others each from their own view of it"),
        },
        100.0 * scale_rel_se[0],
        100.0 * scale_rel_se[1],
        100.0 * scale_rel_se[2]
    );
    match camera_noise {
        Some(n) => {
            let _ = writeln!(
                s,
                "camera noise (linear photo values, variance = var0 + gain x value; from {} flat blocks of board per channel): var0 [{:.3e}, {:.3e}, {:.3e}], gain [{:.3e}, {:.3e}, {:.3e}]; at value 0.2 that is {:.2} % / {:.2} % / {:.2} %: the capture gives the fit these sigmas",
                n.blocks,
                n.var0[0], n.var0[1], n.var0[2],
                n.gain[0], n.gain[1], n.gain[2],
                100.0 * n.sigma(0, 0.2) / 0.2,
                100.0 * n.sigma(1, 0.2) / 0.2,
                100.0 * n.sigma(2, 0.2) / 0.2,
            );
        }
        None => {
            let _ = writeln!(s, "camera noise: not estimated (see the warnings)");
        }
    }
    let _ = writeln!(
        s,
        "texels: {} x {} over the window; a photo's NaN texels are those it does not see well (out of frame, too oblique, clipped): its own mask",
        rect.size[0], rect.size[1]
    );
    let _ = writeln!(s, "photo\tmarkers\trms_px\tx_mm\ty_mm\tz_mm\tse_x_mm\tse_y_mm\tse_z_mm\tscale_r\tscale_g\tscale_b\tseen\texif_s\texif_iso\texif_f\tlight_theta\tlight_phi\tview_theta\tview_phi\tlight");
    for (i, photo) in photos.iter().enumerate() {
        let p = &photo.path;
        let e = photo.exif.unwrap_or_default();
        let show = |v: Option<f64>| v.map_or("-".to_string(), |v| format!("{v}"));
        let (c, se, sc) = (cal.poses[i].position, cal.position_se_mm[i], rect.scale[i]);
        let _ = writeln!(
            s,
            "{}\t{}\t{:.3}\t{:.2}\t{:.2}\t{:.2}\t{:.3}\t{:.3}\t{:.3}\t{:.4}\t{:.4}\t{:.4}\t{:.2}\t{}\t{}\t{}\t{:.1}\t{:.1}\t{:.1}\t{:.1}\t{}",
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
            rect.seen[i],
            show(e.time_s),
            show(e.iso),
            show(e.f_number),
            dirs[i][0][0],
            dirs[i][0][1],
            dirs[i][1][0],
            dirs[i][1][1],
            lights[i]
        );
    }
    for w in warnings {
        let _ = writeln!(s, "warning: {w}");
    }
    let masked = rect.mask.iter().filter(|&&m| m == 0).count();
    let _ = writeln!(
        s,
        "mask: {masked} of {} texels left out (no photo sees them well, or at the window's edge)",
        rect.mask.len()
    );
    s
}

/// Photos whose reprojection RMS is over 0.5 px and three times the median's: blurred, the board
/// not flat there, or a marker misread.
fn rms_outliers(photos: &[PhotoInfo], cal: &Calibration) -> Vec<String> {
    let mut sorted = cal.rms_px.clone();
    sorted.sort_by(f64::total_cmp);
    let median = sorted[sorted.len() / 2];
    cal.rms_px
        .iter()
        .enumerate()
        .filter(|(_, &r)| r > 0.5 && r > 3.0 * median)
        .map(|(k, r)| {
            format!(
                "{}: reprojection RMS {r:.2} px against the photos' median {median:.2} px: blurred, the board not flat, or a marker misread (see its overlay)",
                photos[k].path.display()
            )
        })
        .collect()
}

/// Photos whose patch-derived exposure (green) disagrees by over 15 % with what their EXIF
/// exposure (time x ISO / f-number^2) says relative to the others: another light than the
/// flash, the patch in shadow, or a wrong EXIF.
pub fn exif_disagreements(photos: &[PhotoInfo], scale: &[[f64; 3]]) -> Vec<(usize, String)> {
    let ratios: Vec<(usize, f64)> = photos
        .iter()
        .enumerate()
        .filter_map(|(k, p)| Some((k, scale[k][1] / p.exif?.product()?)))
        .collect();
    if ratios.len() < 2 {
        return vec![];
    }
    let mut sorted: Vec<f64> = ratios.iter().map(|r| r.1).collect();
    sorted.sort_by(f64::total_cmp);
    let median = sorted[sorted.len() / 2];
    ratios
        .iter()
        .filter(|(_, r)| (r / median - 1.0).abs() > 0.15)
        .map(|(k, r)| {
            (*k, format!(
                "{}: the reference patch reads {:+.0} % against its EXIF exposure (the other photos agree): another light, the patch in shadow, or a wrong EXIF; its own reading is used",
                photos[*k].path.display(),
                100.0 * (r / median - 1.0)
            ))
        })
        .collect()
}
