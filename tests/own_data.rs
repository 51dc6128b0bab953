//! The first hour with one's own data (issue 22): files in other delimiters and with other
//! column names, progress on long work and what an interrupted auto run leaves, no absolute
//! paths in exports, and the command-line defects (an optional --out, help texts, warnings
//! once, score's verdict, a data file given as --params).

use assert_cmd::Command;
use std::fs;
use std::io::BufRead;
use std::path::{Path, PathBuf};

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

fn fibrefit() -> Command {
    let mut c = Command::cargo_bin("fibrefit").unwrap();
    c.env_remove("FIBREFIT_PROGRESS");
    c
}

fn text(b: &[u8]) -> String {
    String::from_utf8_lossy(b).into_owned()
}

/// Fit `data` with the brushed config; the result's parameters.
fn brushed_parameters(data: &Path, extra: &[&str]) -> serde_json::Value {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("fit.json");
    let o = fibrefit()
        .arg("fit")
        .arg(data)
        .arg("--config")
        .arg(root().join("configs/fit_brushed.toml"))
        .arg("--out")
        .arg(&out)
        .arg("--quiet")
        .args(extra)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", text(&o.stderr));
    let r: serde_json::Value = serde_json::from_str(&fs::read_to_string(&out).unwrap()).unwrap();
    r["parameters"].clone()
}

#[test]
fn tab_semicolon_and_whitespace_copies_fit_as_the_comma_file_and_inspect_names_the_delimiter() {
    let src = root().join("data_synthetic/brushed/gonio.csv");
    let comma = fs::read_to_string(&src).unwrap();
    let reference = brushed_parameters(&src, &[]);
    let dir = tempfile::tempdir().unwrap();
    for (name, sep) in [("tab", "\t"), ("semicolon", ";"), ("whitespace", "   ")] {
        let copy = dir.path().join(format!("{name}.csv"));
        fs::write(&copy, comma.replace(',', sep)).unwrap();
        assert_eq!(
            brushed_parameters(&copy, &[]),
            reference,
            "{name}-separated copy"
        );
        let o = fibrefit()
            .arg("inspect")
            .arg(&copy)
            .arg("--json")
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", text(&o.stderr));
        let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
        assert_eq!(v["delimiter"], name, "{v}");
        let o = fibrefit().arg("inspect").arg(&copy).output().unwrap();
        assert!(
            text(&o.stdout).contains(&format!("format           {name}-separated")),
            "{}",
            text(&o.stdout)
        );
    }
}

