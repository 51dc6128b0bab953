//! `fibrefit board`: board.toml's geometry is board.png's, the AprilTag detector finds every
//! marker where board.toml puts it, and refused options write nothing.

use assert_cmd::Command;
use fibrefit::api::board::{board, BoardRequest};
use fibrefit::board::detect;
use fibrefit::load::board::BoardFile;

fn make(paper: &str, window_mm: f64, dpi: u32) -> (tempfile::TempDir, BoardFile, image::GrayImage) {
    let dir = tempfile::tempdir().unwrap();
    let req = BoardRequest {
        paper: paper.into(),
        window_mm,
        dpi,
        patch_reflectance: 0.5,
    };
    board(&req, dir.path()).unwrap();
    let file = BoardFile::read(&dir.path().join("board.toml")).unwrap();
    let png = image::open(dir.path().join("board.png"))
        .unwrap()
        .to_luma8();
    (dir, file, png)
}

#[test]
fn board_toml_is_the_png_geometry() {
    for (paper, window, dpi) in [("a4", 60.0, 300), ("letter", 80.0, 200), ("a3", 120.0, 150)] {
        let (_dir, b, png) = make(paper, window, dpi);
        assert_eq!([png.width(), png.height()], b.png_px, "{paper}");
        assert!(b.marker.len() >= 12, "{paper}: {} markers", b.marker.len());
        // the origin is the window's centre
        let w = b.window_mm;
        assert!(
            (w[0] + w[2]).abs() < 1e-9 && (w[1] + w[3]).abs() < 1e-9,
            "{w:?}"
        );
        assert!((w[2] - w[0] - window).abs() <= b.mm_per_px(), "{w:?}");
        let bar = b.scale_bar.rect_mm;
        assert!((bar[2] - bar[0] - 100.0).abs() <= b.mm_per_px(), "{bar:?}");
        for m in &b.marker {
            // every corner is a pixel corner; the pixel inside it is the black border, the
            // pixel diagonally outside is the white ring
            let px: Vec<[f64; 2]> = m
                .corners_mm
                .iter()
                .map(|c| b.mm_to_png(c[0], c[1]))
                .collect();
            let (cu, cv) = (
                px.iter().map(|p| p[0]).sum::<f64>() / 4.0,
                px.iter().map(|p| p[1]).sum::<f64>() / 4.0,
            );
            for p in &px {
                assert!(
                    (p[0] - p[0].round()).abs() < 1e-6 && (p[1] - p[1].round()).abs() < 1e-6,
                    "{p:?}"
                );
                let (su, sv) = ((cu - p[0]).signum(), (cv - p[1]).signum());
                let at = |du: f64, dv: f64| {
                    png.get_pixel((p[0] + du).floor() as u32, (p[1] + dv).floor() as u32)[0]
                };
                assert_eq!(at(0.5 * su, 0.5 * sv), 0, "marker {} corner {p:?}", m.id);
                assert_eq!(
                    at(-0.5 * su, -0.5 * sv),
                    255,
                    "marker {} corner {p:?}",
                    m.id
                );
            }
        }
        // the patch prints its stated reflectance
        let p = b.patch.rect_mm;
        let [u, v] = b.mm_to_png(0.5 * (p[0] + p[2]), 0.5 * (p[1] + p[3]));
        let grey = png.get_pixel(u as u32, v as u32)[0] as f32 / 255.0;
        let linear = fibrefit::load::image_io::srgb_to_linear(grey) as f64;
        assert!((linear - b.patch.reflectance).abs() < 1e-6);
    }
}

#[test]
fn the_detector_finds_every_marker_where_board_toml_puts_it() {
    let (_dir, b, png) = make("a4", 60.0, 300);
    let found = detect::find(png.as_raw(), png.width() as usize, png.height() as usize).unwrap();
    assert_eq!(found.len(), b.marker.len());
    let (mut worst, mut mean) = (0.0f64, [0.0f64; 2]);
    for f in &found {
        let m = b.marker(f.id).unwrap();
        for (c, mm) in f.corners.iter().zip(&m.corners_mm) {
            let p = b.mm_to_png(mm[0], mm[1]);
            worst = worst.max((c[0] - p[0]).hypot(c[1] - p[1]));
            mean[0] += (c[0] - p[0]) / (4 * found.len()) as f64;
            mean[1] += (c[1] - p[1]) / (4 * found.len()) as f64;
        }
    }
    eprintln!(
        "{} markers, worst corner {worst:.3} px, mean offset {:.3}, {:.3} px",
        found.len(),
        mean[0],
        mean[1]
    );
    assert!(worst < 0.5, "worst corner {worst} px");
}

#[test]
fn refused_options_name_the_option_and_write_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("board");
    for (args, flag) in [
        (vec!["--paper", "b5"], "--paper"),
        (vec!["--window-mm", "250"], "--window-mm"),
        (vec!["--dpi", "20"], "--dpi"),
        (vec!["--patch-reflectance", "1.5"], "--patch-reflectance"),
    ] {
        let o = Command::cargo_bin("fibrefit")
            .unwrap()
            .arg("board")
            .arg("--out")
            .arg(&out)
            .args(&args)
            .output()
            .unwrap();
        assert_eq!(o.status.code(), Some(2), "{args:?}");
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(err.contains(flag), "{args:?}: {err}");
        assert!(!out.exists(), "{args:?} wrote {}", out.display());
    }
    // a second run does not replace a board.png that is an input elsewhere: it rewrites its own
    let o = Command::cargo_bin("fibrefit")
        .unwrap()
        .args(["board", "--quiet", "--out"])
        .arg(&out)
        .output()
        .unwrap();
    assert_eq!(
        o.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&o.stderr)
    );
    assert!(out.join("board.png").exists() && out.join("board.toml").exists());
}

#[test]
fn board_pdf_is_the_png_on_a_page_of_its_printed_size() {
    let (dir, b, png) = make("a4", 60.0, 300);
    let pdf = std::fs::read(dir.path().join("board.pdf")).unwrap();
    assert!(pdf.starts_with(b"%PDF-"));
    let text = String::from_utf8_lossy(&pdf);
    // the page: the picture's size in points (1/72 inch), so "actual size" prints it at scale
    let at = text.find("/MediaBox [").expect("a media box") + "/MediaBox [".len();
    let nums: Vec<f64> = text[at..text[at..].find(']').unwrap() + at]
        .split_whitespace()
        .map(|v| v.parse().unwrap())
        .collect();
    let p = b.paper_mm;
    let want = [(p[2] - p[0]) / 25.4 * 72.0, (p[3] - p[1]) / 25.4 * 72.0];
    assert!(
        (nums[2] - want[0]).abs() < 0.01 && (nums[3] - want[1]).abs() < 0.01,
        "{nums:?} against {want:?} pt"
    );
    // the image: the PNG's own pixels
    for key in [
        format!("/Width {}", png.width()),
        format!("/Height {}", png.height()),
    ] {
        assert!(text.contains(&key), "{key}");
    }
    let start = pdf.windows(7).position(|w| w == b"stream\n").unwrap() + 7;
    let end = start
        + pdf[start..]
            .windows(10)
            .position(|w| w == b"\nendstream")
            .unwrap();
    let pixels = miniz_oxide::inflate::decompress_to_vec_zlib(&pdf[start..end]).unwrap();
    assert!(
        pixels == *png.as_raw(),
        "the PDF's image differs from board.png"
    );
}
