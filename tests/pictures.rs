//! Pictures that show something (issue 22, items 5, 7, 9, 10): a capture fit's report draws the
//! captured samples, residual maps at the image's resolution with a colour bar in percent, the
//! recovered maps of `fit --maps` as pictures with colour bars; plots have short, nice ticks;
//! renders keep their highlight and have no black half; a PNG capture read with the wrong
//! transfer curve is named.

mod common;

use assert_cmd::Command;
use fibrefit::export::atomic::Sink;
use fibrefit::export::plots::{self, nice_ticks, tick_label, Series};
use std::path::{Path, PathBuf};

fn fibrefit() -> Command {
    Command::cargo_bin("fibrefit").expect("binary built")
}

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// A copy of the shipped brushed capture (sRGB 16-bit PNGs) in `dir`, with `encoding` set.
fn brushed(dir: &Path, encoding: &str) -> PathBuf {
    let src = root().join("data_synthetic/brushed");
    let d = dir.join(format!("brushed_{encoding}"));
    std::fs::create_dir_all(&d).unwrap();
    for e in std::fs::read_dir(&src).unwrap() {
        let p = e.unwrap().path();
        std::fs::copy(&p, d.join(p.file_name().unwrap())).unwrap();
    }
    let toml = std::fs::read_to_string(d.join("capture.toml")).unwrap();
    assert!(toml.contains("encoding = \"srgb\""));
    let toml = toml.replace("encoding = \"srgb\"", &format!("encoding = \"{encoding}\""));
    std::fs::write(d.join("capture.toml"), toml).unwrap();
    d.join("capture.toml")
}

/// Fit the brushed capture with the shipped config; (stdout, stderr).
fn fit_brushed(capture: &Path, out: &Path, report: Option<&Path>) -> (String, String) {
    let mut cmd = fibrefit();
    cmd.arg("fit")
        .arg(capture)
        .arg("--config")
        .arg(root().join("configs/fit_brushed.toml"))
        .arg("--out")
        .arg(out);
    if let Some(r) = report {
        cmd.arg("--report").arg(r);
    }
    let run = cmd.output().unwrap();
    let (o, e) = (
        String::from_utf8_lossy(&run.stdout).to_string(),
        String::from_utf8_lossy(&run.stderr).to_string(),
    );
    assert!(run.status.success(), "{e}");
    (o, e)
}

#[test]
fn srgb_pngs_read_as_linear_are_named_and_the_right_encoding_is_not() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let (out, err) = fit_brushed(&brushed(d, "linear"), &d.join("lin.json"), None);
    // on stderr (the quality banner), in the report's warnings and in the result JSON
    assert!(
        err.contains("wrong transfer curve") && err.contains("`encoding"),
        "{err}"
    );
    assert!(err.contains("encoding = \\\"srgb\\\"") || err.contains("encoding = \"srgb\""));
    assert!(out.contains("wrong transfer curve"), "{out}");
    let json = std::fs::read_to_string(d.join("lin.json")).unwrap();
    assert!(json.contains("wrong transfer curve"));
    // the slope it measured is far from 1
    let slope: f64 = err
        .split("ln(data) rises ")
        .nth(1)
        .and_then(|t| t.split(' ').next())
        .and_then(|t| t.parse().ok())
        .expect("the slope in the warning");
    assert!((slope - 1.0).abs() > 0.15, "{slope}");

    let (out, err) = fit_brushed(&brushed(d, "srgb"), &d.join("ok.json"), None);
    assert!(!err.contains("transfer curve"), "{err}");
    assert!(!out.contains("transfer curve"), "{out}");
}

