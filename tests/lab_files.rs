//! A lab's own files (issue 40, items 1 and 6): goniometric tables as labs write them (`.csv`,
//! `.tsv`, `.txt`, `.dat`, the delimiter sniffed from the content; angles in radians with
//! `--angles rad` or the config's `[data] angles`), and a result folder that moves (its
//! topology map found beside the result wherever it is run from, checked by hash).

use assert_cmd::Command;
use std::fs;
use std::path::{Path, PathBuf};

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

fn fibrefit() -> Command {
    Command::cargo_bin("fibrefit").unwrap()
}

fn silk() -> PathBuf {
    root().join("data_synthetic/silk/gonio.csv")
}

/// The silk config, written into `dir` with its topology map named absolutely (so the copy
/// reads the same map) and `extra` appended.
fn silk_config(dir: &Path, extra: &str) -> PathBuf {
    let text = fs::read_to_string(root().join("configs/fit_silk.toml")).unwrap();
    let map = root().join("data_synthetic/silk/topology.png");
    let text = text.replace(
        "\"../data_synthetic/silk/topology.png\"",
        &format!("{:?}", map.display().to_string()),
    );
    assert!(text.contains(&map.display().to_string()));
    let p = dir.join("fit.toml");
    fs::write(&p, format!("{text}\n{extra}\n")).unwrap();
    p
}

/// The silk table's rows as fields (header first).
fn silk_rows() -> Vec<Vec<String>> {
    fs::read_to_string(silk())
        .unwrap()
        .lines()
        .filter(|l| !l.trim().is_empty())
        .map(|l| l.split(',').map(str::to_owned).collect())
        .collect()
}

/// Fit `data` with `config` and the extra `flags`; the result's parameter values.
fn fit(data: &Path, config: &Path, flags: &[&str]) -> serde_json::Map<String, serde_json::Value> {
    let out = data.with_extension("result.json");
    let o = fibrefit()
        .arg("fit")
        .arg(data)
        .arg("--config")
        .arg(config)
        .args(flags)
        .arg("--out")
        .arg(&out)
        .arg("--quiet")
        .output()
        .unwrap();
    assert!(
        o.status.success(),
        "{}: {}",
        data.display(),
        String::from_utf8_lossy(&o.stderr)
    );
    let r: serde_json::Value = serde_json::from_str(&fs::read_to_string(&out).unwrap()).unwrap();
    r["parameters"].as_object().unwrap().clone()
}

/// Every parameter value of `a` within `rel` of `b`'s.
fn same_parameters(
    a: &serde_json::Map<String, serde_json::Value>,
    b: &serde_json::Map<String, serde_json::Value>,
    rel: f64,
    what: &str,
) {
    assert_eq!(
        a.keys().collect::<Vec<_>>(),
        b.keys().collect::<Vec<_>>(),
        "{what}"
    );
    let values = |v: &serde_json::Value| -> Vec<f64> {
        match &v["value"] {
            serde_json::Value::Array(x) => x.iter().map(|y| y.as_f64().unwrap()).collect(),
            x => vec![x.as_f64().unwrap()],
        }
    };
    for (k, va) in a {
        for (x, y) in values(va).iter().zip(values(&b[k])) {
            assert!(
                (x - y).abs() <= rel * x.abs().max(y.abs()).max(1e-6),
                "{what}: {k} {x} vs {y}"
            );
        }
    }
}

#[test]
fn tsv_txt_and_dat_tables_fit_as_the_csv() {
    let dir = tempfile::tempdir().unwrap();
    let cfg = silk_config(dir.path(), "");
    let rows = silk_rows();
    let csv = dir.path().join("silk.csv");
    fs::copy(silk(), &csv).unwrap();
    let reference = fit(&csv, &cfg, &[]);
    // the extension names the kind of file, the content its delimiter (upper case too)
    for (name, sep) in [
        ("silk.tsv", "\t"),
        ("silk.txt", "   "),
        ("silk.dat", ";"),
        ("silk_tabs.TXT", "\t"),
    ] {
        let p = dir.path().join(name);
        let text: String = rows.iter().map(|r| r.join(sep) + "\n").collect();
        fs::write(&p, text).unwrap();
        let o = fibrefit().arg("inspect").arg(&p).output().unwrap();
        assert!(
            o.status.success(),
            "{name}: {}",
            String::from_utf8_lossy(&o.stderr)
        );
        same_parameters(&fit(&p, &cfg, &[]), &reference, 1e-12, name);
    }
}

#[test]
fn unknown_extensions_list_the_table_types() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("silk.xlsx");
    fs::copy(silk(), &p).unwrap();
    for cmd in ["inspect", "fit"] {
        let mut c = fibrefit();
        c.arg(cmd).arg(&p);
        if cmd == "fit" {
            c.args(["--model", "lambert"]);
        }
        let o = c.output().unwrap();
        assert_eq!(o.status.code(), Some(2), "{cmd}");
        let e = String::from_utf8_lossy(&o.stderr);
        assert!(
            e.contains("silk.xlsx") && e.contains("unknown data file type"),
            "{e}"
        );
        for ext in [".csv", ".tsv", ".txt", ".dat"] {
            assert!(e.contains(ext), "{cmd}: {ext} not named: {e}");
        }
    }
}

