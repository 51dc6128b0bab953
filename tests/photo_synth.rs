//! Synthetic photos of the board (synth::photo): the AprilTag detector finds the markers where
//! the true camera projects board.toml's corners, through perspective and radial distortion.

use fibrefit::api::board::{board, BoardRequest};
use fibrefit::board::camera::{Intrinsics, Pose};
use fibrefit::board::detect;
use fibrefit::model::params::{ModelParams, RawParams};
use fibrefit::model::ModelId;
use fibrefit::synth::photo::{PhotoShot, SwatchOnBoard};
use nalgebra::Vector3;

#[test]
fn detected_corners_are_the_true_cameras_projections() {
    let dir = tempfile::tempdir().unwrap();
    board(&BoardRequest::default(), dir.path()).unwrap();
    let raw: RawParams = toml::from_str("kd = [0.6, 0.4, 0.3]").unwrap();
    let (params, _) = ModelParams::from_raw(&raw, ModelId::Lambert).unwrap();
    let set =
        SwatchOnBoard::read(&dir.path().join("board.toml"), ModelId::Lambert, params).unwrap();
    let (b, scene) = (&set.board, set.scene());
    let intrinsics = Intrinsics {
        size_px: [1600, 1200],
        focal_px: 1500.0,
        principal_px: [805.0, 596.0],
        k: [-0.08, 0.02],
    };
    let mut worst_rms = 0.0f64;
    for (k, (elev, azim)) in [(40.0f64, -90.0f64), (25.0, 30.0), (60.0, 160.0)]
        .into_iter()
        .enumerate()
    {
        let (e, a) = (elev.to_radians(), azim.to_radians());
        let eye = Vector3::new(a.cos() * e.cos(), a.sin() * e.cos(), e.sin()) * 300.0;
        let pose = Pose::look_at(eye, Vector3::zeros());
        let shot = PhotoShot {
            room_light: None,
            intrinsics,
            pose,
            light_mm: eye + pose.to_board_direction(&Vector3::new(10.0, 0.0, 0.0)),
            intensity: 1.0,
            exposure: 0.6 * std::f64::consts::PI * 0.09,
            noise_gain: 3e-5,
            noise_floor: 0.002,
            seed: k as u64,
            supersample: 3,
            blur_px: 0.0,
        };
        let photo = scene.render(&shot).unwrap();
        let grey = detect::linear_grey(&photo);
        let found = detect::find(&grey, 1600, 1200).unwrap();
        let (mut sum, mut n, mut mean) = (0.0, 0, [0.0; 2]);
        for f in &found {
            let m = b.marker(f.id).expect("a board marker");
            for (c, mm) in f.corners.iter().zip(&m.corners_mm) {
                let p = intrinsics
                    .project(&pose.to_camera(&Vector3::new(mm[0], mm[1], 0.0)))
                    .unwrap();
                sum += (c[0] - p[0]).powi(2) + (c[1] - p[1]).powi(2);
                mean[0] += c[0] - p[0];
                mean[1] += c[1] - p[1];
                n += 1;
            }
        }
        let rms = (sum / n.max(1) as f64).sqrt();
        eprintln!("photo {k} (elevation {elev}): {} of {} markers, corner RMS {rms:.3} px, mean offset {:.3}, {:.3}", found.len(), b.marker.len(), mean[0] / n as f64, mean[1] / n as f64);
        assert!(
            found.len() * 2 > b.marker.len(),
            "photo {k}: {} markers",
            found.len()
        );
        worst_rms = worst_rms.max(rms);
    }
    assert!(worst_rms < 0.3, "corner RMS {worst_rms} px");
}