#[test]
fn a_capture_report_draws_its_samples_residuals_at_image_size_and_colour_bars() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let rep = d.join("rep");
    fit_brushed(&brushed(d, "srgb"), &d.join("r.json"), Some(&rep));
    let md = std::fs::read_to_string(rep.join("report.md")).unwrap();
    // hemispheres: one row per image, every sample drawn (4 images of 64 x 64)
    assert!(md.contains("one row per capture image"), "{md}");
    assert!(md.contains("16384 samples drawn"), "{md}");
    let bar: f64 = md
        .split("samples drawn; residual colour bar +/-")
        .nth(1)
        .and_then(|t| t.split(' ').next())
        .and_then(|t| t.parse().ok())
        .expect("the residual colour bar in the report");
    // sized to the residuals (1 % noise), not to a factor e
    assert!(bar > 0.1 && bar < 20.0, "{bar}");
    // slices: binned means
    assert!(md.contains("per 2 deg bin of theta_o"), "{md}");
    // residual maps at the image's resolution, a colour bar in percent
    for k in 0..4 {
        let line = md
            .lines()
            .find(|l| l.starts_with(&format!("### Image {k}:")))
            .unwrap_or_else(|| panic!("image {k} in {md}"));
        assert!(
            line.contains("64 x 64 px") && line.contains("colour bar +/-"),
            "{line}"
        );
        let png = image::open(rep.join(format!("residual_map_{k:03}.png"))).unwrap();
        // magnified: each pixel a block, with axes and the bar
        assert!(png.width() > 64 * 5 && png.height() > 64 * 5);
    }
    let hemi = image::open(rep.join("hemispheres.png")).unwrap();
    // four rows (one per image)
    assert!(hemi.height() > 4 * 260, "{}", hemi.height());
}

#[test]
fn maps_are_drawn_as_pictures_with_colour_bars() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::write(d.join("synth.toml"), common::SYNTH).unwrap();
    fibrefit::synth::run(
        &d.join("synth.toml"),
        &d.join("d"),
        &fibrefit::progress::Progress::quiet(),
    )
    .unwrap();
    let blind = fibrefit::bench::maps::write_blind(&d.join("d")).unwrap();
    std::fs::write(
        d.join("fit.toml"),
        "model = \"varying-topology\"\nseed = 1\n[parameters]\nspacing = { value = 2.0, vary = false }\n\
         [maps]\nheight = true\nfibre_azimuth = true\nkd = true\nrounds = 4\n",
    )
    .unwrap();
    let run = fibrefit()
        .arg("fit")
        .arg(&blind)
        .args([
            "--config", "fit.toml", "--out", "r.json", "--maps", "maps", "-q",
        ])
        .current_dir(d)
        .output()
        .unwrap();
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(d.join("r.json")).unwrap()).unwrap();
    for name in ["height", "fibre_azimuth", "kd"] {
        let m = &json["maps"]["maps"][name];
        assert_eq!(m["picture"], format!("{name}.png"), "{m}");
        for f in [format!("{name}.png"), format!("{name}_std_error.png")] {
            let img = image::open(d.join("maps").join(&f)).unwrap().to_rgb8();
            // 16 x 16 texels magnified, panels (3 for RGB kd) and a colour bar
            let panels = if name == "kd" { 3 } else { 1 };
            assert!(img.width() > panels * 16 * 10 + 100, "{f}: {}", img.width());
            // the colour bar's column holds many colours
            let x = img.width() - 75;
            let colours: std::collections::BTreeSet<[u8; 3]> =
                (0..img.height()).map(|y| img.get_pixel(x, y).0).collect();
            assert!(
                colours.len() > 30,
                "{f}: {} colours in the bar",
                colours.len()
            );
        }
    }
    assert!(d.join("maps/residual.png").exists());
    assert_eq!(json["maps"]["maps"]["residual"]["picture"], "residual.png");
}

