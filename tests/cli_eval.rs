//! `fibrefit eval` end to end: shipped files, every rung, bad input (exit code 2, message naming
//! the problem, no output file written or clobbered).

use assert_cmd::Command;
use std::fs;
use std::path::{Path, PathBuf};

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

fn fibrefit() -> Command {
    Command::cargo_bin("fibrefit").expect("binary built")
}

fn write(dir: &Path, name: &str, text: &str) -> PathBuf {
    let p = dir.join(name);
    fs::write(&p, text).unwrap();
    p
}

const QUERIES: &str =
    "theta_i,phi_i,theta_o,phi_o\n0,0,0,0\n30,90,30,90\n45,10,60,200\n89.9,0,10,0\n";

fn run_ok(args: &[&str]) -> String {
    let out = fibrefit().args(args).output().unwrap();
    assert!(
        out.status.success(),
        "stderr: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8(out.stdout).unwrap()
}

fn run_err(args: &[&str]) -> String {
    let out = fibrefit().args(args).output().unwrap();
    assert_eq!(
        out.status.code(),
        Some(2),
        "stdout: {}",
        String::from_utf8_lossy(&out.stdout)
    );
    String::from_utf8(out.stderr).unwrap()
}

#[test]
fn shipped_params_evaluate_on_shipped_queries() {
    let params = root().join("configs/silk_params.toml");
    let queries = root().join("data_synthetic/queries_slices.csv");
    let text = run_ok(&[
        "eval",
        "--params",
        params.to_str().unwrap(),
        "--queries",
        queries.to_str().unwrap(),
    ]);
    let mut lines = text.lines();
    assert_eq!(
        lines.next().unwrap(),
        "theta_i,phi_i,theta_o,phi_o,brdf_r,brdf_g,brdf_b,intensity_r,intensity_g,intensity_b"
    );
    let n_queries = fs::read_to_string(&queries).unwrap().lines().count() - 1;
    assert_eq!(lines.count(), n_queries);
}

#[test]
fn every_rung_evaluates_from_the_cli_and_gives_known_values() {
    let dir = tempfile::tempdir().unwrap();
    let q = write(dir.path(), "q.csv", QUERIES);
    let p = write(
        dir.path(),
        "p.toml",
        "kd = 1.0\nsubstrate_albedo = 1.0\nks = 0.0\nexponent = 10\nspacing = 2\nalpha_x = 0.2\nalpha_y = 0.5\nrho_s = 0.3\n",
    );
    for id in [
        "lambert",
        "max-normal",
        "hast-diffuse",
        "poulin-fournier",
        "varying-topology",
        "reference",
        "ward",
    ] {
        let text = run_ok(&[
            "eval",
            "-q",
            "--model",
            id,
            "--params",
            p.to_str().unwrap(),
            "--queries",
            q.to_str().unwrap(),
        ]);
        let rows: Vec<Vec<f64>> = text
            .lines()
            .skip(1)
            .map(|l| l.split(',').map(|x| x.parse().unwrap()).collect())
            .collect();
        assert_eq!(rows.len(), 4, "{id}");
        for r in &rows {
            assert!(
                r[4].is_finite() && r[4] >= 0.0 && r[5] >= 0.0,
                "{id}: {r:?}"
            );
            // intensity = brdf * cos(theta_i)
            assert!(
                (r[5] - r[4] * r[0].to_radians().cos()).abs() <= 1e-12 * r[4].max(1.0),
                "{id}: {r:?}"
            );
        }
        if matches!(id, "poulin-fournier" | "varying-topology" | "reference") {
            assert!(
                (rows[0][4] - 0.25).abs() < 1e-12,
                "{id}: l = v = N gives 0.25, got {}",
                rows[0][4]
            );
            assert!((rows[1][4] - 0.3067).abs() < 1e-4, "{id}: {}", rows[1][4]);
        }
        if id == "lambert" {
            assert!((rows[0][4] - 1.0 / std::f64::consts::PI).abs() < 1e-15);
        }
    }
}

#[test]
fn json_params_with_model_id_and_height_column() {
    let dir = tempfile::tempdir().unwrap();
    let q = write(
        dir.path(),
        "q.csv",
        "theta_i,phi_i,theta_o,phi_o,height\n30,90,30,90,0\n30,90,30,90,1.0\n",
    );
    let p = write(
        dir.path(),
        "p.json",
        r#"{"model": "varying-topology", "kd": 1.0, "spacing": 2.0, "height": 1.7, "map_scale": 0.25}"#,
    );
    let text = run_ok(&[
        "eval",
        "--params",
        p.to_str().unwrap(),
        "--queries",
        q.to_str().unwrap(),
    ]);
    let rows: Vec<Vec<f64>> = text
        .lines()
        .skip(1)
        .map(|l| l.split(',').map(|x| x.parse().unwrap()).collect())
        .collect();
    // height 0 is the flat layer: the known value regardless of the file's height
    assert!((rows[0][5] - 0.3067).abs() < 1e-4, "{rows:?}");
    assert!((rows[1][5] - rows[0][5]).abs() > 1e-3);
}

#[test]
fn rgb_parameters_give_rgb_columns_to_a_file() {
    let dir = tempfile::tempdir().unwrap();
    let q = write(dir.path(), "q.csv", QUERIES);
    let p = write(dir.path(), "p.toml", "kd = [0.2, 0.4, 0.6]\n");
    let out = dir.path().join("out.csv");
    run_ok(&[
        "eval",
        "--model",
        "lambert",
        "--params",
        p.to_str().unwrap(),
        "--queries",
        q.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    let text = fs::read_to_string(&out).unwrap();
    assert!(text.starts_with(
        "theta_i,phi_i,theta_o,phi_o,brdf_r,brdf_g,brdf_b,intensity_r,intensity_g,intensity_b\n"
    ));
    let r: Vec<f64> = text
        .lines()
        .nth(1)
        .unwrap()
        .split(',')
        .map(|x| x.parse().unwrap())
        .collect();
    assert!((r[6] / r[4] - 3.0).abs() < 1e-12);
    // no temporary files left behind
    assert_eq!(fs::read_dir(dir.path()).unwrap().count(), 3);
}

#[test]
fn bad_input_exits_2_names_the_problem_and_writes_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let good_q = write(dir.path(), "q.csv", QUERIES);
    let good_p = write(dir.path(), "p.toml", "kd = 0.5\n");
    let out = dir.path().join("out.csv");
    fs::write(&out, "previous result\n").unwrap();
    let cases: Vec<(Vec<String>, &str)> = vec![
        (
            vec!["--model".into(), "phong".into()],
            "unknown model id 'phong'",
        ),
        (
            vec![
                "--params".into(),
                write(dir.path(), "u.toml", "kd = 0.5\nspacng = 3\n")
                    .display()
                    .to_string(),
            ],
            "spacng",
        ),
        (
            vec![
                "--params".into(),
                write(dir.path(), "r.toml", "kd = 0.5\nspacing = 1\n")
                    .display()
                    .to_string(),
            ],
            "`spacing` = 1 is out of range",
        ),
        (
            vec![
                "--params".into(),
                write(dir.path(), "e.toml", "kd = 0.5\nexponent = 2e4\n")
                    .display()
                    .to_string(),
            ],
            "`exponent`",
        ),
        (
            vec![
                "--params".into(),
                write(dir.path(), "n.toml", "kd = nan\n")
                    .display()
                    .to_string(),
            ],
            "`kd` is NaN",
        ),
        (
            vec![
                "--params".into(),
                write(dir.path(), "h.toml", "kd = 0.5\nheight = 2\n")
                    .display()
                    .to_string(),
            ],
            "`height` = 2 is out of range",
        ),
        (
            vec![
                "--model".into(),
                "varying-topology".into(),
                "--params".into(),
                write(
                    dir.path(),
                    "m.toml",
                    "kd = 0.5\ntopology_map = \"missing.png\"\n",
                )
                .display()
                .to_string(),
            ],
            "missing.png",
        ),
        (
            vec![
                "--queries".into(),
                write(
                    dir.path(),
                    "bad.csv",
                    "theta_i,phi_i,theta_o,phi_o\n10,0,10,0\n10,0,abc,0\n",
                )
                .display()
                .to_string(),
            ],
            "bad.csv:3: column `theta_o`: 'abc' is not a number",
        ),
        (
            vec![
                "--queries".into(),
                write(
                    dir.path(),
                    "col.csv",
                    "theta_i,phi_i,theta_out,phi_o\n10,0,10,0\n",
                )
                .display()
                .to_string(),
            ],
            "unknown column `theta_out`",
        ),
        (
            vec![
                "--queries".into(),
                write(
                    dir.path(),
                    "hq.csv",
                    "theta_i,phi_i,theta_o,phi_o,height\n10,0,10,0,0.5\n",
                )
                .display()
                .to_string(),
            ],
            "needs a model with a topology",
        ),
        (
            vec![
                "--model".into(),
                "varying-topology".into(),
                "--queries".into(),
                write(
                    dir.path(),
                    "hmax.csv",
                    "theta_i,phi_i,theta_o,phi_o,height\n10,0,10,0,0.5\n10,0,10,0,5\n",
                )
                .display()
                .to_string(),
            ],
            "hmax.csv:3: column `height` = 5 exceeds H_max",
        ),
        (
            vec![
                "--queries".into(),
                dir.path().join("nope.csv").display().to_string(),
            ],
            "nope.csv: cannot open",
        ),
    ];
    for (override_args, needle) in cases {
        let mut args: Vec<String> = vec!["eval".into()];
        if !override_args.contains(&"--model".to_string()) {
            args.extend(["--model".into(), "poulin-fournier".into()]);
        }
        if !override_args.contains(&"--params".to_string()) {
            args.extend(["--params".into(), good_p.display().to_string()]);
        }
        if !override_args.contains(&"--queries".to_string()) {
            args.extend(["--queries".into(), good_q.display().to_string()]);
        }
        args.extend(override_args);
        args.extend(["--out".into(), out.display().to_string()]);
        let argv: Vec<&str> = args.iter().map(String::as_str).collect();
        let err = run_err(&argv);
        assert!(err.contains(needle), "expected '{needle}' in: {err}");
        assert_eq!(
            fs::read_to_string(&out).unwrap(),
            "previous result\n",
            "output clobbered for {needle}"
        );
    }
    let leftovers: Vec<_> = fs::read_dir(dir.path())
        .unwrap()
        .filter_map(|e| e.ok())
        .filter(|e| e.file_name().to_string_lossy().ends_with(".tmp"))
        .collect();
    assert!(leftovers.is_empty());
}

#[test]
fn help_states_units_and_defaults() {
    let text = run_ok(&["eval", "--help"]);
    for needle in ["degrees", "1/sr", "(default 16)", "fibre radii", "--out"] {
        assert!(text.contains(needle), "help lacks '{needle}'");
    }
    let out = fibrefit()
        .args(["eval", "--no-such-flag"])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
}

#[test]
fn lambert_preview_variants_of_seed_003() {
    let dir = tempfile::tempdir().unwrap();
    // light from below (theta_i 120) and from above (theta_i 60)
    let q = write(
        dir.path(),
        "q.csv",
        "theta_i,phi_i,theta_o,phi_o\n120,0,0,0\n60,0,0,0\n",
    );
    let run = |params: &str| -> Vec<Vec<f64>> {
        let p = write(dir.path(), "p.toml", params);
        let text = run_ok(&[
            "eval",
            "-q",
            "--model",
            "lambert",
            "--params",
            p.to_str().unwrap(),
            "--queries",
            q.to_str().unwrap(),
        ]);
        text.lines()
            .skip(1)
            .map(|l| l.split(',').map(|x| x.parse().unwrap()).collect())
            .collect()
    };
    let pi = std::f64::consts::PI;
    let one = run("kd = 0.8\n");
    assert_eq!(one[0][5], 0.0); // one-sided: dark from below
    let two = run("kd = 0.8\ntwo_sided = true\n");
    assert!((two[0][5] - 0.8 * 0.5 / pi).abs() < 1e-12); // |n.l| = 0.5
    let amb = run("kd = 0.8\nambient = 0.1\n");
    assert!((amb[0][5] - 0.8 * 0.1 / pi).abs() < 1e-12);
    assert!((amb[1][5] - 0.8 * (0.1 + 0.5) / pi).abs() < 1e-12);
}