#[test]
fn columns_map_a_files_own_names_and_an_unknown_header_shows_both_headers() {
    let src = root().join("data_synthetic/brushed/gonio.csv");
    let reference = brushed_parameters(&src, &[]);
    let body = fs::read_to_string(&src).unwrap();
    let (_, rows) = body.split_once('\n').unwrap();
    let dir = tempfile::tempdir().unwrap();
    let renamed = dir.path().join("own.csv");
    fs::write(
        &renamed,
        format!(
            "theta_in\tphi_in\ttheta_out\tphi_out\tf\ts\n{}",
            rows.replace(',', "\t")
        ),
    )
    .unwrap();
    let map = "theta_i=theta_in,phi_i=phi_in,theta_o=theta_out,phi_o=phi_out,brdf=f,sigma=s";
    assert_eq!(
        brushed_parameters(&renamed, &["--columns", map]),
        reference,
        "--columns"
    );
    // the same map as the config's [columns] table
    let cfg = dir.path().join("fit.toml");
    fs::write(
        &cfg,
        fs::read_to_string(root().join("configs/fit_brushed.toml")).unwrap()
            + "\n[columns]\ntheta_i = \"theta_in\"\nphi_i = \"phi_in\"\ntheta_o = \"theta_out\"\nphi_o = \"phi_out\"\nbrdf = \"f\"\nsigma = \"s\"\n",
    )
    .unwrap();
    let out = dir.path().join("cfg.json");
    let o = fibrefit()
        .arg("fit")
        .arg(&renamed)
        .arg("--config")
        .arg(&cfg)
        .arg("--out")
        .arg(&out)
        .arg("-q")
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", text(&o.stderr));
    let r: serde_json::Value = serde_json::from_str(&fs::read_to_string(&out).unwrap()).unwrap();
    assert_eq!(r["parameters"], reference, "[columns]");
    let o = fibrefit()
        .arg("inspect")
        .arg(&renamed)
        .arg("--columns")
        .arg(map)
        .output()
        .unwrap();
    assert!(
        text(&o.stdout).contains("theta_in -> theta_i"),
        "{}",
        text(&o.stdout)
    );

    // without the map: the header read and the one expected, and the hint
    let out = dir.path().join("none.json");
    let o = fibrefit()
        .arg("fit")
        .arg(&renamed)
        .arg("--config")
        .arg(root().join("configs/fit_brushed.toml"))
        .arg("--out")
        .arg(&out)
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(2));
    let e = text(&o.stderr);
    assert!(
        e.contains("own.csv:1: unknown column `theta_in`")
            && e.contains("the header read (tab-separated, 6 columns): `theta_in`, `phi_in`, `theta_out`, `phi_out`, `f`, `s`")
            && e.contains("expected the columns: theta_i, phi_i, theta_o, phi_o, brdf")
            && e.contains("--columns"),
        "{e}"
    );
    assert!(!out.exists());
    // a map naming a column the file lacks, or one that is not ours
    for (bad, says) in [
        ("theta_i=th", "the header has no column `th`"),
        ("angle=theta_in", "`angle` is not a column fibrefit reads"),
        ("theta_i", "is not OURS=THEIRS"),
    ] {
        let o = fibrefit()
            .arg("inspect")
            .arg(&renamed)
            .arg("--columns")
            .arg(bad)
            .output()
            .unwrap();
        assert_eq!(o.status.code(), Some(2), "{bad}");
        assert!(text(&o.stderr).contains(says), "{bad}: {}", text(&o.stderr));
    }
}

#[test]
fn progress_lines_show_when_forced_and_not_otherwise() {
    let data = root().join("data_synthetic/brushed/gonio.csv");
    let run = |force: Option<&str>| {
        let mut c = fibrefit();
        c.arg("fit")
            .arg(&data)
            .arg("--config")
            .arg(root().join("configs/fit_brushed.toml"));
        if let Some(f) = force {
            c.env("FIBREFIT_PROGRESS", f);
        }
        let o = c.output().unwrap();
        assert!(o.status.success(), "{}", text(&o.stderr));
        text(&o.stderr)
    };
    let forced = run(Some("1"));
    for stage in [
        "progress: fit: global search over",
        "progress: fit: polishing",
        "progress: fit: standard errors and quality checks",
    ] {
        assert!(forced.contains(stage), "{stage}:\n{forced}");
    }
    // stderr is not a terminal here: no progress unless forced
    assert!(!run(None).contains("progress:"));
    assert!(!run(Some("0")).contains("progress:"));
}

