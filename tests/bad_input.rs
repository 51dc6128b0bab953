//! The bad-input corpus: every file in tests/bad_input/ (one case each) is fed to
//! `fibrefit inspect`. Its first line `# expect: TEXT` names the problem; the run must exit with
//! code 2, print an error containing TEXT, print nothing on stdout, and write nothing.

use assert_cmd::Command;
use std::collections::BTreeSet;
use std::fs;
use std::path::{Path, PathBuf};

fn listing(dir: &Path) -> BTreeSet<PathBuf> {
    let mut out = BTreeSet::new();
    for e in fs::read_dir(dir).unwrap().flatten() {
        let p = e.path();
        if p.is_dir() {
            out.extend(listing(&p));
        } else {
            out.insert(p);
        }
    }
    out
}

#[test]
fn every_bad_input_case_fails_cleanly() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/bad_input");
    let before = listing(&dir);
    let mut cases = 0;
    for path in &before {
        if path.parent().is_some_and(|p| p.ends_with("assets")) {
            continue;
        }
        let first = fs::read_to_string(path)
            .unwrap()
            .lines()
            .next()
            .unwrap_or("")
            .to_string();
        let expect = first
            .strip_prefix("# expect: ")
            .unwrap_or_else(|| panic!("{}: first line must be '# expect: ...'", path.display()));
        let out = Command::cargo_bin("fibrefit")
            .unwrap()
            .arg("inspect")
            .arg(path)
            .output()
            .unwrap();
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(
            out.status.code(),
            Some(2),
            "{}: exit code; stderr: {stderr}",
            path.display()
        );
        assert!(
            stderr.contains(expect),
            "{}: expected '{expect}' in: {stderr}",
            path.display()
        );
        assert!(
            stderr.starts_with("error: "),
            "{}: {stderr}",
            path.display()
        );
        assert!(!stderr.contains("panicked"), "{}: {stderr}", path.display());
        assert!(out.stdout.is_empty(), "{}: wrote to stdout", path.display());
        cases += 1;
    }
    assert!(cases >= 25, "corpus shrank to {cases} cases");
    assert_eq!(listing(&dir), before, "a failed run wrote files");
}

#[test]
fn skipping_bad_rows_reports_the_count() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("g.csv");
    fs::write(&p, "theta_i,phi_i,theta_o,phi_o,brdf\n10,0,20,0,0.1\n10,0,95,0,0.1\n10,x,20,0,0.1\n30,0,20,0,0.2\n").unwrap();
    let out = Command::cargo_bin("fibrefit")
        .unwrap()
        .args(["inspect", "--skip-bad-rows"])
        .arg(&p)
        .output()
        .unwrap();
    assert!(out.status.success());
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(text.contains("samples          2"), "{text}");
    assert!(text.contains("skipped rows 2"), "{text}");
    assert!(text.contains("g.csv:3"), "{text}");
}

#[test]
fn inspect_json_and_subsampling_of_shipped_captures() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let cap = root.join("data_synthetic/silk/capture.toml");
    let out = Command::cargo_bin("fibrefit")
        .unwrap()
        .args(["inspect", "--json", "--stride", "2"])
        .arg(&cap)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let kept = v["samples"].as_u64().unwrap();
    let subsampled = v["dropped"]["subsampled"].as_u64().unwrap();
    assert_eq!(kept + subsampled, 6 * 64 * 64);
    assert_eq!(kept, 6 * 32 * 32);
    assert_eq!(v["channels"], 3);
    assert_eq!(v["has_topology_map"], true);
    let out = Command::cargo_bin("fibrefit")
        .unwrap()
        .args([
            "inspect",
            "--json",
            "--fraction",
            "0.1",
            "--subsample-seed",
            "3",
        ])
        .arg(&cap)
        .output()
        .unwrap();
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let frac = v["samples"].as_f64().unwrap() / (6.0 * 64.0 * 64.0);
    assert!((frac - 0.1).abs() < 0.01, "{frac}");
}
