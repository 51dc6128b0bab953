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
    // the file is not reciprocal: f(l, v) and f(v, l) differ by ~0.1 in log (RMS) at its pairs
    let j: serde_json::Value = serde_json::from_str(&text).unwrap();
    let r = &j["reciprocity"];
    let all = r["rms_log_ratio_all"].as_f64().unwrap();
    assert!(
        r["pairs"].as_u64().unwrap() > 400 && all > 0.05 && all < 0.3,
        "{r}"
    );
    assert_eq!(r["least_log_error"].as_f64(), Some(all / 2.0));
    let o = fibrefit()
        .args(["inspect", "--directions", "500"])
        .arg(felt())
        .output()
        .unwrap();
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(text.contains("not reciprocal: no material"), "{text}");

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
    // MERL's half/difference layout is reciprocal by construction
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(
        text.contains("RMS of the log ratio") && text.contains("(reciprocal)"),
        "{text}"
    );
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

/// A CUReT folder as the database lays it out: `table.txt` (index theta_v phi_v theta_i phi_i,
/// radians) and `abrdf_subset.dat` (sample number, then a value per geometry); `values(k)` is
/// sample `number`'s value at geometry k.
fn curet_folder(dir: &std::path::Path, geometries: &[[f64; 4]], samples: &[(u32, Vec<f64>)]) {
    let mut t = String::new();
    for (k, g) in geometries.iter().enumerate() {
        t += &format!("{} {} {} {} {}\n", k + 1, g[0], g[1], g[2], g[3]);
    }
    fs::write(dir.join("table.txt"), t).unwrap();
    let mut v = String::new();
    for (n, values) in samples {
        v += &n.to_string();
        for x in values {
            v += &format!(" {x}");
        }
        v += "\n";
    }
    fs::write(dir.join("abrdf_subset.dat"), v).unwrap();
}

/// Geometries spread over the hemisphere (view and light up to 75 deg), deterministic.
fn geometries(n: usize) -> Vec<[f64; 4]> {
    (0..n)
        .map(|k| {
            let x = k as f64;
            [
                (0.15 + 0.55 * ((x * 0.618).fract())) * 1.9,
                (x * 2.39996) % std::f64::consts::TAU,
                (0.1 + 0.6 * ((x * 0.382 + 0.2).fract())) * 1.9,
                (x * 1.7 + 1.0) % std::f64::consts::TAU,
            ]
        })
        .collect()
}

#[test]
fn a_curet_folder_gives_each_sample_its_directions_and_skips_unmeasured_values() {
    use fibrefit::load::curet;
    let dir = tempfile::tempdir().unwrap();
    let g = [
        [0.3, 0.5, 0.7, 2.0],
        [1.0, 0.0, 0.2, 3.0],
        [0.4, 1.0, 0.9, 0.1],
    ];
    curet_folder(
        dir.path(),
        &g,
        &[(2, vec![0.1, 0.0, 0.3]), (42, vec![0.5, 0.6, 0.7])],
    );
    assert!(curet::is_curet_dir(dir.path()));
    let sets = curet::load_dir(dir.path()).unwrap();
    assert_eq!(sets.iter().map(|(n, _)| *n).collect::<Vec<_>>(), [2, 42]);
    let (_, s) = &sets[0];
    assert_eq!(s.channels, 1);
    assert_eq!(s.samples.len(), 2, "the 0 (unmeasured) is left out");
    assert_eq!(s.dropped.invalid, 1);
    // the table's theta_v phi_v are the view, theta_i phi_i the light
    let first = &s.samples[0];
    let dir_of = |t: f64, p: f64| [t.sin() * p.cos(), t.sin() * p.sin(), t.cos()];
    for (a, b) in first.v.iter().zip(dir_of(0.3, 0.5)) {
        assert!((a - b).abs() < 1e-12);
    }
    for (a, b) in first.l.iter().zip(dir_of(0.7, 2.0)) {
        assert!((a - b).abs() < 1e-12);
    }
    assert_eq!(first.value, [0.1; 3]);
    assert_eq!(sets[1].1.samples[2].value, [0.7; 3]);
    assert_eq!(curet::sample_name(42), Some("corduroy"));
}

