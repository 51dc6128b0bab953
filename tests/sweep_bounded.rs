//! Issue 26, the sweep's classes as one property test: seeded random combinations of a command,
//! a hostile or valid input and a hostile or plain output location, each run under an
//! address-space limit (`prlimit --as`, MEMORY_BOUND) and a time limit. For every run: the exit
//! is 0 or 2 (never a panic, an abort or a hang), no input changes, a failed run changes no
//! output, special files stay special, and no temporary file is left.

mod common;

use std::fs;
use std::os::unix::fs::FileTypeExt;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

/// The most address space a run may use: 3 GiB (the binary, its threads and its work).
const MEMORY_BOUND: u64 = 3 << 30;
/// The longest a run may take (generous for a busy 2-core CI machine).
const TIME_BOUND: Duration = Duration::from_secs(60);

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// The inputs of the sweep in `d`: valid ones and hostile ones (names say which).
fn lay_inputs(d: &Path) {
    let csv: String = fs::read_to_string(root().join("data_synthetic/brushed/gonio.csv"))
        .unwrap()
        .lines()
        .take(61)
        .map(|l| format!("{l}\n"))
        .collect();
    fs::write(d.join("good.csv"), &csv).unwrap();
    fs::write(d.join("cut.csv"), &csv[..csv.len() / 2]).unwrap();
    fs::write(d.join("nan.csv"), csv.replacen("\n0", "\nnan", 3)).unwrap();
    std::os::unix::fs::symlink("/dev/zero", d.join("zero.csv")).unwrap();
    fs::write(d.join("bomb.png"), common::png_claiming(100_000, 100_000)).unwrap();
    fs::write(
        d.join("bomb.toml"),
        "[swatch]\nsize_mm = [10.0, 10.0]\nfibre_azimuth_deg = 0\n[[images]]\nfile = \"bomb.png\"\n\
         encoding = \"linear\"\nexposure = 1.0\n\
         light = { type = \"directional\", theta_deg = 30, phi_deg = 0, irradiance = 1.0 }\n\
         camera = { type = \"orthographic\", theta_deg = 0, phi_deg = 0 }\n",
    )
    .unwrap();
    fs::write(
        d.join("heavy.toml"),
        "model = \"poulin-fournier\"\n[knobs]\nquadrature_order = 1024\nazimuth_nodes = 1024\n",
    )
    .unwrap();
    fs::write(
        d.join("many.toml"),
        "model = \"lambert\"\n[optimizer]\nglobal_candidates = 1000000000\n",
    )
    .unwrap();
    fs::write(
        d.join("synth_big.toml"),
        "model = \"lambert\"\n[params]\nkd = 0.5\n[gonio]\nrandom = { count = 100000000000, seed = 1 }\n",
    )
    .unwrap();
    fs::write(
        d.join("synth_ok.toml"),
        "model = \"lambert\"\n[params]\nkd = 0.5\n[gonio]\nrandom = { count = 10, seed = 1 }\n",
    )
    .unwrap();
    fs::write(d.join("poly.obj"), {
        let n = 2000;
        let mut s = String::new();
        for i in 0..n {
            let a = i as f64 / n as f64 * std::f64::consts::TAU;
            s += &format!("v {} {} 0\n", a.cos(), a.sin());
        }
        s += "f";
        for i in 1..=n {
            s += &format!(" {i}");
        }
        s + "\nf 1 1 2\n"
    })
    .unwrap();
    let st = std::process::Command::new(assert_cmd::cargo::cargo_bin("fibrefit"))
        .current_dir(d)
        .args([
            "fit",
            "good.csv",
            "--model",
            "lambert",
            "--out",
            "result.json",
            "-q",
        ])
        .status()
        .unwrap();
    assert!(st.success());
    fs::write(
        d.join("queries.csv"),
        "theta_i,phi_i,theta_o,phi_o\n30,0,30,180\n89.9,0,89.9,180\n",
    )
    .unwrap();
}

/// Output locations: a new file, links and hard links onto an input, a FIFO with a reader,
/// /dev/null, /dev/full, a directory, a missing directory.
const OUTPUTS: [&str; 8] = [
    "new.csv",
    "link_to_input",
    "hard_to_input",
    "pipe",
    "/dev/null",
    "/dev/full",
    "a_dir",
    "missing/x.csv",
];

fn lay_outputs(d: &Path) {
    std::os::unix::fs::symlink("good.csv", d.join("link_to_input")).unwrap();
    fs::hard_link(d.join("good.csv"), d.join("hard_to_input")).unwrap();
    assert!(std::process::Command::new("mkfifo")
        .arg(d.join("pipe"))
        .status()
        .unwrap()
        .success());
    fs::create_dir(d.join("a_dir")).unwrap();
}

