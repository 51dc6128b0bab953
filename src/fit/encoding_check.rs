//! Is the transfer curve of a PNG capture the right one? PNG codes are decoded by the capture's
//! `encoding` (`linear` or `srgb`); the wrong one bends every pixel value by a power (sRGB read
//! as linear: roughly value^(1/2.2)), which no BRDF parameter can undo. What it leaves is
//! residuals that scale with the intensity: within one image, ln(pixel value) rises with
//! ln(fitted pixel value) at a slope other than 1.
//!
//! The check: for each PNG image of a capture, the pixels' values in the image's own units
//! (data BRDF x cos theta_i, the fitted BRDF x cos theta_i; the irradiance and the exposure are
//! one factor per image) are compared on a log scale, and the slope is pooled over the images
//! (each image's mean taken out, so a wrong exposure does not count; an image whose fitted
//! values do not vary adds nothing). A right curve gives 1 within [`SLOPE_TOLERANCE`] (the
//! shipped brushed capture with its `srgb` encoding does not warn, tests/pictures.rs); the same
//! capture read as `linear` gives 0.64. EXR images are linear by definition and not checked.

use crate::load::capture::CaptureFile;
use crate::load::image_io::Encoding;
use crate::load::samples::{DataKind, Origin, Samples};

/// |slope - 1| above this is reported.
pub const SLOPE_TOLERANCE: f64 = 0.15;
/// Fewest usable pixel values (over the PNG images) for a verdict.
pub const MIN_VALUES: usize = 200;
/// The fitted values must span at least this factor within the images (else the slope is not
/// determined: a flat, uniformly lit capture).
pub const MIN_SPAN: f64 = 1.5;

/// The pooled within-image slope of ln(data) on ln(fitted) over the PNG images of a capture:
/// (slope, values used, the images' declared encodings). `None` when the data are no capture,
/// have no PNG image, or too few values or too little spread decide it.
pub fn slope(samples: &Samples, fitted: &[[f64; 3]]) -> Option<(f64, usize, Vec<Encoding>)> {
    if samples.kind != DataKind::Capture {
        return None;
    }
    let capture = CaptureFile::load(&samples.source).ok()?;
    let png: Vec<Option<Encoding>> = capture
        .images
        .iter()
        .map(|im| {
            // integer-coded images (PNG, 8/16-bit TIFF; a float TIFF has no encoding)
            let is_png = im.frames().iter().all(|(f, _)| {
                f.extension().and_then(|e| e.to_str()).is_some_and(|e| {
                    ["png", "tif", "tiff"].contains(&e.to_ascii_lowercase().as_str())
                })
            });
            if is_png {
                im.encoding
            } else {
                None
            }
        })
        .collect();
    let ch = samples.channels;
    // per image: (x, y) pairs
    let mut per_image: Vec<Vec<(f64, f64)>> = vec![Vec::new(); png.len()];
    for (s, m) in samples.samples.iter().zip(fitted) {
        let Origin::Pixel { image, .. } = s.origin else {
            continue;
        };
        let k = image as usize;
        if png.get(k).copied().flatten().is_none() || s.l.z <= 0.0 {
            continue;
        }
        for c in 0..ch {
            let (d, f) = (s.value[c], m[c]);
            if d > 0.0 && f > 0.0 && d.is_finite() && f.is_finite() {
                let u = s.l.z.ln();
                per_image[k].push(((f.ln() + u), (d.ln() + u)));
            }
        }
    }
    let (mut sxy, mut sxx, mut n) = (0.0, 0.0, 0usize);
    let mut span = 1.0f64;
    for pts in per_image.iter().filter(|p| p.len() >= 10) {
        let mx = pts.iter().map(|p| p.0).sum::<f64>() / pts.len() as f64;
        let my = pts.iter().map(|p| p.1).sum::<f64>() / pts.len() as f64;
        let lo = pts.iter().map(|p| p.0).fold(f64::INFINITY, f64::min);
        let hi = pts.iter().map(|p| p.0).fold(f64::NEG_INFINITY, f64::max);
        span = span.max((hi - lo).exp());
        for &(x, y) in pts {
            sxy += (x - mx) * (y - my);
            sxx += (x - mx) * (x - mx);
        }
        n += pts.len();
    }
    if n < MIN_VALUES || span < MIN_SPAN || sxx <= 0.0 {
        return None;
    }
    let encodings = png.into_iter().flatten().collect();
    Some((sxy / sxx, n, encodings))
}

/// The warning, when the residuals of a PNG capture scale with the intensity as a wrong
/// transfer curve makes them (empty otherwise).
pub fn check(samples: &Samples, fitted: &[[f64; 3]]) -> Vec<String> {
    let Some((g, n, encodings)) = slope(samples, fitted) else {
        return vec![];
    };
    if (g - 1.0).abs() <= SLOPE_TOLERANCE {
        return vec![];
    }
    let all = |e: Encoding| encodings.iter().all(|x| *x == e);
    let (declared, other) = if all(Encoding::Linear) {
        ("linear", "srgb")
    } else if all(Encoding::Srgb) {
        ("srgb", "linear")
    } else {
        ("linear for some images, srgb for others", "the other one")
    };
    let hint = match (g < 1.0, declared) {
        (true, "linear") => "the data are flatter than any fit: PNGs saved by a camera or an editor are usually sRGB",
        (false, "srgb") => "the data are steeper than any fit: these PNGs may hold linear values",
        _ => "the transfer curve of the PNGs may not be the one declared",
    };
    vec![format!(
        "the residuals scale with the intensity as a wrong transfer curve makes them: within each PNG \
         image, ln(data) rises {g:.2} times as fast as ln(fitted) ({n} values; a right curve gives \
         1 +/- {SLOPE_TOLERANCE}); the capture declares `encoding = \"{declared}\"`: {hint}; check \
         the `encoding` key of the capture's [[images]] (try `encoding = \"{other}\"`)"
    )]
}
