//! `fibrefit bench shader`: what the exported shader costs. For each rung (representative
//! parameters), evaluations per second of `fibrefit_brdf` on this machine's GPU driver (one
//! dispatch over many pairs, median of repeats) against the Rust model on the CPU (`basis_many`,
//! one thread and all threads), the SPIR-V instruction count of the exported library (naga) and
//! its loop sizes, and the agreement with the Rust model on the same run.

use crate::export::shader::{self, check, gpu::Gpu};
use crate::model::frame::DirectionPair;
use crate::model::params::{ModelParams, RawParams};
use crate::model::topology::max_height;
use crate::model::{self, Basis, ModelId};
use anyhow::{anyhow, Result};
use indicatif::ProgressBar;
use rayon::prelude::*;
use std::time::Instant;

/// (label, parameters as TOML): every rung, the cross-section ones at a single height (what a
/// renderer feeding per-texel maps pays per evaluation) and with a 16-bin height histogram, the
/// renderers' own materials last.
pub const RUNGS: &[(&str, &str)] = &[
    ("lambert", "model = 'lambert'\nkd = 0.5"),
    ("hast-diffuse", "model = 'hast-diffuse'\nkd = 0.5"),
    ("max-normal", "model = 'max-normal'\nkd = 0.5\nks = 0.3\nexponent = 60"),
    ("ward", "model = 'ward'\nrho_d = 0.3\nrho_s = 0.2\nalpha_x = 0.1\nalpha_y = 0.4"),
    ("poulin-fournier", "model = 'poulin-fournier'\nkd = 0.5\nks = 0.3\nexponent = 60\nspacing = 2.5"),
    ("varying-topology, one height (per texel)", "model = 'varying-topology'\nkd = 0.5\nks = 0.3\nexponent = 60\nspacing = 2\nheight = 0.9"),
    ("varying-topology, 16 height bins", "model = 'varying-topology'\nkd = 0.5\nks = 0.3\nexponent = 60\nspacing = 2\nheight = 0.9\nmap_scale = 0.5"),
    ("varying-topology, 16 bins, spread 16 nodes", "model = 'varying-topology'\nkd = 0.5\nks = 0.3\nexponent = 60\nspacing = 2\nheight = 0.9\nmap_scale = 0.5\nazimuth_spread_deg = 20"),
    ("gltf", "model = 'gltf'\nkd = 0.4\nroughness = 0.45\nanisotropy_strength = 0.6\nsheen = 0.3\nsheen_roughness = 0.5"),
    ("principled", "model = 'principled'\nkd = 0.4\nroughness = 0.45\nanisotropic = 0.6\nsheen_weight = 0.5\nsheen_roughness = 0.5"),
    ("openpbr", "model = 'openpbr'\nkd = 0.4\nspecular_roughness = 0.45\nspecular_roughness_anisotropy = 0.6\nfuzz_weight = 0.5\nfuzz_roughness = 0.5"),
];

#[derive(Clone, Debug, serde::Serialize)]
pub struct ShaderCostRow {
    pub rung: String,
    pub model: String,
    /// Gauss–Legendre nodes N, height nodes K, spread nodes M baked in.
    pub quadrature_order: usize,
    pub height_nodes: usize,
    pub spread_nodes: usize,
    pub spirv_instructions: usize,
    /// Beyond the lambert export's (the frame, spread loop, Fresnel, fuzz and entry points every
    /// export has): the rung's own code.
    pub spirv_instructions_of_the_rung: usize,
    pub pairs: usize,
    pub gpu_evals_per_second: f64,
    pub cpu_one_thread_evals_per_second: f64,
    pub cpu_all_threads_evals_per_second: f64,
    /// GPU driver over the CPU with all threads.
    pub ratio_gpu_to_cpu: f64,
    pub p99_relative_error: f64,
    pub max_relative_error: f64,
}

pub struct ShaderCostRun {
    pub adapter: String,
    pub threads: usize,
    pub rows: Vec<ShaderCostRow>,
}

fn params(text: &str) -> Result<(ModelId, ModelParams)> {
    let raw: RawParams = toml::from_str(text).map_err(|e| anyhow!("{e}"))?;
    let id: ModelId = raw
        .model
        .as_deref()
        .unwrap_or_default()
        .parse()
        .map_err(|e: String| anyhow!(e))?;
    let (p, _) = ModelParams::from_raw(&raw, id)?;
    Ok((id, p))
}

fn median(mut x: Vec<f64>) -> f64 {
    x.sort_by(f64::total_cmp);
    x[x.len() / 2]
}

/// Run the study with `pairs_total` pairs per rung divided by its height and spread nodes (at
/// least `min_pairs`; `repeats` timings each).
pub fn run(
    pairs_total: usize,
    min_pairs: usize,
    repeats: usize,
    bar: &ProgressBar,
) -> Result<ShaderCostRun> {
    let gpu = Gpu::new()?;
    let mut rows = Vec::new();
    let shared = {
        let (id, p) = params(RUNGS[0].1)?;
        shader::spirv_instructions(&shader::wgsl(id, &p, &[])?)?
    };
    for (label, text) in RUNGS {
        let (id, p) = params(text)?;
        let src = shader::wgsl(id, &p, &[])?;
        let baked = shader::Baked::new(id, &p)?;
        let n = (pairs_total / (baked.heights.len() * baked.spread.len())).max(min_pairs);
        let cases: Vec<check::Case> = check::cases(n, 17, max_height(p.spacing))
            .into_iter()
            .take(n)
            .map(|c| check::Case { at: None, ..c })
            .collect();
        let gpu_seconds = gpu.time_brdf(&src, &cases, repeats)?;
        let count = shader::spirv_instructions(&src)?;
        let m = model::build(id, &p)?;
        let pr: Vec<DirectionPair> = cases.iter().map(check::local_pair).collect();
        let mut out = vec![Basis::default(); pr.len()];
        let mut one = Vec::new();
        let mut all = Vec::new();
        for _ in 0..repeats {
            let t = Instant::now();
            m.basis_many(&pr, &mut out);
            one.push(t.elapsed().as_secs_f64());
            let t = Instant::now();
            out.par_chunks_mut(256)
                .zip(pr.par_chunks(256))
                .for_each(|(o, p)| m.basis_many(p, o));
            all.push(t.elapsed().as_secs_f64());
        }
        let (a, _) = check::on_gpu(&gpu, &src, id, &p, &cases)?;
        let (gpu_rate, one_rate, all_rate) = (
            n as f64 / gpu_seconds,
            n as f64 / median(one),
            n as f64 / median(all),
        );
        rows.push(ShaderCostRow {
            rung: label.to_string(),
            model: id.as_str().to_string(),
            quadrature_order: baked.quadrature_order,
            height_nodes: baked.heights.len(),
            spread_nodes: baked.spread.len(),
            spirv_instructions: count,
            spirv_instructions_of_the_rung: count.saturating_sub(shared),
            pairs: n,
            gpu_evals_per_second: gpu_rate,
            cpu_one_thread_evals_per_second: one_rate,
            cpu_all_threads_evals_per_second: all_rate,
            ratio_gpu_to_cpu: gpu_rate / all_rate,
            p99_relative_error: a.p99_relative,
            max_relative_error: a.max_relative,
        });
        bar.inc(1);
    }
    Ok(ShaderCostRun {
        adapter: gpu.adapter.clone(),
        threads: rayon::current_num_threads(),
        rows,
    })
}
