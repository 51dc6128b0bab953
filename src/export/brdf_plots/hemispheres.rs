//! Hemisphere maps: for a few lights, every view direction in orthographic projection, measured,
//! fitted and the relative residual side by side, each row with its colour bars.

use super::common::{axes, err, in_plane, mean, save, Brdf};
use crate::export::atomic::Sink;
use crate::export::plots::{colour_bar, font, ColourBar, ColourMap, Drawn, MapScale};
use crate::load::samples::Sample;
use crate::model::frame::Vec3;
use anyhow::Result;
use plotters::coord::Shift;
use plotters::prelude::*;

/// Incidence angles of the maps' lights (degrees).
pub const MAP_THETAS: [f64; 3] = [0.0, 40.0, 70.0];
/// A sample is shown on a hemisphere map when its light is within this of the map's (degrees).
pub const NEAR_LIGHT_DEG: f64 = 8.0;
/// Most rows of a capture's hemisphere maps (one per image, the images with the most samples).
pub const MAX_IMAGE_ROWS: usize = 6;
/// Measured samples on a hemisphere map are averaged in cells of this many screen pixels.
pub const CELL_PX: i32 = 6;

/// Disk radius of a hemisphere map in pixels.
const R: i32 = 110;

fn rows_note(capture: bool, dense: bool) -> &'static str {
    if capture {
        "one row per capture image, lit from the image's mean light direction; measured and \
         residual: the image's samples at their view directions, averaged in cells"
    } else if dense {
        "lights across the fibres (from -B) at theta_i 0, 40, 70 deg. Measured: the file evaluated densely"
    } else {
        "lights across the fibres (from -B) at theta_i 0, 40, 70 deg; measured and residual: the \
         samples whose light is within 8 deg of the row's"
    }
}

/// One row of hemisphere maps: a light, its label, and the samples drawn with it.
struct Row<'a> {
    label: String,
    light: Vec3,
    samples: Vec<&'a Sample>,
}

/// The rows: with a measured file, lights across the fibres at [`MAP_THETAS`]; for a capture, one
/// row per image (at most [`MAX_IMAGE_ROWS`], those with the most samples) with the image's mean
/// light and all its samples; otherwise lights at [`MAP_THETAS`] with the samples whose light
/// lies within [`NEAR_LIGHT_DEG`].
fn rows<'a>(b_axis: &Vec3, dense: bool, samples: &'a [Sample]) -> (Vec<Row<'a>>, bool) {
    use crate::load::samples::Origin;
    let mut by_image: std::collections::BTreeMap<u32, Vec<&Sample>> = Default::default();
    for s in samples {
        if let Origin::Pixel { image, .. } = s.origin {
            by_image.entry(image).or_default().push(s);
        }
    }
    if !dense && !by_image.is_empty() {
        let mut images: Vec<(u32, Vec<&Sample>)> = by_image.into_iter().collect();
        images.sort_by_key(|(k, v)| (std::cmp::Reverse(v.len()), *k));
        images.truncate(MAX_IMAGE_ROWS);
        images.sort_by_key(|(k, _)| *k);
        let rows = images
            .into_iter()
            .map(|(k, v)| {
                let sum = v.iter().fold(Vec3::zeros(), |a, s| a + s.l);
                let light = if sum.norm() > 0.0 {
                    sum.normalize()
                } else {
                    Vec3::z()
                };
                let theta = light.z.clamp(-1.0, 1.0).acos().to_degrees();
                let phi = light.y.atan2(light.x).to_degrees();
                Row {
                    label: format!("image {k}: light {theta:.0},{phi:.0} deg"),
                    light,
                    samples: v,
                }
            })
            .collect();
        return (rows, true);
    }
    let rows = MAP_THETAS
        .iter()
        .map(|&theta_i| {
            let light = in_plane(b_axis, -theta_i);
            let near = if dense {
                vec![]
            } else {
                samples
                    .iter()
                    .filter(|s| {
                        s.l.dot(&light).clamp(-1.0, 1.0).acos().to_degrees() <= NEAR_LIGHT_DEG
                    })
                    .collect()
            };
            Row {
                label: format!("theta_i {theta_i:.0} deg"),
                light,
                samples: near,
            }
        })
        .collect();
    (rows, false)
}

