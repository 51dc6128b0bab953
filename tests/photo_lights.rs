//! The photo route's lights and photo formats (issue 36): photos lit by a lamp at a measured
//! position (`--lights`), one by the flash, each with an ambient frame (the same pose with the
//! lamp off, a room light on) subtracted; 16-bit linear TIFFs (`--encoding linear`); the grid
//! from `--px-per-mm`; each photo's own mask (NaN texels) in its rectified image. The fit of
//! the capture lands on the truth.

use assert_cmd::Command;
use fibrefit::api::board::{board, BoardRequest};
use fibrefit::board::camera::{Intrinsics, Pose};
use fibrefit::load::board::BoardFile;
use fibrefit::load::image_io;
use fibrefit::model::params::{ModelParams, RawParams};
use fibrefit::model::ModelId;
use fibrefit::synth::photo::{PhotoScene, PhotoShot, SwatchOnBoard};
use nalgebra::Vector3;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

const CAMERA: Intrinsics = Intrinsics {
    size_px: [1600, 1200],
    focal_px: 1000.0,
    principal_px: [805.0, 596.0],
    k: [-0.08, 0.02],
};
const KD: [f64; 3] = [0.5, 0.4, 0.25];
const LAMP: [f64; 3] = [150.0, -100.0, 400.0];
const FLASH: [f64; 3] = [10.0, 0.0, 0.0];

fn pose(i: usize) -> Pose {
    let elev = (20.0 + 40.0 * (i % 4) as f64 / 3.0).to_radians();
    let azim = (60.0 * i as f64 + 10.0).to_radians();
    let eye = Vector3::new(azim.cos() * elev.cos(), azim.sin() * elev.cos(), elev.sin()) * 300.0;
    Pose::look_at(eye, Vector3::zeros())
}

/// A 16-bit linear TIFF of linear RGB `values`.
fn write_tiff(path: &Path, values: &[f32]) {
    let [w, h] = CAMERA.size_px;
    let data: Vec<u16> = values
        .iter()
        .map(|&v| (v.clamp(0.0, 1.0) * 65535.0).round() as u16)
        .collect();
    image::ImageBuffer::<image::Rgb<u16>, _>::from_raw(w, h, data)
        .unwrap()
        .save(path)
        .unwrap();
}

/// The board, six photos (photo 0 by the flash, the others by the lamp, a room light in
/// every one) and their ambient frames as 16-bit linear TIFFs, and the lights file.
fn shoot(dir: &Path) -> (PathBuf, Vec<PathBuf>, PathBuf) {
    board(&BoardRequest::default(), dir).unwrap();
    let raw: RawParams = toml::from_str(&format!("kd = {KD:?}")).unwrap();
    let (params, _) = ModelParams::from_raw(&raw, ModelId::Lambert).unwrap();
    let set = SwatchOnBoard::read(&dir.join("board.toml"), ModelId::Lambert, params).unwrap();
    let scene = set.scene();
    let room = Some((Vector3::new(-400.0, 300.0, 700.0), 0.3));
    let mut lights = format!("lamp_mm = {LAMP:?}\n");
    let mut files = Vec::new();
    for k in 0..6 {
        let p = pose(k);
        let main = match k {
            0 => p.position + p.to_board_direction(&Vector3::from(FLASH)),
            _ => Vector3::from(LAMP),
        };
        let shot = |intensity: f64, seed: u64| PhotoShot {
            intrinsics: CAMERA,
            pose: p,
            light_mm: main,
            intensity,
            room_light: room,
            exposure: 0.25,
            noise_gain: 7.5e-6,
            noise_floor: 0.0005,
            seed,
            supersample: 2,
            blur_px: 0.0,
        };
        let (lit, off) = (
            dir.join(format!("p{k}.tif")),
            dir.join(format!("p{k}_off.tif")),
        );
        write_tiff(&lit, &scene.render_linear(&shot(1.0, k as u64)).unwrap());
        write_tiff(
            &off,
            &scene.render_linear(&shot(0.0, 100 + k as u64)).unwrap(),
        );
        write!(
            lights,
            "[[photo]]\nfile = \"p{k}.tif\"\nambient = \"p{k}_off.tif\"\n"
        )
        .unwrap();
        if k == 0 {
            lights.push_str("flash = true\n");
        }
        files.push(lit);
    }
    std::fs::write(dir.join("lights.toml"), lights).unwrap();
    (dir.join("board.toml"), files, dir.join("lights.toml"))
}

