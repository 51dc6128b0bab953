//! `--model auto` (issue 23): candidates compared by their cross-validated error, the simplest
//! within one standard error of the best chosen. It picks the cheapest rung the data need
//! (`lambert` for Lambertian data, `poulin-fournier` for flat fibres with gaps,
//! `varying-topology` for climbing fibres with a topology map), a fibre rung with the fuzz layer
//! when the truth has one, the same choice on every fold when the truth is clear; and data
//! without sigmas spanning decades are fitted and judged in the log metric, which the report
//! and the result say.

use assert_cmd::Command;
use fibrefit::fit::config::{FitConfig, Metric};
use fibrefit::fit::fit_with_hints;
use fibrefit::fit::selection::{rule_choice, select, select_with, table, SelectionOutcome};
use fibrefit::load::samples::Samples;
use fibrefit::load::{load_data, LoadOptions};
use std::path::{Path, PathBuf};

fn synth_text(dir: &Path, name: &str, text: &str) -> PathBuf {
    let p = dir.join(format!("{name}.toml"));
    std::fs::write(&p, text).unwrap();
    let out = dir.join(name);
    fibrefit::synth::run(&p, &out, &fibrefit::progress::Progress::quiet()).unwrap();
    out
}

fn synth(dir: &Path, model: &str, params: &str) -> PathBuf {
    let text = format!(
        r#"
model = "{model}"
[params]
{params}
[topology_map]
width = 16
height = 16
seed = 5
[gonio]
random = {{ count = 900, seed = 1, max_theta_deg = 80 }}
[noise]
relative = 0.01
seed = 3
"#
    );
    synth_text(dir, model, &text)
}

fn auto_config(map: &Path) -> FitConfig {
    let text = format!(
        r#"
model = "auto"
starts = 1
seed = 1
[knobs]
histogram_bins = 8
topology_map = "{}"
[optimizer]
global_candidates = 16
global_subsample = 300
[parameters]
exponent = {{ value = 20, min = 1, max = 1000 }}
spacing = {{ value = 2.5, min = 2, max = 6 }}
height = {{ value = 0.5, min = 0, max = 1.7 }}
map_scale = {{ value = 0.1, min = 0, max = 0.6 }}
substrate_albedo = {{ value = 0.5 }}
"#,
        map.display()
    );
    let cfg: FitConfig = toml::from_str(&text).unwrap();
    cfg.validate().unwrap();
    cfg
}

fn chosen(dir: &Path, model: &str, params: &str) -> String {
    let d = synth(dir, model, params);
    let data = load_data(&d.join("gonio.csv"), &LoadOptions::default()).unwrap();
    let s = select(&data, &auto_config(&d.join("topology.png"))).unwrap();
    eprintln!("{model} data:\n{}", table(&s));
    s.chosen
}

#[test]
fn auto_picks_the_cheapest_sufficient_rung() {
    let dir = tempfile::tempdir().unwrap();
    assert_eq!(
        chosen(
            dir.path(),
            "poulin-fournier",
            "kd = 0.7\nks = 0.15\nexponent = 30\nspacing = 3.5\nsubstrate_albedo = 0.2"
        ),
        "poulin-fournier"
    );
    assert_eq!(
        chosen(
            dir.path(),
            "varying-topology",
            "kd = 0.5\nks = 0.25\nexponent = 60\nspacing = 2.0\nheight = 0.9\nmap_scale = 0.3\nhistogram_bins = 8"
        ),
        "varying-topology"
    );
}

/// Grey samples of a synthetic truth without their sigmas (as a measurement that gives none).
fn without_sigmas(d: &Path) -> Samples {
    let mut data = load_data(&d.join("gonio.csv"), &LoadOptions::default()).unwrap();
    for s in &mut data.samples {
        s.sigma = None;
    }
    data
}

/// Every fold's own errors lead the rule to the pooled choice.
fn same_choice_on_every_fold(s: &SelectionOutcome) {
    let pooled = rule_choice(&s.candidates, None, None).unwrap();
    assert!(s.candidates[pooled].chosen);
    assert_eq!(s.folds, 5, "{}", s.validation);
    for j in 0..s.folds {
        let k = rule_choice(&s.candidates, Some(j), None).unwrap();
        assert_eq!(
            s.candidates[k].name,
            s.candidates[pooled].name,
            "fold {j} alone chooses otherwise:\n{}",
            table(s)
        );
    }
}

