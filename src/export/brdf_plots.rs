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
use super::plots::{font, palette};
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

/// Slices: rows along / across the fibres, one column per incidence in [`SLICE_THETAS`]; each
/// panel the curves over theta_o in [-85, 85] deg and the measured samples near the slice.
/// Returns the number of measured points drawn.
#[allow(clippy::too_many_arguments)]
pub fn slices(
    path: Sink,
    title: &str,
    psi_deg: f64,
    channels: usize,
    curves: &[Curve],
    samples: &[Sample],
    log_y: bool,
) -> Result<usize> {
    font();
    let (cols, rows) = (SLICE_THETAS.len(), 2usize);
    let (w, h) = (380 * cols as u32, 340 * rows as u32 + 60);
    let mut buf = vec![0u8; (w * h * 3) as usize];
    let (t_axis, b_axis) = axes(psi_deg);
    let mut drawn = 0;
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
            let lines: Vec<Vec<(f64, f64)>> = curves
                .iter()
                .map(|c| {
                    xs.iter()
                        .filter_map(|&x| {
                            (c.brdf)(&l, &in_plane(&axis, x)).map(|f| (x, mean(&f, channels)))
                        })
                        .collect()
                })
                .collect();
            let near = near_slice(samples, psi_deg, theta_i, across, channels);
            drawn += near.len();
            let points: Vec<(f64, f64)> = near.iter().map(|p| (p.0, p.1)).collect();
            // the last curve (the fit) at each sample's own directions: off the slice's plane
            // the model differs from the curve, and these show what the data were fitted with
            let at_samples: Vec<(f64, f64)> = match curves.last() {
                Some(c) if !c.dashed => near
                    .iter()
                    .filter_map(|p| (c.brdf)(&p.2.l, &p.2.v).map(|f| (p.0, mean(&f, channels))))
                    .collect(),
                _ => Vec::new(),
            };
            let ys = lines
                .iter()
                .flatten()
                .chain(points.iter())
                .chain(at_samples.iter())
                .map(|p| p.1)
                .filter(|y| y.is_finite() && (!log_y || *y > 0.0));
            let (mut y0, mut y1) = ys.fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), y| {
                (a.min(y), b.max(y))
            });
            if !y0.is_finite() {
                (y0, y1) = (1e-3, 1.0);
            }
            let caption = format!(
                "{} the fibres, theta_i {theta_i:.0} deg ({} pts)",
                if across { "across" } else { "along" },
                points.len()
            );
            let mut builder = ChartBuilder::on(area);
            builder
                .caption(caption, ("sans-serif", 14))
                .margin(8)
                .x_label_area_size(32)
                .y_label_area_size(52);
            macro_rules! draw {
                ($chart:expr) => {{
                    let mut chart = $chart;
                    chart
                        .configure_mesh()
                        .x_desc("theta_o [deg] (+: far side)")
                        .y_desc("BRDF [1/sr]")
                        .x_label_formatter(&|x| format!("{x:.0}"))
                        .y_label_formatter(&|y| short(*y))
                        .label_style(("sans-serif", 11))
                        .draw()
                        .map_err(err)?;
                    for (i, (c, line)) in curves.iter().zip(&lines).enumerate() {
                        let color = palette(i + 1);
                        let style = color.stroke_width(2);
                        if c.dashed {
                            // dashes: every other pair of consecutive points
                            let segs = line.windows(2).step_by(2).map(|s| s.to_vec());
                            let s = chart
                                .draw_series(segs.map(|s| PathElement::new(s, style)))
                                .map_err(err)?;
                            if k == 0 {
                                s.label(c.name.clone()).legend(move |(x, y)| {
                                    PathElement::new(vec![(x, y), (x + 8, y)], style)
                                });
                            }
                        } else {
                            let s = chart
                                .draw_series(LineSeries::new(line.clone(), style))
                                .map_err(err)?;
                            if k == 0 {
                                s.label(c.name.clone()).legend(move |(x, y)| {
                                    PathElement::new(vec![(x, y), (x + 20, y)], style)
                                });
                            }
                        }
                    }
                    let dots = chart
                        .draw_series(
                            points
                                .iter()
                                .filter(|p| !log_y || p.1 > 0.0)
                                .map(|&p| Circle::new(p, 3, palette(0).filled())),
                        )
                        .map_err(err)?;
                    if k == 0 {
                        dots.label("measured near the slice")
                            .legend(|(x, y)| Circle::new((x + 10, y), 3, palette(0).filled()));
                    }
                    let fit_color = palette(curves.len());
                    let hollow = chart
                        .draw_series(
                            at_samples
                                .iter()
                                .filter(|p| !log_y || p.1 > 0.0)
                                .map(|&p| Circle::new(p, 4, fit_color.stroke_width(1))),
                        )
                        .map_err(err)?;
                    if k == 0 && !at_samples.is_empty() {
                        hollow
                            .label("fitted at those samples")
                            .legend(move |(x, y)| {
                                Circle::new((x + 10, y), 4, fit_color.stroke_width(1))
                            });
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
                draw!(builder
                    .build_cartesian_2d(-90.0..90.0, (y0 / 1.5..y1 * 1.5).log_scale())
                    .map_err(err)?);
            } else {
                let pad = 0.05 * (y1 - y0).max(1e-12);
                draw!(builder
                    .build_cartesian_2d(-90.0..90.0, (y0 - pad).min(0.0)..y1 + pad)
                    .map_err(err)?);
            }
        }
        root.present().map_err(err)?;
    }
    save(path, w, h, buf)?;
    Ok(drawn)
}

