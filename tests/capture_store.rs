//! Captures at camera resolution: the compact store's memory per pixel value does not regress
//! (bytes counted, not timed), it groups every pixel under its texel, and a global fit on a
//! sample of the texels agrees with the fit on all of them and is checked on every pixel.

use assert_cmd::Command;
use fibrefit::load::capture_store::CaptureStore;
use fibrefit::load::samples::Origin;
use fibrefit::load::{load_data, LoadOptions};
use std::path::Path;

fn fibrefit() -> Command {
    Command::cargo_bin("fibrefit").expect("binary built")
}

/// An 8-image synthetic capture of `size` x `size` texels (RGB when `rgb`), with its topology
/// and tangent maps, into `dir`.
fn capture(dir: &Path, size: usize, rgb: bool) -> std::path::PathBuf {
    let kd = if rgb { "[0.4, 0.3, 0.2]" } else { "0.4" };
    let mut images = String::new();
    for (lt, lp, vt, vp) in [
        (30, 110, 0, 0),
        (60, 100, 30, 290),
        (45, 20, 45, 200),
        (70, 300, 20, 110),
        (50, 180, 50, 0),
        (20, 200, 60, 20),
        (65, 240, 40, 60),
        (40, 330, 55, 150),
    ] {
        images += &format!(
            "[[capture.images]]\nlight = {{ type = \"directional\", theta_deg = {lt}, phi_deg = {lp}, irradiance = 1.0 }}\ncamera = {{ type = \"orthographic\", theta_deg = {vt}, phi_deg = {vp} }}\n"
        );
    }
    let synth = format!(
        "model = \"varying-topology\"\n[params]\nkd = {kd}\nks = 0.3\nexponent = 40\nspacing = 2.0\nheight = 0.9\nmap_scale = 0.6\nfibre_azimuth_deg = 0\n[topology_map]\nwidth = {size}\nheight = {size}\nseed = 3\n[capture]\nwidth = {size}\nheight = {size}\nsize_mm = [20.0, 20.0]\nformat = \"exr\"\ntangent = {{ from_deg = -30, to_deg = 40 }}\n{images}[noise]\nrelative = 0.01\nseed = 5\n"
    );
    std::fs::write(dir.join("synth.toml"), synth).unwrap();
    fibrefit()
        .args(["synth", "--config"])
        .arg(dir.join("synth.toml"))
        .arg("--out")
        .arg(dir.join("d"))
        .arg("-q")
        .assert()
        .success();
    dir.join("d/capture.toml")
}

/// Bytes per pixel value the store may hold: its raw f32 values (4 B per channel) plus texel
/// list, texel index and the two maps spread over the 8 images (1 + 0.5 + 0.5 + 0.5 B), with
/// a little slack. A vector of samples took ~160 B per pixel value, a fit ~1000 B.
const GREY_BYTES_PER_VALUE: f64 = 7.0;
const RGB_BYTES_PER_VALUE: f64 = 15.0;

