//! Issue 38 item 2: `fibrefit export --gltf` of a `gltf` fit writes the fit itself (its values,
//! its maps as textures) and states its error against the data; any other result, a `gltf +
//! fuzz` fit included (glTF has no fuzz layer), gets a material converted from the model,
//! labelled as a conversion. Every GLB is read back with the `gltf` crate.

use assert_cmd::Command;
use fibrefit::load::image_io;
use serde_json::Value;
use std::f64::consts::FRAC_PI_2;
use std::path::Path;

fn fibrefit() -> Command {
    Command::cargo_bin("fibrefit").expect("binary built")
}

/// The GLB's JSON chunk.
fn glb_json(bytes: &[u8]) -> Value {
    let glb = gltf::binary::Glb::from_slice(bytes).unwrap();
    serde_json::from_slice(&glb.json).unwrap()
}

fn used(raw: &Value) -> Vec<String> {
    raw["extensionsUsed"]
        .as_array()
        .map(|a| a.iter().map(|v| v.as_str().unwrap().to_string()).collect())
        .unwrap_or_default()
}

/// Export `params` as a swatch GLB; (stderr, bytes).
fn export(params: &Path, glb: &Path) -> (String, Vec<u8>) {
    let out = fibrefit()
        .arg("export")
        .arg(params)
        .arg("--gltf")
        .arg(glb)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
    assert!(out.status.success(), "{stderr}");
    (stderr, std::fs::read(glb).unwrap())
}

const GLTF_PARAMS: &str = r#"
model = "gltf"
kd = [0.5, 0.4, 0.3]
metallic = 0.2
roughness = 0.4
anisotropy_strength = 0.6
specular_factor = 0.8
ior = 1.6
sheen = 0.3
sheen_roughness = 0.5
fibre_azimuth_deg = 25
"#;

fn close(v: &Value, want: f64) -> bool {
    (v.as_f64().unwrap_or(f64::NAN) - want).abs() < 1e-12
}

#[test]
fn a_gltf_parameter_set_is_written_exactly_with_every_extension_declared() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("g.toml");
    std::fs::write(&p, GLTF_PARAMS).unwrap();
    let glb = dir.path().join("g.glb");
    let (stderr, bytes) = export(&p, &glb);
    assert!(stderr.contains("written exactly"), "{stderr}");
    assert!(stderr.contains("no error against data"), "{stderr}");

    // the typed reader accepts it, and the core values round-trip (as f32)
    let g = gltf::Gltf::from_slice(&bytes).expect("a valid glTF");
    let prim = g.meshes().next().unwrap().primitives().next().unwrap();
    let pbr = prim.material().pbr_metallic_roughness();
    assert_eq!(pbr.base_color_factor(), [0.5, 0.4, 0.3, 1.0]);
    assert_eq!(pbr.metallic_factor(), 0.2);
    assert_eq!(pbr.roughness_factor(), 0.4);

    // the extensions, exactly (the JSON's f64)
    let raw = glb_json(&bytes);
    let u = used(&raw);
    for ext in [
        "KHR_materials_anisotropy",
        "KHR_materials_specular",
        "KHR_materials_ior",
        "KHR_materials_sheen",
    ] {
        assert!(u.iter().any(|x| x == ext), "{ext} not in {u:?}");
    }
    let m = &raw["materials"][0];
    let e = &m["extensions"];
    assert!(close(
        &e["KHR_materials_anisotropy"]["anisotropyStrength"],
        0.6
    ));
    // across the fibres, which lie at 25 deg from the TANGENT (the swatch's u axis)
    assert!(close(
        &e["KHR_materials_anisotropy"]["anisotropyRotation"],
        25f64.to_radians() + FRAC_PI_2
    ));
    assert!(close(&e["KHR_materials_specular"]["specularFactor"], 0.8));
    assert_eq!(
        e["KHR_materials_specular"]["specularColorFactor"],
        serde_json::json!([1.0, 1.0, 1.0])
    );
    assert!(close(&e["KHR_materials_ior"]["ior"], 1.6));
    assert_eq!(
        e["KHR_materials_sheen"]["sheenColorFactor"],
        serde_json::json!([0.3, 0.3, 0.3])
    );
    assert!(close(
        &e["KHR_materials_sheen"]["sheenRoughnessFactor"],
        0.5
    ));
    let x = &m["extras"]["fibrefit"];
    assert!(x["route"].as_str().unwrap().starts_with("fitted"), "{x}");
    assert!(x["error_against_data"]["relative_rms_error"].is_null());

    // the swatch's frame: TANGENT the u axis (x), the bitangent N x T = +y the v axis
    let blob = g.blob.as_ref().unwrap();
    let reader = prim.reader(|_| Some(blob));
    let pos: Vec<[f32; 3]> = reader.read_positions().unwrap().collect();
    let uv: Vec<[f32; 2]> = reader.read_tex_coords(0).unwrap().into_f32().collect();
    for t in reader.read_tangents().unwrap() {
        assert_eq!(t, [1.0, 0.0, 0.0, 1.0]);
    }
    for (p, t) in pos.iter().zip(&uv) {
        // u grows with x; glTF's t = 1 - v falls with y
        assert!((t[0] - 0.5 * (p[0] + 1.0)).abs() < 1e-6, "{p:?} {t:?}");
        assert!((t[1] - 0.5 * (1.0 - p[1])).abs() < 1e-6, "{p:?} {t:?}");
    }

    // without sheen the extension is absent, not written as 0
    std::fs::write(&p, GLTF_PARAMS.replace("sheen = 0.3", "sheen = 0")).unwrap();
    let (_, bytes) = export(&p, &glb);
    let raw = glb_json(&bytes);
    assert!(!used(&raw).iter().any(|x| x == "KHR_materials_sheen"));
    assert!(raw["materials"][0]["extensions"]["KHR_materials_sheen"].is_null());
}