fn small_auto(rungs: &str) -> FitConfig {
    let cfg: FitConfig = toml::from_str(&format!(
        "model = \"auto\"\nstarts = 2\nseed = 2\n[optimizer]\nglobal_candidates = 24\n\
         global_subsample = 300\n[selection]\nrungs = [{rungs}]\n"
    ))
    .unwrap();
    cfg.validate().unwrap();
    cfg
}

#[test]
fn cross_validation_picks_lambert_for_a_small_noisy_lambertian_set() {
    let dir = tempfile::tempdir().unwrap();
    let d = synth_text(
        dir.path(),
        "lambert",
        "model = \"lambert\"\n[params]\nkd = 0.6\n[gonio]\n\
         random = { count = 200, seed = 4, max_theta_deg = 80 }\n\
         [noise]\nrelative = 0.05\nseed = 6\n",
    );
    let data = without_sigmas(&d);
    let s = select(
        &data,
        &small_auto("\"lambert\", \"hast-diffuse\", \"ward\", \"max-normal\""),
    )
    .unwrap();
    eprintln!("{}", table(&s));
    assert_eq!(s.chosen, "lambert");
    assert_eq!(s.validation, "5-fold cross-validation");
    // every sample held out once, each candidate with and without the fuzz layer
    assert_eq!(s.counts.heldout_samples_total, 200);
    // per fold: n / folds held out, the rest trained on, and the table says so
    assert_eq!(s.counts.heldout_samples_per_fold, 200 / 5);
    assert_eq!(s.counts.train_samples_per_fold, 200 - 200 / 5);
    assert!(
        table(&s).contains("160 training / 40 held-out samples per fold, 200 held out in all"),
        "{}",
        table(&s)
    );
    assert_eq!(s.candidates.len(), 8);
    assert!(s.candidates.iter().any(|c| c.name == "ward + fuzz"));
    for c in s.candidates.iter().filter(|c| c.error.is_none()) {
        assert_eq!(c.fold_errors.len(), 5, "{}", c.name);
        assert!(
            c.cv_standard_error > 0.0 && c.cv_standard_error < c.cv_error,
            "{}",
            c.name
        );
    }
    same_choice_on_every_fold(&s);
}

#[test]
fn a_fibre_truth_with_a_fuzz_layer_picks_a_fibre_rung_with_fuzz() {
    let dir = tempfile::tempdir().unwrap();
    let d = synth_text(
        dir.path(),
        "fuzzy",
        "model = \"poulin-fournier\"\n[params]\nkd = 0.3\nks = 0.3\nexponent = 20\nspacing = 2.4\n\
         fibre_azimuth_deg = 10\nfuzz = 3.0\nfuzz_depth = 0.2\nfuzz_asymmetry = 0.6\n\
         [gonio]\nrandom = { count = 600, seed = 3, max_theta_deg = 80 }\n\
         [noise]\nrelative = 0.01\nseed = 5\n",
    );
    let data = load_data(&d.join("gonio.csv"), &LoadOptions::default()).unwrap();
    let s = select(
        &data,
        &small_auto("\"lambert\", \"ward\", \"max-normal\", \"poulin-fournier\""),
    )
    .unwrap();
    eprintln!("{}", table(&s));
    assert!(s.chosen_fuzz, "{}", table(&s));
    assert!(
        ["max-normal", "poulin-fournier"].contains(&s.chosen_rung.as_str()),
        "{}",
        table(&s)
    );
    // the layer pays: the rung without it is worse beyond the noise
    let plain = s
        .candidates
        .iter()
        .find(|c| c.name == s.chosen_rung)
        .unwrap();
    let fuzz = s.candidates.iter().find(|c| c.chosen).unwrap();
    assert!(
        plain.cv_error > fuzz.cv_error + 3.0 * fuzz.cv_standard_error,
        "{}",
        table(&s)
    );
    same_choice_on_every_fold(&s);
}

