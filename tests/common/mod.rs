//! Shared helpers for the integration tests: direction sets and parameter sets.
#![allow(dead_code)]

pub mod mutate;

/// The fit config that recovers [`SYNTH`]'s maps (height, fibre azimuth and kd per texel) in at
/// most `rounds` alternations of the global stage (tests/maps.rs, tests/gltf_maps.rs).
pub fn maps_fit(rounds: u32) -> String {
    format!(
        r#"
model = "varying-topology"
metric = "linear"
seed = 1
[parameters]
kd = {{ value = 0.5 }}
ks = {{ value = 0.2 }}
exponent = {{ value = 20, min = 1, max = 1000 }}
spacing = {{ value = 2.0, vary = false }}
height = {{ value = 0.8 }}
fibre_azimuth_deg = {{ value = 0 }}
[maps]
height = true
fibre_azimuth = true
kd = true
rounds = {rounds}
"#
    )
}

/// The synth config of a small capture whose maps are known (tests/maps.rs, tests/gltf_maps.rs):
/// 16 x 16 texels, 8 images; fibres from -30 to 40 deg across x, heights from a topology map.
pub const SYNTH: &str = r#"
model = "varying-topology"
[params]
kd = 0.4
ks = 0.3
exponent = 40
spacing = 2.0
height = 0.9
map_scale = 0.6
fibre_azimuth_deg = 0
[topology_map]
width = 16
height = 16
seed = 3
[capture]
width = 16
height = 16
size_mm = [20.0, 20.0]
format = "exr"
tangent = { from_deg = -30, to_deg = 40 }
[[capture.images]]
light = { type = "directional", theta_deg = 30, phi_deg = 110, irradiance = 1.0 }
camera = { type = "orthographic", theta_deg = 0, phi_deg = 0 }
[[capture.images]]
light = { type = "directional", theta_deg = 60, phi_deg = 100, irradiance = 1.0 }
camera = { type = "orthographic", theta_deg = 30, phi_deg = 290 }
[[capture.images]]
light = { type = "directional", theta_deg = 45, phi_deg = 20, irradiance = 1.0 }
camera = { type = "orthographic", theta_deg = 45, phi_deg = 200 }
[[capture.images]]
light = { type = "directional", theta_deg = 70, phi_deg = 300, irradiance = 1.0 }
camera = { type = "orthographic", theta_deg = 20, phi_deg = 110 }
[[capture.images]]
light = { type = "directional", theta_deg = 50, phi_deg = 180, irradiance = 1.0 }
camera = { type = "orthographic", theta_deg = 50, phi_deg = 0 }
[[capture.images]]
light = { type = "directional", theta_deg = 20, phi_deg = 200, irradiance = 1.0 }
camera = { type = "orthographic", theta_deg = 60, phi_deg = 20 }
[[capture.images]]
light = { type = "directional", theta_deg = 65, phi_deg = 240, irradiance = 1.0 }
camera = { type = "orthographic", theta_deg = 40, phi_deg = 60 }
[[capture.images]]
light = { type = "directional", theta_deg = 40, phi_deg = 330, irradiance = 1.0 }
camera = { type = "orthographic", theta_deg = 55, phi_deg = 150 }
[noise]
relative = 0.01
seed = 5
"#;

use fibrefit::model::frame::{direction_from_angles, FibreFrame, Vec3};
use fibrefit::model::topology::Topology;
use fibrefit::model::{self, DirectionPair, ModelId, ShadingModel};

/// Deterministic xorshift generator (tests need no `rand`).
pub struct Rng(u64);
impl Rng {
    pub fn new(seed: u64) -> Self {
        Rng(seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1)
    }
    pub fn uniform(&mut self) -> f64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        (self.0 >> 11) as f64 / (1u64 << 53) as f64
    }
    /// Uniform direction on the upper hemisphere.
    pub fn hemisphere(&mut self) -> Vec3 {
        let z = self.uniform();
        let r = (1.0 - z * z).sqrt();
        let p = 2.0 * std::f64::consts::PI * self.uniform();
        Vec3::new(r * p.cos(), r * p.sin(), z)
    }
}

