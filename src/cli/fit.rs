//! `fibrefit fit`: fit a rung to measurements and export what a renderer needs.

use super::data::LoadArgs;
use crate::export::atomic::Outputs;
use crate::export::maps_out::MapFiles;
use crate::export::report::ReportFiles;
use crate::export::{report, result_json as rj};
use crate::fit::config::FitConfig;
use crate::fit::problem::{albedos_of, model_for};
use crate::fit::{self, parameters::Shape, ward_fallback};
use crate::load::capture_store::CaptureStore;
use crate::load::load_data;
use crate::load::samples::DataKind;
use crate::model::{brdf_at_degrees, ModelId};
use anyhow::{Context, Result};
use clap::Args;
use std::path::PathBuf;

#[derive(Debug, Args)]
#[command(after_help = "\
DATA is a goniometric CSV, an image capture TOML or an RGL measured BRDF (.bsdf, sampled at
--directions pairs; see `fibrefit inspect --help`).
The config (TOML) names the rung (`model`), each parameter's `value`, `min`, `max`, `vary`,
the residual `metric` (linear: additive noise, under a decade of range; log: ln(f + eps),
eps = 1 % of the median, for measured BRDFs spanning decades; cosine: errors in shaded
intensity), [knobs] (quadrature_order, histogram_bins,
stride, fraction, topology_map), [optimizer] (max_iterations, tolerance, global_candidates
[default 32 + 24 per free shape parameter], global_subsample [600], separable), `starts` [6]
and `seed`. Examples: configs/fit_*.toml.
The search covers the shape space (a space-filling design, the distinct best candidates
polished, every competitive basin polished on all samples), so the fit is the global minimum;
when it does not fit within the noise, when other minima are as good, or when residuals are
systematic, a FIT QUALITY banner says so on stderr (even with --quiet). Check a fit on other
data with `fibrefit score`.
The result JSON (schema fibrefit-result/1) is written atomically: a failed fit writes nothing.")]
pub struct FitArgs {
    /// Goniometric CSV, capture TOML or measured BRDF (.bsdf)
    pub data: PathBuf,
    /// Fit configuration (TOML) [default: every setting at its default; then --model is needed]
    #[arg(long, value_name = "FILE")]
    pub config: Option<PathBuf>,
    /// Rung id, or `auto`: choose the cheapest rung that the held-out data do not reject
    /// [default: the config's `model`]
    #[arg(long, value_name = "ID|auto")]
    pub model: Option<String>,
    /// Residual metric: linear, log or cosine [default: the config's; without a config, log for
    /// measured-BRDF files (.bsdf, .binary) and linear otherwise]
    #[arg(long, value_name = "METRIC")]
    pub metric: Option<String>,
    /// Add the fuzz layer (stray fibres scattering light forward at grazing angles; its weight
    /// `fuzz`, depth `fuzz_depth` and asymmetry `fuzz_asymmetry` free) to the rung, or to every
    /// rung `auto` tries. Real felt and brushed cloth need it (reports/felt.md)
    #[arg(long)]
    pub fuzz: bool,
    /// Result JSON for renderers (and `fibrefit eval --params`) [not with --tile]
    #[arg(long, value_name = "FILE", required_unless_present = "tile")]
    pub out: Option<PathBuf>,
    /// With [maps] in the config: only the first stage of map recovery, the global parameters
    /// (from `[maps] global_texels` texels), written to --out for `--tile` runs
    #[arg(long, conflicts_with_all = ["maps", "tile"])]
    pub map_globals: bool,
    /// Fit the per-texel maps of the rows of tile I of N (I from 0) given --globals, writing
    /// DIR/tile_I_of_N.json for `fibrefit merge-maps` (use with --maps DIR)
    #[arg(long, value_name = "I/N", requires_all = ["globals", "maps"])]
    pub tile: Option<String>,
    /// The result of `fit --map-globals` that the tiles share
    #[arg(long, value_name = "FILE", requires = "tile")]
    pub globals: Option<PathBuf>,
    /// Image captures: also recover the per-texel maps the config's [maps] section asks for
    /// (height, fibre_azimuth, kd, ks) and write them as EXRs into DIR
    #[arg(long, value_name = "DIR")]
    pub maps: Option<PathBuf>,
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

pub fn run(args: &FitArgs) -> Result<()> {
    let mut cfg = match (&args.config, &args.model) {
        (Some(path), _) => FitConfig::load(path)?,
        (None, Some(m)) => {
            let mut c: FitConfig = toml::from_str(&format!("model = {m:?}\n"))?;
            let measured = args.data.extension().is_some_and(|e| {
                e.eq_ignore_ascii_case("bsdf") || e.eq_ignore_ascii_case("binary")
            });
            if measured {
                c.metric = crate::fit::config::Metric::Log;
            }
            c
        }
        (None, None) => {
            anyhow::bail!("give --config FILE, or --model ID|auto to fit with the defaults")
        }
    };
    if let Some(m) = &args.model {
        cfg.model = m.clone();
    }
    if let Some(m) = &args.metric {
        cfg.metric = serde_json::from_value(serde_json::Value::String(m.clone()))
            .map_err(|_| anyhow::anyhow!("--metric {m}: expected linear, log or cosine"))?;
    }
    if args.fuzz {
        cfg.parameters.entry("fuzz_depth".into()).or_default();
    }
    cfg.validate()
        .map_err(|e| anyhow::anyhow!("--model: {e}"))?;
    // Check every output first: a bad path fails before the work, and no output replaces an input.
    let mut inputs = crate::load::input_files(&args.data);
    inputs.extend(args.config.iter().cloned());
    inputs.extend(cfg.knobs.topology_map.iter().cloned());
    if let Some(tile) = &args.tile {
        return super::map_tiles::run_tile(args, cfg, tile, &inputs);
    }
    let out_path = args.out.clone().expect("clap: --out unless --tile");
    if args.map_globals {
        crate::fit::maps::check_request(&cfg, &cfg.maps)?;
    }
    if args.maps.is_some() {
        if cfg.model == "auto" {
            anyhow::bail!("--maps: name a rung (`model` or --model), not auto");
        }
        crate::fit::maps::check_request(&cfg, &cfg.maps)?;
    }
    // every output reserved before the work (none an input or another output), written together
    let mut outs = Outputs::new(&inputs);
    let json_out = outs.file(&out_path, "--out")?;
    let map_files = match &args.maps {
        Some(dir) => Some(MapFiles::reserve(&mut outs, dir, &cfg.maps.requested())?),
        None => None,
    };
    let mut report_files = match &args.report {
        Some(dir) => Some(ReportFiles::reserve(&mut outs, dir)?),
        None => None,
    };
    let opts = args
        .load
        .options_with(cfg.knobs.stride, cfg.knobs.fraction)?;
    // captures are held compactly by texel; the global fit takes a seeded sample of texels
    let store = match crate::load::is_capture(&args.data) {
        true => Some(CaptureStore::load(&args.data, opts.subsample)?),
        false => None,
    };
    let fit_texels = store.as_ref().map(|st| fit_texel_sample(st, &cfg));
    let samples = match (&store, &fit_texels) {
        (Some(st), Some(ids)) => st.samples_of(ids),
        _ => load_data(&args.data, &opts)?,
    };
    if let Some(files) = &mut report_files {
        // a residual map per capture image
        let images: std::collections::BTreeSet<u32> = samples
            .samples
            .iter()
            .filter_map(|s| match s.origin {
                crate::load::samples::Origin::Pixel { image, .. } => Some(image),
                _ => None,
            })
            .collect();
        files.add_images(&mut outs, images)?;
    }
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
    let hints = selection
        .as_ref()
        .map(|s| s.hints.clone())
        .unwrap_or_default();
    let (mut outcome, stage_costs) = match args.maps.is_some() || args.map_globals {
        true => {
            let store = store.as_ref().ok_or_else(|| {
                anyhow::anyhow!("--maps needs an image capture (a capture TOML): per-texel maps come from pixels")
            })?;
            let st = fit::maps::global_stage(store, &cfg, &cfg.maps, args.quiet || args.json)
                .with_context(|| {
                    format!("recovering maps with {} from {}", id, args.data.display())
                })?;
            let mut global = st.outcome;
            global.warnings.extend(st.warnings.iter().cloned());
            (global, Some((st.costs, st.texel_variance)))
        }
        false => (
            fit::fit_with_hints(&samples, &cfg, args.quiet || args.json, &hints)
                .with_context(|| format!("fitting {} to {}", id, args.data.display()))?,
            None,
        ),
    };
    let channels = samples.channels;
    // a fit on a sample of a capture's texels, checked on every pixel
    let mut all_pixels = None;
    if let (Some(st), Some(ids), None) = (&store, &fit_texels, &stage_costs) {
        let fitted_texels = ids.len();
        if fitted_texels < st.texels().len() {
            let all = fit::all_pixels::statistics(st, &cfg, &outcome, args.quiet || args.json)?;
            if let Some(w) =
                fit::all_pixels::warning(&all, outcome.statistics.reduced_chi_square, fitted_texels)
            {
                outcome.warnings.push(w);
            }
            all_pixels = Some(all);
        }
    }
    let m = model_for(
        &outcome.set,
        cfg.knobs.quadrature_order,
        cfg.knobs.histogram_bins,
        cfg.knobs.azimuth_nodes,
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
            brdf: brdf_at_degrees(m.as_ref(), &albedos, psi, d, channels),
        })
        .collect();
    // an optional stage: its failure is a warning, never the loss of the fit
    let mut warnings = outcome.warnings.clone();
    let ward = if id == ModelId::Ward {
        None
    } else {
        match ward_fallback::fit(m.as_ref(), &albedos, psi.to_degrees(), cfg.seed, channels) {
            Ok(w) => Some(rj::WardFallback {
                model: "ward".into(),
                parameters: w
                    .parameters
                    .into_iter()
                    .map(|(k, v)| (k, rj::number_or_rgb(&v)))
                    .collect(),
                rms_error: w.rms_error,
                relative_rms_error: w.relative_rms_error,
                directions: w.directions,
            }),
            Err(e) => {
                warnings.push(format!(
                    "the Ward fallback could not be fitted, so the result has none: {e:#}"
                ));
                None
            }
        }
    };
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
        statistics: {
            let mut v = serde_json::to_value(&outcome.statistics)?;
            if let Some(all) = &all_pixels {
                v["all_pixels"] = serde_json::to_value(all)?;
            }
            v
        },
        knobs,
        data: rj::Provenance {
            file: args
                .data
                .file_name()
                .map(|f| f.to_string_lossy().into_owned())
                .unwrap_or_default(),
            // of the bytes the loader read, not of the file as it is now
            sha256: crate::load::sha256_read(&args.data).with_context(|| {
                format!("{}: its loader recorded no hash", args.data.display())
            })?,
            kind: match samples.kind {
                DataKind::Gonio => "goniometric".into(),
                DataKind::Capture => "image capture".into(),
                DataKind::Measured => "measured BRDF file".into(),
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
        quality: Some(serde_json::to_value(&outcome.quality)?),
        maps: None,
        warnings: warnings.clone(),
    };
    let mut report_text = report::text(&outcome, id.as_str(), &args.data.display().to_string());
    if let Some(s) = &selection {
        report_text += &format!("[[Model selection]]\n{}", crate::fit::selection::table(s));
    }
    let mut result = result;
    if let Some((costs, texel_variance)) = &stage_costs {
        let method = super::map_tiles::method(&cfg, costs, *texel_variance);
        if args.map_globals {
            result.maps = Some(serde_json::json!({
                "stage": "globals",
                "requested": cfg.maps.requested(),
                "method": method,
            }));
        } else if let Some(dir) = &args.maps {
            // the texel stage takes the globals as the result states them, as tiles do
            let globals = crate::fit::score::result_from_value(
                &serde_json::to_value(&result)?,
                "the global fit",
                channels,
            )?
            .set;
            let store = store.as_ref().expect("the global stage needed the capture");
            let (w, h) = (store.width, store.height);
            let part = fit::maps::texel_stage(
                store,
                &cfg,
                &cfg.maps,
                &globals,
                (0, h as u32),
                *texel_variance,
                args.quiet || args.json,
            )?;
            let (maps, variance, warns) = fit::maps::finish_maps(
                vec![part],
                w,
                h,
                channels,
                &cfg.maps,
                outcome.statistics.free_parameters,
                crate::model::topology::max_height(globals.shape_value(Shape::Spacing)),
            )?;
            let files = map_files.as_ref().expect("reserved with --maps");
            let _ = dir;
            let mut desc =
                crate::export::maps_out::write(&mut outs, files, &cfg.maps.requested(), &maps)?;
            desc["method"] = method;
            desc["method"]["residual_variance"] = serde_json::json!(variance);
            result.maps = Some(desc);
            result.warnings.extend(warns);
            outcome.fitted = fit::maps::fitted_all(&samples, &cfg, &cfg.maps, &globals, &maps)?;
        }
    }
    if let (Some(dir), Some(files)) = (&args.report, &report_files) {
        // the report is optional: its failure is a warning in the result, never the lost fit
        let fitted = fit::fitted_brdf(&outcome, &cfg);
        let measured = crate::load::measured_brdf(&args.data).unwrap_or(None);
        if let Err(e) = report::write_dir(
            &mut outs,
            files,
            &outcome,
            &samples,
            &report_text,
            fitted.as_ref(),
            measured.as_deref(),
        ) {
            let w = format!("{}: the report could not be written: {e:#}", dir.display());
            eprintln!("warning: {w}");
            result.warnings.push(w);
            files.discard(&mut outs);
        }
    }
    serde_json::to_writer_pretty(outs.writer(json_out), &result)
        .with_context(|| format!("--out {}: cannot write the result", out_path.display()))?;
    outs.commit()?;
    // stdout's failure (a closed pipe, a full disk) is reported after the banner, never instead
    let mut printed = Ok(());
    if args.json {
        let s = &outcome.statistics;
        printed = super::print_out(&format!(
            "{}\n",
            serde_json::json!({
                "model": id.as_str(), "out": out_path.display().to_string(), "samples": samples.samples.len(),
                "rmse": s.rmse, "relative_rmse": s.relative_rmse, "reduced_chi_square": s.reduced_chi_square,
                "iterations": outcome.iterations, "evaluations": outcome.evaluations,
                "seconds": outcome.elapsed_seconds, "warnings": outcome.warnings.len()
            })
        ));
    } else if !args.quiet {
        printed = super::print_out(&report_text);
        eprintln!("wrote {}", out_path.display());
    }
    if !args.quiet {
        for w in warnings
            .iter()
            .filter(|w| !outcome.quality.warnings.contains(w))
        {
            eprintln!("warning: {w}");
        }
    }
    // what the quality checks found is printed even with --quiet: it must not be missed
    quality_banner(&outcome.quality);
    printed.with_context(|| format!("the outputs were written ({})", out_path.display()))
}

/// The texels of a capture the global fit uses: every one, or a seeded sample of
/// `[knobs] fit_texels` of them.
fn fit_texel_sample(store: &CaptureStore, cfg: &FitConfig) -> Vec<usize> {
    let n = match cfg.knobs.fit_texels {
        0 => usize::MAX,
        k => k,
    };
    store.sample_texels(n, cfg.seed ^ 0x6669_7474)
}

/// The quality warnings as a banner on stderr (bold red on a terminal).
pub fn quality_banner(q: &fit::quality::Quality) {
    use std::io::IsTerminal;
    if q.warnings.is_empty() {
        return;
    }
    let (on, off) = if std::io::stderr().is_terminal() {
        ("\x1b[1;31m", "\x1b[0m")
    } else {
        ("", "")
    };
    let rule = "=".repeat(78);
    eprintln!("{on}{rule}");
    eprintln!("FIT QUALITY: {}", q.verdict.to_uppercase());
    for w in &q.warnings {
        eprintln!("WARNING: {w}");
    }
    eprintln!("{rule}{off}");
}
