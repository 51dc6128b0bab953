//! `fibrefit bench robustness`: how often the default fit finds the global minimum.
//!
//! Hard synthetic truths (climbing fibres at d = 2 near both flat limits, gapped d > 3, sharp
//! specular e = 1000, the fibre azimuth near the wrap at +-90 deg, a topology map, and diffuse-only
//! swatches like the path-traced ones that exposed wrong minima) are rendered as goniometric data
//! with 1 % Gaussian noise and sigmas, once per noise seed, and fitted from a random start inside
//! the bounds with the default optimizer settings. A run succeeds when its final chi-square is
//! within the noise of the truth's: chi2_fit - chi2_truth <= sqrt(2 (n - p)), one standard
//! deviation of the truth's own chi-square.

use crate::fit::config::FitConfig;
use crate::fit::problem::FitProblem;
use crate::fit::{fit, parameters::ParamSet};
use crate::load::samples::{DataKind, Dropped, Origin, Sample, Samples};
use crate::model::frame::{direction_from_angles, FibreFrame};
use crate::model::params::{ModelParams, RawParams};
use crate::model::{self, DirectionPair, ModelId, Param};
use anyhow::{Context, Result};
use indicatif::ProgressBar;
use rand::{Rng, SeedableRng};
use rand_distr::{Distribution, StandardNormal};
use std::path::Path;
use std::time::Instant;

/// One hard truth.
#[derive(Clone, Copy, Debug)]
pub struct Case {
    pub name: &'static str,
    pub what: &'static str,
    pub spacing: f64,
    pub height: f64,
    pub exponent: f64,
    pub ks: f64,
    pub azimuth_deg: f64,
    /// > 0: a generated topology map with this scale.
    pub map_scale: f64,
}

pub const CASES: [Case; 8] = [
    Case {
        name: "near-flat",
        what: "d = 2, climbing barely (H = 0.12)",
        spacing: 2.0,
        height: 0.12,
        exponent: 60.0,
        ks: 0.25,
        azimuth_deg: 20.0,
        map_scale: 0.0,
    },
    Case {
        name: "near-top",
        what: "d = 2, nearly a new flat layer (H = 1.62 of 1.73)",
        spacing: 2.0,
        height: 1.62,
        exponent: 60.0,
        ks: 0.25,
        azimuth_deg: -35.0,
        map_scale: 0.0,
    },
    Case {
        name: "gapped",
        what: "d = 3.6, elevation 14.5 deg, substrate visible",
        spacing: 3.6,
        height: 0.9,
        exponent: 30.0,
        ks: 0.25,
        azimuth_deg: 50.0,
        map_scale: 0.0,
    },
    Case {
        name: "sharp",
        what: "d = 2.2, sharp specular e = 1000",
        spacing: 2.2,
        height: 0.7,
        exponent: 1000.0,
        ks: 0.3,
        azimuth_deg: 0.0,
        map_scale: 0.0,
    },
    Case {
        name: "wrap",
        what: "d = 2.5, azimuth 88 deg (near the wrap)",
        spacing: 2.5,
        height: 1.0,
        exponent: 40.0,
        ks: 0.25,
        azimuth_deg: 88.0,
        map_scale: 0.0,
    },
    Case {
        name: "mapped",
        what: "d = 2.3, H0 = 0.9 with a topology map, s = 0.3",
        spacing: 2.3,
        height: 0.9,
        exponent: 60.0,
        ks: 0.25,
        azimuth_deg: -60.0,
        map_scale: 0.3,
    },
    Case {
        name: "diffuse-d2",
        what: "diffuse only, d = 2, elevation 35 deg",
        spacing: 2.0,
        height: 1.147152872702092,
        exponent: 1.0,
        ks: 0.0,
        azimuth_deg: 10.0,
        map_scale: 0.0,
    },
    Case {
        name: "diffuse-d3",
        what: "diffuse only, d = 3, elevation 20 deg",
        spacing: 3.0,
        height: 1.026060429977006,
        exponent: 1.0,
        ks: 0.0,
        azimuth_deg: -70.0,
        map_scale: 0.0,
    },
];

/// One fit of the study.
#[derive(Clone, Debug, serde::Serialize)]
pub struct Run {
    pub case: String,
    pub seed: u64,
    pub samples: usize,
    pub chi2_truth: f64,
    pub chi2_fit: f64,
    /// (chi2_fit - chi2_truth) / sqrt(2 (n - p)).
    pub excess_in_sd: f64,
    pub success: bool,
    pub seconds: f64,
    pub evaluations: usize,
    pub warnings: usize,
    /// The fitted shape parameters, "name value; ...".
    pub fitted: String,
}

