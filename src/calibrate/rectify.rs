//! Rectifying calibrated photos onto the window's texel grid (undistorted, resampled
//! bilinearly; texels out of frame, too oblique, clipped or blurred left out) and making their values absolute from the reference patch: per photo and
//! channel, the light-intensity x exposure product that makes the patch read its known
//! reflectance, so the capture's point lights have intensity 1 and its albedos come out
//! absolute (white balance included).

use super::Calibration;
use crate::load::board::BoardFile;
use crate::load::capture::pixel_position;
use crate::load::photo::Photo;
use anyhow::{bail, Result};
use nalgebra::Vector3;

/// What rectifying every photo leaves besides the images (each written as it is made).
pub struct Rectified {
    /// Texels across and down the window.
    pub size: [usize; 2],
    /// 255 where some photo sees the texel well and it is not at the window's edge, 0
    /// elsewhere.
    pub mask: Vec<u8>,
    /// Each photo's light x exposure product per channel (its images are divided by it).
    pub scale: Vec<[f64; 3]>,
    /// Each photo's fraction of window texels it sees well.
    pub seen: Vec<f64>,
    /// Each photo's fraction of window texels it shows clipped (left out).
    pub clipped: Vec<f64>,
    /// Each photo's fraction of window texels it shows blurred (left out).
    pub blurred: Vec<f64>,
}

/// Views more oblique than this (cosine to the normal) are masked.
const MIN_VIEW_COS: f64 = 0.17;
/// A texel whose photo value reaches this (linear) is clipped.
const CLIPPED: f32 = 0.98;
/// Texels this close to the window's edge (mm) are masked (the swatch's edge, the outline).
const EDGE_MM: f64 = 1.0;

/// Rectifies calibrated photos one at a time onto a texel grid over the board's window, so
/// that only one photo's pixels need be held.
pub struct Rectifier<'a> {
    board: &'a BoardFile,
    cal: &'a Calibration,
    done: Rectified,
}

impl<'a> Rectifier<'a> {
    /// A `size` texel grid over `board`'s window for the photos `cal` calibrated.
    pub fn new(board: &'a BoardFile, cal: &'a Calibration, size: [usize; 2]) -> Self {
        Self {
            board,
            cal,
            done: Rectified {
                size,
                mask: vec![0u8; size[0] * size[1]],
                scale: Vec::new(),
                seen: Vec::new(),
                clipped: Vec::new(),
                blurred: Vec::new(),
            },
        }
    }

