//! `fibrefit fit CAPTURE --maps DIR`: per-texel maps recovered from a small synthetic capture
//! whose maps are known, with honest standard errors; requests the rung cannot honour refused.

mod common;

use assert_cmd::Command;
use common::{maps_fit, SYNTH};
use fibrefit::load::image_io;
use fibrefit::model::topology::TopologyMap;
use std::path::Path;

fn fibrefit() -> Command {
    Command::cargo_bin("fibrefit").expect("binary built")
}

/// A synthetic capture in `dir`, and a copy of its capture TOML without the maps (the unknowns).
fn capture(dir: &Path) -> std::path::PathBuf {
    capture_of(dir, SYNTH)
}

/// The capture the synth config `synth` describes, without its maps.
fn capture_of(dir: &Path, synth: &str) -> std::path::PathBuf {
    std::fs::write(dir.join("synth.toml"), synth).unwrap();
    fibrefit::synth::run(
        &dir.join("synth.toml"),
        &dir.join("d"),
        &fibrefit::progress::Progress::quiet(),
    )
    .unwrap();
    fibrefit::bench::maps::write_blind(&dir.join("d")).unwrap()
}

fn sorted(mut v: Vec<f64>) -> Vec<f64> {
    v.sort_by(f64::total_cmp);
    v
}