#[test]
fn lamps_ambient_frames_and_linear_tiffs_make_a_capture_that_fits_the_truth() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let (board_toml, photos, lights) = shoot(d);
    let out = d.join("cal");
    let run = Command::cargo_bin("fibrefit")
        .unwrap()
        .arg("calibrate")
        .arg("--board")
        .arg(&board_toml)
        .arg("--lights")
        .arg(&lights)
        .args(["--encoding", "linear", "--px-per-mm", "1.0", "--out"])
        .arg(&out)
        .args(&photos)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&run.stderr);
    eprintln!("{stderr}");
    assert!(run.status.success(), "{stderr}");
    assert!(stderr.contains("lamp at (150, -100, 400) mm") && stderr.contains("flash"));

    // the capture's lights: the lamp where the file puts it, photo 0's flash beside its lens
    let cap: toml::Value =
        toml::from_str(&std::fs::read_to_string(out.join("capture.toml")).unwrap()).unwrap();
    let b = BoardFile::read(&board_toml).unwrap();
    let side = [
        b.window_mm[2] - b.window_mm[0],
        b.window_mm[3] - b.window_mm[1],
    ];
    let images = cap["images"].as_array().unwrap();
    for (k, img) in images.iter().enumerate() {
        let at: Vec<f64> = img["light"]["position_mm"]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_float().unwrap())
            .collect();
        let want = match k {
            0 => {
                let p = pose(0);
                let f = p.position + p.to_board_direction(&Vector3::from(FLASH));
                [f.x, f.y, f.z]
            }
            _ => LAMP,
        };
        let err = (0..3)
            .map(|c| (at[c] - want[c]).powi(2))
            .sum::<f64>()
            .sqrt();
        assert!(
            err < if k == 0 { 1.5 } else { 1e-9 },
            "photo {k}: light at {at:?}, truth {want:?}"
        );
        // --px-per-mm 1: one texel per millimetre of the window
        let im = image_io::read(&out.join(format!("img_{k:03}.exr")), None, None).unwrap();
        assert_eq!([im.width as f64, im.height as f64], side.map(f64::round));
    }
    // each photo's own mask (NaN texels) covers the capture's mask, and a texel no photo sees
    // is in the capture's mask
    let mask = image::open(out.join("mask.png")).unwrap().to_luma8();
    let nan: Vec<Vec<bool>> = (0..6)
        .map(|k| {
            let im = image_io::read(&out.join(format!("img_{k:03}.exr")), None, None).unwrap();
            im.data.chunks(3).map(|p| p[0].is_nan()).collect()
        })
        .collect();
    for (i, m) in mask.pixels().enumerate() {
        let unseen = nan.iter().all(|n| n[i]);
        assert_eq!(
            m[0] == 0,
            unseen,
            "texel {i}: mask {} but NaN in every photo: {unseen}",
            m[0]
        );
    }

    // lambert on the capture: the ambient light taken off, the albedo absolute
    let result = d.join("lambert.json");
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
    for c in 0..3 {
        let v = r["parameters"]["kd"]["value"][c].as_f64().unwrap();
        eprintln!("kd[{c}] = {v:.5} (truth {})", KD[c]);
        assert!(
            (v - KD[c]).abs() < 0.01 * KD[c],
            "kd[{c}] {v}, truth {}",
            KD[c]
        );
    }
}

#[test]
fn an_ambient_frame_at_another_exposure_or_size_is_refused_by_name() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let (board_toml, photos, _) = shoot_two(d);
    // the ambient frame of another size
    image::RgbImage::from_pixel(320, 240, image::Rgb([10, 10, 10]))
        .save(d.join("small_off.png"))
        .unwrap();
    std::fs::write(
        d.join("lights.toml"),
        "[[photo]]\nfile = \"p0.png\"\nambient = \"small_off.png\"\n",
    )
    .unwrap();
    let out = d.join("cal");
    let run = Command::cargo_bin("fibrefit")
        .unwrap()
        .arg("calibrate")
        .arg("--board")
        .arg(&board_toml)
        .arg("--lights")
        .arg(d.join("lights.toml"))
        .arg("--out")
        .arg(&out)
        .args(&photos)
        .output()
        .unwrap();
    assert_eq!(run.status.code(), Some(2));
    let err = String::from_utf8_lossy(&run.stderr);
    assert!(
        err.contains("small_off.png") && err.contains("same pose"),
        "{err}"
    );
    assert!(!out.join("capture.toml").exists());
}

/// The board and two 8-bit sRGB PNG photos by the flash (the refusals need no more).
fn shoot_two(dir: &Path) -> (PathBuf, Vec<PathBuf>, ()) {
    board(&BoardRequest::default(), dir).unwrap();
    let b = BoardFile::read(&dir.join("board.toml")).unwrap();
    let picture = image::open(dir.join("board.png")).unwrap().to_luma8();
    let scene = PhotoScene {
        board: &b,
        picture: &picture,
        swatch: None,
        table_reflectance: 0.05,
    };
    let files = (0..2)
        .map(|k| {
            let p = pose(k);
            let shot = PhotoShot {
                intrinsics: CAMERA,
                pose: p,
                light_mm: p.position + p.to_board_direction(&Vector3::from(FLASH)),
                intensity: 1.0,
                room_light: None,
                exposure: 0.15,
                noise_gain: 7.5e-6,
                noise_floor: 0.0005,
                seed: k as u64,
                supersample: 1,
                blur_px: 0.0,
            };
            let path = dir.join(format!("p{k}.png"));
            scene.render(&shot).unwrap().save(&path).unwrap();
            path
        })
        .collect();
    (dir.join("board.toml"), files, ())
}
