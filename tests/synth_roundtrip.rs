//! synth -> load gives back the rendered values (noise off): goniometric to f64 precision, EXR
//! captures to f32 precision, 16-bit PNG captures to their quantisation, with the topology texel
//! and the per-pixel geometry of pinhole cameras and point lights.

use fibrefit::load::{load_data, samples::Origin, LoadOptions};
use fibrefit::model::frame::{FibreFrame, Vec3};
use fibrefit::model::params::{ModelParams, RawParams};
use fibrefit::model::topology::TopologyMap;
use fibrefit::model::{self, DirectionPair, ModelId};
use std::path::Path;

const CONFIG: &str = r#"
model = "varying-topology"
[params]
kd = [0.5, 0.3, 0.2]
ks = 0.3
exponent = 40
spacing = 2.2
height = 0.8
map_scale = 0.4
fibre_azimuth_deg = 15
histogram_bins = 8
[topology_map]
width = 12
height = 10
seed = 3
[gonio]
random = { count = 200, seed = 9, max_theta_deg = 85 }
[capture]
width = 12
height = 10
size_mm = [100.0, 50.0]
format = "FORMAT"
[[capture.images]]
light = { type = "point", position_mm = [400.0, 0.0, 300.0], intensity = 0.25 }
camera = { type = "pinhole", position_mm = [0.0, -300.0, 400.0] }
[[capture.images]]
light = { type = "directional", theta_deg = 40, phi_deg = 100, irradiance = 2.0 }
camera = { type = "orthographic", theta_deg = 20, phi_deg = 260 }
"#;

fn synth(dir: &Path, format: &str) {
    let cfg = dir.join("synth.toml");
    std::fs::write(&cfg, CONFIG.replace("FORMAT", format)).unwrap();
    fibrefit::synth::run(
        &cfg,
        &dir.join("out"),
        &fibrefit::progress::Progress::quiet(),
    )
    .unwrap();
}

fn truth(dir: &Path) -> (ModelParams, Box<dyn model::ShadingModel>) {
    let raw = RawParams::load(&dir.join("out/truth.json")).unwrap();
    let (p, _) = ModelParams::from_raw(&raw, ModelId::VaryingTopology).unwrap();
    let m = model::build(ModelId::VaryingTopology, &p).unwrap();
    (p, m)
}

#[test]
fn gonio_round_trip_is_exact() {
    let dir = tempfile::tempdir().unwrap();
    synth(dir.path(), "exr");
    let (p, m) = truth(dir.path());
    let data = load_data(&dir.path().join("out/gonio.csv"), &LoadOptions::default()).unwrap();
    assert_eq!(data.samples.len(), 200);
    assert_eq!(data.channels, 3);
    let frame = FibreFrame::from_azimuth(p.fibre_azimuth);
    for s in &data.samples {
        let b = m.basis(&DirectionPair::new(&frame, &s.l, &s.v));
        for c in 0..3 {
            let want = b.brdf(&p.albedos, c);
            assert!(
                (s.value[c] - want).abs() <= 1e-14 * want.abs(),
                "{:?}: {} vs {want}",
                s.origin,
                s.value[c]
            );
        }
        assert_eq!(
            s.map_value, None,
            "a goniometric spot averages over the map"
        );
    }
}

fn check_capture(format: &str, rel_tol: f64) {
    let dir = tempfile::tempdir().unwrap();
    synth(dir.path(), format);
    let (p, m) = truth(dir.path());
    let data = load_data(
        &dir.path().join("out/capture.toml"),
        &LoadOptions::default(),
    )
    .unwrap();
    assert_eq!(data.samples.len(), 2 * 12 * 10);
    let map = TopologyMap::load(&dir.path().join("out/topology.png")).unwrap();
    let mut worst: f64 = 0.0;
    for s in &data.samples {
        let Origin::Pixel { image, x, y } = s.origin else {
            panic!("capture samples come from pixels")
        };
        let m_texel = map.texel(x as usize, y as usize);
        assert_eq!(
            s.map_value,
            Some(m_texel),
            "topology texel of pixel ({x}, {y})"
        );
        let frame = FibreFrame::from_azimuth(s.fibre_azimuth.expect("capture states the azimuth"));
        let pair = DirectionPair::new(&frame, &s.l, &s.v);
        let b = m
            .basis_at_height(&pair, p.topology.texel_height(m_texel, p.spacing))
            .unwrap();
        for c in 0..3 {
            let want = b.brdf(&p.albedos, c);
            let err = (s.value[c] - want).abs() / want;
            worst = worst.max(err);
            assert!(
                err < rel_tol,
                "{format} image {image} ({x}, {y}) channel {c}: {} vs {want}",
                s.value[c]
            );
        }
        if (image, x, y) == (0, 3, 0) {
            // hand-computed: pixel (3, 0) of 12 x 10 over 100 x 50 mm sits at
            // x = (3.5/12 - 0.5) 100 = -20.8333.., y = (0.5 - 0.5/10) 50 = 22.5
            let px = Vec3::new(-62.5 / 3.0, 22.5, 0.0);
            let v = (Vec3::new(0.0, -300.0, 400.0) - px).normalize();
            let l = (Vec3::new(400.0, 0.0, 300.0) - px).normalize();
            assert!((s.v - v).norm() < 1e-12 && (s.l - l).norm() < 1e-12);
        }
    }
    eprintln!("{format}: worst relative round-trip error {worst:.2e}");
}

#[test]
fn exr_capture_round_trip_to_float_precision() {
    check_capture("exr", 3e-7);
}

#[test]
fn png_capture_round_trip_to_16_bit_quantisation() {
    check_capture("png", 2e-4);
}

#[test]
fn noise_is_seeded_and_of_the_stated_size() {
    let dir = tempfile::tempdir().unwrap();
    let cfg = dir.path().join("synth.toml");
    let text = CONFIG.replace("FORMAT", "exr") + "[noise]\nrelative = 0.05\nseed = 4\n";
    std::fs::write(&cfg, &text).unwrap();
    fibrefit::synth::run(
        &cfg,
        &dir.path().join("a"),
        &fibrefit::progress::Progress::quiet(),
    )
    .unwrap();
    fibrefit::synth::run(
        &cfg,
        &dir.path().join("b"),
        &fibrefit::progress::Progress::quiet(),
    )
    .unwrap();
    let a = std::fs::read(dir.path().join("a/gonio.csv")).unwrap();
    assert_eq!(
        a,
        std::fs::read(dir.path().join("b/gonio.csv")).unwrap(),
        "same seed, same data"
    );
    let (p, m) = {
        let raw = RawParams::load(&dir.path().join("a/truth.json")).unwrap();
        let (p, _) = ModelParams::from_raw(&raw, ModelId::VaryingTopology).unwrap();
        let m = model::build(ModelId::VaryingTopology, &p).unwrap();
        (p, m)
    };
    let data = load_data(&dir.path().join("a/gonio.csv"), &LoadOptions::default()).unwrap();
    let frame = FibreFrame::from_azimuth(p.fibre_azimuth);
    let z: Vec<f64> = data
        .samples
        .iter()
        .map(|s| {
            let f = m
                .basis(&DirectionPair::new(&frame, &s.l, &s.v))
                .brdf(&p.albedos, 0);
            (s.value[0] - f) / s.sigma.unwrap()[0]
        })
        .collect();
    let rms = (z.iter().map(|x| x * x).sum::<f64>() / z.len() as f64).sqrt();
    assert!((rms - 1.0).abs() < 0.15, "normalised residual rms {rms}");
}
