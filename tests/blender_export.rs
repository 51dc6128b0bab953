//! Issue 37 items 1 and 3 (Blender): `fibrefit export --blender FILE.py` writes a `principled`
//! result's values into a Principled BSDF exactly, by Blender's input names, with the tangent
//! across the fibres, its provenance and error in the header; every other result, a fuzz layer,
//! a wrong extension, an output onto the input are refused (exit 2, nothing written). That
//! Cycles renders what the rung evaluates is python/tests/test_blender.py (Blender's own
//! module).

use assert_cmd::Command;
use std::path::Path;

fn fibrefit() -> Command {
    Command::cargo_bin("fibrefit").expect("binary built")
}

const PARAMS: &str = r#"
model = "principled"
kd = [0.5, 0.3, 0.2]
roughness = 0.45
anisotropic = 0.6
ior = 1.5
specular_ior_level = 0.4
specular_tint = 0.9
sheen_weight = 0.5
sheen_roughness = 0.6
fibre_azimuth_deg = 20
"#;

/// The value the script gives input `key` (its INPUTS line).
fn input<'a>(script: &'a str, key: &str) -> &'a str {
    let line = script
        .lines()
        .find(|l| l.trim_start().starts_with(&format!("\"{key}\":")))
        .unwrap_or_else(|| panic!("no input {key}:\n{script}"));
    line.split_once(": ").unwrap().1.trim_end_matches(',')
}

#[test]
fn a_principled_result_is_written_exactly_by_blenders_names() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("felt.toml");
    std::fs::write(&p, PARAMS).unwrap();
    let py = dir.path().join("felt.py");
    let out = fibrefit()
        .args(["export"])
        .arg(&p)
        .arg("--blender")
        .arg(&py)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{stderr}");
    assert!(stderr.contains("Blender material `felt`"), "{stderr}");
    let s = std::fs::read_to_string(&py).unwrap();
    assert!(s.contains("NAME = \"felt\""));
    assert_eq!(input(&s, "Base Color"), "(0.5, 0.3, 0.2, 1.0)");
    assert_eq!(input(&s, "Roughness"), "0.45");
    assert_eq!(input(&s, "Anisotropic"), "0.6");
    assert_eq!(input(&s, "IOR"), "1.5");
    assert_eq!(input(&s, "Specular IOR Level"), "0.4");
    assert_eq!(input(&s, "Specular Tint"), "(0.9, 0.9, 0.9, 1.0)");
    assert_eq!(input(&s, "Sheen Weight"), "0.5");
    assert_eq!(input(&s, "Sheen Roughness"), "0.6");
    assert_eq!(input(&s, "Sheen Tint"), "(1.0, 1.0, 1.0, 1.0)");
    // the anisotropy across the fibres: (20 + 90) / 360 of a turn from the UV tangent
    let rot: f64 = input(&s, "Anisotropic Rotation").parse().unwrap();
    assert!((rot - 110.0 / 360.0).abs() < 1e-15, "{rot}");
    for (k, v) in [
        ("Metallic", "0.0"),
        ("Coat Weight", "0.0"),
        ("Transmission Weight", "0.0"),
    ] {
        assert_eq!(input(&s, k), v);
    }
    assert!(s.contains("direction_type = \"UV_MAP\"") && s.contains("\"MULTI_GGX\""));
    assert!(s.contains("# from felt.toml (sha256 "));
    assert!(s.contains("no error against data: the file is a parameter file"));
    // --name
    let named = dir.path().join("named.py");
    fibrefit()
        .arg("export")
        .arg(&p)
        .args(["--blender"])
        .arg(&named)
        .args(["--name", "green \"felt\""])
        .assert()
        .success();
    let s = std::fs::read_to_string(&named).unwrap();
    assert!(s.contains(r#"NAME = "green \"felt\"""#), "{s}");
}

fn refused(params: &str, out_name: &str, want: &str) {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("r.toml");
    std::fs::write(&p, params).unwrap();
    let out_path = if out_name == "INPUT" {
        p.clone()
    } else {
        dir.path().join(out_name)
    };
    let out = fibrefit()
        .arg("export")
        .arg(&p)
        .arg("--blender")
        .arg(&out_path)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{stderr}");
    assert!(stderr.contains(want), "{want}: {stderr}");
    let files: Vec<_> = std::fs::read_dir(dir.path()).unwrap().collect();
    assert_eq!(files.len(), 1, "nothing written beside the input");
    assert_eq!(std::fs::read_to_string(&p).unwrap(), params);
}

#[test]
fn other_results_fuzz_and_bad_outputs_are_refused_with_nothing_written() {
    refused(
        "model = \"ward\"\nrho_d = 0.3\nrho_s = 0.1\nalpha_x = 0.2\nalpha_y = 0.3\n",
        "m.py",
        "fibrefit fit DATA --model principled",
    );
    refused(
        &format!("{PARAMS}fuzz = 0.5\nfuzz_depth = 0.3\n"),
        "m.py",
        "has no fuzz layer",
    );
    refused(PARAMS, "m.txt", "expected a .py file name");
    refused(PARAMS, "INPUT", "r.toml");
    assert!(Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("python/tests/test_blender.py")
        .is_file());
}
