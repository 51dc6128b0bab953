//! The coverage picture of a photo set (`calibrate`'s `report/coverage.png`): each photo's light
//! (orange), view (blue, numbered) and half vector (grey) at the window's centre, seen from
//! above the board (x right, y up the page), the rim the horizon, circles every 30 degrees.

use super::atomic::Sink;
use super::plots::font;
use anyhow::{anyhow, Result};
use plotters::prelude::*;

const SIZE: u32 = 640;

fn err<E: std::fmt::Debug>(e: E) -> anyhow::Error {
    anyhow!("coverage picture: {e:?}")
}

/// (theta, phi) degrees as a point of the top view (sin theta, the azimuth).
fn top(d: [f64; 2]) -> (f64, f64) {
    let (t, p) = (d[0].to_radians(), d[1].to_radians());
    (t.sin() * p.cos(), t.sin() * p.sin())
}

/// Draw `dirs` (per photo: light, view, half vector as (theta, phi) degrees) into `sink`, with
/// `warnings` under the title (the first two).
pub fn coverage(sink: Sink, dirs: &[[[f64; 2]; 3]], warnings: &[String]) -> Result<()> {
    font();
    let mut buf = vec![0u8; (SIZE * SIZE * 3) as usize];
    {
        let root = BitMapBackend::with_buffer(&mut buf, (SIZE, SIZE)).into_drawing_area();
        root.fill(&WHITE).map_err(err)?;
        let caption = "light (orange), view (blue), half vector (grey) at the window's centre";
        let mut chart = ChartBuilder::on(&root)
            .caption(caption, ("sans-serif", 16))
            .margin(20)
            .build_cartesian_2d(-1.1f64..1.1f64, -1.1f64..1.1f64)
            .map_err(err)?;
        let grey = RGBColor(190, 190, 190);
        for theta in [30.0f64, 60.0, 90.0] {
            let r = theta.to_radians().sin();
            let ring = (0..=120).map(|k| {
                let a = k as f64 / 120.0 * std::f64::consts::TAU;
                (r * a.cos(), r * a.sin())
            });
            chart
                .draw_series(LineSeries::new(ring, grey.stroke_width(1)))
                .map_err(err)?;
            chart
                .draw_series(std::iter::once(Text::new(
                    format!("{theta:.0}°"),
                    (r * 0.707 + 0.01, -r * 0.707 - 0.01),
                    ("sans-serif", 13).into_font().color(&grey),
                )))
                .map_err(err)?;
        }
        for (a, b) in [((-1.0, 0.0), (1.0, 0.0)), ((0.0, -1.0), (0.0, 1.0))] {
            chart
                .draw_series(LineSeries::new([a, b], grey.stroke_width(1)))
                .map_err(err)?;
        }
        chart
            .draw_series([("x", (1.03, 0.02)), ("y", (0.02, 1.03))].map(|(t, at)| {
                Text::new(t, at, ("sans-serif", 14).into_font().color(&BLACK))
            }))
            .map_err(err)?;
        let orange = RGBColor(240, 140, 20);
        let blue = RGBColor(30, 90, 220);
        chart
            .draw_series(dirs.iter().map(|d| Circle::new(top(d[2]), 3, grey.filled())))
            .map_err(err)?;
        chart
            .draw_series(dirs.iter().map(|d| Circle::new(top(d[0]), 6, orange.filled())))
            .map_err(err)?;
        chart
            .draw_series(dirs.iter().map(|d| Circle::new(top(d[1]), 5, blue.stroke_width(2))))
            .map_err(err)?;
        chart
            .draw_series(dirs.iter().enumerate().map(|(k, d)| {
                let (x, y) = top(d[1]);
                Text::new(
                    k.to_string(),
                    (x + 0.03, y + 0.03),
                    ("sans-serif", 13).into_font().color(&blue),
                )
            }))
            .map_err(err)?;
        for (i, w) in warnings.iter().take(2).enumerate() {
            let short: String = w.chars().take(90).collect();
            root.draw(&Text::new(
                format!("warning: {short}{}", if w.len() > 90 { "..." } else { "" }),
                (10, SIZE as i32 - 40 + 18 * i as i32),
                ("sans-serif", 12).into_font().color(&RED),
            ))
            .map_err(err)?;
        }
        root.present().map_err(err)?;
    }
    let img = image::RgbImage::from_raw(SIZE, SIZE, buf).ok_or_else(|| anyhow!("plot buffer size"))?;
    sink.png(&img)
}
