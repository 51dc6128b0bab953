//! Issue 26, outputs: nothing a user owns is ever destroyed. Every file a command writes goes
//! through one checked writer: never onto an input or another output of the run (links and hard
//! links included), never replacing a FIFO or device (written as a stream), committed together
//! (a failure or a signal leaves every old output as it was), within stated budgets; a closed
//! or full stream exits cleanly. Disk-full cases mount a small tmpfs (CI runs as root).

mod common;

use assert_cmd::Command;
use std::fs;
use std::os::unix::fs::FileTypeExt;
use std::path::{Path, PathBuf};
use std::process::Output;

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

fn fibrefit() -> Command {
    Command::cargo_bin("fibrefit").unwrap()
}

fn run(args: &[&str], dir: &Path) -> Output {
    fibrefit().current_dir(dir).args(args).output().unwrap()
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

fn refused(o: &Output, fragment: &str) {
    let e = stderr(o);
    assert_eq!(o.status.code(), Some(2), "{e}");
    assert!(e.contains(fragment), "expected '{fragment}' in: {e}");
}

fn ok(o: &Output) {
    assert!(o.status.success(), "{}", stderr(o));
}

/// The first 101 lines of the brushed gonio set as `g.csv` in `d`, and a lambert result `o.json`.
fn small_set(d: &Path) {
    let csv: String = fs::read_to_string(root().join("data_synthetic/brushed/gonio.csv"))
        .unwrap()
        .lines()
        .take(101)
        .map(|l| format!("{l}\n"))
        .collect();
    fs::write(d.join("g.csv"), csv).unwrap();
    ok(&run(
        &[
            "fit", "g.csv", "--model", "lambert", "--out", "o.json", "-q",
        ],
        d,
    ));
}

fn queries() -> String {
    root()
        .join("data_synthetic/queries_slices.csv")
        .display()
        .to_string()
}

/// A tmpfs of `kib` KiB mounted at `dir` (unmounted on drop); None where mounting is not allowed.
struct Tmpfs(PathBuf);
impl Tmpfs {
    fn mount(dir: &Path, kib: usize) -> Option<Self> {
        fs::create_dir_all(dir).unwrap();
        let ok = std::process::Command::new("mount")
            .args(["-t", "tmpfs", "-o", &format!("size={kib}k"), "tmpfs"])
            .arg(dir)
            .stderr(std::process::Stdio::null())
            .status()
            .is_ok_and(|s| s.success());
        if !ok {
            eprintln!("note: cannot mount a tmpfs here (not root?): disk-full case not run");
        }
        ok.then(|| Self(dir.to_path_buf()))
    }
}
impl Drop for Tmpfs {
    fn drop(&mut self) {
        let _ = std::process::Command::new("umount").arg(&self.0).status();
    }
}

#[test]
fn report_files_never_go_onto_inputs() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    small_set(d);
    let before = fs::read(d.join("g.csv")).unwrap();
    // a symlink and a hard link in the report folder, each onto the input
    for (plot, hard) in [
        ("slices.png", false),
        ("hemispheres.png", true),
        ("residuals.png", false),
    ] {
        let rep = d.join(format!("rep_{plot}"));
        fs::create_dir(&rep).unwrap();
        if hard {
            fs::hard_link(d.join("g.csv"), rep.join(plot)).unwrap();
        } else {
            std::os::unix::fs::symlink("../g.csv", rep.join(plot)).unwrap();
        }
        let o = fibrefit()
            .current_dir(d)
            .args([
                "fit", "g.csv", "--model", "lambert", "--out", "x.json", "-q", "--report",
            ])
            .arg(&rep)
            .output()
            .unwrap();
        refused(&o, "is an input of this run");
        assert_eq!(fs::read(d.join("g.csv")).unwrap(), before, "{plot}");
    }
    // `--report .` beside a capture whose image is called residual_map_000.png
    let cap = d.join("cap");
    fs::create_dir(&cap).unwrap();
    let src = root().join("data_synthetic/brushed");
    let toml = fs::read_to_string(src.join("capture.toml"))
        .unwrap()
        .replace("img_000.png", "residual_map_000.png");
    fs::write(cap.join("capture.toml"), toml).unwrap();
    fs::copy(src.join("img_000.png"), cap.join("residual_map_000.png")).unwrap();
    for k in 1..4 {
        let f = format!("img_{k:03}.png");
        fs::copy(src.join(&f), cap.join(&f)).unwrap();
    }
    let image = fs::read(cap.join("residual_map_000.png")).unwrap();
    let o = run(
        &[
            "fit",
            "capture.toml",
            "--model",
            "lambert",
            "--out",
            "r.json",
            "--report",
            ".",
            "-q",
        ],
        &cap,
    );
    refused(&o, "residual_map_000.png: is an input of this run");
    assert_eq!(fs::read(cap.join("residual_map_000.png")).unwrap(), image);
    assert!(!cap.join("r.json").exists());
}

