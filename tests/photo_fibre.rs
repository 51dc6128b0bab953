//! The photo route against its ideal (issue 36): 8 synthetic RAW (DNG) photos of a
//! poulin-fournier swatch on the board (20-60 degrees of elevation, a flash 10 mm beside the
//! lens, camera noise: variance floor^2 + gain x value), `fibrefit calibrate` (which estimates
//! the camera's noise from the board and gives the capture its sigmas), then `fibrefit fit`.
//! The baseline is an ideal rectified capture of the same directions: the true cameras and
//! lights, each texel's exact value plus noise of the variance the photo capture states. The
//! photo route must fit within its noise, land within 3 standard errors of the truth, and its
//! parameter errors stay within 1.5x of the baseline's.

use assert_cmd::Command;
use fibrefit::api::board::{board, BoardRequest};
use fibrefit::board::camera::{Intrinsics, Pose};
use fibrefit::load::capture::{Camera, CaptureFile, Light};
use fibrefit::model::frame::{DirectionPair, FibreFrame};
use fibrefit::model::params::{ModelParams, RawParams};
use fibrefit::model::ModelId;
use fibrefit::synth::photo::{set_pose, PhotoShot, SwatchOnBoard, SET_CAMERA, SET_FLASH_MM};
use nalgebra::Vector3;
use rand::SeedableRng;
use rand_distr::{Distribution, Normal};
use std::path::{Path, PathBuf};

// the camera and flash of `synth --photos`' set
const CAMERA: Intrinsics = SET_CAMERA;
const FLASH: [f64; 3] = SET_FLASH_MM;
const TRUTH: &str = "model = \"poulin-fournier\"
kd = [0.5, 0.35, 0.25]
ks = 0.4
exponent = 30
spacing = 2.6
fibre_azimuth_deg = 25";
const TEXELS: usize = 40;

/// The set's 8 cameras: 300 mm away, 20-60 degrees of elevation, all around.
fn poses() -> Vec<Pose> {
    (0..8).map(|i| set_pose(i, 8)).collect()
}

fn truth() -> (ModelParams, Box<dyn fibrefit::model::ShadingModel>) {
    let raw: RawParams = toml::from_str(TRUTH).unwrap();
    let (params, _) = ModelParams::from_raw(&raw, ModelId::PoulinFournier).unwrap();
    let model = fibrefit::model::build(ModelId::PoulinFournier, &params).unwrap();
    (params, model)
}

/// The board and 8 DNG photos in `dir`.
fn shoot(dir: &Path) -> (PathBuf, Vec<PathBuf>) {
    board(&BoardRequest::default(), dir).unwrap();
    let (params, _) = truth();
    let set =
        SwatchOnBoard::read(&dir.join("board.toml"), ModelId::PoulinFournier, params).unwrap();
    let scene = set.scene();
    let mut files = Vec::new();
    for (k, pose) in poses().iter().enumerate() {
        let shot = PhotoShot {
            room_light: None,
            intrinsics: CAMERA,
            pose: *pose,
            light_mm: pose.position + pose.to_board_direction(&Vector3::from(FLASH)),
            intensity: 1.0,
            exposure: 0.35 * std::f64::consts::PI * 0.09 * (1.0 + 0.1 * k as f64),
            noise_gain: 3e-5,
            noise_floor: 0.002,
            seed: 100 + k as u64,
            supersample: 2,
            blur_px: 0.0,
        };
        let linear = scene.render_linear(&shot).unwrap();
        let exposure = fibrefit::export::dng::DngExposure {
            time_s: 0.01 * (1.0 + 0.1 * k as f64),
            iso: 100,
            f_number: 2.0,
        };
        let path = dir.join(format!("photo_{k}.dng"));
        std::fs::write(
            &path,
            fibrefit::export::dng::dng_bytes(1600, 1200, &linear, exposure).unwrap(),
        )
        .unwrap();
        files.push(path);
    }
    (dir.join("board.toml"), files)
}

