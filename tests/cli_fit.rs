//! `fibrefit fit` end to end: the README's main job, the result JSON, `eval --params result.json`,
//! and bad configs (exit 2, the key named, an existing output untouched).

use assert_cmd::Command;
use sha2::{Digest, Sha256};
use std::fs;
use std::path::{Path, PathBuf};

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

fn fibrefit() -> Command {
    Command::cargo_bin("fibrefit").unwrap()
}

#[test]
fn main_job_writes_a_complete_result_that_eval_reproduces() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("silk_fit.json");
    let report = dir.path().join("report");
    let data = root().join("data_synthetic/silk/gonio.csv");
    let o = fibrefit()
        .arg("fit")
        .arg(&data)
        .arg("--config")
        .arg(root().join("configs/fit_silk.toml"))
        .arg("--out")
        .arg(&out)
        .arg("--report")
        .arg(&report)
        .arg("--json")
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let line: serde_json::Value = serde_json::from_slice(&o.stdout).expect("one JSON line");
    assert_eq!(line["model"], "varying-topology");
    assert!(line["relative_rmse"].as_f64().unwrap() < 0.02);
    // the verdict, and with sigmas the reduced chi-square (not the residual variance)
    assert_eq!(line["verdict"], "fits within the noise", "{line}");
    assert!(line["reduced_chi_square"].as_f64().is_some(), "{line}");
    assert!(line.get("residual_variance").is_none(), "{line}");
    assert!(report.join("report.md").exists());

    let r: serde_json::Value = serde_json::from_str(&fs::read_to_string(&out).unwrap()).unwrap();
    assert_eq!(r["schema"], "fibrefit-result/1");
    assert_eq!(r["model"], "varying-topology");
    for key in [
        "conventions",
        "parameters",
        "correlations",
        "statistics",
        "knobs",
        "data",
        "check_values",
        "renderer_materials",
        "tool",
    ] {
        assert!(r.get(key).is_some(), "missing {key}");
    }
    let sha: String = Sha256::digest(fs::read(&data).unwrap())
        .iter()
        .map(|b| format!("{b:02x}"))
        .collect();
    assert_eq!(r["data"]["sha256"], sha);
    assert_eq!(r["data"]["file"], "gonio.csv");
    let h = &r["parameters"]["height"];
    assert!(
        (h["value"].as_f64().unwrap() - 0.9).abs() < 0.01 && h["std_error"].as_f64().unwrap() > 0.0
    );
    assert_eq!(r["parameters"]["spacing"]["fixed"], true);
    assert!(r["parameters"]["kd"]["value"].as_array().unwrap().len() == 3);
    let checks = r["check_values"].as_array().unwrap();
    assert_eq!(checks.len(), 20);
    // the renderers' own materials, fitted to the same data: each a result of its own
    let materials = r["renderer_materials"].as_array().unwrap();
    let names: Vec<&str> = materials
        .iter()
        .map(|m| m["model"].as_str().unwrap())
        .collect();
    assert_eq!(names, ["gltf", "principled", "openpbr"]);
    for m in materials {
        assert_eq!(m["schema"], "fibrefit-result/1");
        assert!(m["statistics"]["relative_rmse"]
            .as_f64()
            .unwrap()
            .is_finite());
        assert!(m["parameters"]["kd"]["value"].is_array());
        assert_eq!(m["data"]["sha256"], sha);
    }

    // eval with the result file (model id taken from it) reproduces the check values
    let mut q = String::from("theta_i,phi_i,theta_o,phi_o\n");
    for c in checks {
        q += &format!(
            "{},{},{},{}\n",
            c["theta_i"], c["phi_i"], c["theta_o"], c["phi_o"]
        );
    }
    let qp = dir.path().join("q.csv");
    fs::write(&qp, q).unwrap();
    let o = fibrefit()
        .arg("eval")
        .arg("--params")
        .arg(&out)
        .arg("--queries")
        .arg(&qp)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let text = String::from_utf8(o.stdout).unwrap();
    for (line, c) in text.lines().skip(1).zip(checks) {
        let v: Vec<f64> = line.split(',').map(|x| x.parse().unwrap()).collect();
        for ch in 0..3 {
            let want = c["brdf"][ch].as_f64().unwrap();
            assert!(
                (v[4 + ch] - want).abs() <= 1e-12 * want.abs().max(1e-12),
                "{line} vs {c}"
            );
        }
    }
}

