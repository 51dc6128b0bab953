//! Cost of each rung, per evaluation of one (l, v) pair: `cargo bench --bench forward`.
//! Parallel throughput of `varying-topology` (N = 16) on all cores is the `parallel` group: chunks
//! of 1024 pairs through `basis_many` on rayon's pool, as the fitter evaluates its samples.

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion, Throughput};
use fibrefit::model::frame::{direction_from_angles, FibreFrame};
use fibrefit::model::topology::Topology;
use fibrefit::model::*;
use rayon::prelude::*;
use std::hint::black_box;

/// Fixed pseudo-random pairs above the horizon (same set every run).
fn pairs(n: usize) -> Vec<DirectionPair> {
    let fr = FibreFrame::from_azimuth(0.3);
    let mut s = 0x2545_F491_4F6C_DD1Du64;
    let mut u = move || {
        s ^= s << 13;
        s ^= s >> 7;
        s ^= s << 17;
        (s >> 11) as f64 / (1u64 << 53) as f64
    };
    (0..n)
        .map(|_| {
            let l = direction_from_angles(u().acos(), std::f64::consts::TAU * u());
            let v = direction_from_angles(u().acos(), std::f64::consts::TAU * u());
            DirectionPair::new(&fr, &l, &v)
        })
        .collect()
}

/// One pair at a time: the latency of a single evaluation.
fn eval_all(m: &dyn ShadingModel, ps: &[DirectionPair]) -> f64 {
    ps.iter()
        .map(|p| {
            let b = m.basis(black_box(p));
            b.diffuse + b.specular + b.substrate
        })
        .sum()
}

/// A batch through `basis_many`, as the fitter evaluates its samples.
fn eval_batch(m: &dyn ShadingModel, ps: &[DirectionPair]) -> f64 {
    let mut out = vec![Basis::default(); ps.len()];
    m.basis_many(black_box(ps), &mut out);
    out.iter()
        .map(|b| b.diffuse + b.specular + b.substrate)
        .sum()
}

fn rungs(c: &mut Criterion) {
    let ps = pairs(4096);
    let (d, h, e) = (2.2, 1.0, 60.0);
    let topo = Topology {
        height: h,
        map_scale: 0.0,
        map: None,
    };
    let mut g = c.benchmark_group("rung");
    g.throughput(Throughput::Elements(ps.len() as u64));
    let models: Vec<(String, Box<dyn ShadingModel>)> = vec![
        ("lambert".into(), Box::new(lambert::Lambert)),
        ("max-normal".into(), Box::new(max_normal::MaxNormal::new(e))),
        ("hast-diffuse".into(), Box::new(hast_diffuse::HastDiffuse)),
        ("ward".into(), Box::new(ward::Ward::new(0.1, 0.3))),
        (
            "poulin-fournier/N16".into(),
            Box::new(poulin_fournier::PoulinFournier::new(d, e, 16)),
        ),
        (
            "varying-topology/N4".into(),
            Box::new(varying_topology::VaryingTopology::new(
                d,
                e,
                4,
                topo.discretise(d, 1),
            )),
        ),
        (
            "varying-topology/N16".into(),
            Box::new(varying_topology::VaryingTopology::new(
                d,
                e,
                16,
                topo.discretise(d, 1),
            )),
        ),
        (
            "varying-topology/N64".into(),
            Box::new(varying_topology::VaryingTopology::new(
                d,
                e,
                64,
                topo.discretise(d, 1),
            )),
        ),
    ];
    for (name, m) in &models {
        g.bench_function(BenchmarkId::from_parameter(name), |b| {
            b.iter(|| eval_all(m.as_ref(), &ps))
        });
    }
    // the same pairs as one batch (basis_many)
    for (name, m) in models.iter().filter(|(n, _)| n.contains("N16")) {
        g.bench_function(BenchmarkId::from_parameter(format!("{name}/batch")), |b| {
            b.iter(|| eval_batch(m.as_ref(), &ps))
        });
    }
    g.finish();

    // Histogram bins multiply the cost; the reference is slow, so fewer pairs.
    let mut g = c.benchmark_group("rung-slow");
    let few = &ps[..64];
    g.throughput(Throughput::Elements(few.len() as u64));
    g.sample_size(10);
    let spread = Topology {
        height: h,
        map_scale: 0.25,
        map: None,
    };
    let vt16 = varying_topology::VaryingTopology::new(d, e, 16, spread.discretise(d, 16));
    g.bench_function("varying-topology/N16/K16", |b| {
        b.iter(|| eval_all(&vt16, few))
    });
    let reference = reference::Reference::new(d, e, topo);
    g.bench_function("reference", |b| b.iter(|| eval_all(&reference, few)));
    g.finish();
}

fn parallel(c: &mut Criterion) {
    let ps = pairs(1 << 16);
    let topo = Topology {
        height: 1.0,
        map_scale: 0.0,
        map: None,
    };
    let m = varying_topology::VaryingTopology::new(2.2, 60.0, 16, topo.discretise(2.2, 1));
    let mut g = c.benchmark_group("parallel");
    g.throughput(Throughput::Elements(ps.len() as u64));
    g.sample_size(20);
    g.bench_function(
        format!(
            "varying-topology/N16/{}-threads",
            rayon::current_num_threads()
        ),
        |b| {
            b.iter(|| {
                ps.par_chunks(1024)
                    .map(|chunk| eval_batch(&m, chunk))
                    .sum::<f64>()
            })
        },
    );
    g.finish();
}

criterion_group!(benches, rungs, parallel);
criterion_main!(benches);