    /// Photo `k` rectified: its linear RGB texels (row 0 at the window's top) divided by `s`,
    /// its light x exposure product per channel (so that its light has intensity 1); NaN
    /// where that photo does not see the texel well (out of frame, too oblique, clipped): the
    /// photo's own mask, which the capture's loader honours. Photos come in order, from 0.
    pub fn photo(
        &mut self,
        k: usize,
        photo: &Photo,
        s: [f64; 3],
        blur: &super::blur::BlurField,
    ) -> Result<Vec<f32>> {
        let (board, cal, size) = (self.board, self.cal, self.done.size);
        assert_eq!(k, self.done.scale.len(), "photos are rectified in order");
        let w = board.window_mm;
        let size_mm = [w[2] - w[0], w[3] - w[1]];
        let centre = Vector3::new(0.5 * (w[0] + w[2]), 0.5 * (w[1] + w[3]), 0.0);
        let n = size[0] * size[1];
        let pose = &cal.poses[k];
        let mut img = vec![f32::NAN; 3 * n];
        let (mut good, mut clipped, mut blurred) = (0usize, 0usize, 0usize);
        let texel_mm = (size_mm[0] / size[0] as f64).min(size_mm[1] / size[1] as f64);
        for y in 0..size[1] {
            for x in 0..size[0] {
                let p = centre + pixel_position(size_mm, size[0], size[1], x, y);
                let i = y * size[0] + x;
                let near_edge = p.x - w[0] < EDGE_MM
                    || w[2] - p.x < EDGE_MM
                    || p.y - w[1] < EDGE_MM
                    || w[3] - p.y < EDGE_MM;
                let view_cos = (pose.position - p).normalize().z;
                let value = cal
                    .intrinsics
                    .project(&pose.to_camera(&p))
                    .and_then(|[u, v]| Some((photo.sample(u, v)?, photo.peak_near(u, v)?)));
                // blurred: the photo's blur here exceeds a sharp photo's, and spans more than a
                // texel on the board
                let is_blurred = || {
                    let Some(b) = blur.at(p.x, p.y).filter(|b| *b > super::blur::BLURRED_PX) else {
                        return false;
                    };
                    let step = Vector3::new(texel_mm, 0.0, 0.0);
                    let px_per_texel = match (
                        cal.intrinsics.project(&pose.to_camera(&p)),
                        cal.intrinsics.project(&pose.to_camera(&(p + step))),
                        cal.intrinsics
                            .project(&pose.to_camera(&(p + Vector3::new(0.0, texel_mm, 0.0)))),
                    ) {
                        (Some(a), Some(b), Some(c)) => {
                            (b[0] - a[0]).hypot(b[1] - a[1]).max((c[0] - a[0]).hypot(c[1] - a[1]))
                        }
                        _ => return false,
                    };
                    b > px_per_texel
                };
                match value {
                    Some(_) if !near_edge && view_cos > MIN_VIEW_COS && is_blurred() => {
                        blurred += 1
                    }
                    Some((rgb, peak)) if !near_edge && view_cos > MIN_VIEW_COS && peak < CLIPPED => {
                        for c in 0..3 {
                            img[3 * i + c] = (rgb[c] as f64 / s[c]) as f32;
                        }
                        self.done.mask[i] = 255;
                        good += 1;
                    }
                    Some((_, peak)) if !near_edge && peak >= CLIPPED => clipped += 1,
                    _ => {}
                }
            }
        }
        self.done.scale.push(s);
        self.done.seen.push(good as f64 / n as f64);
        self.done.clipped.push(clipped as f64 / n as f64);
        self.done.blurred.push(blurred as f64 / n as f64);
        Ok(img)
    }

    /// What the photos left: the mask, each one's scale and share seen.
    pub fn finish(self) -> Rectified {
        self.done
    }
}

/// What the reference patch says of one photo's light x exposure product.
#[derive(Clone, Copy, Debug)]
pub struct PatchScale {
    /// Per channel: the product.
    pub scale: [f64; 3],
    /// Per channel: its relative standard error, from the scatter of the patch's points
    /// (counted as a quarter as many independent ones: neighbouring points share pixels).
    pub rel_se: [f64; 3],
}

