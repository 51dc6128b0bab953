//! Issue 26, the input side: malformed measured files, image headers claiming huge sizes, inputs
//! that are devices or FIFOs, files that change while read, hostile OBJ meshes. Every case exits
//! 2 with a message naming the file (and the field or line), or loads; none panics or aborts.

#![allow(dead_code)]

mod common;

use assert_cmd::Command;
use fibrefit::load;
use std::fs;
use std::path::Path;
use std::time::{Duration, Instant};

pub fn fibrefit() -> Command {
    let mut c = Command::cargo_bin("fibrefit").unwrap();
    c.timeout(Duration::from_secs(60));
    c
}

/// `fibrefit ARGS`: exit 2, stderr an error containing every one of `want`, no panic.
fn refused(args: &[&str], dir: &Path, want: &[&str]) {
    let out = fibrefit().current_dir(dir).args(args).output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{args:?}: {err}");
    assert!(err.starts_with("error: "), "{args:?}: {err}");
    assert!(!err.contains("panicked"), "{args:?}: {err}");
    for w in want {
        assert!(err.contains(w), "{args:?}: expected '{w}' in: {err}");
    }
}

fn accepted(args: &[&str], dir: &Path) -> String {
    let out = fibrefit().current_dir(dir).args(args).output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(0), "{args:?}: {err}");
    String::from_utf8_lossy(&out.stdout).into_owned()
}

// ---------------------------------------------------------------------------------------------
// RGL tensor files

/// One field of a tensor file to write: name, type code, shape, raw little-endian data.
pub struct TField {
    pub name: String,
    pub dtype: u8,
    pub shape: Vec<u64>,
    pub data: Vec<u8>,
    /// Written instead of the real offset when set.
    pub offset: Option<u64>,
}

pub fn f32_field(name: &str, shape: &[u64], values: &[f32]) -> TField {
    TField {
        name: name.into(),
        dtype: 10,
        shape: shape.to_vec(),
        data: values.iter().flat_map(|v| v.to_le_bytes()).collect(),
        offset: None,
    }
}

pub fn tensor_file(fields: &[TField]) -> Vec<u8> {
    let mut head = b"tensor_file\0".to_vec();
    head.extend([1, 0]);
    head.extend((fields.len() as u32).to_le_bytes());
    let table: usize = fields
        .iter()
        .map(|f| 2 + f.name.len() + 2 + 1 + 8 + 8 * f.shape.len())
        .sum();
    let mut offset = (head.len() + table) as u64;
    let mut data: Vec<u8> = Vec::new();
    for f in fields {
        head.extend((f.name.len() as u16).to_le_bytes());
        head.extend(f.name.as_bytes());
        head.extend((f.shape.len() as u16).to_le_bytes());
        head.push(f.dtype);
        head.extend(f.offset.unwrap_or(offset).to_le_bytes());
        for d in &f.shape {
            head.extend(d.to_le_bytes());
        }
        offset += f.data.len() as u64;
        data.extend(&f.data);
    }
    head.extend(data);
    head
}

/// A small valid isotropic RGL file: 3 incidences, 4 x 4 tables.
pub fn small_rgl_fields() -> Vec<TField> {
    let theta = [0.0f32, 0.6, 1.570_796_3];
    let n = 4usize;
    let table = |f: &dyn Fn(usize, usize) -> f32| -> Vec<f32> {
        (0..n * n).map(|i| f(i / n, i % n)).collect()
    };
    let ndf = table(&|y, _| 1.0 - 0.2 * y as f32);
    let sigma = table(&|_, x| 0.5 + 0.1 * x as f32);
    let mut vndf = Vec::new();
    let mut rgb = Vec::new();
    for t in 0..3 {
        vndf.extend(table(&|y, x| 1.0 + 0.1 * (x + y + t) as f32));
        for c in 0..3 {
            rgb.extend(table(&|y, x| 0.2 + 0.05 * (x + 2 * y + c) as f32));
        }
    }
    let nu = n as u64;
    vec![
        TField {
            name: "description".into(),
            dtype: 1,
            shape: vec![4],
            data: b"test".to_vec(),
            offset: None,
        },
        f32_field("phi_i", &[1], &[0.0]),
        f32_field("theta_i", &[3], &theta),
        f32_field("sigma", &[nu, nu], &sigma),
        f32_field("ndf", &[nu, nu], &ndf),
        f32_field("vndf", &[1, 3, nu, nu], &vndf),
        f32_field("rgb", &[1, 3, 3, nu, nu], &rgb),
    ]
}

