//! Issue 26: a fuzz-style property test per parser, in process. A valid small file of each kind
//! (goniometric CSV, RGL `.bsdf`, MERL `.binary`, capture TOML, OBJ, EXR and PNG images) is
//! mutated at random, seeded (truncation, byte flips, swapped fields, extreme numbers, huge
//! dimensions and offsets written over binary fields) and loaded inside `catch_unwind`: the
//! loader must not panic, and must give `Ok` or an error whose message names the file. The
//! number of mutations is bounded so that the whole test runs in seconds on 2 cores.

mod common;

use common::mutate::{mutate, Lcg};
use fibrefit::load::{self, LoadOptions};
use std::fs;
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::path::{Path, PathBuf};

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// Mutations per parser.
const MUTATIONS: usize = 160;

/// Mutate `path` (a copy of `valid`) `MUTATIONS` times and run `load` on it each time.
fn fuzz(
    what: &str,
    path: &Path,
    valid: &[u8],
    header: usize,
    text: bool,
    seed: u64,
    names: &[&str],
    load: &dyn Fn(&Path) -> anyhow::Result<()>,
) {
    // the valid file loads
    fs::write(path, valid).unwrap();
    if let Err(e) = load(path) {
        panic!("{what}: the valid file fails: {e:#}");
    }
    let mut rng = Lcg(seed);
    let (mut ok, mut refused) = (0, 0);
    for k in 0..MUTATIONS {
        let bytes = mutate(valid, &mut rng, header, text);
        fs::write(path, &bytes).unwrap();
        match catch_unwind(AssertUnwindSafe(|| load(path))) {
            Ok(Ok(())) => ok += 1,
            Ok(Err(e)) => {
                let msg = format!("{e:#}");
                assert!(
                    names.iter().any(|n| msg.contains(n)),
                    "{what} mutation {k}: the message names no file: {msg}"
                );
                refused += 1;
            }
            Err(_) => {
                let keep = std::env::temp_dir().join(format!("fuzz_{what}_{k}"));
                fs::write(&keep, &bytes).unwrap();
                panic!(
                    "{what} mutation {k} panicked (input kept at {})",
                    keep.display()
                );
            }
        }
    }
    eprintln!("{what}: {ok} loaded, {refused} refused");
    assert!(refused > 0, "{what}: no mutation was refused");
}

fn opts() -> LoadOptions {
    let mut o = LoadOptions::default();
    o.measured.directions = 200;
    o
}

#[test]
fn gonio_csv() {
    let d = tempfile::tempdir().unwrap();
    let text = fs::read_to_string(root().join("data_synthetic/silk/gonio.csv")).unwrap();
    let valid: String = text.lines().take(120).map(|l| format!("{l}\n")).collect();
    fuzz(
        "gonio",
        &d.path().join("g.csv"),
        valid.as_bytes(),
        200,
        true,
        26,
        &["g.csv"],
        &|p| load::load_data(p, &opts()).map(|_| ()),
    );
}

#[test]
fn rgl_bsdf() {
    let d = tempfile::tempdir().unwrap();
    let valid = fs::read(root().join("tests/data/rgl/acrylic_felt_green_rgb.bsdf")).unwrap();
    fuzz(
        "bsdf",
        &d.path().join("m.bsdf"),
        &valid,
        420,
        false,
        261,
        &["m.bsdf"],
        &|p| {
            load::load_data(p, &opts())?;
            load::measured_brdf(p).map(|_| ())
        },
    );
}

#[test]
fn merl_binary() {
    let d = tempfile::tempdir().unwrap();
    let dims = [6i32, 6, 12];
    let mut valid = Vec::new();
    for x in dims {
        valid.extend(x.to_le_bytes());
    }
    let n = 3 * 6 * 6 * 12;
    for i in 0..n {
        let v: f64 = if i % 7 == 0 { -1.0 } else { 100.0 + i as f64 };
        valid.extend(v.to_le_bytes());
    }
    fuzz(
        "merl",
        &d.path().join("m.binary"),
        &valid,
        12,
        false,
        262,
        &["m.binary"],
        &|p| load::load_data(p, &opts()).map(|_| ()),
    );
}