#[test]
fn a_gltf_fit_with_a_fuzz_layer_is_a_labelled_conversion() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("g.toml");
    std::fs::write(
        &p,
        format!("{GLTF_PARAMS}fuzz = 0.5\nfuzz_depth = 0.2\nfuzz_asymmetry = 0.3\n"),
    )
    .unwrap();
    let glb = dir.path().join("g.glb");
    let (stderr, bytes) = export(&p, &glb);
    assert!(
        stderr.contains("glTF has no extension for the fuzz layer"),
        "{stderr}"
    );
    assert!(
        stderr.contains("converted from the `gltf` model"),
        "{stderr}"
    );
    let x = &glb_json(&bytes)["materials"][0]["extras"]["fibrefit"];
    assert!(x["route"].as_str().unwrap().starts_with("converted"), "{x}");
    assert!(x["why_converted"].as_str().unwrap().contains("fuzz"), "{x}");
    assert!(x["relative_rms_error"].as_f64().unwrap() > 0.0, "{x}");
}

#[test]
fn another_rungs_result_stays_a_labelled_conversion() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let dir = tempfile::tempdir().unwrap();
    let glb = dir.path().join("silk.glb");
    let (stderr, bytes) = export(&root.join("configs/silk_params.toml"), &glb);
    assert!(
        stderr.contains("converted from the `varying-topology` model"),
        "{stderr}"
    );
    let raw = glb_json(&bytes);
    let x = &raw["materials"][0]["extras"]["fibrefit"];
    assert!(x["route"].as_str().unwrap().starts_with("converted"), "{x}");
    assert!(x["why_converted"].is_null());
    assert!(!used(&raw).iter().any(|e| e == "KHR_materials_specular"));
}

