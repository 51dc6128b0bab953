//! Slices at fixed incidence: the curves of the BRDFs over the signed view angle theta_o, along
//! and across the fibres, with the measured samples near each slice averaged in bins.

use super::common::{axes, err, in_plane, mean, save, Brdf, Curve};
use super::legend::{self, Entry, Mark};
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

/// A measured sample near a slice, in the slice's terms. The sample is turned half round N
/// when its light lies on the positive side (T ~ -T), so the light is on the negative side.
pub struct NearSample<'a> {
    /// Signed theta_o (degrees) of the view in the plane: +: the far side.
    pub x: f64,
    /// The channel mean of its value.
    pub value: f64,
    /// The sample.
    pub sample: &'a Sample,
    /// The light's signed angle in the plane (degrees; about -theta_i).
    pub light_deg: f64,
    /// The light's and the view's components out of the plane (direction cosines).
    pub light_off: f64,
    /// See `light_off`.
    pub view_off: f64,
}

/// Measured samples near the slice at `theta_i` along (`across` false) or across the fibres.
pub fn near_slice(
    samples: &[Sample],
    psi_deg: f64,
    theta_i: f64,
    across: bool,
    channels: usize,
) -> Vec<NearSample<'_>> {
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
            // the light on the negative side: turn half round N when it is on the positive one
            let side = if la > 0.0 { -1.0 } else { 1.0 };
            Some(NearSample {
                x: (side * va).atan2(v.n).to_degrees(),
                value: mean(&s.value, channels),
                sample: s,
                light_deg: (side * la).atan2(l.n).to_degrees(),
                light_off: side * lo,
                view_off: side * vo,
            })
        })
        .collect()
}

/// The direction at signed angle `theta_deg` in the plane of `axis` and N, moved out of it
/// along `other` to the direction cosine `off`.
fn off_plane(axis: &Vec3, other: &Vec3, theta_deg: f64, off: f64) -> Vec3 {
    in_plane(axis, theta_deg) * (1.0 - off * off).max(0.0).sqrt() + other * off
}

/// Most samples' offsets over which a slice's band spans the model.
pub const MAX_BAND_OFFSETS: usize = 32;

