//! Issue 23 item 5: parameters that mean what they say. A dielectric fibre's surface reflection
//! is colourless, so the fibre rungs fit one grey `ks` for RGB data by default and the dye's
//! colour lives in kd: felts of one geometry dyed three colours are fitted to one geometry within
//! their errors; `ks = { colour = true }` still fits a coloured lobe; a config that mixes the two
//! up is refused with the key named.

use fibrefit::fit::config::FitConfig;
use fibrefit::fit::{fit, FitOutcome, ParamRecord};
use fibrefit::load::{load_data, samples::Samples, LoadOptions};
use std::path::Path;

/// The felt's geometry (varying-topology with the fibre-direction spread).
const GEOMETRY: [(&str, f64); 4] = [
    ("exponent", 30.0),
    ("spacing", 2.6),
    ("height", 0.8),
    ("azimuth_spread_deg", 40.0),
];

fn synth(dir: &Path, name: &str, kd: [f64; 3], ks: &str, noise_seed: u64) -> Samples {
    let (e, d, h, spread) = (GEOMETRY[0].1, GEOMETRY[1].1, GEOMETRY[2].1, GEOMETRY[3].1);
    let cfg = format!(
        r#"
model = "varying-topology"
[params]
kd = [{}, {}, {}]
ks = {ks}
exponent = {e}
spacing = {d}
height = {h}
azimuth_spread_deg = {spread}
azimuth_nodes = 8
histogram_bins = 8
[gonio]
random = {{ count = 1200, seed = 4, max_theta_deg = 80 }}
[noise]
relative = 0.01
seed = {noise_seed}
"#,
        kd[0], kd[1], kd[2]
    );
    let path = dir.join(format!("{name}.toml"));
    std::fs::write(&path, cfg).unwrap();
    let out = dir.join(name);
    fibrefit::synth::run(&path, &out, &fibrefit::progress::Progress::quiet()).unwrap();
    load_data(&out.join("gonio.csv"), &LoadOptions::default()).unwrap()
}

fn config(ks: &str) -> FitConfig {
    let text = format!(
        r#"
model = "varying-topology"
starts = 2
seed = 3
[knobs]
histogram_bins = 8
azimuth_nodes = 8
[optimizer]
global_candidates = 40
global_subsample = 400
[parameters]
kd = {{ value = 0.3 }}
ks = {ks}
exponent = {{ value = 10, min = 1, max = 1000 }}
spacing = {{ value = 3.0, min = 2, max = 5 }}
height = {{ value = 0.5 }}
azimuth_spread_deg = {{ value = 60 }}
"#
    );
    let cfg: FitConfig = toml::from_str(&text).unwrap();
    cfg.validate().unwrap();
    cfg
}

fn record<'a>(o: &'a FitOutcome, name: &str) -> &'a ParamRecord {
    o.records.iter().find(|r| r.name == name).unwrap()
}

#[test]
fn felts_of_one_geometry_in_three_colours_fit_one_geometry_with_a_grey_ks() {
    let dir = tempfile::tempdir().unwrap();
    let ks_truth = 0.3;
    let colours = [
        ("red", [0.55, 0.08, 0.06]),
        ("green", [0.07, 0.45, 0.12]),
        ("blue", [0.05, 0.09, 0.5]),
    ];
    let mut fits = Vec::new();
    for (k, (name, kd)) in colours.iter().enumerate() {
        let data = synth(dir.path(), name, *kd, &ks_truth.to_string(), 20 + k as u64);
        assert_eq!(data.channels, 3);
        let o = fit(
            &data,
            &config("{ value = 0.5 }"),
            &fibrefit::progress::Progress::quiet(),
        )
        .unwrap();
        eprintln!("{name}: warnings {:?}", o.warnings);
        // the grey ks: one free parameter, equal in every channel, said so in the result
        let ks = record(&o, "ks");
        assert!(ks.grey, "{name}: ks not marked grey");
        assert_eq!(ks.value.len(), 3);
        assert!(
            ks.value[0] == ks.value[1] && ks.value[1] == ks.value[2],
            "{:?}",
            ks.value
        );
        let se = ks.std_error[0].expect("ks standard error");
        assert!(ks.std_error.iter().all(|e| *e == Some(se)));
        assert!(
            (ks.value[0] - ks_truth).abs() < 4.0 * se,
            "{name}: ks {} +/- {se} (truth {ks_truth})",
            ks.value[0]
        );
        // 4 shapes + 3 kd channels + 1 ks
        assert_eq!(o.statistics.free_parameters, 8, "{name}");
        let json = fibrefit::export::result_json::params_out(&o);
        assert!(json["ks"].grey && !json["kd"].grey);
        let report = fibrefit::export::report::text(&o, "varying-topology", name, None);
        assert!(
            report.contains("[grey: one value fitted for r, g and b]"),
            "{report}"
        );
        // the dye in kd, per channel
        let kd_rec = record(&o, "kd");
        for c in 0..3 {
            let e = kd_rec.std_error[c].expect("kd standard error");
            assert!(
                (kd_rec.value[c] - kd[c]).abs() < 4.0 * e,
                "{name}: kd[{c}] {} +/- {e} (truth {})",
                kd_rec.value[c],
                kd[c]
            );
        }
        // the geometry within errors of the truth
        for (p, truth) in GEOMETRY {
            let r = record(&o, p);
            let e = r.std_error[0].unwrap_or_else(|| panic!("{name}: {p} has no standard error"));
            eprintln!("{name}: {p} = {:.4} +/- {e:.4} (truth {truth})", r.value[0]);
            assert!(
                (r.value[0] - truth).abs() < 4.0 * e,
                "{name}: {p} = {} +/- {e} is off the truth {truth}",
                r.value[0]
            );
        }
        fits.push(o);
    }
    // one material: every pair of colours agrees on every geometric parameter within errors
    for (p, _) in GEOMETRY {
        for i in 0..fits.len() {
            for j in i + 1..fits.len() {
                let (a, b) = (record(&fits[i], p), record(&fits[j], p));
                let (ea, eb) = (a.std_error[0].unwrap(), b.std_error[0].unwrap());
                let z = (a.value[0] - b.value[0]) / (ea * ea + eb * eb).sqrt();
                assert!(
                    z.abs() < 4.0,
                    "{p}: {} ({}) and {} ({}) differ by {z:.1} combined errors",
                    a.value[0],
                    colours[i].0,
                    b.value[0],
                    colours[j].0
                );
            }
        }
    }
}