#[test]
fn height_azimuth_and_albedo_maps_are_recovered_with_honest_errors() {
    let dir = tempfile::tempdir().unwrap();
    let blind = capture(dir.path());
    std::fs::write(dir.path().join("fit.toml"), maps_fit(25)).unwrap();
    let out = dir.path().join("maps");
    let run = fibrefit()
        .arg("fit")
        .arg(&blind)
        .arg("--config")
        .arg(dir.path().join("fit.toml"))
        .arg("--out")
        .arg(dir.path().join("r.json"))
        .arg("--maps")
        .arg(&out)
        .output()
        .unwrap();
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    // the report (stdout) names the mapped parameters per texel, with the real work of both
    // stages and a summary of each map (issue 22 item 6)
    let report = String::from_utf8_lossy(&run.stdout).into_owned();
    for name in ["height", "map_scale", "fibre_azimuth_deg", "kd"] {
        let line = report
            .lines()
            .find(|l| l.trim_start().starts_with(&format!("{name} ")))
            .unwrap_or_else(|| panic!("no {name} in {report}"));
        assert!(
            line.contains("per texel") && !line.contains("fixed"),
            "{line}"
        );
    }
    let iterations: u64 = report
        .lines()
        .find(|l| l.contains("# iterations"))
        .and_then(|l| l.split('=').nth(1))
        .and_then(|v| v.split_whitespace().next())
        .and_then(|v| v.parse().ok())
        .unwrap();
    assert!(iterations > 0, "{report}");
    assert!(!report.contains("wall time          = 0.000 s"), "{report}");
    assert!(report.contains("[[Maps]]"), "{report}");
    let stage = report
        .lines()
        .find(|l| l.contains("global stage       ="))
        .unwrap();
    assert!(
        stage.contains("LM iterations") && !stage.contains(" 0 LM"),
        "{stage}"
    );
    assert!(
        report.contains("texel stage        = 256 texels"),
        "{report}"
    );
    for name in ["height", "fibre_azimuth", "kd"] {
        let line = report
            .lines()
            .skip_while(|l| !l.starts_with("[[Maps]]"))
            .find(|l| l.trim_start().starts_with(&format!("{name} ")))
            .unwrap_or_else(|| panic!("no summary of {name} in {report}"));
        assert!(line.contains("% of 256 texels"), "{line}");
    }
    let read = |n: &str| image_io::read(&out.join(n), None, None).unwrap();
    let (h, h_se, p, p_se) = (
        read("height.exr"),
        read("height_std_error.exr"),
        read("fibre_azimuth.exr"),
        read("fibre_azimuth_std_error.exr"),
    );
    let (kd, kd_se) = (read("kd.exr"), read("kd_std_error.exr"));
    assert!(out.join("residual.exr").exists());
    let topo = TopologyMap::load(&dir.path().join("d/topology.png")).unwrap();
    let tan = TopologyMap::load_as(&dir.path().join("d/tangent.png"), "tangent map").unwrap();
    let (mut zh, mut zp, mut zk) = (vec![], vec![], vec![]);
    let (mut eh, mut ep) = (0.0, 0.0);
    for y in 0..16 {
        for x in 0..16 {
            let th = 0.9 + 0.6 * (2.0 * topo.texel(x, y) - 1.0);
            let tp = -90.0 + 180.0 * tan.texel(x, y);
            let dh = h.pixel(x, y)[0] as f64 - th;
            let dp = (p.pixel(x, y)[0] as f64 - tp + 90.0).rem_euclid(180.0) - 90.0;
            eh += dh * dh;
            ep += dp * dp;
            zh.push((dh / h_se.pixel(x, y)[0] as f64).abs());
            zp.push((dp / p_se.pixel(x, y)[0] as f64).abs());
            zk.push(((kd.pixel(x, y)[0] as f64 - 0.4) / kd_se.pixel(x, y)[0] as f64).abs());
        }
    }
    let n = 256.0;
    let (rms_h, rms_p) = ((eh / n).sqrt(), (ep / n).sqrt());
    eprintln!("rms error: H {rms_h:.4} fibre radii, psi {rms_p:.3} deg");
    // accuracy (a texel in the other flat branch at d = 2 costs ~0.08 here; its error covers it)
    assert!(rms_h < 0.15 && rms_p < 1.5, "H {rms_h}, psi {rms_p}");
    // honest standard errors: |error| / se behaves like |N(0, 1)| for the bulk of the texels
    for (name, z) in [("H", zh), ("psi", zp), ("kd", zk)] {
        let z = sorted(z);
        let median = z[z.len() / 2];
        let within = z.iter().filter(|x| **x <= 3.0).count() as f64 / z.len() as f64;
        eprintln!("{name}: median |z| {median:.2}, within 3 se {within:.3}");
        assert!((0.4..=1.1).contains(&median), "{name}: median |z| {median}");
        assert!(within >= 0.95, "{name}: {within} within 3 se");
    }
    // the result names the maps with their units; the globals are recovered too
    let r: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.path().join("r.json")).unwrap()).unwrap();
    assert_eq!(r["maps"]["maps"]["height"]["file"], "height.exr");
    assert!(r["maps"]["maps"]["height"]["unit"]
        .as_str()
        .unwrap()
        .contains("fibre radii"));
    assert!(r["maps"]["maps"]["fibre_azimuth"]["unit"]
        .as_str()
        .unwrap()
        .contains("degrees"));
    // the maps' summary in the result: median and 5-95 % range, fraction flagged
    let summary = r["maps"]["summary"].as_array().unwrap();
    let h = summary.iter().find(|m| m["name"] == "height").unwrap();
    let (med, p5, p95) = (
        h["median"].as_f64().unwrap(),
        h["p5"].as_f64().unwrap(),
        h["p95"].as_f64().unwrap(),
    );
    assert!(p5 < med && med < p95 && (med - 0.9).abs() < 0.2, "{h}");
    assert!(
        (0.0..0.5).contains(&h["flagged_fraction"].as_f64().unwrap()),
        "{h}"
    );
    assert!(
        r["maps"]["method"]["global_stage_seconds"]
            .as_f64()
            .unwrap()
            > 0.0
    );
    assert!(r["maps"]["method"]["texel_stage_seconds"].as_f64().unwrap() > 0.0);
    assert_eq!(
        r["parameters"]["height"]["fixed_reason"]
            .as_str()
            .unwrap()
            .split(' ')
            .take(2)
            .collect::<Vec<_>>(),
        ["per", "texel"]
    );
    let e = &r["parameters"]["exponent"];
    let (v, se) = (
        e["value"].as_f64().unwrap(),
        e["std_error"].as_f64().unwrap(),
    );
    assert!((v - 40.0).abs() < 5.0 * se + 0.2, "exponent {v} +/- {se}");

    // round trip: synth with the recovered globals and maps renders the captured images within
    // the noise (1 % relative)
    let images = &SYNTH[SYNTH.find("[[capture.images]]").unwrap()..SYNTH.find("[noise]").unwrap()];
    let again = format!(
        "model = \"varying-topology\"\nparams_file = \"r.json\"\n[capture]\nwidth = 16\nheight = 16\n\
         size_mm = [20.0, 20.0]\nmaps = \"maps\"\n{images}"
    );
    std::fs::write(dir.path().join("again.toml"), again).unwrap();
    fibrefit::synth::run(
        &dir.path().join("again.toml"),
        &dir.path().join("again"),
        &fibrefit::progress::Progress::quiet(),
    )
    .unwrap();
    let (mut chi, mut n) = (0.0, 0.0);
    for k in 0..8 {
        let name = format!("img_{k:03}.exr");
        let a = image_io::read(&dir.path().join("d").join(&name), None, None).unwrap();
        let b = image_io::read(&dir.path().join("again").join(&name), None, None).unwrap();
        for (x, y) in a.data.iter().zip(&b.data) {
            chi += ((x - y) as f64 / (0.01 * *y as f64)).powi(2);
            n += 1.0;
        }
    }
    eprintln!(
        "round trip: mean squared difference / noise variance {:.3}",
        chi / n
    );
    assert!((0.7..1.3).contains(&(chi / n)), "{}", chi / n);
    // the re-rendered capture carries the maps as inputs and fits
    let recap = std::fs::read_to_string(dir.path().join("again/capture.toml")).unwrap();
    assert!(recap.contains("height_map = \"height.exr\"") && recap.contains("fibre_azimuth_map"));
    let refit = fibrefit()
        .arg("fit")
        .arg(dir.path().join("again/capture.toml"))
        .arg("--model")
        .arg("varying-topology")
        .arg("--out")
        .arg(dir.path().join("refit.json"))
        .arg("-q")
        .output()
        .unwrap();
    assert!(
        refit.status.success(),
        "{}",
        String::from_utf8_lossy(&refit.stderr)
    );
}

