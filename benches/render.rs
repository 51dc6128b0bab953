//! Render cost: `cargo bench --bench render`. A 1 Mpx (1024 x 1024, one ray per pixel)
//! varying-topology torus (seed 001's, fibres climbing twice), one light; issue 14's goal is
//! <= 2 s on 2 cores.

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use fibrefit::model::frame::direction_from_angles;
use fibrefit::model::params::{ModelParams, RawParams};
use fibrefit::model::{self, ModelId};
use fibrefit::render::objects::Object;
use fibrefit::render::{render, Camera, Light, Material};

fn torus(c: &mut Criterion) {
    let raw: RawParams =
        toml::from_str("kd = 0.5\nks = 0.4\nexponent = 60\nspacing = 2.0\n").unwrap();
    let (params, _) = ModelParams::from_raw(&raw, ModelId::VaryingTopology).unwrap();
    let m = model::build(ModelId::VaryingTopology, &params).unwrap();
    let material = Material {
        model: m.as_ref(),
        albedos: params.albedos,
        channels: 1,
        spacing: 2.0,
        height: 0.0,
        map_scale: 0.0,
        topology_map: None,
        texel_maps: None,
        fibre_azimuth_deg: 0.0,
        lobe: params.gltf.lobe(),
        ward_curvature: None,
        correction: None,
    };
    let lights = [Light::Directional {
        direction: direction_from_angles(40f64.to_radians(), 120f64.to_radians()),
        irradiance: 1.0,
    }];
    let camera = Camera {
        direction: direction_from_angles(50f64.to_radians(), 270f64.to_radians()),
        target: fibrefit::model::frame::Vec3::zeros(),
        width: 1024,
        height: 1024,
        half_width: 1.05,
        pinhole: None,
    };
    let bar = indicatif::ProgressBar::hidden();
    let mut g = c.benchmark_group("render");
    g.sample_size(10);
    g.throughput(Throughput::Elements(1024 * 1024));
    g.bench_function("varying-topology torus 1 Mpx (per pixel)", |b| {
        b.iter(|| {
            render(
                &[Object::Torus { spacing: 2.0 }],
                &material,
                &lights,
                &camera,
                1,
                &bar,
            )
            .alpha
            .len()
        })
    });
    g.finish();
}

criterion_group!(benches, torus);
criterion_main!(benches);
