//! PNG plots with plotters, drawn into an RGB buffer and encoded by the `image` crate. Text uses
//! plotters' pure-Rust font rendering (ab_glyph) with DejaVu Sans embedded in the binary, so no
//! system font library is needed.

use super::atomic::Sink;
use anyhow::{anyhow, Result};
use plotters::coord::ranged1d::{AsRangedCoord, Ranged};
use plotters::prelude::*;
use std::sync::Once;

static FONT: &[u8] = include_bytes!("../../assets/fonts/DejaVuSans.ttf");
static REGISTER: Once = Once::new();

pub(crate) fn font() {
    REGISTER.call_once(|| {
        // the embedded font is valid; failure would only mean no text
        let _ = plotters::style::register_font("sans-serif", FontStyle::Normal, FONT);
    });
}

fn err<E: std::fmt::Debug>(e: E) -> anyhow::Error {
    anyhow!("plot: {e:?}")
}

/// A named set of points.
#[derive(Clone, Debug)]
pub struct Series {
    pub name: String,
    pub points: Vec<(f64, f64)>,
    /// Join the points with a line (else markers only).
    pub line: bool,
}

const W: u32 = 900;
const H: u32 = 600;

/// What a plot drew, so that a test (or a report's text) can say what a picture shows without
/// reading its pixels: the tick labels, the axis labels, how many data points, the colour bars.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Drawn {
    pub x_label: String,
    pub y_label: String,
    pub x_ticks: Vec<String>,
    pub y_ticks: Vec<String>,
    /// Data points (or samples, or pixels) drawn.
    pub points: usize,
    pub colour_bars: Vec<ColourBar>,
    /// Panel captions.
    pub panels: Vec<String>,
    /// One sentence on what the picture shows (for a report's text).
    pub note: String,
}

/// A colour bar as drawn: its label, the range it spans and its tick labels.
#[derive(Clone, Debug, PartialEq)]
pub struct ColourBar {
    pub label: String,
    pub lo: f64,
    pub hi: f64,
    pub ticks: Vec<String>,
}

/// An axis (linear or log) whose ticks are given: plotters' own key points, replaced by
/// [`nice_ticks`], with plotters' default (Debug) formatting replaced by the caller's.
pub struct Ticked<R: Ranged<ValueType = f64>> {
    inner: R,
    ticks: Vec<f64>,
}

/// `axis` (a range, or a range's `log_scale()`) with the ticks `ticks`.
pub fn ticked<A: AsRangedCoord<Value = f64>>(axis: A, ticks: Vec<f64>) -> Ticked<A::CoordDescType>
where
    A::CoordDescType: Ranged<ValueType = f64>,
{
    Ticked {
        inner: axis.into(),
        ticks,
    }
}

impl<R: Ranged<ValueType = f64>> Ranged for Ticked<R> {
    type FormatOption = plotters::coord::ranged1d::DefaultFormatting;
    type ValueType = f64;
    fn map(&self, value: &f64, limit: (i32, i32)) -> i32 {
        self.inner.map(value, limit)
    }
    fn key_points<Hint: plotters::coord::ranged1d::KeyPointHint>(&self, _hint: Hint) -> Vec<f64> {
        self.ticks.clone()
    }
    fn range(&self) -> std::ops::Range<f64> {
        self.inner.range()
    }
}