/// A tick label with two significant digits.
fn short(y: f64) -> String {
    if y == 0.0 || !y.is_finite() {
        return format!("{y}");
    }
    let digits = (1 - y.abs().log10().floor() as i32).max(0) as usize;
    format!("{y:.digits$}")
}

fn save(path: Sink, w: u32, h: u32, buf: Vec<u8>) -> Result<()> {
    let img = image::RgbImage::from_raw(w, h, buf).ok_or_else(|| anyhow!("plot buffer size"))?;
    path.png(&img)
}

/// Viridis-like colour of t in [0, 1].
pub(crate) fn sequential(t: f64) -> RGBColor {
    const C: [(f64, f64, f64); 5] = [
        (68.0, 1.0, 84.0),
        (59.0, 82.0, 139.0),
        (33.0, 145.0, 140.0),
        (94.0, 201.0, 98.0),
        (253.0, 231.0, 37.0),
    ];
    let x = t.clamp(0.0, 1.0) * (C.len() - 1) as f64;
    let i = (x.floor() as usize).min(C.len() - 2);
    let f = x - i as f64;
    let mix = |a: f64, b: f64| (a + f * (b - a)).round() as u8;
    RGBColor(
        mix(C[i].0, C[i + 1].0),
        mix(C[i].1, C[i + 1].1),
        mix(C[i].2, C[i + 1].2),
    )
}

/// Blue (model below data) - white - red (above) for t in [-1, 1].
pub(crate) fn diverging(t: f64) -> RGBColor {
    let t = t.clamp(-1.0, 1.0);
    let a = (255.0 * (1.0 - t.abs())) as u8;
    if t >= 0.0 {
        RGBColor(255, a, a)
    } else {
        RGBColor(a, a, 255)
    }
}

/// Residual range of the maps: ln(fitted / measured) of +-1 (a factor e) saturates.
pub const RESIDUAL_LN_RANGE: f64 = 1.0;

