//! Slices at fixed incidence: the curves of the BRDFs over the signed view angle theta_o, along
//! and across the fibres, with the measured samples near each slice averaged in bins.

use super::common::{axes, err, in_plane, mean, save, Brdf, Curve};
use crate::export::atomic::Sink;
use crate::export::plots::{font, nice_ticks, palette, tick_label, ticked, Drawn, Ticked};
use crate::load::samples::Sample;
use crate::model::frame::{FibreFrame, Vec3};
use anyhow::Result;
use plotters::coord::types::RangedCoordf64;
use plotters::prelude::*;
use std::cell::RefCell;

/// Incidence angles of the slices (degrees).
pub const SLICE_THETAS: [f64; 4] = [0.0, 30.0, 50.0, 70.0];
/// A measured sample lies near a slice when its theta_i is within this of the slice's (degrees)
/// and both directions are within this angle of the slice's plane (direction cosine 0.2).
pub const NEAR_THETA_DEG: f64 = 6.0;
pub const NEAR_PLANE_COSINE: f64 = 0.2;

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

/// What a slices figure shows (the request of [`slices`]).
pub struct SlicePlot<'a> {
    pub title: &'a str,
    /// The fibre azimuth psi (degrees): T lies at it, B = N x T.
    pub psi_deg: f64,
    /// The data's channels: 1 (grey) or 3 (RGB).
    pub channels: usize,
    /// The curves; the last, when solid, is the fit, also drawn as its mean at each bin's
    /// samples.
    pub curves: &'a [Curve<'a>],
    /// The measured samples (those near a slice are drawn).
    pub samples: &'a [Sample],
    /// A logarithmic y axis.
    pub log_y: bool,
}