/// Tick positions for an axis over [lo, hi]: 1, 2, 2.5 or 5 x 10^k steps, about 6 of them; on a
/// log axis the decades (every other one past 8), else 1-2-5 or 1..9 x 10^k, else (a range
/// narrower than a factor 3) linear steps; at least 2 ticks whenever lo < hi.
pub fn nice_ticks(lo: f64, hi: f64, log: bool) -> Vec<f64> {
    if !(lo.is_finite() && hi.is_finite()) || hi <= lo {
        return if lo.is_finite() { vec![lo] } else { vec![] };
    }
    if log && lo > 0.0 && hi / lo >= 3.0 {
        let (d0, d1) = (lo.log10().ceil() as i32, hi.log10().floor() as i32);
        let decades = d1 - d0 + 1;
        if decades >= 3 {
            let every = if decades > 8 { 2 } else { 1 };
            return (d0..=d1)
                .filter(|d| (d - d0) % every == 0)
                .map(|d| 10f64.powi(d))
                .collect();
        }
        for mantissas in [
            &[1.0, 2.0, 5.0][..],
            &[1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0, 9.0],
        ] {
            let mut t = vec![];
            for d in (lo.log10().floor() as i32)..=(hi.log10().ceil() as i32) {
                for m in mantissas {
                    let v = m * 10f64.powi(d);
                    if v >= lo * (1.0 - 1e-12) && v <= hi * (1.0 + 1e-12) {
                        t.push(v);
                    }
                }
            }
            if t.len() >= 3 {
                return t;
            }
        }
    }
    let raw = (hi - lo) / 6.0;
    let mag = 10f64.powf(raw.log10().floor());
    let step = [1.0, 2.0, 2.5, 5.0, 10.0]
        .iter()
        .map(|m| m * mag)
        .find(|s| *s >= raw)
        .unwrap_or(10.0 * mag);
    let (k0, k1) = ((lo / step).ceil() as i64, (hi / step).floor() as i64);
    let mut t: Vec<f64> = (k0..=k1)
        .map(|k| {
            let v = k as f64 * step;
            // snap to the step's decimals: 3 * 0.1 is 0.30000000000000004
            let digits = (-step.log10().floor()).max(0.0) as i32 + 1;
            let f = 10f64.powi(digits);
            (v * f).round() / f
        })
        .filter(|v| !log || *v > 0.0)
        .collect();
    if t.len() < 2 {
        t = vec![lo, hi];
    }
    t
}

/// A short tick label: at most 3 significant digits, trailing zeros dropped, exponent notation
/// below 1e-3 and from 1e5 (0.30000000000000004 -> "0.3", 2.5e-5 -> "2.5e-5").
pub fn tick_label(x: f64) -> String {
    if x == 0.0 {
        return "0".into();
    }
    if !x.is_finite() {
        return format!("{x}");
    }
    let a = x.abs();
    let trim = |s: String| -> String {
        if s.contains('.') {
            s.trim_end_matches('0').trim_end_matches('.').to_string()
        } else {
            s
        }
    };
    if !(1e-3..1e5).contains(&a) {
        let e = a.log10().floor() as i32;
        let m = x / 10f64.powi(e);
        let m = trim(format!("{m:.2}"));
        let m = if m == "10" || m == "-10" {
            return tick_label(x / 10.0).replace(&format!("e{e}"), &format!("e{}", e + 1));
        } else {
            m
        };
        return format!("{m}e{e}");
    }
    let digits = (2 - a.log10().floor() as i32).clamp(0, 6) as usize;
    trim(format!("{x:.digits$}"))
}

/// How a colour map turns a value into a colour.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum ColourMap {
    /// Viridis-like, low dark.
    Sequential,
    /// Blue - white - red, symmetric about 0.
    Diverging,
    /// A hue circle (angles with a period: the fibre azimuth).
    Cyclic,
}

/// A colour scale: the colour map over [lo, hi] (on a log axis with `log`), its label.
#[derive(Clone, Debug)]
pub struct MapScale {
    pub lo: f64,
    pub hi: f64,
    pub log: bool,
    pub map: ColourMap,
    pub label: String,
}

impl MapScale {
    /// Position of `v` in [0, 1] (clamped).
    pub fn t(&self, v: f64) -> f64 {
        let t = if self.log {
            (v.max(f64::MIN_POSITIVE).ln() - self.lo.ln()) / (self.hi.ln() - self.lo.ln())
        } else {
            (v - self.lo) / (self.hi - self.lo)
        };
        if t.is_finite() {
            t.clamp(0.0, 1.0)
        } else {
            0.5
        }
    }