#[test]
fn candidates_are_ranked_with_the_spread_as_fitted_and_the_chosen_fit_holds_it() {
    // aligned fibres: the spread the data cannot tell from 0 is held in the delivered fit
    // (`fit::spread_hold`); the candidates are ranked as fitted, else holding it in the anchor
    // fit holds it in every fold's refit too: one free parameter fewer counted, other errors
    let dir = tempfile::tempdir().unwrap();
    let d = synth_text(
        dir.path(),
        "aligned",
        "model = \"poulin-fournier\"\n[params]\nkd = 0.3\nks = 0.4\nexponent = 30\n\
         spacing = 2.4\nfibre_azimuth_deg = 10\n\
         [gonio]\nrandom = { count = 300, seed = 3, max_theta_deg = 80 }\n\
         [noise]\nrelative = 0.01\nseed = 5\n",
    );
    let data = load_data(&d.join("gonio.csv"), &LoadOptions::default()).unwrap();
    let mut cfg = small_auto("\"poulin-fournier\"");
    cfg.selection.fuzz = false;
    let spread_of = |o: &fibrefit::fit::FitOutcome| {
        o.records
            .iter()
            .find(|r| r.name == "azimuth_spread_deg")
            .map(|r| (r.value[0], r.fixed))
            .unwrap()
    };
    let mut anchors = Vec::new();
    let quiet = fibrefit::progress::Progress::quiet();
    let s = select_with(&data, &cfg, &quiet, &mut |d| {
        anchors.push(d.outcome.map(spread_of))
    })
    .unwrap();
    assert_eq!(s.chosen, "poulin-fournier", "{}", table(&s));
    let (value, fixed) = anchors[0].unwrap();
    assert!(!fixed, "the candidate's anchor fit keeps its spread free");
    let chosen = s.chosen_config.clone().unwrap();
    let delivered = fit_with_hints(&data, &chosen, &quiet, &s.hints).unwrap();
    let (held, fixed) = spread_of(&delivered);
    assert!(
        fixed && held == 0.0,
        "delivered spread {held} (fitted {value})"
    );
}

#[test]
fn the_final_fit_searches_at_the_ranking_knobs_and_lands_where_the_config_knobs_do() {
    // fibres spread around their direction: the knobs change the model (spread nodes, the lobe's
    // quadrature). `--model auto`'s final fit finds its basins at the knobs the candidates were
    // ranked at and polishes them at the config's; a search at the config's knobs (the slow
    // way) must land on the same minimum, the truth.
    let dir = tempfile::tempdir().unwrap();
    let d = synth_text(
        dir.path(),
        "spread",
        "model = \"poulin-fournier\"\n[params]\nkd = 0.3\nks = 0.5\nexponent = 40\n\
         spacing = 2.4\nfibre_azimuth_deg = 15\nazimuth_spread_deg = 25\n\
         [gonio]\nrandom = { count = 300, seed = 4, max_theta_deg = 80 }\n\
         [noise]\nrelative = 0.01\nseed = 6\n",
    );
    let data = load_data(&d.join("gonio.csv"), &LoadOptions::default()).unwrap();
    let mut cfg = small_auto("\"lambert\", \"poulin-fournier\", \"gltf\"");
    cfg.selection.fuzz = false;
    let quiet = fibrefit::progress::Progress::quiet();
    let s = select(&data, &cfg).unwrap();
    assert_eq!(s.chosen, "poulin-fournier", "{}", table(&s));
    let chosen = s.chosen_config.clone().unwrap();
    let coarse = fibrefit::fit::selection::ranking_config(&chosen).knobs;
    assert_eq!(chosen.search_knobs.as_ref(), Some(&coarse));
    assert_ne!(coarse, chosen.knobs, "the ranking knobs are coarser here");
    let fast = fit_with_hints(&data, &chosen, &quiet, &s.hints).unwrap();
    let mut slow_cfg = chosen.clone();
    slow_cfg.search_knobs = None;
    let slow = fit_with_hints(&data, &slow_cfg, &quiet, &s.hints).unwrap();
    // the same minimum: chi-squares within 1 of each other (one standard deviation apart)
    let (a, b) = (fast.statistics.chi_square, slow.statistics.chi_square);
    assert!((a - b).abs() <= 1.0, "chi-square {a} against {b}");
    for name in [
        "exponent",
        "spacing",
        "fibre_azimuth_deg",
        "azimuth_spread_deg",
        "ks",
    ] {
        let of = |o: &fibrefit::fit::FitOutcome| {
            let r = o.records.iter().find(|r| r.name == name).unwrap();
            (r.value[0], r.std_error[0].unwrap_or(0.0))
        };
        let ((x, sx), (y, _)) = (of(&fast), of(&slow));
        assert!(
            (x - y).abs() <= sx.max(1e-9),
            "{name}: {x} +/- {sx} against {y}"
        );
    }
    // a renderer's material is ranked at the config's knobs: its final fit searches there
    let mut g = small_auto("\"gltf\"");
    g.selection.fuzz = false;
    let s = select(&data, &g).unwrap();
    assert_eq!(s.chosen_config.unwrap().search_knobs, None);
}

