//! Cost of a whole fit: `cargo bench --bench fit`. 10 000 goniometric samples rendered by
//! `synth` (varying topology, topology map, 1 % noise); the full varying-topology model with a
//! K-bin topology histogram; 7 free parameters (exponent, spacing, height, map_scale,
//! fibre_azimuth_deg, kd, ks).

use criterion::{criterion_group, criterion_main, Criterion};
use fibrefit::fit::{config::FitConfig, fit};
use fibrefit::load::{load_data, LoadOptions};

fn setup(dir: &std::path::Path) {
    let synth = r#"
model = "varying-topology"
[params]
kd = 0.5
ks = 0.25
exponent = 60
spacing = 2.3
height = 0.9
map_scale = 0.3
fibre_azimuth_deg = 15
histogram_bins = 8
[topology_map]
width = 32
height = 32
seed = 3
[gonio]
random = { count = 10000, seed = 1, max_theta_deg = 80 }
[noise]
relative = 0.01
seed = 2
"#;
    std::fs::write(dir.join("synth.toml"), synth).unwrap();
    fibrefit::synth::run(
        &dir.join("synth.toml"),
        &dir.join("data"),
        &fibrefit::progress::Progress::quiet(),
    )
    .unwrap();
}

fn config(dir: &std::path::Path, bins: usize) -> FitConfig {
    let text = format!(
        r#"
model = "varying-topology"
starts = 1
seed = 1
[knobs]
histogram_bins = {bins}
topology_map = "{}"
[parameters]
kd = {{ value = 0.4 }}
ks = {{ value = 0.3 }}
exponent = {{ value = 30, min = 1, max = 1000 }}
spacing = {{ value = 2.5, min = 2, max = 4 }}
height = {{ value = 0.6, min = 0, max = 1.7 }}
map_scale = {{ value = 0.1, min = 0, max = 0.6 }}
fibre_azimuth_deg = {{ value = 0, min = -90, max = 90 }}
"#,
        dir.join("data/topology.png").display()
    );
    toml::from_str(&text).unwrap()
}

fn bench(c: &mut Criterion) {
    let dir = tempfile::tempdir().unwrap();
    setup(dir.path());
    let data = load_data(&dir.path().join("data/gonio.csv"), &LoadOptions::default()).unwrap();
    let mut g = c.benchmark_group("fit");
    g.sample_size(10);
    for bins in [4, 8] {
        let cfg = config(dir.path(), bins);
        let o = fit(&data, &cfg, &fibrefit::progress::Progress::quiet()).unwrap();
        eprintln!(
            "fit/10k/K{bins}: {} LM iterations on all samples, {} model evaluations, relative RMSE {:.4}",
            o.iterations, o.evaluations, o.statistics.relative_rmse
        );
        g.bench_function(
            format!("varying-topology/10k-samples/7-free/K{bins}"),
            |b| {
                b.iter(|| {
                    fit(&data, &cfg, &fibrefit::progress::Progress::quiet())
                        .unwrap()
                        .statistics
                        .chi_square
                })
            },
        );
    }
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