/// What a figure of hemisphere maps shows (the request of [`hemispheres`]).
pub struct HemispherePlot<'a> {
    pub title: &'a str,
    /// The fibre azimuth psi (degrees): T lies at it, B = N x T.
    pub psi_deg: f64,
    /// The data's channels: 1 (grey) or 3 (RGB); the maps show their mean.
    pub channels: usize,
    /// The fitted model.
    pub fitted: Brdf<'a>,
    /// The measured file, when the data is one: the maps are then dense.
    pub measured: Option<Brdf<'a>>,
    /// The measured samples.
    pub samples: &'a [Sample],
}

/// Hemisphere maps, one row per light: columns measured, fitted and the relative residual
/// (fitted - measured) / measured in percent, each row with a colour bar of its log BRDF scale
/// and the residual colour bar (symmetric, sized to the 99th percentile of |residual|). With
/// `measured` (a measured file) the maps are dense and the lights lie across the fibres at
/// [`MAP_THETAS`]; a capture gets a row per image (see [`rows`]) with its samples at their view
/// directions, averaged in [`CELL_PX`] cells (an orthographic image is one cell: one view);
/// goniometric data the samples near each row's light. Values: the channel mean. Returns what
/// it drew (`points`: the samples drawn; `note`: what the rows are, for the report).
pub fn hemispheres(path: Sink, plot: &HemispherePlot) -> Result<Drawn> {
    font();
    let side = 2 * R as u32 + 40;
    let (t_axis, b_axis) = axes(plot.psi_deg);
    let disk = Disk { t_axis, b_axis };
    let dense = plot.measured.is_some();
    let (rows, capture) = rows(&b_axis, dense, plot.samples);
    let bar_w = 100u32;
    let (cols, nrows) = (3u32, rows.len() as u32);
    let (w, h) = (side * cols + 2 * bar_w, (side + 34) * nrows + 100);
    let mut buf = vec![0u8; (w * h * 3) as usize];
    let mut drawn = Drawn::default();
    let mut maps = Vec::new();
    for row in &rows {
        maps.push(Maps::new(&disk, row, plot));
        drawn.points += row.samples.len();
    }
    // the residual scale over every row: dense residuals or the cells'
    let residuals: Vec<Vec<Option<f64>>> = maps.iter().map(Maps::dense_residuals).collect();
    let res_scale = MapScale::symmetric(
        residuals.iter().flatten().flatten().copied().chain(
            maps.iter()
                .flat_map(|m| m.cells.iter().filter_map(|c| c.residual)),
        ),
        99.0,
        1e-6,
        "(fitted - measured) / measured [%]",
    );
    {
        let root = BitMapBackend::with_buffer(&mut buf, (w, h)).into_drawing_area();
        root.fill(&WHITE).map_err(err)?;
        let root = root.titled(plot.title, ("sans-serif", 20)).map_err(err)?;
        let (body, legend) = root.split_vertically(h as i32 - 70);
        let row_areas = body.split_evenly((nrows as usize, 1));
        let layout = Layout {
            disk,
            side,
            cols,
            bar_w,
            dense,
            res_scale,
        };
        let mut res_bar = None;
        for (r, (row, m)) in rows.iter().zip(&maps).enumerate() {
            let maps = RowMaps {
                row,
                maps: m,
                residual: &residuals[r],
            };
            let rb = layout.draw_row(&row_areas[r], &maps, &mut drawn)?;
            if r == 0 {
                res_bar = Some(rb);
            }
        }
        // the residual bar last (one scale for every row)
        drawn.colour_bars.extend(res_bar);
        draw_legend(&legend, plot.psi_deg, rows_note(capture, dense))?;
    }
    save(path, w, h, buf)?;
    drawn.note = format!("Rows: {}.", rows_note(capture, dense));
    drawn.x_label = "view direction x = v.B".into();
    drawn.y_label = "view direction y = v.T".into();
    Ok(drawn)
}

