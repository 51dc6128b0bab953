//! The reported standard errors are honest: over 20 noise seeds the spread of the estimates
//! matches the mean reported standard error within a factor 1.5.

use fibrefit::fit::config::FitConfig;
use fibrefit::fit::fit;
use fibrefit::load::{load_data, LoadOptions};

fn synth(dir: &std::path::Path, seed: u64) -> std::path::PathBuf {
    let cfg = format!(
        r#"
model = "varying-topology"
[params]
kd = 0.5
ks = 0.25
exponent = 60
spacing = 2.4
height = 0.9
map_scale = 0.3
histogram_bins = 4
[topology_map]
width = 16
height = 16
seed = 3
[gonio]
random = {{ count = 500, seed = 1, max_theta_deg = 80 }}
[noise]
relative = 0.01
seed = {seed}
"#
    );
    let p = dir.join(format!("s{seed}.toml"));
    std::fs::write(&p, cfg).unwrap();
    let out = dir.join(format!("d{seed}"));
    fibrefit::synth::run(&p, &out, &fibrefit::progress::Progress::quiet()).unwrap();
    out
}

#[test]
fn spread_over_noise_seeds_matches_reported_errors() {
    let dir = tempfile::tempdir().unwrap();
    let names = ["kd", "ks", "exponent", "spacing", "height", "map_scale"];
    let mut est: Vec<Vec<f64>> = vec![vec![]; names.len()];
    let mut se: Vec<Vec<f64>> = vec![vec![]; names.len()];
    for seed in 0..20 {
        let d = synth(dir.path(), 100 + seed);
        let text = format!(
            r#"
model = "varying-topology"
starts = 1
seed = 1
[knobs]
histogram_bins = 4
topology_map = "{}"
[optimizer]
global_candidates = 8
[parameters]
kd = {{ value = 0.45 }}
ks = {{ value = 0.3 }}
exponent = {{ value = 50, min = 1, max = 1000 }}
spacing = {{ value = 2.5, min = 2, max = 4 }}
height = {{ value = 0.8, min = 0, max = 1.7 }}
map_scale = {{ value = 0.25, min = 0, max = 0.6 }}
"#,
            d.join("topology.png").display()
        );
        let cfg: FitConfig = toml::from_str(&text).unwrap();
        let data = load_data(&d.join("gonio.csv"), &LoadOptions::default()).unwrap();
        let o = fit(&data, &cfg, &fibrefit::progress::Progress::quiet()).unwrap();
        for (k, n) in names.iter().enumerate() {
            let r = o.records.iter().find(|r| r.name == *n).unwrap();
            est[k].push(r.value[0]);
            se[k].push(r.std_error[0].expect("standard error"));
        }
    }
    for (k, n) in names.iter().enumerate() {
        let m = est[k].iter().sum::<f64>() / 20.0;
        let spread = (est[k].iter().map(|x| (x - m).powi(2)).sum::<f64>() / 19.0).sqrt();
        let reported = se[k].iter().sum::<f64>() / 20.0;
        let ratio = spread / reported;
        eprintln!("{n}: spread {spread:.5}, mean reported SE {reported:.5}, ratio {ratio:.2}");
        assert!(
            (1.0 / 1.5..=1.5).contains(&ratio),
            "{n}: spread {spread} vs reported {reported} (ratio {ratio:.2})"
        );
    }
}
