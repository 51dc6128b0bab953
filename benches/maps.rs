//! Camera-resolution costs: `cargo bench --bench maps`. A synthetic 64 x 64 x 8 capture
//! (varying-topology, 1 % noise): loading it into the compact store (per pixel value), and the
//! per-texel stage of map recovery (H and psi) given the globals (per texel). The whole-capture
//! figures at 8 x 1 Mpx are `fibrefit bench --camera` (reports/camera_resolution.md).

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use fibrefit::fit::config::FitConfig;
use fibrefit::fit::maps;
use fibrefit::load::capture_store::CaptureStore;

const SIZE: usize = 64;

fn capture(dir: &std::path::Path) -> std::path::PathBuf {
    let mut s = format!(
        "model = \"varying-topology\"\n[params]\nkd = 0.4\nks = 0.3\nexponent = 40\nspacing = 2.0\nheight = 0.9\nmap_scale = 0.6\nfibre_azimuth_deg = 0\n[topology_map]\nwidth = {SIZE}\nheight = {SIZE}\nseed = 3\n[capture]\nwidth = {SIZE}\nheight = {SIZE}\nsize_mm = [20.0, 20.0]\nformat = \"exr\"\ntangent = {{ from_deg = -30, to_deg = 40 }}\n"
    );
    for [lt, lp, vt, vp] in fibrefit::bench::maps::EIGHT_IMAGES {
        s += &format!(
            "[[capture.images]]\nlight = {{ type = \"directional\", theta_deg = {lt}, phi_deg = {lp}, irradiance = 1.0 }}\ncamera = {{ type = \"orthographic\", theta_deg = {vt}, phi_deg = {vp} }}\n"
        );
    }
    s += "[noise]\nrelative = 0.01\nseed = 5\n";
    std::fs::write(dir.join("synth.toml"), s).unwrap();
    fibrefit::synth::run(
        &dir.join("synth.toml"),
        &dir.join("d"),
        &fibrefit::progress::Progress::quiet(),
    )
    .unwrap();
    fibrefit::bench::maps::write_blind(&dir.join("d")).unwrap()
}

fn camera(c: &mut Criterion) {
    let dir = tempfile::tempdir().unwrap();
    let path = capture(dir.path());
    let store = CaptureStore::load(&path, Default::default()).unwrap();
    let values = store.sample_count() as u64;
    let mut g = c.benchmark_group("camera");
    g.sample_size(10);
    g.throughput(Throughput::Elements(values));
    g.bench_function("capture-store-load/64x64x8-exr (per pixel value)", |b| {
        b.iter(|| {
            CaptureStore::load(&path, Default::default())
                .unwrap()
                .sample_count()
        })
    });
    let cfg: FitConfig = toml::from_str(fibrefit::bench::camera::FIT_MAPS).unwrap();
    let globals = maps::global_stage(
        &store,
        &cfg,
        &cfg.maps,
        &fibrefit::progress::Progress::quiet(),
    )
    .unwrap();
    let rows = 8u32;
    g.throughput(Throughput::Elements(rows as u64 * SIZE as u64));
    g.bench_function("texel-stage/H+psi (per texel)", |b| {
        b.iter(|| {
            maps::texel_stage(
                &maps::TexelStageRequest {
                    store: &store,
                    cfg: &cfg,
                    req: &cfg.maps,
                    set: &globals.outcome.set,
                    rows: (0, rows),
                    variance_hint: globals.texel_variance,
                    schur: Some(&globals.schur),
                },
                &fibrefit::progress::Progress::quiet(),
            )
            .unwrap()
            .values
            .len()
        })
    });
    g.finish();
}

criterion_group!(benches, camera);
criterion_main!(benches);