#[test]
fn map_requests_the_rung_or_data_cannot_honour_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let capture = root.join("data_synthetic/loose/capture.toml");
    let gonio = root.join("data_synthetic/silk/gonio.csv");
    let cases = [
        (
            "model = \"lambert\"\n[maps]\nheight = true\n",
            &capture,
            "no fibre topology",
        ),
        (
            "model = \"lambert\"\n[maps]\nfibre_azimuth = true\n",
            &capture,
            "no fibre direction",
        ),
        ("model = \"poulin-fournier\"\n", &capture, "requests no map"),
        (
            "model = \"poulin-fournier\"\n[maps]\nkd = true\n",
            &gonio,
            "needs an image capture",
        ),
        (
            "model = \"poulin-fournier\"\n[maps]\nkd = true\nsmoothness = -1\n",
            &capture,
            "smoothness",
        ),
        (
            "model = \"poulin-fournier\"\n[maps]\nkd = true\nsharpness = 1\n",
            &capture,
            "sharpness",
        ),
    ];
    for (k, (cfg, data, says)) in cases.iter().enumerate() {
        let c = dir.path().join(format!("c{k}.toml"));
        std::fs::write(&c, cfg).unwrap();
        let out = dir.path().join(format!("r{k}.json"));
        let maps = dir.path().join(format!("maps{k}"));
        let run = fibrefit()
            .arg("fit")
            .arg(data)
            .arg("--config")
            .arg(&c)
            .arg("--out")
            .arg(&out)
            .arg("--maps")
            .arg(&maps)
            .args(["-q", "--stride", "4"])
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&run.stderr);
        assert_eq!(run.status.code(), Some(2), "case {k}: {err}");
        assert!(err.contains(says), "case {k}: {err}");
        assert!(!out.exists() && !maps.exists(), "case {k} wrote output");
    }
}

