//! Captures at camera resolution: the compact store's memory per pixel value does not regress
//! (bytes counted, not timed), it groups every pixel under its texel, and a global fit on a
//! sample of the texels agrees with the fit on all of them and is checked on every pixel.
//! `score` and `inspect` read a capture through the store, a piece at a time: their numbers
//! equal those of every sample at once, and the heap they use beyond the store is counted
//! (this test binary's allocator counts its bytes).

use assert_cmd::Command;
use fibrefit::fit::config::Metric;
use fibrefit::fit::score;
use fibrefit::load::capture::{CaptureFile, Subsample};
use fibrefit::load::capture_store::CaptureStore;
use fibrefit::load::samples::Origin;
use fibrefit::load::summary::Summary;
use fibrefit::load::{load_data, LoadOptions};
use std::alloc::{GlobalAlloc, Layout, System};
use std::path::Path;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Mutex;

/// The system allocator, counting the bytes allocated now and their peak.
struct Counting;

static NOW: AtomicUsize = AtomicUsize::new(0);
static PEAK: AtomicUsize = AtomicUsize::new(0);

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        let p = unsafe { System.alloc(layout) };
        if !p.is_null() {
            let now = NOW.fetch_add(layout.size(), Ordering::Relaxed) + layout.size();
            PEAK.fetch_max(now, Ordering::Relaxed);
        }
        p
    }
    unsafe fn dealloc(&self, p: *mut u8, layout: Layout) {
        unsafe { System.dealloc(p, layout) };
        NOW.fetch_sub(layout.size(), Ordering::Relaxed);
    }
    unsafe fn realloc(&self, p: *mut u8, layout: Layout, size: usize) -> *mut u8 {
        let q = unsafe { System.realloc(p, layout, size) };
        if !q.is_null() {
            if size >= layout.size() {
                let now =
                    NOW.fetch_add(size - layout.size(), Ordering::Relaxed) + size - layout.size();
                PEAK.fetch_max(now, Ordering::Relaxed);
            } else {
                NOW.fetch_sub(layout.size() - size, Ordering::Relaxed);
            }
        }
        q
    }
}

#[global_allocator]
static ALLOCATOR: Counting = Counting;

/// The tests of this file one at a time (the heap counts are the process's).
static SERIAL: Mutex<()> = Mutex::new(());

fn serial() -> std::sync::MutexGuard<'static, ()> {
    SERIAL.lock().unwrap_or_else(|p| p.into_inner())
}

/// `f`'s result and the peak heap bytes it allocated beyond what was allocated before it.
fn peak_heap<T>(f: impl FnOnce() -> T) -> (T, usize) {
    let before = NOW.load(Ordering::SeqCst);
    PEAK.store(before, Ordering::SeqCst);
    let out = f();
    (out, PEAK.load(Ordering::SeqCst) - before)
}

fn fibrefit() -> Command {
    Command::cargo_bin("fibrefit").expect("binary built")
}

/// An 8-image synthetic capture of `size` x `size` texels (RGB when `rgb`), with its topology
/// and tangent maps, into `dir`.
fn capture(dir: &Path, size: usize, rgb: bool) -> std::path::PathBuf {
    capture_of(dir, size, rgb, false)
}