    pub fn colour(&self, v: f64) -> RGBColor {
        let t = self.t(v);
        match self.map {
            ColourMap::Sequential => sequential(t),
            ColourMap::Diverging => diverging(2.0 * t - 1.0),
            ColourMap::Cyclic => hue(t),
        }
    }

    /// A symmetric diverging scale [-s, s] with s the `pct` percentile of |values| (at least
    /// `floor`): residuals scaled to themselves, not to a fixed factor.
    pub fn symmetric(values: impl Iterator<Item = f64>, pct: f64, floor: f64, label: &str) -> Self {
        let s = percentile_abs(values, pct).max(floor);
        Self {
            lo: -s,
            hi: s,
            log: false,
            map: ColourMap::Diverging,
            label: label.into(),
        }
    }
}

/// The `pct` percentile of |v| over the finite values (0 when there are none).
pub fn percentile_abs(values: impl Iterator<Item = f64>, pct: f64) -> f64 {
    let mut a: Vec<f64> = values.filter(|v| v.is_finite()).map(f64::abs).collect();
    if a.is_empty() {
        return 0.0;
    }
    a.sort_by(f64::total_cmp);
    a[((a.len() - 1) as f64 * pct / 100.0).round() as usize]
}

/// The `lo`, `hi` percentiles of the finite values (None when there are none).
pub fn percentiles(values: impl Iterator<Item = f64>, lo: f64, hi: f64) -> Option<(f64, f64)> {
    let mut a: Vec<f64> = values.filter(|v| v.is_finite()).collect();
    if a.is_empty() {
        return None;
    }
    a.sort_by(f64::total_cmp);
    let at = |p: f64| a[((a.len() - 1) as f64 * p / 100.0).round() as usize];
    Some((at(lo), at(hi)))
}

/// A hue circle for t in [0, 1] (t = 0 and 1 the same colour), at moderate saturation.
fn hue(t: f64) -> RGBColor {
    let h = (t.rem_euclid(1.0)) * 6.0;
    let x = 1.0 - (h % 2.0 - 1.0).abs();
    let (r, g, b) = match h as u32 {
        0 => (1.0, x, 0.0),
        1 => (x, 1.0, 0.0),
        2 => (0.0, 1.0, x),
        3 => (0.0, x, 1.0),
        4 => (x, 0.0, 1.0),
        _ => (1.0, 0.0, x),
    };
    let c = |v: f64| (40.0 + 190.0 * v).round() as u8;
    RGBColor(c(r), c(g), c(b))
}