fn with(mut fields: Vec<TField>, name: &str, f: impl FnOnce(&mut TField)) -> Vec<TField> {
    f(fields.iter_mut().find(|x| x.name == name).unwrap());
    fields
}

fn set_f32(field: &mut TField, i: usize, v: f32) {
    field.data[4 * i..4 * i + 4].copy_from_slice(&v.to_le_bytes());
}

#[test]
fn malformed_bsdf_files_are_refused_field_by_field() {
    let d = tempfile::tempdir().unwrap();
    let dir = d.path();
    fs::write(dir.join("ok.bsdf"), tensor_file(&small_rgl_fields())).unwrap();
    let text = accepted(&["inspect", "ok.bsdf"], dir);
    assert!(!text.contains("inf"), "{text}");
    let cases: Vec<(&str, Vec<TField>, Vec<&str>)> = vec![
        // 1-wide tables (panicked at the interpolation)
        (
            "narrow_ndf",
            with(small_rgl_fields(), "ndf", |f| {
                *f = f32_field("ndf", &[1, 4], &[1.0; 4])
            }),
            vec!["field `ndf`", "at least 2"],
        ),
        (
            "narrow_vndf",
            with(small_rgl_fields(), "vndf", |f| {
                *f = f32_field("vndf", &[1, 3, 16, 1], &[1.0; 48])
            }),
            vec!["field `vndf`", "at least 2"],
        ),
        // shape products that overflow usize
        (
            "overflow",
            with(small_rgl_fields(), "ndf", |f| {
                f.shape = vec![1 << 32, (1 << 32) + 1]
            }),
            vec!["field `ndf`", "beyond the end"],
        ),
        (
            "huge_offset",
            with(small_rgl_fields(), "sigma", |f| {
                f.offset = Some(u64::MAX - 3)
            }),
            vec!["field `sigma`", "beyond the end"],
        ),
        // values
        (
            "nan_rgb",
            with(small_rgl_fields(), "rgb", |f| set_f32(f, 7, f32::NAN)),
            vec!["field `rgb` entry 7", "finite"],
        ),
        (
            "inf_ndf",
            with(small_rgl_fields(), "ndf", |f| set_f32(f, 0, f32::INFINITY)),
            vec!["field `ndf` entry 0", "finite"],
        ),
        (
            "negative_vndf",
            with(small_rgl_fields(), "vndf", |f| set_f32(f, 3, -1.0)),
            vec!["field `vndf` entry 3", "non-negative"],
        ),
        (
            "zero_sigma",
            with(small_rgl_fields(), "sigma", |f| set_f32(f, 2, 0.0)),
            vec!["field `sigma` entry 2", "positive"],
        ),
        (
            "nan_theta",
            with(small_rgl_fields(), "theta_i", |f| set_f32(f, 1, f32::NAN)),
            vec!["field `theta_i` entry 1"],
        ),
        (
            "negative_theta",
            with(small_rgl_fields(), "theta_i", |f| set_f32(f, 0, -0.5)),
            vec!["field `theta_i` entry 0"],
        ),
        (
            "huge_theta",
            with(small_rgl_fields(), "theta_i", |f| set_f32(f, 2, 3e38)),
            vec!["field `theta_i` entry 2"],
        ),
        (
            "unsorted_theta",
            with(small_rgl_fields(), "theta_i", |f| set_f32(f, 1, 1.5708)),
            vec!["field `theta_i` is not increasing"],
        ),
        (
            "nan_phi",
            with(small_rgl_fields(), "phi_i", |f| set_f32(f, 0, f32::NAN)),
            vec!["field `phi_i` entry 0"],
        ),
        (
            "missing_rgb",
            small_rgl_fields()
                .into_iter()
                .filter(|f| f.name != "rgb")
                .collect(),
            vec!["no field `rgb`"],
        ),
        (
            "duplicate",
            {
                let mut f = small_rgl_fields();
                f.push(f32_field("phi_i", &[1], &[0.0]));
                f
            },
            vec!["`phi_i` appears twice"],
        ),
    ];
    for (case, fields, want) in cases {
        let file = format!("{case}.bsdf");
        fs::write(dir.join(&file), tensor_file(&fields)).unwrap();
        let mut w = want.clone();
        w.push(&file);
        refused(&["inspect", &file], dir, &w);
    }
    // a file full of NaN (inspect showed "inf .. -inf", fit gave kd 0)
    let mut nan = small_rgl_fields();
    for f in nan.iter_mut().filter(|f| f.dtype == 10) {
        for i in 0..f.data.len() / 4 {
            set_f32(f, i, f32::NAN);
        }
    }
    fs::write(dir.join("nan.bsdf"), tensor_file(&nan)).unwrap();
    refused(&["inspect", "nan.bsdf"], dir, &["nan.bsdf", "finite"]);
    refused(
        &["fit", "nan.bsdf", "--model", "lambert", "--out", "o.json"],
        dir,
        &["nan.bsdf"],
    );
    assert!(!dir.join("o.json").exists());
    // every truncation of the valid file: refused, never a panic
    let bytes = tensor_file(&small_rgl_fields());
    for cut in (0..bytes.len()).step_by(bytes.len() / 40 + 1) {
        fs::write(dir.join("cut.bsdf"), &bytes[..cut]).unwrap();
        let e = load::rgl::RglBsdf::load(&dir.join("cut.bsdf")).err();
        assert!(
            e.is_some_and(|e| e.to_string().contains("cut.bsdf")),
            "cut {cut}"
        );
    }
}