#[test]
fn eval_takes_map_values_per_query_row() {
    // a row with a texel's map values equals the model with those values as its parameters
    let dir = tempfile::tempdir().unwrap();
    let write = |name: &str, text: &str| {
        let p = dir.path().join(name);
        std::fs::write(&p, text).unwrap();
        p
    };
    let base = "model = \"varying-topology\"\nspacing = 2.0\nexponent = 30\nfibre_azimuth_deg = 0\nheight = 0.5\nkd = 0.4\nks = 0.3\n";
    let texel = "model = \"varying-topology\"\nspacing = 2.0\nexponent = 30\nfibre_azimuth_deg = 25\nheight = 0.8\nkd = [0.2, 0.3, 0.1]\nks = [0.5, 0.5, 0.5]\n";
    let rows = "40,10,50,200\n30,90,30,90\n60,0,70,180\n";
    let mapped: String = rows
        .lines()
        .map(|l| format!("{l},0.8,25,0.2,0.3,0.1,0.5\n"))
        .collect();
    let q_mapped = write(
        "qm.csv",
        &format!(
            "theta_i,phi_i,theta_o,phi_o,height,fibre_azimuth_deg,kd_r,kd_g,kd_b,ks\n{mapped}"
        ),
    );
    let q_plain = write("qp.csv", &format!("theta_i,phi_i,theta_o,phi_o\n{rows}"));
    let run = |params: &Path, q: &Path| -> Vec<Vec<f64>> {
        let o = fibrefit()
            .arg("eval")
            .arg("--params")
            .arg(params)
            .arg("--queries")
            .arg(q)
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        String::from_utf8(o.stdout)
            .unwrap()
            .lines()
            .skip(1)
            .map(|l| {
                let f: Vec<f64> = l.split(',').map(|x| x.parse().unwrap()).collect();
                f[f.len() - 6..f.len() - 3].to_vec()
            })
            .collect()
    };
    let a = run(&write("base.toml", base), &q_mapped);
    let b = run(&write("texel.toml", texel), &q_plain);
    for (x, y) in a.iter().flatten().zip(b.iter().flatten()) {
        assert!(
            (x - y).abs() <= 1e-12 * y.abs().max(1e-12),
            "{a:?} vs {b:?}"
        );
    }
    // a texel column out of range is refused, naming the line
    let bad = write(
        "bad.csv",
        "theta_i,phi_i,theta_o,phi_o,fibre_azimuth_deg\n30,0,30,180,120\n",
    );
    let o = fibrefit()
        .arg("eval")
        .arg("--params")
        .arg(dir.path().join("base.toml"))
        .arg("--queries")
        .arg(&bad)
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&o.stderr).contains("bad.csv:2"));
}