/// The silk capture (first two images) copied into `dir`.
fn silk_capture(dir: &Path) -> String {
    let src = root().join("data_synthetic/silk");
    for f in ["img_000.exr", "img_001.exr", "topology.png"] {
        fs::copy(src.join(f), dir.join(f)).unwrap();
    }
    let text = fs::read_to_string(src.join("capture.toml")).unwrap();
    // the description up to its third image
    let cut = text
        .match_indices("[[images]]")
        .nth(2)
        .map_or(text.len(), |m| m.0);
    text[..cut].to_string()
}

#[test]
fn capture_toml() {
    let d = tempfile::tempdir().unwrap();
    let valid = silk_capture(d.path());
    fuzz(
        "capture",
        &d.path().join("c.toml"),
        valid.as_bytes(),
        valid.len(),
        true,
        263,
        // an error may name an image the description names (possibly a mutated name)
        &["c.toml", "img_", d.path().to_str().unwrap()],
        &|p| load::load_data(p, &opts()).map(|_| ()),
    );
}

#[test]
fn exr_and_png_images() {
    let d = tempfile::tempdir().unwrap();
    let valid_toml = silk_capture(d.path());
    fs::write(d.path().join("c.toml"), &valid_toml).unwrap();
    let exr = fs::read(d.path().join("img_000.exr")).unwrap();
    // the image alone and as part of the capture
    let capture = d.path().join("c.toml");
    fuzz(
        "exr",
        &d.path().join("img_000.exr"),
        &exr,
        400,
        false,
        264,
        &["img_000.exr"],
        &|p| {
            load::image_io::read(p, None, None)?;
            load::load_data(&capture, &opts()).map(|_| ())
        },
    );
    fs::write(d.path().join("img_000.exr"), &exr).unwrap();
    let png = fs::read(d.path().join("topology.png")).unwrap();
    fuzz(
        "png",
        &d.path().join("topology.png"),
        &png,
        64,
        false,
        265,
        &["topology.png"],
        &|p| {
            load::image_io::read(p, Some(load::image_io::Encoding::Linear), None)?;
            load::load_data(&capture, &opts()).map(|_| ())
        },
    );
}

#[test]
fn obj_mesh() {
    let d = tempfile::tempdir().unwrap();
    // a small open cylinder with texture coordinates, quads, a pentagon cap and comments
    let (nu, nv) = (8, 3);
    let mut obj = String::from("# cylinder\no cyl\n");
    for j in 0..=nv {
        for i in 0..nu {
            let a = std::f64::consts::TAU * i as f64 / nu as f64;
            obj += &format!("v {} {} {}\n", a.cos(), a.sin(), j as f64 / nv as f64);
            obj += &format!("vt {} {}\n", i as f64 / nu as f64, j as f64 / nv as f64);
        }
    }
    obj += "vn 0 0 1\ns 1\nusemtl none\n";
    for j in 0..nv {
        for i in 0..nu {
            let id = |i: usize, j: usize| j * nu + (i % nu) + 1;
            let (a, b, c, e) = (id(i, j), id(i + 1, j), id(i + 1, j + 1), id(i, j + 1));
            obj += &format!("f {a}/{a} {b}/{b} {c}/{c} {e}/{e}\n");
        }
    }
    obj += "f -1 -2 -3 -4 -5 -6 -7 -8\n";
    fuzz(
        "obj",
        &d.path().join("m.obj"),
        obj.as_bytes(),
        obj.len(),
        true,
        266,
        &["m.obj"],
        &|p| {
            let m = load::mesh::load_obj(p)?;
            let c = fibrefit::render::curvature::principal_curvatures(&m, 2);
            assert!(c.iter().all(|v| v.normal.iter().all(|x| x.is_finite())));
            Ok(())
        },
    );
}