#[test]
fn too_many_directions_are_refused_not_a_capacity_overflow() {
    let d = tempfile::tempdir().unwrap();
    fs::write(d.path().join("ok.bsdf"), tensor_file(&small_rgl_fields())).unwrap();
    refused(
        &["inspect", "ok.bsdf", "--directions", "18446744073709551615"],
        d.path(),
        &["--directions"],
    );
}

// ---------------------------------------------------------------------------------------------
// MERL

fn merl_bytes(dims: [i32; 3], value: impl Fn(usize) -> f64) -> Vec<u8> {
    let mut b = Vec::new();
    for x in dims {
        b.extend(x.to_le_bytes());
    }
    let n = 3 * dims.iter().map(|&d| d as usize).product::<usize>();
    for i in 0..n {
        b.extend(value(i).to_le_bytes());
    }
    b
}

#[test]
fn merl_values_beyond_range_are_refused_and_negative_markers_kept() {
    let d = tempfile::tempdir().unwrap();
    let dir = d.path();
    let dims = [4, 4, 8];
    // a quarter of the cells unmeasured (negative): accepted, as before
    fs::write(
        dir.join("ok.binary"),
        merl_bytes(dims, |i| if i % 4 == 0 { -1.0 } else { 150.0 }),
    )
    .unwrap();
    accepted(&["inspect", "ok.binary"], dir);
    for (case, bad) in [("huge", 1e300), ("nan", f64::NAN), ("inf", f64::INFINITY)] {
        let file = format!("{case}.binary");
        fs::write(
            dir.join(&file),
            merl_bytes(dims, |i| if i == 37 { bad } else { 150.0 }),
        )
        .unwrap();
        refused(
            &["inspect", &file],
            dir,
            &[&file, "table entry 37", "finite"],
        );
    }
    // dimensions whose table would not fit (checked arithmetic, no allocation)
    let mut b = Vec::new();
    for x in [4096i32, 4096, 4096] {
        b.extend(x.to_le_bytes());
    }
    fs::write(dir.join("big.binary"), &b).unwrap();
    refused(
        &["inspect", "big.binary"],
        dir,
        &["big.binary", "need more than"],
    );
    let mut short = merl_bytes(dims, |_| 1.0);
    short.truncate(short.len() - 3);
    fs::write(dir.join("short.binary"), &short).unwrap();
    refused(&["inspect", "short.binary"], dir, &["short.binary", "need"]);
}

