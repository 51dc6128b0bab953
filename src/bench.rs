//! `fibrefit bench`: the speed–accuracy trade, measured.
//!
//! Forward ladder: every rung and knob (N, K) on four parameter sets (flat, climbing, gapped,
//! sharp specular) over a fixed direction set with random, grazing and near-tangent pairs:
//! median ns per evaluation (single thread, one batch through `basis_many`) and RMS / maximum
//! relative error against `reference`. Rungs with other physics (lambert, hast-diffuse,
//! max-normal, ward) are first fitted to the reference values, so their error is the best they
//! can do. Fit level: wall time, iterations
//! and parameter error against the truth of a shipped capture at several subsampling fractions
//! and quadrature orders.

pub mod camera;
pub mod felt;
pub mod maps;
pub mod photos;
pub mod real;
pub mod render;
pub mod renderers;
pub mod report;
pub mod robustness;
pub mod sampling;
pub mod selection;
pub mod shader;

use crate::fit::config::FitConfig;
use crate::load::samples::{DataKind, Dropped, Origin, Sample, Samples};
use crate::load::{capture::Subsample, load_data, LoadOptions};
use crate::model::frame::{direction_from_angles, FibreFrame, Vec3};
use crate::model::topology::Topology;
use crate::model::{self, Albedos, Basis, DirectionPair, ShadingModel};
use anyhow::{anyhow, Result};
use indicatif::ProgressBar;
use rand::{Rng, SeedableRng};
use std::path::Path;
use std::time::Instant;

#[derive(Clone, Debug, serde::Serialize)]
pub struct ForwardRow {
    pub set: String,
    pub rung: String,
    pub knob: String,
    pub ns_per_eval: f64,
    pub rms_rel_error: f64,
    pub max_rel_error: f64,
}

#[derive(Clone, Debug, serde::Serialize)]
pub struct FitRow {
    pub fraction: f64,
    pub quadrature_order: usize,
    pub samples: usize,
    pub seconds: f64,
    pub iterations: u64,
    pub max_param_rel_error: f64,
    pub param_rel_errors: String,
}

/// A cross-section parameter set.
#[derive(Clone, Copy, Debug)]
pub struct ParamSet {
    pub name: &'static str,
    pub spacing: f64,
    pub height: f64,
    pub map_scale: f64,
    pub exponent: f64,
    pub substrate: f64,
}

pub const SETS: [ParamSet; 4] = [
    ParamSet {
        name: "flat",
        spacing: 2.0,
        height: 0.0,
        map_scale: 0.0,
        exponent: 20.0,
        substrate: 0.6,
    },
    ParamSet {
        name: "climbing",
        spacing: 2.0,
        height: 0.9,
        map_scale: 0.25,
        exponent: 40.0,
        substrate: 0.6,
    },
    ParamSet {
        name: "gapped",
        spacing: 4.0,
        height: 0.0,
        map_scale: 0.0,
        exponent: 10.0,
        substrate: 0.3,
    },
    ParamSet {
        name: "sharp",
        spacing: 2.0,
        height: 0.5,
        map_scale: 0.0,
        exponent: 1000.0,
        substrate: 0.6,
    },
];

pub const ORDERS: [usize; 6] = [2, 4, 8, 16, 32, 64];
pub const BINS: [usize; 4] = [1, 4, 16, 64];

/// The fixed direction set (fibres along x): seeded random pairs plus grazing and near-tangent.
pub fn directions(random: usize) -> Vec<DirectionPair> {
    let frame = FibreFrame::from_azimuth(0.0);
    let mut rng = rand::rngs::StdRng::seed_from_u64(2024);
    let mut dir = |max_deg: f64| {
        let cos_max = max_deg.to_radians().cos();
        let z: f64 = cos_max + (1.0 - cos_max) * rng.random::<f64>();
        direction_from_angles(z.acos(), std::f64::consts::TAU * rng.random::<f64>())
    };
    let mut pairs: Vec<DirectionPair> = (0..random)
        .map(|_| {
            let (l, v) = (dir(80.0), dir(80.0));
            DirectionPair::new(&frame, &l, &v)
        })
        .collect();
    let d = |t: f64, p: f64| direction_from_angles(t.to_radians(), p.to_radians());
    for (tl, pl, tv, pv) in [
        (85.0, 90.0, 30.0, 270.0),
        (88.0, 90.0, 88.0, 90.0),
        (89.5, 270.0, 20.0, 90.0),
        (60.0, 0.0, 89.0, 180.0),
        (87.0, 45.0, 87.0, 225.0),
        (89.0, 120.0, 45.0, 300.0),
    ] {
        pairs.push(DirectionPair::new(&frame, &d(tl, pl), &d(tv, pv)));
    }
    // near-tangent: light almost along the fibres
    for (eps, v) in [
        (0.05, d(30.0, 90.0)),
        (0.02, d(50.0, 200.0)),
        (0.1, d(10.0, 0.0)),
    ] {
        let l = Vec3::new(1.0, 0.0, eps).normalize();
        pairs.push(DirectionPair::new(&frame, &l, &v));
    }
    pairs
}

