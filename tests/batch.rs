//! Many swatches: `fibrefit fit A B C --out-dir DIR` fits each input into DIR/NAME/ with its
//! report, keeps a summary row per input in DIR/summary.csv (also when several runs share the
//! folder, as job arrays and GNU parallel do), goes on past a failed input and exits 2 at the
//! end; `--threads`; inputs refused before any work.

use assert_cmd::Command;
use std::fs;
use std::path::{Path, PathBuf};

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

fn fibrefit() -> Command {
    Command::cargo_bin("fibrefit").unwrap()
}

/// The first `rows` rows of a shipped synthetic table, as `dir/name.csv`.
fn table(dir: &Path, name: &str, from: &str, rows: usize) -> PathBuf {
    let text = fs::read_to_string(root().join(from)).unwrap();
    let cut: Vec<&str> = text.lines().take(rows + 1).collect();
    let path = dir.join(format!("{name}.csv"));
    fs::write(&path, cut.join("\n") + "\n").unwrap();
    path
}

/// An auto config over two cheap rungs (the batch machinery, not the rungs, is under test).
fn auto_config(dir: &Path) -> PathBuf {
    let p = dir.join("auto.toml");
    fs::write(
        &p,
        "model = \"auto\"\n[selection]\nrungs = [\"lambert\", \"ward\"]\nfuzz = false\n",
    )
    .unwrap();
    p
}

fn summary(dir: &Path) -> Vec<csv::StringRecord> {
    let mut rd = csv::Reader::from_path(dir.join("summary.csv")).unwrap();
    let header = rd.headers().unwrap().clone();
    assert_eq!(
        header.iter().collect::<Vec<_>>(),
        [
            "name",
            "input",
            "status",
            "model",
            "verdict",
            "heldout_error",
            "heldout_metric",
            "heldout_relative_rmse",
            "floor",
            "floor_ratio",
            "rmse",
            "relative_rmse",
            "samples",
            "seconds",
            "result",
            "report",
            "warnings",
            "error"
        ]
    );
    rd.records().map(|r| r.unwrap()).collect()
}

#[test]
fn each_input_gets_its_folder_and_a_summary_row_and_a_failure_stops_nothing() {
    let tmp = tempfile::tempdir().unwrap();
    let silk = table(tmp.path(), "silk", "data_synthetic/silk/gonio.csv", 300);
    let loose = table(tmp.path(), "loose", "data_synthetic/loose/gonio.csv", 300);
    let broken = tmp.path().join("broken.csv");
    fs::write(&broken, "theta_i,phi_i,theta_o,phi_o,brdf\n10,0,20\n").unwrap();
    let out = tmp.path().join("fits");
    let o = fibrefit()
        .arg("fit")
        .args([&silk, &broken, &loose])
        .arg("--config")
        .arg(auto_config(tmp.path()))
        .arg("--out-dir")
        .arg(&out)
        .arg("--json")
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{stderr}");
    assert!(
        stderr.contains("1 of 3 inputs failed") && stderr.contains("broken.csv"),
        "{stderr}"
    );
    assert!(
        stderr.contains("[2/3]") && stderr.contains("FAILED"),
        "{stderr}"
    );
    // one JSON line per input on stdout, as the summary rows
    let lines: Vec<serde_json::Value> = String::from_utf8_lossy(&o.stdout)
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    assert_eq!(lines.len(), 3);
    assert_eq!(lines[1]["status"], "failed");
    let rows = summary(&out);
    assert_eq!(rows.len(), 3);
    // sorted by name: broken, loose, silk
    assert_eq!(&rows[0][0], "broken");
    assert_eq!(&rows[0][2], "failed");
    assert!(
        rows[0][17].contains("broken.csv:2: malformed row"),
        "{:?}",
        rows[0]
    );
    assert!(
        !out.join("broken").exists(),
        "a failed input writes nothing"
    );
    for (row, name) in rows[1..].iter().zip(["loose", "silk"]) {
        assert_eq!(&row[0], name);
        assert_eq!(&row[2], "ok", "{row:?}");
        assert!(["lambert", "ward"].contains(&&row[3]), "{row:?}");
        assert!(!row[4].is_empty(), "a verdict: {row:?}");
        let heldout: f64 = row[5].parse().unwrap();
        assert!(heldout.is_finite() && heldout > 0.0, "{row:?}");
        assert_eq!(&row[6], "linear");
        // the floor: what the data allow on the same held-out samples
        let (floor, ratio): (f64, f64) = (row[8].parse().unwrap(), row[9].parse().unwrap());
        assert!(
            floor > 0.0 && (ratio - heldout / floor).abs() < 1e-6 * ratio,
            "{row:?}"
        );
        assert_eq!(row[12].parse::<usize>().unwrap(), 300);
        assert!(row[13].parse::<f64>().unwrap() > 0.0);
        // the result and report named relative to the folder, and there
        let result: serde_json::Value =
            serde_json::from_slice(&fs::read(out.join(&row[14])).unwrap()).unwrap();
        assert_eq!(result["model"], row[3].to_string());
        assert!(out.join(&row[15]).is_file());
        assert!(out.join(name).join("slices.png").is_file());
    }
}

