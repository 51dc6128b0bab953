//! The plots a BRDF person expects: the fitted model as continuous curves along slices at fixed
//! incidence, with the measured points that lie near each slice, and hemisphere maps of measured,
//! fitted and residual values for a few incidence directions.
//!
//! Conventions (stated in the figures): directions in the swatch frame with the fibre tangent T at
//! the fitted azimuth psi and B = N x T. A slice lies in the T-N plane ("along the fibres") or in
//! the B-N plane ("across the fibres"): the light at theta_i on the negative side of the plane's
//! axis, the view at a signed angle theta_o, positive on the far side (forward, towards the
//! mirror direction), negative on the light's side (back). Values are the BRDF in 1/sr, the mean
//! over the channels. A hemisphere map shows every view direction for one light, in orthographic
//! projection seen from above: right = +B (the far side of a light coming from -B), up = +T.

use super::atomic::Sink;
use super::plots::{colour_bar, font, palette, tick_label, ticked, ColourMap, Drawn, MapScale};
use crate::load::samples::Sample;
use crate::model::frame::{FibreFrame, Vec3};
use anyhow::{anyhow, Result};
use plotters::prelude::*;

/// A BRDF per channel at (l, v) in the swatch frame; `None` where it is not defined (outside a
/// measured file's range).
pub type Brdf<'a> = &'a (dyn Fn(&Vec3, &Vec3) -> Option<[f64; 3]> + Sync);

/// A named BRDF drawn as a curve.
pub struct Curve<'a> {
    pub name: String,
    pub brdf: Brdf<'a>,
    /// Dashed (a measured file evaluated densely) rather than solid.
    pub dashed: bool,
}

/// Incidence angles of the slices and maps (degrees).
pub const SLICE_THETAS: [f64; 4] = [0.0, 30.0, 50.0, 70.0];
pub const MAP_THETAS: [f64; 3] = [0.0, 40.0, 70.0];
/// A measured sample lies near a slice when its theta_i is within this of the slice's (degrees)
/// and both directions are within this angle of the slice's plane (direction cosine 0.2).
pub const NEAR_THETA_DEG: f64 = 6.0;
pub const NEAR_PLANE_COSINE: f64 = 0.2;
/// A sample is shown on a hemisphere map when its light is within this of the map's (degrees).
pub const NEAR_LIGHT_DEG: f64 = 8.0;

fn err<E: std::fmt::Debug>(e: E) -> anyhow::Error {
    anyhow!("plot: {e:?}")
}

fn mean(v: &[f64; 3], channels: usize) -> f64 {
    v[..channels].iter().sum::<f64>() / channels as f64
}

/// Unit direction at signed angle `theta` (degrees) from N towards `axis`.
fn in_plane(axis: &Vec3, theta_deg: f64) -> Vec3 {
    let t = theta_deg.to_radians();
    axis * t.sin() + Vec3::z() * t.cos()
}

fn axes(psi_deg: f64) -> (Vec3, Vec3) {
    let p = psi_deg.to_radians();
    (
        Vec3::new(p.cos(), p.sin(), 0.0),
        Vec3::new(-p.sin(), p.cos(), 0.0),
    )
}

/// Measured samples near the slice at `theta_i` along (`across` false) or across the fibres:
/// (signed theta_o in degrees, channel mean, the sample).
pub fn near_slice(
    samples: &[Sample],
    psi_deg: f64,
    theta_i: f64,
    across: bool,
    channels: usize,
) -> Vec<(f64, f64, &Sample)> {
    samples
        .iter()
        .filter_map(|s| {
            let frame = FibreFrame::from_azimuth(s.fibre_azimuth.unwrap_or(psi_deg.to_radians()));
            let (l, v) = (frame.to_local(&s.l), frame.to_local(&s.v));
            // (in-plane, out-of-plane) components
            let (la, lo, va, vo) = if across {
                (l.b, l.t, v.b, v.t)
            } else {
                (l.t, l.b, v.t, v.b)
            };
            let ti = l.n.clamp(-1.0, 1.0).acos().to_degrees();
            if (ti - theta_i).abs() > NEAR_THETA_DEG
                || lo.abs() > NEAR_PLANE_COSINE
                || vo.abs() > NEAR_PLANE_COSINE
            {
                return None;
            }
            // the light on the negative side: flip when it is on the positive one (T ~ -T)
            let side = if la > 0.0 { -1.0 } else { 1.0 };
            Some((
                (side * va).atan2(v.n).to_degrees(),
                mean(&s.value, channels),
                s,
            ))
        })
        .collect()
}