/// The command of case `k`: its arguments with `{in}` and `{out}` to fill, and the inputs
/// that fit it.
fn command(k: usize) -> (Vec<&'static str>, &'static [&'static str]) {
    match k % 7 {
        0 => (
            vec!["fit", "{in}", "--model", "lambert", "--out", "{out}", "-q"],
            &["good.csv", "cut.csv", "nan.csv", "zero.csv", "bomb.toml"],
        ),
        1 => (
            vec![
                "fit", "good.csv", "--config", "{in}", "--out", "{out}", "-q",
            ],
            &["heavy.toml", "many.toml"],
        ),
        2 => (
            vec!["inspect", "{in}"],
            &["good.csv", "cut.csv", "zero.csv", "bomb.toml"],
        ),
        3 => (
            vec![
                "eval",
                "--params",
                "result.json",
                "--queries",
                "{in}",
                "--out",
                "{out}",
            ],
            &["queries.csv", "good.csv", "zero.csv"],
        ),
        4 => (
            vec!["tangents", "{in}", "--out", "{out}", "-q"],
            &["poly.obj"],
        ),
        5 => (
            vec!["synth", "--config", "{in}", "--out", "{out}", "-q"],
            &["synth_ok.toml", "synth_big.toml"],
        ),
        _ => (
            vec!["export", "{in}", "--shader", "wgsl", "--out", "{out}", "-q"],
            &["result.json", "good.csv"],
        ),
    }
}

#[test]
fn hostile_combinations_exit_cleanly_within_bounds_and_destroy_nothing() {
    let bin = assert_cmd::cargo::cargo_bin("fibrefit");
    let mut rng = common::Rng::new(26);
    let mut exits = [0usize; 2];
    for case in 0..42 {
        let dir = tempfile::tempdir().unwrap();
        let d = dir.path();
        lay_inputs(d);
        lay_outputs(d);
        let (args, inputs) = command(case);
        let input = inputs[(rng.uniform() * inputs.len() as f64) as usize % inputs.len()];
        let output = OUTPUTS[(rng.uniform() * OUTPUTS.len() as f64) as usize % OUTPUTS.len()];
        let args: Vec<String> = args
            .iter()
            .map(|a| a.replace("{in}", input).replace("{out}", output))
            .collect();
        let before = common::snapshot(d);
        // a reader for the FIFO, so a write to it completes
        let fifo = d.join("pipe");
        let reader = std::thread::spawn(move || {
            let _ = fs::read(&fifo);
        });
        let t = Instant::now();
        let mut child = std::process::Command::new("prlimit")
            .arg(format!("--as={MEMORY_BOUND}"))
            .arg(&bin)
            .args(&args)
            .current_dir(d)
            .stdout(std::process::Stdio::null())
            .stderr(std::process::Stdio::piped())
            .spawn()
            .unwrap();
        let status = loop {
            if let Some(s) = child.try_wait().unwrap() {
                break s;
            }
            if t.elapsed() > TIME_BOUND {
                let _ = child.kill();
                panic!("case {case} {args:?}: still running after {TIME_BOUND:?}");
            }
            std::thread::sleep(Duration::from_millis(20));
        };
        let mut err = String::new();
        std::io::Read::read_to_string(&mut child.stderr.take().unwrap(), &mut err).unwrap();
        // release the reader if nothing opened the FIFO for writing (without blocking when the
        // reader is already gone)
        let _ = std::os::unix::fs::OpenOptionsExt::custom_flags(
            fs::OpenOptions::new().write(true),
            libc::O_NONBLOCK,
        )
        .open(d.join("pipe"));
        reader.join().unwrap();
        let code = status.code();
        assert!(
            matches!(code, Some(0) | Some(2)),
            "case {case} {args:?}: exit {status:?}: {err}"
        );
        exits[(code == Some(2)) as usize] += 1;
        eprintln!(
            "case {case}: {args:?} -> {code:?} {}",
            err.lines().last().unwrap_or("")
        );
        if code == Some(2) {
            assert!(err.contains("error: "), "case {case} {args:?}: no message");
        }
        let after = common::snapshot(d);
        // inputs never change; after a failure nothing changes at all. The links and the hard
        // link name good.csv: written through when it is not an input of the run.
        let reads_good = args.iter().any(|a| a == "good.csv");
        for (name, content) in &before {
            let now = after.iter().find(|(n, _)| n == name);
            let through_link = name == "good.csv"
                && matches!(output, "link_to_input" | "hard_to_input")
                && !reads_good;
            let is_output = name == output || through_link;
            if code == Some(2) || !is_output {
                assert_eq!(
                    now.map(|x| &x.1),
                    Some(content),
                    "case {case} {args:?}: {name} changed ({err})"
                );
            }
        }
        if code == Some(2) {
            let new: Vec<_> = after
                .iter()
                .filter(|(n, _)| !before.iter().any(|(b, _)| b == n))
                .map(|(n, _)| n.clone())
                .collect();
            assert!(
                new.is_empty(),
                "case {case} {args:?}: a failed run wrote {new:?}"
            );
        }
        assert!(
            !after.iter().any(|(n, _)| n.contains(".fibrefit-")),
            "case {case} {args:?}: a temporary was left"
        );
        assert!(fs::symlink_metadata(d.join("pipe"))
            .unwrap()
            .file_type()
            .is_fifo());
        assert!(fs::metadata("/dev/null")
            .unwrap()
            .file_type()
            .is_char_device());
    }
    // the sweep exercised both outcomes
    assert!(exits[0] > 0 && exits[1] > 0, "exits 0/2: {exits:?}");
}