/// The silk table with its angle columns in radians.
fn silk_in_radians(dir: &Path) -> PathBuf {
    let rows = silk_rows();
    let mut text = rows[0].join(",") + "\n";
    for r in &rows[1..] {
        let f: Vec<String> = r
            .iter()
            .enumerate()
            .map(|(k, x)| match k < 4 {
                true => format!("{}", x.parse::<f64>().unwrap().to_radians()),
                false => x.clone(),
            })
            .collect();
        text += &(f.join(",") + "\n");
    }
    let p = dir.join("silk_rad.csv");
    fs::write(&p, text).unwrap();
    p
}

#[test]
fn radians_fit_with_the_flag_or_the_config_and_are_named_without() {
    let dir = tempfile::tempdir().unwrap();
    let cfg = silk_config(dir.path(), "");
    let csv = dir.path().join("silk.csv");
    fs::copy(silk(), &csv).unwrap();
    let reference = fit(&csv, &cfg, &[]);
    let rad = silk_in_radians(dir.path());

    // without the flag: the hint names it, and nothing is written
    let out = dir.path().join("none.json");
    let o = fibrefit()
        .arg("fit")
        .arg(&rad)
        .arg("--config")
        .arg(&cfg)
        .arg("--out")
        .arg(&out)
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(2));
    let e = String::from_utf8_lossy(&o.stderr);
    assert!(
        e.contains("silk_rad.csv") && e.contains("look like radians") && e.contains("--angles rad"),
        "{e}"
    );
    assert!(!out.exists());
    for cmd in ["inspect", "score"] {
        let mut c = fibrefit();
        c.arg(cmd);
        if cmd == "score" {
            c.arg(csv.with_extension("result.json"));
        }
        let o = c.arg(&rad).output().unwrap();
        assert_eq!(o.status.code(), Some(2), "{cmd}");
        assert!(String::from_utf8_lossy(&o.stderr).contains("--angles rad"));
        let mut c = fibrefit();
        c.arg(cmd);
        if cmd == "score" {
            c.arg(csv.with_extension("result.json"));
        }
        let o = c.arg(&rad).args(["--angles", "rad"]).output().unwrap();
        assert!(
            o.status.success(),
            "{cmd}: {}",
            String::from_utf8_lossy(&o.stderr)
        );
    }

    // with the flag, and with the config's [data] section (which the flag overrides)
    same_parameters(
        &fit(&rad, &cfg, &["--angles", "rad"]),
        &reference,
        1e-6,
        "--angles rad",
    );
    let cfg_rad = silk_config(dir.path(), "[data]\nangles = \"rad\"");
    same_parameters(&fit(&rad, &cfg_rad, &[]), &reference, 1e-6, "[data] angles");
    same_parameters(
        &fit(&csv, &cfg_rad, &["--angles", "deg"]),
        &reference,
        1e-12,
        "--angles deg over the config",
    );
}

#[test]
fn bad_angle_units_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let o = fibrefit()
        .arg("inspect")
        .arg(silk())
        .args(["--angles", "grad"])
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(2));
    let e = String::from_utf8_lossy(&o.stderr);
    assert!(
        e.contains("--angles") && e.contains("grad") && e.contains("rad"),
        "{e}"
    );

    let cfg = silk_config(dir.path(), "[data]\nangles = \"grad\"");
    let out = dir.path().join("r.json");
    let o = fibrefit()
        .arg("fit")
        .arg(silk())
        .arg("--config")
        .arg(&cfg)
        .arg("--out")
        .arg(&out)
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(2));
    let e = String::from_utf8_lossy(&o.stderr);
    assert!(
        e.contains("fit.toml") && e.contains("angles") && e.contains("`grad` is not an angle unit"),
        "{e}"
    );
    assert!(!out.exists());
}

/// Fit the silk with its topology map in `a/maps/` and the result in `a/out/fit.json`.
fn fit_with_map(a: &Path) -> PathBuf {
    fs::create_dir_all(a.join("maps")).unwrap();
    fs::create_dir_all(a.join("out")).unwrap();
    fs::copy(
        root().join("data_synthetic/silk/topology.png"),
        a.join("maps/topology.png"),
    )
    .unwrap();
    let text = fs::read_to_string(root().join("configs/fit_silk.toml"))
        .unwrap()
        .replace("../data_synthetic/silk/topology.png", "maps/topology.png");
    fs::write(a.join("fit.toml"), text).unwrap();
    let out = a.join("out/fit.json");
    let o = fibrefit()
        .arg("fit")
        .arg(silk())
        .arg("--config")
        .arg(a.join("fit.toml"))
        .arg("--out")
        .arg(&out)
        .arg("--quiet")
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    out
}

