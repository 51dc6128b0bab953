//! The photo route end to end (issue 36): `fibrefit board`, 8 synthetic JPEG photos of a
//! lambert swatch in its window (20-60 degrees of elevation, a flash 10 mm beside the lens,
//! a different exposure each), `fibrefit calibrate`, then `fibrefit fit` on the capture it
//! writes. Bad photos are refused by name with nothing written.

use assert_cmd::Command;
use fibrefit::api::board::{board, BoardRequest};
use fibrefit::board::camera::{Intrinsics, Pose};
use fibrefit::load::board::BoardFile;
use fibrefit::model::params::{ModelParams, RawParams};
use fibrefit::model::ModelId;
use fibrefit::synth::photo::{PhotoShot, SwatchOnBoard};
use nalgebra::Vector3;
use std::path::{Path, PathBuf};

const TRUTH: Intrinsics = Intrinsics {
    size_px: [1600, 1200],
    focal_px: 1000.0, // a phone's wide lens: the whole A4 board (and its patch) in every frame at 300 mm
    principal_px: [805.0, 596.0],
    k: [-0.08, 0.02],
};
const KD: [f64; 3] = [0.6, 0.45, 0.3];

fn poses() -> Vec<Pose> {
    (0..8)
        .map(|i| {
            let elev = (20.0 + 40.0 * (i % 4) as f64 / 3.0).to_radians();
            let azim = (45.0 * i as f64 + 10.0).to_radians();
            let eye =
                Vector3::new(azim.cos() * elev.cos(), azim.sin() * elev.cos(), elev.sin()) * 300.0;
            Pose::look_at(eye, Vector3::zeros())
        })
        .collect()
}

/// The board and 8 JPEG photos in `dir`.
fn shoot(dir: &Path) -> (PathBuf, Vec<PathBuf>) {
    board(&BoardRequest::default(), dir).unwrap();
    let raw: RawParams = toml::from_str(&format!("kd = {KD:?}")).unwrap();
    let (params, _) = ModelParams::from_raw(&raw, ModelId::Lambert).unwrap();
    let set = SwatchOnBoard::read(&dir.join("board.toml"), ModelId::Lambert, params).unwrap();
    let scene = set.scene();
    let mut files = Vec::new();
    for (k, pose) in poses().iter().enumerate() {
        let shot = PhotoShot {
            room_light: None,
            intrinsics: TRUTH,
            pose: *pose,
            light_mm: pose.position + pose.to_board_direction(&Vector3::new(10.0, 0.0, 0.0)),
            intensity: 1.0,
            exposure: 0.5 * std::f64::consts::PI * 0.09 * (1.0 + 0.1 * k as f64),
            noise_gain: 3e-5,
            noise_floor: 0.002,
            seed: k as u64,
            supersample: 3,
            blur_px: 0.0,
        };
        let photo = scene.render(&shot).unwrap();
        let path = dir.join(format!("photo_{k}.jpg"));
        let mut f = std::fs::File::create(&path).unwrap();
        image::codecs::jpeg::JpegEncoder::new_with_quality(&mut f, 95)
            .encode_image(&photo)
            .unwrap();
        files.push(path);
    }
    (dir.join("board.toml"), files)
}

fn calibrate(board: &Path, photos: &[PathBuf], out: &Path) -> std::process::Output {
    Command::cargo_bin("fibrefit")
        .unwrap()
        .arg("calibrate")
        .arg("--board")
        .arg(board)
        .arg("--out")
        .arg(out)
        .args(["--texels", "64", "64", "-q"])
        .args(photos)
        .output()
        .unwrap()
}