/// The orthographic projection of the view hemisphere onto a disk of [`R`] pixels, seen from
/// above: right = +B, up = +T.
struct Disk {
    t_axis: Vec3,
    b_axis: Vec3,
}

impl Disk {
    /// The view direction under pixel (`px`, `py`) from the disk's centre (None outside it).
    fn view(&self, px: i32, py: i32) -> Option<Vec3> {
        let (x, y) = (px as f64 / R as f64, -(py as f64) / R as f64);
        let r2 = x * x + y * y;
        (r2 < 0.995).then(|| self.b_axis * x + self.t_axis * y + Vec3::z() * (1.0 - r2).sqrt())
    }

    /// The pixel from the disk's centre of a direction with (x, y) = (d.B, d.T).
    fn pixel(x: f64, y: f64) -> (i32, i32) {
        (
            (x * R as f64).round() as i32,
            (-y * R as f64).round() as i32,
        )
    }

    /// The value of `f` (the channel mean) for light `l` at every pixel of the disk's square,
    /// row by row from the top (None outside the disk or where `f` has none).
    fn grid(&self, l: &Vec3, f: Brdf, channels: usize) -> Vec<Option<f64>> {
        let mut g = Vec::with_capacity(((2 * R + 1) * (2 * R + 1)) as usize);
        for py in -R..=R {
            for px in -R..=R {
                g.push(
                    self.view(px, py)
                        .and_then(|v| f(l, &v))
                        .map(|b| mean(&b, channels)),
                );
            }
        }
        g
    }
}

/// A cell of a map's measured samples: its centre pixel (from the disk's centre), the mean
/// measured value and the mean relative residual in percent (None: no fitted value).
struct Cell {
    px: i32,
    py: i32,
    measured: f64,
    residual: Option<f64>,
}

/// One row's maps: the dense grids (fitted, and measured with a measured file), the measured
/// cells, and the range of the row's log BRDF scale.
struct Maps {
    fit: Vec<Option<f64>>,
    meas: Option<Vec<Option<f64>>>,
    cells: Vec<Cell>,
    lo: f64,
    hi: f64,
}

impl Maps {
    fn new(disk: &Disk, row: &Row, plot: &HemispherePlot) -> Self {
        let channels = plot.channels;
        let l = row.light;
        let fit = disk.grid(&l, plot.fitted, channels);
        let meas = plot.measured.map(|f| disk.grid(&l, f, channels));
        let cells = cells(disk, row, plot.fitted, channels);
        let vals = fit
            .iter()
            .flatten()
            .chain(meas.iter().flatten().flatten())
            .copied()
            .chain(cells.iter().map(|c| c.measured))
            .filter(|v| *v > 0.0 && v.is_finite());
        let (lo, hi) = vals.fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
            (a.min(v), b.max(v))
        });
        let (lo, hi) = if lo.is_finite() {
            (lo, hi.max(lo * (1.0 + 1e-9)))
        } else {
            (1e-3, 1.0)
        };
        Self {
            fit,
            meas,
            cells,
            lo,
            hi,
        }
    }

    /// The dense relative residual in percent, pixel by pixel (empty without a measured file).
    fn dense_residuals(&self) -> Vec<Option<f64>> {
        match &self.meas {
            Some(meas) => meas
                .iter()
                .zip(&self.fit)
                .map(|(a, b)| match (a, b) {
                    (Some(a), Some(b)) if *a > 0.0 => Some(100.0 * (b - a) / a),
                    _ => None,
                })
                .collect(),
            None => vec![],
        }
    }
}