/// The ideal twin of the capture in `cal`: the true cameras and flashes, each texel the
/// photo capture sees given its exact value plus noise of the variance that capture states.
fn ideal_capture(cal: &Path, out: &Path) -> PathBuf {
    std::fs::create_dir_all(out).unwrap();
    let text = std::fs::read_to_string(cal.join("capture.toml")).unwrap();
    let mut desc: CaptureFile = toml::from_str(&text).unwrap();
    let (params, model) = truth();
    let frame = FibreFrame::from_azimuth(params.fibre_azimuth);
    let size_mm = desc.swatch.size_mm;
    let unit = Normal::new(0.0, 1.0).unwrap();
    for (k, (spec, pose)) in desc.images.iter_mut().zip(poses()).enumerate() {
        let light = pose.position + pose.to_board_direction(&Vector3::from(FLASH));
        spec.camera = Camera::Pinhole {
            position_mm: pose.position.into(),
        };
        spec.light = Light::Point {
            position_mm: light.into(),
            intensity: 1.0,
        };
        let file = spec.file.clone().unwrap();
        let seen = fibrefit::load::image_io::read(&cal.join(&file), None, None).unwrap();
        let noise = spec.noise.clone().expect("calibrate estimated the noise");
        let mut rng = rand::rngs::StdRng::seed_from_u64(7 + k as u64);
        let mut data = vec![f32::NAN; 3 * TEXELS * TEXELS];
        for y in 0..TEXELS {
            for x in 0..TEXELS {
                let i = y * TEXELS + x;
                if seen.data[3 * i].is_nan() {
                    continue;
                }
                let p = fibrefit::load::capture::pixel_position(size_mm, TEXELS, TEXELS, x, y);
                let d = light - p;
                let r_m = d.norm() / 1000.0;
                let l = d.normalize();
                let v = (pose.position - p).normalize();
                let e = l.z.max(0.0) / (r_m * r_m);
                let basis = model.basis(&DirectionPair::new(&frame, &l, &v));
                for c in 0..3 {
                    let value = basis.brdf(&params.albedos, c) * e;
                    let sigma = (noise.var0[c] + noise.gain[c] * value.max(0.0)).sqrt();
                    data[3 * i + c] = (value + sigma * unit.sample(&mut rng)) as f32;
                }
            }
        }
        fibrefit::export::images::write_exr(&out.join(&file), TEXELS, TEXELS, 3, &data).unwrap();
    }
    std::fs::copy(cal.join("mask.png"), out.join("mask.png")).unwrap();
    let path = out.join("capture.toml");
    std::fs::write(&path, toml::to_string(&desc).unwrap()).unwrap();
    path
}

/// `fibrefit fit CAPTURE --model poulin-fournier`: the result JSON.
fn fit(capture: &Path, out: &Path) -> serde_json::Value {
    let f = Command::cargo_bin("fibrefit")
        .unwrap()
        .arg("fit")
        .arg(capture)
        .args(["--model", "poulin-fournier", "-q", "--out"])
        .arg(out)
        .output()
        .unwrap();
    assert!(f.status.success(), "{}", String::from_utf8_lossy(&f.stderr));
    serde_json::from_str(&std::fs::read_to_string(out).unwrap()).unwrap()
}

/// (name, value, standard error) of every fitted scalar.
fn fitted(r: &serde_json::Value) -> Vec<(String, f64, f64)> {
    let mut out = Vec::new();
    for (name, p) in r["parameters"].as_object().unwrap() {
        let (v, se) = (&p["value"], &p["std_error"]);
        match (v, se) {
            (serde_json::Value::Array(v), serde_json::Value::Array(se)) => {
                for (c, (v, se)) in v.iter().zip(se).enumerate() {
                    if let (Some(v), Some(se)) = (v.as_f64(), se.as_f64()) {
                        out.push((format!("{name}[{c}]"), v, se));
                    }
                }
            }
            (v, se) => {
                if let (Some(v), Some(se)) = (v.as_f64(), se.as_f64()) {
                    out.push((name.clone(), v, se));
                }
            }
        }
    }
    out
}

fn truth_of(name: &str) -> Option<f64> {
    Some(match name {
        "kd[0]" => 0.5,
        "kd[1]" => 0.35,
        "kd[2]" => 0.25,
        "ks" => 0.4,
        "exponent" => 30.0,
        "spacing" => 2.6,
        "fibre_azimuth_deg" => 25.0,
        _ => return None,
    })
}

