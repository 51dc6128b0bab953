//! Issue 37 item 4: the old approximations go. A fit records each renderer's own material
//! (`principled`, `openpbr`, `gltf`) fitted to the same data (`renderer_materials`, replacing
//! the Ward fallback fitted to the model), and `export --blender`, `--materialx` and `--gltf` of
//! any result write those, with their own error against the data, instead of converting the
//! fitted model; a parameter file alone (no data) is refused by the renderer exports and
//! converted by `--gltf`, labelled a conversion with its error against the model.

use assert_cmd::Command;
use std::path::{Path, PathBuf};

fn fibrefit() -> Command {
    Command::cargo_bin("fibrefit").expect("binary built")
}

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// A `hast-diffuse` fit of the shipped silk table (quick), its result JSON.
fn fit(dir: &Path) -> (PathBuf, serde_json::Value) {
    let out = dir.join("silk.json");
    let o = fibrefit()
        .arg("fit")
        .arg(root().join("data_synthetic/silk/gonio.csv"))
        .args(["--model", "hast-diffuse", "--out"])
        .arg(&out)
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(stdout.contains("[[Renderer materials]]"), "{stdout}");
    assert!(!stdout.contains("Ward fallback"), "{stdout}");
    let v = serde_json::from_str(&std::fs::read_to_string(&out).unwrap()).unwrap();
    (out, v)
}

fn material<'a>(v: &'a serde_json::Value, model: &str) -> &'a serde_json::Value {
    v["renderer_materials"]
        .as_array()
        .unwrap()
        .iter()
        .find(|m| m["model"] == model)
        .unwrap_or_else(|| panic!("no {model} material"))
}

fn value(m: &serde_json::Value, name: &str) -> f64 {
    m["parameters"][name]["value"].as_f64().unwrap()
}

#[test]
fn a_fit_records_the_renderers_materials_and_the_exports_write_them() {
    let dir = tempfile::tempdir().unwrap();
    let (result, v) = fit(dir.path());
    assert!(v.get("ward_fallback").is_none());
    let p = material(&v, "principled");
    let o = material(&v, "openpbr");
    let g = material(&v, "gltf");
    for m in [p, o, g] {
        assert!(m["renderer"].as_str().unwrap().len() > 3);
        assert!(m["fit_seconds"].as_f64().unwrap() > 0.0);
        let rel = m["statistics"]["relative_rmse"].as_f64().unwrap();
        assert!(rel.is_finite() && rel > 0.0);
    }
    // --blender, --materialx, --usd and --gltf of the hast-diffuse result: the recorded materials
    let (py, mtlx, usda, glb) = (
        dir.path().join("m.py"),
        dir.path().join("m.mtlx"),
        dir.path().join("m.usda"),
        dir.path().join("m.glb"),
    );
    let out = fibrefit()
        .arg("export")
        .arg(&result)
        .arg("--blender")
        .arg(&py)
        .arg("--materialx")
        .arg(&mtlx)
        .arg("--usd")
        .arg(&usda)
        .arg("--gltf")
        .arg(&glb)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{stderr}");
    for rung in ["principled", "openpbr"] {
        assert!(
            stderr.contains(&format!("the `{rung}` material"))
                && stderr.contains("not a conversion of the `hast-diffuse` model"),
            "{stderr}"
        );
    }
    assert!(
        stderr.contains("--gltf: recorded: the glTF material the `hast-diffuse` fit recorded"),
        "{stderr}"
    );
    assert!(!stderr.contains("converted"), "{stderr}");
    // a recorded material's own undetermined values are named as such (not the fit's)
    for m in [p, o, g] {
        for (name, e) in m["parameters"].as_object().unwrap() {
            let undetermined = match &e["determined"] {
                serde_json::Value::Bool(b) => !b,
                serde_json::Value::Array(a) => a.iter().any(|d| d == false),
                _ => false,
            };
            if undetermined {
                let rung = m["model"].as_str().unwrap();
                assert!(
                    stderr.contains(&format!("the recorded `{rung}` material's `{name}")),
                    "{rung} {name}: {stderr}"
                );
            }
        }
    }
    // the values written are the recorded ones, and the error line is the material's own
    let script = std::fs::read_to_string(&py).unwrap();
    assert!(
        script.contains(&format!("\"Roughness\": {:?}", value(p, "roughness"))),
        "{script}"
    );
    let rel = p["statistics"]["relative_rmse"].as_f64().unwrap();
    assert!(
        script.contains(&format!("relative RMS error {:.1} %", 100.0 * rel)),
        "{script}"
    );
    let doc = std::fs::read_to_string(&mtlx).unwrap();
    assert!(doc.contains(&format!(
        "<input name=\"specular_roughness\" type=\"float\" value=\"{:?}\" />",
        value(o, "specular_roughness")
    )));
    assert!(std::fs::read_to_string(&usda)
        .unwrap()
        .contains("ND_open_pbr_surface_surfaceshader"));
    let bytes = std::fs::read(&glb).unwrap();
    let json_len = u32::from_le_bytes(bytes[12..16].try_into().unwrap()) as usize;
    let gltf: serde_json::Value = serde_json::from_slice(&bytes[20..20 + json_len]).unwrap();
    let mat = &gltf["materials"][0];
    let rough = mat["pbrMetallicRoughness"]["roughnessFactor"]
        .as_f64()
        .unwrap();
    assert!((rough - value(g, "roughness")).abs() < 1e-6, "{mat}");
    assert!(
        mat["extras"]["fibrefit"]["route"]
            .as_str()
            .unwrap()
            .starts_with("recorded"),
        "{mat}"
    );
}

#[test]
fn a_parameter_file_alone_is_refused_by_the_renderer_exports_and_converted_by_gltf() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("vt.toml");
    std::fs::write(
        &p,
        "model = \"hast-diffuse\"\nkd = 0.4\nfibre_azimuth_deg = 10\n",
    )
    .unwrap();
    for (flag, file) in [("--blender", "m.py"), ("--materialx", "m.mtlx")] {
        let out = fibrefit()
            .arg("export")
            .arg(&p)
            .arg(flag)
            .arg(dir.path().join(file))
            .output()
            .unwrap();
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{stderr}");
        assert!(
            stderr.contains("fitted to its data") && stderr.contains("fibrefit fit DATA --model"),
            "{stderr}"
        );
        assert!(!dir.path().join(file).exists());
    }
    let glb = dir.path().join("m.glb");
    let out = fibrefit()
        .arg("export")
        .arg(&p)
        .arg("--gltf")
        .arg(&glb)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{stderr}");
    assert!(
        stderr.contains("converted") || stderr.contains("conversion"),
        "{stderr}"
    );
}