#[test]
fn tiles_fitted_as_parallel_processes_merge_into_the_single_run_bit_for_bit() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let small = SYNTH.replace("width = 24\nheight = 24", "width = 12\nheight = 12");
    std::fs::write(d.join("synth.toml"), small).unwrap();
    fibrefit::synth::run(
        &d.join("synth.toml"),
        &d.join("d"),
        &fibrefit::progress::Progress::quiet(),
    )
    .unwrap();
    let capture = d.join("d/capture.toml");
    let cfg = d.join("fit.toml");
    std::fs::write(&cfg, maps_fit(25).replace("kd = true\n", "")).unwrap();
    let fit = |extra: &[&str]| {
        let mut c = std::process::Command::new(env!("CARGO_BIN_EXE_fibrefit"));
        c.arg("fit")
            .arg(&capture)
            .arg("--config")
            .arg(&cfg)
            .arg("-q");
        c.args(extra);
        c
    };
    let ok = |mut c: std::process::Command| {
        let o = c.output().unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    };
    let p = |x: &str| d.join(x).display().to_string();
    ok(fit(&["--out", &p("single.json"), "--maps", &p("single")]));
    ok(fit(&["--out", &p("g.json"), "--map-globals"]));
    // the tiles as parallel local processes, as a job array would run them
    let children: Vec<_> = (0..3)
        .map(|i| {
            fit(&[
                "--globals",
                &p("g.json"),
                "--tile",
                &format!("{i}/3"),
                "--maps",
                &p("tiles"),
            ])
            .spawn()
            .unwrap()
        })
        .collect();
    for mut c in children {
        assert!(c.wait().unwrap().success());
    }
    let merge = |tiles: &str, globals: &str, out: &str| {
        std::process::Command::new(env!("CARGO_BIN_EXE_fibrefit"))
            .args(["merge-maps", &p(tiles), "--globals", &p(globals)])
            .args([
                "--maps",
                &p(&format!("{out}_maps")),
                "--out",
                &p(&format!("{out}.json")),
                "-q",
            ])
            .output()
            .unwrap()
    };
    let o = merge("tiles", "g.json", "merged");
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    for f in [
        "height.exr",
        "height_std_error.exr",
        "fibre_azimuth.exr",
        "fibre_azimuth_std_error.exr",
        "residual.exr",
    ] {
        let a = std::fs::read(d.join("single").join(f)).unwrap();
        let b = std::fs::read(d.join("merged_maps").join(f)).unwrap();
        assert!(
            a == b,
            "{f} differs between the single run and the merged tiles"
        );
    }
    // nor do the maps depend on how many threads fit the texels, in whatever order they reach
    // them (which texels read a shared column table is planned before any is fitted)
    for threads in ["1", "3"] {
        let maps = format!("threads_{threads}");
        let mut c = fit(&["--out", &p(&format!("{maps}.json")), "--maps", &p(&maps)]);
        c.env("RAYON_NUM_THREADS", threads);
        ok(c);
        for f in ["height.exr", "height_std_error.exr", "residual.exr"] {
            let a = std::fs::read(d.join("single").join(f)).unwrap();
            let b = std::fs::read(d.join(&maps).join(f)).unwrap();
            assert!(
                a == b,
                "{f} differs between the default run and {threads} thread(s)"
            );
        }
    }
    // and so does the maps' summary in the result
    let read = |f: &str| -> serde_json::Value {
        serde_json::from_slice(&std::fs::read(d.join(f)).unwrap()).unwrap()
    };
    let summary = read("single.json")["maps"]["summary"].clone();
    assert!(
        summary.as_array().is_some_and(|s| s.len() == 2),
        "{summary}"
    );
    // (to the last bits: the tiles' values pass through JSON)
    let merged = read("merged.json")["maps"]["summary"].clone();
    for (a, b) in summary
        .as_array()
        .unwrap()
        .iter()
        .zip(merged.as_array().unwrap())
    {
        assert_eq!(a["name"], b["name"]);
        for k in [
            "median",
            "p5",
            "p95",
            "median_std_error",
            "flagged_fraction",
        ] {
            let (x, y) = (a[k].as_f64().unwrap(), b[k].as_f64().unwrap());
            assert!((x - y).abs() <= 1e-12 * x.abs().max(1.0), "{k}: {a} vs {b}");
        }
    }
    // the result records each map's hash (the same for the single run and the merged tiles,
    // whose maps are the same bits); copied with its maps the result renders anywhere, and a
    // map that is not the fit's is refused, naming both hashes
    let hashes = read("single.json")["maps"]["sha256"].clone();
    assert_eq!(hashes, read("merged.json")["maps"]["sha256"]);
    assert!(
        hashes["height.exr"].as_str().is_some_and(|h| h.len() == 64),
        "{hashes}"
    );
    let moved = tempfile::tempdir().unwrap();
    std::fs::create_dir(moved.path().join("single")).unwrap();
    for f in hashes.as_object().unwrap().keys() {
        std::fs::copy(
            d.join("single").join(f),
            moved.path().join("single").join(f),
        )
        .unwrap();
    }
    std::fs::copy(d.join("single.json"), moved.path().join("fit.json")).unwrap();
    let render = || {
        std::process::Command::new(env!("CARGO_BIN_EXE_fibrefit"))
            .current_dir(d)
            .args([
                "render", "--object", "swatch", "--size", "16", "16", "--out", "r.png", "--params",
            ])
            .arg(moved.path().join("fit.json"))
            .output()
            .unwrap()
    };
    let o = render();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    std::fs::remove_file(d.join("r.png")).unwrap();
    std::fs::copy(
        d.join("single/height_std_error.exr"),
        moved.path().join("single/height.exr"),
    )
    .unwrap();
    let o = render();
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{err}");
    assert!(
        err.contains("height.exr is not the one this result was fitted with"),
        "{err}"
    );
    assert!(
        err.contains(hashes["height.exr"].as_str().unwrap()),
        "{err}"
    );
    assert!(!d.join("r.png").exists());
    // refused, writing nothing: a tile index out of range, a missing tile, other globals
    let o = fit(&[
        "--globals",
        &p("g.json"),
        "--tile",
        "3/3",
        "--maps",
        &p("tiles"),
    ])
    .output()
    .unwrap();
    assert_eq!(o.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&o.stderr).contains("0 <= I < N"));
    std::fs::create_dir(d.join("partial")).unwrap();
    for i in [0, 2] {
        std::fs::copy(
            d.join(format!("tiles/tile_{i}_of_3.json")),
            d.join(format!("partial/tile_{i}_of_3.json")),
        )
        .unwrap();
    }
    let o = merge("partial", "g.json", "never");
    assert_eq!(o.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&o.stderr).contains("tiles 1 of 3 are missing"));
    let mut other: serde_json::Value =
        serde_json::from_slice(&std::fs::read(d.join("g.json")).unwrap()).unwrap();
    other["parameters"]["exponent"]["value"] = serde_json::json!(41.0);
    std::fs::write(d.join("other.json"), other.to_string()).unwrap();
    let o = merge("tiles", "other.json", "never");
    assert_eq!(o.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&o.stderr).contains("other globals"));
    assert!(!d.join("never.json").exists() && !d.join("never_maps").exists());
}