/// Width of the theta_o bins in which the measured samples near a slice are averaged (degrees).
pub const BIN_DEG: f64 = 2.0;

/// Colour of channel `c` of `channels` (grey data: the palette's first colour).
fn channel_colour(c: usize, channels: usize) -> RGBColor {
    if channels == 1 {
        return palette(0);
    }
    [
        RGBColor(214, 39, 40),
        RGBColor(44, 160, 44),
        RGBColor(31, 90, 200),
    ][c.min(2)]
}

/// One bin of samples near a slice: mean theta_o, per channel the mean, the standard deviation
/// and the fit's mean at the same samples, and the count.
struct Bin {
    x: f64,
    mean: [f64; 3],
    sd: [f64; 3],
    fit: Option<[f64; 3]>,
    n: usize,
}

/// The values drawn of a BRDF triple: each of `ch` channels, or (`ch` 1 of RGB data) the mean.
fn pick(v: &[f64; 3], ch: usize, channels: usize) -> [f64; 3] {
    if ch == 1 {
        [mean(v, channels), 0.0, 0.0]
    } else {
        *v
    }
}

fn bin_samples(near: &[(f64, &Sample)], fit: Option<Brdf>, ch: usize, all: usize) -> Vec<Bin> {
    let channels = ch;
    let mut by: std::collections::BTreeMap<i64, Vec<(f64, &Sample)>> = Default::default();
    for &(x, s) in near {
        by.entry((x / BIN_DEG).floor() as i64)
            .or_default()
            .push((x, s));
    }
    by.into_values()
        .map(|pts| {
            let n = pts.len();
            let x = pts.iter().map(|p| p.0).sum::<f64>() / n as f64;
            let mut mean = [0.0; 3];
            let mut sd = [0.0; 3];
            for c in 0..channels {
                let val = |s: &Sample| pick(&s.value, ch, all)[c];
                let m = pts.iter().map(|p| val(p.1)).sum::<f64>() / n as f64;
                let v =
                    pts.iter().map(|p| (val(p.1) - m).powi(2)).sum::<f64>() / (n.max(2) - 1) as f64;
                mean[c] = m;
                sd[c] = if n > 1 { v.sqrt() } else { 0.0 };
            }
            let fit = fit.and_then(|f| {
                let mut acc = [0.0; 3];
                for p in &pts {
                    let v = pick(&f(&p.1.l, &p.1.v)?, ch, all);
                    for c in 0..3 {
                        acc[c] += v[c] / n as f64;
                    }
                }
                Some(acc)
            });
            Bin {
                x,
                mean,
                sd,
                fit,
                n,
            }
        })
        .collect()
}

