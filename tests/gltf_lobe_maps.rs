//! Issue 38 item 1: the `gltf` rung's roughness and anisotropy strength per texel. A capture
//! synthesised from known roughness and anisotropy-strength maps (`synth` with `capture.maps`)
//! is fitted with `[maps] roughness`, `anisotropy_strength` and `kd`; every map comes back within
//! its standard errors, and `export --gltf` writes them as the metallic-roughness texture (G)
//! and KHR_materials_anisotropy's texture (B) with the factors at 1.

use assert_cmd::Command;
use fibrefit::load::image_io;
use std::fmt::Write as _;
use std::path::Path;

const N: usize = 16;

/// The truth: roughness across x, anisotropy strength up y.
fn roughness_at(x: usize) -> f64 {
    0.25 + 0.35 * x as f64 / (N - 1) as f64
}

fn strength_at(y: usize) -> f64 {
    0.1 + 0.7 * y as f64 / (N - 1) as f64
}

/// The synth config: 16 x 16 texels, 16 images (a light at 45 deg from eight azimuths, seen
/// near the mirror direction and from near the normal), grey kd, the lobe from the maps.
fn synth_config() -> String {
    let mut s = String::from(
        r#"model = "gltf"
[params]
kd = 0.3
metallic = 0.0
roughness = 0.4
anisotropy_strength = 0.4
specular_factor = 1.0
ior = 1.5
sheen = 0.0
fibre_azimuth_deg = 20
[capture]
width = 16
height = 16
size_mm = [20.0, 20.0]
format = "exr"
maps = "truth_maps"
[noise]
relative = 0.005
seed = 7
"#,
    );
    for k in 0..8 {
        let phi = 45.0 * k as f64;
        for (theta_v, dphi) in [(35.0, 180.0), (10.0, 150.0)] {
            writeln!(
                s,
                "[[capture.images]]\nlight = {{ type = \"directional\", theta_deg = 45, phi_deg = {phi}, irradiance = 1.0 }}\ncamera = {{ type = \"orthographic\", theta_deg = {theta_v}, phi_deg = {} }}",
                (phi + dphi) % 360.0
            )
            .unwrap();
        }
    }
    s
}

const FIT: &str = r#"model = "gltf"
metric = "linear"
seed = 1
[parameters]
kd = { value = 0.5 }
roughness = { value = 0.5 }
anisotropy_strength = { value = 0.3 }
fibre_azimuth_deg = { value = 20, vary = false }
metallic = { value = 0, vary = false }
specular_factor = { value = 1, vary = false }
ior = { value = 1.5, vary = false }
sheen = { value = 0, vary = false }
[maps]
kd = true
roughness = true
anisotropy_strength = true
rounds = 3
"#;

fn fibrefit() -> Command {
    Command::cargo_bin("fibrefit").expect("binary built")
}

fn write_map(path: &Path, f: impl Fn(usize, usize) -> f64) {
    let data: Vec<f32> = (0..N * N).map(|i| f(i % N, i / N) as f32).collect();
    fibrefit::export::images::write_exr(path, N, N, 1, &data).unwrap();
}

fn glb_json(bytes: &[u8]) -> serde_json::Value {
    let glb = gltf::binary::Glb::from_slice(bytes).unwrap();
    serde_json::from_slice(&glb.json).unwrap()
}

/// Image `i` of a GLB, decoded to 8-bit RGB.
fn image_rgb(g: &gltf::Gltf, i: usize) -> image::RgbImage {
    let blob = g.blob.as_ref().unwrap();
    let img = g.images().nth(i).unwrap();
    let gltf::image::Source::View { view, .. } = img.source() else {
        panic!("image {i} is not in the buffer");
    };
    let bytes = &blob[view.offset()..view.offset() + view.length()];
    image::load_from_memory_with_format(bytes, image::ImageFormat::Png)
        .unwrap()
        .to_rgb8()
}