/// Draw a vertical colour bar of `scale` filling `area` (the label above it, ticks on its
/// right); returns what it drew.
pub fn colour_bar<DB: DrawingBackend>(
    area: &DrawingArea<DB, plotters::coord::Shift>,
    scale: &MapScale,
) -> Result<ColourBar>
where
    DB::ErrorType: 'static,
{
    let (lo, hi) = if scale.hi > scale.lo {
        (scale.lo, scale.hi)
    } else {
        (
            scale.lo - 0.5 * scale.lo.abs().max(1e-12),
            scale.lo + 0.5 * scale.lo.abs().max(1e-12),
        )
    };
    let ticks = nice_ticks(lo, hi, scale.log);
    let labels = std::cell::RefCell::new(Vec::new());
    let fmt = |v: &f64| {
        let t = tick_label(*v);
        labels.borrow_mut().push(t.clone());
        t
    };
    let steps = 200;
    macro_rules! bar {
        ($y:expr, $at:expr) => {{
            // the tick labels and the rotated label right of a narrow bar
            let labels = (area.dim_in_pixel().0 as f64 * 0.62).min(80.0) as u32;
            let mut chart = ChartBuilder::on(area)
                .margin_top(10)
                .margin_bottom(10)
                .margin_right(4)
                .right_y_label_area_size(labels)
                .build_cartesian_2d(0.0..1.0, $y)
                .map_err(err)?;
            chart
                .configure_mesh()
                .disable_mesh()
                .disable_x_axis()
                .y_desc(scale.label.as_str())
                .y_label_formatter(&fmt)
                .label_style(("sans-serif", 11))
                .axis_desc_style(("sans-serif", 11))
                .draw()
                .map_err(err)?;
            chart
                .draw_series((0..steps).map(|k| {
                    let (a, b) = (
                        $at(k as f64 / steps as f64),
                        $at((k + 1) as f64 / steps as f64),
                    );
                    let c = scale.colour(0.5 * (a + b));
                    Rectangle::new([(0.0, a), (1.0, b)], c.filled())
                }))
                .map_err(err)?;
            chart
                .draw_series(std::iter::once(Rectangle::new(
                    [(0.0, lo), (1.0, hi)],
                    BLACK.stroke_width(1),
                )))
                .map_err(err)?;
        }};
    }
    if scale.log && lo > 0.0 {
        let at = |t: f64| (lo.ln() + t * (hi.ln() - lo.ln())).exp();
        bar!(ticked((lo..hi).log_scale(), ticks), at);
    } else {
        let at = |t: f64| lo + t * (hi - lo);
        bar!(ticked(lo..hi, ticks), at);
    }
    let mut ticks = labels.into_inner();
    ticks.dedup();
    Ok(ColourBar {
        label: scale.label.clone(),
        lo,
        hi,
        ticks,
    })
}

/// Image panels of one size (`width` x `height` values each, row-major from the top-left; NaN
/// grey: no value) side by side, each titled, drawn at an integer magnification (one value per
/// block of screen pixels, so the image's own resolution shows), with pixel axes and one
/// colour bar of `scale` on the right.
pub fn image_panels(
    path: Sink,
    title: &str,
    width: usize,
    height: usize,
    panels: &[(String, Vec<f32>)],
    scale: &MapScale,
) -> Result<Drawn> {
    font();
    let big = width.max(height).max(1);
    // an integer magnification of small images; images beyond 1024 px shown at 1024
    let mag = if big <= 420 {
        (420 / big).max(1) as f64
    } else {
        1024f64.min(big as f64) / big as f64
    };
    let (pw, ph) = (
        (width as f64 * mag).round() as u32,
        (height as f64 * mag).round() as u32,
    );
    let (pw, ph) = (pw.max(1), ph.max(1));
    // the panel's caption and its axes around the pw x ph image
    let (left, bottom, top, gap) = (56u32, 44u32, 24u32, 16u32);
    let bar_w = 110u32;
    let n = panels.len().max(1) as u32;
    let w = n * (left + pw + gap) + bar_w;
    let h = 40 + top + ph + bottom;
    let mut buf = vec![0u8; (w * h * 3) as usize];
    let mut drawn = Drawn {
        x_label: "x [pixel]".into(),
        y_label: "y [pixel]".into(),
        ..Default::default()
    };
    {
        let canvas = BitMapBackend::with_buffer(&mut buf, (w, h)).into_drawing_area();
        canvas.fill(&WHITE).map_err(err)?;
        let root = canvas.titled(title, ("sans-serif", 18)).map_err(err)?;
        let (body, bar_area) = root.split_horizontally(w - bar_w);
        let xt = std::cell::RefCell::new(Vec::new());
        let yt = std::cell::RefCell::new(Vec::new());
        for (k, (name, values)) in panels.iter().enumerate() {
            let x0 = (k as u32 * (left + pw + gap)) as i32;
            let area = body
                .clone()
                .shrink((x0, 0), (left + pw + gap, top + ph + bottom));
            let mut chart = ChartBuilder::on(&area)
                .caption(name.as_str(), ("sans-serif", 14))
                .margin_right(gap)
                .x_label_area_size(bottom)
                .y_label_area_size(left)
                .build_cartesian_2d(
                    ticked(0.0..width as f64, nice_ticks(0.0, width as f64, false)),
                    ticked(height as f64..0.0, nice_ticks(0.0, height as f64, false)),
                )
                .map_err(err)?;
            chart
                .configure_mesh()
                .disable_mesh()
                .x_desc("x [pixel]")
                .y_desc("y [pixel]")
                .x_label_formatter(&|v| {
                    let t = tick_label(*v);
                    xt.borrow_mut().push(t.clone());
                    t
                })
                .y_label_formatter(&|v| {
                    let t = tick_label(*v);
                    yt.borrow_mut().push(t.clone());
                    t
                })
                .label_style(("sans-serif", 11))
                .draw()
                .map_err(err)?;
            let plot = chart.plotting_area();
            let (xr, yr) = plot.get_pixel_range();
            let (sw, sh) = ((xr.end - xr.start).max(1), (yr.end - yr.start).max(1));
            for py in 0..sh {
                for px in 0..sw {
                    // the value under the screen pixel (blocks of about `mag` pixels)
                    let ix = (px as usize * width / sw as usize).min(width - 1);
                    let iy = (py as usize * height / sh as usize).min(height - 1);
                    let v = values[iy * width + ix];
                    let c = if v.is_finite() {
                        scale.colour(v as f64)
                    } else {
                        RGBColor(160, 160, 160)
                    };
                    canvas
                        .draw_pixel((xr.start + px, yr.start + py), &c)
                        .map_err(err)?;
                }
            }
            drawn.points += values.iter().filter(|v| v.is_finite()).count();
            drawn.panels.push(name.clone());
        }
        drawn.x_ticks = xt.into_inner();
        drawn.y_ticks = yt.into_inner();
        drawn.x_ticks.dedup();
        drawn.y_ticks.dedup();
        let bar_area = bar_area.shrink((8, top as i32 - 10), (bar_w - 8, ph + 20));
        drawn.colour_bars.push(colour_bar(&bar_area, scale)?);
        root.present().map_err(err)?;
    }
    let img = image::RgbImage::from_raw(w, h, buf).ok_or_else(|| anyhow!("plot buffer size"))?;
    path.png(&img)?;
    Ok(drawn)
}

