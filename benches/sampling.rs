//! Importance sampling per rung: `cargo bench --bench sampling`. One `Sampler::sample` (the
//! direction, its exact pdf over the whole mixture and the rung's evaluation at it) per
//! iteration over a fixed set of views and uniforms (`sample`), the same draws as one block
//! (`with_eval_batch`: `Sampler::sample_many`, the evaluations at once), and the sampler alone
//! with a constant model (`sampler_only`), and one instance of the material per draw where it
//! mixes several (`one_instance`: `Sampler::sample_instance`, a spread node and a histogram
//! height drawn with a third uniform). The variance the sampler buys is `fibrefit bench
//! --sampling` (reports/sampling.md).

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion, Throughput};
use fibrefit::bench::sampling::{HEIGHT_PER_DRAW, SPEED_VARIANTS};
use fibrefit::model::frame::Local;
use fibrefit::model::lambert::Lambert;
use fibrefit::model::params::{ModelParams, RawParams};
use fibrefit::model::sampling::{Draw, Sampler};
use fibrefit::model::{self, ModelId};
use std::hint::black_box;

fn params(id: ModelId, text: &str) -> ModelParams {
    let raw: RawParams = toml::from_str(text).unwrap();
    ModelParams::from_raw(&raw, id).unwrap().0
}

/// The rung's typical parameters from the registry, at exponent 1000 where it has one.
fn text(id: ModelId) -> String {
    id.rung().example_text(Some(1000.0))
}

/// 64 fixed (view, uniforms, height fraction) draws, views above the horizon.
fn draws() -> Vec<(Local, [f64; 2], f64)> {
    let mut s = 0x2545_F491_4F6C_DD1Du64;
    let mut u = move || {
        s ^= s << 13;
        s ^= s >> 7;
        s ^= s << 17;
        (s >> 11) as f64 / (1u64 << 53) as f64
    };
    (0..64)
        .map(|_| {
            let z = 0.05 + 0.95 * u();
            let r = (1.0 - z * z).sqrt();
            let p = std::f64::consts::TAU * u();
            let v = Local {
                t: r * p.cos(),
                b: r * p.sin(),
                n: z,
            };
            (v, [u(), u()], u())
        })
        .collect()
}

fn sampling(c: &mut Criterion) {
    let d = draws();
    let mut g = c.benchmark_group("sample");
    g.throughput(Throughput::Elements(d.len() as u64));
    let mut variants: Vec<(String, ModelId, String)> = ModelId::ALL
        .iter()
        .filter(|&&id| id != ModelId::Reference)
        .map(|&id| (id.to_string(), id, text(id).to_string()))
        .collect();
    // the variants of `fibrefit bench sampling`'s speed table, what issue 41's 2e6 samples/s
    // goal is read on
    for &(id, variant, extra) in &SPEED_VARIANTS {
        variants.push((format!("{id} {variant}"), id, text(id) + extra));
    }
    for (name, id, t) in &variants {
        let p = params(*id, t);
        let m = model::build(*id, &p).unwrap();
        let sampler = Sampler::new(*id, &p);
        // a per-texel height map: every draw at its own height over the whole range
        let top = fibrefit::model::topology::max_height(p.spacing);
        let per_draw = name.ends_with(HEIGHT_PER_DRAW);
        let height = |r: f64| per_draw.then_some(top * r);
        g.bench_with_input(BenchmarkId::new("with_eval", name), &d, |b, d| {
            b.iter(|| {
                d.iter()
                    .map(|(v, u, r)| {
                        sampler
                            .sample(m.as_ref(), &p.albedos, height(*r), black_box(v), *u)
                            .map_or(0.0, |s| s.weight[0])
                    })
                    .sum::<f64>()
            })
        });
        // the same draws as one block (`sample_many`: the evaluations at once, in lanes)
        let block: Vec<Draw> = d
            .iter()
            .map(|(v, u, r)| Draw {
                albedos: p.albedos,
                height: height(*r),
                v: *v,
                u: *u,
            })
            .collect();
        g.bench_with_input(
            BenchmarkId::new("with_eval_batch", name),
            &block,
            |b, block| {
                let mut out = vec![None; block.len()];
                b.iter(|| {
                    sampler.sample_many(m.as_ref(), black_box(block), &mut out);
                    out.iter().flatten().map(|s| s.weight[0]).sum::<f64>()
                })
            },
        );
        // one instance of the material per draw (a spread node and a histogram height, drawn
        // with the third uniform): where the material has more than one
        if sampler.instances_given(per_draw) > 1 {
            let aligned = model::build_instance(*id, &p).unwrap();
            g.bench_with_input(BenchmarkId::new("one_instance", name), &d, |b, d| {
                b.iter(|| {
                    d.iter()
                        .map(|(v, u, r)| {
                            let inst = sampler.instance(*r, height(*r));
                            sampler
                                .sample_instance(
                                    aligned.as_ref(),
                                    &p.albedos,
                                    &inst,
                                    black_box(v),
                                    *u,
                                )
                                .map_or(0.0, |s| s.weight[0])
                        })
                        .sum::<f64>()
                })
            });
        }
        g.bench_with_input(BenchmarkId::new("sampler_only", name), &d, |b, d| {
            b.iter(|| {
                d.iter()
                    .map(|(v, u, _)| {
                        sampler
                            .sample(&Lambert, &p.albedos, None, black_box(v), *u)
                            .map_or(0.0, |s| s.pdf)
                    })
                    .sum::<f64>()
            })
        });
    }
    g.finish();
}

criterion_group!(benches, sampling);
criterion_main!(benches);