#[test]
fn two_outputs_of_one_run_never_share_a_file() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    small_set(d);
    fs::create_dir(d.join("rep")).unwrap();
    let o = run(
        &[
            "fit",
            "g.csv",
            "--model",
            "lambert",
            "--out",
            "rep/report.md",
            "--report",
            "rep",
            "-q",
        ],
        d,
    );
    refused(&o, "is also the output --out rep/report.md");
    fs::create_dir(d.join("a")).unwrap();
    std::os::unix::fs::symlink("a/normal.exr", d.join("n.exr")).unwrap();
    let o = run(
        &[
            "render", "--params", "o.json", "--object", "sphere", "--size", "8", "8", "--out",
            "n.exr", "--aovs", "a", "-q",
        ],
        d,
    );
    refused(&o, "is also the output --out n.exr");
    assert!(fs::read_dir(d.join("a")).unwrap().next().is_none());
    // export: the shader and the GLB on one file
    let o = run(
        &[
            "export", "o.json", "--shader", "wgsl", "--out", "s.glb", "--gltf", "s.glb", "-q",
        ],
        d,
    );
    refused(&o, "is also the output --out s.glb");
}

#[test]
fn fifos_and_devices_are_streamed_never_replaced() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    small_set(d);
    let fifo = d.join("pipe");
    assert!(std::process::Command::new("mkfifo")
        .arg(&fifo)
        .status()
        .unwrap()
        .success());
    let q = queries();
    // every writer: eval, fit, export --shader; a reader takes the stream each time
    let commands: Vec<Vec<&str>> = vec![
        vec![
            "eval",
            "--params",
            "o.json",
            "--queries",
            &q,
            "--out",
            "pipe",
        ],
        vec!["fit", "g.csv", "--model", "lambert", "--out", "pipe", "-q"],
        vec![
            "export", "o.json", "--shader", "wgsl", "--out", "pipe", "-q",
        ],
    ];
    for args in commands {
        let f = fifo.clone();
        let reader = std::thread::spawn(move || fs::read(&f).unwrap());
        ok(&run(&args, d));
        let got = reader.join().unwrap();
        assert!(!got.is_empty(), "{args:?}: nothing streamed");
        let t = fs::symlink_metadata(&fifo).unwrap().file_type();
        assert!(t.is_fifo(), "{args:?}: the FIFO was replaced");
    }
    // a character device: /dev/null stays the device; /dev/full is a clear error, exit 2
    ok(&run(
        &[
            "eval",
            "--params",
            "o.json",
            "--queries",
            &q,
            "--out",
            "/dev/null",
        ],
        d,
    ));
    assert!(fs::metadata("/dev/null")
        .unwrap()
        .file_type()
        .is_char_device());
    let o = run(
        &[
            "eval",
            "--params",
            "o.json",
            "--queries",
            &q,
            "--out",
            "/dev/full",
        ],
        d,
    );
    refused(
        &o,
        "--out /dev/full: cannot write output: No space left on device",
    );
    assert!(fs::metadata("/dev/full")
        .unwrap()
        .file_type()
        .is_char_device());
    // nothing staged is left in the temporary directory's name space of ours
    assert!(!common::snapshot(d)
        .iter()
        .any(|(n, _)| n.contains(".fibrefit-")));
}