pub(crate) fn palette(i: usize) -> RGBColor {
    const C: [RGBColor; 10] = [
        RGBColor(31, 119, 180),
        RGBColor(255, 127, 14),
        RGBColor(44, 160, 44),
        RGBColor(214, 39, 40),
        RGBColor(148, 103, 189),
        RGBColor(140, 86, 75),
        RGBColor(227, 119, 194),
        RGBColor(127, 127, 127),
        RGBColor(188, 189, 34),
        RGBColor(23, 190, 207),
    ];
    C[i % C.len()]
}

fn range(v: impl Iterator<Item = f64> + Clone, log: bool) -> (f64, f64) {
    let ok = |x: &f64| x.is_finite() && (!log || *x > 0.0);
    let lo = v.clone().filter(ok).fold(f64::INFINITY, f64::min);
    let hi = v.filter(ok).fold(f64::NEG_INFINITY, f64::max);
    if !lo.is_finite() {
        return if log { (1e-3, 1.0) } else { (0.0, 1.0) };
    }
    if log {
        (lo / 1.5, hi * 1.5)
    } else {
        let pad = 0.05 * (hi - lo).max(1e-12);
        (lo - pad, hi + pad)
    }
}

fn save(path: Sink, buf: Vec<u8>) -> Result<()> {
    let img = image::RgbImage::from_raw(W, H, buf).ok_or_else(|| anyhow!("plot buffer size"))?;
    path.png(&img)
}