#[test]
fn globals_that_trade_off_with_the_maps_are_said_to() {
    // light and view within 10 deg of the normal: kd, ks, the exponent and the heights trade
    // off (reports/maps_accuracy.md, "near normal")
    let near_normal = SYNTH
        .split("[[capture.images]]")
        .next()
        .unwrap()
        .to_string()
        + &[[5, 0, 0, 0], [10, 90, 5, 270], [10, 180, 5, 0], [10, 270, 5, 90], [8, 45, 8, 225], [8, 135, 8, 315]]
            .iter()
            .map(|[lt, lp, vt, vp]| {
                format!(
                    "[[capture.images]]\nlight = {{ type = \"directional\", theta_deg = {lt}, phi_deg = {lp}, irradiance = 1.0 }}\ncamera = {{ type = \"orthographic\", theta_deg = {vt}, phi_deg = {vp} }}\n"
                )
            })
            .collect::<String>()
        + "[noise]\nrelative = 0.01\nseed = 5\n";
    let fit_toml = maps_fit(25).replace("kd = true\n", "");
    let mut widened = Vec::new();
    for (name, synth) in [("near", near_normal.as_str()), ("eight", SYNTH)] {
        let dir = tempfile::tempdir().unwrap();
        let blind = capture_of(dir.path(), synth);
        std::fs::write(dir.path().join("fit.toml"), &fit_toml).unwrap();
        fibrefit()
            .arg("fit")
            .arg(&blind)
            .arg("--config")
            .arg(dir.path().join("fit.toml"))
            .arg("--out")
            .arg(dir.path().join("r.json"))
            .arg("--maps")
            .arg(dir.path().join("m"))
            .arg("-q")
            .assert()
            .success();
        let r: serde_json::Value =
            serde_json::from_slice(&std::fs::read(dir.path().join("r.json")).unwrap()).unwrap();
        let said = r["warnings"]
            .as_array()
            .unwrap()
            .iter()
            .any(|w| w.as_str().unwrap().contains("trade off with the maps"));
        widened.push((name, said));
    }
    assert_eq!(widened, [("near", true), ("eight", false)]);
}
