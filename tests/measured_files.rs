//! Issue 11 (first part): RGL measured-BRDF files go through `inspect`, `fit` and `score` like
//! any dataset (the loader's values are checked against the shared check values in its unit
//! test).

use assert_cmd::Command;
use std::fs;
use std::path::PathBuf;

fn felt() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/data/rgl/acrylic_felt_green_rgb.bsdf")
}

fn fibrefit() -> Command {
    Command::cargo_bin("fibrefit").unwrap()
}

#[test]
fn the_felt_is_inspected_fitted_and_scored() {
    let o = fibrefit()
        .args(["inspect", "--json", "--directions", "500"])
        .arg(felt())
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(text.contains("500") && text.contains("measured"), "{text}");

    let dir = tempfile::tempdir().unwrap();
    let cfg = dir.path().join("lambert.toml");
    fs::write(&cfg, "model = \"lambert\"\n").unwrap();
    let out = dir.path().join("felt.json");
    let rep = dir.path().join("report");
    let o = fibrefit()
        .arg("fit")
        .arg(felt())
        .arg("--config")
        .arg(&cfg)
        .arg("--out")
        .arg(&out)
        .arg("--report")
        .arg(&rep)
        .args(["--quiet", "--directions", "800", "--max-theta", "70"])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    // the report draws the file itself along the slices and densely on the hemisphere maps
    let md = fs::read_to_string(rep.join("report.md")).unwrap();
    for needle in [
        "dashed: the measured file on the same directions",
        "Measured: the file evaluated densely",
    ] {
        assert!(md.contains(needle), "report lacks {needle}");
    }
    assert!(rep.join("slices.png").exists() && rep.join("hemispheres.png").exists());
    let r: serde_json::Value = serde_json::from_str(&fs::read_to_string(&out).unwrap()).unwrap();
    assert_eq!(r["data"]["kind"], "measured BRDF file");
    assert_eq!(r["data"]["samples"], 800);
    // held-out directions (another seed) scored with the fit
    let o = fibrefit()
        .arg("score")
        .arg(&out)
        .arg(felt())
        .args(["--json", "--directions", "400", "--direction-seed", "7"])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let s: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(s["samples"], 400);
    let rel = s["statistics"]["relative_rmse"].as_f64().unwrap();
    assert!(rel > 0.1 && rel < 2.0, "lambert on felt: {rel}");
}

#[test]
fn a_merl_table_is_inspected_and_fitted() {
    // a small isotropic table in the MERL layout: grey 0.2 / pi-ish everywhere (f = value / 1500
    // per channel scale), dimensions 9 x 9 x 18
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("grey.binary");
    let dims = [9i32, 9, 18];
    let n = (9 * 9 * 18) as usize;
    let mut bytes = Vec::new();
    for d in dims {
        bytes.extend_from_slice(&d.to_le_bytes());
    }
    for (c, scale) in [1.0, 1.15, 1.66].iter().enumerate() {
        for _ in 0..n {
            let f = 0.1 + 0.02 * c as f64;
            bytes.extend_from_slice(&(f * 1500.0 / scale).to_le_bytes());
        }
    }
    fs::write(&path, bytes).unwrap();
    let o = fibrefit()
        .args(["inspect", "--directions", "300"])
        .arg(&path)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let out = dir.path().join("fit.json");
    let o = fibrefit()
        .arg("fit")
        .arg(&path)
        .args([
            "--model",
            "lambert",
            "--quiet",
            "--directions",
            "300",
            "--out",
        ])
        .arg(&out)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let r: serde_json::Value = serde_json::from_str(&fs::read_to_string(&out).unwrap()).unwrap();
    let kd = r["parameters"]["kd"]["value"].as_array().unwrap();
    for (c, k) in kd.iter().enumerate() {
        let want = (0.1 + 0.02 * c as f64) * std::f64::consts::PI;
        assert!(
            (k.as_f64().unwrap() - want).abs() < 1e-9,
            "kd[{c}] = {k}, want {want}"
        );
    }
}