/// An x-y plot (the request of [`xy`]): several series, each axis linear or logarithmic.
pub struct XyPlot<'a> {
    pub title: &'a str,
    pub x_label: &'a str,
    pub y_label: &'a str,
    pub series: &'a [Series],
    /// A logarithmic x axis (points at x <= 0 are left out).
    pub log_x: bool,
    /// A logarithmic y axis (points at y <= 0 are left out).
    pub log_y: bool,
}

/// An x-y plot of several series, each axis linear or logarithmic, with nice ticks (see
/// [`nice_ticks`], [`tick_label`]); returns what it drew.
pub fn xy(path: Sink, plot: &XyPlot) -> Result<Drawn> {
    font();
    let (log_x, log_y) = (plot.log_x, plot.log_y);
    let mut buf = vec![0u8; (W * H * 3) as usize];
    let ticks = DrawnTicks::default();
    let points;
    {
        let root = BitMapBackend::with_buffer(&mut buf, (W, H)).into_drawing_area();
        root.fill(&WHITE).map_err(err)?;
        let series = plot.series;
        let xs = series.iter().flat_map(|s| s.points.iter().map(|p| p.0));
        let ys = series.iter().flat_map(|s| s.points.iter().map(|p| p.1));
        let (x0, x1) = range(xs.collect::<Vec<_>>().into_iter(), log_x);
        let (y0, y1) = range(ys.collect::<Vec<_>>().into_iter(), log_y);
        let (kx, ky) = (nice_ticks(x0, x1, log_x), nice_ticks(y0, y1, log_y));
        let mut builder = ChartBuilder::on(&root);
        builder
            .caption(plot.title, ("sans-serif", 22))
            .margin(15)
            .x_label_area_size(50)
            .y_label_area_size(80);
        points = match (log_x, log_y) {
            (true, true) => draw_xy(
                &mut builder
                    .build_cartesian_2d(
                        ticked((x0..x1).log_scale(), kx),
                        ticked((y0..y1).log_scale(), ky),
                    )
                    .map_err(err)?,
                plot,
                &ticks,
            )?,
            (true, false) => draw_xy(
                &mut builder
                    .build_cartesian_2d(ticked((x0..x1).log_scale(), kx), ticked(y0..y1, ky))
                    .map_err(err)?,
                plot,
                &ticks,
            )?,
            (false, true) => draw_xy(
                &mut builder
                    .build_cartesian_2d(ticked(x0..x1, kx), ticked((y0..y1).log_scale(), ky))
                    .map_err(err)?,
                plot,
                &ticks,
            )?,
            (false, false) => draw_xy(
                &mut builder
                    .build_cartesian_2d(ticked(x0..x1, kx), ticked(y0..y1, ky))
                    .map_err(err)?,
                plot,
                &ticks,
            )?,
        };
        root.present().map_err(err)?;
    }
    save(path, buf)?;
    let (mut x_ticks, mut y_ticks) = (ticks.x.into_inner(), ticks.y.into_inner());
    x_ticks.dedup();
    y_ticks.dedup();
    Ok(Drawn {
        x_label: plot.x_label.into(),
        y_label: plot.y_label.into(),
        x_ticks,
        y_ticks,
        points,
        ..Default::default()
    })
}

/// The tick labels an x-y chart drew, in the order it drew them.
#[derive(Default)]
struct DrawnTicks {
    x: std::cell::RefCell<Vec<String>>,
    y: std::cell::RefCell<Vec<String>>,
}

/// An x-y chart whose axes (linear or log) have given ticks.
type XyChart<'a, 'b, X, Y> = ChartContext<'a, BitMapBackend<'b>, Cartesian2d<Ticked<X>, Ticked<Y>>>;