fn albedos(set: &ParamSet) -> Albedos {
    Albedos::grey(0.6, 0.3, set.substrate)
}

fn topology(set: &ParamSet) -> Topology {
    Topology {
        height: set.height,
        map_scale: set.map_scale,
        map: None,
    }
}

/// Median ns per evaluation over `repeats` passes, and the values (combined with the albedos).
fn timed(
    m: &dyn ShadingModel,
    pairs: &[DirectionPair],
    a: &Albedos,
    repeats: usize,
) -> (f64, Vec<f64>) {
    let mut times = Vec::new();
    let mut values = Vec::new();
    let mut bases = vec![Basis::default(); pairs.len()];
    for _ in 0..repeats.max(1) {
        let t = Instant::now();
        // one batch, as the fitter evaluates its samples
        m.basis_many(pairs, &mut bases);
        values = bases.iter().map(|b| b.brdf(a, 0)).collect();
        times.push(t.elapsed().as_nanos() as f64 / pairs.len() as f64);
    }
    times.sort_by(f64::total_cmp);
    (times[times.len() / 2], values)
}

fn errors(values: &[f64], reference: &[f64]) -> (f64, f64) {
    let rel: Vec<f64> = values
        .iter()
        .zip(reference)
        .filter(|(_, r)| **r > 1e-12)
        .map(|(v, r)| (v - r).abs() / r)
        .collect();
    let rms = (rel.iter().map(|e| e * e).sum::<f64>() / rel.len().max(1) as f64).sqrt();
    (rms, rel.iter().copied().fold(0.0, f64::max))
}

/// Fit a cheap rung to reference values (its best case) and return the fitted model values.
fn best_case(
    rung: &str,
    pairs: &[DirectionPair],
    reference: &[f64],
) -> Result<(Box<dyn ShadingModel>, Albedos)> {
    let samples: Vec<Sample> = pairs
        .iter()
        .zip(reference)
        .enumerate()
        .map(|(k, (p, &f))| Sample {
            l: Vec3::new(p.l.t, p.l.b, p.l.n),
            v: Vec3::new(p.v.t, p.v.b, p.v.n),
            fibre_azimuth: None,
            map_value: None,
            texel_height: None,
            value: [f; 3],
            sigma: None,
            weight: 1.0,
            origin: Origin::Line(k as u64),
        })
        .collect();
    let data = Samples {
        samples,
        channels: 1,
        kind: DataKind::Gonio,
        source: "reference".into(),
        dropped: Dropped::default(),
        skipped_examples: vec![],
        image_size: None,
        scale_rel_se: None,
    };
    let cfg: FitConfig = toml::from_str(&format!(
        "model = \"{rung}\"\nstarts = 2\n[optimizer]\nglobal_candidates = 16\n"
    ))?;
    let o = crate::fit::fit(&data, &cfg, &crate::progress::Progress::quiet())?;
    let m = crate::fit::problem::model_for(&o.set, 16, 16, 16, None);
    Ok((m, crate::fit::problem::albedos_of(&o.set)))
}

/// The forward ladder on every parameter set.
pub fn forward(quick: bool, bar: &ProgressBar) -> Result<Vec<ForwardRow>> {
    let pairs = directions(if quick { 40 } else { 160 });
    let repeats = if quick { 3 } else { 7 };
    let mut rows = Vec::new();
    for set in &SETS {
        bar.set_message(format!("forward ladder: {}", set.name));
        let a = albedos(set);
        let reference = model::reference::Reference::new(set.spacing, set.exponent, topology(set));
        let t = Instant::now();
        let ref_values: Vec<f64> = pairs
            .iter()
            .map(|p| reference.basis(p).brdf(&a, 0))
            .collect();
        let ref_ns = t.elapsed().as_nanos() as f64 / pairs.len() as f64;
        rows.push(ForwardRow {
            set: set.name.into(),
            rung: "reference".into(),
            knob: "adaptive 1e-12".into(),
            ns_per_eval: ref_ns,
            rms_rel_error: 0.0,
            max_rel_error: 0.0,
        });
        bar.inc(1);
        let mut push = |rung: &str, knob: String, m: &dyn ShadingModel, a: &Albedos| {
            let (ns, values) = timed(m, &pairs, a, repeats);
            let (rms, max) = errors(&values, &ref_values);
            rows.push(ForwardRow {
                set: set.name.into(),
                rung: rung.into(),
                knob,
                ns_per_eval: ns,
                rms_rel_error: rms,
                max_rel_error: max,
            });
        };
        for rung in ["lambert", "hast-diffuse", "max-normal", "ward"] {
            let (m, fitted) = best_case(rung, &pairs, &ref_values)?;
            push(rung, "fitted to reference".into(), m.as_ref(), &fitted);
        }
        bar.inc(1);
        let pf = model::poulin_fournier::PoulinFournier::new(set.spacing, set.exponent, 16);
        push("poulin-fournier", "N=16".into(), &pf, &a);
        for n in ORDERS {
            let m = model::varying_topology::VaryingTopology::new(
                set.spacing,
                set.exponent,
                n,
                topology(set).discretise(set.spacing, 16),
            );
            push("varying-topology", format!("N={n} K=16"), &m, &a);
        }
        for k in BINS {
            let m = model::varying_topology::VaryingTopology::new(
                set.spacing,
                set.exponent,
                16,
                topology(set).discretise(set.spacing, k),
            );
            push("varying-topology", format!("N=16 K={k}"), &m, &a);
        }
        bar.inc(1);
    }
    rows.extend(spread_rows(&pairs, repeats));
    Ok(rows)
}

