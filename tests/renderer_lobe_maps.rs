//! Issue 37 item 2: the renderers' own materials (`principled`, `openpbr`) fitted per texel. A
//! capture synthesised from known base colour, roughness, anisotropy and fibre-direction maps
//! (`synth` with `capture.maps`, the maps named as each rung names its parameters) is fitted
//! with `[maps]` of those names; every map comes back within its standard errors. The exports
//! carry them as textures beside the material (`export --blender`, `--materialx`, `--usd`),
//! pixel for pixel; in the renderers themselves they are checked by
//! `python/tests/test_blender.py` (Cycles at two texels) and `python/tests/test_materialx.py`.

use assert_cmd::Command;
use fibrefit::load::image_io;
use std::fmt::Write as _;
use std::path::Path;

const N: usize = 12;

/// The truth: base colour across x and y, roughness across x, anisotropy up y, the fibres
/// turning along the diagonal.
fn kd_at(x: usize, y: usize) -> f64 {
    0.2 + 0.3 * ((x + y) as f64 / (2 * (N - 1)) as f64)
}

fn roughness_at(x: usize, _: usize) -> f64 {
    0.3 + 0.3 * x as f64 / (N - 1) as f64
}

fn anisotropy_at(_: usize, y: usize) -> f64 {
    0.4 + 0.4 * y as f64 / (N - 1) as f64
}

fn azimuth_at(x: usize, y: usize) -> f64 {
    -40.0 + 60.0 * ((x + (N - 1 - y)) as f64 / (2 * (N - 1)) as f64)
}

