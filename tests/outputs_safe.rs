//! Issue 12: outputs never destroy data. An output naming an input is refused; outputs go
//! through symlinks and hard links and keep an existing file's mode; a bad --report is found
//! before the fit; SIGTERM leaves no temporary files; a failed synth leaves the old dataset whole;
//! eval is 0 at the horizon.

use assert_cmd::Command;
use std::fs;
use std::os::unix::fs::PermissionsExt;
use std::path::{Path, PathBuf};

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

fn fibrefit() -> Command {
    Command::cargo_bin("fibrefit").unwrap()
}

/// A small gonio file and a fast config in `d`.
fn inputs(d: &Path) -> (PathBuf, PathBuf) {
    let csv: String = fs::read_to_string(root().join("data_synthetic/brushed/gonio.csv"))
        .unwrap()
        .lines()
        .take(101)
        .map(|l| format!("{l}\n"))
        .collect();
    fs::write(d.join("g.csv"), csv).unwrap();
    fs::write(
        d.join("fit.toml"),
        "model = \"poulin-fournier\"\n[knobs]\nquadrature_order = 8\n[parameters]\nexponent = { value = 100, min = 1, max = 10000 }\n",
    )
    .unwrap();
    (d.join("g.csv"), d.join("fit.toml"))
}

fn fit(data: &Path, config: &Path, out: &Path, extra: &[&str]) -> std::process::Output {
    fibrefit()
        .arg("fit")
        .arg(data)
        .arg("--config")
        .arg(config)
        .arg("--out")
        .arg(out)
        .arg("--quiet")
        .args(extra)
        .output()
        .unwrap()
}

/// The process umask (Linux: /proc/self/status), which a new file's mode must respect.
fn umask() -> u32 {
    let status = std::fs::read_to_string("/proc/self/status").unwrap();
    let line = status.lines().find(|l| l.starts_with("Umask:")).unwrap();
    u32::from_str_radix(line["Umask:".len()..].trim(), 8).unwrap()
}

fn refused(o: &std::process::Output, fragment: &str) {
    let e = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{e}");
    assert!(e.contains(fragment), "expected '{fragment}' in: {e}");
}

#[test]
fn an_output_never_replaces_an_input() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let (data, config) = inputs(d);
    let before = (fs::read(&data).unwrap(), fs::read(&config).unwrap());
    std::os::unix::fs::symlink("g.csv", d.join("alias.csv")).unwrap();
    for out in [
        data.clone(),
        config.clone(),
        d.join("alias.csv"),
        d.join("./g.csv"),
    ] {
        refused(&fit(&data, &config, &out, &[]), "is an input of this run");
    }
    assert_eq!(
        (fs::read(&data).unwrap(), fs::read(&config).unwrap()),
        before
    );
    // eval: the params and the queries
    fs::write(d.join("p.toml"), "kd = 0.5\n").unwrap();
    fs::write(
        d.join("q.csv"),
        "theta_i,phi_i,theta_o,phi_o\n30,0,30,180\n",
    )
    .unwrap();
    for out in ["p.toml", "q.csv"] {
        let o = fibrefit()
            .args(["eval", "--model", "lambert", "--params"])
            .arg(d.join("p.toml"))
            .arg("--queries")
            .arg(d.join("q.csv"))
            .arg("--out")
            .arg(d.join(out))
            .output()
            .unwrap();
        refused(&o, "is an input of this run");
    }
    assert_eq!(fs::read_to_string(d.join("p.toml")).unwrap(), "kd = 0.5\n");
}

#[test]
fn outputs_go_through_links_and_keep_modes() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let (data, config) = inputs(d);
    // symlink: the link stays, its target gets the result
    fs::write(d.join("target.json"), "old").unwrap();
    std::os::unix::fs::symlink("target.json", d.join("link.json")).unwrap();
    assert!(fit(&data, &config, &d.join("link.json"), &[])
        .status
        .success());
    assert!(fs::symlink_metadata(d.join("link.json"))
        .unwrap()
        .file_type()
        .is_symlink());
    assert!(fs::read_to_string(d.join("target.json"))
        .unwrap()
        .contains("fibrefit-result/1"));
    // hard link: both names see the result; the mode is kept
    fs::write(d.join("a.json"), "old").unwrap();
    fs::set_permissions(d.join("a.json"), fs::Permissions::from_mode(0o640)).unwrap();
    fs::hard_link(d.join("a.json"), d.join("b.json")).unwrap();
    assert!(fit(&data, &config, &d.join("a.json"), &[]).status.success());
    assert!(fs::read_to_string(d.join("b.json"))
        .unwrap()
        .contains("fibrefit-result/1"));
    let mode = fs::metadata(d.join("a.json")).unwrap().permissions().mode() & 0o777;
    assert_eq!(mode, 0o640);
    // a new file gets 0666 less the umask (not 0600 whatever the umask)
    assert!(fit(
        &data,
        &config,
        &d.join("new.json"),
        &["--report", d.join("rep").to_str().unwrap()]
    )
    .status
    .success());
    for f in [d.join("new.json"), d.join("rep/report.md")] {
        let mode = fs::metadata(&f).unwrap().permissions().mode() & 0o777;
        assert_eq!(mode, 0o666 & !umask(), "{}: {mode:o}", f.display());
    }
}

