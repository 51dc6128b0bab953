//! The fuzz layer (src/model/fuzz.rs): recovered from noisy synthetic data, needed by the real
//! felt's grazing forward peak, read and refused at the command line.

mod common;

use assert_cmd::Command;
use fibrefit::fit::config::FitConfig;
use fibrefit::model::ModelId;

fn fibrefit() -> Command {
    Command::cargo_bin("fibrefit").expect("binary built")
}

#[test]
fn the_fuzz_layer_is_recovered_from_noisy_data() {
    let dir = tempfile::tempdir().unwrap();
    let synth = dir.path().join("s.toml");
    std::fs::write(
        &synth,
        "model = \"poulin-fournier\"\n[params]\nkd = 0.3\nks = 0.3\nexponent = 20\nspacing = 2.4\n\
         fibre_azimuth_deg = 10\nfuzz = 3.0\nfuzz_depth = 0.2\nfuzz_asymmetry = 0.6\n\
         [gonio]\nrandom = { count = 1200, seed = 3, max_theta_deg = 80 }\n\
         [noise]\nrelative = 0.01\nseed = 5\n",
    )
    .unwrap();
    fibrefit::synth::run(
        &synth,
        &dir.path().join("d"),
        &fibrefit::progress::Progress::quiet(),
    )
    .unwrap();
    let data =
        fibrefit::load::load_data(&dir.path().join("d/gonio.csv"), &Default::default()).unwrap();
    // starts away from the truth: a deep isotropic layer
    let cfg: FitConfig = toml::from_str(
        "model = \"poulin-fournier\"\n[parameters]\nspacing = { value = 3, min = 2, max = 6 }\n\
         fibre_azimuth_deg = { value = 0 }\nexponent = { value = 10, max = 1000 }\n\
         fuzz = { value = 1 }\nfuzz_depth = { value = 2 }\nfuzz_asymmetry = { value = 0 }\n",
    )
    .unwrap();
    let o = fibrefit::fit::fit(&data, &cfg, &fibrefit::progress::Progress::quiet()).unwrap();
    for (name, truth) in [("fuzz", 3.0), ("fuzz_depth", 0.2), ("fuzz_asymmetry", 0.6)] {
        let r = o.records.iter().find(|r| r.name == name).unwrap();
        let se = r.std_error[0].expect("a standard error");
        assert!(
            (r.value[0] - truth).abs() < 4.0 * se,
            "{name} {} +/- {se} (truth {truth})",
            r.value[0]
        );
    }
    assert_eq!(
        o.quality.verdict, "fits within the noise",
        "{:?}",
        o.quality.warnings
    );
}

#[test]
fn on_real_felt_the_fuzz_layer_closes_the_grazing_forward_peak() {
    // poulin-fournier with the fibre-direction spread, with and without the layer
    let auto: FitConfig =
        toml::from_str("model = \"auto\"\nmetric = \"log\"\n[knobs]\nazimuth_nodes = 12\n")
            .unwrap();
    let plain_cfg = auto.for_rung(ModelId::PoulinFournier);
    let mut fuzz_cfg = plain_cfg.clone();
    fuzz_cfg
        .parameters
        .insert("fuzz_depth".into(), Default::default());
    let plain = common::felt_heldout(&plain_cfg);
    let fuzz = common::felt_heldout(&fuzz_cfg);
    eprintln!("felt held-out: without {plain:?}; with the fuzz layer {fuzz:?}");
    assert!(
        fuzz.log_error <= 0.8 * plain.log_error,
        "log error {} vs {} without",
        fuzz.log_error,
        plain.log_error
    );
    assert!(fuzz.relative_rmse < plain.relative_rmse);
    assert!(
        (fuzz.grazing_forward_ratio - 1.0).abs() < 0.5 * (plain.grazing_forward_ratio - 1.0).abs(),
        "grazing forward data/model {} vs {} without",
        fuzz.grazing_forward_ratio,
        plain.grazing_forward_ratio
    );
}

#[test]
fn eval_reads_the_layer_and_refuses_bad_values() {
    let dir = tempfile::tempdir().unwrap();
    let q = dir.path().join("q.csv");
    std::fs::write(&q, "theta_i,phi_i,theta_o,phi_o\n70,0,70,180\n70,0,70,0\n").unwrap();
    let params = |extra: &str| {
        let p = dir.path().join("p.toml");
        std::fs::write(&p, format!("model = \"lambert\"\nkd = 0.5\n{extra}")).unwrap();
        p
    };
    // a forward-scattering layer: the grazing mirror side outshines the grazing back side
    let out = fibrefit()
        .args(["eval", "--queries"])
        .arg(&q)
        .arg("--params")
        .arg(params(
            "fuzz = 2.0\nfuzz_depth = 0.3\nfuzz_asymmetry = 0.7\n",
        ))
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let text = String::from_utf8(out.stdout).unwrap();
    let brdf: Vec<f64> = text
        .lines()
        .skip(1)
        .map(|l| l.split(',').nth(4).unwrap().parse().unwrap())
        .collect();
    assert!(brdf[0] > 2.0 * brdf[1], "{brdf:?}");
    for (extra, says) in [
        ("fuzz_depth = 0.3\n", "needs the layer's weight `fuzz`"),
        ("fuzz = 1\nfuzz_depth = 20\n", "fuzz_depth"),
        (
            "fuzz = 1\nfuzz_depth = 0.3\nfuzz_asymmetry = 1\n",
            "fuzz_asymmetry",
        ),
        ("fuzz = -1\nfuzz_depth = 0.3\n", "fuzz"),
    ] {
        let out_file = dir.path().join("never.csv");
        let out = fibrefit()
            .args(["eval", "--queries"])
            .arg(&q)
            .arg("--params")
            .arg(params(extra))
            .arg("--out")
            .arg(&out_file)
            .output()
            .unwrap();
        assert_eq!(out.status.code(), Some(2), "{extra}");
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(err.contains(says), "{extra}: {err}");
        assert!(!out_file.exists());
    }
}

#[test]
fn fit_with_the_fuzz_flag_writes_the_layer() {
    let dir = tempfile::tempdir().unwrap();
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    let out = dir.path().join("r.json");
    let run = fibrefit()
        .arg("fit")
        .arg(root.join("data_synthetic/silk/gonio.csv"))
        .args(["--model", "lambert", "--fuzz", "-q", "--out"])
        .arg(&out)
        .output()
        .unwrap();
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    let r: serde_json::Value = serde_json::from_slice(&std::fs::read(&out).unwrap()).unwrap();
    for name in ["fuzz", "fuzz_depth", "fuzz_asymmetry"] {
        assert!(
            r["parameters"][name]["value"].is_number() || r["parameters"][name]["value"].is_array(),
            "{name}: {}",
            r["parameters"]
        );
    }
}