/// The samples' offsets from the slice (light angle, light and view out of the plane) over
/// which the band spans the model: all, or at most [`MAX_BAND_OFFSETS`] (each component's
/// extremes and an even selection of the rest).
fn band_offsets(near: &[NearSample]) -> Vec<(f64, f64, f64)> {
    let all: Vec<(f64, f64, f64)> = near
        .iter()
        .map(|p| (p.light_deg, p.light_off, p.view_off))
        .collect();
    if all.len() <= MAX_BAND_OFFSETS {
        return all;
    }
    let mut keep = std::collections::BTreeSet::new();
    let keys: [fn(&(f64, f64, f64)) -> f64; 3] = [|o| o.0, |o| o.1, |o| o.2];
    for key in keys {
        let by = |a: &usize, b: &usize| key(&all[*a]).total_cmp(&key(&all[*b]));
        keep.extend((0..all.len()).min_by(by));
        keep.extend((0..all.len()).max_by(by));
    }
    let step = all.len() as f64 / (MAX_BAND_OFFSETS - keep.len()) as f64;
    let mut k = 0.0;
    while keep.len() < MAX_BAND_OFFSETS && (k as usize) < all.len() {
        keep.insert(k as usize);
        k += step;
    }
    keep.into_iter().map(|i| all[i]).collect()
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

/// One bin of samples near a slice as drawn: per channel drawn (the first `ch` of each triple)
/// the mean, the standard deviation and the samples' own sigma, the fit's mean at the same
/// samples, and the count.
#[derive(Clone, Debug)]
pub struct DrawnBin {
    /// The panel (row-major: along the fibres first, one column per [`SLICE_THETAS`]).
    pub panel: usize,
    /// The mean theta_o of its samples (degrees).
    pub x: f64,
    /// The mean per channel drawn.
    pub mean: [f64; 3],
    /// The standard deviation of the values per channel drawn (0 for one sample).
    pub sd: [f64; 3],
    /// The RMS of the samples' own sigma per channel drawn (0 where they have none).
    pub sigma: [f64; 3],
    /// The fit's mean at the bin's own samples, when a fit is drawn.
    pub fit: Option<[f64; 3]>,
    /// The samples in the bin.
    pub n: usize,
    /// Its mean was drawn as a dot (not on a log axis below zero).
    pub drawn: bool,
}

/// The values drawn of a BRDF triple: each of `ch` channels, or (`ch` 1 of RGB data) the mean.
fn pick(v: &[f64; 3], ch: usize, channels: usize) -> [f64; 3] {
    if ch == 1 {
        [mean(v, channels), 0.0, 0.0]
    } else {
        *v
    }
}

/// The samples `near` a slice in [`BIN_DEG`] bins of theta_o with `fit`'s mean at each bin's
/// samples; `ch` channels drawn of `all`, bins on panel `panel`, on a log axis when `log_y`.
fn bin_samples(near: &[NearSample], fit: Option<Brdf>, chans: (usize, usize), at: (usize, bool)) -> Vec<DrawnBin> {
    let ((ch, all), (panel, log_y)) = (chans, at);
    let mut by: std::collections::BTreeMap<i64, Vec<&NearSample>> = Default::default();
    for p in near {
        by.entry((p.x / BIN_DEG).floor() as i64).or_default().push(p);
    }
    by.into_values()
        .map(|pts| {
            let n = pts.len();
            let x = pts.iter().map(|p| p.x).sum::<f64>() / n as f64;
            let (mut mean, mut sd, mut sigma) = ([0.0; 3], [0.0; 3], [0.0; 3]);
            for c in 0..ch {
                let val = |s: &Sample| pick(&s.value, ch, all)[c];
                let m = pts.iter().map(|p| val(p.sample)).sum::<f64>() / n as f64;
                let v = pts.iter().map(|p| (val(p.sample) - m).powi(2)).sum::<f64>()
                    / (n.max(2) - 1) as f64;
                mean[c] = m;
                sd[c] = if n > 1 { v.sqrt() } else { 0.0 };
                let s2 = pts
                    .iter()
                    .filter_map(|p| p.sample.sigma.map(|s| pick(&s, ch, all)[c].powi(2)))
                    .sum::<f64>();
                sigma[c] = (s2 / n as f64).sqrt();
            }
            let fit = fit.and_then(|f| {
                let mut acc = [0.0; 3];
                for p in &pts {
                    let v = pick(&f(&p.sample.l, &p.sample.v)?, ch, all);
                    for c in 0..3 {
                        acc[c] += v[c] / n as f64;
                    }
                }
                Some(acc)
            });
            DrawnBin {
                panel,
                x,
                mean,
                sd,
                sigma,
                fit,
                n,
                drawn: !log_y || (0..ch).any(|c| mean[c] > 0.0),
            }
        })
        .collect()
}

/// What a slices figure shows (the request of [`slices`]).
pub struct SlicePlot<'a> {
    /// The figure's title.
    pub title: &'a str,
    /// The fibre azimuth psi (degrees): T lies at it, B = N x T.
    pub psi_deg: f64,
    /// The data's channels: 1 (grey) or 3 (RGB).
    pub channels: usize,
    /// The curves; each solid one (a fit) also as a band over the near samples' offsets from
    /// the plane; the last, when solid, is the fit, also drawn as its mean at each bin's samples.
    pub curves: &'a [Curve<'a>],
    /// The measured samples (those near a slice are drawn).
    pub samples: &'a [Sample],
    /// A logarithmic y axis.
    pub log_y: bool,
}

/// What [`slices`] drew: the common account, every bin (with the fit's mean at its samples),
/// the legend's box and the dots' centres (pixels of the picture).
pub struct SlicesDrawn {
    /// Labels, ticks, captions; `points`: the samples whose bins were drawn.
    pub drawn: Drawn,
    /// Every bin of every panel.
    pub bins: Vec<DrawnBin>,
    /// The legend's box: (left, top, right, bottom) in pixels.
    pub legend: (i32, i32, i32, i32),
    /// The centre of every dot (a bin's mean) drawn, in pixels.
    pub dots: Vec<(i32, i32)>,
}