#[test]
fn a_full_disk_changes_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    small_set(d);
    let q = queries();
    let Some(_full) = Tmpfs::mount(&d.join("full"), 48) else {
        return;
    };
    // a hard-linked output: the old content (both names) stays whole, no temporary left. The
    // disk is filled so that the staged file fits but the rewrite of the old one cannot.
    ok(&run(
        &[
            "eval",
            "--params",
            "o.json",
            "--queries",
            &q,
            "--out",
            "e_len.csv",
        ],
        d,
    ));
    let pages = |n: u64| n.div_ceil(4096);
    let staged = pages(fs::metadata(d.join("e_len.csv")).unwrap().len());
    assert!(staged >= 3 && staged <= 10, "{staged} pages");
    let old: Vec<u8> = (0..4000u32).map(|i| (i * 7 % 251) as u8).collect();
    fs::write(d.join("full/e.csv"), &old).unwrap();
    fs::hard_link(d.join("full/e.csv"), d.join("full/e2.csv")).unwrap();
    fs::write(
        d.join("full/fill"),
        vec![0u8; ((12 - 1 - staged) * 4096) as usize],
    )
    .unwrap();
    let o = run(
        &[
            "eval",
            "--params",
            "o.json",
            "--queries",
            &q,
            "--out",
            "full/e.csv",
        ],
        d,
    );
    refused(
        &o,
        "full/e.csv: cannot write output: No space left on device",
    );
    assert_eq!(fs::read(d.join("full/e.csv")).unwrap(), old);
    assert_eq!(fs::read(d.join("full/e2.csv")).unwrap(), old);
    let names: Vec<String> = fs::read_dir(d.join("full"))
        .unwrap()
        .flatten()
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .collect();
    assert_eq!(names.len(), 3, "{names:?}");
    fs::remove_file(d.join("full/fill")).unwrap();
    // a fit whose result goes to the full disk leaves its report folder as it was
    ok(&run(
        &[
            "fit", "g.csv", "--model", "lambert", "--out", "x.json", "--report", "rep", "-q",
        ],
        d,
    ));
    let report_before = common::snapshot(&d.join("rep"));
    fs::write(d.join("full/fill"), vec![1u8; 40_000]).unwrap();
    let o = run(
        &[
            "fit",
            "g.csv",
            "--model",
            "lambert",
            "--out",
            "full/o.json",
            "--report",
            "rep",
            "-q",
        ],
        d,
    );
    refused(&o, "No space left on device");
    assert_eq!(common::snapshot(&d.join("rep")), report_before);
    // render: the picture is not written when its AOVs do not fit
    let o = run(
        &[
            "render",
            "--params",
            "o.json",
            "--object",
            "sphere",
            "--size",
            "64",
            "64",
            "--out",
            "pic.png",
            "--aovs",
            "full/aovs",
            "-q",
        ],
        d,
    );
    refused(&o, "No space left on device");
    assert!(!d.join("pic.png").exists());
    assert!(!d.join("full/aovs").exists());
    // a report on the full disk: a warning, never a truncated plot
    let o = run(
        &[
            "fit", "g.csv", "--model", "lambert", "--out", "y.json", "--report", "full/rep", "-q",
        ],
        d,
    );
    let e = stderr(&o);
    if o.status.success() {
        assert!(e.contains("the report could not be written"), "{e}");
    }
    assert!(!d.join("full/rep/slices.png").exists(), "{e}");
}