// ---------------------------------------------------------------------------------------------
// Images

/// A small valid EXR (one channel Y, 4 x 4), written by the exr crate.
pub fn small_exr(path: &Path) {
    use exr::prelude::*;
    let ch = AnyChannel::new("Y", FlatSamples::F32(vec![0.5f32; 16]));
    let layer = Layer::new(
        (4, 4),
        LayerAttributes::named("main"),
        Encoding::UNCOMPRESSED,
        AnyChannels::sort(SmallVec::from_vec(vec![ch])),
    );
    Image::from_layer(layer).write().to_file(path).unwrap();
}

/// The bytes of an EXR whose data window is patched to claim `w` x `h` pixels.
pub fn exr_claiming(valid: &[u8], w: i32, h: i32) -> Vec<u8> {
    let key = b"dataWindow\0box2i\0";
    let at = valid
        .windows(key.len())
        .position(|x| x == key)
        .expect("a data window")
        + key.len()
        + 4;
    let mut b = valid.to_vec();
    for (k, v) in [0i32, 0, w - 1, h - 1].iter().enumerate() {
        b[at + 4 * k..at + 4 * k + 4].copy_from_slice(&v.to_le_bytes());
    }
    b
}

fn capture_toml(image: &str, extra: &str) -> String {
    let encoding = if image.ends_with(".png") {
        "encoding = \"linear\"\n"
    } else {
        ""
    };
    format!(
        "[swatch]\nsize_mm = [10.0, 10.0]\nfibre_azimuth_deg = 0\n{extra}\n[[images]]\nfile = \"{image}\"\n{encoding}exposure = 1.0\nlight = {{ type = \"directional\", theta_deg = 30, phi_deg = 0, irradiance = 1.0 }}\ncamera = {{ type = \"orthographic\", theta_deg = 0, phi_deg = 0 }}\n"
    )
}

#[test]
fn image_headers_claiming_huge_sizes_are_refused_before_decoding() {
    let d = tempfile::tempdir().unwrap();
    let dir = d.path();
    small_exr(&dir.join("ok.exr"));
    fs::write(dir.join("ok.toml"), capture_toml("ok.exr", "")).unwrap();
    accepted(&["inspect", "ok.toml"], dir);
    let valid = fs::read(dir.join("ok.exr")).unwrap();
    let huge = exr_claiming(&valid, 100_000, 100_000);
    assert!(huge.len() < 1000, "{} bytes", huge.len());
    fs::write(dir.join("huge.exr"), &huge).unwrap();
    fs::write(dir.join("huge.toml"), capture_toml("huge.exr", "")).unwrap();
    refused(
        &["inspect", "huge.toml"],
        dir,
        &["huge.exr", "100000x100000", "2^28"],
    );
    // just over the limit
    fs::write(dir.join("over.exr"), exr_claiming(&valid, 16385, 16384)).unwrap();
    fs::write(dir.join("over.toml"), capture_toml("over.exr", "")).unwrap();
    refused(&["inspect", "over.toml"], dir, &["over.exr", "16385x16384"]);
    // the same header as a topology map, and as a result's map
    fs::write(
        dir.join("topo.toml"),
        capture_toml("ok.exr", "topology_map = \"huge.exr\""),
    )
    .unwrap();
    refused(
        &["inspect", "topo.toml"],
        dir,
        &["huge.exr", "100000x100000"],
    );
    let e = load::texel_maps::TexelMapsIn::load(
        &{
            let m = dir.join("maps");
            fs::create_dir(&m).unwrap();
            fs::write(m.join("kd.exr"), &huge).unwrap();
            m
        },
        None,
    )
    .err()
    .unwrap()
    .to_string();
    assert!(e.contains("kd.exr") && e.contains("100000x100000"), "{e}");
    // PNGs: a header claiming 100000^2 (a decompression bomb's shape)
    fs::write(dir.join("bomb.png"), common::png_claiming(100_000, 100_000)).unwrap();
    fs::write(dir.join("bomb.toml"), capture_toml("bomb.png", "")).unwrap();
    refused(
        &["inspect", "bomb.toml"],
        dir,
        &["bomb.png", "100000x100000"],
    );
    fs::write(
        dir.join("mask.toml"),
        capture_toml("ok.exr", "mask = \"bomb.png\""),
    )
    .unwrap();
    refused(
        &["inspect", "mask.toml"],
        dir,
        &["bomb.png", "100000x100000"],
    );
}