/// Draw `plot` into its built `chart`: the axes (their tick labels noted in `ticks`), each
/// series, and the legend. Returns the number of points drawn.
fn draw_xy<'a, 'b: 'a, X, Y>(
    chart: &mut XyChart<'a, 'b, X, Y>,
    plot: &XyPlot,
    ticks: &DrawnTicks,
) -> Result<usize>
where
    X: Ranged<ValueType = f64>,
    Y: Ranged<ValueType = f64>,
{
    chart
        .configure_mesh()
        .x_desc(plot.x_label)
        .y_desc(plot.y_label)
        .x_label_formatter(&|v| {
            let t = tick_label(*v);
            ticks.x.borrow_mut().push(t.clone());
            t
        })
        .y_label_formatter(&|v| {
            let t = tick_label(*v);
            ticks.y.borrow_mut().push(t.clone());
            t
        })
        .label_style(("sans-serif", 14))
        .axis_desc_style(("sans-serif", 15))
        .draw()
        .map_err(err)?;
    let mut points = 0;
    for (i, s) in plot.series.iter().enumerate() {
        points += draw_series(chart, s, palette(i), (plot.log_x, plot.log_y))?;
    }
    chart
        .configure_series_labels()
        .label_font(("sans-serif", 13))
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .position(SeriesLabelPosition::LowerLeft)
        .draw()
        .map_err(err)?;
    Ok(points)
}

/// Draw one series in `color` with its legend entry: a line with dots, or markers only; the
/// points that a log axis (`log`: x, y) cannot show are left out. Returns the points drawn.
fn draw_series<'a, 'b: 'a, X, Y>(
    chart: &mut XyChart<'a, 'b, X, Y>,
    s: &Series,
    color: RGBColor,
    log: (bool, bool),
) -> Result<usize>
where
    X: Ranged<ValueType = f64>,
    Y: Ranged<ValueType = f64>,
{
    let (log_x, log_y) = log;
    let pts: Vec<(f64, f64)> = s
        .points
        .iter()
        .copied()
        .filter(|p| {
            p.0.is_finite() && p.1.is_finite() && (!log_x || p.0 > 0.0) && (!log_y || p.1 > 0.0)
        })
        .collect();
    if s.line {
        chart
            .draw_series(LineSeries::new(pts.clone(), color.stroke_width(2)))
            .map_err(err)?
            .label(s.name.clone())
            .legend(move |(x, y)| {
                PathElement::new(vec![(x, y), (x + 20, y)], color.stroke_width(2))
            });
        chart
            .draw_series(pts.iter().map(|&p| Circle::new(p, 3, color.filled())))
            .map_err(err)?;
    } else {
        chart
            .draw_series(pts.iter().map(|&p| Circle::new(p, 4, color.filled())))
            .map_err(err)?
            .label(s.name.clone())
            .legend(move |(x, y)| Circle::new((x + 10, y), 4, color.filled()));
    }
    Ok(pts.len())
}

/// A histogram of `values` in `bins` equal bins.
pub fn histogram(
    path: Sink,
    title: &str,
    x_label: &str,
    values: &[f64],
    bins: usize,
) -> Result<()> {
    font();
    let (lo, hi) = range(values.iter().copied(), false);
    let width = (hi - lo) / bins as f64;
    let mut counts = vec![0u32; bins];
    for v in values.iter().filter(|v| v.is_finite()) {
        counts[(((v - lo) / width) as usize).min(bins - 1)] += 1;
    }
    let top = counts.iter().copied().max().unwrap_or(1) as f64 * 1.1;
    let mut buf = vec![0u8; (W * H * 3) as usize];
    {
        let root = BitMapBackend::with_buffer(&mut buf, (W, H)).into_drawing_area();
        root.fill(&WHITE).map_err(err)?;
        let mut chart = ChartBuilder::on(&root)
            .caption(title, ("sans-serif", 22))
            .margin(15)
            .x_label_area_size(45)
            .y_label_area_size(60)
            .build_cartesian_2d(
                ticked(lo..hi, nice_ticks(lo, hi, false)),
                ticked(0.0..top, nice_ticks(0.0, top, false)),
            )
            .map_err(err)?;
        chart
            .configure_mesh()
            .x_desc(x_label)
            .y_desc("count")
            .x_label_formatter(&|v| tick_label(*v))
            .y_label_formatter(&|v| tick_label(*v))
            .label_style(("sans-serif", 14))
            .draw()
            .map_err(err)?;
        chart
            .draw_series(counts.iter().enumerate().map(|(i, &c)| {
                let x0 = lo + i as f64 * width;
                Rectangle::new(
                    [(x0, 0.0), (x0 + width, c as f64)],
                    palette(0).mix(0.7).filled(),
                )
            }))
            .map_err(err)?;
        root.present().map_err(err)?;
    }
    save(path, buf)
}

