//! The report's overlay pictures: a photo with its detected marker corners (green), the
//! corners reprojected through the calibration (red) and the window's outline (blue).

use super::Calibration;
use crate::load::board::BoardFile;
use crate::load::image_io::linear_to_srgb;
use crate::load::photo::Photo;
use image::{Rgb, RgbImage};
use nalgebra::Vector3;

/// Photo `k`'s overlay; `found`: its detected corners (px).
pub fn overlay(
    board: &BoardFile,
    cal: &Calibration,
    k: usize,
    photo: &Photo,
    found: &[[f64; 2]],
) -> RgbImage {
    let data: Vec<u8> = photo
        .linear
        .iter()
        .map(|&v| (linear_to_srgb(v.clamp(0.0, 1.0)) * 255.0).round() as u8)
        .collect();
    let mut img = RgbImage::from_raw(photo.width as u32, photo.height as u32, data)
        .expect("width x height x 3 values");
    let mut dot = |p: [f64; 2], r: i64, colour: [u8; 3]| {
        let (cx, cy) = (p[0].floor() as i64, p[1].floor() as i64);
        for dy in -r..=r {
            for dx in -r..=r {
                let (x, y) = (cx + dx, cy + dy);
                if x >= 0 && y >= 0 && (x as u32) < img.width() && (y as u32) < img.height() {
                    img.put_pixel(x as u32, y as u32, Rgb(colour));
                }
            }
        }
    };
    let pose = &cal.poses[k];
    let project = |x: f64, y: f64| {
        cal.intrinsics
            .project(&pose.to_camera(&Vector3::new(x, y, 0.0)))
    };
    let w = board.window_mm;
    for t in 0..400 {
        let s = t as f64 / 400.0;
        for (x, y) in [
            (w[0] + s * (w[2] - w[0]), w[1]),
            (w[0] + s * (w[2] - w[0]), w[3]),
            (w[0], w[1] + s * (w[3] - w[1])),
            (w[2], w[1] + s * (w[3] - w[1])),
        ] {
            if let Some(p) = project(x, y) {
                dot(p, 0, [40, 80, 255]);
            }
        }
    }
    for &p in found {
        dot(p, 2, [0, 220, 0]);
    }
    for m in &board.marker {
        for c in &m.corners_mm {
            if let Some(p) = project(c[0], c[1]) {
                dot(p, 0, [255, 0, 0]);
            }
        }
    }
    img
}
