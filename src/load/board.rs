//! `board.toml`: a printed calibration board's geometry (written by `fibrefit board`, read by
//! `fibrefit calibrate` and by the synthetic photos). Every length is in millimetres in the
//! **board frame**: origin at the window's centre, x to the right, y up the page, z out of the
//! paper (the swatch frame of captures).

use anyhow::{bail, Context, Result};
use serde::{Deserialize, Serialize};
use std::path::Path;

/// The marker family every board uses (the AprilTag library's 36h11 tags).
pub const FAMILY: &str = "tag36h11";

/// A board as `board.toml` describes it.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct BoardFile {
    /// The marker family (`tag36h11`).
    pub family: String,
    /// The paper size the board was laid out for (`a4`, `letter`, `a3`).
    pub paper: String,
    /// Resolution of `board.png` (pixels per inch): print it at 100 %.
    pub dpi: u32,
    /// Size of `board.png` in pixels, [width, height].
    pub png_px: [u32; 2],
    /// `[x0, y0, x1, y1]`: the rectangle `board.png` covers exactly; its pixel (0, 0) is the
    /// top-left corner (x0, y1).
    pub paper_mm: [f64; 4],
    /// `[x0, y0, x1, y1]`: the window where the swatch lies (centred on the origin).
    pub window_mm: [f64; 4],
    /// The grey reference patch.
    pub patch: Patch,
    /// The scale bar (100 mm as printed: measure it to check the print scale).
    pub scale_bar: ScaleBar,
    /// Every marker, by id.
    pub marker: Vec<Marker>,
}

/// The reference patch: a uniform grey of known linear reflectance.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Patch {
    /// `[x0, y0, x1, y1]` in mm.
    pub rect_mm: [f64; 4],
    /// Linear reflectance: the value the PNG prints (its sRGB grey decoded), or the measured
    /// value of the print when the user edits it.
    pub reflectance: f64,
}

/// The printed scale bar.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct ScaleBar {
    /// `[x0, y0, x1, y1]` in mm (its length x1 - x0 is 100 mm to the nearest pixel).
    pub rect_mm: [f64; 4],
}

/// One marker: its id in the family and its black border's outer corners.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Marker {
    /// Id in the family.
    pub id: u32,
    /// The black border's outer corners `[x, y]` in mm, in the detector's order: the printed
    /// tag's bottom-left, bottom-right, top-right, top-left.
    pub corners_mm: [[f64; 2]; 4],
}

impl BoardFile {
    /// Read and check `path`.
    pub fn read(path: &Path) -> Result<Self> {
        let text = super::input::read_text_as(path, "board file")?;
        let board: BoardFile =
            toml::from_str(&text).with_context(|| format!("{}: not a board file", path.display()))?;
        board
            .check()
            .with_context(|| format!("{}: not a usable board", path.display()))?;
        Ok(board)
    }

    /// Refuse what no printed board can be.
    pub fn check(&self) -> Result<()> {
        if self.family != FAMILY {
            bail!("family = '{}': only {FAMILY} boards are read", self.family);
        }
        let finite = |r: &[f64]| r.iter().all(|v| v.is_finite());
        for (name, r) in [
            ("paper_mm", &self.paper_mm),
            ("window_mm", &self.window_mm),
            ("patch.rect_mm", &self.patch.rect_mm),
            ("scale_bar.rect_mm", &self.scale_bar.rect_mm),
        ] {
            if !finite(r) || r[2] <= r[0] || r[3] <= r[1] {
                bail!("{name} = {r:?}: expected [x0, y0, x1, y1] with x0 < x1, y0 < y1");
            }
        }
        if !(self.patch.reflectance > 0.0 && self.patch.reflectance <= 1.0) {
            bail!(
                "patch.reflectance = {}: expected a linear reflectance in (0, 1]",
                self.patch.reflectance
            );
        }
        if self.marker.len() < 4 {
            bail!("{} markers: a board needs at least 4", self.marker.len());
        }
        let mut ids: Vec<u32> = self.marker.iter().map(|m| m.id).collect();
        ids.sort_unstable();
        if ids.windows(2).any(|w| w[0] == w[1]) {
            bail!("a marker id appears twice");
        }
        if self
            .marker
            .iter()
            .any(|m| !m.corners_mm.iter().flatten().all(|v| v.is_finite()))
        {
            bail!("a marker corner is not a finite number");
        }
        Ok(())
    }

    /// The marker with `id`, if the board has it.
    pub fn marker(&self, id: u32) -> Option<&Marker> {
        self.marker.iter().find(|m| m.id == id)
    }

    /// Millimetres per pixel of `board.png`.
    pub fn mm_per_px(&self) -> f64 {
        (self.paper_mm[2] - self.paper_mm[0]) / self.png_px[0] as f64
    }

    /// The board frame's point (mm) at `board.png`'s pixel position `(u, v)` (pixel edges at
    /// integers: pixel (0, 0) covers [0, 1] x [0, 1]).
    pub fn png_to_mm(&self, u: f64, v: f64) -> [f64; 2] {
        let s = self.mm_per_px();
        [self.paper_mm[0] + u * s, self.paper_mm[3] - v * s]
    }

    /// `board.png`'s pixel position of the board frame's point `(x, y)` (mm).
    pub fn mm_to_png(&self, x: f64, y: f64) -> [f64; 2] {
        let s = self.mm_per_px();
        [(x - self.paper_mm[0]) / s, (self.paper_mm[3] - y) / s]
    }

    /// The file's text.
    pub fn to_toml(&self) -> Result<String> {
        let body = toml::to_string(self).context("board.toml")?;
        Ok(format!(
            "# fibrefit calibration board: print board.png at 100 % (check the 100 mm scale bar).\n\
             # Lengths in mm in the board frame: origin at the window's centre, x right, y up the\n\
             # page, z out of the paper. Marker corners: the black border's outer corners, in the\n\
             # detector's order (the printed tag's bottom-left, bottom-right, top-right, top-left).\n\
             # Edit patch.reflectance after measuring the printed patch.\n{body}"
        ))
    }
}