/// Slices: rows along / across the fibres, one column per incidence in [`SLICE_THETAS`]; each
/// panel the curves over theta_o in [-85, 85] deg in the plane (one per channel for RGB data),
/// each fitted curve with a band spanning it over the near samples' offsets from the plane (so
/// a fit that matches the samples covers them), and the measured samples near the slice
/// averaged in [`BIN_DEG`] bins of theta_o: the mean with a +-1 standard deviation bar (a
/// capture image puts thousands of pixels at nearly one view), and the fit's mean at the same
/// samples as a ring. The legend lies in a strip above the panels. Returns what it drew.
pub fn slices(path: Sink, plot: &SlicePlot) -> Result<SlicesDrawn> {
    font();
    let (cols, rows) = (SLICE_THETAS.len(), 2usize);
    let channels = plot.channels;
    // one curve per channel of RGB data, unless that makes more than 6 curves (the mean then)
    let ch = if channels == 3 && plot.curves.len() <= 2 {
        3
    } else {
        1
    };
    let (t_axis, b_axis) = axes(plot.psi_deg);
    let panels: Vec<Panel> = (0..rows * cols)
        .map(|k| {
            let (across, col) = (k / cols == 1, k % cols);
            let axis = if across { (b_axis, t_axis) } else { (t_axis, b_axis) };
            Panel::new(plot, (ch, k), across, &axis, SLICE_THETAS[col])
        })
        .collect();
    let entries = legend_entries(plot.curves, ch, &panels);
    let strip = legend::height(entries.len());
    let (w, h) = (380 * cols as u32, 340 * rows as u32 + 60 + strip);
    let mut buf = vec![0u8; (w * h * 3) as usize];
    let mut out = SlicesDrawn {
        drawn: Drawn {
            x_label: "theta_o [deg] (+: far side)".into(),
            y_label: "BRDF [1/sr]".into(),
            note: if ch == 3 {
                "per channel (R, G, B)".into()
            } else if channels == 3 {
                "channel mean".into()
            } else {
                "grey".into()
            },
            ..Default::default()
        },
        bins: Vec::new(),
        legend: (0, 0, 0, 0),
        dots: Vec::new(),
    };
    let style = PanelStyle {
        curves: plot.curves,
        ch,
        log_y: plot.log_y,
        y_ticks: RefCell::new(Vec::new()),
        dots: RefCell::new(Vec::new()),
    };
    {
        let root = BitMapBackend::with_buffer(&mut buf, (w, h)).into_drawing_area();
        root.fill(&WHITE).map_err(err)?;
        let root = root.titled(plot.title, ("sans-serif", 22)).map_err(err)?;
        let (top, body) = root.split_vertically(strip);
        out.legend = legend::draw(&top, &entries)?;
        for (panel, area) in panels.into_iter().zip(body.split_evenly((rows, cols))) {
            out.drawn.points += panel.near;
            out.drawn.panels.push(panel.caption.clone());
            style.draw(&area, &panel)?;
            out.bins.extend(panel.bins);
        }
        root.present().map_err(err)?;
    }
    save(path, w, h, buf)?;
    out.drawn.y_ticks = style.y_ticks.into_inner();
    out.drawn.x_ticks = (-3..=3).map(|k| tick_label(30.0 * k as f64)).collect();
    out.dots = style.dots.into_inner();
    Ok(out)
}

