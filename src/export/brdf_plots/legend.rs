//! A figure's legend in a strip of its own, above the panels, where no data or curve lies.

use super::common::err;
use anyhow::Result;
use plotters::coord::Shift;
use plotters::prelude::*;

/// Legend entries per row of the strip.
const COLUMNS: usize = 3;
/// Height of one row of entries (pixels).
const ROW_PX: u32 = 18;

/// How an entry is marked.
pub(super) enum Mark {
    /// A curve: its colour, its width and whether it is dashed.
    Line {
        colour: RGBColor,
        width: u32,
        dashed: bool,
    },
    /// A shaded band in this colour.
    Band(RGBColor),
    /// A filled dot.
    Dot(RGBColor),
    /// A grey ring.
    Ring,
}

/// One entry of a legend: its mark and label.
pub(super) struct Entry {
    pub label: String,
    pub mark: Mark,
}

/// The strip's height (pixels) for `n` entries.
pub(super) fn height(n: usize) -> u32 {
    n.div_ceil(COLUMNS).max(1) as u32 * ROW_PX + 14
}

/// Draw `entries` into `strip` ([`COLUMNS`] to a row, in a box); returns the box's (left,
/// top, right, bottom) in the picture's pixels.
pub(super) fn draw(strip: &DrawingArea<BitMapBackend<'_>, Shift>, entries: &[Entry]) -> Result<(i32, i32, i32, i32)> {
    let (w, h) = strip.dim_in_pixel();
    let (x0, y0) = strip.get_base_pixel();
    let col_w = (w as i32 - 40) / COLUMNS as i32;
    let (left, top, right, bottom) = (10, 4, w as i32 - 10, h as i32 - 4);
    strip
        .draw(&Rectangle::new([(left, top), (right, bottom)], BLACK.stroke_width(1)))
        .map_err(err)?;
    for (k, e) in entries.iter().enumerate() {
        let x = 20 + col_w * (k % COLUMNS) as i32;
        let y = top + 6 + ROW_PX as i32 * (k / COLUMNS) as i32 + ROW_PX as i32 / 2 - 2;
        match e.mark {
            Mark::Line {
                colour,
                width,
                dashed,
            } => {
                let style = colour.stroke_width(width);
                let segs: Vec<(i32, i32)> = if dashed {
                    vec![(x, x + 6), (x + 10, x + 16), (x + 20, x + 26)]
                } else {
                    vec![(x, x + 26)]
                };
                for (a, b) in segs {
                    strip
                        .draw(&PathElement::new(vec![(a, y), (b, y)], style))
                        .map_err(err)?;
                }
            }
            Mark::Band(c) => strip
                .draw(&Rectangle::new(
                    [(x, y - 5), (x + 26, y + 5)],
                    c.mix(0.16).filled(),
                ))
                .map_err(err)?,
            Mark::Dot(c) => strip
                .draw(&Circle::new((x + 13, y), 3, c.filled()))
                .map_err(err)?,
            Mark::Ring => strip
                .draw(&Circle::new((x + 13, y), 5, BLACK.mix(0.7).stroke_width(1)))
                .map_err(err)?,
        }
        strip
            .draw(&Text::new(
                e.label.clone(),
                (x + 34, y - 6),
                ("sans-serif", 11),
            ))
            .map_err(err)?;
    }
    Ok((x0 + left, y0 + top, x0 + right, y0 + bottom))
}
