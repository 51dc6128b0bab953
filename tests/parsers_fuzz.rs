//! Issue 26: a fuzz-style property test per parser, in process. A valid small file of each kind
//! (goniometric CSV, RGL `.bsdf`, MERL `.binary`, capture TOML, OBJ, EXR and PNG images) is
//! mutated at random, seeded (truncation, byte flips, swapped fields, extreme numbers, huge
//! dimensions and offsets written over binary fields) and loaded inside `catch_unwind`: the
//! loader must not panic, and must give `Ok` or an error whose message names the file. The
//! number of mutations is bounded so that the whole test runs in seconds on 2 cores.

use fibrefit::load::{self, LoadOptions};
use std::fs;
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::path::{Path, PathBuf};

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// Mutations per parser.
const MUTATIONS: usize = 160;

struct Lcg(u64);
impl Lcg {
    fn next(&mut self) -> u64 {
        self.0 = self
            .0
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        self.0 >> 17
    }
    fn below(&mut self, n: usize) -> usize {
        (self.next() % n.max(1) as u64) as usize
    }
}

const EXTREMES: [&str; 14] = [
    "1e308", "-1e308", "nan", "inf", "-inf", "-0", "1e-320", "0", "99999", "-5", "90",
    "18446744073709551615", "4294967296", "1e39",
];

/// Binary values written over 1, 2, 4 or 8 bytes: sizes, offsets and floats at their extremes.
fn extreme_word(rng: &mut Lcg) -> Vec<u8> {
    let v: [Vec<u8>; 12] = [
        u64::MAX.to_le_bytes().to_vec(),
        (1u64 << 32).to_le_bytes().to_vec(),
        (1u64 << 62).to_le_bytes().to_vec(),
        0u64.to_le_bytes().to_vec(),
        1u64.to_le_bytes().to_vec(),
        u32::MAX.to_le_bytes().to_vec(),
        0x7fff_ffffu32.to_le_bytes().to_vec(),
        f32::NAN.to_le_bytes().to_vec(),
        f32::INFINITY.to_le_bytes().to_vec(),
        (-1.0f32).to_le_bytes().to_vec(),
        1e300f64.to_le_bytes().to_vec(),
        f64::NAN.to_le_bytes().to_vec(),
    ];
    v[rng.below(v.len())].clone()
}

/// One random mutation of `bytes`; `header`: how many leading bytes hold the structure (binary
/// mutations hit there half of the time); `text`: whether text mutations apply.
fn mutate(bytes: &[u8], rng: &mut Lcg, header: usize, text: bool) -> Vec<u8> {
    let mut t = bytes.to_vec();
    let kinds = if text { 5 } else { 3 };
    let pos = |rng: &mut Lcg, len: usize| {
        if rng.below(2) == 0 {
            rng.below(header.min(len))
        } else {
            rng.below(len)
        }
    };
    match rng.below(kinds) {
        0 => t.truncate(pos(rng, t.len())),
        1 => {
            for _ in 0..1 + rng.below(4) {
                let i = pos(rng, t.len());
                if i < t.len() {
                    t[i] ^= 1 << rng.below(8);
                }
            }
        }
        2 => {
            let w = extreme_word(rng);
            let i = pos(rng, t.len());
            let n = [1, 2, 4, 8][rng.below(4)].min(w.len());
            for k in 0..n {
                if i + k < t.len() {
                    t[i + k] = w[k];
                }
            }
        }
        3 => {
            // swap two fields of one line, or two lines
            let s = String::from_utf8_lossy(&t).into_owned();
            let mut lines: Vec<String> = s.lines().map(str::to_owned).collect();
            if lines.len() > 2 {
                let k = rng.below(lines.len());
                let mut fields: Vec<String> =
                    lines[k].split([',', ' ']).map(str::to_owned).collect();
                if fields.len() > 1 {
                    let (a, b) = (rng.below(fields.len()), rng.below(fields.len()));
                    fields.swap(a, b);
                    lines[k] = fields.join(if lines[k].contains(',') { "," } else { " " });
                } else {
                    let j = rng.below(lines.len());
                    lines.swap(k, j);
                }
            }
            t = (lines.join("\n") + "\n").into_bytes();
        }
        _ => {
            // an extreme number in place of a number
            let s = String::from_utf8_lossy(&t).into_owned();
            let b = s.as_bytes();
            let mut spans = Vec::new();
            let mut i = 0;
            while i < b.len() {
                if b[i].is_ascii_digit() {
                    let j0 = i;
                    while i < b.len() && (b[i].is_ascii_digit() || b[i] == b'.') {
                        i += 1;
                    }
                    spans.push((j0, i));
                } else {
                    i += 1;
                }
            }
            if !spans.is_empty() {
                let (a, e) = spans[rng.below(spans.len())];
                let x = EXTREMES[rng.below(EXTREMES.len())];
                t = format!("{}{x}{}", &s[..a], &s[e..]).into_bytes();
            }
        }
    }
    t
}

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
                panic!("{what} mutation {k} panicked (input kept at {})", keep.display());
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
    let valid = fs::read(root().join("../shared/data/rgl/acrylic_felt_green_rgb.bsdf")).unwrap();
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
    let cut = text.match_indices("[[images]]").nth(2).map_or(text.len(), |m| m.0);
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
