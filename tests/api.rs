//! The library API (`fibrefit::api`) is what the command line runs: a fit through the API gives
//! the result file the CLI writes, value for value; its outputs go only where reserved.

use fibrefit::api::fit::{self, FitRequest, FitTargets, Maps};
use fibrefit::export::atomic::Outputs;
use std::path::PathBuf;

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

#[test]
fn a_fit_through_the_api_is_the_cli_fit() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let data = root().join("data_synthetic/brushed/gonio.csv");
    let cfg = fit::configure(None, Some("poulin-fournier"), None, None, &data).unwrap();
    let req = FitRequest {
        data: data.clone(),
        load: fibrefit::load::LoadOptions::default(),
        maps: Maps::None,
        progress: fibrefit::progress::Progress::quiet(),
        config: cfg,
        held: None,
    };
    let mut run = fit::fit(&req).unwrap();
    assert_eq!(run.model.as_str(), "poulin-fournier");
    assert!(run.report_text.contains("[[Fit Statistics]]"));
    // written through reserved outputs
    let mut outs = Outputs::new(&fit::inputs(&req, None));
    let json = d.join("api.json");
    let targets = FitTargets::reserve(&mut outs, &req, Some(&json), None).unwrap();
    run.write(&mut outs, &targets).unwrap();
    outs.commit().unwrap();
    // the CLI on the same data and settings
    let cli = d.join("cli.json");
    let o = assert_cmd::Command::cargo_bin("fibrefit")
        .unwrap()
        .arg("fit")
        .arg(&data)
        .args(["--model", "poulin-fournier", "-q", "--out"])
        .arg(&cli)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let read = |p: &PathBuf| -> serde_json::Value {
        let mut v: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(p).unwrap()).unwrap();
        // wall times differ from run to run
        v["statistics"]["elapsed_seconds"] = serde_json::Value::Null;
        v
    };
    let (a, b) = (read(&json), read(&cli));
    assert_eq!(a["parameters"], b["parameters"]);
    assert_eq!(a["check_values"], b["check_values"]);
    assert_eq!(a["data"], b["data"]);
    let params = |v: &serde_json::Value| -> Vec<serde_json::Value> {
        let m = v["renderer_materials"]
            .as_array()
            .cloned()
            .unwrap_or_default();
        m.iter().map(|m| m["parameters"].clone()).collect()
    };
    assert_eq!(params(&a), params(&b));
}

#[test]
fn configure_names_what_is_wrong() {
    let data = root().join("data_synthetic/brushed/gonio.csv");
    let e = fit::configure(None, None, None, None, &data).err().unwrap();
    assert!(e.to_string().contains("--model"), "{e}");
    let e = fit::configure(None, Some("lambert"), Some("cubic"), None, &data)
        .err()
        .unwrap();
    assert!(e.to_string().contains("--metric cubic"), "{e}");
    let e = fit::configure(None, Some("no-such-rung"), None, None, &data)
        .err()
        .unwrap();
    assert!(e.to_string().contains("no-such-rung"), "{e}");
    // a measured file without a config is fitted with the log metric
    let c = fit::configure(
        None,
        Some("lambert"),
        None,
        None,
        std::path::Path::new("x.bsdf"),
    )
    .unwrap();
    assert_eq!(c.metric, fibrefit::fit::config::Metric::Log);
}

#[test]
fn fuzz_true_false_and_none_set_auto_s_candidates() {
    let data = root().join("data_synthetic/brushed/gonio.csv");
    let names = |fuzz: Option<bool>| -> Vec<String> {
        let c = fit::configure(None, Some("auto"), None, fuzz, &data).unwrap();
        fibrefit::fit::selection::candidates_of(&c)
            .unwrap()
            .into_iter()
            .map(|c| c.0)
            .collect()
    };
    let (default, with, without) = (names(None), names(Some(true)), names(Some(false)));
    // every rung of the ladder (nine with gltf, principled and openpbr), without and with the
    // fuzz layer but those auto tries without it only (principled, openpbr: their renderers
    // have no fuzz layer of fibrefit's)
    let rungs = without.len();
    assert!(rungs >= 8, "{without:?}");
    let plain_only = fibrefit::model::rungs::auto_candidates()
        .into_iter()
        .filter(|id| !id.rung().auto_fuzz)
        .count();
    assert_eq!(plain_only, 2);
    assert_eq!(default.len(), 2 * rungs - plain_only, "{default:?}");
    assert!(
        default.contains(&"principled".to_string())
            && !default.contains(&"principled + fuzz".to_string())
            && default.contains(&"openpbr".to_string())
            && !default.contains(&"openpbr + fuzz".to_string())
    );
    assert!(with.iter().all(|n| n.ends_with("+ fuzz")) && with.len() == rungs);
    assert!(without.iter().all(|n| !n.contains("fuzz")));
    // --no-fuzz against a config that lists a fuzz parameter: refused, naming it
    let dir = tempfile::tempdir().unwrap();
    let cfg = dir.path().join("auto.toml");
    std::fs::write(&cfg, "model = \"auto\"\n[parameters]\nfuzz = {}\n").unwrap();
    let e = fit::configure(Some(&cfg), None, None, Some(false), &data)
        .err()
        .unwrap();
    assert!(e.to_string().contains("parameter `fuzz`"), "{e}");
}