/// Photo `k`'s light x exposure product per channel (lit by a point light at `light`, mm):
/// the patch's value over what a unit light gives there (reflectance / pi x cos(theta_i) / r^2, r in metres), on a fine grid of the
/// patch. Points nearer than [`PATCH_CLEAR_PX`] pixels to the patch's outline (as the photo
/// shows it) are left out, and so are points whose value strays from the others' median by
/// more than 4 of their median absolute deviations: a photo that sees the patch obliquely or
/// small would otherwise blend the paper around it in (demosaicing and resampling reach a pixel
/// or two), and a speck or a glint on the patch would count.
pub fn patch_scale(
    board: &BoardFile,
    cal: &Calibration,
    k: usize,
    photo: &Photo,
    light: &Vector3<f64>,
) -> Result<PatchScale> {
    let r = board.patch.rect_mm;
    let pose = &cal.poses[k];
    let project = |p: &Vector3<f64>| cal.intrinsics.project(&pose.to_camera(p));
    let corners: Vec<[f64; 2]> = [(r[0], r[1]), (r[2], r[1]), (r[2], r[3]), (r[0], r[3])]
        .iter()
        .filter_map(|&(x, y)| project(&Vector3::new(x, y, 0.0)))
        .collect();
    let mut ratios: Vec<[f64; 3]> = Vec::new();
    let steps = 32;
    if corners.len() == 4 {
        for j in 0..steps {
            for i in 0..steps {
                let x = r[0] + (r[2] - r[0]) * (i as f64 + 0.5) / steps as f64;
                let y = r[1] + (r[3] - r[1]) * (j as f64 + 0.5) / steps as f64;
                let p = Vector3::new(x, y, 0.0);
                let Some(at) = project(&p) else { continue };
                let clear = (0..4).all(|e| {
                    segment_distance(at, corners[e], corners[(e + 1) % 4]) >= PATCH_CLEAR_PX
                });
                let rgb = photo.sample(at[0], at[1]);
                let (true, Some(rgb)) = (clear, rgb) else {
                    continue;
                };
                let d = light - p;
                let r_m = d.norm() / 1000.0;
                let g = board.patch.reflectance / std::f64::consts::PI
                    * (d.z / d.norm()).max(0.0)
                    / (r_m * r_m);
                if g > 0.0 {
                    ratios.push(rgb.map(|v| v as f64 / g));
                }
            }
        }
    }
    let mut out = [0.0; 3];
    let mut rel_se = [0.0; 3];
    let mut kept = usize::MAX;
    for c in 0..3 {
        let mut v: Vec<f64> = ratios.iter().map(|q| q[c]).collect();
        v.sort_by(f64::total_cmp);
        let median = v.get(v.len() / 2).copied().unwrap_or(0.0);
        let mut dev: Vec<f64> = v.iter().map(|x| (x - median).abs()).collect();
        dev.sort_by(f64::total_cmp);
        let mad = dev.get(dev.len() / 2).copied().unwrap_or(0.0);
        let inliers: Vec<f64> = v
            .into_iter()
            .filter(|x| (x - median).abs() <= 4.0 * mad.max(1e-6 * median.abs()))
            .collect();
        kept = kept.min(inliers.len());
        let n = inliers.len().max(2) as f64;
        out[c] = inliers.iter().sum::<f64>() / n;
        let var = inliers.iter().map(|x| (x - out[c]).powi(2)).sum::<f64>() / (n - 1.0);
        rel_se[c] = (var / (n / 4.0).max(1.0)).sqrt() / out[c].abs().max(1e-300);
    }
    if kept < MIN_PATCH_SAMPLES || out.iter().any(|&s| !(s > 0.0)) {
        bail!(
            "{}: the reference patch is not in the picture, too small or too oblique in it ({} points of it at least {PATCH_CLEAR_PX} px inside its outline; at least {MIN_PATCH_SAMPLES} needed), or not lit: frame the whole board, nearer",
            photo.path.display(),
            kept.min(ratios.len())
        );
    }
    Ok(PatchScale { scale: out, rel_se })
}