/// The row's samples at their view directions, averaged in [`CELL_PX`] cells: the measured
/// channel mean and the relative residual of `fitted` in percent.
fn cells(disk: &Disk, row: &Row, fitted: Brdf, channels: usize) -> Vec<Cell> {
    let mut cells: std::collections::BTreeMap<(i32, i32), (f64, f64, usize, usize)> =
        Default::default();
    for s in &row.samples {
        let (px, py) = Disk::pixel(s.v.dot(&disk.b_axis), s.v.dot(&disk.t_axis));
        let key = (px.div_euclid(CELL_PX), py.div_euclid(CELL_PX));
        let e = cells.entry(key).or_insert((0.0, 0.0, 0, 0));
        let d = mean(&s.value, channels);
        e.0 += d;
        e.2 += 1;
        if let Some(m) = fitted(&s.l, &s.v) {
            if d > 0.0 {
                e.1 += 100.0 * (mean(&m, channels) - d) / d;
                e.3 += 1;
            }
        }
    }
    cells
        .into_iter()
        .map(|((cx, cy), (d, r, n, nr))| Cell {
            px: cx * CELL_PX + CELL_PX / 2,
            py: cy * CELL_PX + CELL_PX / 2,
            measured: d / n as f64,
            residual: (nr > 0).then(|| r / nr as f64),
        })
        .collect()
}

/// What one row of the figure draws: its light, maps and dense residuals.
struct RowMaps<'a> {
    row: &'a Row<'a>,
    maps: &'a Maps,
    /// The dense relative residual in percent (empty without a measured file).
    residual: &'a [Option<f64>],
}

/// How the rows are laid out and coloured: the projection, the disks' square (`side` pixels,
/// `cols` of them), the colour bars' width, and the residual scale shared by every row.
struct Layout {
    disk: Disk,
    side: u32,
    cols: u32,
    bar_w: u32,
    /// The measured column is a measured file evaluated densely.
    dense: bool,
    res_scale: MapScale,
}

type Area<'a> = DrawingArea<BitMapBackend<'a>, Shift>;

impl Layout {
    /// Draw one row into `area`: its three disks, then its log colour bar and the residual colour
    /// bar. Notes the panels and the log bar in `drawn`; returns the residual bar.
    fn draw_row(&self, area: &Area, maps: &RowMaps, drawn: &mut Drawn) -> Result<ColourBar> {
        let (disks, bars) = area.split_horizontally(self.side * self.cols);
        let (bar_log, bar_res) = bars.split_horizontally(self.bar_w);
        let panels = disks.split_evenly((1, 3));
        let log_scale = MapScale {
            lo: maps.maps.lo,
            hi: maps.maps.hi,
            log: true,
            map: ColourMap::Sequential,
            label: "BRDF [1/sr] (log)".into(),
        };
        for (col, area) in panels.iter().enumerate() {
            let name = self.draw_panel(area, col, maps, &log_scale)?;
            drawn.panels.push(format!("{}: {name}", maps.row.label));
        }
        let bar_log = bar_log.margin(18, 18, 4, 4);
        drawn.colour_bars.push(colour_bar(&bar_log, &log_scale)?);
        let bar_res = bar_res.margin(18, 18, 4, 4);
        colour_bar(&bar_res, &self.res_scale)
    }