/// Slices: rows along / across the fibres, one column per incidence in [`SLICE_THETAS`]; each
/// panel the curves over theta_o in [-85, 85] deg (one per channel for RGB data) and the measured
/// samples near the slice averaged in [`BIN_DEG`] bins of theta_o: the mean with a +-1 standard
/// deviation bar (a capture image puts thousands of pixels at nearly one view), and the fit's
/// mean at the same samples as a ring. Returns what it drew (`points`: the samples near a
/// slice).
pub fn slices(path: Sink, plot: &SlicePlot) -> Result<Drawn> {
    font();
    let (cols, rows) = (SLICE_THETAS.len(), 2usize);
    let (w, h) = (380 * cols as u32, 340 * rows as u32 + 60);
    let mut buf = vec![0u8; (w * h * 3) as usize];
    let (t_axis, b_axis) = axes(plot.psi_deg);
    let mut drawn = Drawn {
        x_label: "theta_o [deg] (+: far side)".into(),
        y_label: "BRDF [1/sr]".into(),
        ..Default::default()
    };
    let channels = plot.channels;
    // one curve per channel of RGB data, unless that makes more than 6 curves (the mean then)
    let ch = if channels == 3 && plot.curves.len() <= 2 {
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
    let style = PanelStyle {
        curves: plot.curves,
        ch,
        log_y: plot.log_y,
        y_ticks: RefCell::new(Vec::new()),
    };
    {
        let root = BitMapBackend::with_buffer(&mut buf, (w, h)).into_drawing_area();
        root.fill(&WHITE).map_err(err)?;
        let root = root.titled(plot.title, ("sans-serif", 22)).map_err(err)?;
        let panels = root.split_evenly((rows, cols));
        for (k, area) in panels.iter().enumerate() {
            let (row, col) = (k / cols, k % cols);
            let across = row == 1;
            let axis = if across { b_axis } else { t_axis };
            let panel = Panel::new(plot, ch, across, &axis, SLICE_THETAS[col]);
            drawn.points += panel.near;
            drawn.panels.push(panel.caption.clone());
            // the first panel carries the legend
            style.draw(area, panel, k == 0)?;
        }
        root.present().map_err(err)?;
    }
    save(path, w, h, buf)?;
    drawn.y_ticks = style.y_ticks.into_inner();
    drawn.x_ticks = (-3..=3).map(|k| tick_label(30.0 * k as f64)).collect();
    Ok(drawn)
}

/// One panel of the slices, worked out before it is drawn: the curves along it and the bins of
/// the samples near it.
struct Panel {
    /// Per curve, per channel drawn: (theta_o, value).
    lines: Vec<Vec<Vec<(f64, f64)>>>,
    bins: Vec<Bin>,
    /// The smallest and largest value drawn (on a log axis, of the positive ones).
    y_range: (f64, f64),
    caption: String,
    /// The samples near the slice.
    near: usize,
}

impl Panel {
    /// The slice at incidence `theta_i` in the plane of `axis` (along the fibres, or `across`
    /// them), `ch` channels per curve.
    fn new(plot: &SlicePlot, ch: usize, across: bool, axis: &Vec3, theta_i: f64) -> Self {
        let channels = plot.channels;
        let l = in_plane(axis, -theta_i);
        let xs: Vec<f64> = (0..=170).map(|i| -85.0 + i as f64).collect();
        // per curve, per channel
        let lines: Vec<Vec<Vec<(f64, f64)>>> = plot
            .curves
            .iter()
            .map(|c| {
                let vals: Vec<(f64, [f64; 3])> = xs
                    .iter()
                    .filter_map(|&x| (c.brdf)(&l, &in_plane(axis, x)).map(|f| (x, f)))
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
        let near = near_slice(plot.samples, plot.psi_deg, theta_i, across, channels);
        let near: Vec<(f64, &Sample)> = near.iter().map(|p| (p.0, p.2)).collect();
        let fit_curve = plot.curves.last().filter(|c| !c.dashed).map(|c| c.brdf);
        let bins = bin_samples(&near, fit_curve, ch, channels);
        let y_range = y_range(&lines, &bins, ch, plot.log_y);
        let caption = format!(
            "{} the fibres, theta_i {theta_i:.0} deg ({} samples, {} bins)",
            if across { "across" } else { "along" },
            near.len(),
            bins.len()
        );
        Self {
            lines,
            bins,
            y_range,
            caption,
            near: near.len(),
        }
    }
}

/// The smallest and largest of the values drawn: the curves, each bin's mean and its +-1 sd,
/// the fit's means; only the positive ones on a log axis; (1e-3, 1) when there is none.
fn y_range(lines: &[Vec<Vec<(f64, f64)>>], bins: &[Bin], ch: usize, log_y: bool) -> (f64, f64) {
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
    (y0, y1)
}

/// How every panel of one slices figure is drawn, and the y tick labels they drew.
struct PanelStyle<'a> {
    curves: &'a [Curve<'a>],
    /// Channels drawn per curve: 3 (R, G, B) or 1 (grey, or the channel mean).
    ch: usize,
    log_y: bool,
    y_ticks: RefCell<Vec<String>>,
}

/// A slice's chart: theta_o across, the BRDF (linear or log) up.
type SliceChart<'a, 'b, Y> =
    ChartContext<'a, BitMapBackend<'b>, Cartesian2d<Ticked<RangedCoordf64>, Ticked<Y>>>;

impl PanelStyle<'_> {
    /// Draw `panel` into `area`: its caption, axes, curves and bins (the `legend` on it).
    fn draw(
        &self,
        area: &DrawingArea<BitMapBackend<'_>, plotters::coord::Shift>,
        panel: Panel,
        legend: bool,
    ) -> Result<()> {
        let (y0, y1) = panel.y_range;
        let mut builder = ChartBuilder::on(area);
        builder
            .caption(panel.caption.as_str(), ("sans-serif", 14))
            .margin(8)
            .x_label_area_size(36)
            .y_label_area_size(56);
        let kx: Vec<f64> = (-3..=3).map(|k| 30.0 * k as f64).collect();
        if self.log_y {
            let (a, b) = (y0 / 1.5, y1 * 1.5);
            self.draw_chart(
                &mut builder
                    .build_cartesian_2d(
                        ticked(-90.0..90.0, kx),
                        ticked((a..b).log_scale(), nice_ticks(a, b, true)),
                    )
                    .map_err(err)?,
                &panel,
                legend,
            )
        } else {
            let pad = 0.05 * (y1 - y0).max(1e-12);
            let (a, b) = ((y0 - pad).min(0.0), y1 + pad);
            self.draw_chart(
                &mut builder
                    .build_cartesian_2d(
                        ticked(-90.0..90.0, kx),
                        ticked(a..b, nice_ticks(a, b, false)),
                    )
                    .map_err(err)?,
                &panel,
                legend,
            )
        }
    }

    /// Draw into the panel's built chart: the axes, the curves, the bins channel by channel and
    /// (on the first panel) the legend.
    fn draw_chart<'a, 'b: 'a, Y>(
        &self,
        chart: &mut SliceChart<'a, 'b, Y>,
        panel: &Panel,
        legend: bool,
    ) -> Result<()>
    where
        Y: Ranged<ValueType = f64>,
    {
        chart
            .configure_mesh()
            .x_desc("theta_o [deg] (+: far side)")
            .y_desc("BRDF [1/sr]")
            .x_label_formatter(&|x| tick_label(*x))
            .y_label_formatter(&|y| {
                let t = tick_label(*y);
                self.y_ticks.borrow_mut().push(t.clone());
                t
            })
            .label_style(("sans-serif", 11))
            .draw()
            .map_err(err)?;
        for (i, (c, line)) in self.curves.iter().zip(&panel.lines).enumerate() {
            for (cc, line) in line.iter().enumerate() {
                self.draw_curve(chart, c, (i, cc), line, legend)?;
            }
        }
        for cc in 0..self.ch {
            self.draw_bins(chart, &panel.bins, cc, legend)?;
        }
        if legend {
            chart
                .configure_series_labels()
                .label_font(("sans-serif", 11))
                .background_style(WHITE.mix(0.85))
                .border_style(BLACK)
                .position(SeriesLabelPosition::UpperLeft)
                .draw()
                .map_err(err)?;
        }
        Ok(())
    }

    /// Draw channel `cc` of curve `c` (number `i`; `at` = (i, cc)): solid, or dashed (every
    /// other pair of consecutive points), labelled for the `legend`.
    fn draw_curve<'a, 'b: 'a, Y>(
        &self,
        chart: &mut SliceChart<'a, 'b, Y>,
        c: &Curve,
        at: (usize, usize),
        line: &[(f64, f64)],
        legend: bool,
    ) -> Result<()>
    where
        Y: Ranged<ValueType = f64>,
    {
        let (i, cc) = at;
        let ch = self.ch;
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
            if legend {
                s.label(name)
                    .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 8, y)], style));
            }
        } else {
            let s = chart
                .draw_series(LineSeries::new(line.to_vec(), style))
                .map_err(err)?;
            if legend {
                s.label(name)
                    .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], style));
            }
        }
        Ok(())
    }

    /// Draw channel `cc` of the bins: the +-1 sd bars, the means as dots and the fit's means
    /// as rings, labelled for the `legend` (once, on channel 0).
    fn draw_bins<'a, 'b: 'a, Y>(
        &self,
        chart: &mut SliceChart<'a, 'b, Y>,
        bins: &[Bin],
        cc: usize,
        legend: bool,
    ) -> Result<()>
    where
        Y: Ranged<ValueType = f64>,
    {
        let (ch, log_y) = (self.ch, self.log_y);
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
        if legend && cc == 0 {
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
        if legend && cc == 0 && bins.iter().any(|b| b.fit.is_some()) {
            rings
                .label("fitted at those samples (mean)")
                .legend(|(x, y)| Circle::new((x + 10, y), 5, BLACK.mix(0.7).stroke_width(1)));
        }
        Ok(())
    }
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