#[test]
fn raw_photos_fit_as_well_as_an_ideal_capture_of_the_same_directions() {
    let dir = tempfile::tempdir().unwrap();
    let (board_toml, photos) = shoot(dir.path());
    let req = fibrefit::api::calibrate::CalibrateRequest {
        texels: [TEXELS, TEXELS],
        ..fibrefit::api::calibrate::CalibrateRequest::new(board_toml, photos)
    };
    let cal = dir.path().join("cal");
    let o = fibrefit::api::calibrate::calibrate(&req, &cal, &fibrefit::progress::Progress::quiet())
        .unwrap();
    eprint!("{}", o.report);
    for (i, (p, t)) in o.calibration.poses.iter().zip(poses()).enumerate() {
        let flash = |q: &Pose| q.position + q.to_board_direction(&Vector3::from(FLASH));
        eprintln!(
            "photo {i}: camera position error {:.3} mm, flash {:.3} mm",
            (p.position - t.position).norm(),
            (flash(p) - flash(&t)).norm()
        );
    }
    assert!(!o.report.contains("JPEG"), "no sRGB note for RAW photos");
    let noise = o.noise.expect("the camera's noise estimated");
    for c in 0..3 {
        // per pixel the truth is var0 4e-6, gain 3e-5; demosaicing and bilinear resampling
        // average neighbours, so a rectified sample varies less, never more
        assert!(
            noise.gain[c] > 0.2 * 3e-5 && noise.gain[c] < 1.2 * 3e-5,
            "{noise:?}"
        );
    }
    let photo = fit(&cal.join("capture.toml"), &dir.path().join("photo.json"));
    let ideal_toml = ideal_capture(&cal, &dir.path().join("ideal"));
    let ideal = fit(&ideal_toml, &dir.path().join("ideal.json"));
    let stats = |r: &serde_json::Value| r["statistics"]["reduced_chi_square"].as_f64().unwrap();
    eprintln!(
        "reduced chi-square: photo route {:.3}, ideal {:.3}",
        stats(&photo),
        stats(&ideal)
    );
    // the estimated sigmas are honest: the photo route fits within them
    assert!(
        stats(&photo) < 1.5,
        "photo route chi2/dof {}",
        stats(&photo)
    );
    for (route, r) in [("photo route", &photo), ("ideal", &ideal)] {
        eprintln!("{route}: spread {}", r["parameters"]["azimuth_spread_deg"]);
    }
    let (p, q) = (fitted(&photo), fitted(&ideal));
    let q: std::collections::HashMap<String, (f64, f64)> =
        q.into_iter().map(|(n, v, se)| (n, (v, se))).collect();
    let (mut photo_rms, mut ideal_rms, mut n, mut worst) = (0.0, 0.0, 0, 0.0f64);
    for (name, v, se) in &p {
        let Some(t) = truth_of(name) else { continue };
        let (vi, sei) = q[name];
        eprintln!(
            "{name}: photo {v:.5} +- {se:.2e} ({:+.2} se), ideal {vi:.5} +- {sei:.2e} ({:+.2} se), truth {t}",
            (v - t) / se,
            (vi - t) / sei
        );
        worst = worst.max((v - t).abs() / se);
        photo_rms += ((v - t) / sei).powi(2);
        ideal_rms += ((vi - t) / sei).powi(2);
        n += 1;
    }
    let (photo_rms, ideal_rms) = ((photo_rms / n as f64).sqrt(), (ideal_rms / n as f64).sqrt());
    eprintln!("RMS error in the ideal's standard errors: photo route {photo_rms:.2}, ideal {ideal_rms:.2}");
    assert!(n >= 6, "{n} parameters compared");
    assert!(
        worst < 3.0,
        "a parameter {worst:.2} standard errors from the truth"
    );
    // the ideal's errors are a draw of its noise; the photo route's within 1.5x of what that
    // noise gives (its RMS, or the expected 1 standard error when the draw was lucky)
    assert!(
        photo_rms <= 1.5 * ideal_rms.max(1.0),
        "photo route {photo_rms:.2} against ideal {ideal_rms:.2} standard errors"
    );
}
