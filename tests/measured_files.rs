//! Issue 11 (first part): RGL measured-BRDF files go through `inspect`, `fit` and `score` like
//! any dataset (the loader's values are checked against the shared check values in its unit
//! test).

use assert_cmd::Command;
use std::fs;
use std::path::PathBuf;

fn felt() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../shared/data/rgl/acrylic_felt_green_rgb.bsdf")
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
    let o = fibrefit()
        .arg("fit")
        .arg(felt())
        .arg("--config")
        .arg(&cfg)
        .arg("--out")
        .arg(&out)
        .args(["--quiet", "--directions", "800", "--max-theta", "70"])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
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