/// Measurements a program holds (numpy arrays, a DataFrame's table through Python) fit as the
/// file they came from: the same samples, the same parameters.
#[test]
fn held_arrays_and_tables_fit_as_their_file() {
    use fibrefit::api::{FitOptions, Held, OwnedArrays};
    let data = root().join("data_synthetic/silk/gonio.csv");
    let text = std::fs::read_to_string(&data).unwrap();
    let cut: String = text.lines().take(301).collect::<Vec<_>>().join("\n") + "\n";
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("silk.csv");
    std::fs::write(&file, &cut).unwrap();
    let options = FitOptions {
        config: None,
        model: Some("ward".into()),
        metric: None,
        fuzz: None,
        load: Default::default(),
        maps: Maps::None,
        progress: fibrefit::progress::Progress::quiet(),
        gltf_variant: None,
        correction: None,
    };
    let from_file = fit::fit(&options.request(&file).unwrap()).unwrap();
    let samples = &from_file.samples.samples;
    let arrays = OwnedArrays {
        l: samples.iter().map(|s| [s.l.x, s.l.y, s.l.z]).collect(),
        v: samples.iter().map(|s| [s.v.x, s.v.y, s.v.z]).collect(),
        values: samples.iter().flat_map(|s| s.value).collect(),
        channels: 3,
        sigma: Some(samples.iter().flat_map(|s| s.sigma.unwrap()).collect()),
    };
    let held = [
        Held::Arrays {
            arrays,
            name: "arrays".into(),
        },
        Held::Table {
            text: cut.clone(),
            name: "DataFrame".into(),
        },
    ];
    for h in held {
        let req = options.request_held(h).unwrap();
        assert!(
            fit::inputs(&req, None).is_empty(),
            "nothing on disk is read"
        );
        let run = fit::fit(&req).unwrap();
        assert_eq!(run.samples.samples.len(), 300);
        for (a, b) in run.samples.samples.iter().zip(samples) {
            assert!((a.l - b.l).norm() < 1e-12 && (a.v - b.v).norm() < 1e-12);
            assert_eq!((a.value, a.sigma), (b.value, b.sigma));
        }
        let (x, y) = (&run.outcome.statistics, &from_file.outcome.statistics);
        assert!(
            (x.rmse - y.rmse).abs() <= 1e-9 * y.rmse,
            "{} vs {}",
            x.rmse,
            y.rmse
        );
    }
    // what is wrong, named with the array and row
    let bad = |f: &dyn Fn(&mut OwnedArrays)| {
        let mut a = OwnedArrays {
            l: vec![[0.0, 0.0, 1.0]; 4],
            v: vec![[0.6, 0.0, 0.8]; 4],
            values: vec![0.3; 4],
            channels: 1,
            sigma: None,
        };
        f(&mut a);
        let e = options
            .request_held(Held::Arrays {
                arrays: a,
                name: "arrays".into(),
            })
            .err()
            .expect("refused");
        format!("{e:#}")
    };
    assert!(bad(&|a| a.l[2] = [0.0, 0.0, 2.0]).contains("arrays: l[2] = (0, 0, 2) has length 2"));
    assert!(
        bad(&|a| a.v[1] = [1.0, 0.0, 0.0]).contains("v[1] = (1, 0, 0) is at or below the horizon")
    );
    assert!(bad(&|a| a.values[3] = f64::NAN).contains("values[3] = NaN"));
    assert!(bad(&|a| a.values[0] = -0.3).contains("values[0] = -0.3 is negative beyond noise"));
    assert!(bad(&|a| a.sigma = Some(vec![0.1, 0.1, 0.0, 0.1]))
        .contains("sigma[2] = 0 must be positive"));
    assert!(bad(&|a| a.v.pop().map(|_| ()).unwrap()).contains("l has 4 rows, v has 3"));
    assert!(bad(&|a| a.sigma = Some(vec![0.1; 3])).contains("sigma has 3 entries"));
}
