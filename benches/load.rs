//! Loading cost: `cargo bench --bench load`. A 1e6-row RGB goniometric CSV with sigmas.

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use fibrefit::load::gonio::{self, GonioOptions};
use std::io::Write;

fn big_csv(rows: usize) -> tempfile::NamedTempFile {
    let mut f = tempfile::Builder::new().suffix(".csv").tempfile().unwrap();
    let mut w = std::io::BufWriter::new(f.as_file_mut());
    writeln!(
        w,
        "theta_i,phi_i,theta_o,phi_o,brdf_r,brdf_g,brdf_b,sigma_r,sigma_g,sigma_b"
    )
    .unwrap();
    let mut s = 0x1234_5678_9abc_def1u64;
    let mut u = move || {
        s ^= s << 13;
        s ^= s >> 7;
        s ^= s << 17;
        (s >> 11) as f64 / (1u64 << 53) as f64
    };
    for _ in 0..rows {
        writeln!(
            w,
            "{:.6},{:.6},{:.6},{:.6},{:.8},{:.8},{:.8},0.001,0.001,0.001",
            85.0 * u(),
            360.0 * u(),
            85.0 * u(),
            360.0 * u(),
            u(),
            u(),
            u()
        )
        .unwrap();
    }
    drop(w);
    f
}

fn load(c: &mut Criterion) {
    let rows = 1_000_000;
    let file = big_csv(rows);
    let mut g = c.benchmark_group("load");
    g.throughput(Throughput::Elements(rows as u64));
    g.sample_size(10);
    g.bench_function("gonio-csv/1e6-rows-rgb-sigma", |b| {
        b.iter(|| {
            gonio::load(file.path(), &GonioOptions::default())
                .unwrap()
                .samples
                .len()
        })
    });
    g.finish();
}

criterion_group!(benches, load);
criterion_main!(benches);