/// Slices: rows along / across the fibres, one column per incidence in [`SLICE_THETAS`]; each
/// panel the curves over theta_o in [-85, 85] deg (one per channel for RGB data) and the measured
/// samples near the slice averaged in [`BIN_DEG`] bins of theta_o: the mean with a +-1 standard
/// deviation bar (a capture image puts thousands of pixels at nearly one view), and the fit's
/// mean at the same samples as a ring. Returns what it drew (`points`: the samples near a
/// slice).
#[allow(clippy::too_many_arguments)]
pub fn slices(
    path: Sink,
    title: &str,
    psi_deg: f64,
    channels: usize,
    curves: &[Curve],
    samples: &[Sample],
    log_y: bool,
) -> Result<Drawn> {
    font();
    let (cols, rows) = (SLICE_THETAS.len(), 2usize);
    let (w, h) = (380 * cols as u32, 340 * rows as u32 + 60);
    let mut buf = vec![0u8; (w * h * 3) as usize];
    let (t_axis, b_axis) = axes(psi_deg);
    let mut drawn = Drawn {
        x_label: "theta_o [deg] (+: far side)".into(),
        y_label: "BRDF [1/sr]".into(),
        ..Default::default()
    };
    // one curve per channel of RGB data, unless that makes more than 6 curves (the mean then)
    let ch = if channels == 3 && curves.len() <= 2 {
        3
    } else {
        1
    };
    drawn.note = if ch == 3 {
        "per channel (R, G, B)".into()
    } else if channels == 3 {
        "channel mean".into()
    } else {
        "grey".into()
    };
    let fit_curve = curves.last().filter(|c| !c.dashed).map(|c| c.brdf);
    let yt = std::cell::RefCell::new(Vec::new());
    {
        let root = BitMapBackend::with_buffer(&mut buf, (w, h)).into_drawing_area();
        root.fill(&WHITE).map_err(err)?;
        let root = root.titled(title, ("sans-serif", 22)).map_err(err)?;
        let panels = root.split_evenly((rows, cols));
        for (k, area) in panels.iter().enumerate() {
            let (row, col) = (k / cols, k % cols);
            let across = row == 1;
            let theta_i = SLICE_THETAS[col];
            let axis = if across { b_axis } else { t_axis };
            let l = in_plane(&axis, -theta_i);
            let xs: Vec<f64> = (0..=170).map(|i| -85.0 + i as f64).collect();
            // per curve, per channel
            let lines: Vec<Vec<Vec<(f64, f64)>>> = curves
                .iter()
                .map(|c| {
                    let vals: Vec<(f64, [f64; 3])> = xs
                        .iter()
                        .filter_map(|&x| (c.brdf)(&l, &in_plane(&axis, x)).map(|f| (x, f)))
                        .collect();
                    (0..ch)
                        .map(|k| {
                            vals.iter()
                                .map(|(x, f)| (*x, pick(f, ch, channels)[k]))
                                .collect()
                        })
                        .collect()
                })
                .collect();
            let near = near_slice(samples, psi_deg, theta_i, across, channels);
            drawn.points += near.len();
            let near: Vec<(f64, &Sample)> = near.iter().map(|p| (p.0, p.2)).collect();
            let bins = bin_samples(&near, fit_curve, ch, channels);
            let positive = |y: &f64| y.is_finite() && (!log_y || *y > 0.0);
            let ys = lines
                .iter()
                .flatten()
                .flatten()
                .map(|p| p.1)
                .chain(bins.iter().flat_map(|b| {
                    (0..ch).flat_map(move |c| [b.mean[c] + b.sd[c], b.mean[c] - b.sd[c], b.mean[c]])
                }))
                .chain(
                    bins.iter()
                        .filter_map(|b| b.fit)
                        .flat_map(|f| f.into_iter().take(ch)),
                )
                .filter(positive);
            let (mut y0, mut y1) = ys.fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), y| {
                (a.min(y), b.max(y))
            });
            if !y0.is_finite() {
                (y0, y1) = (1e-3, 1.0);
            }
            let caption = format!(
                "{} the fibres, theta_i {theta_i:.0} deg ({} samples, {} bins)",
                if across { "across" } else { "along" },
                near.len(),
                bins.len()
            );
            drawn.panels.push(caption.clone());
            let mut builder = ChartBuilder::on(area);
            builder
                .caption(caption, ("sans-serif", 14))
                .margin(8)
                .x_label_area_size(36)
                .y_label_area_size(56);
            let kx: Vec<f64> = (-3..=3).map(|k| 30.0 * k as f64).collect();
            macro_rules! draw {
                ($chart:expr) => {{
                    let mut chart = $chart;
                    chart
                        .configure_mesh()
                        .x_desc("theta_o [deg] (+: far side)")
                        .y_desc("BRDF [1/sr]")
                        .x_label_formatter(&|x| tick_label(*x))
                        .y_label_formatter(&|y| {
                            let t = tick_label(*y);
                            yt.borrow_mut().push(t.clone());
                            t
                        })
                        .label_style(("sans-serif", 11))
                        .draw()
                        .map_err(err)?;
                    for (i, (c, line)) in curves.iter().zip(&lines).enumerate() {
                        for (cc, line) in line.iter().enumerate() {
                            let color = if ch == 1 {
                                palette(i + 1)
                            } else {
                                channel_colour(cc, ch)
                            };
                            let style = color.stroke_width(if c.dashed { 1 } else { 2 });
                            let name = if ch == 1 {
                                c.name.clone()
                            } else {
                                format!("{} ({})", c.name, ["R", "G", "B"][cc])
                            };
                            if c.dashed {
                                // dashes: every other pair of consecutive points
                                let segs = line.windows(2).step_by(2).map(|s| s.to_vec());
                                let s = chart
                                    .draw_series(segs.map(|s| PathElement::new(s, style)))
                                    .map_err(err)?;
                                if k == 0 {
                                    s.label(name).legend(move |(x, y)| {
                                        PathElement::new(vec![(x, y), (x + 8, y)], style)
                                    });
                                }
                            } else {
                                let s = chart
                                    .draw_series(LineSeries::new(line.clone(), style))
                                    .map_err(err)?;
                                if k == 0 {
                                    s.label(name).legend(move |(x, y)| {
                                        PathElement::new(vec![(x, y), (x + 20, y)], style)
                                    });
                                }
                            }
                        }
                    }
                    for cc in 0..ch {
                        let color = if ch == 1 {
                            palette(0)
                        } else {
                            channel_colour(cc, ch)
                        };
                        let bars = bins.iter().filter(|b| b.n > 1 && b.sd[cc] > 0.0).map(|b| {
                            let lo = b.mean[cc] - b.sd[cc];
                            let lo = if log_y && lo <= 0.0 {
                                b.mean[cc] / 10.0
                            } else {
                                lo
                            };
                            PathElement::new(
                                vec![(b.x, lo), (b.x, b.mean[cc] + b.sd[cc])],
                                color.stroke_width(1),
                            )
                        });
                        chart.draw_series(bars).map_err(err)?;
                        let dots = chart
                            .draw_series(
                                bins.iter()
                                    .filter(|b| !log_y || b.mean[cc] > 0.0)
                                    .map(|b| Circle::new((b.x, b.mean[cc]), 3, color.filled())),
                            )
                            .map_err(err)?;
                        if k == 0 && cc == 0 {
                            dots.label(format!(
                                "measured near the slice: mean, +-1 sd per {BIN_DEG:.0} deg bin"
                            ))
                            .legend(move |(x, y)| Circle::new((x + 10, y), 3, color.filled()));
                        }
                        let rings = chart
                            .draw_series(
                                bins.iter()
                                    .filter_map(|b| b.fit.map(|f| (b.x, f[cc])))
                                    .filter(|p| !log_y || p.1 > 0.0)
                                    .map(|p| Circle::new(p, 5, BLACK.mix(0.7).stroke_width(1))),
                            )
                            .map_err(err)?;
                        if k == 0 && cc == 0 && bins.iter().any(|b| b.fit.is_some()) {
                            rings
                                .label("fitted at those samples (mean)")
                                .legend(|(x, y)| {
                                    Circle::new((x + 10, y), 5, BLACK.mix(0.7).stroke_width(1))
                                });
                        }
                    }
                    if k == 0 {
                        chart
                            .configure_series_labels()
                            .label_font(("sans-serif", 11))
                            .background_style(WHITE.mix(0.85))
                            .border_style(BLACK)
                            .position(SeriesLabelPosition::UpperLeft)
                            .draw()
                            .map_err(err)?;
                    }
                }};
            }
            if log_y {
                let (a, b) = (y0 / 1.5, y1 * 1.5);
                draw!(builder
                    .build_cartesian_2d(
                        ticked(-90.0..90.0, kx.clone()),
                        ticked((a..b).log_scale(), super::plots::nice_ticks(a, b, true))
                    )
                    .map_err(err)?);
            } else {
                let pad = 0.05 * (y1 - y0).max(1e-12);
                let (a, b) = ((y0 - pad).min(0.0), y1 + pad);
                draw!(builder
                    .build_cartesian_2d(
                        ticked(-90.0..90.0, kx.clone()),
                        ticked(a..b, super::plots::nice_ticks(a, b, false))
                    )
                    .map_err(err)?);
            }
        }
        root.present().map_err(err)?;
    }
    save(path, w, h, buf)?;
    drawn.y_ticks = yt.into_inner();
    drawn.x_ticks = (-3..=3).map(|k| tick_label(30.0 * k as f64)).collect();
    Ok(drawn)
}

