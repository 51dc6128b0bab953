//! The printable calibration board (`fibrefit board`) and finding its markers in pictures.
//!
//! A board is laid out in whole pixels of `board.png` (so every edge the file states is an
//! edge of printed pixels) and described in millimetres in the board frame by
//! [`crate::load::board::BoardFile`]: AprilTag 36h11 markers on a grid around a square window
//! where the swatch lies, a grey reference patch and a 100 mm scale bar below.

pub mod camera;
pub mod detect;
pub mod draw;

// Debian's libapriltag keeps the image functions (`image_u8_create_alignment`,
// `image_u8_destroy`) that the bindings call in a second library, libapriltag-utils.
#[link(name = "apriltag-utils")]
extern "C" {}

use crate::load::board::{BoardFile, Marker, Patch, ScaleBar, FAMILY};
use anyhow::{bail, Result};

/// Paper sizes (portrait, mm).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Paper {
    /// ISO A4, 210 x 297 mm.
    A4,
    /// US Letter, 215.9 x 279.4 mm.
    Letter,
    /// ISO A3, 297 x 420 mm.
    A3,
}

impl Paper {
    /// The paper named `name` (`--paper`).
    pub fn parse(name: &str) -> Result<Self> {
        Ok(match name.to_ascii_lowercase().as_str() {
            "a4" => Paper::A4,
            "letter" => Paper::Letter,
            "a3" => Paper::A3,
            _ => bail!("--paper {name}: expected a4, letter or a3"),
        })
    }

    /// Its name as the option spells it.
    pub fn name(self) -> &'static str {
        match self {
            Paper::A4 => "a4",
            Paper::Letter => "letter",
            Paper::A3 => "a3",
        }
    }

    /// Width and height in mm.
    pub fn size_mm(self) -> [f64; 2] {
        match self {
            Paper::A4 => [210.0, 297.0],
            Paper::Letter => [215.9, 279.4],
            Paper::A3 => [297.0, 420.0],
        }
    }
}

/// What the user asks of a board.
#[derive(Clone, Debug)]
pub struct BoardSpec {
    /// The paper.
    pub paper: Paper,
    /// The window's side (mm; the window is square).
    pub window_mm: f64,
    /// Pixels per inch of `board.png`.
    pub dpi: u32,
    /// The reference patch's linear reflectance (printed as its sRGB grey).
    pub patch_reflectance: f64,
}

impl Default for BoardSpec {
    fn default() -> Self {
        Self {
            paper: Paper::A4,
            window_mm: 60.0,
            dpi: 300,
            patch_reflectance: 0.5,
        }
    }
}

/// Side of a marker's black border (mm, to the nearest pixel): 8 cells of 2 mm.
const TAG_MM: f64 = 16.0;
/// Cells of a 36h11 tag across its black border (its white ring adds one each side).
const TAG_CELLS: i64 = 8;
/// Blank paper kept at each edge for printers' margins (mm).
const MARGIN_MM: f64 = 10.0;
/// Height of the band under the markers holding the patch and the scale bar (mm).
const BAND_MM: f64 = 28.0;
/// The reference patch's side (mm).
const PATCH_MM: f64 = 20.0;
/// Fewest markers a board may have.
const MIN_MARKERS: usize = 12;

/// A board laid out in pixels of `board.png`: what [`draw::png`] draws and
/// [`BoardLayout::file`] describes.
#[derive(Clone, Debug)]
pub struct BoardLayout {
    /// The request.
    pub spec: BoardSpec,
    /// `board.png`'s size in pixels.
    pub size_px: [i64; 2],
    /// The window's centre (the board frame's origin), a pixel corner.
    pub origin_px: [i64; 2],
    /// Pixels per marker cell.
    pub cell_px: i64,
    /// The window `[u0, v0, u1, v1]` (pixel edges).
    pub window_px: [i64; 4],
    /// The reference patch `[u0, v0, u1, v1]`.
    pub patch_px: [i64; 4],
    /// The scale bar `[u0, v0, u1, v1]` and its 10 mm ticks' left edges.
    pub bar_px: [i64; 4],
    /// The ticks: `[u0, v0, u1, v1]` each.
    pub ticks_px: Vec<[i64; 4]>,
    /// Every marker: id and the top-left pixel of its black border.
    pub markers: Vec<(u32, [i64; 2])>,
}

