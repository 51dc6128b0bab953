//! An image's own noise model in a capture (`noise = { var0, gain }`, as `fibrefit calibrate`
//! writes it) gives every sample its sigma, and a capture's common-scale uncertainty
//! (`scale_rel_se`) reaches the samples; both are checked, with the image or field named.

use fibrefit::load::capture::Subsample;
use fibrefit::load::capture_store::CaptureStore;
use std::path::Path;

/// A 6 x 6 capture of two EXR images (values 0.2 and 0.5), with `noise_1`, `noise_2` (TOML
/// inline tables or "") and a top-level `extra`.
fn capture(dir: &Path, noise_1: &str, noise_2: &str, extra: &str) -> std::path::PathBuf {
    for (k, v) in [(0, 0.2f32), (1, 0.5)] {
        fibrefit::export::images::write_exr(
            &dir.join(format!("img_{k}.exr")),
            6,
            6,
            3,
            &vec![v; 3 * 36],
        )
        .unwrap();
    }
    let image = |k: usize, noise: &str| {
        format!(
            "[[images]]\nfile = \"img_{k}.exr\"\n{}light = {{ type = \"directional\", theta_deg = 0, phi_deg = 0, irradiance = 1.0 }}\ncamera = {{ type = \"orthographic\", theta_deg = 0, phi_deg = 0 }}\n",
            if noise.is_empty() { String::new() } else { format!("noise = {noise}\n") }
        )
    };
    let text = format!(
        "{extra}\n[swatch]\nsize_mm = [6.0, 6.0]\nfibre_azimuth_deg = 0\n\n{}\n{}",
        image(0, noise_1),
        image(1, noise_2)
    );
    let path = dir.join("capture.toml");
    std::fs::write(&path, text).unwrap();
    path
}

fn refusal(path: &Path) -> String {
    match CaptureStore::load(path, Subsample::default()) {
        Ok(_) => panic!("{} loaded", path.display()),
        Err(e) => format!("{e:#}"),
    }
}

const NOISE: &str = "{ var0 = [1e-4, 1e-4, 4e-4], gain = [1e-3, 1e-3, 0.0] }";

#[test]
fn an_images_noise_gives_its_samples_their_sigmas() {
    let dir = tempfile::tempdir().unwrap();
    let path = capture(
        dir.path(),
        NOISE,
        NOISE,
        "scale_rel_se = [0.01, 0.01, 0.02]",
    );
    let store = CaptureStore::load(&path, Subsample::default()).unwrap();
    let samples = store.to_samples();
    assert_eq!(samples.scale_rel_se, Some([0.01, 0.01, 0.02]));
    for s in &samples.samples {
        let sigma = s.sigma.expect("a sigma from the image's noise");
        // light and view at the normal, irradiance 1: the BRDF value is pixel / (E cos
        // theta_i) = the pixel, and its sigma the pixel's standard deviation
        let v = s.value[0];
        let want = [
            (1e-4 + 1e-3 * v).sqrt(),
            (1e-4 + 1e-3 * v).sqrt(),
            4e-4f64.sqrt(),
        ];
        for c in 0..3 {
            assert!((sigma[c] / want[c] - 1.0).abs() < 1e-5, "{sigma:?} for {v}");
        }
    }
}

#[test]
fn noise_given_for_some_images_or_a_bad_scale_is_refused_by_name() {
    let dir = tempfile::tempdir().unwrap();
    let path = capture(dir.path(), NOISE, "", "");
    let e = refusal(&path);
    assert!(
        e.contains("[[images]] 1 gives `noise` but [[images]] 2 does not"),
        "{e}"
    );
    let path = capture(
        dir.path(),
        "{ var0 = [-1.0, 0.0, 0.0], gain = [1.0, 1.0, 1.0] }",
        NOISE,
        "",
    );
    let e = refusal(&path);
    assert!(
        e.contains("[[images]] 1") && e.contains("noise.var0"),
        "{e}"
    );
    let path = capture(dir.path(), NOISE, NOISE, "scale_rel_se = [0.5, 2.0, 0.0]");
    let e = refusal(&path);
    assert!(e.contains("scale_rel_se"), "{e}");
}