/// Run `args` from the working directory `cwd`: (exit code, stderr).
fn run_in(cwd: &Path, args: &[&std::ffi::OsStr]) -> (Option<i32>, String) {
    let o = fibrefit().current_dir(cwd).args(args).output().unwrap();
    (
        o.status.code(),
        String::from_utf8_lossy(&o.stderr).into_owned(),
    )
}

/// `render`, `eval` and `score` of the result at `result`, run from `cwd`, writing into `cwd`.
fn use_result(cwd: &Path, result: &Path) -> Vec<(&'static str, Option<i32>, String)> {
    let queries = root().join("data_synthetic/queries_slices.csv");
    let (png, csv, data) = (cwd.join("r.png"), cwd.join("e.csv"), silk());
    let os = |s: &'static str| std::ffi::OsStr::new(s);
    let cases: [(&str, Vec<&std::ffi::OsStr>); 3] = [
        (
            "render",
            vec![
                os("render"),
                os("--params"),
                result.as_os_str(),
                os("--size"),
                os("24"),
                os("24"),
                os("--quiet"),
                os("--out"),
                png.as_os_str(),
            ],
        ),
        (
            "eval",
            vec![
                os("eval"),
                os("--params"),
                result.as_os_str(),
                os("--queries"),
                queries.as_os_str(),
                os("--quiet"),
                os("--out"),
                csv.as_os_str(),
            ],
        ),
        (
            "score",
            vec![os("score"), result.as_os_str(), data.as_os_str()],
        ),
    ];
    cases
        .into_iter()
        .map(|(name, args)| {
            let (code, err) = run_in(cwd, &args);
            (name, code, err)
        })
        .collect()
}

#[test]
fn a_result_folder_copied_with_its_map_loads_anywhere() {
    let (a, b, c) = (
        tempfile::tempdir().unwrap(),
        tempfile::tempdir().unwrap(),
        tempfile::tempdir().unwrap(),
    );
    let out = fit_with_map(a.path());
    let r: serde_json::Value = serde_json::from_str(&fs::read_to_string(&out).unwrap()).unwrap();
    assert_eq!(r["knobs"]["topology_map"], "../maps/topology.png");
    let sha = r["knobs"]["topology_map_sha256"]
        .as_str()
        .unwrap()
        .to_owned();
    assert_eq!(sha.len(), 64);

    // the folder moved, with the map in the same place relative to the result
    fs::create_dir_all(b.path().join("out")).unwrap();
    fs::create_dir_all(b.path().join("maps")).unwrap();
    fs::copy(&out, b.path().join("out/fit.json")).unwrap();
    fs::copy(
        a.path().join("maps/topology.png"),
        b.path().join("maps/topology.png"),
    )
    .unwrap();
    drop(a);
    let moved = b.path().join("out/fit.json");
    for (cmd, code, err) in use_result(c.path(), &moved) {
        assert_eq!(code, Some(0), "{cmd}: {err}");
    }
    // a relative path to the result, from another working directory
    let (code, err) = run_in(
        b.path(),
        &[
            "score".as_ref(),
            "out/fit.json".as_ref(),
            silk().as_os_str(),
        ],
    );
    assert_eq!(code, Some(0), "{err}");

    fs::remove_file(c.path().join("r.png")).unwrap();
    fs::remove_file(c.path().join("e.csv")).unwrap();

    // another map in its place: refused, naming both hashes (and nothing written)
    let mut png = fs::read(b.path().join("maps/topology.png")).unwrap();
    png.extend_from_slice(b"edited");
    fs::write(b.path().join("maps/topology.png"), &png).unwrap();
    for (cmd, code, err) in use_result(c.path(), &moved) {
        assert_eq!(code, Some(2), "{cmd}: {err}");
        assert!(
            err.contains("is not the one this result was fitted with")
                && err.contains(&sha)
                && err.contains("topology.png"),
            "{cmd}: {err}"
        );
        assert!(!c.path().join("r.png").exists() && !c.path().join("e.csv").exists());
    }

    // no map: the error names the path looked for and what the result named
    fs::remove_file(b.path().join("maps/topology.png")).unwrap();
    let looked = fs::canonicalize(b.path())
        .unwrap()
        .join("maps/topology.png");
    for (cmd, code, err) in use_result(c.path(), &moved) {
        assert_eq!(code, Some(2), "{cmd}: {err}");
        assert!(
            err.contains(&looked.display().to_string())
                && err.contains("\"../maps/topology.png\"")
                && err.contains("never the working directory"),
            "{cmd}: {err}"
        );
    }
}

#[test]
fn results_without_a_map_hash_keep_loading() {
    let (a, c) = (tempfile::tempdir().unwrap(), tempfile::tempdir().unwrap());
    let out = fit_with_map(a.path());
    let mut r: serde_json::Value =
        serde_json::from_str(&fs::read_to_string(&out).unwrap()).unwrap();
    r["knobs"]
        .as_object_mut()
        .unwrap()
        .remove("topology_map_sha256");
    fs::write(&out, serde_json::to_string_pretty(&r).unwrap()).unwrap();
    for (cmd, code, err) in use_result(c.path(), &out) {
        assert_eq!(code, Some(0), "{cmd}: {err}");
    }
}