    /// Draw column `col` (measured, fitted, residual) of a row into `area`: the row's light above
    /// the first, the panel's name, the disk and its content, the light's mirror direction.
    /// Returns the panel's name.
    fn draw_panel(
        &self,
        area: &Area,
        col: usize,
        maps: &RowMaps,
        log_scale: &MapScale,
    ) -> Result<String> {
        let (row, m) = (maps.row, maps.maps);
        let name = match col {
            0 if self.dense => "measured (dense)".to_string(),
            0 => format!("measured ({} samples)", row.samples.len()),
            1 => "fitted".to_string(),
            _ => "residual (fitted - measured) / measured".to_string(),
        };
        // the row's light above its first panel, each panel's content below it
        if col == 0 {
            area.draw(&Text::new(row.label.clone(), (8, 0), ("sans-serif", 13)))
                .map_err(err)?;
        }
        area.draw(&Text::new(name.clone(), (8, 15), ("sans-serif", 11)))
            .map_err(err)?;
        let centre = (self.side as i32 / 2, R + 32);
        area.draw(&Circle::new(centre, R, BLACK.stroke_width(1)))
            .map_err(err)?;
        let grid: Option<&[Option<f64>]> = match col {
            0 => m.meas.as_deref(),
            1 => Some(&m.fit),
            _ => m.meas.as_ref().map(|_| maps.residual),
        };
        if let Some(g) = grid {
            let scale = if col == 2 { &self.res_scale } else { log_scale };
            draw_grid(area, centre, g, scale)?;
        } else {
            self.draw_cells(area, centre, col, &m.cells, log_scale)?;
        }
        // the light's mirror direction, for orientation
        let (cx, cy) = centre;
        let (mx, my) = (
            -row.light.dot(&self.disk.b_axis),
            -row.light.dot(&self.disk.t_axis),
        );
        let (mx, my) = Disk::pixel(mx, my);
        area.draw(&Cross::new((cx + mx, cy + my), 5, BLACK.stroke_width(1)))
            .map_err(err)?;
        Ok(name)
    }

    /// Draw the measured cells around `centre` of column `col`: the measured value on the log
    /// scale (column 0), else the residual where there is one; each with a dark border.
    fn draw_cells(
        &self,
        area: &Area,
        centre: (i32, i32),
        col: usize,
        cells: &[Cell],
        log_scale: &MapScale,
    ) -> Result<()> {
        let (cx, cy) = centre;
        for cell in cells {
            let (px, py) = (cell.px, cell.py);
            let c = match (col, cell.residual) {
                (0, _) => log_scale.colour(cell.measured),
                (_, Some(r)) => self.res_scale.colour(r),
                _ => continue,
            };
            let half = CELL_PX / 2 + 1;
            let rect = [
                (cx + px - half, cy + py - half),
                (cx + px + half, cy + py + half),
            ];
            area.draw(&Rectangle::new(rect, c.filled())).map_err(err)?;
            area.draw(&Rectangle::new(rect, BLACK.mix(0.6)))
                .map_err(err)?;
        }
        Ok(())
    }
}

/// Draw a dense grid ([`Disk::grid`]'s order) around `centre` on `scale`, pixel by pixel.
fn draw_grid(area: &Area, centre: (i32, i32), g: &[Option<f64>], scale: &MapScale) -> Result<()> {
    let (cx, cy) = centre;
    let mut k = 0;
    for py in -R..=R {
        for px in -R..=R {
            if let Some(v) = g[k] {
                area.draw_pixel((cx + px, cy + py), &scale.colour(v))
                    .map_err(err)?;
            }
            k += 1;
        }
    }
    Ok(())
}

/// The figure's legend: the projection, what the rows are (`rows_are`), the colours.
fn draw_legend(legend: &Area, psi_deg: f64, rows_are: &str) -> Result<()> {
    for (i, line) in [
        format!(
            "Orthographic view hemisphere: right = +B, up = +T (fibres at {psi_deg:.1} deg); x = mirror direction of the row's light."
        ),
        format!("Rows: {rows_are}."),
        "Colour: BRDF on a log scale (channel mean, one scale per row, left bar). Residual: blue = fitted below measured, red = above (right bar, percent).".to_string(),
    ]
    .into_iter()
    .enumerate()
    {
        legend
            .draw(&Text::new(line, (8, 4 + 16 * i as i32), ("sans-serif", 11)))
            .map_err(err)?;
    }
    Ok(())
}