#[test]
fn the_store_holds_a_pixel_value_in_a_few_bytes_and_groups_pixels_by_texel() {
    let dir = tempfile::tempdir().unwrap();
    for (rgb, bound) in [(false, GREY_BYTES_PER_VALUE), (true, RGB_BYTES_PER_VALUE)] {
        let sub = dir.path().join(if rgb { "rgb" } else { "grey" });
        std::fs::create_dir_all(&sub).unwrap();
        let path = capture(&sub, 24, rgb);
        let store = CaptureStore::load(&path, Default::default()).unwrap();
        assert_eq!(store.channels, if rgb { 3 } else { 1 });
        assert_eq!(store.sample_count(), 24 * 24 * 8);
        let per_value = store.bytes() as f64 / store.sample_count() as f64;
        assert!(
            per_value <= bound,
            "{} B per pixel value (bound {bound})",
            per_value
        );
        // every sample of the loader sits under its texel, in image order
        let samples = load_data(&path, &LoadOptions::default()).unwrap();
        assert_eq!(samples.samples.len(), store.sample_count());
        for (t, &(x, y)) in store.texels().iter().enumerate().step_by(37) {
            let mine = store.texel_samples(t);
            let theirs: Vec<_> = samples
                .samples
                .iter()
                .filter(|s| matches!(s.origin, Origin::Pixel { x: sx, y: sy, .. } if sx == x && sy == y))
                .cloned()
                .collect();
            assert_eq!(mine.len(), 8);
            for (a, b) in mine.iter().zip(&theirs) {
                assert_eq!(a.l, b.l);
                assert_eq!(a.v, b.v);
                assert_eq!(a.value, b.value);
                assert_eq!(a.map_value, b.map_value);
                assert_eq!(a.fibre_azimuth, b.fibre_azimuth);
                assert_eq!(a.origin, b.origin);
            }
            assert_eq!(store.texel_at(x as i64, y as i64), Some(t));
        }
        // the values are the decoded images' own: pixel x exposure / (E cos theta_i), exact
        let img = fibrefit::load::image_io::read(&sub.join("d/img_003.exr"), None, None).unwrap();
        for (t, &(x, y)) in store.texels().iter().enumerate().step_by(53) {
            let s = store.sample(t, 3).unwrap();
            let px = img.pixel(x as usize, y as usize);
            for (v, p) in s.value.iter().zip(px) {
                assert_eq!(*v, *p as f64 * (1.0 / (1.0 * s.l.z)));
            }
        }
        assert_eq!(store.texel_at(-1, 0), None);
        assert_eq!(store.texel_at(24, 0), None);
    }
}

const FIT: &str = r#"
model = "varying-topology"
metric = "linear"
seed = 1
[parameters]
kd = { value = 0.5 }
ks = { value = 0.2 }
exponent = { value = 20, min = 1, max = 1000 }
spacing = { value = 2.0, vary = false }
height = { value = 0.8 }
map_scale = { value = 0.5 }
fibre_azimuth_deg = { value = 0, vary = false }
"#;

fn fit(data: &Path, cfg: &str, out: &Path) -> serde_json::Value {
    let c = out.with_extension("toml");
    std::fs::write(&c, cfg).unwrap();
    fibrefit()
        .arg("fit")
        .arg(data)
        .arg("--config")
        .arg(&c)
        .arg("--out")
        .arg(out)
        .arg("-q")
        .assert()
        .success();
    serde_json::from_slice(&std::fs::read(out).unwrap()).unwrap()
}

#[test]
fn a_global_fit_on_sampled_texels_agrees_with_all_texels_and_is_checked_on_every_pixel() {
    let dir = tempfile::tempdir().unwrap();
    let data = capture(dir.path(), 40, false);
    let all = fit(&data, FIT, &dir.path().join("all.json"));
    let sampled = fit(
        &data,
        &format!("{FIT}[knobs]\nfit_texels = 200\n"),
        &dir.path().join("sampled.json"),
    );
    assert_eq!(all["data"]["samples"], 40 * 40 * 8);
    assert!(all["statistics"].get("all_pixels").is_none());
    assert_eq!(sampled["data"]["samples"], 200 * 8);
    assert_eq!(sampled["knobs"]["fit_texels"], 200);
    let every = &sampled["statistics"]["all_pixels"];
    assert_eq!(every["texels"], 1600);
    assert_eq!(every["n"], 1600 * 8);
    // the model fits every pixel as well as the sample it was fitted on (1 % noise)
    let v_all = every["residual_variance"].as_f64().unwrap();
    let v_sample = sampled["statistics"]["residual_variance"].as_f64().unwrap();
    assert!(v_all < 1.5 * v_sample, "{v_all} vs {v_sample}");
    assert!(every["relative_rmse"].as_f64().unwrap() < 0.02);
    // the sample's parameters agree with all texels' within the sample's (wider) errors
    for name in ["kd", "ks", "exponent", "height", "map_scale"] {
        let a = all["parameters"][name]["value"].as_f64().unwrap();
        let s = &sampled["parameters"][name];
        let (v, se) = (
            s["value"].as_f64().unwrap(),
            s["std_error"].as_f64().unwrap(),
        );
        let se_all = all["parameters"][name]["std_error"].as_f64().unwrap();
        assert!(
            se >= se_all,
            "{name}: sample se {se} < all-texel se {se_all}"
        );
        assert!((v - a).abs() <= 4.0 * se, "{name}: {v} +- {se} vs {a}");
    }
}