#[test]
fn photos_become_a_capture_that_fits_the_truth() {
    let dir = tempfile::tempdir().unwrap();
    let (board_toml, photos) = shoot(dir.path());
    // the calibration, through the API: cameras within 1 mm, RMS under 0.3 px
    let req = fibrefit::api::calibrate::CalibrateRequest {
        texels: [64, 64],
        ..fibrefit::api::calibrate::CalibrateRequest::new(board_toml.clone(), photos.clone())
    };
    let out = dir.path().join("cal");
    let o = fibrefit::api::calibrate::calibrate(&req, &out, &fibrefit::progress::Progress::quiet())
        .unwrap();
    eprint!("{}", o.report);
    // eight photos from all around at 20-60 deg: nothing left undetermined
    assert!(!o.report.contains("warning"), "{}", o.report);
    let mut worst = 0.0f64;
    for (i, (p, t)) in o.calibration.poses.iter().zip(poses()).enumerate() {
        let err = (p.position - t.position).norm();
        eprintln!("photo {i}: camera position error {err:.3} mm");
        worst = worst.max(err);
        assert!(
            o.calibration.rms_px[i] < 0.3,
            "photo {i}: {} px",
            o.calibration.rms_px[i]
        );
    }
    assert!(worst < 1.0, "worst camera position error {worst} mm");
    for f in [
        "capture.toml",
        "mask.png",
        "cam.toml",
        "report/report.txt",
        "report/overlay_000.png",
        "report/coverage.png",
        "img_007.exr",
    ] {
        assert!(out.join(f).exists(), "{f}");
    }
    // fit lambert on the capture, unchanged
    let result = dir.path().join("lambert.json");
    let f = Command::cargo_bin("fibrefit")
        .unwrap()
        .arg("fit")
        .arg(out.join("capture.toml"))
        .args(["--model", "lambert", "-q", "--out"])
        .arg(&result)
        .output()
        .unwrap();
    assert!(f.status.success(), "{}", String::from_utf8_lossy(&f.stderr));
    let r: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&result).unwrap()).unwrap();
    let kd = &r["parameters"]["kd"];
    for c in 0..3 {
        let v = kd["value"][c].as_f64().unwrap();
        let se = kd["std_error"][c].as_f64().unwrap();
        eprintln!("kd[{c}] = {v:.5} +- {se:.2e} (truth {})", KD[c]);
        // the standard error includes the radiometry's: each photo's patch reading (no EXIF
        // here to pool them), about 0.5 %
        assert!(
            (v - KD[c]).abs() < 3.0 * se,
            "kd[{c}] {v} +- {se}, truth {}",
            KD[c]
        );
    }
    // cam.toml is reused
    let again = dir.path().join("again");
    let o = Command::cargo_bin("fibrefit")
        .unwrap()
        .arg("calibrate")
        .arg("--board")
        .arg(&board_toml)
        .arg("--intrinsics")
        .arg(out.join("cam.toml"))
        .arg("--out")
        .arg(&again)
        .args(["-q"])
        .args(&photos[..3])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
}

#[test]
fn bad_photos_are_refused_by_name_and_nothing_is_written() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    board(&BoardRequest::default(), d).unwrap();
    let board_toml = d.join("board.toml");
    // no markers: a blank grey picture
    let blank = d.join("blank.png");
    image::GrayImage::from_pixel(400, 300, image::Luma([128]))
        .save(&blank)
        .unwrap();
    // a truncated JPEG
    let trunc = d.join("trunc.jpg");
    let mut bytes = Vec::new();
    image::codecs::jpeg::JpegEncoder::new_with_quality(&mut bytes, 90)
        .encode_image(&image::RgbImage::from_pixel(
            64,
            48,
            image::Rgb([200, 100, 50]),
        ))
        .unwrap();
    std::fs::write(&trunc, &bytes[..bytes.len() / 3]).unwrap();
    // not a JPEG at all
    let junk = d.join("junk.jpg");
    std::fs::write(&junk, b"this is not a photo").unwrap();
    // too few markers: a crop of the board with one marker
    let one = d.join("one.png");
    let png = image::open(d.join("board.png")).unwrap().to_luma8();
    let b = BoardFile::read(&board_toml).unwrap();
    let m = &b.marker[0];
    let [u0, v1] = b.mm_to_png(m.corners_mm[0][0], m.corners_mm[0][1]);
    let [u1, v0] = b.mm_to_png(m.corners_mm[2][0], m.corners_mm[2][1]);
    let pad = 30.0;
    image::imageops::crop_imm(
        &png,
        (u0 - pad) as u32,
        (v0 - pad) as u32,
        (u1 - u0 + 2.0 * pad) as u32,
        (v1 - v0 + 2.0 * pad) as u32,
    )
    .to_image()
    .save(&one)
    .unwrap();
    // mixed sizes: the board itself and a half-size copy
    let full = d.join("full.png");
    png.save(&full).unwrap();
    let half = d.join("half.png");
    image::imageops::resize(
        &png,
        png.width() / 2,
        png.height() / 2,
        image::imageops::FilterType::Triangle,
    )
    .save(&half)
    .unwrap();
    // a decompression bomb: a tiny PNG whose header claims 60000 x 60000 pixels
    let bomb = d.join("bomb.png");
    std::fs::write(&bomb, png_claiming(60_000, 60_000)).unwrap();
    // a JPEG whose header claims 65000 x 65000 pixels
    let jbomb = d.join("jbomb.jpg");
    let mut j = Vec::new();
    image::codecs::jpeg::JpegEncoder::new_with_quality(&mut j, 90)
        .encode_image(&image::RgbImage::from_pixel(16, 8, image::Rgb([9, 9, 9])))
        .unwrap();
    let sof = j.windows(2).position(|w| w == [0xff, 0xc0]).unwrap();
    j[sof + 5..sof + 9].copy_from_slice(&[0xfd, 0xe8, 0xfd, 0xe8]);
    std::fs::write(&jbomb, &j).unwrap();
    let out = d.join("cal");
    for (photos, name, what) in [
        (vec![bomb.clone()], "bomb.png", "pixels"),
        (vec![jbomb.clone()], "jbomb.jpg", "pixels"),
        (vec![blank.clone()], "blank.png", "no markers"),
        (vec![trunc.clone()], "trunc.jpg", ""),
        (vec![junk.clone()], "junk.jpg", "JPEG"),
        (vec![one.clone()], "one.png", "a pose needs at least 2"),
        (vec![full.clone(), half.clone()], "half.png", "one size"),
    ] {
        let o = calibrate(&board_toml, &photos, &out);
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{name}: {err}");
        assert!(err.contains(name) && err.contains(what), "{name}: {err}");
        assert!(!out.exists(), "{name}: wrote {}", out.display());
    }
}