#[test]
fn ticks_are_nice_and_short_and_a_narrow_log_axis_has_several() {
    assert_eq!(tick_label(0.30000000000000004), "0.3");
    assert_eq!(tick_label(0.01), "0.01");
    assert_eq!(tick_label(150.0), "150");
    assert_eq!(tick_label(2.5e-5), "2.5e-5");
    assert_eq!(tick_label(1e6), "1e6");
    assert_eq!(
        nice_ticks(0.0, 1.0, false),
        vec![0.0, 0.2, 0.4, 0.6, 0.8, 1.0]
    );
    for (lo, hi) in [(0.9, 1.3), (0.5, 2.0), (1e-4, 1e2), (3.0, 7.0)] {
        let t = nice_ticks(lo, hi, true);
        assert!(t.len() >= 3, "{lo}..{hi}: {t:?}");
        assert!(t.iter().all(|v| *v >= lo * 0.999 && *v <= hi * 1.001));
    }
    // a plot reports what it drew: its ticks are short, there are several on each axis
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("xy.png");
    let series = vec![Series {
        name: "N = 8".into(),
        points: vec![(0.1, 1.0), (0.2, 1.1), (0.30000000000000004, 1.25)],
        line: true,
    }];
    let d = plots::xy(
        Sink::File(&p),
        &plots::XyPlot {
            title: "t",
            x_label: "x [s]",
            y_label: "ratio",
            series: &series,
            log_x: true,
            log_y: true,
        },
    )
    .unwrap();
    assert!(d.x_ticks.len() >= 3 && d.y_ticks.len() >= 3, "{d:?}");
    for t in d.x_ticks.iter().chain(&d.y_ticks) {
        assert!(t.len() <= 6, "{t}");
    }
    assert_eq!(d.points, 3);
    assert_eq!(d.x_label, "x [s]");
}

#[test]
fn a_render_of_the_silk_fit_keeps_its_highlight_and_has_no_black_half() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let run = fibrefit()
        .arg("fit")
        .arg(root().join("data_synthetic/silk/gonio.csv"))
        .arg("--config")
        .arg(root().join("configs/fit_silk.toml"))
        .args(["--out", "silk.json", "-q"])
        .current_dir(d)
        .output()
        .unwrap();
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    let render = |extra: &[&str], out: &str| {
        fibrefit()
            .args([
                "render",
                "--params",
                "silk.json",
                "--object",
                "sphere",
                "--size",
                "160",
                "160",
            ])
            // the flat lighting: one key light and the fill (studio, the default, adds more)
            .args(["--preset", "flat", "-q", "--out", out])
            .args(extra)
            .current_dir(d)
            .assert()
            .success();
        let img = image::open(d.join(out)).unwrap().to_rgba8();
        // the largest channel of each covered pixel
        let mut lit: Vec<u8> = img
            .pixels()
            .filter(|p| p.0[3] == 255)
            .map(|p| p.0[0].max(p.0[1]).max(p.0[2]))
            .collect();
        lit.sort();
        lit
    };
    let stats = |lit: &[u8]| {
        let n = lit.len() as f64;
        let median = lit[lit.len() / 2] as f64;
        let max = *lit.last().unwrap() as f64;
        let clipped = lit.iter().filter(|&&v| v == 255).count() as f64 / n;
        let black = lit.iter().filter(|&&v| v < 10).count() as f64 / n;
        (median, max, clipped, black)
    };
    let (median, max, clipped, black) = stats(&render(&[], "sphere.png"));
    // a highlight well above the body colour, not a clipped area
    assert!(max > 1.4 * median, "max {max}, median {median}");
    assert!(clipped < 0.01, "{clipped} of the sphere clipped");
    // the fill light: no black half
    assert!(black < 0.02, "{black} of the sphere black");
    // asked for no fill: the unlit side is black, as before
    let (_, _, _, black) = stats(&render(&["--fill", "0"], "nofill.png"));
    assert!(black > 0.2, "{black}");
    // a bad fill is refused
    let bad = fibrefit()
        .args([
            "render",
            "--params",
            "silk.json",
            "--fill",
            "-1",
            "--out",
            "x.png",
        ])
        .current_dir(d)
        .assert()
        .code(2);
    let err = String::from_utf8_lossy(&bad.get_output().stderr).to_string();
    assert!(err.contains("--fill -1"), "{err}");
    assert!(!d.join("x.png").exists());
}