// ---------------------------------------------------------------------------------------------
// Devices, FIFOs, files that change while read

#[cfg(unix)]
#[test]
fn devices_and_links_to_them_are_read_with_a_limit() {
    if !Path::new("/dev/zero").exists() {
        return;
    }
    let d = tempfile::tempdir().unwrap();
    let dir = d.path();
    let link = |name: &str| {
        std::os::unix::fs::symlink("/dev/zero", dir.join(name)).unwrap();
    };
    for name in ["z.csv", "z.bsdf", "z.binary", "z.toml", "z.obj"] {
        link(name);
    }
    let t = Instant::now();
    refused(&["inspect", "z.csv"], dir, &["z.csv", "no header line"]);
    refused(&["inspect", "z.bsdf"], dir, &["z.bsdf", "tensor_file"]);
    refused(&["inspect", "z.binary"], dir, &["z.binary", "dimensions"]);
    refused(&["inspect", "z.toml"], dir, &["z.toml", "64 MiB"]);
    refused(
        &["tangents", "z.obj", "--out", "t.csv"],
        dir,
        &["z.obj:1", "16 MiB"],
    );
    // an OBJ naming /dev/zero as its material library: materials are never read
    fs::write(
        dir.join("m.obj"),
        "mtllib /dev/zero\nv 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0.5\nf 1 2 3\nf 2 4 3\n",
    )
    .unwrap();
    accepted(&["tangents", "m.obj", "--out", "m.csv", "-q"], dir);
    assert!(t.elapsed() < Duration::from_secs(30), "{:?}", t.elapsed());
    // in process: the limit of a device read
    let e = load::input::read_input(&dir.join("z.csv"), 1 << 20)
        .unwrap_err()
        .to_string();
    assert!(e.contains("z.csv") && e.contains("1 MiB"), "{e}");
}

#[cfg(unix)]
#[test]
fn a_fifo_with_a_writer_is_read_as_a_stream() {
    let d = tempfile::tempdir().unwrap();
    let fifo = d.path().join("g.csv");
    let ok = std::process::Command::new("mkfifo")
        .arg(&fifo)
        .status()
        .is_ok_and(|s| s.success());
    if !ok {
        return;
    }
    let writer = {
        let fifo = fifo.clone();
        std::thread::spawn(move || {
            let mut text = String::from("theta_i,phi_i,theta_o,phi_o,brdf\n");
            for i in 0..200 {
                text += &format!("{},0,{},180,0.3\n", i % 80, (i * 7) % 80);
            }
            fs::write(&fifo, text).unwrap();
        })
    };
    let s = load::load_data(&fifo, &Default::default()).unwrap();
    writer.join().unwrap();
    assert_eq!(s.samples.len(), 200);
    assert!(load::sha256_read(&fifo).is_some());
}