#[test]
fn outputs_are_checked_before_the_work_and_leave_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    small_set(d);
    let before = common::snapshot(d);
    let q = queries();
    for args in [
        vec![
            "fit",
            "g.csv",
            "--model",
            "lambert",
            "--out",
            "newdir/o.json",
            "-q",
        ],
        vec![
            "fit", "g.csv", "--model", "lambert", "--out", "newdir/", "-q",
        ],
        vec![
            "eval",
            "--params",
            "o.json",
            "--queries",
            &q,
            "--out",
            "newdir/e.csv",
        ],
        vec![
            "render",
            "--params",
            "o.json",
            "--object",
            "torus",
            "--size",
            "2048",
            "2048",
            "--supersample",
            "4",
            "--out",
            "newdir/r.png",
            "-q",
        ],
        vec![
            "export",
            "o.json",
            "--shader",
            "glsl",
            "--out",
            "newdir/s.glsl",
            "-q",
        ],
    ] {
        let t = std::time::Instant::now();
        let o = run(&args, d);
        refused(&o, "newdir");
        // render would take many seconds: refused before it (generous bound for a busy CI)
        assert!(t.elapsed().as_secs_f64() < 5.0, "{args:?} failed late");
    }
    assert_eq!(common::snapshot(d), before, "a failed run left something");
}

#[test]
fn synth_keeps_what_it_did_not_write() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    fs::write(
        d.join("s.toml"),
        "model = \"lambert\"\n[params]\nkd = 0.5\n[gonio]\nrandom = { count = 20, seed = 1 }\n",
    )
    .unwrap();
    // a user's own folder with a gonio.csv: refused, untouched
    fs::create_dir(d.join("set")).unwrap();
    fs::write(d.join("set/gonio.csv"), "mine").unwrap();
    let o = run(&["synth", "--config", "s.toml", "--out", "set", "-q"], d);
    refused(&o, "not a folder synth wrote");
    assert_eq!(fs::read_to_string(d.join("set/gonio.csv")).unwrap(), "mine");
    assert_eq!(fs::read_dir(d.join("set")).unwrap().count(), 1);
    // --force writes over it
    ok(&run(
        &[
            "synth", "--config", "s.toml", "--out", "set", "--force", "-q",
        ],
        d,
    ));
    assert!(fs::read_to_string(d.join("set/gonio.csv"))
        .unwrap()
        .starts_with("theta_i"));
    // in synth's own folder, a user's new file is kept across runs, and one that a new set
    // would replace is refused
    fs::write(d.join("set/notes.txt"), "mine").unwrap();
    ok(&run(
        &["synth", "--config", "s.toml", "--out", "set", "-q"],
        d,
    ));
    assert_eq!(fs::read_to_string(d.join("set/notes.txt")).unwrap(), "mine");
    fs::write(
        d.join("s2.toml"),
        "model = \"lambert\"\n[params]\nkd = 0.5\n[capture]\nwidth = 4\nheight = 4\nsize_mm = [1.0, 1.0]\n\
         [[capture.images]]\nlight = { type = \"directional\", theta_deg = 30.0, phi_deg = 0.0, irradiance = 1.0 }\n\
         camera = { type = \"orthographic\", theta_deg = 0.0, phi_deg = 0.0 }\n",
    )
    .unwrap();
    fs::write(d.join("set/capture.toml"), "my own").unwrap();
    let o = run(&["synth", "--config", "s2.toml", "--out", "set", "-q"], d);
    if o.status.code() == Some(2) && stderr(&o).contains("capture.toml is not a file synth wrote") {
        assert_eq!(
            fs::read_to_string(d.join("set/capture.toml")).unwrap(),
            "my own"
        );
    } else {
        panic!(
            "expected a refusal to replace the user's capture.toml: {}",
            stderr(&o)
        );
    }
    // a linked output folder stays a link; its target's own files stay put
    fs::create_dir(d.join("real")).unwrap();
    std::os::unix::fs::symlink("real", d.join("link")).unwrap();
    ok(&run(
        &["synth", "--config", "s.toml", "--out", "link", "-q"],
        d,
    ));
    assert!(fs::symlink_metadata(d.join("link"))
        .unwrap()
        .file_type()
        .is_symlink());
    fs::write(d.join("real/mine.txt"), "keep").unwrap();
    ok(&run(
        &["synth", "--config", "s.toml", "--out", "link", "-q"],
        d,
    ));
    assert!(fs::symlink_metadata(d.join("link"))
        .unwrap()
        .file_type()
        .is_symlink());
    assert_eq!(fs::read_to_string(d.join("real/mine.txt")).unwrap(), "keep");
    assert!(d.join("real/gonio.csv").is_file());
    assert!(!common::snapshot(d)
        .iter()
        .any(|(n, _)| n.contains(".fibrefit-")));
}