#[test]
fn roughness_and_anisotropy_maps_are_recovered_and_exported_as_textures() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::create_dir(d.join("truth_maps")).unwrap();
    write_map(&d.join("truth_maps/roughness.exr"), |x, _| roughness_at(x));
    write_map(&d.join("truth_maps/anisotropy_strength.exr"), |_, y| {
        strength_at(y)
    });
    std::fs::write(d.join("synth.toml"), synth_config()).unwrap();
    fibrefit::synth::run(
        &d.join("synth.toml"),
        &d.join("cap"),
        &fibrefit::progress::Progress::quiet(),
    )
    .unwrap();
    std::fs::write(d.join("fit.toml"), FIT).unwrap();
    let (maps, result) = (d.join("maps"), d.join("r.json"));
    let out = fibrefit()
        .arg("fit")
        .arg(d.join("cap/capture.toml"))
        .arg("--config")
        .arg(d.join("fit.toml"))
        .arg("--out")
        .arg(&result)
        .arg("--maps")
        .arg(&maps)
        .arg("-q")
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );

    // every texel's lobe within its errors (at most one value in 256 beyond 4 standard errors:
    // a sharp and a broad lobe both fit some texels' 16 directions closely, and the search must
    // find the right one), and the median error small against the maps' ranges
    let read = |f: &str| image_io::read(&maps.join(f), None, None).unwrap();
    for (name, truth, range) in [
        (
            "roughness",
            &(|x, _| roughness_at(x)) as &dyn Fn(usize, usize) -> f64,
            0.35,
        ),
        ("anisotropy_strength", &|_, y| strength_at(y), 0.7),
    ] {
        let (m, se) = (
            read(&format!("{name}.exr")),
            read(&format!("{name}_std_error.exr")),
        );
        let (mut beyond, mut errors) = (0, Vec::new());
        for y in 0..N {
            for x in 0..N {
                let (got, s) = (m.pixel(x, y)[0] as f64, se.pixel(x, y)[0] as f64);
                let want = truth(x, y);
                assert!(
                    got.is_finite() && s > 0.0,
                    "{name} ({x}, {y}): {got} +/- {s}"
                );
                if (got - want).abs() > 4.0 * s {
                    beyond += 1;
                    eprintln!("{name} ({x}, {y}): {got} +/- {s}, truth {want}");
                }
                errors.push((got - want).abs());
            }
        }
        errors.sort_by(f64::total_cmp);
        let median = errors[errors.len() / 2];
        eprintln!(
            "{name}: median |error| {median:.4}, {beyond} of {} beyond 4 se",
            N * N
        );
        assert!(median < 0.05 * range, "{name}: median |error| {median}");
        assert!(
            beyond <= N * N / 50,
            "{name}: {beyond} texels beyond 4 standard errors"
        );
    }

    // the GLB carries them: G of the metallic-roughness texture, B of the anisotropy texture
    let glb = d.join("m.glb");
    fibrefit()
        .arg("export")
        .arg(&result)
        .arg("--gltf")
        .arg(&glb)
        .arg("-q")
        .assert()
        .success();
    let bytes = std::fs::read(&glb).unwrap();
    let json = glb_json(&bytes);
    let mat = &json["materials"][0];
    let pbr = &mat["pbrMetallicRoughness"];
    assert_eq!(pbr["roughnessFactor"].as_f64(), Some(1.0), "{mat}");
    let aniso = &mat["extensions"]["KHR_materials_anisotropy"];
    assert_eq!(aniso["anisotropyStrength"].as_f64(), Some(1.0), "{mat}");
    let g = gltf::Gltf::from_slice(&bytes).unwrap();
    let tex = |v: &serde_json::Value| {
        let t = v["index"].as_u64().unwrap() as usize;
        json["textures"][t]["source"].as_u64().unwrap() as usize
    };
    let rough = image_rgb(&g, tex(&pbr["metallicRoughnessTexture"]));
    let strength = image_rgb(&g, tex(&aniso["anisotropyTexture"]));
    let (rmap, smap) = (read("roughness.exr"), read("anisotropy_strength.exr"));
    let unorm = |v: f32| (v.clamp(0.0, 1.0) * 255.0).round() as u8;
    for y in 0..N {
        for x in 0..N {
            let (r, s) = (
                rough.get_pixel(x as u32, y as u32),
                strength.get_pixel(x as u32, y as u32),
            );
            assert_eq!(
                r[1],
                unorm(rmap.pixel(x, y)[0]),
                "roughness texel ({x}, {y})"
            );
            assert_eq!(r[2], 255, "metallic multiplier ({x}, {y})");
            assert_eq!(
                s[2],
                unorm(smap.pixel(x, y)[0]),
                "strength texel ({x}, {y})"
            );
        }
    }
}

#[test]
fn lobe_maps_need_a_rung_with_that_lobe() {
    let dir = tempfile::tempdir().unwrap();
    let cfg = dir.path().join("maps.toml");
    std::fs::write(&cfg, "model = \"ward\"\n[maps]\nroughness = true\n").unwrap();
    let capture = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/data_synthetic/silk/capture.toml"
    );
    let out = fibrefit()
        .args(["fit", capture, "-q", "--config"])
        .arg(&cfg)
        .arg("--maps")
        .arg(dir.path().join("maps"))
        .arg("--out")
        .arg(dir.path().join("r.json"))
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("roughness") && err.contains("gltf"), "{err}");
    assert!(!dir.path().join("r.json").exists());
}
