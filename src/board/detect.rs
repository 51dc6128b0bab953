//! Finding a board's markers in a grey picture with the AprilTag library's detector (sub-pixel
//! corners from its edge refinement).

use anyhow::{anyhow, Result};

/// One marker found in a picture.
#[derive(Clone, Debug)]
pub struct Found {
    /// Its id in the family.
    pub id: u32,
    /// Its black border's outer corners (pixels; pixel (0, 0) covers [0, 1] x [0, 1]), in the
    /// order of [`crate::load::board::Marker::corners_mm`].
    pub corners: [[f64; 2]; 4],
    /// The detector's decision margin (higher: surer).
    pub margin: f32,
}


/// The tag36h11 markers in the 8-bit grey picture `grey` (`width` x `height`, row-major), each
/// id once (a repeated id, which a board never has, is dropped with its twin).
pub fn find(grey: &[u8], width: usize, height: usize) -> Result<Vec<Found>> {
    if grey.len() != width * height || width == 0 || height == 0 {
        return Err(anyhow!("a {width} x {height} picture needs {} values", width * height));
    }
    let mut image = apriltag::Image::zeros_with_alignment(width, height, 96)
        .map_err(|e| anyhow!("the AprilTag detector's image: {e}"))?;
    for y in 0..height {
        for x in 0..width {
            image[(x, y)] = grey[y * width + x];
        }
    }
    let mut detector = apriltag::Detector::builder()
        .add_family_bits(apriltag::Family::tag_36h11(), 1)
        .build()
        .map_err(|e| anyhow!("the AprilTag detector: {e}"))?;
    detector.set_decimation(1.0);
    detector.set_refine_edges(true);
    detector.set_thread_number(1);
    let mut found: Vec<Found> = detector
        .detect(&image)
        .into_iter()
        .filter(|d| d.hamming() == 0)
        .map(|d| Found {
            id: d.id() as u32,
            // the library's pixel centres are at half-integers too (its quad fit and edge
            // refinement say so; tests/photo_board.rs measures it)
            corners: d.corners(),
            margin: d.decision_margin(),
        })
        .collect();
    found.sort_by_key(|f| f.id);
    let ids: Vec<u32> = found.iter().map(|f| f.id).collect();
    found.retain(|f| ids.iter().filter(|&&i| i == f.id).count() == 1);
    Ok(found)
}

/// The detector's picture of an 8-bit sRGB photo: linear luminance (Rec. 709 weights) scaled
/// to 8 bits. Edges are found at half the contrast in linear values, where a blurred edge
/// truly is (in sRGB values the black squares would shrink by a fraction of a pixel).
pub fn linear_grey(rgb: &image::RgbImage) -> Vec<u8> {
    let lut: Vec<f32> = (0..256)
        .map(|i| crate::load::image_io::srgb_to_linear(i as f32 / 255.0))
        .collect();
    rgb.pixels()
        .map(|p| {
            let y = 0.2126 * lut[p[0] as usize] + 0.7152 * lut[p[1] as usize] + 0.0722 * lut[p[2] as usize];
            (y * 255.0).round().clamp(0.0, 255.0) as u8
        })
        .collect()
}
