//! `--model auto` picks the cheapest rung the data need (1 % noise each): `lambert` for
//! Lambertian data, `poulin-fournier` for flat fibres with gaps, `varying-topology` for climbing
//! fibres with a topology map.

use fibrefit::fit::config::FitConfig;
use fibrefit::fit::selection::{select, table};
use fibrefit::load::{load_data, LoadOptions};
use std::path::Path;

fn synth(dir: &Path, model: &str, params: &str) -> std::path::PathBuf {
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
    let p = dir.join(format!("{model}.toml"));
    std::fs::write(&p, text).unwrap();
    let out = dir.join(model);
    fibrefit::synth::run(&p, &out, true).unwrap();
    out
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
    assert_eq!(chosen(dir.path(), "lambert", "kd = 0.6"), "lambert");
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