#[test]
fn an_interrupted_auto_run_writes_the_rungs_it_finished_marked_partial() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("auto.json");
    let report = dir.path().join("report");
    let data = root().join("data_synthetic/loose/gonio.csv");
    let mut child = std::process::Command::new(env!("CARGO_BIN_EXE_fibrefit"))
        .arg("fit")
        .arg(&data)
        .arg("--model")
        .arg("auto")
        .arg("--out")
        .arg(&out)
        .arg("--report")
        .arg(&report)
        .env("FIBREFIT_PROGRESS", "1")
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let mut lines = std::io::BufReader::new(child.stderr.take().unwrap()).lines();
    let mut seen = Vec::new();
    let mut rung_lines = 0;
    // after two rungs finished (the richer rungs left take far longer)
    while seen.len() < 2 {
        let line = lines
            .next()
            .expect("the run ended before two rungs finished")
            .unwrap();
        if line.starts_with("progress: auto: rung ") {
            rung_lines += 1;
        }
        if let Some(rest) = line.strip_prefix("progress: auto: ") {
            if let Some((rung, _)) = rest.split_once(" fitted in ") {
                seen.push(rung.to_string());
            }
        }
    }
    assert!(rung_lines >= 2);
    unsafe {
        assert_eq!(libc::kill(child.id() as i32, libc::SIGINT), 0);
    }
    let rest: Vec<String> = lines.map_while(Result::ok).collect();
    let status = child.wait().unwrap();
    let rest = rest.join("\n");
    assert_eq!(status.code(), Some(130), "{rest}");
    assert!(rest.contains("PARTIAL: wrote"), "{rest}");
    let v: serde_json::Value = serde_json::from_str(&fs::read_to_string(&out).unwrap()).unwrap();
    assert_eq!(v["partial"], true);
    assert_eq!(v["schema"], "fibrefit-partial/1");
    let done: Vec<String> = v["rungs_done"]
        .as_array()
        .unwrap()
        .iter()
        .map(|r| r.as_str().unwrap().to_string())
        .collect();
    assert!(done.len() >= seen.len(), "{done:?} vs {seen:?}");
    assert_eq!(&done[..seen.len()], &seen[..]);
    assert_eq!(v["model_selection"].as_array().unwrap().len(), done.len());
    assert!(!v["rungs_not_done"].as_array().unwrap().is_empty());
    assert!(v["training_fits"][0]["parameters"].is_object(), "{v}");
    let md = fs::read_to_string(report.join("report.md")).unwrap();
    assert!(md.starts_with("# PARTIAL"), "{md}");
    for r in &seen {
        assert!(md.contains(&format!("| {r} |")), "{md}");
    }
    // and no command takes it for a result
    let o = fibrefit()
        .arg("score")
        .arg(&out)
        .arg(&data)
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(2));
    assert!(
        text(&o.stderr).contains("partial result"),
        "{}",
        text(&o.stderr)
    );
}

/// Every file under `dir`, recursively.
fn files_under(dir: &Path) -> Vec<PathBuf> {
    let mut out = Vec::new();
    for e in fs::read_dir(dir).unwrap().flatten() {
        let p = e.path();
        if p.is_dir() {
            out.extend(files_under(&p));
        } else {
            out.push(p);
        }
    }
    out
}