#[test]
fn the_no_fuzz_setting_and_the_fuzz_flag_set_the_candidates() {
    let mut cfg = small_auto("\"lambert\", \"ward\"");
    let names = |c: &FitConfig| -> Vec<String> {
        fibrefit::fit::selection::candidates_of(c)
            .unwrap()
            .into_iter()
            .map(|c| c.0)
            .collect()
    };
    assert_eq!(
        names(&cfg),
        ["lambert", "lambert + fuzz", "ward", "ward + fuzz"]
    );
    cfg.selection.fuzz = false;
    assert_eq!(names(&cfg), ["lambert", "ward"]);
    // --fuzz (a fuzz parameter listed): every rung with the layer
    let mut with = small_auto("\"lambert\", \"ward\"");
    with.parameters
        .insert("fuzz_depth".into(), Default::default());
    assert_eq!(names(&with), ["lambert + fuzz", "ward + fuzz"]);
}

fn fibrefit() -> Command {
    Command::cargo_bin("fibrefit").unwrap()
}

/// `gonio.csv` of `d` without its sigma columns, written to `out`.
fn strip_sigmas(d: &Path, out: &Path) {
    let text = std::fs::read_to_string(d.join("gonio.csv")).unwrap();
    // the columns whose header does not name a sigma (comment lines kept as they are)
    let header = text.lines().find(|l| !l.starts_with('#')).unwrap();
    let keep: Vec<bool> = header.split(',').map(|c| !c.starts_with("sigma")).collect();
    let lines: Vec<String> = text
        .lines()
        .map(|l| match l.starts_with('#') {
            true => l.to_string(),
            false => l
                .split(',')
                .zip(&keep)
                .filter(|(_, k)| **k)
                .map(|(c, _)| c)
                .collect::<Vec<_>>()
                .join(","),
        })
        .collect();
    std::fs::write(out, lines.join("\n") + "\n").unwrap();
}

#[test]
fn data_spanning_decades_without_sigmas_are_fitted_in_the_log_metric_and_the_report_says_so() {
    let dir = tempfile::tempdir().unwrap();
    // a sharp lobe over a dark base: values span far more than a decade
    let d = synth_text(
        dir.path(),
        "hdr",
        "model = \"max-normal\"\n[params]\nkd = 0.02\nks = 0.6\nexponent = 20\n\
         [gonio]\nrandom = { count = 300, seed = 7, max_theta_deg = 75 }\n\
         [noise]\nrelative = 0.01\nseed = 8\n",
    );
    let csv = dir.path().join("hdr.csv");
    strip_sigmas(&d, &csv);
    let data = load_data(&csv, &LoadOptions::default()).unwrap();
    let why = fibrefit::fit::config::metric_for_data(&data);
    assert_eq!(why.0, Metric::Log, "{}", why.1);
    let out = dir.path().join("r.json");
    let o = fibrefit()
        .arg("fit")
        .arg(&csv)
        .args(["--model", "lambert", "--out"])
        .arg(&out)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let report = String::from_utf8_lossy(&o.stdout);
    assert!(
        report.contains("metric: log, chosen from the data"),
        "{report}"
    );
    let r: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&out).unwrap()).unwrap();
    assert_eq!(r["knobs"]["metric"], "log");
    assert!(
        r["knobs"]["metric_reason"]
            .as_str()
            .unwrap()
            .contains("no sigmas"),
        "{r}"
    );
    // --metric overrides
    let o = fibrefit()
        .arg("fit")
        .arg(&csv)
        .args(["--model", "lambert", "--metric", "linear", "--out"])
        .arg(&out)
        .output()
        .unwrap();
    assert!(o.status.success());
    let r: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&out).unwrap()).unwrap();
    assert_eq!(r["knobs"]["metric"], "linear");
    // with sigmas the same values stay linear (chi-square against their noise)
    let with = load_data(&d.join("gonio.csv"), &LoadOptions::default()).unwrap();
    assert_eq!(
        fibrefit::fit::config::metric_for_data(&with).0,
        Metric::Linear
    );
    // and a Lambertian set without sigmas (a factor of a few) stays linear
    let l = synth_text(
        dir.path(),
        "flat",
        "model = \"lambert\"\n[params]\nkd = 0.6\n[gonio]\n\
         random = { count = 100, seed = 4, max_theta_deg = 60 }\n\
         [noise]\nrelative = 0.02\nseed = 6\n",
    );
    assert_eq!(
        fibrefit::fit::config::metric_for_data(&without_sigmas(&l)).0,
        Metric::Linear
    );
}