#[test]
fn a_late_signal_leaves_all_old_or_all_new() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    small_set(d);
    let bin = assert_cmd::cargo::cargo_bin("fibrefit");
    let args = [
        "render", "--params", "o.json", "--object", "torus", "--size", "96", "96", "--out",
        "pic.exr", "--aovs", "aovs", "-q",
    ];
    ok(&run(&args, d));
    let files = [
        "pic.exr",
        "aovs/normal.exr",
        "aovs/tangent.exr",
        "aovs/position.exr",
    ];
    let stamp = |f: &str| fs::metadata(d.join(f)).unwrap().modified().unwrap();
    // measure one run, then interrupt runs at delays spread across it (the commit included)
    let t = std::time::Instant::now();
    ok(&run(&args, d));
    let whole = t.elapsed();
    for k in 0..12u32 {
        let old: Vec<_> = files.iter().map(|f| stamp(f)).collect();
        let child = std::process::Command::new(&bin)
            .current_dir(d)
            .args(args)
            .stderr(std::process::Stdio::piped())
            .spawn()
            .unwrap();
        std::thread::sleep(whole.mul_f64(0.5 + 0.06 * k as f64));
        let _ = std::process::Command::new("kill")
            .args(["-TERM", &child.id().to_string()])
            .status();
        let out = child.wait_with_output().unwrap();
        let new: Vec<_> = files.iter().map(|f| stamp(f)).collect();
        let changed = old.iter().zip(&new).filter(|(a, b)| a != b).count();
        let e = String::from_utf8_lossy(&out.stderr);
        assert!(
            changed == 0 || changed == files.len(),
            "run {k}: {changed} of {} outputs changed ({e})",
            files.len()
        );
        if out.status.code() == Some(130) && changed == 0 {
            assert!(e.contains("no output was written"), "{e}");
        }
        if out.status.code() == Some(130) && changed > 0 {
            assert!(e.contains("after the outputs were written"), "{e}");
        }
    }
    assert!(!common::snapshot(d)
        .iter()
        .any(|(n, _)| n.contains(".fibrefit-")));
}

#[test]
fn closed_and_full_streams_exit_cleanly() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    small_set(d);
    let full = || {
        fs::OpenOptions::new()
            .write(true)
            .open("/dev/full")
            .unwrap()
    };
    // stdout on a full disk: exit 2 naming it; stderr full: still exit 2, no panic
    for args in [
        vec!["inspect", "g.csv"],
        vec!["inspect", "--json", "g.csv"],
        vec![
            "fit", "g.csv", "--model", "lambert", "--out", "z.json", "--json",
        ],
    ] {
        let o = std::process::Command::new(assert_cmd::cargo::cargo_bin("fibrefit"))
            .current_dir(d)
            .args(&args)
            .stdout(full())
            .output()
            .unwrap();
        refused(&o, "standard output: No space left on device");
        let o = std::process::Command::new(assert_cmd::cargo::cargo_bin("fibrefit"))
            .current_dir(d)
            .args(&args)
            .stdout(full())
            .stderr(full())
            .output()
            .unwrap();
        assert_eq!(o.status.code(), Some(2), "{args:?}");
    }
    let o = std::process::Command::new(assert_cmd::cargo::cargo_bin("fibrefit"))
        .current_dir(d)
        .args(["inspect", "missing.csv"])
        .stderr(full())
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(2));
    // a reader that goes away: exit 0, as Unix tools do
    let mut child = std::process::Command::new(assert_cmd::cargo::cargo_bin("fibrefit"))
        .current_dir(d)
        .args(["eval", "--params", "o.json", "--queries", &queries()])
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    drop(child.stdout.take());
    let status = child.wait().unwrap();
    assert_eq!(status.code(), Some(0));
}