/// The legend's entries: each curve's channels (in the plane where it has a band), the band,
/// the measured dots and the fit's rings.
fn legend_entries(curves: &[Curve], ch: usize, panels: &[Panel]) -> Vec<Entry> {
    let banded = panels.iter().any(|p| p.bands.iter().any(|b| b.is_some()));
    let mut entries = Vec::new();
    for (i, c) in curves.iter().enumerate() {
        for cc in 0..ch {
            let colour = curve_colour(i, cc, ch);
            let mut label = if ch == 1 {
                c.name.clone()
            } else {
                format!("{} ({})", c.name, ["R", "G", "B"][cc])
            };
            if banded && !c.dashed {
                label += ", in the plane";
            }
            entries.push(Entry {
                label,
                mark: Mark::Line {
                    colour,
                    width: if c.dashed { 1 } else { 2 },
                    dashed: c.dashed,
                },
            });
        }
    }
    if banded {
        let i = curves.iter().position(|c| !c.dashed).unwrap_or(0);
        entries.push(Entry {
            label: "band: the fit over the near samples' offsets from the plane".into(),
            mark: Mark::Band(curve_colour(i, 0, ch)),
        });
    }
    entries.push(Entry {
        label: format!("measured near the slice: mean, +-1 sd per {BIN_DEG:.0} deg bin"),
        mark: Mark::Dot(bin_colour(0, ch)),
    });
    if panels.iter().flat_map(|p| &p.bins).any(|b| b.fit.is_some()) {
        entries.push(Entry {
            label: "fitted at those samples (mean)".into(),
            mark: Mark::Ring,
        });
    }
    entries
}

/// The colour of channel `cc` of curve `i` (`ch` channels drawn).
fn curve_colour(i: usize, cc: usize, ch: usize) -> RGBColor {
    if ch == 1 {
        palette(i + 1)
    } else {
        channel_colour(cc, ch)
    }
}

/// The colour of the bins' channel `cc` (`ch` channels drawn).
fn bin_colour(cc: usize, ch: usize) -> RGBColor {
    if ch == 1 {
        palette(0)
    } else {
        channel_colour(cc, ch)
    }
}

/// Per channel drawn: (theta_o, value).
type Lines = Vec<Vec<(f64, f64)>>;
/// Per channel drawn: (theta_o, smallest, largest).
type Band = Vec<Vec<(f64, f64, f64)>>;

/// One panel of the slices, worked out before it is drawn: the curves along it, their bands
/// and the bins of the samples near it.
struct Panel {
    /// Per curve, per channel drawn: (theta_o, value).
    lines: Vec<Lines>,
    /// Per curve, its band (solid curves, when samples lie near the slice).
    bands: Vec<Option<Band>>,
    bins: Vec<DrawnBin>,
    /// The smallest and largest value drawn (on a log axis, of the positive ones).
    y_range: (f64, f64),
    caption: String,
    /// The samples in the bins drawn.
    near: usize,
}

impl Panel {
    /// The slice at incidence `theta_i` in the plane of `axes.0` (along the fibres, or `across`
    /// them; `axes.1` out of it); `at` = (channels drawn per curve, the panel's number).
    fn new(plot: &SlicePlot, at: (usize, usize), across: bool, axes: &(Vec3, Vec3), theta_i: f64) -> Self {
        let ((ch, k), channels) = (at, plot.channels);
        let (axis, other) = axes;
        let l = in_plane(axis, -theta_i);
        let xs: Vec<f64> = (0..=170).map(|i| -85.0 + i as f64).collect();
        let per_channel = |vals: &[(f64, [f64; 3])]| -> Lines {
            (0..ch)
                .map(|c| {
                    vals.iter()
                        .map(|(x, f)| (*x, pick(f, ch, channels)[c]))
                        .collect()
                })
                .collect()
        };
        let lines: Vec<Lines> = plot
            .curves
            .iter()
            .map(|c| {
                let vals: Vec<(f64, [f64; 3])> = xs
                    .iter()
                    .filter_map(|&x| (c.brdf)(&l, &in_plane(axis, x)).map(|f| (x, f)))
                    .collect();
                per_channel(&vals)
            })
            .collect();
        let near = near_slice(plot.samples, plot.psi_deg, theta_i, across, channels);
        let offsets = band_offsets(&near);
        let bands: Vec<Option<Band>> = plot
            .curves
            .iter()
            .map(|c| {
                (!c.dashed && !offsets.is_empty()).then(|| {
                    let span = |x: f64| span(c.brdf, &offsets, (axis, other), x);
                    let b: Vec<(f64, [f64; 3], [f64; 3])> =
                        xs.iter().filter_map(|&x| span(x).map(|(a, b)| (x, a, b))).collect();
                    (0..ch)
                        .map(|cc| {
                            b.iter()
                                .map(|(x, lo, hi)| {
                                    let (lo, hi) = (pick(lo, ch, channels), pick(hi, ch, channels));
                                    (*x, lo[cc], hi[cc])
                                })
                                .collect()
                        })
                        .collect()
                })
            })
            .collect();
        let fit_curve = plot.curves.last().filter(|c| !c.dashed).map(|c| c.brdf);
        let bins = bin_samples(&near, fit_curve, (ch, channels), (k, plot.log_y));
        let y_range = y_range(&lines, &bands, &bins, ch, plot.log_y);
        let drawn: Vec<&DrawnBin> = bins.iter().filter(|b| b.drawn).collect();
        let n: usize = drawn.iter().map(|b| b.n).sum();
        let caption = format!(
            "{} the fibres, theta_i {theta_i:.0} deg ({n} samples, {} bins)",
            if across { "across" } else { "along" },
            drawn.len()
        );
        Self {
            lines,
            bands,
            bins,
            y_range,
            caption,
            near: n,
        }
    }
}