/// A PNG of one grey pixel row whose header claims `w` x `h` pixels (CRCs right).
fn png_claiming(w: u32, h: u32) -> Vec<u8> {
    fn crc32(bytes: &[u8]) -> u32 {
        let mut c = !0u32;
        for &b in bytes {
            c ^= b as u32;
            for _ in 0..8 {
                c = if c & 1 != 0 {
                    0xedb8_8320 ^ (c >> 1)
                } else {
                    c >> 1
                };
            }
        }
        !c
    }
    let chunk = |out: &mut Vec<u8>, kind: &[u8], data: &[u8]| {
        out.extend((data.len() as u32).to_be_bytes());
        let mut body = kind.to_vec();
        body.extend(data);
        out.extend(&body);
        out.extend(crc32(&body).to_be_bytes());
    };
    let mut png = b"\x89PNG\r\n\x1a\n".to_vec();
    let mut ihdr = Vec::new();
    ihdr.extend(w.to_be_bytes());
    ihdr.extend(h.to_be_bytes());
    ihdr.extend([8, 0, 0, 0, 0]);
    chunk(&mut png, b"IHDR", &ihdr);
    // a zlib stream of nothing much: the decoder must refuse before inflating
    chunk(
        &mut png,
        b"IDAT",
        &[0x78, 0x9c, 0x03, 0x00, 0x00, 0x00, 0x00, 0x01],
    );
    chunk(&mut png, b"IEND", &[]);
    png
}

/// A JPEG with an EXIF block (exposure 1/60 s, f/1.8, ISO 200) written by hand.
fn jpeg_with_exif() -> Vec<u8> {
    let mut jpeg = Vec::new();
    image::codecs::jpeg::JpegEncoder::new_with_quality(&mut jpeg, 90)
        .encode_image(&image::RgbImage::from_pixel(
            32,
            24,
            image::Rgb([120, 120, 120]),
        ))
        .unwrap();
    let mut t: Vec<u8> = b"II\x2a\x00".to_vec();
    t.extend(8u32.to_le_bytes());
    let entry = |t: &mut Vec<u8>, tag: u16, kind: u16, value: u32| {
        t.extend(tag.to_le_bytes());
        t.extend(kind.to_le_bytes());
        t.extend(1u32.to_le_bytes());
        t.extend(value.to_le_bytes());
    };
    // IFD0: the Exif IFD's offset (26)
    t.extend(1u16.to_le_bytes());
    entry(&mut t, 0x8769, 4, 26);
    t.extend(0u32.to_le_bytes());
    // the Exif IFD: ExposureTime, FNumber (rationals at 68 and 76), ISO (inline)
    t.extend(3u16.to_le_bytes());
    entry(&mut t, 0x829a, 5, 68);
    entry(&mut t, 0x829d, 5, 76);
    entry(&mut t, 0x8827, 3, 200);
    t.extend(0u32.to_le_bytes());
    for (n, d) in [(1u32, 60u32), (18, 10)] {
        t.extend(n.to_le_bytes());
        t.extend(d.to_le_bytes());
    }
    let mut app1 = vec![0xff, 0xe1];
    app1.extend(((2 + 6 + t.len()) as u16).to_be_bytes());
    app1.extend(b"Exif\0\0");
    app1.extend(t);
    jpeg.splice(2..2, app1);
    jpeg
}