/// The distance (px) from `p` to the segment `a`-`b`.
fn segment_distance(p: [f64; 2], a: [f64; 2], b: [f64; 2]) -> f64 {
    let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
    let len2 = dx * dx + dy * dy;
    let t = if len2 > 0.0 {
        (((p[0] - a[0]) * dx + (p[1] - a[1]) * dy) / len2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    (p[0] - a[0] - t * dx).hypot(p[1] - a[1] - t * dy)
}

/// How far (px, in the photo) a patch sample keeps from the patch's edge.
const PATCH_CLEAR_PX: f64 = 4.0;
/// Fewest patch samples a photo's scale rests on.
const MIN_PATCH_SAMPLES: usize = 64;

/// The photos' light x exposure products, pooled where the exposure is known: photos lit by
/// one light (equal `group`) whose EXIF gives their exposure product `exposure[k]` (time x ISO
/// / f-number^2) share one scale S per channel, `s_k = S x exposure[k]`, S the inverse-variance
/// weighted mean of the patch's `s_k / exposure[k]`: the patch's noise averages over the
/// photos instead of tilting each photo against the others. A photo without EXIF, alone in its
/// group, or marked in `apart` (its patch disagrees with its exposure) keeps its own reading.
/// Returns every photo's scale, per channel the relative standard error of the common scale
/// (the largest over the groups), and how many photos were pooled.
pub fn pool_scales(
    patch: &[PatchScale],
    exposure: &[Option<f64>],
    group: &[u64],
    apart: &[bool],
) -> (Vec<[f64; 3]>, [f64; 3], usize) {
    let n = patch.len();
    let mut out: Vec<[f64; 3]> = patch.iter().map(|p| p.scale).collect();
    let mut rel_se = [0.0f64; 3];
    let mut pooled = 0;
    let mut done = vec![false; n];
    for k in 0..n {
        if done[k] {
            continue;
        }
        let members: Vec<usize> = (k..n)
            .filter(|&j| group[j] == group[k] && !apart[j] && exposure[j].is_some())
            .collect();
        if members.len() < 2 {
            done[k] = true;
            for c in 0..3 {
                rel_se[c] = rel_se[c].max(patch[k].rel_se[c]);
            }
            continue;
        }
        for c in 0..3 {
            let (mut sw, mut swx) = (0.0, 0.0);
            for &j in &members {
                let x = patch[j].scale[c] / exposure[j].expect("member");
                let w = 1.0 / (x * patch[j].rel_se[c]).powi(2).max(1e-300);
                sw += w;
                swx += w * x;
            }
            let s = swx / sw;
            for &j in &members {
                out[j][c] = s * exposure[j].expect("member");
            }
            rel_se[c] = rel_se[c].max(1.0 / sw.sqrt() / s);
        }
        for &j in &members {
            done[j] = true;
        }
        pooled += members.len();
        done[k] = true;
    }
    (out, rel_se, pooled)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::board::camera::{Intrinsics, Pose};

    /// A photo from straight above: texels under a glint are left out and counted as clipped,
    /// the others divided by the scale.
    #[test]
    fn clipped_texels_are_left_out_and_counted() {
        let dir = tempfile::tempdir().unwrap();
        crate::api::board::board(&crate::api::board::BoardRequest::default(), dir.path()).unwrap();
        let board = BoardFile::read(&dir.path().join("board.toml")).unwrap();
        let intrinsics = Intrinsics {
            size_px: [800, 600],
            focal_px: 1000.0,
            principal_px: [400.0, 300.0],
            k: [0.0, 0.0],
        };
        let pose = Pose::look_at(Vector3::new(0.0, 1.0, 300.0), Vector3::zeros());
        let cal = Calibration {
            intrinsics,
            poses: vec![pose],
            rms_px: vec![0.1],
            position_se_mm: vec![[0.0; 3]],
        };
        // 0.4 everywhere, 1.0 (clipped) within 60 px of the centre
        let (w, h) = (800usize, 600usize);
        let mut linear = vec![0.4f32; 3 * w * h];
        for y in 0..h {
            for x in 0..w {
                if (x as f64 - 400.0).hypot(y as f64 - 300.0) < 60.0 {
                    linear[3 * (y * w + x)..3 * (y * w + x) + 3].fill(1.0);
                }
            }
        }
        let peak = linear.chunks_exact(3).map(|p| p[0]).collect();
        let photo = Photo {
            path: "glint.png".into(),
            width: w,
            height: h,
            linear,
            peak,
            exif: None,
        };
        let mut r = Rectifier::new(&board, &cal, [32, 32]);
        let img = r
            .photo(0, &photo, [0.2, 0.2, 0.4], &super::super::blur::BlurField::default())
            .unwrap();
        let done = r.finish();
        // the disc covers 36 mm of the window's diameter at 300 mm (f 1000 px: 3.33 px/mm)
        assert!(done.clipped[0] > 0.05 && done.clipped[0] < 0.4, "{}", done.clipped[0]);
        let kept: Vec<f32> = img.iter().copied().filter(|v| v.is_finite()).collect();
        assert!(!kept.is_empty());
        for (i, v) in kept.iter().enumerate() {
            let want = if i % 3 == 2 { 1.0 } else { 2.0 };
            assert!((v - want).abs() < 1e-5, "{v}");
        }
    }
}