/// The smallest and largest value per channel of `f` at view angle `x` (degrees) over the
/// samples' `offsets` from the plane of `axes.0` (`axes.1` out of it); None where `f` has none.
fn span(f: Brdf, offsets: &[(f64, f64, f64)], axes: (&Vec3, &Vec3), x: f64) -> Option<([f64; 3], [f64; 3])> {
    let (axis, other) = axes;
    let mut lo = [f64::INFINITY; 3];
    let mut hi = [f64::NEG_INFINITY; 3];
    for &(light_deg, light_off, view_off) in offsets {
        let l = off_plane(axis, other, light_deg, light_off);
        let v = off_plane(axis, other, x, view_off);
        let Some(val) = f(&l, &v) else { continue };
        for c in 0..3 {
            lo[c] = lo[c].min(val[c]);
            hi[c] = hi[c].max(val[c]);
        }
    }
    lo[0].is_finite().then_some((lo, hi))
}

/// The smallest and largest of the values drawn: the curves, their bands, each bin's mean and
/// its +-1 sd, the fit's means; only the positive ones on a log axis; (1e-3, 1) when there is
/// none.
fn y_range(lines: &[Lines], bands: &[Option<Band>], bins: &[DrawnBin], ch: usize, log_y: bool) -> (f64, f64) {
    let positive = |y: &f64| y.is_finite() && (!log_y || *y > 0.0);
    let ys = lines
        .iter()
        .flatten()
        .flatten()
        .map(|p| p.1)
        .chain(bands.iter().flatten().flatten().flatten().flat_map(|p| [p.1, p.2]))
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

/// How every panel of one slices figure is drawn, and the y tick labels and dots they drew.
struct PanelStyle<'a> {
    curves: &'a [Curve<'a>],
    /// Channels drawn per curve: 3 (R, G, B) or 1 (grey, or the channel mean).
    ch: usize,
    log_y: bool,
    y_ticks: RefCell<Vec<String>>,
    dots: RefCell<Vec<(i32, i32)>>,
}

/// A slice's chart: theta_o across, the BRDF (linear or log) up.
type SliceChart<'a, 'b, Y> =
    ChartContext<'a, BitMapBackend<'b>, Cartesian2d<Ticked<RangedCoordf64>, Ticked<Y>>>;