#[test]
fn a_bad_report_directory_is_found_before_the_fit() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let (data, config) = inputs(d);
    fs::write(d.join("afile"), "x").unwrap();
    let out = d.join("r.json");
    let o = fit(
        &data,
        &config,
        &out,
        &["--report", d.join("afile").to_str().unwrap()],
    );
    refused(&o, "exists and is not a directory");
    assert!(!out.exists());
    let o = fit(
        &data,
        &config,
        &out,
        &["--report", d.join("afile/sub").to_str().unwrap()],
    );
    refused(&o, "is not a directory");
    assert!(!out.exists());
}

#[test]
fn sigterm_leaves_no_temporary_files() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let bin = assert_cmd::cargo::cargo_bin("fibrefit");
    let mut child = std::process::Command::new(bin)
        .arg("fit")
        .arg(root().join("data_synthetic/silk/gonio.csv"))
        .arg("--config")
        .arg(root().join("configs/fit_silk.toml"))
        .arg("--out")
        .arg(d.join("out.json"))
        .arg("--quiet")
        .spawn()
        .unwrap();
    // wait until the output's temporary file exists, then interrupt
    let t = std::time::Instant::now();
    let has_temp = || {
        fs::read_dir(d)
            .unwrap()
            .flatten()
            .any(|e| e.file_name().to_string_lossy().starts_with(".fibrefit-"))
    };
    while !has_temp() && t.elapsed().as_secs() < 20 {
        std::thread::sleep(std::time::Duration::from_millis(5));
    }
    let finished = child.try_wait().unwrap().is_some();
    std::process::Command::new("kill")
        .args(["-TERM", &child.id().to_string()])
        .status()
        .unwrap();
    let status = child.wait().unwrap();
    let left: Vec<_> = fs::read_dir(d)
        .unwrap()
        .flatten()
        .map(|e| e.file_name())
        .collect();
    if !finished && status.code() == Some(130) {
        assert!(left.is_empty(), "left behind: {left:?}");
    }
    // a stale temporary of a dead process is swept by the next run writing there
    let stale = d.join(".fibrefit-999999999-0123456789ab.tmp");
    fs::write(&stale, "").unwrap();
    let (data, config) = inputs(d);
    assert!(fit(&data, &config, &d.join("r.json"), &[]).status.success());
    assert!(!stale.exists());
}

#[test]
fn a_failed_synth_leaves_the_old_dataset_whole() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let good =
        "model = \"lambert\"\n[params]\nkd = 0.5\n[gonio]\nrandom = { count = 20, seed = 1 }\n";
    fs::write(d.join("good.toml"), good).unwrap();
    let out = d.join("set");
    let o = fibrefit()
        .args(["synth", "--config"])
        .arg(d.join("good.toml"))
        .arg("--out")
        .arg(&out)
        .arg("--quiet")
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    fs::write(out.join("notes.txt"), "mine").unwrap();
    let snapshot = |p: &Path| {
        let mut v: Vec<(String, Vec<u8>)> = fs::read_dir(p)
            .unwrap()
            .flatten()
            .map(|e| {
                (
                    e.file_name().to_string_lossy().into_owned(),
                    fs::read(e.path()).unwrap(),
                )
            })
            .collect();
        v.sort();
        v
    };
    let before = snapshot(&out);
    // a config whose gonio part renders, then the capture part fails
    let bad = format!(
        "{}[capture]\nwidth = 4\nheight = 4\nsize_mm = [10, 10]\nformat = \"tiff\"\n[[capture.images]]\n\
         light = {{ type = \"directional\", theta_deg = 30, phi_deg = 0, irradiance = 1.0 }}\n\
         camera = {{ type = \"orthographic\", theta_deg = 0, phi_deg = 0 }}\n[noise]\nrelative = 0.5\nseed = 9\n",
        good
    );
    fs::write(d.join("bad.toml"), bad).unwrap();
    let o = fibrefit()
        .args(["synth", "--config"])
        .arg(d.join("bad.toml"))
        .arg("--out")
        .arg(&out)
        .output()
        .unwrap();
    refused(&o, "capture.format");
    assert_eq!(snapshot(&out), before, "the old set changed");
    let strays: Vec<_> = fs::read_dir(d)
        .unwrap()
        .flatten()
        .filter(|e| e.file_name().to_string_lossy().starts_with(".fibrefit"))
        .collect();
    assert!(strays.is_empty(), "{strays:?}");
}

#[test]
fn eval_is_zero_at_the_horizon() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    fs::write(
        d.join("p.toml"),
        "kd = 0.5\nks = 0.2\nexponent = 10\nspacing = 2.5\n",
    )
    .unwrap();
    fs::write(
        d.join("q.csv"),
        "theta_i,phi_i,theta_o,phi_o\n90,0,30,180\n30,0,90,180\n90,90,90,270\n",
    )
    .unwrap();
    for model in [
        "lambert",
        "poulin-fournier",
        "varying-topology",
        "hast-diffuse",
        "max-normal",
    ] {
        let o = fibrefit()
            .args(["eval", "--quiet", "--model", model, "--params"])
            .arg(d.join("p.toml"))
            .arg("--queries")
            .arg(d.join("q.csv"))
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        for line in String::from_utf8_lossy(&o.stdout).lines().skip(1) {
            let f: Vec<f64> = line.split(',').map(|x| x.parse().unwrap()).collect();
            assert_eq!((f[4], f[5]), (0.0, 0.0), "{model}: {line}");
        }
    }
}
