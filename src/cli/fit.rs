//! `fibrefit fit`: fit a rung to measurements and export what a renderer needs.

use super::data::LoadArgs;
use crate::export::atomic::AtomicFile;
use crate::export::{report, result_json as rj};
use crate::fit::config::FitConfig;
use crate::fit::problem::{albedos_of, model_for};
use crate::fit::{self, parameters::Shape};
use crate::load::load_data;
use crate::load::samples::{DataKind, Dropped, Origin, Sample, Samples};
use crate::model::frame::direction_from_angles;
use crate::model::{Albedos, ModelId, ShadingModel};
use anyhow::{Context, Result};
use clap::Args;
use rand::{Rng, SeedableRng};
use sha2::{Digest, Sha256};
use std::path::{Path, PathBuf};

#[derive(Debug, Args)]
#[command(after_help = "\
DATA is a goniometric CSV or an image capture TOML (see `fibrefit inspect --help`).
The config (TOML) names the rung (`model`), each parameter's `value`, `min`, `max`, `vary`,
the residual `metric` (linear | log | cosine), [knobs] (quadrature_order, histogram_bins,
stride, fraction, topology_map), [optimizer] (max_iterations, tolerance, global_candidates,
global_subsample, separable), `starts` and `seed`. Examples: configs/fit_*.toml.
The result JSON (schema fibrefit-result/1) is written atomically: a failed fit writes nothing.")]
pub struct FitArgs {
    /// Goniometric CSV or capture TOML
    pub data: PathBuf,
    /// Fit configuration (TOML)
    #[arg(long, value_name = "FILE")]
    pub config: PathBuf,
    /// Rung id, or `auto`: choose the cheapest rung that the held-out data do not reject
    /// [default: the config's `model`]
    #[arg(long, value_name = "ID|auto")]
    pub model: Option<String>,
    /// Result JSON for renderers (and `fibrefit eval --params`)
    #[arg(long, value_name = "FILE")]
    pub out: PathBuf,
    /// Also write a report (report.md with the fit report) into DIR
    #[arg(long, value_name = "DIR")]
    pub report: Option<PathBuf>,
    /// No progress bar and no report on stdout
    #[arg(long, short)]
    pub quiet: bool,
    /// Print a one-line machine-readable summary (JSON) on stdout
    #[arg(long)]
    pub json: bool,
    #[command(flatten)]
    pub load: LoadArgs,
}

fn sha256_of(path: &Path) -> Result<String> {
    let bytes = std::fs::read(path).with_context(|| format!("{}: cannot read", path.display()))?;
    Ok(Sha256::digest(&bytes)
        .iter()
        .map(|b| format!("{b:02x}"))
        .collect())
}

/// The Ward lobe fitted to the fitted model `m` (with its albedos and fibre azimuth `psi`,
/// degrees) over a dense direction set.
fn ward_fallback(
    m: &dyn ShadingModel,
    albedos: &Albedos,
    psi: f64,
    cfg: &FitConfig,
    channels: usize,
) -> Result<Option<rj::WardFallback>> {
    if cfg.model_id()? == ModelId::Ward {
        return Ok(None);
    }
    let mut rng = rand::rngs::StdRng::seed_from_u64(cfg.seed ^ 0x5741_5244);
    let cos_max = 80f64.to_radians().cos();
    let mut dir = || {
        let z: f64 = cos_max + (1.0 - cos_max) * rng.random::<f64>();
        (z.acos().to_degrees(), rng.random::<f64>() * 360.0)
    };
    let count = 1500;
    let samples: Vec<Sample> = (0..count)
        .map(|k| {
            let (ti, pi) = dir();
            let (to, po) = dir();
            let f = rj::brdf_at(m, albedos, psi.to_radians(), [ti, pi, to, po], channels);
            let mut value = [f[0]; 3];
            value[..channels].copy_from_slice(&f);
            Sample {
                l: direction_from_angles(ti.to_radians(), pi.to_radians()),
                v: direction_from_angles(to.to_radians(), po.to_radians()),
                fibre_azimuth: None,
                map_value: None,
                value,
                sigma: None,
                weight: 1.0,
                origin: Origin::Line(k as u64 + 2),
            }
        })
        .collect();
    let data = Samples {
        samples,
        channels,
        kind: DataKind::Gonio,
        source: "fitted model".into(),
        dropped: Dropped::default(),
        skipped_examples: vec![],
    };
    let text = format!(
        "model = \"ward\"\nstarts = 3\nseed = {}\n[parameters]\nfibre_azimuth_deg = {{ value = {psi}, vary = false }}\nalpha_x = {{ value = 0.2 }}\nalpha_y = {{ value = 0.2 }}\n",
        cfg.seed
    );
    let ward_cfg: FitConfig = toml::from_str(&text)?;
    let w = fit::fit(&data, &ward_cfg, true)?;
    let mut parameters = std::collections::BTreeMap::new();
    for (k, v) in rj::params_out(&w) {
        parameters.insert(k, v.value);
    }
    Ok(Some(rj::WardFallback {
        model: "ward".into(),
        parameters,
        rms_error: w.statistics.rmse,
        relative_rms_error: w.statistics.relative_rmse,
        directions: count,
    }))
}