impl PanelStyle<'_> {
    /// Draw `panel` into `area`: its caption, axes, bands, curves and bins.
    fn draw(
        &self,
        area: &DrawingArea<BitMapBackend<'_>, plotters::coord::Shift>,
        panel: &Panel,
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
                panel,
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
                panel,
            )
        }
    }

    /// Draw into the panel's built chart: the axes, the bands, the curves and the bins channel
    /// by channel.
    fn draw_chart<'a, 'b: 'a, Y>(&self, chart: &mut SliceChart<'a, 'b, Y>, panel: &Panel) -> Result<()>
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
        for (i, band) in panel.bands.iter().enumerate() {
            for (cc, band) in band.iter().flatten().enumerate() {
                let pts: Vec<(f64, f64, f64)> = band
                    .iter()
                    .copied()
                    .filter(|p| !self.log_y || p.1 > 0.0)
                    .collect();
                let outline: Vec<(f64, f64)> = pts
                    .iter()
                    .map(|p| (p.0, p.2))
                    .chain(pts.iter().rev().map(|p| (p.0, p.1)))
                    .collect();
                let colour = curve_colour(i, cc, self.ch).mix(0.16);
                chart
                    .draw_series(std::iter::once(Polygon::new(outline, colour.filled())))
                    .map_err(err)?;
            }
        }
        for (i, (c, line)) in self.curves.iter().zip(&panel.lines).enumerate() {
            let thin = panel.bands[i].is_some();
            for (cc, line) in line.iter().enumerate() {
                self.draw_curve(chart, c, (i, cc, thin), line)?;
            }
        }
        for cc in 0..self.ch {
            self.draw_bins(chart, &panel.bins, cc)?;
        }
        Ok(())
    }

    /// Draw channel `cc` of curve `c` (number `i`; `at` = (i, cc, thin: drawn in 1 px beside
    /// its band)): solid, or dashed (every other pair of consecutive points).
    fn draw_curve<'a, 'b: 'a, Y>(
        &self,
        chart: &mut SliceChart<'a, 'b, Y>,
        c: &Curve,
        at: (usize, usize, bool),
        line: &[(f64, f64)],
    ) -> Result<()>
    where
        Y: Ranged<ValueType = f64>,
    {
        let (i, cc, thin) = at;
        let color = curve_colour(i, cc, self.ch);
        let style = color.stroke_width(if c.dashed || thin { 1 } else { 2 });
        if c.dashed {
            // dashes: every other pair of consecutive points
            let segs = line.windows(2).step_by(2).map(|s| s.to_vec());
            chart
                .draw_series(segs.map(|s| PathElement::new(s, style)))
                .map_err(err)?;
        } else {
            chart
                .draw_series(LineSeries::new(line.to_vec(), style))
                .map_err(err)?;
        }
        Ok(())
    }

    /// Draw channel `cc` of the bins: the +-1 sd bars, the means as dots (their centres noted)
    /// and the fit's means as rings.
    fn draw_bins<'a, 'b: 'a, Y>(
        &self,
        chart: &mut SliceChart<'a, 'b, Y>,
        bins: &[DrawnBin],
        cc: usize,
    ) -> Result<()>
    where
        Y: Ranged<ValueType = f64>,
    {
        let log_y = self.log_y;
        let color = bin_colour(cc, self.ch);
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
        let means: Vec<(f64, f64)> = bins
            .iter()
            .filter(|b| !log_y || b.mean[cc] > 0.0)
            .map(|b| (b.x, b.mean[cc]))
            .collect();
        self.dots
            .borrow_mut()
            .extend(means.iter().map(|p| chart.backend_coord(p)));
        chart
            .draw_series(means.iter().map(|p| Circle::new(*p, 3, color.filled())))
            .map_err(err)?;
        chart
            .draw_series(
                bins.iter()
                    .filter_map(|b| b.fit.map(|f| (b.x, f[cc])))
                    .filter(|p| !log_y || p.1 > 0.0)
                    .map(|p| Circle::new(p, 5, BLACK.mix(0.7).stroke_width(1))),
            )
            .map_err(err)?;
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
        let got: Vec<(f64, f64)> = near.iter().map(|p| (p.x, p.value)).collect();
        assert_eq!(got.len(), 3, "{got:?}");
        for (g, want) in got.iter().zip([40.0, 40.0, -40.0]) {
            assert!(
                (g.0 - want).abs() < 1e-9 && (g.1 - 0.4).abs() < 1e-15,
                "{g:?}"
            );
        }
        let near = near_slice(&all, psi, 30.0, true, 1);
        assert_eq!(near.len(), 1);
        assert!((near[0].x - 40.0).abs() < 1e-9 && near[0].value == 0.2);
    }
}