/// A `gltf` fit with base colour and fibre-direction maps on the silk capture, exported: the
/// maps as textures, the values as fitted, the error as the result states it.
#[test]
fn a_gltf_maps_fit_is_written_with_its_maps_as_textures_and_its_error() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let capture = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/data_synthetic/silk/capture.toml"
    );
    std::fs::write(
        d.join("maps.toml"),
        "model = \"gltf\"\n[maps]\nkd = true\nfibre_azimuth = true\n",
    )
    .unwrap();
    let (result, maps) = (d.join("result.json"), d.join("maps"));
    let out = fibrefit()
        .args(["fit", capture, "--quiet", "--config"])
        .arg(d.join("maps.toml"))
        .arg("--maps")
        .arg(&maps)
        .arg("--out")
        .arg(&result)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let glb = d.join("fit.glb");
    let (stderr, bytes) = export(&result, &glb);
    assert!(stderr.contains("written exactly"), "{stderr}");
    assert!(
        stderr.contains("error against the data: relative RMS error"),
        "{stderr}"
    );
    assert!(stderr.contains("textures from the maps"), "{stderr}");

    let r: Value = serde_json::from_str(&std::fs::read_to_string(&result).unwrap()).unwrap();
    let par = |n: &str| r["parameters"][n]["value"].as_f64().unwrap();
    let raw = glb_json(&bytes);
    let m = &raw["materials"][0];
    let pbr = &m["pbrMetallicRoughness"];
    assert!(close(&pbr["metallicFactor"], par("metallic")));
    assert!(close(&pbr["roughnessFactor"], par("roughness")));
    assert_eq!(
        pbr["baseColorFactor"],
        serde_json::json!([1.0, 1.0, 1.0, 1.0])
    );
    let e = &m["extensions"];
    let an = &e["KHR_materials_anisotropy"];
    assert!(close(&an["anisotropyStrength"], par("anisotropy_strength")));
    let psi0 = par("fibre_azimuth_deg");
    assert!(close(
        &an["anisotropyRotation"],
        psi0.to_radians() + FRAC_PI_2
    ));
    assert!(close(
        &e["KHR_materials_specular"]["specularFactor"],
        par("specular_factor")
    ));
    assert!(close(&e["KHR_materials_ior"]["ior"], par("ior")));
    let x = &m["extras"]["fibrefit"];
    let stated = x["error_against_data"]["relative_rms_error"]
        .as_f64()
        .unwrap();
    assert_eq!(stated, r["statistics"]["relative_rmse"].as_f64().unwrap());
    for ext in [
        "KHR_materials_anisotropy",
        "KHR_materials_specular",
        "KHR_materials_ior",
    ] {
        assert!(used(&raw).iter().any(|u| u == ext), "{ext}");
    }

    // the textures: base colour = the kd map in sRGB, anisotropy = the fibre map's direction
    let g = gltf::Gltf::from_slice(&bytes).unwrap();
    let image = |i: usize| {
        let blob = g.blob.as_ref().unwrap();
        let img = g.images().nth(i).unwrap();
        let gltf::image::Source::View { view, mime_type } = img.source() else {
            panic!("image {i} is not in the buffer");
        };
        assert_eq!(mime_type, "image/png");
        image::load_from_memory_with_format(
            &blob[view.offset()..view.offset() + view.length()],
            image::ImageFormat::Png,
        )
        .unwrap()
        .to_rgb8()
    };
    let bt = pbr["baseColorTexture"]["index"].as_u64().unwrap() as usize;
    let at = an["anisotropyTexture"]["index"].as_u64().unwrap() as usize;
    assert_ne!(bt, at);
    assert!(pbr.get("metallicRoughnessTexture").is_none());
    let (base, aniso) = (image(bt), image(at));
    let kd = image_io::read(&maps.join("kd.exr"), None, None).unwrap();
    let psi = image_io::read(&maps.join("fibre_azimuth.exr"), None, None).unwrap();
    assert_eq!(
        (base.width() as usize, base.height() as usize),
        (kd.width, kd.height)
    );
    let srgb = |c: u8| {
        let c = f64::from(c) / 255.0;
        if c <= 0.04045 {
            c / 12.92
        } else {
            ((c + 0.055) / 1.055).powf(2.4)
        }
    };
    let (mut worst_kd, mut worst_dir): (f64, f64) = (0.0, 0.0);
    for y in 0..kd.height {
        for x in 0..kd.width {
            let b = base.get_pixel(x as u32, y as u32).0;
            let k = kd.pixel(x, y);
            for c in 0..3 {
                if k[c].is_finite() {
                    // within one 8-bit sRGB step
                    // the larger of the two neighbouring steps
                    let (lo, hi) = (b[c].saturating_sub(1), b[c].saturating_add(1));
                    let step = (srgb(hi) - srgb(b[c])).max(srgb(b[c]) - srgb(lo));
                    worst_kd = worst_kd.max((srgb(b[c]) - k[c] as f64).abs() / step);
                }
            }
            let a = aniso.get_pixel(x as u32, y as u32).0;
            assert_eq!(a[2], 255, "B is the strength's factor 1");
            let p = psi.pixel(x, y)[0] as f64;
            if p.is_finite() {
                let got = (2.0 * a[1] as f64 / 255.0 - 1.0)
                    .atan2(2.0 * a[0] as f64 / 255.0 - 1.0)
                    .to_degrees();
                let diff = (got - (p - psi0) + 90.0).rem_euclid(180.0) - 90.0;
                worst_dir = worst_dir.max(diff.abs());
            }
        }
    }
    assert!(worst_kd <= 0.51, "base colour off by {worst_kd} sRGB steps");
    assert!(
        worst_dir < 0.5,
        "anisotropy direction off by {worst_dir} deg"
    );
}