/// Local-frame pairs (T = x, B = y, N = z) covering the extremes the brief lists: l along T,
/// l across T, N.l = 0, N.v = 0, l = v, mirror, grazing, plus random pairs.
pub fn extreme_pairs() -> Vec<DirectionPair> {
    let deg = |a: f64| a.to_radians();
    let frame = FibreFrame::from_azimuth(0.0);
    let mut dirs: Vec<Vec3> = vec![
        Vec3::new(0.0, 0.0, 1.0),
        Vec3::new(1.0, 0.0, 0.0),              // along T, at the horizon
        Vec3::new(1.0, 0.0, 1e-9).normalize(), // along T, just above
        Vec3::new(0.0, 1.0, 0.0),              // across T, at the horizon
        Vec3::new(0.0, 1.0, 1e-9).normalize(), // across T, grazing
        Vec3::new(0.0, -1.0, 1e-6).normalize(),
        Vec3::new(0.6, 0.8, 0.0), // N.l = 0
        direction_from_angles(deg(89.99), deg(45.0)),
        direction_from_angles(deg(30.0), deg(90.0)),
        direction_from_angles(deg(60.0), deg(-120.0)),
        direction_from_angles(deg(45.0), deg(10.0)),
        direction_from_angles(deg(80.0), deg(170.0)),
    ];
    let mut rng = Rng::new(7);
    for _ in 0..12 {
        dirs.push(rng.hemisphere());
    }
    let mut pairs = Vec::new();
    for l in &dirs {
        for v in &dirs {
            pairs.push(DirectionPair::new(&frame, l, v));
        }
        // mirror of l about N
        let m = Vec3::new(-l.x, -l.y, l.z);
        pairs.push(DirectionPair::new(&frame, l, &m));
    }
    pairs
}

/// Random pairs above the horizon (not grazing closer than `min_cos`).
pub fn random_pairs(n: usize, seed: u64, min_cos: f64) -> Vec<DirectionPair> {
    let frame = FibreFrame::from_azimuth(0.0);
    let mut rng = Rng::new(seed);
    let mut out = Vec::new();
    while out.len() < n {
        let (l, v) = (rng.hemisphere(), rng.hemisphere());
        if l.z > min_cos && v.z > min_cos {
            out.push(DirectionPair::new(&frame, &l, &v));
        }
    }
    out
}

/// A cross-section parameter set: (spacing, height H, exponent).
#[derive(Clone, Copy, Debug)]
pub struct Section {
    pub spacing: f64,
    pub height: f64,
    pub exponent: f64,
}

pub fn sections() -> Vec<Section> {
    let s = |spacing: f64, height: f64, exponent: f64| Section {
        spacing,
        height,
        exponent,
    };
    let hmax = |d: f64| (d * d - 1.0f64).sqrt();
    vec![
        s(2.0, 0.0, 1.0),
        s(2.0, 0.9, 20.0),
        s(2.0, hmax(2.0), 20.0), // elevation at its limit
        s(2.5, 1.2, 100.0),
        s(4.0, 0.0, 5.0), // gaps, substrate visible
        s(4.0, hmax(4.0), 50.0),
        s(20.0, 3.0, 1e4),
    ]
}

pub fn vt(s: &Section, order: usize) -> Box<dyn ShadingModel> {
    Box::new(model::varying_topology::VaryingTopology::new(
        s.spacing,
        s.exponent,
        order,
        vec![(s.height, 1.0)],
    ))
}

pub fn reference(s: &Section) -> Box<dyn ShadingModel> {
    Box::new(model::reference::Reference::new(
        s.spacing,
        s.exponent,
        Topology {
            height: s.height,
            map_scale: 0.0,
            map: None,
        },
    ))
}

/// The value of `p` in the example of rung `id` (the table's absent value where it has none).
fn example(id: ModelId, p: model::parameter::Param) -> f64 {
    let example = id.rung().example.iter().find(|e| e.0 == p);
    example.map_or(p.info().absent, |e| e.1)
}