fn save(path: Sink, w: u32, h: u32, buf: Vec<u8>) -> Result<()> {
    let img = image::RgbImage::from_raw(w, h, buf).ok_or_else(|| anyhow!("plot buffer size"))?;
    path.png(&img)
}

/// Most rows of a capture's hemisphere maps (one per image, the images with the most samples).
pub const MAX_IMAGE_ROWS: usize = 6;
/// Measured samples on a hemisphere map are averaged in cells of this many screen pixels.
pub const CELL_PX: i32 = 6;

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

/// Hemisphere maps, one row per light: columns measured, fitted and the relative residual
/// (fitted - measured) / measured in percent, each row with a colour bar of its log BRDF scale
/// and the residual colour bar (symmetric, sized to the 99th percentile of |residual|). With
/// `measured` (a measured file) the maps are dense and the lights lie across the fibres at
/// [`MAP_THETAS`]; a capture gets a row per image (see [`rows`]) with its samples at their view
/// directions, averaged in [`CELL_PX`] cells (an orthographic image is one cell: one view);
/// goniometric data the samples near each row's light. Values: the channel mean. Returns what
/// it drew (`points`: the samples drawn; `note`: what the rows are, for the report).
pub fn hemispheres(
    path: Sink,
    title: &str,
    psi_deg: f64,
    channels: usize,
    fitted: Brdf,
    measured: Option<Brdf>,
    samples: &[Sample],
) -> Result<Drawn> {
    font();
    const R: i32 = 110; // disk radius in pixels
    let side = 2 * R as u32 + 40;
    let (t_axis, b_axis) = axes(psi_deg);
    let (rows, capture) = rows(&b_axis, measured.is_some(), samples);
    let bar_w = 100u32;
    let (cols, nrows) = (3u32, rows.len() as u32);
    let (w, h) = (side * cols + 2 * bar_w, (side + 34) * nrows + 100);
    let mut buf = vec![0u8; (w * h * 3) as usize];
    let mut drawn = Drawn::default();
    let view = |px: i32, py: i32| -> Option<Vec3> {
        let (x, y) = (px as f64 / R as f64, -(py as f64) / R as f64);
        let r2 = x * x + y * y;
        (r2 < 0.995).then(|| b_axis * x + t_axis * y + Vec3::z() * (1.0 - r2).sqrt())
    };
    // per row: the dense grids, and the measured cells (px, py, measured, residual %)
    struct Maps {
        fit: Vec<Option<f64>>,
        meas: Option<Vec<Option<f64>>>,
        cells: Vec<(i32, i32, f64, Option<f64>, usize)>,
        lo: f64,
        hi: f64,
    }
    let mut maps = Vec::new();
    for row in &rows {
        let l = row.light;
        let grid = |f: Brdf| -> Vec<Option<f64>> {
            let mut g = Vec::with_capacity(((2 * R + 1) * (2 * R + 1)) as usize);
            for py in -R..=R {
                for px in -R..=R {
                    g.push(
                        view(px, py)
                            .and_then(|v| f(&l, &v))
                            .map(|b| mean(&b, channels)),
                    );
                }
            }
            g
        };
        let fit = grid(fitted);
        let meas = measured.map(grid);
        let mut cells: std::collections::BTreeMap<(i32, i32), (f64, f64, usize, usize)> =
            Default::default();
        for s in &row.samples {
            let (x, y) = (s.v.dot(&b_axis), s.v.dot(&t_axis));
            let (px, py) = (
                (x * R as f64).round() as i32,
                (-y * R as f64).round() as i32,
            );
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
        drawn.points += row.samples.len();
        let cells: Vec<(i32, i32, f64, Option<f64>, usize)> = cells
            .into_iter()
            .map(|((cx, cy), (d, r, n, nr))| {
                (
                    cx * CELL_PX + CELL_PX / 2,
                    cy * CELL_PX + CELL_PX / 2,
                    d / n as f64,
                    (nr > 0).then(|| r / nr as f64),
                    n,
                )
            })
            .collect();
        let vals = fit
            .iter()
            .flatten()
            .chain(meas.iter().flatten().flatten())
            .copied()
            .chain(cells.iter().map(|c| c.2))
            .filter(|v| *v > 0.0 && v.is_finite());
        let (lo, hi) = vals.fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
            (a.min(v), b.max(v))
        });
        let (lo, hi) = if lo.is_finite() {
            (lo, hi.max(lo * (1.0 + 1e-9)))
        } else {
            (1e-3, 1.0)
        };
        maps.push(Maps {
            fit,
            meas,
            cells,
            lo,
            hi,
        });
    }
    // the residual scale over every row: dense residuals or the cells'
    let dense_res = |m: &Maps| -> Vec<Option<f64>> {
        match &m.meas {
            Some(meas) => meas
                .iter()
                .zip(&m.fit)
                .map(|(a, b)| match (a, b) {
                    (Some(a), Some(b)) if *a > 0.0 => Some(100.0 * (b - a) / a),
                    _ => None,
                })
                .collect(),
            None => vec![],
        }
    };
    let residuals: Vec<Vec<Option<f64>>> = maps.iter().map(dense_res).collect();
    let res_scale = MapScale::symmetric(
        residuals
            .iter()
            .flatten()
            .flatten()
            .copied()
            .chain(maps.iter().flat_map(|m| m.cells.iter().filter_map(|c| c.3))),
        99.0,
        1e-6,
        "(fitted - measured) / measured [%]",
    );
    {
        let root = BitMapBackend::with_buffer(&mut buf, (w, h)).into_drawing_area();
        root.fill(&WHITE).map_err(err)?;
        let root = root.titled(title, ("sans-serif", 20)).map_err(err)?;
        let (body, legend) = root.split_vertically(h as i32 - 70);
        let row_areas = body.split_evenly((nrows as usize, 1));
        let mut res_bar = None;
        for (r, (row, m)) in rows.iter().zip(&maps).enumerate() {
            let (disks, bars) = row_areas[r].split_horizontally(side * cols);
            let (bar_log, bar_res) = bars.split_horizontally(bar_w);
            let panels = disks.split_evenly((1, 3));
            let log_scale = MapScale {
                lo: m.lo,
                hi: m.hi,
                log: true,
                map: ColourMap::Sequential,
                label: "BRDF [1/sr] (log)".into(),
            };
            for (col, area) in panels.iter().enumerate() {
                let name = match col {
                    0 if measured.is_some() => "measured (dense)".to_string(),
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
                drawn.panels.push(format!("{}: {name}", row.label));
                let (cx, cy) = (side as i32 / 2, R + 32);
                area.draw(&Circle::new((cx, cy), R, BLACK.stroke_width(1)))
                    .map_err(err)?;
                let grid: Option<&Vec<Option<f64>>> = match col {
                    0 => m.meas.as_ref(),
                    1 => Some(&m.fit),
                    _ => m.meas.as_ref().map(|_| &residuals[r]),
                };
                if let Some(g) = grid {
                    let mut k = 0;
                    for py in -R..=R {
                        for px in -R..=R {
                            if let Some(v) = g[k] {
                                let c = if col == 2 {
                                    res_scale.colour(v)
                                } else {
                                    log_scale.colour(v)
                                };
                                area.draw_pixel((cx + px, cy + py), &c).map_err(err)?;
                            }
                            k += 1;
                        }
                    }
                } else {
                    for &(px, py, y, res, _) in &m.cells {
                        let c = match (col, res) {
                            (0, _) => log_scale.colour(y),
                            (_, Some(r)) => res_scale.colour(r),
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
                }
                // the light's mirror direction, for orientation
                let (mx, my) = (-row.light.dot(&b_axis), -row.light.dot(&t_axis));
                let (mx, my) = (
                    (mx * R as f64).round() as i32,
                    (-my * R as f64).round() as i32,
                );
                area.draw(&Cross::new((cx + mx, cy + my), 5, BLACK.stroke_width(1)))
                    .map_err(err)?;
            }
            let bar_log = bar_log.margin(18, 18, 4, 4);
            drawn.colour_bars.push(colour_bar(&bar_log, &log_scale)?);
            let bar_res = bar_res.margin(18, 18, 4, 4);
            let rb = colour_bar(&bar_res, &res_scale)?;
            if r == 0 {
                res_bar = Some(rb);
            }
        }
        // the residual bar last (one scale for every row)
        drawn.colour_bars.extend(res_bar);
        let rows_are = rows_note(capture, measured.is_some());
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
    }
    save(path, w, h, buf)?;
    drawn.note = format!("Rows: {}.", rows_note(capture, measured.is_some()));
    drawn.x_label = "view direction x = v.B".into();
    drawn.y_label = "view direction y = v.T".into();
    Ok(drawn)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::load::samples::Origin;

    fn sample(l: Vec3, v: Vec3) -> Sample {
        Sample {
            l,
            v,
            fibre_azimuth: None,
            map_value: None,
            texel_height: None,
            value: [0.2, 0.4, 0.6],
            sigma: None,
            weight: 1.0,
            origin: Origin::Line(1),
        }
    }

    #[test]
    fn samples_near_a_slice_get_their_signed_angle() {
        let psi = 30.0;
        let (t, b) = axes(psi);
        // light from -T at 30 deg, view on the far side at 40 deg: +40 along the fibres
        let fwd = sample(in_plane(&t, -30.0), in_plane(&t, 40.0));
        // the same geometry seen from the other end of the fibres (T -> -T): still +40
        let flipped = sample(in_plane(&t, 30.0), in_plane(&t, -40.0));
        // view on the light's side: -40
        let back = sample(in_plane(&t, -30.0), in_plane(&t, -40.0));
        // across the fibres, and a light too far from 30 deg
        let across = sample(in_plane(&b, -30.0), in_plane(&b, 40.0));
        let steep = sample(in_plane(&t, -45.0), in_plane(&t, 40.0));
        let all = [fwd, flipped, back, across, steep];
        let near = near_slice(&all, psi, 30.0, false, 3);
        let got: Vec<(f64, f64)> = near.iter().map(|p| (p.0, p.1)).collect();
        assert_eq!(got.len(), 3, "{got:?}");
        for (g, want) in got.iter().zip([40.0, 40.0, -40.0]) {
            assert!(
                (g.0 - want).abs() < 1e-9 && (g.1 - 0.4).abs() < 1e-15,
                "{g:?}"
            );
        }
        let near = near_slice(&all, psi, 30.0, true, 1);
        assert_eq!(near.len(), 1);
        assert!((near[0].0 - 40.0).abs() < 1e-9 && near[0].1 == 0.2);
    }
}