/// [`capture`]; `repeat`: a ninth image takes the first one's light and camera again (its own
/// noise), so every texel repeats a direction pair.
fn capture_of(dir: &Path, size: usize, rgb: bool, repeat: bool) -> std::path::PathBuf {
    let kd = if rgb { "[0.4, 0.3, 0.2]" } else { "0.4" };
    let mut images = String::new();
    let mut directions = vec![
        (30, 110, 0, 0),
        (60, 100, 30, 290),
        (45, 20, 45, 200),
        (70, 300, 20, 110),
        (50, 180, 50, 0),
        (20, 200, 60, 20),
        (65, 240, 40, 60),
        (40, 330, 55, 150),
    ];
    if repeat {
        directions.push(directions[0]);
    }
    for (lt, lp, vt, vp) in directions {
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
    let _serial = serial();
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
    let _serial = serial();
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

/// Every number of two scores, the JSON's, to 1e-12 of its size (sums in another grouping
/// differ in the last bits), and their text exactly.
fn assert_same_score(streamed: &score::Score, every: &score::Score, what: &str) {
    assert_eq!(
        score::text(streamed),
        score::text(every),
        "{what}: the printed score"
    );
    fn close(a: &serde_json::Value, b: &serde_json::Value, at: &str) {
        match (a, b) {
            (serde_json::Value::Number(x), serde_json::Value::Number(y)) => {
                let (x, y) = (x.as_f64().unwrap(), y.as_f64().unwrap());
                assert!(
                    (x - y).abs() <= 1e-12 * x.abs().max(y.abs()),
                    "{at}: {x} vs {y}"
                );
            }
            (serde_json::Value::Object(x), serde_json::Value::Object(y)) => {
                assert_eq!(x.len(), y.len(), "{at}");
                for (k, v) in x {
                    close(v, &y[k], &format!("{at}.{k}"));
                }
            }
            (serde_json::Value::Array(x), serde_json::Value::Array(y)) => {
                assert_eq!(x.len(), y.len(), "{at}");
                for (i, (u, v)) in x.iter().zip(y).enumerate() {
                    close(u, v, &format!("{at}[{i}]"));
                }
            }
            _ => assert_eq!(a, b, "{at}"),
        }
    }
    close(
        &serde_json::to_value(streamed).unwrap(),
        &serde_json::to_value(every).unwrap(),
        what,
    );
}

#[test]
fn score_and_inspect_of_a_capture_from_the_store_equal_those_of_every_sample() {
    let _serial = serial();
    let dir = tempfile::tempdir().unwrap();
    let data = capture(dir.path(), 24, true);
    let result = dir.path().join("fit.json");
    fit(&data, FIT, &result);
    let store = CaptureStore::load(&data, Default::default()).unwrap();
    let every = store.to_samples();
    let mut fitted = fibrefit::export::result_json::read_result(&result, 3).unwrap();
    assert_eq!(fitted.metric, Metric::Linear);
    // pieces of one row and of whole images; the linear metric and the log one (its floors
    // are the whole capture's)
    let mut printed = None;
    for metric in [Metric::Linear, Metric::Log] {
        fitted.metric = metric;
        let all = score::score(&fitted, &every).unwrap();
        assert_eq!(all.samples, 24 * 24 * 8);
        assert_eq!(all.noise.source, "neighbouring pixels");
        for piece in [1, 24 * 24] {
            let streamed = score::score_capture_in_pieces(&fitted, &store, piece).unwrap();
            assert_same_score(&streamed, &all, &format!("{metric:?}, pieces of {piece}"));
        }
        if metric == Metric::Linear {
            printed = Some(score::text(&all));
        }
    }
    // the command prints the streamed score: the numbers of every sample
    fibrefit()
        .arg("score")
        .arg(&result)
        .arg(&data)
        .assert()
        .success()
        .stdout(printed.unwrap());
    // inspect: the summary counted from the store is the one of every sample
    let from_store = serde_json::to_value(Summary::of_capture(&store)).unwrap();
    assert_eq!(
        from_store,
        serde_json::to_value(Summary::of(&every)).unwrap()
    );
    let out = fibrefit()
        .arg("inspect")
        .arg(&data)
        .arg("--json")
        .assert()
        .success()
        .get_output()
        .stdout
        .clone();
    let printed: serde_json::Value = serde_json::from_slice(&out).unwrap();
    assert_eq!(printed, from_store);
    assert_eq!(printed["samples"], 24 * 24 * 8);
}

#[test]
fn a_subsampled_capture_is_judged_by_its_repeated_directions_alike() {
    let _serial = serial();
    let dir = tempfile::tempdir().unwrap();
    let data = capture_of(dir.path(), 24, false, true);
    let result = dir.path().join("fit.json");
    fit(&data, FIT, &result);
    assert_eq!(CaptureFile::load(&data).unwrap().images.len(), 9);
    // every 9th pixel: no neighbours within 8 pixels, so the noise comes from the texels'
    // repeated direction pairs (images 0 and 8)
    let sub = Subsample {
        stride: 9,
        ..Default::default()
    };
    let store = CaptureStore::load(&data, sub).unwrap();
    let fitted = fibrefit::export::result_json::read_result(&result, 1).unwrap();
    let all = score::score(&fitted, &store.to_samples()).unwrap();
    assert_eq!(all.samples, 9 * 9);
    assert_eq!(all.noise.source, "repeated directions");
    assert_eq!(all.noise.estimate_dof, Some(9));
    for piece in [1, 4, 100] {
        let streamed = score::score_capture_in_pieces(&fitted, &store, piece).unwrap();
        assert_same_score(&streamed, &all, &format!("pieces of {piece}"));
    }
}

/// Heap `score` may take beyond the store, per pixel value, scoring a 64 x 64 x 8 capture in
/// pieces of one image row: one f64 per value (a channel's magnitudes for the log floor's
/// median, 16 B while its vector grows) and a piece of 64 samples with their model columns and
/// residuals, spread over the 32 768 values (measured: 16.0 B). Every sample at once took
/// 288 B per value beyond the store.
const SCORE_BYTES_PER_VALUE: f64 = 24.0;
/// Heap `inspect` may take beyond the store: a tally per image, nothing per pixel (measured:
/// 0.01 B per value, ~300 B).
const INSPECT_BYTES: usize = 64 << 10;

#[test]
fn score_and_inspect_of_a_capture_hold_the_store_and_one_piece() {
    let _serial = serial();
    let dir = tempfile::tempdir().unwrap();
    let size = 64;
    let data = capture(dir.path(), size, true);
    let result = dir.path().join("fit.json");
    fit(&data, &format!("{FIT}[knobs]\nfit_texels = 256\n"), &result);
    let store = CaptureStore::load(&data, Default::default()).unwrap();
    let values = store.sample_count();
    assert_eq!(values, size * size * 8);
    let fitted = fibrefit::export::result_json::read_result(&result, 3).unwrap();
    // every sample at once, as score and inspect read a capture before
    let ((), every_bytes) = peak_heap(|| {
        let every = store.to_samples();
        score::score(&fitted, &every).unwrap();
    });
    // a piece of one image row: the heap beyond the store is one f64 per pixel value (one
    // channel's magnitudes for the log floor's median) and the piece's samples and model
    let (_, score_bytes) = peak_heap(|| score::score_capture_in_pieces(&fitted, &store, size));
    let (_, summary_bytes) = peak_heap(|| Summary::of_capture(&store));
    let per_value = |b: usize| b as f64 / values as f64;
    eprintln!(
        "heap beyond the store per pixel value: every sample {:.1} B, score {:.1} B, inspect {:.2} B (store {:.1} B)",
        per_value(every_bytes),
        per_value(score_bytes),
        per_value(summary_bytes),
        per_value(store.bytes())
    );
    assert!(
        per_value(score_bytes) <= SCORE_BYTES_PER_VALUE,
        "score: {} B per pixel value beyond the store",
        per_value(score_bytes)
    );
    assert!(
        summary_bytes <= INSPECT_BYTES,
        "inspect: {summary_bytes} B beyond the store"
    );
    assert!(per_value(every_bytes) > 10.0 * per_value(score_bytes));
}