#[test]
fn a_bad_curet_folder_is_refused_naming_file_and_line() {
    use fibrefit::load::curet;
    let dir = tempfile::tempdir().unwrap();
    let g = [[0.3, 0.5, 0.7, 2.0], [1.0, 0.0, 0.2, 3.0]];
    curet_folder(dir.path(), &g, &[(2, vec![0.1, 0.2]), (3, vec![0.1])]);
    let e = format!("{:#}", curet::load_dir(dir.path()).unwrap_err());
    assert!(
        e.contains("abrdf_subset.dat, line 2") && e.contains("1 values"),
        "{e}"
    );
    fs::write(
        dir.path().join("table.txt"),
        "1 0.3 0.5 0.7 2.0\n2 1.0 zero 0.2 3.0\n",
    )
    .unwrap();
    let e = format!("{:#}", curet::load_dir(dir.path()).unwrap_err());
    assert!(
        e.contains("table.txt, line 2") && e.contains("five numbers"),
        "{e}"
    );
    curet_folder(dir.path(), &g, &[(2, vec![0.1, f64::NAN])]);
    let e = format!("{:#}", curet::load_dir(dir.path()).unwrap_err());
    assert!(
        e.contains("line 1") && e.contains("'NaN' is not a BRDF value"),
        "{e}"
    );
    // a dark geometry's noise below 0 is left out, as the unmeasured 0 is
    curet_folder(dir.path(), &g, &[(2, vec![0.1, -0.009])]);
    let s = &curet::load_dir(dir.path()).unwrap()[0].1;
    assert_eq!((s.samples.len(), s.dropped.invalid), (1, 1));
}

#[test]
fn bench_real_judges_each_curet_sample_against_its_floor() {
    let dir = tempfile::tempdir().unwrap();
    let g = geometries(60);
    // a matte sample (lambert 0.5 / pi, 3 % noise) and a control with a forward lobe
    let noise = |k: usize| 1.0 + 0.03 * ((k as f64 * 12.9898).sin() * 43758.5453).fract();
    let matte: Vec<f64> = (0..g.len())
        .map(|k| 0.5 / std::f64::consts::PI * noise(k))
        .collect();
    let lobe: Vec<f64> = g
        .iter()
        .enumerate()
        .map(|(k, x)| (0.1 + (2.0 * (x[0].cos() * x[2].cos())).powi(4)) * noise(k + 7))
        .collect();
    curet_folder(dir.path(), &g, &[(2, matte), (4, lobe)]);
    let out = dir.path().join("reports");
    let o = fibrefit()
        .args(["bench", "real", "--quiet", "--curet"])
        .arg(dir.path())
        .arg("--out")
        .arg(&out)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let md = fs::read_to_string(out.join("real_fabrics.md")).unwrap();
    assert!(
        md.contains("Generated by `fibrefit bench real --curet"),
        "{md}"
    );
    assert!(md.contains("| CUReT 2 (polyester) | 60 |"), "{md}");
    assert!(md.contains("CUReT 4 (rough plastic) (control)"), "{md}");
    assert!(
        md.contains("## Issue 39's goals") && md.contains("median"),
        "{md}"
    );
    let csv = fs::read_to_string(out.join("real_fabrics.csv")).unwrap();
    let chosen: Vec<&str> = csv
        .lines()
        .filter(|l| l.split(',').nth(12) == Some("true"))
        .collect();
    // one chosen candidate per sample, with a finite floor; lambert is within the matte's noise
    assert_eq!(chosen.len(), 2, "{csv}");
    let matte = chosen.iter().find(|l| l.starts_with("CUReT 2")).unwrap();
    let f: Vec<&str> = matte.split(',').collect();
    let (error, floor): (f64, f64) = (f[8].parse().unwrap(), f[10].parse().unwrap());
    assert!(floor.is_finite() && floor > 0.0, "{matte}");
    assert!(
        error < 0.05,
        "the matte sample's chosen model is off its 3 % noise: {matte}"
    );

    // nothing to run
    let o = fibrefit()
        .args(["bench", "real", "--out"])
        .arg(&out)
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&o.stderr).contains("give at least one FILE or --curet DIR"));
}