/// Issue 40, item 4: the silk fit (within the noise) drawn in slices: the model at the plotted
/// samples' own directions agrees with the plotted means within their spread, a band covers
/// the samples' offsets from the plane, the legend lies clear of every dot, and the captions
/// count what is drawn.
#[test]
fn silk_slices_show_the_model_where_the_data_are() {
    use fibrefit::export::brdf_plots::{self, Curve, SlicePlot};
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let run = fibrefit()
        .arg("fit")
        .arg(root().join("data_synthetic/silk/gonio.csv"))
        .arg("--config")
        .arg(root().join("configs/fit_silk.toml"))
        .args(["--out", "silk.json", "--report", "rep", "-q"])
        .current_dir(d)
        .output()
        .unwrap();
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(d.join("silk.json")).unwrap()).unwrap();
    let psi = json["parameters"]["fibre_azimuth_deg"]["value"]
        .as_f64()
        .expect("the fitted azimuth");
    let (material, _) =
        fibrefit::api::material::Material::load(&d.join("silk.json"), None).unwrap();
    let samples = fibrefit::api::data::load(
        &root().join("data_synthetic/silk/gonio.csv"),
        &Default::default(),
    )
    .unwrap();
    let fitted = |l: &fibrefit::api::Vec3, v: &fibrefit::api::Vec3| Some(material.eval(l, v, None));
    let curves = [Curve {
        name: "fitted".into(),
        brdf: &fitted,
        dashed: false,
    }];
    let out = brdf_plots::slices(
        Sink::File(&d.join("slices.png")),
        &SlicePlot {
            title: "silk",
            psi_deg: psi,
            channels: samples.channels,
            curves: &curves,
            samples: &samples.samples,
            log_y: true,
        },
    )
    .unwrap();
    // the model at the samples agrees with the data's means within their spread
    let mut worst: f64 = 0.0;
    for b in &out.bins {
        let fit = b.fit.expect("the fit at every bin");
        for c in 0..3 {
            let spread = b.sd[c].max(b.sigma[c]);
            assert!(spread > 0.0, "{b:?}");
            worst = worst.max((fit[c] - b.mean[c]).abs() / spread);
        }
    }
    assert!(
        worst < 4.0,
        "a bin's fit is {worst:.2} spreads from its mean"
    );
    // the legend lies clear of every dot (radius 3 px)
    let (l, t, r, bt) = out.legend;
    assert!(out.dots.len() > 100, "{}", out.dots.len());
    for &(x, y) in &out.dots {
        assert!(
            x + 3 < l || x - 3 > r || y + 3 < t || y - 3 > bt,
            "dot ({x}, {y}) under the legend {:?}",
            out.legend
        );
    }
    // the captions count what is drawn: three dots (R, G, B) per bin
    let drawn: Vec<_> = out.bins.iter().filter(|b| b.drawn).collect();
    assert_eq!(out.dots.len(), 3 * drawn.len());
    let n: usize = drawn.iter().map(|b| b.n).sum();
    assert_eq!(out.drawn.points, n);
    let captioned: usize = out
        .drawn
        .panels
        .iter()
        .map(|c| {
            c.split(" deg (")
                .nth(1)
                .and_then(|t| t.split(' ').next())
                .and_then(|t| t.parse::<usize>().ok())
                .unwrap_or_else(|| panic!("{c}"))
        })
        .sum();
    assert_eq!(captioned, n);
    // the report says the same counts: the slices' and the hemisphere maps' samples drawn
    let md = std::fs::read_to_string(d.join("rep/report.md")).unwrap();
    assert!(
        md.contains(&format!("dots: the {n} samples near a slice")),
        "{md}"
    );
    let hemi = brdf_plots::hemispheres(
        Sink::File(&d.join("hemi.png")),
        &brdf_plots::HemispherePlot {
            title: "silk",
            psi_deg: psi,
            channels: samples.channels,
            fitted: &fitted,
            measured: None,
            samples: &samples.samples,
        },
    )
    .unwrap();
    assert!(hemi.points > 0);
    assert!(
        md.contains(&format!(" {} samples drawn;", hemi.points)),
        "{md}"
    );
}
