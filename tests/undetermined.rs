//! Parameters the data cannot determine are reported as undetermined, with the value used and
//! why, not as measured facts: in the fit's records, the report, the result JSON (read back by
//! the exports, and old results without the field still read), `fit --json`, and every renderer
//! export (a warning, the shader's header, the GLB's `extras`). A well-determined fit flags
//! none (the recovery tests check that too).

use assert_cmd::Command;
use fibrefit::fit::config::FitConfig;
use fibrefit::fit::{fit, FitOutcome};
use fibrefit::load::{load_data, LoadOptions};
use std::path::{Path, PathBuf};

/// Goniometric data rendered from Ward with the lobe of albedo `rho_s` (600 random directions,
/// 1 % noise).
fn ward_data(dir: &Path, rho_s: f64) -> PathBuf {
    let synth = dir.join("synth.toml");
    std::fs::write(
        &synth,
        format!(
            r#"
model = "ward"
[params]
rho_d = 0.3
rho_s = {rho_s}
alpha_x = 0.3
alpha_y = 0.1
[gonio]
random = {{ count = 600, seed = 5, max_theta_deg = 80 }}
[noise]
relative = 0.01
seed = 2
"#
        ),
    )
    .unwrap();
    let out = dir.join("data");
    fibrefit::synth::run(&synth, &out, &fibrefit::progress::Progress::quiet()).unwrap();
    out.join("gonio.csv")
}

fn ward_fit(data: &Path, extra: &str) -> FitOutcome {
    let cfg: FitConfig = toml::from_str(&format!("model = \"ward\"\n{extra}")).unwrap();
    cfg.validate().unwrap();
    let samples = load_data(data, &LoadOptions::default()).unwrap();
    fit(&samples, &cfg, &fibrefit::progress::Progress::quiet()).unwrap()
}

fn labels(o: &FitOutcome) -> Vec<String> {
    o.quality
        .undetermined
        .iter()
        .map(|u| u.label.clone())
        .collect()
}

fn reason<'a>(o: &'a FitOutcome, label: &str) -> &'a str {
    &o.quality
        .undetermined
        .iter()
        .find(|u| u.label == label)
        .unwrap_or_else(|| panic!("{label} not undetermined: {:?}", o.quality.undetermined))
        .reason
}

#[test]
fn a_well_determined_fit_flags_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let data = ward_data(dir.path(), 0.5);
    let o = ward_fit(&data, "");
    assert!(
        o.quality.undetermined.is_empty(),
        "{:?}",
        o.quality.undetermined
    );
    assert!(o.records.iter().all(|r| r.undetermined.is_empty()));
    let report = fibrefit::export::report::text(&o, "ward", "data", None);
    assert!(!report.contains("undetermined"), "{report}");
}

/// The data ask for a lobe narrower than the bounds allow: alpha_y ends on its lower bound.
#[test]
fn a_value_pinned_at_a_bound_is_undetermined_with_that_reason() {
    let dir = tempfile::tempdir().unwrap();
    let data = ward_data(dir.path(), 0.5);
    let o = ward_fit(
        &data,
        "[parameters]\nalpha_y = { value = 0.3, min = 0.2, max = 1.0 }\n",
    );
    assert_eq!(labels(&o), ["alpha_y"], "{:?}", o.quality.undetermined);
    let why = reason(&o, "alpha_y");
    assert!(
        why.starts_with(
            "at its lower bound 0.2: the data ask for less and the model cannot give it"
        ),
        "{why}"
    );
    assert!(o
        .warnings
        .iter()
        .any(|w| w.starts_with("`alpha_y` is undetermined (value used: 0.2): at its lower bound")));
    let report = fibrefit::export::report::text(&o, "ward", "data", None);
    assert!(
        report.contains(
            "undetermined (value used: 0.200000; init = 0.300000): at its lower bound 0.2"
        ),
        "{report}"
    );
    assert!(
        report.contains("undetermined       = 1 value the data do not determine"),
        "{report}"
    );
}

/// Data without a specular lobe: the fit imitates the flat diffuse part with a lobe stretched to
/// its extremes (alpha_x at its lower bound, alpha_y at its upper one, traded against rho_s):
/// the lobe's widths are then not measurements of anything.
#[test]
fn parameters_without_effect_on_the_data_are_undetermined() {
    let dir = tempfile::tempdir().unwrap();
    let data = ward_data(dir.path(), 0.0);
    let o = ward_fit(&data, "");
    eprintln!("{:#?}", o.quality.undetermined);
    let l = labels(&o);
    for a in ["alpha_x", "alpha_y"] {
        let why = reason(&o, a);
        assert!(
            why.starts_with("at its")
                || why.starts_with("the cost is flat along it")
                || why.starts_with("not separable from"),
            "{a}: {why}"
        );
    }
    // the diffuse albedo is measured
    assert!(!l.contains(&"rho_d".to_string()), "{l:?}");
}

fn cli() -> Command {
    Command::cargo_bin("fibrefit").expect("binary built")
}