/// `fibrefit fit --model auto` prints the model-selection table once (in the report, not again
/// through the progress lines), with the right counts: 5 folds of 300 hold out 60 each; the
/// result's `selection` block says what it counts; and `--json` carries the verdict and,
/// without sigmas, the residual variance under its own name, never a reduced chi-square.
#[test]
fn the_selection_table_is_printed_once_with_per_fold_counts_and_json_is_honest() {
    let dir = tempfile::tempdir().unwrap();
    let d = synth_text(
        dir.path(),
        "flat",
        "model = \"lambert\"\n[params]\nkd = 0.6\n[gonio]\n\
         random = { count = 300, seed = 4, max_theta_deg = 80 }\n\
         [noise]\nrelative = 0.02\nseed = 6\n",
    );
    let csv = dir.path().join("flat.csv");
    strip_sigmas(&d, &csv);
    let cfg = dir.path().join("auto.toml");
    std::fs::write(
        &cfg,
        "model = \"auto\"\nstarts = 2\nseed = 2\n[optimizer]\nglobal_candidates = 24\n\
         global_subsample = 300\n[selection]\nrungs = [\"lambert\", \"max-normal\"]\nfuzz = false\n",
    )
    .unwrap();
    let out = dir.path().join("r.json");
    let run = |json: bool| {
        let mut c = fibrefit();
        c.env("FIBREFIT_PROGRESS", "1")
            .arg("fit")
            .arg(&csv)
            .arg("--config")
            .arg(&cfg)
            .arg("--out")
            .arg(&out);
        if json {
            c.arg("--json");
        }
        let o = c.output().unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        (
            String::from_utf8_lossy(&o.stdout).into_owned(),
            String::from_utf8_lossy(&o.stderr).into_owned(),
        )
    };
    let (stdout, stderr) = run(false);
    let all = format!("{stdout}{stderr}");
    assert_eq!(all.matches("Model selection by").count(), 1, "{all}");
    assert!(stdout.contains("Model selection by"), "{stdout}");
    assert!(
        stdout.contains("240 training / 60 held-out samples per fold, 300 held out in all"),
        "{stdout}"
    );
    let r: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&out).unwrap()).unwrap();
    let s = &r["selection"];
    assert_eq!(s["folds"], 5, "{s}");
    assert_eq!(s["train_samples_per_fold"], 240, "{s}");
    assert_eq!(s["heldout_samples_per_fold"], 60, "{s}");
    assert_eq!(s["heldout_samples_total"], 300, "{s}");
    // --json: the summary line with the verdict; no sigmas: no chi-square
    let (stdout, _) = run(true);
    let line: serde_json::Value = serde_json::from_str(stdout.trim()).expect("one JSON line");
    assert_eq!(line["verdict"], r["quality"]["verdict"], "{line}");
    assert!(line["verdict"].as_str().is_some_and(|v| !v.is_empty()));
    assert!(line.get("reduced_chi_square").is_none(), "{line}");
    assert!(line["residual_variance"].as_f64().is_some(), "{line}");
    assert_eq!(line["sigmas_given"], false, "{line}");
}