#[test]
fn no_absolute_path_in_the_result_the_shader_or_the_gltf() {
    // inside the worktree, so that a relative path from the outputs to the data does not pass
    // through the worktree's absolute path
    let dir = tempfile::tempdir_in(env!("CARGO_TARGET_TMPDIR")).unwrap();
    let outs = dir.path().join("outs");
    fs::create_dir(&outs).unwrap();
    let result = outs.join("silk_fit.json");
    let data = root().join("data_synthetic/silk/gonio.csv");
    let o = fibrefit()
        .arg("fit")
        .arg(&data)
        .arg("--config")
        .arg(root().join("configs/fit_silk.toml"))
        .arg("--out")
        .arg(&result)
        .arg("-q")
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", text(&o.stderr));
    let r: serde_json::Value = serde_json::from_str(&fs::read_to_string(&result).unwrap()).unwrap();
    let map = r["knobs"]["topology_map"].as_str().unwrap();
    assert!(
        map.ends_with("topology.png") && Path::new(map).is_relative(),
        "{map}"
    );
    // read back beside the result: score reproduces the fit
    let o = fibrefit()
        .arg("score")
        .arg(&result)
        .arg(&data)
        .arg("--json")
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", text(&o.stderr));
    let s: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let (a, b) = (
        s["statistics"]["rmse"].as_f64().unwrap(),
        r["statistics"]["rmse"].as_f64().unwrap(),
    );
    assert!((a - b).abs() <= 1e-9 * b, "{a} vs {b}");
    // a parameter TOML naming its map by an absolute path, and the fitted result
    let params = outs.join("params.toml");
    fs::write(
        &params,
        format!(
            "model = 'varying-topology'\nkd = 0.5\nks = 0.25\nexponent = 60\nspacing = 2\nheight = 0.9\nmap_scale = 0.25\ntopology_map = '{}'\n",
            root().join("data_synthetic/silk/topology.png").display()
        ),
    )
    .unwrap();
    for (k, input) in [&result, &params].into_iter().enumerate() {
        let o = fibrefit()
            .arg("export")
            .arg(input)
            .arg("--shader")
            .arg("wgsl")
            .arg("--out")
            .arg(outs.join(format!("m{k}.wgsl")))
            .arg("--gltf")
            .arg(outs.join(format!("m{k}.glb")))
            .arg("-q")
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", text(&o.stderr));
        let wgsl = fs::read_to_string(outs.join(format!("m{k}.wgsl"))).unwrap();
        assert!(
            wgsl.contains("topology map topology.png"),
            "{}",
            &wgsl[..2000.min(wgsl.len())]
        );
    }
    let needles = [
        root().canonicalize().unwrap().display().to_string(),
        root().display().to_string(),
        dir.path().canonicalize().unwrap().display().to_string(),
        dir.path().display().to_string(),
    ];
    let written: Vec<PathBuf> = files_under(&outs)
        .into_iter()
        .filter(|p| p != &params)
        .collect();
    assert_eq!(written.len(), 5, "{written:?}");
    for f in &written {
        let bytes = fs::read(f).unwrap();
        let t = String::from_utf8_lossy(&bytes);
        for n in &needles {
            assert!(!t.contains(n.as_str()), "{} contains {n}", f.display());
        }
    }
}

#[test]
fn fit_without_out_prints_the_report_writes_nothing_and_names_out() {
    let dir = tempfile::tempdir().unwrap();
    let o = fibrefit()
        .current_dir(dir.path())
        .arg("fit")
        .arg(root().join("data_synthetic/brushed/gonio.csv"))
        .arg("--config")
        .arg(root().join("configs/fit_brushed.toml"))
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", text(&o.stderr));
    assert!(text(&o.stdout).contains("[[Variables]]"));
    let e = text(&o.stderr);
    assert_eq!(e.lines().filter(|l| l.contains("--out")).count(), 1, "{e}");
    assert!(e.contains("nothing written: add --out FILE"), "{e}");
    assert_eq!(fs::read_dir(dir.path()).unwrap().count(), 0);
}

#[test]
fn warnings_print_once_and_score_ends_with_the_fits_verdict() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("b.json");
    let capture = root().join("data_synthetic/brushed/capture.toml");
    let o = fibrefit()
        .arg("fit")
        .arg(&capture)
        .arg("--config")
        .arg(root().join("configs/fit_brushed.toml"))
        .arg("--out")
        .arg(&out)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", text(&o.stderr));
    let (stdout, stderr) = (text(&o.stdout), text(&o.stderr));
    let r: serde_json::Value = serde_json::from_str(&fs::read_to_string(&out).unwrap()).unwrap();
    let warnings: Vec<&str> = r["warnings"]
        .as_array()
        .unwrap()
        .iter()
        .map(|w| w.as_str().unwrap())
        .collect();
    assert!(!warnings.is_empty(), "the brushed capture fit warns");
    for w in warnings {
        let n = stdout.matches(w).count() + stderr.matches(&format!("warning: {w}")).count();
        assert_eq!(n, 1, "`{w}` printed {n} times:\n{stdout}\n{stderr}");
    }
    for data in [capture, root().join("data_synthetic/brushed/gonio.csv")] {
        let o = fibrefit()
            .arg("score")
            .arg(&out)
            .arg(&data)
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", text(&o.stderr));
        let s = text(&o.stdout);
        let tail: Vec<&str> = s.lines().rev().take(3).collect();
        let verdict = tail
            .iter()
            .find_map(|l| l.trim().strip_prefix("verdict            = "))
            .unwrap_or_else(|| panic!("no verdict at the end:\n{s}"));
        assert!(
            [
                "fits within the noise",
                "does not fit within the noise",
                "noise unknown"
            ]
            .contains(&verdict),
            "{verdict}"
        );
        let o = fibrefit()
            .arg("score")
            .arg(&out)
            .arg(&data)
            .arg("--json")
            .output()
            .unwrap();
        let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
        assert_eq!(v["verdict"], verdict);
    }
}