/// Directions, data rows and noise seeds of a study.
#[derive(Clone, Copy, Debug)]
pub struct StudySize {
    pub samples: usize,
    pub seeds: u64,
}

fn truth_params(case: &Case, map: Option<&Path>) -> Result<ModelParams> {
    let mut raw = RawParams {
        kd: Some(crate::model::params::Albedo::Grey(0.5)),
        ks: Some(crate::model::params::Albedo::Grey(case.ks)),
        exponent: Some(case.exponent),
        spacing: Some(case.spacing),
        height: Some(case.height),
        fibre_azimuth_deg: Some(case.azimuth_deg),
        ..Default::default()
    };
    if let Some(m) = map {
        raw.topology_map = Some(m.to_path_buf());
        raw.map_scale = Some(case.map_scale);
    }
    Ok(ModelParams::from_raw(&raw, ModelId::VaryingTopology)?.0)
}

/// Goniometric samples of `case` (seeded random directions up to 80 deg, 1 % noise, sigmas).
pub fn case_samples(case: &Case, map: Option<&Path>, n: usize, seed: u64) -> Result<Samples> {
    let p = truth_params(case, map)?;
    let m = model::build(ModelId::VaryingTopology, &p)?;
    let frame = FibreFrame::from_azimuth(p.fibre_azimuth);
    let mut rng = rand::rngs::StdRng::seed_from_u64(0xd1ec_0000 + seed);
    let cos_max = 80f64.to_radians().cos();
    let dir = |rng: &mut rand::rngs::StdRng| {
        let z: f64 = cos_max + (1.0 - cos_max) * rng.random::<f64>();
        direction_from_angles(z.acos(), rng.random::<f64>() * std::f64::consts::TAU)
    };
    let samples = (0..n)
        .map(|k| {
            let (l, v) = (dir(&mut rng), dir(&mut rng));
            let f = m
                .basis(&DirectionPair::new(&frame, &l, &v))
                .brdf(&p.albedos, 0);
            let z: f64 = StandardNormal.sample(&mut rng);
            let noisy = f * (1.0 + 0.01 * z);
            let sigma = (0.01 * f).max(1e-9);
            Sample {
                l,
                v,
                fibre_azimuth: None,
                map_value: None,
                texel_height: None,
                value: [noisy; 3],
                sigma: Some([sigma; 3]),
                weight: 1.0,
                origin: Origin::Line(k as u64 + 2),
            }
        })
        .collect();
    Ok(Samples {
        samples,
        channels: 1,
        kind: DataKind::Gonio,
        source: format!("robustness/{}", case.name).into(),
        dropped: Dropped::default(),
        skipped_examples: vec![],
        image_size: None,
        scale_rel_se: None,
    })
}

/// The default fit configuration of the study: spacing (over MODEL.md's whole range [2, 20]),
/// height, exponent, azimuth (and the map scale with a map) free, from a random start inside the
/// bounds.
pub fn case_config(case: &Case, map: Option<&Path>, start_seed: u64) -> Result<FitConfig> {
    let mut rng = rand::rngs::StdRng::seed_from_u64(0x57a7 + start_seed);
    let mut u = || rng.random::<f64>();
    let d0 = 1.0 / (0.05 + 0.45 * u());
    let h0 = u() * crate::model::topology::max_height(d0);
    let e0 = (4000f64.ln() * u()).exp();
    let psi0 = -90.0 + 180.0 * u();
    let s0 = 0.8 * u();
    let mut text = format!(
        "model = \"varying-topology\"\nseed = {start_seed}\n[parameters]\n\
         kd = {{ value = 0.3 }}\n\
         spacing = {{ value = {d0}, min = 2, max = 20 }}\n\
         height = {{ value = {h0} }}\n\
         fibre_azimuth_deg = {{ value = {psi0}, min = -90, max = 90 }}\n"
    );
    if case.ks > 0.0 {
        text += &format!(
            "ks = {{ value = 0.5 }}\nexponent = {{ value = {e0}, min = 1, max = 4000 }}\n"
        );
    } else {
        text += "[components]\nspecular = false\n";
    }
    if let Some(m) = map {
        text = text.replacen(
            "[parameters]",
            &format!(
                "[knobs]\ntopology_map = \"{}\"\n[parameters]\nmap_scale = {{ value = {s0}, min = 0, max = 0.8 }}",
                m.display()
            ),
            1,
        );
    }
    let cfg: FitConfig = toml::from_str(&text).context("robustness config")?;
    cfg.validate()?;
    Ok(cfg)
}