/// Every rung, built at the given section.
pub fn all_rungs(s: &Section) -> Vec<Box<dyn ShadingModel>> {
    let topology = Topology {
        height: s.height,
        map_scale: 0.0,
        map: None,
    };
    ModelId::ALL
        .iter()
        .map(|&id| {
            (id.rung().build)(&model::AlignedInputs {
                exponent: s.exponent,
                spacing: s.spacing,
                alpha_x: 0.05,
                alpha_y: 0.4,
                quadrature_order: 16,
                histogram_bins: 16,
                topology: &topology,
                gltf: model::params::GltfShape::of(|p| example(id, p)),
                principled: model::params::PrincipledShape::of(|p| example(id, p)),
                openpbr: model::params::OpenPbrShape::of(|p| example(id, p)),
            })
        })
        .collect()
}

pub fn rel_diff(a: f64, b: f64) -> f64 {
    (a - b).abs() / a.abs().max(b.abs()).max(1e-300)
}

/// Held-out errors of a fit on the shared real felt.
#[derive(Debug)]
pub struct FeltScore {
    /// RMS of ln(m + eps) - ln(y + eps), eps the log metric's floor.
    pub log_error: f64,
    pub relative_rmse: f64,
    /// Sum of data over sum of model where theta_i, theta_o > 55 deg on opposite sides.
    pub grazing_forward_ratio: f64,
}

/// Fit `cfg` to 1200 seeded directions of the shared felt (`tests/data/rgl`) and score it
/// on 600 others: a fast version of `fibrefit bench --felt`.
pub fn felt_heldout(cfg: &fibrefit::fit::config::FitConfig) -> FeltScore {
    let felt = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data/rgl/acrylic_felt_green_rgb.bsdf");
    let opts = |n: usize, seed: u64| fibrefit::load::LoadOptions {
        measured: fibrefit::load::rgl::MeasuredOptions {
            directions: n,
            seed,
            max_theta_deg: 78.0,
        },
        ..Default::default()
    };
    let train = fibrefit::load::load_data(&felt, &opts(1200, 1)).unwrap();
    let test = fibrefit::load::load_data(&felt, &opts(600, 2)).unwrap();
    let o = fibrefit::fit::fit(&train, cfg, &fibrefit::progress::Progress::quiet()).unwrap();
    let (_, m) = fibrefit::fit::selection::model_values_on(&o, cfg, &test).unwrap();
    let raw: Vec<[f64; 3]> = test.samples.iter().map(|s| s.value).collect();
    let (mut sl, mut se, mut sy, mut n) = (0.0, 0.0, 0.0, 0.0);
    let (mut gd, mut gm) = (0.0, 0.0);
    for c in 0..3 {
        let eps = fibrefit::fit::problem::log_floor(&raw, c);
        for (mv, s) in m.iter().zip(&test.samples) {
            sl += ((mv[c].max(0.0) + eps).ln() - (s.value[c] + eps).ln()).powi(2);
            se += (mv[c] - s.value[c]).powi(2);
            sy += s.value[c].powi(2);
            n += 1.0;
            let opposite = s.l.x * s.v.x + s.l.y * s.v.y < 0.0;
            if s.l.z < 55f64.to_radians().cos() && s.v.z < 55f64.to_radians().cos() && opposite {
                gd += s.value[c];
                gm += mv[c];
            }
        }
    }
    FeltScore {
        log_error: (sl / n).sqrt(),
        relative_rmse: (se / sy).sqrt(),
        grazing_forward_ratio: gd / gm,
    }
}

/// CRC-32 (IEEE) of `data`, as PNG chunks carry it.
pub fn crc32(data: &[u8]) -> u32 {
    let mut c = 0xFFFF_FFFFu32;
    for &b in data {
        c ^= b as u32;
        for _ in 0..8 {
            c = if c & 1 != 0 {
                0xEDB8_8320 ^ (c >> 1)
            } else {
                c >> 1
            };
        }
    }
    !c
}