#[test]
fn a_photos_exif_exposure_is_read() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("exif.jpg");
    std::fs::write(&p, jpeg_with_exif()).unwrap();
    let photo =
        fibrefit::load::photo::Photo::read(&p, fibrefit::load::image_io::Encoding::Srgb).unwrap();
    let e = photo.exif.expect("EXIF read");
    assert_eq!(e.time_s, Some(1.0 / 60.0));
    assert_eq!(e.f_number, Some(1.8));
    assert_eq!(e.iso, Some(200.0));
    let product = e.product().unwrap();
    assert!((product - 200.0 / 60.0 / 3.24).abs() < 1e-12);
    // a photo whose patch disagrees with its EXIF is named
    let mut other =
        fibrefit::load::photo::Photo::read(&p, fibrefit::load::image_io::Encoding::Srgb).unwrap();
    other.path = dir.path().join("odd.jpg");
    let third =
        fibrefit::load::photo::Photo::read(&p, fibrefit::load::image_io::Encoding::Srgb).unwrap();
    let w = fibrefit::api::calibrate::exif_disagreements(
        &[photo.info(), other.info(), third.info()],
        &[[1.0; 3], [1.5; 3], [1.0; 3]],
    );
    assert_eq!(w.len(), 1, "{w:?}");
    assert_eq!(w[0].0, 1, "{w:?}");
    assert!(
        w[0].1.contains("odd.jpg") && w[0].1.contains("+50 %"),
        "{w:?}"
    );
}

#[test]
fn synth_photos_then_calibrate_from_the_command_line() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let run = |args: &[&std::ffi::OsStr]| {
        let o = Command::cargo_bin("fibrefit")
            .unwrap()
            .args(args)
            .output()
            .unwrap();
        assert_eq!(
            o.status.code(),
            Some(0),
            "{args:?}: {}",
            String::from_utf8_lossy(&o.stderr)
        );
    };
    let os = |s: &str| std::ffi::OsString::from(s);
    run(&[
        &os("board"),
        &os("-q"),
        &os("--out"),
        d.join("b").as_os_str(),
    ]);
    std::fs::write(
        d.join("p.toml"),
        "model = \"lambert\"\nkd = [0.5, 0.4, 0.2]\n",
    )
    .unwrap();
    let shots = d.join("shots");
    run(&[
        &os("synth"),
        &os("--photos"),
        &os("-q"),
        &os("--board"),
        d.join("b/board.toml").as_os_str(),
        &os("--params"),
        d.join("p.toml").as_os_str(),
        &os("--count"),
        &os("4"),
        &os("--out"),
        shots.as_os_str(),
    ]);
    let truth: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(shots.join("truth.json")).unwrap()).unwrap();
    assert_eq!(truth["photos"].as_array().unwrap().len(), 4);
    assert_eq!(truth["intrinsics"]["focal_px"].as_f64(), Some(1000.0));
    let cal = d.join("cal");
    let mut args = vec![
        os("calibrate"),
        os("-q"),
        os("--board"),
        d.join("b/board.toml").into_os_string(),
        os("--out"),
        cal.clone().into_os_string(),
        os("--texels"),
        os("32"),
        os("32"),
    ];
    for k in 0..4 {
        args.push(shots.join(format!("photo_{k:03}.jpg")).into_os_string());
    }
    run(&args.iter().map(|a| a.as_os_str()).collect::<Vec<_>>());
    let capture: toml::Value =
        toml::from_str(&std::fs::read_to_string(cal.join("capture.toml")).unwrap()).unwrap();
    let images = capture["images"].as_array().unwrap();
    for (k, img) in images.iter().enumerate() {
        let got: Vec<f64> = img["camera"]["position_mm"]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_float().unwrap())
            .collect();
        let want: Vec<f64> = truth["photos"][k]["position_mm"]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_f64().unwrap())
            .collect();
        let err = (0..3)
            .map(|i| (got[i] - want[i]).powi(2))
            .sum::<f64>()
            .sqrt();
        eprintln!("synth --photos photo {k}: camera position error {err:.3} mm");
        assert!(err < 1.0, "photo {k}: {err} mm");
    }
    // --photos needs its board and parameters
    let o = Command::cargo_bin("fibrefit")
        .unwrap()
        .args(["synth", "--photos", "--out"])
        .arg(d.join("x"))
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(2));
    assert!(!d.join("x").exists());
}