/// chi-square of the truth under the fit's own problem (same knobs, same samples).
fn truth_chi2(case: &Case, map: Option<&Path>, data: &Samples, cfg: &FitConfig) -> Result<f64> {
    let mut set = ParamSet::from_config(cfg, 1)?;
    for s in set.shapes.iter_mut() {
        s.value = match s.kind {
            Param::Spacing => case.spacing,
            Param::Height => case.height,
            Param::Exponent => case.exponent.max(s.min),
            Param::Azimuth => case.azimuth_deg,
            Param::MapScale => case.map_scale,
            _ => s.value,
        };
        s.vary = false;
    }
    for a in set.albedos.iter_mut() {
        a.value = match a.name {
            "kd" => [0.5; 3],
            "ks" => [case.ks; 3],
            _ => a.value,
        };
        a.vary = false;
    }
    let map = match map {
        Some(m) => Some(std::sync::Arc::new(
            crate::model::topology::TopologyMap::load(m)?,
        )),
        None => None,
    };
    let p = FitProblem::new(
        data.samples.iter().collect(),
        set.clone(),
        crate::fit::problem::Settings {
            separable: false,
            ..crate::fit::problem::Settings::of(&cfg)
        },
        map,
    );
    let cols = p.columns(&set)?;
    Ok(p.residuals(&cols, &set).norm_squared())
}

/// Write the study's topology map (32 x 32, seed 11) into `dir`; its path.
pub fn write_map(dir: &Path) -> Result<std::path::PathBuf> {
    let path = dir.join("robustness_map.png");
    let spec = crate::synth::MapSpec {
        width: 32,
        height: 32,
        seed: 11,
        waves: 6,
    };
    crate::export::images::write_gray16(&path, 32, 32, &crate::synth::generate_map(&spec))?;
    Ok(path)
}

/// Run the study: every case x `size.seeds` noise seeds (each with its own random start).
/// `scratch` holds the generated topology map.
pub fn run(cases: &[Case], size: StudySize, scratch: &Path, bar: &ProgressBar) -> Result<Vec<Run>> {
    let map_path = write_map(scratch)?;
    let mut runs = Vec::new();
    for case in cases {
        let map = (case.map_scale > 0.0).then_some(map_path.as_path());
        for seed in 0..size.seeds {
            bar.set_message(format!("robustness: {} seed {seed}", case.name));
            let data = case_samples(case, map, size.samples, seed)?;
            let cfg = case_config(case, map, seed)?;
            let t = Instant::now();
            let o = fit(&data, &cfg, &crate::progress::Progress::quiet())?;
            let seconds = t.elapsed().as_secs_f64();
            let chi2_truth = truth_chi2(case, map, &data, &cfg)?;
            let s = &o.statistics;
            let dof = (s.n - s.free_parameters) as f64;
            let excess = (s.chi_square - chi2_truth) / (2.0 * dof).sqrt();
            runs.push(Run {
                case: case.name.into(),
                seed,
                samples: data.samples.len(),
                chi2_truth,
                chi2_fit: s.chi_square,
                excess_in_sd: excess,
                success: excess <= 1.0,
                seconds,
                evaluations: o.evaluations,
                warnings: o.warnings.len(),
                fitted: o
                    .records
                    .iter()
                    .filter(|r| !r.fixed)
                    .map(|r| format!("{} {:.4}", r.name, r.value[0]))
                    .collect::<Vec<_>>()
                    .join("; "),
            });
            bar.inc(1);
        }
    }
    Ok(runs)
}

/// Per case: runs, successes, median seconds; and the total.
pub fn summary(runs: &[Run]) -> Vec<(String, usize, usize, f64, f64)> {
    let mut names: Vec<String> = Vec::new();
    for r in runs {
        if !names.contains(&r.case) {
            names.push(r.case.clone());
        }
    }
    names.push("all".into());
    names
        .into_iter()
        .map(|n| {
            let rs: Vec<&Run> = runs.iter().filter(|r| n == "all" || r.case == n).collect();
            let ok = rs.iter().filter(|r| r.success).count();
            let mut t: Vec<f64> = rs.iter().map(|r| r.seconds).collect();
            t.sort_by(f64::total_cmp);
            let med = t.get(t.len() / 2).copied().unwrap_or(f64::NAN);
            let worst = rs
                .iter()
                .map(|r| r.excess_in_sd)
                .fold(f64::NEG_INFINITY, f64::max);
            (n, rs.len(), ok, med, worst)
        })
        .collect()
}