#[test]
fn the_hash_is_of_the_bytes_read_and_a_file_changed_while_read_is_an_error() {
    use sha2::Digest;
    use std::io::Read;
    let d = tempfile::tempdir().unwrap();
    let p = d.path().join("g.csv");
    let mut text = String::from("theta_i,phi_i,theta_o,phi_o,brdf\n");
    for i in 0..5000 {
        text += &format!("{},0,{},180,0.3\n", i % 80, (i * 7) % 80);
    }
    fs::write(&p, &text).unwrap();
    let s = load::load_data(&p, &Default::default()).unwrap();
    assert_eq!(s.samples.len(), 5000);
    let want: String = sha2::Sha256::digest(text.as_bytes())
        .iter()
        .map(|b| format!("{b:02x}"))
        .collect();
    assert_eq!(load::sha256_read(&p).as_deref(), Some(want.as_str()));
    // the same file by another name
    let other = d.path().join(".").join("g.csv");
    assert_eq!(load::sha256_read(&other).as_deref(), Some(want.as_str()));
    // truncated while read
    let mut input = load::input::open(&p, load::MAX_INPUT_BYTES).unwrap();
    let mut first = vec![0u8; 1000];
    input.read_exact(&mut first).unwrap();
    fs::OpenOptions::new()
        .write(true)
        .open(&p)
        .unwrap()
        .set_len(2000)
        .unwrap();
    let mut rest = Vec::new();
    input.read_to_end(&mut rest).unwrap();
    let e = input.finish().unwrap_err().to_string();
    assert!(e.contains("g.csv") && e.contains("changed while"), "{e}");
    // appended to while read
    fs::write(&p, &text).unwrap();
    let mut input = load::input::open(&p, load::MAX_INPUT_BYTES).unwrap();
    let mut all = Vec::new();
    input.read_to_end(&mut all).unwrap();
    fs::OpenOptions::new()
        .append(true)
        .open(&p)
        .unwrap()
        .write_all_bytes(b"10,0,20,180,0.3\n");
    let e = input.finish().unwrap_err().to_string();
    assert!(e.contains("changed while"), "{e}");
    // replaced (renamed over) while read
    fs::write(&p, &text).unwrap();
    let mut input = load::input::open(&p, load::MAX_INPUT_BYTES).unwrap();
    let mut all = Vec::new();
    input.read_to_end(&mut all).unwrap();
    let q = d.path().join("new.csv");
    fs::write(&q, &text).unwrap();
    fs::rename(&q, &p).unwrap();
    let e = input.finish().unwrap_err().to_string();
    assert!(e.contains("changed while"), "{e}");
}

trait WriteAll {
    fn write_all_bytes(self, b: &[u8]);
}
impl WriteAll for fs::File {
    fn write_all_bytes(mut self, b: &[u8]) {
        use std::io::Write;
        self.write_all(b).unwrap();
    }
}

// ---------------------------------------------------------------------------------------------
// OBJ

#[test]
fn obj_errors_name_the_line() {
    let d = tempfile::tempdir().unwrap();
    let dir = d.path();
    let cases = [
        (
            "num.obj",
            "v 0 0 0\nv 1 0 0\nv 0 x 0\nf 1 2 3\n",
            "num.obj:3:",
        ),
        (
            "nan.obj",
            "v 0 0 0\nv 1 0 nan\nv 0 1 0\nf 1 2 3\n",
            "nan.obj:2:",
        ),
        (
            "big.obj",
            "v 0 0 0\nv 1 0 1e39\nv 0 1 0\nf 1 2 3\n",
            "big.obj:2:",
        ),
        (
            "idx.obj",
            "v 0 0 0\nv 1 0 0\nv 0 1 0\n\nf 1 2 3\nf 1 2 9\n",
            "idx.obj:6:",
        ),
        (
            "zero.obj",
            "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 0 1 2\n",
            "zero.obj:4:",
        ),
        (
            "neg.obj",
            "v 0 0 0\nv 1 0 0\nv 0 1 0\nf -1 -2 -4\n",
            "neg.obj:4:",
        ),
        (
            "two.obj",
            "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2\n",
            "two.obj:4:",
        ),
        (
            "vt.obj",
            "v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nf 1/1 2/2 3/1\n",
            "vt.obj:5:",
        ),
        ("empty.obj", "# nothing\n", "no triangles"),
    ];
    for (file, text, want) in cases {
        fs::write(dir.join(file), text).unwrap();
        refused(&["tangents", file, "--out", "t.csv"], dir, &[file, want]);
        let e = load::mesh::load_obj(&dir.join(file))
            .unwrap_err()
            .to_string();
        assert!(e.contains(want), "{e}");
    }
    assert!(!dir.join("t.csv").exists());
}