pub fn run(args: &FitArgs) -> Result<()> {
    let mut cfg = FitConfig::load(&args.config)?;
    if let Some(m) = &args.model {
        cfg.model = m.clone();
        cfg.validate()
            .map_err(|e| anyhow::anyhow!("--model: {e}"))?;
    }
    // Create the output first: a bad path fails before the work.
    let mut out = AtomicFile::create(&args.out)?;
    let opts = args
        .load
        .options_with(cfg.knobs.stride, cfg.knobs.fraction)?;
    let samples = load_data(&args.data, &opts)?;
    let selection = if cfg.model == "auto" {
        let s = crate::fit::selection::select(&samples, &cfg)?;
        cfg = cfg.for_rung(s.chosen.parse().map_err(|e: String| anyhow::anyhow!(e))?);
        if !args.quiet && !args.json {
            eprintln!("{}", crate::fit::selection::table(&s));
        }
        Some(s)
    } else {
        None
    };
    let id = cfg.model_id()?;
    let outcome = fit::fit(&samples, &cfg, args.quiet || args.json)
        .with_context(|| format!("fitting {} to {}", id, args.data.display()))?;
    let channels = samples.channels;
    let m = model_for(
        &outcome.set,
        cfg.knobs.quadrature_order,
        cfg.knobs.histogram_bins,
        outcome.map.clone(),
    );
    let albedos = albedos_of(&outcome.set);
    let psi = outcome.set.shape_value(Shape::Azimuth).to_radians();
    let check_values = rj::check_directions()
        .into_iter()
        .map(|d| rj::CheckValue {
            theta_i: d[0],
            phi_i: d[1],
            theta_o: d[2],
            phi_o: d[3],
            brdf: rj::brdf_at(m.as_ref(), &albedos, psi, d, channels),
        })
        .collect();
    let ward = ward_fallback(m.as_ref(), &albedos, psi.to_degrees(), &cfg, channels)
        .context("fitting the Ward fallback")?;
    let mut knobs = rj::knobs(&cfg, opts.subsample.stride, opts.subsample.fraction);
    if let Some(mp) = &outcome.map {
        knobs.topology_map = Some(
            std::fs::canonicalize(&mp.source)
                .unwrap_or(mp.source.clone())
                .display()
                .to_string(),
        );
    }
    let result = rj::ResultFile {
        schema: rj::SCHEMA.into(),
        tool: format!("fibrefit {}", env!("CARGO_PKG_VERSION")),
        model: id.to_string(),
        conventions: rj::Conventions::default(),
        parameters: rj::params_out(&outcome),
        correlations: outcome
            .correlations
            .iter()
            .map(|(a, b, r)| rj::Correlation {
                a: a.clone(),
                b: b.clone(),
                r: *r,
            })
            .collect(),
        statistics: serde_json::to_value(&outcome.statistics)?,
        knobs,
        data: rj::Provenance {
            file: args
                .data
                .file_name()
                .map(|f| f.to_string_lossy().into_owned())
                .unwrap_or_default(),
            sha256: sha256_of(&args.data)?,
            kind: match samples.kind {
                DataKind::Gonio => "goniometric".into(),
                DataKind::Capture => "image capture".into(),
            },
            samples: samples.samples.len(),
            channels,
        },
        check_values,
        ward_fallback: ward,
        model_selection: selection
            .as_ref()
            .map(|s| {
                s.candidates
                    .iter()
                    .map(|c| serde_json::to_value(c).unwrap_or_default())
                    .collect()
            })
            .unwrap_or_default(),
        warnings: outcome.warnings.clone(),
    };
    let mut report_text = report::text(&outcome, id.as_str(), &args.data.display().to_string());
    if let Some(s) = &selection {
        report_text += &format!("[[Model selection]]\n{}", crate::fit::selection::table(s));
    }
    if let Some(dir) = &args.report {
        report::write_dir(
            dir,
            &outcome,
            &samples,
            &report_text,
            outcome.set.shape_value(Shape::Azimuth),
        )
        .with_context(|| format!("{}: writing the report", dir.display()))?;
    }
    serde_json::to_writer_pretty(out.writer(), &result)?;
    out.commit()?;
    if args.json {
        let s = &outcome.statistics;
        println!(
            "{}",
            serde_json::json!({
                "model": id.as_str(), "out": args.out.display().to_string(), "samples": samples.samples.len(),
                "rmse": s.rmse, "relative_rmse": s.relative_rmse, "reduced_chi_square": s.reduced_chi_square,
                "iterations": outcome.iterations, "evaluations": outcome.evaluations,
                "seconds": outcome.elapsed_seconds, "warnings": outcome.warnings.len()
            })
        );
    } else if !args.quiet {
        print!("{report_text}");
        eprintln!("wrote {}", args.out.display());
    }
    for w in &outcome.warnings {
        if !args.quiet {
            eprintln!("warning: {w}");
        }
    }
    Ok(())
}
