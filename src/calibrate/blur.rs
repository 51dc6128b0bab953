//! How blurred a photo is, where: around every marker, the photo is compared with the board
//! as printed (`board.png`, seen through the calibrated camera) blurred by Gaussians of
//! growing width; the width whose picture, scaled and offset (light and exposure), fits the
//! photo best is the photo's blur there (its standard deviation in pixels; analysis by
//! synthesis, which needs no long edges: a tag's cells are a few pixels at grazing views).
//! On synthetic photos blurred by 4 px, markers large in the photo read 4.0-4.5 px; small ones,
//! whose cells the blur all but erases, read up to the widest tried (7 px): the measure
//! detects blur surely (sharp photos read 0.3-0.45 px) and errs towards more where it is large.
//! Rectifying masks a texel where the photo's blur, interpolated from the markers, exceeds both
//! a sharp photo's ([`BLURRED_PX`]) and a texel's size in the photo: the photo cannot resolve
//! the swatch at the texels' scale there (defocus at grazing views, shake).

use super::Calibration;
use crate::board::camera::{gaussian_blur, pixel_on_board};
use crate::load::board::BoardFile;
use crate::load::image_io::srgb_to_linear;
use crate::load::photo::Photo;
use image::GrayImage;
use nalgebra::Vector3;

/// A photo is blurred at a point where its blur's standard deviation exceeds this many pixels
/// (a sharp photo measures 0.3-1 px).
pub const BLURRED_PX: f64 = 2.5;

/// Half the side of the window compared around a marker (px), and the margin of it left out of
/// the comparison (the blur's reach at its widest).
const HALF: usize = 32;
const MARGIN: usize = 12;

/// The blurs tried (px), each about 1.25x the last.
const SIGMAS: [f64; 14] = [
    0.25, 0.35, 0.5, 0.7, 0.9, 1.15, 1.45, 1.8, 2.3, 2.9, 3.6, 4.5, 5.6, 7.0,
];

/// A photo's blur at each of its markers: (the marker's centre on the board in mm, the blur's
/// standard deviation in the photo's pixels).
#[derive(Clone, Debug, Default)]
pub struct BlurField {
    pub at: Vec<([f64; 2], f64)>,
}

impl BlurField {
    /// The blur of photo `k` around every marker of `board` it shows whole, against the
    /// board's picture `picture` (`board.png`) lit by a point light at `light` (mm: its
    /// falloff across the window, which a blur would otherwise be asked to explain).
    pub fn measure(
        board: &BoardFile,
        picture: &GrayImage,
        cal: &Calibration,
        k: usize,
        photo: &Photo,
        light: &Vector3<f64>,
    ) -> Self {
        let pose = &cal.poses[k];
        let side = 2 * HALF;
        let (pw, ph) = (picture.width() as f64, picture.height() as f64);
        let printed = |x: f64, y: f64| -> Option<f64> {
            let [u, v] = board.mm_to_png(x, y);
            if !(0.0..pw).contains(&u) || !(0.0..ph).contains(&v) {
                return None;
            }
            let g = picture.get_pixel(u as u32, v as u32)[0];
            Some(srgb_to_linear(g as f32 / 255.0) as f64)
        };
        let mut at = Vec::new();
        for m in &board.marker {
            let c = m.corners_mm;
            let centre = [
                c.iter().map(|p| p[0]).sum::<f64>() / 4.0,
                c.iter().map(|p| p[1]).sum::<f64>() / 4.0,
            ];
            let Some([uc, vc]) = cal
                .intrinsics
                .project(&pose.to_camera(&Vector3::new(centre[0], centre[1], 0.0)))
            else {
                continue;
            };
            let (u0, v0) = (uc.floor() as i64 - HALF as i64, vc.floor() as i64 - HALF as i64);
            if u0 < 0
                || v0 < 0
                || u0 + side as i64 > photo.width as i64
                || v0 + side as i64 > photo.height as i64
            {
                continue;
            }
            // the printed board through the camera, and the photo, over the window
            let mut sharp = vec![0.0; side * side];
            let mut seen = vec![0.0; side * side];
            // the window holds the swatch, not what is printed there: left out
            let mut used = vec![true; side * side];
            let w = board.window_mm;
            let mut whole = true;
            'px: for j in 0..side {
                for i in 0..side {
                    let (u, v) = ((u0 + i as i64) as usize, (v0 + j as i64) as usize);
                    let Some(p) =
                        pixel_on_board(&cal.intrinsics, pose, u as f64 + 0.5, v as f64 + 0.5)
                    else {
                        whole = false;
                        break 'px;
                    };
                    let Some(r) = printed(p.x, p.y) else {
                        whole = false;
                        break 'px;
                    };
                    used[j * side + i] = !(p.x > w[0] - 2.0
                        && p.x < w[2] + 2.0
                        && p.y > w[1] - 2.0
                        && p.y < w[3] + 2.0);
                    let d = light - p;
                    sharp[j * side + i] = r * (d.z / d.norm()).max(0.0) / (d.norm_squared() * 1e-6);
                    let q = &photo.linear[3 * (v * photo.width + u)..3 * (v * photo.width + u) + 3];
                    seen[j * side + i] =
                        0.2126 * q[0] as f64 + 0.7152 * q[1] as f64 + 0.0722 * q[2] as f64;
                }
            }
            if whole {
                if let Some(s) = best_blur(&sharp, &seen, &used, side) {
                    at.push((centre, s));
                }
            }
        }
        Self { at }
    }

    /// The blur (px) at board point (x, y): the markers' blurs weighted by inverse squared
    /// distance; None without markers.
    pub fn at(&self, x: f64, y: f64) -> Option<f64> {
        let (mut sw, mut swb) = (0.0, 0.0);
        for (p, b) in &self.at {
            let d2 = (p[0] - x).powi(2) + (p[1] - y).powi(2);
            let w = 1.0 / d2.max(1e-6);
            sw += w;
            swb += w * b;
        }
        (sw > 0.0).then(|| swb / sw)
    }

    /// The median blur over the markers (px), 0 without markers.
    pub fn median(&self) -> f64 {
        let mut b: Vec<f64> = self.at.iter().map(|a| a.1).collect();
        b.sort_by(f64::total_cmp);
        b.get(b.len() / 2).copied().unwrap_or(0.0)
    }

    /// The largest blur at any marker (px), 0 without markers.
    pub fn worst(&self) -> f64 {
        self.at.iter().map(|a| a.1).fold(0.0, f64::max)
    }
}