/// A PNG whose header claims `w` x `h` 8-bit grey pixels, with a tiny (incomplete) image body.
pub fn png_claiming(w: u32, h: u32) -> Vec<u8> {
    let mut b = b"\x89PNG\r\n\x1a\n".to_vec();
    let mut chunk = |kind: &[u8], data: &[u8]| {
        b.extend((data.len() as u32).to_be_bytes());
        let mut body = kind.to_vec();
        body.extend(data);
        b.extend(&body);
        b.extend(crc32(&body).to_be_bytes());
    };
    let mut ihdr = Vec::new();
    ihdr.extend(w.to_be_bytes());
    ihdr.extend(h.to_be_bytes());
    ihdr.extend([8, 0, 0, 0, 0]);
    chunk(b"IHDR", &ihdr);
    // zlib stream of a few zero bytes
    chunk(
        b"IDAT",
        &[0x78, 0x9c, 0x63, 0x00, 0x00, 0x00, 0x01, 0x00, 0x01],
    );
    chunk(b"IEND", &[]);
    b
}

/// Every file below `d` (relative name, content): links as `-> target`, directories and FIFOs
/// by their kind, so that two snapshots differ when anything below `d` changed.
pub fn snapshot(d: &std::path::Path) -> Vec<(String, Vec<u8>)> {
    let mut v = vec![];
    let mut stack = vec![d.to_path_buf()];
    while let Some(p) = stack.pop() {
        for e in std::fs::read_dir(&p).unwrap().flatten() {
            let path = e.path();
            let name = path.strip_prefix(d).unwrap().display().to_string();
            let t = e.file_type().unwrap();
            let content = if t.is_symlink() {
                format!("-> {}", std::fs::read_link(&path).unwrap().display()).into_bytes()
            } else if t.is_dir() {
                stack.push(path);
                b"(dir)".to_vec()
            } else if std::os::unix::fs::FileTypeExt::is_fifo(&t) {
                b"(fifo)".to_vec()
            } else {
                std::fs::read(&path).unwrap()
            };
            v.push((name, content));
        }
    }
    v.sort();
    v
}

/// The relative noise of the synthetic data without sigmas (tests/floor.rs,
/// tests/correction.rs): their log values scatter by about this much.
pub const NOISE: f64 = 0.08;

/// A sheen-y fibre swatch (poulin-fournier with the fuzz layer) at `count` random directions,
/// noised by [`NOISE`] relative, written without its sigma columns (a measurement that gives
/// none).
pub fn synth_without_sigmas(dir: &std::path::Path, count: usize) -> std::path::PathBuf {
    synth_noised(dir, count, 5)
}

/// [`synth_without_sigmas`] with the noise seeded by `seed` (the same directions).
pub fn synth_noised(dir: &std::path::Path, count: usize, seed: u64) -> std::path::PathBuf {
    let dir = &dir.join(format!("noise{seed}"));
    std::fs::create_dir_all(dir).unwrap();
    let cfg = dir.join("s.toml");
    std::fs::write(
        &cfg,
        format!(
            "model = \"poulin-fournier\"\n[params]\nkd = [0.5, 0.35, 0.2]\nks = 0.2\nexponent = 8\n\
             spacing = 2.4\nfibre_azimuth_deg = 10\nfuzz = 3.0\nfuzz_depth = 0.3\nfuzz_asymmetry = 0.6\n\
             [gonio]\nrandom = {{ count = {count}, seed = 3, max_theta_deg = 80 }}\n\
             [noise]\nrelative = {NOISE}\nseed = {seed}\n"
        ),
    )
    .unwrap();
    let out = dir.join("d");
    fibrefit::synth::run(&cfg, &out, &fibrefit::progress::Progress::quiet()).unwrap();
    let text = std::fs::read_to_string(out.join("gonio.csv")).unwrap();
    let mut lines = text.lines().filter(|l| !l.trim_start().starts_with('#'));
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let keep: Vec<usize> = (0..header.len())
        .filter(|&k| !header[k].starts_with("sigma"))
        .collect();
    let mut csv = String::new();
    for l in std::iter::once(header.join(",").as_str()).chain(lines) {
        let f: Vec<&str> = l.split(',').collect();
        csv += &keep.iter().map(|&k| f[k]).collect::<Vec<_>>().join(",");
        csv.push('\n');
    }
    let path = dir.join("no_sigmas.csv");
    std::fs::write(&path, csv).unwrap();
    path
}