#[test]
fn help_texts_and_a_data_file_as_params() {
    let o = fibrefit().args(["render", "--help"]).output().unwrap();
    // clap wraps lines: compare with the wrapping undone
    let h = text(&o.stdout)
        .split_whitespace()
        .collect::<Vec<_>>()
        .join(" ");
    assert_eq!(h.matches("[default: 50,270]").count(), 1, "{h}");
    let o = fibrefit().args(["merge-maps", "--help"]).output().unwrap();
    let h = text(&o.stdout);
    let q = h
        .lines()
        .find(|l| l.contains("-q, --quiet"))
        .expect("a -q line");
    assert!(q.split("--quiet").nth(1).unwrap().trim().len() > 10, "{h}");

    let dir = tempfile::tempdir().unwrap();
    let png = dir.path().join("x.png");
    let data = root().join("data_synthetic/silk/gonio.csv");
    for cmd in ["render", "export"] {
        let mut c = fibrefit();
        c.arg(cmd);
        if cmd == "render" {
            c.arg("--params").arg(&data).arg("--out").arg(&png);
        } else {
            c.arg(&data).arg("--gltf").arg(dir.path().join("x.glb"));
        }
        let o = c.output().unwrap();
        assert_eq!(o.status.code(), Some(2), "{cmd}");
        let e = text(&o.stderr);
        assert!(
            e.contains("a goniometric data file (CSV or TSV), not parameters")
                && e.contains("a result JSON written by `fibrefit fit` or a parameter TOML"),
            "{cmd}: {e}"
        );
    }
    assert_eq!(fs::read_dir(dir.path()).unwrap().count(), 0);
}

/// Run `args` under a pseudo-terminal (util-linux `script`): stdout and stderr both terminals,
/// as a user sees them. `None` where `script` is missing.
fn on_a_terminal(args: &[&str]) -> Option<String> {
    let script = ["/usr/bin/script", "/bin/script"]
        .into_iter()
        .find(|p| Path::new(p).exists())?;
    let cmd = std::iter::once(env!("CARGO_BIN_EXE_fibrefit"))
        .chain(args.iter().copied())
        .map(|a| format!("'{a}'"))
        .collect::<Vec<_>>()
        .join(" ");
    let o = std::process::Command::new(script)
        .args(["-qec", &cmd, "/dev/null"])
        .env_remove("FIBREFIT_PROGRESS")
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", text(&o.stdout));
    Some(text(&o.stdout))
}

#[test]
fn on_a_terminal_progress_shows_and_quality_warnings_print_once() {
    let data = root().join("data_synthetic/brushed/gonio.csv");
    let data = data.to_str().unwrap();
    let Some(t) = on_a_terminal(&["fit", data, "--model", "lambert"]) else {
        eprintln!("no `script` here: skipped");
        return;
    };
    // lambert does not fit the brushed swatch: the banner says so, the warnings are in the report
    assert!(
        t.contains("FIT QUALITY: DOES NOT FIT WITHIN THE NOISE"),
        "{t}"
    );
    assert!(t.contains("see [[Warnings]] in the report above"), "{t}");
    assert_eq!(
        t.matches("the model does not fit within the noise: reduced chi-square")
            .count(),
        1,
        "{t}"
    );
    let cfg = root().join("configs/fit_brushed.toml");
    let t = on_a_terminal(&["fit", data, "--config", cfg.to_str().unwrap()]).unwrap();
    assert!(t.contains("progress: fit: global search over"), "{t}");
}