#[test]
fn runs_sharing_a_folder_keep_every_row_and_skip_done_leaves_finished_inputs() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("fits");
    let inputs: Vec<PathBuf> = (0..4)
        .map(|k| {
            table(
                tmp.path(),
                &format!("s{k}"),
                "data_synthetic/silk/gonio.csv",
                120 + k,
            )
        })
        .collect();
    // four processes at once into one folder, as `parallel -j4 fibrefit fit {} --out-dir` does
    let children: Vec<std::process::Child> = inputs
        .iter()
        .map(|p| {
            std::process::Command::new(env!("CARGO_BIN_EXE_fibrefit"))
                .arg("fit")
                .arg(p)
                .args(["--model", "lambert", "--threads", "1", "-q", "--out-dir"])
                .arg(&out)
                .spawn()
                .unwrap()
        })
        .collect();
    for mut c in children {
        assert!(c.wait().unwrap().success());
    }
    let rows = summary(&out);
    assert_eq!(
        rows.iter().map(|r| r[0].to_string()).collect::<Vec<_>>(),
        ["s0", "s1", "s2", "s3"]
    );
    // a named rung's held-out error too (the same folds as auto's), and its floor
    assert!(rows.iter().all(|r| &r[2] == "ok" && &r[3] == "lambert"));
    assert!(rows
        .iter()
        .all(|r| r[5].parse::<f64>().is_ok() && r[8].parse::<f64>().is_ok()));
    let before = fs::read(out.join("s1/result.json")).unwrap();
    fs::remove_dir_all(out.join("s2")).unwrap();
    let o = fibrefit()
        .arg("fit")
        .args(&inputs)
        .args(["--model", "lambert", "--skip-done", "--out-dir"])
        .arg(&out)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{stderr}");
    assert_eq!(stderr.matches("skipped").count(), 3, "{stderr}");
    assert!(
        out.join("s2/result.json").is_file(),
        "the missing one is fitted again"
    );
    assert_eq!(fs::read(out.join("s1/result.json")).unwrap(), before);
    assert_eq!(summary(&out).len(), 4);
}

#[test]
fn a_batch_is_refused_before_any_work() {
    let tmp = tempfile::tempdir().unwrap();
    let a = tmp.path().join("a");
    let b = tmp.path().join("b");
    fs::create_dir_all(&a).unwrap();
    fs::create_dir_all(&b).unwrap();
    let one = table(&a, "felt", "data_synthetic/silk/gonio.csv", 50);
    let two = table(&b, "felt", "data_synthetic/silk/gonio.csv", 60);
    let out = tmp.path().join("fits");
    let cases: Vec<(Vec<std::ffi::OsString>, &str)> = vec![
        (
            vec![
                one.clone().into(),
                two.clone().into(),
                "--out-dir".into(),
                out.clone().into(),
            ],
            "would both be written into",
        ),
        (
            vec![
                one.clone().into(),
                tmp.path().join("missing.csv").into(),
                "--out-dir".into(),
                out.clone().into(),
            ],
            "missing.csv: cannot read",
        ),
        (
            vec![one.clone().into(), two.clone().into()],
            "2 data files: give --out-dir DIR",
        ),
        (
            vec![one.clone().into(), "--threads".into(), "0".into()],
            "--threads 0",
        ),
    ];
    for (args, expected) in cases {
        let o = fibrefit()
            .arg("fit")
            .args(&args)
            .args(["--model", "lambert"])
            .output()
            .unwrap();
        let stderr = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{args:?}: {stderr}");
        assert!(stderr.contains(expected), "{args:?}: {stderr}");
        assert!(!out.exists(), "{args:?}: nothing written");
    }
    // a summary.csv that is not ours is never replaced
    fs::create_dir_all(&out).unwrap();
    fs::write(out.join("summary.csv"), "mine\n1\n").unwrap();
    let o = fibrefit()
        .arg("fit")
        .arg(&one)
        .args(["--model", "lambert", "--out-dir"])
        .arg(&out)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{stderr}");
    assert!(stderr.contains("not a fibrefit fit summary"), "{stderr}");
    assert_eq!(
        fs::read_to_string(out.join("summary.csv")).unwrap(),
        "mine\n1\n"
    );
    assert!(!out.join("felt").exists());
}

#[test]
fn threads_give_the_same_fit() {
    let tmp = tempfile::tempdir().unwrap();
    let data = table(tmp.path(), "silk", "data_synthetic/silk/gonio.csv", 200);
    let fit = |threads: &str| {
        let o = fibrefit()
            .arg("fit")
            .arg(&data)
            .args(["--model", "ward", "--json", "--threads", threads])
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
        v["rmse"].as_f64().unwrap()
    };
    let (one, two) = (fit("1"), fit("2"));
    assert!((one - two).abs() <= 1e-9 * one.abs(), "{one} vs {two}");
}