/// Hemisphere maps: one row per incidence in [`MAP_THETAS`] (light in the B-N plane, from -B);
/// columns measured, fitted, ln(fitted / measured). With `measured` (a measured file) the maps are
/// dense; without, the measured and residual panels show the samples whose light lies within
/// [`NEAR_LIGHT_DEG`] of the row's. Returns the number of samples drawn.
pub fn hemispheres(
    path: Sink,
    title: &str,
    psi_deg: f64,
    channels: usize,
    fitted: Brdf,
    measured: Option<Brdf>,
    samples: &[Sample],
) -> Result<usize> {
    font();
    const R: i32 = 110; // disk radius in pixels
    let side = 2 * R as u32 + 40;
    let (cols, rows) = (3u32, MAP_THETAS.len() as u32);
    let (w, h) = (side * cols, (side + 24) * rows + 90);
    let mut buf = vec![0u8; (w * h * 3) as usize];
    let (t_axis, b_axis) = axes(psi_deg);
    let mut drawn = 0;
    {
        let root = BitMapBackend::with_buffer(&mut buf, (w, h)).into_drawing_area();
        root.fill(&WHITE).map_err(err)?;
        let root = root.titled(title, ("sans-serif", 20)).map_err(err)?;
        let (body, legend) = root.split_vertically(h as i32 - 60);
        let panels = body.split_evenly((rows as usize, cols as usize));
        for (row, &theta_i) in MAP_THETAS.iter().enumerate() {
            let l = in_plane(&b_axis, -theta_i);
            let view = |px: i32, py: i32| -> Option<Vec3> {
                let (x, y) = (px as f64 / R as f64, -(py as f64) / R as f64);
                let r2 = x * x + y * y;
                (r2 < 0.995).then(|| b_axis * x + t_axis * y + Vec3::z() * (1.0 - r2).sqrt())
            };
            // dense grids
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
            let fit_grid = grid(fitted);
            let meas_grid = measured.map(grid);
            let near: Vec<(i32, i32, f64, f64)> = if measured.is_none() {
                samples
                    .iter()
                    .filter(|s| s.l.dot(&l).clamp(-1.0, 1.0).acos().to_degrees() <= NEAR_LIGHT_DEG)
                    .filter_map(|s| {
                        let m = fitted(&s.l, &s.v)?;
                        let (x, y) = (s.v.dot(&b_axis), s.v.dot(&t_axis));
                        Some((
                            (x * R as f64).round() as i32,
                            (-y * R as f64).round() as i32,
                            mean(&s.value, channels),
                            mean(&m, channels),
                        ))
                    })
                    .collect()
            } else {
                Vec::new()
            };
            drawn += near.len();
            // shared log scale of the row
            let vals = fit_grid
                .iter()
                .flatten()
                .chain(meas_grid.iter().flatten().flatten())
                .copied()
                .chain(near.iter().map(|p| p.2))
                .filter(|v| *v > 0.0 && v.is_finite());
            let (lo, hi) = vals.fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
                (a.min(v), b.max(v))
            });
            let (llo, lhi) = if lo.is_finite() {
                (lo.ln(), hi.ln().max(lo.ln() + 1e-9))
            } else {
                (0.0, 1.0)
            };
            let seq = |v: f64| sequential(((v.max(1e-300)).ln() - llo) / (lhi - llo));
            for col in 0..3usize {
                let area = &panels[row * 3 + col];
                let name = match col {
                    0 => "measured".to_string(),
                    1 => format!("fitted; {:.2e}..{:.2e} 1/sr", llo.exp(), lhi.exp()),
                    _ => "ln(fitted / measured)".to_string(),
                };
                area.draw(&Text::new(
                    format!("theta_i {theta_i:.0} deg: {name}"),
                    (8, 2),
                    ("sans-serif", 13),
                ))
                .map_err(err)?;
                let (cx, cy) = (side as i32 / 2, R + 22);
                area.draw(&Circle::new((cx, cy), R, BLACK.stroke_width(1)))
                    .map_err(err)?;
                let dense: Option<Vec<Option<f64>>> = match col {
                    0 => meas_grid.clone(),
                    1 => Some(fit_grid.clone()),
                    _ => meas_grid.as_ref().map(|m| {
                        m.iter()
                            .zip(&fit_grid)
                            .map(|(a, b)| match (a, b) {
                                (Some(a), Some(b)) if *a > 0.0 && *b > 0.0 => Some((b / a).ln()),
                                _ => None,
                            })
                            .collect()
                    }),
                };
                if let Some(g) = dense {
                    let mut k = 0;
                    for py in -R..=R {
                        for px in -R..=R {
                            if let Some(v) = g[k] {
                                let c = if col == 2 {
                                    diverging(v / RESIDUAL_LN_RANGE)
                                } else {
                                    seq(v)
                                };
                                area.draw_pixel((cx + px, cy + py), &c).map_err(err)?;
                            }
                            k += 1;
                        }
                    }
                } else {
                    for &(px, py, y, m) in &near {
                        let c = if col == 0 {
                            seq(y)
                        } else if y > 0.0 && m > 0.0 {
                            diverging((m / y).ln() / RESIDUAL_LN_RANGE)
                        } else {
                            continue;
                        };
                        area.draw(&Circle::new((cx + px, cy + py), 4, c.filled()))
                            .map_err(err)?;
                        area.draw(&Circle::new((cx + px, cy + py), 4, BLACK.mix(0.5)))
                            .map_err(err)?;
                    }
                }
                // the light's mirror direction, for orientation
                let mx = (theta_i.to_radians().sin() * R as f64).round() as i32;
                area.draw(&Cross::new((cx + mx, cy), 5, BLACK.stroke_width(1)))
                    .map_err(err)?;
            }
        }
        for (i, line) in [
            format!(
                "Orthographic view hemisphere: right = +B (the far side of the light, which comes from -B), up = +T (fibres at {psi_deg:.1} deg); x = mirror direction."
            ),
            "Colour: log BRDF (channel mean, one scale per row), dark = low. Residual: blue = fitted below measured, red = above, saturating at a factor e.".to_string(),
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

    #[test]
    fn tick_labels_are_short() {
        assert_eq!(short(0.30000000000000004), "0.30");
        assert_eq!(short(0.01), "0.010");
        assert_eq!(short(2.0), "2.0");
        assert_eq!(short(150.0), "150");
    }
}