fn tangent_rows(dir: &Path, file: &str) -> Vec<Vec<f64>> {
    accepted(&["tangents", file, "--out", "t.csv", "-q"], dir);
    let mut rd = csv::Reader::from_path(dir.join("t.csv")).unwrap();
    rd.records()
        .map(|r| r.unwrap().iter().map(|x| x.parse().unwrap()).collect())
        .collect()
}

#[test]
fn degenerate_faces_give_no_nan_normals_and_rows_follow_the_file() {
    let d = tempfile::tempdir().unwrap();
    let dir = d.path();
    // a pyramid with degenerate faces mixed in: a repeated vertex, collinear corners
    let obj = "v 0 0 1\nv 1 0 0\nv 0 1 0\nv -1 0 0\nv 0 -1 0\nv 2 0 0\n\
               f 1 2 3\nf 1 3 4\nf 1 4 5\nf 1 5 2\nf 2 2 3\nf 2 6 2\nf 4 2 6\n";
    fs::write(dir.join("p.obj"), obj).unwrap();
    let m = load::mesh::load_obj(&dir.join("p.obj")).unwrap();
    assert_eq!(m.triangles.len(), 4);
    assert_eq!(m.degenerate, 3);
    let rows = tangent_rows(dir, "p.obj");
    assert_eq!(rows.len(), 6);
    for r in &rows {
        assert!(r[3..6].iter().all(|v| v.is_finite()), "{r:?}");
    }
    // rows in the file's vertex order, though the faces use the vertices in another order
    let obj = "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0.1\nf 4 2 3\nf 2 1 3\n";
    fs::write(dir.join("o.obj"), obj).unwrap();
    let rows = tangent_rows(dir, "o.obj");
    let want = [
        [0.0, 0.0, 0.0],
        [1.0, 0.0, 0.0],
        [0.0, 1.0, 0.0],
        [1.0, 1.0, 0.1],
    ];
    for (r, w) in rows.iter().zip(want) {
        for k in 0..3 {
            assert!((r[k] - w[k]).abs() < 1e-6, "{r:?} {w:?}");
        }
    }
    // also through the glTF writer: no NaN normal
    accepted(&["tangents", "p.obj", "--out", "p.glb", "-q"], dir);
    let bytes = fs::read(dir.join("p.glb")).unwrap();
    let g = gltf::Gltf::from_slice(&bytes).unwrap();
    let blob = g.blob.as_ref().unwrap();
    let prim = g.meshes().next().unwrap().primitives().next().unwrap();
    let normals: Vec<[f32; 3]> = prim
        .reader(|_| Some(blob))
        .read_normals()
        .unwrap()
        .collect();
    assert!(normals.iter().flatten().all(|v| v.is_finite()));
}

/// A regular polygon of `n` corners as one face.
pub fn polygon_obj(n: usize) -> String {
    let mut s = String::with_capacity(n * 40);
    for i in 0..n {
        let a = std::f64::consts::TAU * i as f64 / n as f64;
        s += &format!("v {} {} 0\n", a.cos(), a.sin());
    }
    s += "f";
    for i in 1..=n {
        s += &format!(" {i}");
    }
    s += "\n";
    s
}

#[test]
fn a_polygon_of_100000_vertices_takes_under_a_second() {
    let d = tempfile::tempdir().unwrap();
    let p = d.path().join("poly.obj");
    fs::write(&p, polygon_obj(100_000)).unwrap();
    let t = Instant::now();
    let m = load::mesh::load_obj(&p).unwrap();
    let c = fibrefit::render::curvature::principal_curvatures(&m, 2);
    let took = t.elapsed();
    assert_eq!(c.len(), 100_000);
    assert!(m.triangles.len() + m.degenerate == 99_998);
    assert!(c.iter().all(|v| v.normal.iter().all(|x| x.is_finite())));
    assert!(took < Duration::from_secs(1), "load + curvature: {took:?}");
    // and through the command line, rows in order
    let t = Instant::now();
    accepted(&["tangents", "poly.obj", "--out", "t.csv", "-q"], d.path());
    assert!(
        t.elapsed() < Duration::from_secs(5),
        "tangents: {:?}",
        t.elapsed()
    );
}