/// The result JSON says which values are undetermined and why; `fit --json` names them; every
/// export uses the values but says so; a result without the field (written before it existed)
/// still reads, with nothing undetermined.
#[test]
fn the_result_records_them_and_the_exports_say_so() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let data = ward_data(d, 0.5);
    let config = d.join("fit.toml");
    std::fs::write(
        &config,
        "model = \"ward\"\n[parameters]\nalpha_y = { value = 0.3, min = 0.2, max = 1.0 }\n",
    )
    .unwrap();
    let result = d.join("fit.json");
    let o = cli()
        .arg("fit")
        .arg(&data)
        .arg("--config")
        .arg(&config)
        .arg("--out")
        .arg(&result)
        .arg("--json")
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let line: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(
        line["undetermined"],
        serde_json::json!(["alpha_y"]),
        "{line}"
    );
    let r: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&result).unwrap()).unwrap();
    let p = &r["parameters"];
    assert_eq!(p["alpha_y"]["determined"], false);
    assert!((p["alpha_y"]["value"].as_f64().unwrap() - 0.2).abs() < 1e-9);
    assert!(p["alpha_y"]["undetermined_reason"]
        .as_str()
        .unwrap()
        .starts_with("at its lower bound 0.2"));
    assert_eq!(p["alpha_x"]["determined"], true);
    assert!(p["alpha_x"].get("undetermined_reason").is_none());
    assert_eq!(p["rho_d"]["determined"], true);
    assert_eq!(r["quality"]["undetermined"][0]["label"], "alpha_y");
    // read back as the exports read it
    let back = fibrefit::export::result_json::undetermined_in(&r);
    assert_eq!(back.len(), 1);
    assert_eq!(back[0].label, "alpha_y");
    assert!((back[0].value - 0.2).abs() < 1e-9);

    // the exports: a warning naming it, the shader's header, the GLB's extras
    let (shader, glb) = (d.join("fibre.wgsl"), d.join("fibre.glb"));
    let e = cli()
        .arg("export")
        .arg(&result)
        .args(["--shader", "wgsl", "--out"])
        .arg(&shader)
        .arg("--gltf")
        .arg(&glb)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&e.stderr);
    assert!(e.status.success(), "{stderr}");
    assert!(
        stderr.contains("`alpha_y` is undetermined (value used: 0.2): at its lower bound 0.2")
            && stderr.contains("used as given, not a measurement"),
        "{stderr}"
    );
    let src = std::fs::read_to_string(&shader).unwrap();
    assert!(
        src.contains("UNDETERMINED: `alpha_y` is undetermined (value used: 0.2)"),
        "{}",
        &src[..src.len().min(3000)]
    );
    let glb_bytes = std::fs::read(&glb).unwrap();
    let doc = glb_json(&glb_bytes);
    // the GLB carries the gltf material the fit recorded (fitted to the same data): its extras
    // name that material's own undetermined values, not the ward fit's
    let recorded = r["renderer_materials"]
        .as_array()
        .unwrap()
        .iter()
        .find(|m| m["model"] == "gltf")
        .unwrap();
    let own = fibrefit::export::result_json::undetermined_in(recorded);
    let und = doc["materials"][0]["extras"]["fibrefit"]["undetermined"]
        .as_array()
        .cloned()
        .unwrap_or_default();
    assert_eq!(und.len(), own.len(), "{und:?}");
    for (u, o) in und.iter().zip(&own) {
        assert_eq!(u["parameter"], o.label.as_str());
        assert!((u["value_used"].as_f64().unwrap() - o.value).abs() < 1e-12);
        assert!(
            stderr.contains(&format!("the recorded `gltf` material's `{}`", o.label)),
            "{stderr}"
        );
    }
    // `eval` and `render` read the values through the same loader: said there too
    let q = d.join("q.csv");
    std::fs::write(&q, "theta_i,phi_i,theta_o,phi_o\n30,0,30,180\n").unwrap();
    let ev = cli()
        .arg("eval")
        .arg("--params")
        .arg(&result)
        .arg("--queries")
        .arg(&q)
        .output()
        .unwrap();
    assert!(ev.status.success());
    assert!(String::from_utf8_lossy(&ev.stderr).contains("`alpha_y` is undetermined"));
    // the material a renderer (Python, Mitsuba) loads carries them, with a warning
    let (m, warnings) = fibrefit::api::material::Material::load(&result, None).unwrap();
    assert_eq!(m.undetermined.len(), 1);
    assert!(warnings
        .iter()
        .any(|w| w.contains("`alpha_y` is undetermined")));

    // a result written before `determined` existed reads, with nothing said
    let mut old = r.clone();
    for (_, e) in old["parameters"].as_object_mut().unwrap() {
        let e = e.as_object_mut().unwrap();
        e.remove("determined");
        e.remove("undetermined_reason");
    }
    old["quality"]
        .as_object_mut()
        .unwrap()
        .remove("undetermined");
    let old_path = d.join("old.json");
    std::fs::write(&old_path, serde_json::to_string_pretty(&old).unwrap()).unwrap();
    let parsed: fibrefit::export::result_json::ResultFile =
        serde_json::from_value(old.clone()).unwrap();
    assert!(parsed.parameters["alpha_y"].determined.is_none());
    assert!(fibrefit::export::result_json::undetermined_in(&old).is_empty());
    let e = cli()
        .arg("export")
        .arg(&old_path)
        .args(["--shader", "wgsl", "--out"])
        .arg(d.join("old.wgsl"))
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&e.stderr);
    assert!(e.status.success(), "{stderr}");
    assert!(!stderr.contains("undetermined"), "{stderr}");
    // and the new file reads as a result too (score's reader)
    fibrefit::export::result_json::read_result(&result, 1).unwrap();
}

/// The JSON chunk of a GLB.
fn glb_json(b: &[u8]) -> serde_json::Value {
    let len = u32::from_le_bytes(b[12..16].try_into().unwrap()) as usize;
    serde_json::from_slice(&b[20..20 + len]).unwrap()
}