/// The blur (px) whose Gaussian, applied to `sharp`, fits `seen` best up to a scale and an
/// offset, over the `side` x `side` windows less their margins; refined between the widths
/// tried by a parabola in log width. None when the window holds no contrast.
fn best_blur(sharp: &[f64], seen: &[f64], used: &[bool], side: usize) -> Option<f64> {
    let costs: Vec<f64> = SIGMAS
        .iter()
        .map(|&s| {
            let b = blurred(sharp, side, s);
            fit_cost(&b, seen, used, side)
        })
        .collect::<Option<_>>()?;
    let (i, _) = costs
        .iter()
        .enumerate()
        .min_by(|a, b| a.1.total_cmp(b.1))?;
    if i == 0 || i == SIGMAS.len() - 1 {
        return Some(SIGMAS[i]);
    }
    // golden-section search in log width between the neighbours of the best tried
    let cost = |ls: f64| {
        fit_cost(&blurred(sharp, side, ls.exp()), seen, used, side).unwrap_or(f64::MAX)
    };
    let g = (5.0f64.sqrt() - 1.0) / 2.0;
    let (mut a, mut b) = (SIGMAS[i - 1].ln(), SIGMAS[i + 1].ln());
    let (mut c, mut d) = (b - g * (b - a), a + g * (b - a));
    let (mut fc, mut fd) = (cost(c), cost(d));
    // ten steps narrow the bracket to 1 % of its width
    for _ in 0..10 {
        if fc < fd {
            (b, d, fd) = (d, c, fc);
            c = b - g * (b - a);
            fc = cost(c);
        } else {
            (a, c, fc) = (c, d, fd);
            d = a + g * (b - a);
            fd = cost(d);
        }
    }
    Some((0.5 * (a + b)).exp())
}

/// The residual sum of squares of `seen` against `a + b model` (a, b fitted) over the inner
/// window's `used` pixels; None when the model is flat there or too few are used.
fn fit_cost(model: &[f64], seen: &[f64], used: &[bool], side: usize) -> Option<f64> {
    let (mut n, mut sx, mut sy, mut sxx, mut sxy, mut syy) = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0);
    for j in MARGIN..side - MARGIN {
        for i in MARGIN..side - MARGIN {
            if !used[j * side + i] {
                continue;
            }
            let (x, y) = (model[j * side + i], seen[j * side + i]);
            n += 1.0;
            sx += x;
            sy += y;
            sxx += x * x;
            sxy += x * y;
            syy += y * y;
        }
    }
    let vx = sxx - sx * sx / n;
    if n < 100.0 || vx <= 1e-12 * n {
        return None;
    }
    let cxy = sxy - sx * sy / n;
    Some((syy - sy * sy / n) - cxy * cxy / vx)
}

/// `image` (`side` x `side`) blurred by the lens blur of standard deviation `sigma` px that
/// `synth --photos` applies ([`gaussian_blur`]).
fn blurred(image: &[f64], side: usize, sigma: f64) -> Vec<f64> {
    let mut out = image.to_vec();
    gaussian_blur(&mut out, side, side, 1, sigma);
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A checkerboard blurred by a known Gaussian reads back its width.
    #[test]
    fn a_blurred_pattern_reads_its_width() {
        let side = 2 * HALF;
        let sharp: Vec<f64> = (0..side * side)
            .map(|k| {
                let (x, y) = (k % side, k / side);
                if ((x / 7) + (y / 5)) % 2 == 0 { 0.05 } else { 0.8 }
            })
            .collect();
        for sigma in [0.6f64, 1.5, 3.0, 5.0] {
            let seen: Vec<f64> = blurred(&sharp, side, sigma).iter().map(|v| 0.1 + 0.5 * v).collect();
            let s = best_blur(&sharp, &seen, &vec![true; side * side], side).unwrap();
            assert!((s / sigma - 1.0).abs() < 0.08, "{s} for {sigma}");
        }
    }
}