/// A rung's material: its name, the parameter file's shape values, its lobe maps' names
/// (roughness, anisotropy) and the fit's fixed values.
struct Material {
    model: &'static str,
    params: &'static str,
    lobe: [&'static str; 2],
    fixed: &'static str,
}

const PRINCIPLED: Material = Material {
    model: "principled",
    params: "roughness = 0.4\nanisotropic = 0.5\nior = 1.5\nspecular_ior_level = 0.5\nspecular_tint = 1.0\nsheen_weight = 0.3\nsheen_roughness = 0.5\n",
    lobe: ["roughness", "anisotropic"],
    fixed: "ior = { value = 1.5, vary = false }\nspecular_ior_level = { value = 0.5, vary = false }\nspecular_tint = { value = 1.0, vary = false }\nsheen_weight = { value = 0.3, vary = false }\nsheen_roughness = { value = 0.5, vary = false }\n",
};

const OPENPBR: Material = Material {
    model: "openpbr",
    params: "specular_roughness = 0.4\nspecular_roughness_anisotropy = 0.5\nspecular_ior = 1.5\nfuzz_weight = 0.3\nfuzz_roughness = 0.5\n",
    lobe: ["specular_roughness", "specular_roughness_anisotropy"],
    fixed: "specular_ior = { value = 1.5, vary = false }\nfuzz_weight = { value = 0.3, vary = false }\nfuzz_roughness = { value = 0.5, vary = false }\n",
};

/// The synth config: N x N texels, 16 images (a light at 45 deg from eight azimuths, seen near
/// the mirror direction and from near the normal), the material from the maps.
fn synth_config(m: &Material) -> String {
    let mut s = format!(
        "model = \"{}\"\n[params]\nkd = 0.3\nfibre_azimuth_deg = 0\n{}[capture]\nwidth = {N}\nheight = {N}\nsize_mm = [20.0, 20.0]\nformat = \"exr\"\nmaps = \"truth_maps\"\n[noise]\nrelative = 0.005\nseed = 7\n",
        m.model, m.params
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

fn fit_config(m: &Material) -> String {
    format!(
        "model = \"{}\"\nmetric = \"linear\"\nseed = 1\n[parameters]\nkd = {{ value = 0.5 }}\n{} = {{ value = 0.5 }}\n{} = {{ value = 0.3 }}\nfibre_azimuth_deg = {{ value = 0 }}\n{}[maps]\nkd = true\nfibre_azimuth = true\n{} = true\n{} = true\nrounds = 3\n",
        m.model, m.lobe[0], m.lobe[1], m.fixed, m.lobe[0], m.lobe[1]
    )
}

fn fibrefit() -> Command {
    Command::cargo_bin("fibrefit").expect("binary built")
}

fn write_map(path: &Path, f: impl Fn(usize, usize) -> f64) {
    let data: Vec<f32> = (0..N * N).map(|i| f(i % N, i / N) as f32).collect();
    fibrefit::export::images::write_exr(path, N, N, 1, &data).unwrap();
}

/// Synthesise `m`'s capture from the truth maps into `d` and fit it per texel: (result, maps).
fn fitted_maps(m: &Material, d: &Path) -> (std::path::PathBuf, std::path::PathBuf) {
    std::fs::create_dir(d.join("truth_maps")).unwrap();
    write_map(&d.join("truth_maps/kd.exr"), kd_at);
    write_map(&d.join("truth_maps/fibre_azimuth.exr"), azimuth_at);
    write_map(
        &d.join(format!("truth_maps/{}.exr", m.lobe[0])),
        roughness_at,
    );
    write_map(
        &d.join(format!("truth_maps/{}.exr", m.lobe[1])),
        anisotropy_at,
    );
    std::fs::write(d.join("synth.toml"), synth_config(m)).unwrap();
    fibrefit::synth::run(
        &d.join("synth.toml"),
        &d.join("cap"),
        &fibrefit::progress::Progress::quiet(),
    )
    .unwrap();
    std::fs::write(d.join("fit.toml"), fit_config(m)).unwrap();
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
    (result, maps)
}

/// Every texel's values within their errors (at most one in 50 beyond 4 standard errors), and
/// the median error small against the maps' ranges; then the exports' textures.
fn maps_are_recovered(m: &Material) {
    let dir = tempfile::tempdir().unwrap();
    let (result, maps) = fitted_maps(m, dir.path());
    exports_carry_the_maps(m, &result, &maps, dir.path());
    let read = |f: &str| image_io::read(&maps.join(f), None, None).unwrap();
    type Truth = &'static dyn Fn(usize, usize) -> f64;
    for (name, truth, range, period) in [
        ("kd", &kd_at as Truth, 0.3, None),
        ("fibre_azimuth", &azimuth_at, 60.0, Some(180.0)),
        (m.lobe[0], &roughness_at, 0.3, None),
        (m.lobe[1], &anisotropy_at, 0.4, None),
    ] {
        let (v, se) = (
            read(&format!("{name}.exr")),
            read(&format!("{name}_std_error.exr")),
        );
        let (mut beyond, mut errors) = (0, Vec::new());
        for y in 0..N {
            for x in 0..N {
                let (got, s) = (v.pixel(x, y)[0] as f64, se.pixel(x, y)[0] as f64);
                let want = truth(x, y);
                assert!(
                    got.is_finite() && s > 0.0,
                    "{} {name} ({x}, {y}): {got} +/- {s}",
                    m.model
                );
                let mut e = got - want;
                if let Some(p) = period {
                    e = (e + 0.5 * p).rem_euclid(p) - 0.5 * p;
                }
                if e.abs() > 4.0 * s {
                    beyond += 1;
                    eprintln!("{} {name} ({x}, {y}): {got} +/- {s}, truth {want}", m.model);
                }
                errors.push(e.abs());
            }
        }
        errors.sort_by(f64::total_cmp);
        let median = errors[errors.len() / 2];
        eprintln!(
            "{} {name}: median |error| {median:.4}, {beyond} of {} beyond 4 se",
            m.model,
            N * N
        );
        assert!(
            median < 0.05 * range,
            "{} {name}: median |error| {median}",
            m.model
        );
        assert!(
            beyond <= N * N / 50,
            "{} {name}: {beyond} texels beyond 4 standard errors",
            m.model
        );
    }
}

#[test]
fn principled_maps_are_recovered() {
    maps_are_recovered(&PRINCIPLED);
}

#[test]
fn openpbr_maps_are_recovered() {
    maps_are_recovered(&OPENPBR);
}

#[test]
fn lobe_maps_take_the_rungs_own_names() {
    let dir = tempfile::tempdir().unwrap();
    let capture = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/data_synthetic/silk/capture.toml"
    );
    for (model, key, says) in [
        ("principled", "anisotropy_strength", "`anisotropic`"),
        ("openpbr", "roughness", "`specular_roughness`"),
        ("gltf", "specular_roughness", "`roughness`"),
        ("ward", "anisotropic", "gltf, principled, openpbr"),
    ] {
        let cfg = dir.path().join("maps.toml");
        std::fs::write(&cfg, format!("model = \"{model}\"\n[maps]\n{key} = true\n")).unwrap();
        let out = fibrefit()
            .args(["fit", capture, "-q", "--config"])
            .arg(&cfg)
            .arg("--maps")
            .arg(dir.path().join("maps"))
            .arg("--out")
            .arg(dir.path().join("r.json"))
            .output()
            .unwrap();
        assert_eq!(out.status.code(), Some(2), "{model} {key}");
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(
            err.contains(key) && err.contains(says),
            "{model} {key}: {err}"
        );
        assert!(!dir.path().join("r.json").exists());
        assert!(!dir.path().join("maps").exists());
    }
}

/// The exports of a maps fit: each material file with its textures beside it, named after it,
/// every pixel the maps' texel (the fibre azimuth as the renderer's rotation), and the material
/// reading them.
fn exports_carry_the_maps(m: &Material, result: &Path, maps: &Path, d: &Path) {
    let read = |p: &Path| image_io::read(p, None, None).unwrap();
    let map = |name: &str| read(&maps.join(format!("{name}.exr")));
    let (kd, psi, rough, aniso) = (
        map("kd"),
        map("fibre_azimuth"),
        map(m.lobe[0]),
        map(m.lobe[1]),
    );
    let out = d.join("out");
    std::fs::create_dir(&out).unwrap();
    let (flag, files): (&[&str], Vec<(&str, std::path::PathBuf)>) = match m.model {
        "principled" => (
            &["--blender", "out/felt.py"],
            vec![("out/felt.py", out.join("felt.py"))],
        ),
        _ => (
            &["--materialx", "out/felt.mtlx", "--usd", "out/stage.usda"],
            vec![
                ("out/felt.mtlx", out.join("felt.mtlx")),
                ("out/stage.usda", out.join("stage.usda")),
            ],
        ),
    };
    let o = fibrefit()
        .current_dir(d)
        .arg("export")
        .arg(result)
        .args(flag)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let said = String::from_utf8_lossy(&o.stderr);
    for (_, path) in &files {
        let stem = path.file_stem().unwrap().to_string_lossy().into_owned();
        let text = std::fs::read_to_string(path).unwrap();
        let suffixes: [(&str, &str); 4] = match m.model {
            "principled" => [
                ("base_color", "\"Base Color\""),
                ("roughness", "\"Roughness\""),
                ("anisotropic", "\"Anisotropic\""),
                ("anisotropic_rotation", "\"Anisotropic Rotation\""),
            ],
            _ => [
                ("base_color", "base_color"),
                ("specular_roughness", "specular_roughness"),
                (
                    "specular_roughness_anisotropy",
                    "specular_roughness_anisotropy",
                ),
                ("tangent_rotation", "amount"),
            ],
        };
        for (suffix, input) in suffixes {
            let file = format!("{stem}_{suffix}.exr");
            assert!(text.contains(&file), "{}: names {file}", path.display());
            assert!(text.contains(input), "{}: drives {input}", path.display());
            assert!(
                said.contains(&file),
                "the export says it wrote {file}: {said}"
            );
            let t = read(&out.join(&file));
            assert_eq!((t.width, t.height, t.channels), (N, N, 3), "{file}");
            for y in 0..N {
                for x in 0..N {
                    let px = t.pixel(x, y);
                    let want: [f64; 3] = match suffix {
                        "base_color" => {
                            [0, 1, 2].map(|c| kd.pixel(x, y)[c.min(kd.channels - 1)] as f64)
                        }
                        "anisotropic_rotation" => {
                            [((psi.pixel(x, y)[0] as f64 + 90.0) / 360.0).rem_euclid(1.0); 3]
                        }
                        "tangent_rotation" => {
                            let a = (-(psi.pixel(x, y)[0] as f64 + 90.0)).rem_euclid(360.0);
                            [if a > 180.0 { a - 360.0 } else { a }; 3]
                        }
                        s if s.ends_with("anisotropy") || s == "anisotropic" => {
                            [aniso.pixel(x, y)[0] as f64; 3]
                        }
                        _ => [rough.pixel(x, y)[0] as f64; 3],
                    };
                    for c in 0..3 {
                        assert!(
                            (px[c] as f64 - want[c]).abs() <= 1e-6 * want[c].abs().max(1.0),
                            "{file} ({x}, {y}) channel {c}: {} against the map's {}",
                            px[c],
                            want[c]
                        );
                    }
                }
            }
        }
        if m.model == "openpbr" {
            // image nodes, closest, the tangent's amount from its map
            assert!(text.contains("closest"), "{text}");
            if stem == "felt" {
                assert!(text.contains("<input name=\"amount\" type=\"float\" nodename=\"r_tangent_rotation_map\" />"), "{text}");
            } else {
                assert!(text.contains("inputs:amount.connect"), "{text}");
                assert!(text.contains("UsdUVTexture"), "{text}");
            }
        } else {
            assert!(
                text.contains("MAPS_DIR = ") && text.contains("Closest"),
                "{text}"
            );
        }
    }
}