/// The fibre-direction spread's knob: poulin-fournier on the gapped set (d 4) with a 30 deg
/// spread, at several azimuth node counts, against the reference integrating the same law
/// adaptively.
fn spread_rows(pairs: &[DirectionPair], repeats: usize) -> Vec<ForwardRow> {
    use model::azimuth_spread::AzimuthSpread;
    let set = &SETS[2];
    let a = albedos(set);
    let spread = 30.0;
    let reference = AzimuthSpread::new(
        Box::new(model::reference::Reference::new(
            set.spacing,
            set.exponent,
            topology(set),
        )),
        spread,
        1,
        0.0,
    );
    let t = Instant::now();
    let ref_values: Vec<f64> = pairs
        .iter()
        .map(|p| reference.basis(p).brdf(&a, 0))
        .collect();
    let mut rows = vec![ForwardRow {
        set: "spread".into(),
        rung: "reference".into(),
        knob: format!("spread {spread} deg, adaptive 1e-8"),
        ns_per_eval: t.elapsed().as_nanos() as f64 / pairs.len() as f64,
        rms_rel_error: 0.0,
        max_rel_error: 0.0,
    }];
    for nodes in [4, 8, 16, 32, 64] {
        let pf = model::poulin_fournier::PoulinFournier::new(set.spacing, set.exponent, 16);
        let m = AzimuthSpread::new(Box::new(pf), spread, nodes, 0.0);
        let (ns, values) = timed(&m, pairs, &a, repeats);
        let (rms, max) = errors(&values, &ref_values);
        rows.push(ForwardRow {
            set: "spread".into(),
            rung: "poulin-fournier".into(),
            knob: format!("spread {spread} deg, N=16, azimuth nodes {nodes}"),
            ns_per_eval: ns,
            rms_rel_error: rms,
            max_rel_error: max,
        });
    }
    rows
}

/// Fit level on the shipped silk capture: subsampling fractions x quadrature orders.
pub fn fit_level(root: &Path, quick: bool, bar: &ProgressBar) -> Result<Vec<FitRow>> {
    let data_path = root.join("data_synthetic/silk/capture.toml");
    let truth =
        crate::export::result_json::read_params(&root.join("data_synthetic/silk/truth.json"))?;
    let mut cfg = FitConfig::load(&root.join("configs/fit_silk.toml"))?;
    cfg.starts = 1;
    let fractions: &[f64] = if quick {
        &[0.02, 0.1]
    } else {
        &[0.02, 0.1, 0.5]
    };
    let orders: &[usize] = if quick { &[4, 16] } else { &[4, 16, 64] };
    let want = |name: &str| -> Option<f64> {
        use crate::model::Param;
        match Param::from_name(name)? {
            Param::Exponent => truth.exponent,
            Param::Height => truth.height,
            Param::MapScale => truth.map_scale,
            Param::Kd => truth.kd.map(|a| a.channels()[0]),
            Param::Ks => truth.ks.map(|a| a.channels()[0]),
            _ => None,
        }
    };
    let mut rows = Vec::new();
    for &fraction in fractions {
        let data = load_data(
            &data_path,
            &LoadOptions {
                subsample: Subsample {
                    stride: 1,
                    fraction,
                    seed: 1,
                },
                ..Default::default()
            },
        )?;
        for &n in orders {
            bar.set_message(format!("fit level: fraction {fraction}, N = {n}"));
            cfg.knobs.quadrature_order = n;
            let t = Instant::now();
            let o = crate::fit::fit(&data, &cfg, &crate::progress::Progress::quiet())?;
            let seconds = t.elapsed().as_secs_f64();
            let mut errs = Vec::new();
            for r in &o.records {
                if let Some(w) = want(&r.name) {
                    errs.push((r.name.clone(), (r.value[0] - w).abs() / w));
                }
            }
            let max = errs.iter().map(|e| e.1).fold(0.0, f64::max);
            rows.push(FitRow {
                fraction,
                quadrature_order: n,
                samples: data.samples.len(),
                seconds,
                iterations: o.iterations,
                max_param_rel_error: max,
                param_rel_errors: errs
                    .iter()
                    .map(|(k, e)| format!("{k} {e:.2e}"))
                    .collect::<Vec<_>>()
                    .join("; "),
            });
            bar.inc(1);
        }
    }
    if rows.is_empty() {
        return Err(anyhow!("no fit-level runs"));
    }
    Ok(rows)
}