/// The relative residuals (fitted - measured) / measured of a capture's samples, image by
/// image, at the image's full size (`size`, or the largest pixel seen): per channel, NaN where
/// a pixel has no sample (masked, saturated or subsampled out); f32, 4 bytes a value.
pub struct ImageResiduals {
    pub width: usize,
    pub height: usize,
    pub channels: usize,
    /// Per channel, row-major values from the top-left.
    pub values: Vec<Vec<f32>>,
}

/// [`ImageResiduals`] of every capture image with samples, by image index.
pub fn image_residuals(
    samples: &crate::load::samples::Samples,
    fitted: &[[f64; 3]],
) -> std::collections::BTreeMap<u32, ImageResiduals> {
    use crate::load::samples::Origin;
    let ch = samples.channels;
    let mut px: std::collections::BTreeMap<u32, Vec<(u32, u32, [f64; 3])>> = Default::default();
    for (s, m) in samples.samples.iter().zip(fitted) {
        if let Origin::Pixel { image, x, y } = s.origin {
            let mut r = [0.0; 3];
            for c in 0..ch {
                r[c] = (m[c] - s.value[c]) / s.value[c].abs().max(1e-12);
            }
            px.entry(image).or_default().push((x, y, r));
        }
    }
    px.into_iter()
        .map(|(k, p)| {
            let (w, h) = samples.image_size.unwrap_or((
                p.iter().map(|q| q.0).max().unwrap_or(0) as usize + 1,
                p.iter().map(|q| q.1).max().unwrap_or(0) as usize + 1,
            ));
            let mut values = vec![vec![f32::NAN; w * h]; ch];
            for (x, y, r) in p {
                let (x, y) = (x as usize, y as usize);
                if x < w && y < h {
                    for c in 0..ch {
                        values[c][y * w + x] = r[c] as f32;
                    }
                }
            }
            (
                k,
                ImageResiduals {
                    width: w,
                    height: h,
                    channels: ch,
                    values,
                },
            )
        })
        .collect()
}

/// Percentile of |relative residual| that sets a residual map's colour scale (so 1 % residuals
/// are not white on a scale sized for the worst outlier).
pub const RESIDUAL_PERCENTILE: f64 = 99.0;

/// A capture image's residual map at the image's resolution: one panel per channel (R, G, B;
/// one for grey), blue (fitted below measured) - white - red (above), grey where the pixel has no
/// sample, on a symmetric colour bar in percent sized to the [`RESIDUAL_PERCENTILE`] of |r|.
pub fn residual_map(path: Sink, title: &str, r: &ImageResiduals) -> Result<Drawn> {
    let pct: Vec<Vec<f32>> = r
        .values
        .iter()
        .map(|v| v.iter().map(|x| 100.0 * x).collect())
        .collect();
    let scale = MapScale::symmetric(
        pct.iter().flatten().map(|&x| x as f64),
        RESIDUAL_PERCENTILE,
        1e-6,
        "(fitted - measured) / measured [%]",
    );
    let names = if r.channels == 1 {
        vec!["grey".to_string()]
    } else {
        ["R", "G", "B"].map(|c| format!("channel {c}")).to_vec()
    };
    let panels: Vec<(String, Vec<f32>)> = names.into_iter().zip(pct).collect();
    image_panels(path, title, r.width, r.height, &panels, &scale)
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
