//! The Ward fallback (`ward_fallback` in the result) says when it is far off the fitted model or
//! ends at a bound of its range: on stderr, in the report and in the result; a model Ward can
//! take draws no warning.

use assert_cmd::Command;
use std::path::Path;

fn fibrefit() -> Command {
    Command::cargo_bin("fibrefit").expect("binary built")
}

/// A Ward fit of a sharp fibre BRDF: the silk truth with its shape fixed (only the albedos
/// fitted, so it is quick).
const SILK_FIT: &str = r#"
model = "varying-topology"
metric = "linear"
starts = 1
seed = 1
[knobs]
quadrature_order = 16
histogram_bins = 16
topology_map = "TOPOLOGY"
[parameters]
kd = { value = 0.5 }
ks = { value = 0.3 }
exponent = { value = 60, vary = false }
spacing = { value = 2.0, vary = false }
height = { value = 0.9, vary = false }
map_scale = { value = 0.25, vary = false }
fibre_azimuth_deg = { value = 20, vary = false }
"#;

#[test]
fn a_poor_ward_fallback_is_warned_about_on_stderr_in_the_report_and_the_result() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let dir = tempfile::tempdir().unwrap();
    let cfg = dir.path().join("fit.toml");
    let topo = root.join("data_synthetic/silk/topology.png");
    std::fs::write(&cfg, SILK_FIT.replace("TOPOLOGY", topo.to_str().unwrap())).unwrap();
    let out = dir.path().join("r.json");
    let report = dir.path().join("report");
    let run = fibrefit()
        .arg("fit")
        .arg(root.join("data_synthetic/silk/gonio.csv"))
        .arg("--config")
        .arg(&cfg)
        .arg("--out")
        .arg(&out)
        .arg("--report")
        .arg(&report)
        .output()
        .unwrap();
    let (stdout, stderr) = (
        String::from_utf8_lossy(&run.stdout),
        String::from_utf8_lossy(&run.stderr),
    );
    assert!(run.status.success(), "{stderr}");
    let r: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&out).unwrap()).unwrap();
    let w = &r["ward_fallback"];
    let rel = w["relative_rms_error"].as_f64().unwrap();
    eprintln!("Ward fallback of the silk truth: relative RMS error {rel:.4}, {w}");
    assert!(rel > 0.25, "{w}");
    let warnings: Vec<&str> = w["warnings"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_str().unwrap())
        .collect();
    let figure = format!("{:.0} % off the fitted model", 100.0 * rel);
    assert!(warnings.iter().any(|s| s.contains(&figure)), "{warnings:?}");
    // silk's alpha_y ends at its bound (the lobe wants to be wider across the fibres): named
    assert_eq!(w["parameters"]["alpha_y"].as_f64(), Some(1.0), "{w}");
    assert!(
        warnings
            .iter()
            .any(|s| s.contains("fallback's alpha_y ended at its upper bound 1")),
        "{warnings:?}"
    );
    // said once: in the printed report (stderr leaves out what the report printed) ...
    for s in &warnings {
        assert!(stdout.contains(&format!("warning: {s}")), "{stdout}");
        assert!(
            !stderr.contains(&format!("warning: {s}")),
            "said twice: {stderr}"
        );
        assert!(r["warnings"].as_array().unwrap().iter().any(|v| v == s));
    }
    // ... and on stderr when no report is printed (--json prints a summary line instead)
    let quiet = fibrefit()
        .arg("fit")
        .arg(root.join("data_synthetic/silk/gonio.csv"))
        .arg("--config")
        .arg(&cfg)
        .arg("--json")
        .output()
        .unwrap();
    let quiet_err = String::from_utf8_lossy(&quiet.stderr);
    for s in &warnings {
        assert!(quiet_err.contains(*s), "{quiet_err}");
    }
    assert!(stdout.contains("[[Ward fallback]]"), "{stdout}");
    let md = std::fs::read_to_string(report.join("report.md")).unwrap();
    assert!(
        md.contains("[[Ward fallback]]") && md.contains(&figure),
        "{md}"
    );
}

#[test]
fn a_ward_fallback_of_a_ward_truth_has_no_warning() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("ward.toml");
    std::fs::write(
        &p,
        "model = \"ward\"\nrho_d = 0.3\nrho_s = 0.2\nalpha_x = 0.15\nalpha_y = 0.4\nfibre_azimuth_deg = 20\n",
    )
    .unwrap();
    let (_, id, params) =
        fibrefit::api::eval::load_params(&p, None, &fibrefit::progress::Progress::quiet()).unwrap();
    let model = fibrefit::model::build(id, &params).unwrap();
    let w = fibrefit::fit::ward_fallback::fit(model.as_ref(), &params.albedos, 20.0, 1, 1).unwrap();
    assert!(w.relative_rms_error < 0.01, "{}", w.relative_rms_error);
    assert!(w.warnings.is_empty(), "{:?}", w.warnings);
    // the rule itself: the figure and the parameter at its bound are named
    let far = fibrefit::fit::ward_fallback::warnings(0.57, &[]);
    assert!(far.len() == 1 && far[0].contains("57 % off"), "{far:?}");
    let record = |name: &str, value: f64, at: bool, fixed: bool| fibrefit::fit::ParamRecord {
        name: name.into(),
        value: vec![value],
        std_error: vec![None],
        init: vec![0.2],
        min: 0.0011,
        max: 1.0,
        fixed,
        at_bound: vec![at],
        fixed_reason: None,
        grey: false,
        held: None,
        undetermined: vec![],
    };
    let bound = fibrefit::fit::ward_fallback::warnings(
        0.1,
        &[
            record("alpha_x", 0.3, false, false),
            record("alpha_y", 1.0, true, false),
            record("fibre_azimuth_deg", 1.0, true, true),
        ],
    );
    assert!(
        bound.len() == 1 && bound[0].contains("alpha_y ended at its upper bound 1"),
        "{bound:?}"
    );
}