impl BoardLayout {
    /// Lay out `spec`, refused (naming the option) when the window leaves no room for a ring of
    /// markers on the paper or a value is out of range.
    pub fn new(spec: &BoardSpec) -> Result<Self> {
        if !(100..=1200).contains(&spec.dpi) {
            bail!("--dpi {}: expected 100 to 1200", spec.dpi);
        }
        if !(spec.patch_reflectance > 0.0 && spec.patch_reflectance <= 1.0) {
            bail!(
                "--patch-reflectance {}: expected a linear reflectance in (0, 1]",
                spec.patch_reflectance
            );
        }
        if !(spec.window_mm.is_finite() && spec.window_mm >= 10.0) {
            bail!(
                "--window-mm {}: expected a side of at least 10 mm",
                spec.window_mm
            );
        }
        let s = 25.4 / spec.dpi as f64; // mm per pixel
        let px = |mm: f64| (mm / s).round() as i64;
        let [pw, ph] = spec.paper.size_mm();
        let size_px = [px(pw), px(ph)];
        let margin = px(MARGIN_MM);
        let cell_px = px(TAG_MM / TAG_CELLS as f64).max(2);
        let band_top = size_px[1] - margin - px(BAND_MM);
        let origin_px = [size_px[0] / 2, (margin + band_top) / 2];
        let half = px(spec.window_mm) / 2;
        let window_px = [
            origin_px[0] - half,
            origin_px[1] - half,
            origin_px[0] + half,
            origin_px[1] + half,
        ];
        // the marker grid: centred on the window, one cell between markers' white rings
        let total = (TAG_CELLS + 2) * cell_px;
        let pitch = total + 2 * cell_px;
        let room = [margin, margin, size_px[0] - margin, band_top];
        let too_big = || {
            anyhow::anyhow!(
                "--window-mm {}: the window leaves no room for a ring of markers on {} paper \
                 ({} x {} mm)",
                spec.window_mm,
                spec.paper.name(),
                pw,
                ph
            )
        };
        if window_px[0] - total - cell_px < room[0] || window_px[1] - total - cell_px < room[1] {
            return Err(too_big());
        }
        let mut markers = Vec::new();
        let reach = size_px[0].max(size_px[1]) / pitch + 1;
        for j in -reach..=reach {
            for i in -reach..=reach {
                let c = [origin_px[0] + i * pitch, origin_px[1] + j * pitch];
                let outer = [
                    c[0] - total / 2,
                    c[1] - total / 2,
                    c[0] + total / 2,
                    c[1] + total / 2,
                ];
                let inside = outer[0] >= room[0]
                    && outer[1] >= room[1]
                    && outer[2] <= room[2]
                    && outer[3] <= room[3];
                let clear = outer[2] + cell_px <= window_px[0]
                    || outer[0] - cell_px >= window_px[2]
                    || outer[3] + cell_px <= window_px[1]
                    || outer[1] - cell_px >= window_px[3];
                if inside && clear {
                    markers.push([outer[0] + cell_px, outer[1] + cell_px]);
                }
            }
        }
        if markers.len() < MIN_MARKERS {
            return Err(too_big());
        }
        // raster order (top row first), ids from 0
        markers.sort_by_key(|m| (m[1], m[0]));
        let markers = markers
            .into_iter()
            .enumerate()
            .map(|(k, m)| (k as u32, m))
            .collect();
        let band_mid = band_top + px(BAND_MM) / 2;
        let patch = px(PATCH_MM);
        let patch_px = [
            margin,
            band_mid - patch / 2,
            margin + patch,
            band_mid + patch / 2,
        ];
        let bar_u0 = patch_px[2] + px(10.0);
        let bar_px = [bar_u0, band_mid, bar_u0 + px(100.0), band_mid + px(2.0)];
        let ticks_px = (0..=10)
            .map(|k| {
                let u = bar_u0 + px(10.0 * k as f64);
                let w = px(0.4).max(1);
                let u = if k == 10 { u - w } else { u };
                [u, band_mid - px(if k % 5 == 0 { 6.0 } else { 4.0 }), u + w, band_mid]
            })
            .collect();
        Ok(Self {
            spec: spec.clone(),
            size_px,
            origin_px,
            cell_px,
            window_px,
            patch_px,
            bar_px,
            ticks_px,
            markers,
        })
    }

    /// Millimetres per pixel.
    pub fn mm_per_px(&self) -> f64 {
        25.4 / self.spec.dpi as f64
    }

    /// The board frame's point (mm) at the pixel corner `(u, v)`.
    fn mm(&self, u: i64, v: i64) -> [f64; 2] {
        let s = self.mm_per_px();
        [
            (u - self.origin_px[0]) as f64 * s,
            (self.origin_px[1] - v) as f64 * s,
        ]
    }

    /// A pixel rectangle `[u0, v0, u1, v1]` as `[x0, y0, x1, y1]` in mm.
    fn rect_mm(&self, r: [i64; 4]) -> [f64; 4] {
        let a = self.mm(r[0], r[3]);
        let b = self.mm(r[2], r[1]);
        [a[0], a[1], b[0], b[1]]
    }

    /// The board's description (`board.toml`).
    pub fn file(&self) -> BoardFile {
        let side = TAG_CELLS * self.cell_px;
        let marker = self
            .markers
            .iter()
            .map(|&(id, [u, v])| Marker {
                id,
                corners_mm: [
                    self.mm(u, v + side),
                    self.mm(u + side, v + side),
                    self.mm(u + side, v),
                    self.mm(u, v),
                ],
            })
            .collect();
        BoardFile {
            family: FAMILY.to_string(),
            paper: self.spec.paper.name().to_string(),
            dpi: self.spec.dpi,
            png_px: [self.size_px[0] as u32, self.size_px[1] as u32],
            paper_mm: self.rect_mm([0, 0, self.size_px[0], self.size_px[1]]),
            window_mm: self.rect_mm(self.window_px),
            patch: Patch {
                rect_mm: self.rect_mm(self.patch_px),
                reflectance: draw::printed_reflectance(self.spec.patch_reflectance),
            },
            scale_bar: ScaleBar {
                rect_mm: self.rect_mm(self.bar_px),
            },
            marker,
        }
    }
}