fn write(dir: &Path, name: &str, text: &str) -> PathBuf {
    let p = dir.join(name);
    fs::write(&p, text).unwrap();
    p
}

#[test]
fn bad_configs_exit_2_name_the_key_and_leave_the_output_alone() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("result.json");
    fs::write(&out, "previous\n").unwrap();
    let data = root().join("data_synthetic/loose/gonio.csv");
    let cases = [
        ("model = \"poulin-fournier\"\nstartz = 2\n", "startz"),
        ("model = \"poulin-fournier\"\n[parameters]\nspacing = { value = 3, min = 5, max = 4 }\n", "parameters.spacing: min = 5 is greater than max = 4"),
        ("model = \"poulin-fournier\"\n[parameters]\nexponent = { value = 5000, max = 100 }\n", "parameters.exponent.value = 5000 is outside its bounds"),
        ("model = \"poulin-fournier\"\n[parameters]\nheight = { value = 0.5 }\n", "parameters.height: not a parameter of `poulin-fournier`"),
        ("model = \"poulin-fournier\"\n[parameters]\nspacing = { value = 3, vary = true, mni = 2 }\n", "mni"),
        ("model = \"phong\"\n", "unknown model id 'phong'"),
        ("model = \"poulin-fournier\"\n[parameters]\nspacing = { value = 3, max = 30 }\n", "exceed the model's range"),
        ("model = \"poulin-fournier\"\n[knobs]\nhistogram_bins = 0\n", "knobs.histogram_bins"),
        ("model = \"auto\"\n[parameters]\nheigth = { value = 0.5 }\n", "parameters.heigth: not a parameter of any rung"),
        ("model = \"auto\"\n[parameters]\nexponent = { value = 5, min = 10 }\n", "parameters.exponent.value = 5 is outside its bounds"),
        // issue 12: the azimuth's range is [-90, 90] (period 180), wider bounds are an error
        ("model = \"poulin-fournier\"\n[parameters]\nfibre_azimuth_deg = { value = 0, min = -180, max = 180 }\n", "parameters.fibre_azimuth_deg: bounds [-180, 180] exceed the model's range [-90, 90]"),
        ("model = \"poulin-fournier\"\n[knobs]\nquadrature_order = 2000\n", "knobs.quadrature_order = 2000 must lie in [1, 1024]"),
    ];
    for (k, (text, needle)) in cases.iter().enumerate() {
        let cfg = write(dir.path(), &format!("c{k}.toml"), text);
        let o = fibrefit()
            .arg("fit")
            .arg(&data)
            .arg("--config")
            .arg(&cfg)
            .arg("--out")
            .arg(&out)
            .arg("-q")
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{text}: {err}");
        assert!(err.contains(needle), "expected '{needle}' in {err}");
        assert_eq!(fs::read_to_string(&out).unwrap(), "previous\n");
    }
    // bad data: same
    let bad = write(
        dir.path(),
        "bad.csv",
        "theta_i,phi_i,theta_o,phi_o,brdf\n10,0,95,0,0.1\n",
    );
    let cfg = write(dir.path(), "ok.toml", "model = \"lambert\"\n");
    let o = fibrefit()
        .arg("fit")
        .arg(&bad)
        .arg("--config")
        .arg(&cfg)
        .arg("--out")
        .arg(&out)
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&o.stderr).contains("bad.csv:2"));
    assert_eq!(fs::read_to_string(&out).unwrap(), "previous\n");
    let tmp: Vec<_> = fs::read_dir(dir.path())
        .unwrap()
        .flatten()
        .filter(|e| e.file_name().to_string_lossy().ends_with(".tmp"))
        .collect();
    assert!(tmp.is_empty());
}