#[test]
fn a_coloured_ks_is_fitted_per_channel_when_the_config_asks() {
    let dir = tempfile::tempdir().unwrap();
    let ks_truth = [0.45, 0.25, 0.1];
    let kd = [0.2, 0.3, 0.25];
    let data = synth(
        dir.path(),
        "metallic",
        kd,
        &format!("[{}, {}, {}]", ks_truth[0], ks_truth[1], ks_truth[2]),
        31,
    );
    let coloured = fit(
        &data,
        &config("{ value = 0.5, colour = true }"),
        &fibrefit::progress::Progress::quiet(),
    )
    .unwrap();
    let ks = record(&coloured, "ks");
    assert!(!ks.grey);
    assert_eq!(coloured.statistics.free_parameters, 10);
    for c in 0..3 {
        let e = ks.std_error[c].expect("ks standard error");
        assert!(
            (ks.value[c] - ks_truth[c]).abs() < 4.0 * e,
            "ks[{c}] {} +/- {e} (truth {})",
            ks.value[c],
            ks_truth[c]
        );
    }
    // the grey default cannot follow a coloured lobe: its least squares are far worse
    let grey = fit(
        &data,
        &config("{ value = 0.5 }"),
        &fibrefit::progress::Progress::quiet(),
    )
    .unwrap();
    assert!(record(&grey, "ks").grey);
    let ratio = grey.statistics.chi_square / coloured.statistics.chi_square;
    eprintln!("sum of squares grey / coloured = {ratio:.2}");
    assert!(ratio > 2.0, "grey / coloured sum of squares {ratio}");
}

#[test]
fn a_colour_choice_where_there_is_none_and_an_rgb_start_for_a_grey_ks_are_refused() {
    let refused = |text: &str, needle: &str| {
        let cfg: FitConfig = toml::from_str(text).unwrap();
        let err = cfg.validate().unwrap_err().to_string();
        assert!(err.contains(needle), "{err}");
    };
    refused(
        "model = \"poulin-fournier\"\n[parameters]\nkd = { colour = false }\n",
        "parameters.kd.colour",
    );
    refused(
        "model = \"poulin-fournier\"\n[parameters]\nks = { value = [0.3, 0.2, 0.1] }\n",
        "parameters.ks.value",
    );
    refused(
        "model = \"auto\"\n[parameters]\nexponent = { colour = true }\n",
        "parameters.exponent.colour",
    );
    // a fixed RGB ks (a result read back) and a coloured start with `colour = true` are fine
    for ok in [
        "model = \"poulin-fournier\"\n[parameters]\nks = { value = [0.3, 0.2, 0.1], vary = false }\n",
        "model = \"poulin-fournier\"\n[parameters]\nks = { value = [0.3, 0.2, 0.1], colour = true }\n",
    ] {
        let cfg: FitConfig = toml::from_str(ok).unwrap();
        cfg.validate().unwrap();
    }
}