#[test]
fn work_beyond_the_budgets_is_refused_up_front() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    small_set(d);
    for (size, fragment) in [
        (["4294967296", "4294967296"], "expected 1 to 32 M pixels"),
        (["1", "67108864"], "expected 1 to 32 M pixels"),
    ] {
        let o = run(
            &[
                "render", "--params", "o.json", "--size", size[0], size[1], "--out", "r.png",
            ],
            d,
        );
        refused(&o, fragment);
    }
    let o = run(
        &[
            "render",
            "--params",
            "o.json",
            "--size",
            "8192",
            "4096",
            "--supersample",
            "16",
            "--out",
            "r.png",
        ],
        d,
    );
    refused(&o, "rays");
    for (i, synth) in [
        "[gonio]\nrandom = { count = 100000000000, seed = 1 }\n",
        "[gonio]\ngrid = { theta_i = [0.0], phi_i = [0.0], theta_o = [0.0], phi_o = [0.0] }\n",
        "[capture]\nwidth = 100000\nheight = 100000\nsize_mm = [1.0, 1.0]\n[[capture.images]]\n\
         light = { type = \"directional\", theta_deg = 30.0, phi_deg = 0.0, irradiance = 1.0 }\n\
         camera = { type = \"orthographic\", theta_deg = 0.0, phi_deg = 0.0 }\n",
        "[topology_map]\nwidth = 20000\nheight = 20000\nseed = 1\nwaves = 4\n\
         [gonio]\nrandom = { count = 10, seed = 1 }\n",
    ]
    .iter()
    .enumerate()
    {
        let mut text = format!("model = \"lambert\"\n[params]\nkd = 0.5\n{synth}");
        if i == 1 {
            // a 1e16-point grid: four lists of 10 000 values
            let list = (0..10_000)
                .map(|k| format!("{:.4}", k as f64 * 0.008))
                .collect::<Vec<_>>()
                .join(", ");
            text = format!(
                "model = \"lambert\"\n[params]\nkd = 0.5\n[gonio]\ngrid = {{ theta_i = [{list}], phi_i = [{list}], theta_o = [{list}], phi_o = [{list}] }}\n"
            );
        }
        fs::write(d.join("s.toml"), text).unwrap();
        let o = run(&["synth", "--config", "s.toml", "--out", "big", "-q"], d);
        refused(&o, "s.toml:");
        assert!(!d.join("big").exists());
    }
    for (cfg, fragment) in [
        (
            "[optimizer]\nglobal_candidates = 1000000000\n",
            "global_candidates",
        ),
        (
            "[knobs]\nquadrature_order = 1024\nazimuth_nodes = 1024\n",
            "quadrature nodes per model evaluation",
        ),
        ("starts = 1000000\n", "starts"),
        (
            // auto with every knob at its documented maximum: refused with the estimate
            "starts = 1000\n[optimizer]\nmax_iterations = 100000\nglobal_candidates = 100000\n\
             global_subsample = 1000000\n[knobs]\nquadrature_order = 256\nazimuth_nodes = 256\n\
             histogram_bins = 65536\n",
            "sample evaluations",
        ),
    ] {
        fs::write(
            d.join("c.toml"),
            format!(
                "model = \"{}\"\n{cfg}",
                if cfg.contains("65536") {
                    "auto"
                } else {
                    "poulin-fournier"
                }
            ),
        )
        .unwrap();
        let o = run(
            &[
                "fit", "g.csv", "--config", "c.toml", "--out", "c.json", "-q",
            ],
            d,
        );
        refused(&o, fragment);
    }
}
