//! Blurred photos (issue 36): a photo whose lens blurs the board (defocus, shake) is found by
//! its markers' edges, named in the report, and its texels are left out where the blur spans
//! more than a texel; sharp photos keep theirs.

use fibrefit::api::board::{board, BoardRequest};
use fibrefit::board::camera::{Intrinsics, Pose};
use fibrefit::model::params::{ModelParams, RawParams};
use fibrefit::model::ModelId;
use fibrefit::synth::photo::{PhotoShot, SwatchOnBoard, SET_CAMERA};
use nalgebra::Vector3;

const CAMERA: Intrinsics = SET_CAMERA;
const BLURRED: usize = 2;

fn light(pose: &Pose) -> Vector3<f64> {
    pose.position + pose.to_board_direction(&Vector3::new(10.0, 0.0, 0.0))
}

#[test]
fn a_blurred_photo_is_named_and_its_texels_left_out() {
    let dir = tempfile::tempdir().unwrap();
    board(&BoardRequest::default(), dir.path()).unwrap();
    let raw: RawParams = toml::from_str("kd = [0.5, 0.4, 0.3]").unwrap();
    let (params, _) = ModelParams::from_raw(&raw, ModelId::Lambert).unwrap();
    let set =
        SwatchOnBoard::read(&dir.path().join("board.toml"), ModelId::Lambert, params).unwrap();
    let (b, picture, scene) = (&set.board, &set.picture, set.scene());
    let mut photos = Vec::new();
    for i in 0..6 {
        let elev = (25.0 + 30.0 * (i % 3) as f64 / 2.0).to_radians();
        let azim = (60.0 * i as f64 + 15.0).to_radians();
        let eye =
            Vector3::new(azim.cos() * elev.cos(), azim.sin() * elev.cos(), elev.sin()) * 300.0;
        let pose = Pose::look_at(eye, Vector3::zeros());
        let shot = PhotoShot {
            room_light: None,
            intrinsics: CAMERA,
            pose,
            light_mm: light(&pose),
            intensity: 1.0,
            exposure: 0.5 * std::f64::consts::PI * 0.09,
            noise_gain: 3e-5,
            noise_floor: 0.002,
            seed: i as u64,
            supersample: 1,
            blur_px: if i == BLURRED { 4.0 } else { 0.0 },
        };
        let img = scene.render(&shot).unwrap();
        let path = dir.path().join(format!("photo_{i}.png"));
        img.save(&path).unwrap();
        photos.push(path);
    }
    let req = fibrefit::api::calibrate::CalibrateRequest {
        texels: [64, 64],
        ..fibrefit::api::calibrate::CalibrateRequest::new(
            dir.path().join("board.toml"),
            photos.clone(),
        )
    };
    let out = dir.path().join("cal");
    let o = fibrefit::api::calibrate::calibrate(&req, &out, &fibrefit::progress::Progress::quiet())
        .unwrap();
    eprint!("{}", o.report);
    for (k, p) in photos.iter().enumerate() {
        let photo = fibrefit::load::photo::Photo::read(p, fibrefit::load::image_io::Encoding::Srgb)
            .unwrap();
        let f = fibrefit::calibrate::blur::BlurField::measure(
            &b,
            &picture,
            &o.calibration,
            k,
            &photo,
            &light(&o.calibration.poses[k]),
        );
        eprintln!(
            "photo {k}: blur {:.2} px at the median of {} markers, worst {:.2} px",
            f.median(),
            f.at.len(),
            f.worst()
        );
        if k == BLURRED {
            for (c, b) in &f.at {
                let p = o.calibration.poses[k].position;
                let d = ((c[0] - p.x).powi(2) + (c[1] - p.y).powi(2) + p.z * p.z).sqrt();
                eprintln!(
                    "  marker at ({:.0}, {:.0}) mm, {d:.0} mm away: {b:.2} px",
                    c[0], c[1]
                );
            }
        }
        // the photo's blur is measured: 4 px where it was blurred (read 4.0-4.5 px where the
        // tags are large in the photo, more where they are small and the blur leaves little
        // contrast), under 1 px where sharp
        if k == BLURRED {
            let least = f.at.iter().map(|a| a.1).fold(f64::MAX, f64::min);
            assert!((least / 4.0 - 1.0).abs() < 0.1, "least {least}");
            assert!(f.median() > 3.5 && f.median() < 7.5, "{}", f.median());
        } else {
            assert!(f.median() < 1.0, "photo {k}: {}", f.median());
        }
    }
    let blurred_line = o
        .report
        .lines()
        .find(|l| l.contains("blurred ("))
        .expect("a blur warning");
    assert!(blurred_line.contains("photo_2.png"), "{blurred_line}");
    assert_eq!(
        o.report.lines().filter(|l| l.contains("blurred (")).count(),
        1,
        "only the blurred photo is named"
    );
    // its image is left out where the blur spans a texel (3 px per texel here: all of it),
    // the sharp photos' are not
    let seen = |k: usize| {
        let img = fibrefit::load::image_io::read(&out.join(format!("img_{k:03}.exr")), None, None)
            .unwrap();
        img.data.iter().step_by(3).filter(|v| v.is_finite()).count() as f64 / (64.0 * 64.0)
    };
    for k in 0..6 {
        eprintln!("photo {k}: {:.2} of the texels seen", seen(k));
    }
    assert!(seen(BLURRED) < 0.1, "{}", seen(BLURRED));
    for k in (0..6).filter(|&k| k != BLURRED) {
        assert!(seen(k) > 0.8, "photo {k}: {}", seen(k));
    }
}
