//! `fibrefit board`: a printable calibration board (`board.png`) and its geometry
//! (`board.toml`) for photographing a swatch.

use crate::board::{draw, BoardLayout, BoardSpec, Paper};
use crate::export::atomic::Outputs;
use anyhow::Result;
use std::path::{Path, PathBuf};

/// What `fibrefit board` is asked.
#[derive(Clone, Debug)]
pub struct BoardRequest {
    /// Paper: `a4`, `letter` or `a3`.
    pub paper: String,
    /// The window's side in mm (square).
    pub window_mm: f64,
    /// Pixels per inch of `board.png`.
    pub dpi: u32,
    /// The reference patch's linear reflectance.
    pub patch_reflectance: f64,
}

impl Default for BoardRequest {
    fn default() -> Self {
        let d = BoardSpec::default();
        Self {
            paper: d.paper.name().to_string(),
            window_mm: d.window_mm,
            dpi: d.dpi,
            patch_reflectance: d.patch_reflectance,
        }
    }
}

/// What was written.
#[derive(Clone, Debug)]
pub struct BoardOutcome {
    /// `DIR/board.png`, `DIR/board.pdf` and `DIR/board.toml`.
    pub files: Vec<PathBuf>,
    /// How many markers the board has.
    pub markers: usize,
    /// The window `[x0, y0, x1, y1]` in mm.
    pub window_mm: [f64; 4],
}

/// Lay out the board and write `out/board.png`, `out/board.pdf` (the same picture as a page of
/// its printed size) and `out/board.toml` together (nothing is written when the request is
/// refused).
pub fn board(req: &BoardRequest, out: &Path) -> Result<BoardOutcome> {
    let spec = BoardSpec {
        paper: Paper::parse(&req.paper)?,
        window_mm: req.window_mm,
        dpi: req.dpi,
        patch_reflectance: req.patch_reflectance,
    };
    let layout = BoardLayout::new(&spec)?;
    let file = layout.file();
    let picture = draw::picture(&layout)?;
    let png = draw::png_bytes(&picture, spec.dpi)?;
    let pdf = draw::pdf_bytes(&picture, spec.dpi);
    let toml = file.to_toml()?;
    let mut outs = Outputs::new(&[]);
    let dir = outs.dir(out, "--out")?;
    let (png_path, toml_path) = (dir.join("board.png"), dir.join("board.toml"));
    let pdf_path = dir.join("board.pdf");
    let png_id = outs.file(&png_path, "--out")?;
    let pdf_id = outs.file(&pdf_path, "--out")?;
    let toml_id = outs.file(&toml_path, "--out")?;
    outs.put(png_id, &png)?;
    outs.put(pdf_id, &pdf)?;
    outs.put(toml_id, toml.as_bytes())?;
    outs.commit()?;
    Ok(BoardOutcome {
        files: vec![png_path, pdf_path, toml_path],
        markers: file.marker.len(),
        window_mm: file.window_mm,
    })
}
