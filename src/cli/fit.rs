//! `fibrefit fit`: parse the command line, reserve the outputs, run [`crate::api::fit`], print.

use super::data::LoadArgs;
use crate::api::batch::{Batch, Done};
use crate::api::fit::{self as fit_api, FitOptions, FitTargets, Maps};
use crate::api::tiles::{self, TileRequest};
use crate::export::atomic::Outputs;
use crate::fit;
use anyhow::{anyhow, Context, Result};
use clap::Args;
use std::path::PathBuf;

#[derive(Debug, Args)]
#[command(after_help = "\
DATA is a goniometric table (.csv, .tsv, .txt or .dat, the delimiter sniffed from the header;
angles in degrees, or radians with --angles rad), an image capture TOML or an RGL measured BRDF
(.bsdf, sampled at --directions pairs; see `fibrefit inspect --help`).
The config (TOML) names the rung (`model`), each parameter's `value`, `min`, `max`, `vary`,
the residual `metric` (linear: additive noise, under a decade of range; log: ln(f + eps),
eps = 1 % of the median, for measured BRDFs spanning decades; cosine: errors in shaded
intensity), [knobs] (quadrature_order, histogram_bins,
stride, fraction, topology_map, gltf_variant), [optimizer] (max_iterations, tolerance, global_candidates
[default 32 + 24 per free shape parameter], global_subsample [600], separable), `starts` [6]
and `seed`, and how the lab's tables are written: [columns] (ours = \"theirs\", as --columns)
and [data] angles = \"rad\" (as --angles; the flags override). Examples: configs/fit_*.toml.
The search covers the shape space (a space-filling design, the distinct best candidates
polished, every competitive basin polished on all samples), so the fit is the global minimum;
when it does not fit within the noise, when other minima are as good, or when residuals are
systematic, a FIT QUALITY banner says so on stderr (even with --quiet). Check a fit on other
data with `fibrefit score`.
Without --out the report is printed and nothing is written. The result JSON (schema
fibrefit-result/1) is written atomically: a failed fit writes nothing. An auto run interrupted
(Ctrl-C, SIGTERM) after a rung finished writes the rungs it finished to --out, marked
`\"partial\": true` (schema fibrefit-partial/1, no fitted model), and a PARTIAL report.md into
--report; it exits 130. Progress (per rung, per stage) goes to stderr on a terminal;
FIBREFIT_PROGRESS=1 shows it elsewhere too, FIBREFIT_PROGRESS=0 hides it.
Many swatches: `fibrefit fit swatches/*.csv --model auto --out-dir fits` fits each into
fits/NAME/ and lists them in fits/summary.csv; runs sharing --out-dir (Slurm job arrays, GNU
parallel) add their rows to the same summary. Recipes: docs/guide/batch.md.")]
pub struct FitArgs {
    /// Goniometric table (.csv, .tsv, .txt, .dat), capture TOML or measured BRDF (.bsdf,
    /// .binary); several (with --out-dir) are fitted one after another with the same settings
    #[arg(required = true, value_name = "DATA")]
    pub data: Vec<PathBuf>,
    /// Fit configuration (TOML) [default: every setting at its default; then --model is needed]
    #[arg(long, value_name = "FILE")]
    pub config: Option<PathBuf>,
    /// Rung id, or `auto`: every rung without and with the fuzz layer, compared by their
    /// held-out error (5-fold cross-validation below 2000 samples, one split above), the
    /// simplest within one standard error of the best chosen [default: the config's `model`].
    /// Without a config a rung fits every shape parameter (as auto's rungs do); over a config
    /// for another rung, the parameters it lacks are ignored
    #[arg(long, value_name = "ID|auto")]
    pub model: Option<String>,
    /// Residual metric: linear, log or cosine [default: the config's; when neither names one,
    /// log for measured-BRDF files (.bsdf, .binary) and for data without sigmas whose values
    /// span more than 10x (99th over 1st percentile), linear otherwise; the report says which]
    #[arg(long, value_name = "METRIC")]
    pub metric: Option<String>,
    /// Add the fuzz layer (stray fibres scattering light forward at grazing angles; its weight
    /// `fuzz`, depth `fuzz_depth` and asymmetry `fuzz_asymmetry` free) to the rung, or to every
    /// rung `auto` tries (auto then tries no rung without it). Real felt and brushed cloth need
    /// it (reports/felt.md)
    #[arg(long, conflicts_with = "no_fuzz")]
    pub fuzz: bool,
    /// `--model auto`: try the rungs without the fuzz layer only (by default each rung is tried
    /// without and with it; as `[selection] fuzz = false`; refused when the config lists a fuzz
    /// parameter)
    #[arg(long)]
    pub no_fuzz: bool,
    /// Never a smooth correction on the rung. By default, where data without sigmas hold
    /// structure the fitted rung misses (its held-out error beyond 1.2x the floor), a smooth
    /// reciprocal factor exp(Legendre series in cos theta_i, cos theta_o, cos dphi) is fitted
    /// on it (not on a renderer's own material without the fuzz layer: that renderer could not
    /// show it), with the instrument's light/view imbalance beside it (what of the data is not
    /// reciprocal: judged with the fit, left out of the material), its degree chosen held out,
    /// and kept only where it pays: `eval`, `render`, `score`, `Material` and the shader export
    /// apply the series; the glTF, Blender and MaterialX/USD materials carry the rung alone and
    /// say so (as `[components] correction = false`)
    #[arg(long)]
    pub no_correction: bool,
    /// Result JSON for renderers (and `fibrefit eval --params`) [default: none: the report is
    /// printed, nothing is written; not with --tile]
    #[arg(long, value_name = "FILE", conflicts_with = "tile")]
    pub out: Option<PathBuf>,
    /// With [maps] in the config: only the first stage of map recovery, the global parameters
    /// (from `[maps] global_texels` texels), written to --out for `--tile` runs
    #[arg(long, conflicts_with_all = ["maps", "tile"], requires = "out")]
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
    /// Also write a report (report.md with the fit report, its plots, and view.html: the
    /// viewer page of `fibrefit view`) into DIR
    #[arg(long, value_name = "DIR")]
    pub report: Option<PathBuf>,
    /// No progress bar and no report on stdout
    #[arg(long, short)]
    pub quiet: bool,
    /// Print a one-line machine-readable summary (JSON) on stdout (with --out-dir: one line
    /// per input, its summary row)
    #[arg(long)]
    pub json: bool,
    /// Fit every DATA into DIR/NAME/ (NAME: the file name without its extension): the result
    /// (result.json) and the report (report.md and figures), and a row per input in
    /// DIR/summary.csv (rung, verdict, held-out error, RMSE, seconds; rows of other runs into
    /// the same DIR are kept, so job arrays can share it). An input that fails is a `failed`
    /// row; the others go on, and the run exits 2 at the end
    #[arg(long, value_name = "DIR", conflicts_with_all = ["out", "report", "maps", "map_globals", "tile", "globals"])]
    pub out_dir: Option<PathBuf>,
    /// With --out-dir: leave out inputs whose DIR/NAME/result.json exists and whose summary row
    /// says ok (a rerun after an interruption, a requeued job)
    #[arg(long, requires = "out_dir")]
    pub skip_done: bool,
    /// Worker threads [default: one per core, or RAYON_NUM_THREADS]; with GNU parallel or job
    /// arrays sharing a machine, jobs x threads = cores
    #[arg(long, value_name = "N")]
    pub threads: Option<usize>,
    /// The gltf rung's variant: khronos (the Khronos specification and Sample Viewer) or
    /// threejs (what stock three.js r187 renders; docs/web.md) [default:
    /// the config's knobs.gltf_variant, else khronos]
    #[arg(long, value_name = "khronos|threejs")]
    pub gltf_variant: Option<String>,
    #[command(flatten)]
    pub load: LoadArgs,
}

pub fn run(args: &FitArgs) -> Result<()> {
    crate::api::with_threads(args.threads, || match &args.out_dir {
        Some(dir) => run_batch(args, dir),
        None if args.data.len() > 1 => Err(anyhow!(
            "{} data files: give --out-dir DIR to fit each into its own folder with a summary (one file at a time otherwise)",
            args.data.len()
        )),
        None => run_one(args),
    })?
}

/// The options every input of the command line is fitted with.
fn options(args: &FitArgs) -> Result<FitOptions> {
    Ok(FitOptions {
        config: args.config.clone(),
        model: args.model.clone(),
        metric: args.metric.clone(),
        fuzz: match (args.fuzz, args.no_fuzz) {
            (true, _) => Some(true),
            (_, true) => Some(false),
            _ => None,
        },
        load: args.load.flags()?,
        maps: match (&args.maps, args.map_globals) {
            (_, true) => Maps::Globals,
            (Some(dir), false) => Maps::Into(dir.clone()),
            (None, false) => Maps::None,
        },
        progress: crate::progress::Progress::new(args.quiet || args.json),
        gltf_variant: args.gltf_variant.clone(),
        correction: args.no_correction.then_some(false),
    })
}

/// `fit --out-dir DIR`: every input into its folder, a line per input on stderr (a JSON line
/// on stdout with --json), exit 2 at the end when any failed.
fn run_batch(args: &FitArgs, dir: &std::path::Path) -> Result<()> {
    let batch = Batch {
        inputs: args.data.clone(),
        options: options(args)?,
        out_dir: dir.to_path_buf(),
        skip_done: args.skip_done,
    };
    let mut printed = Ok(());
    let rows = batch.run(&mut |d| {
        if args.json && printed.is_ok() {
            printed = serde_json::to_string(d.row)
                .map_err(anyhow::Error::from)
                .and_then(|j| super::print_out(&format!("{j}\n")));
        }
        if !args.quiet {
            eprintln!("{}", batch_line(&d, dir));
        }
    })?;
    printed?;
    let failed: Vec<&str> = rows
        .iter()
        .filter(|r| r.status != "ok")
        .map(|r| r.input.as_str())
        .collect();
    let summary = dir.join(crate::export::summary_csv::FILE);
    if !args.quiet {
        eprintln!(
            "wrote {} ({}: {} ok, {} failed)",
            summary.display(),
            counted(rows.len(), "input"),
            rows.len() - failed.len(),
            failed.len()
        );
    }
    if !failed.is_empty() {
        return Err(anyhow!(
            "{} of {} failed (see {}): {}",
            failed.len(),
            counted(rows.len(), "input"),
            summary.display(),
            failed.join(", ")
        ));
    }
    Ok(())
}

/// `n` and `what`, plural unless one.
fn counted(n: usize, what: &str) -> String {
    format!("{n} {what}{}", if n == 1 { "" } else { "s" })
}

/// The stderr line of one finished input of a batch.
fn batch_line(d: &Done, dir: &std::path::Path) -> String {
    let r = d.row;
    let head = format!("[{}/{}] {}", d.index + 1, d.of, r.input);
    if d.skipped {
        return format!("{head}: done before ({}), skipped", r.result);
    }
    if r.status != "ok" {
        return format!("{head}: FAILED: {}", r.error);
    }
    let heldout = match (r.heldout_error, r.floor_ratio) {
        (Some(e), Some(q)) => format!(", held-out {} error {e:.4} ({q:.2}x the floor)", r.heldout_metric),
        (Some(e), None) => format!(", held-out {} error {e:.4}", r.heldout_metric),
        _ => String::new(),
    };
    let loud = match d.run.map(|run| run.outcome.quality.warnings.len()) {
        Some(n) if n > 0 => format!(
            "\n  FIT QUALITY: {n} warning{} in {}",
            if n == 1 { "" } else { "s" },
            dir.join(&r.report).display()
        ),
        _ => String::new(),
    };
    format!(
        "{head}: {}, {}{heldout}, {} -> {}{loud}",
        r.model,
        r.verdict,
        crate::progress::seconds(r.seconds),
        dir.join(&r.name).display()
    )
}

/// `fit DATA`: one input, its outputs where --out, --report and --maps say.
fn run_one(args: &FitArgs) -> Result<()> {
    let options = options(args)?;
    let data = &args.data[0];
    let req = options.request(data)?;
    let inputs = options.inputs(&req);
    if let Some(tile) = &args.tile {
        return run_tile(args, req, tile, &inputs);
    }
    fit_api::check(&req)?;
    // every output reserved before the work (none an input or another output), written together
    let out_path = args.out.clone();
    let mut outs = Outputs::new(&inputs);
    let targets =
        FitTargets::reserve(&mut outs, &req, out_path.as_deref(), args.report.as_deref())?;
    // an interrupted auto run writes the rungs it finished, marked partial
    let sink = (req.config.model.is_auto()).then(fit_api::AutoSink::default);
    if let Some(sink) = &sink {
        let (sink, json, report, inputs) = (
            sink.clone(),
            out_path.clone(),
            args.report.clone(),
            inputs.clone(),
        );
        crate::export::atomic::set_interrupt_hook(Box::new(move || {
            let p = sink.lock().unwrap_or_else(|p| p.into_inner()).clone();
            if p.candidates.is_empty() {
                return;
            }
            eprintln!("\n{}", p.partial_report());
            match fit_api::write_partial(&p, json.as_deref(), report.as_deref(), &inputs) {
                Ok(files) if files.is_empty() => {
                    eprintln!("PARTIAL: nothing written (no --out or --report)")
                }
                Ok(files) => eprintln!(
                    "PARTIAL: wrote {} (marked partial: {})",
                    files
                        .iter()
                        .map(|f| f.display().to_string())
                        .collect::<Vec<_>>()
                        .join(", "),
                    p.stage()
                ),
                Err(e) => eprintln!("PARTIAL: the partial result could not be written: {e:#}"),
            }
        }));
    }
    let fitted = fit_api::fit_reporting(&req, sink.as_ref());
    // from here on the run writes its own outputs (the handler waits if it is writing)
    crate::export::atomic::clear_interrupt_hook();
    let mut run = fitted?;
    run.write(&mut outs, &targets)?;
    outs.commit()?;
    // stdout's failure (a closed pipe, a full disk) is reported after the banner, never instead
    let mut printed = Ok(());
    let outcome = &run.outcome;
    if args.json {
        printed = super::print_out(&format!("{}\n", run.summary_json(out_path.as_deref())));
    } else if !args.quiet {
        printed = super::print_out(&run.report_text);
        match &out_path {
            Some(p) => eprintln!("wrote {}", p.display()),
            None => eprintln!("nothing written: add --out FILE to save the result JSON"),
        }
    }
    // a warning once: not again on stderr when the report just printed says it
    let report_printed = !(args.quiet || args.json);
    if !args.quiet {
        for w in run.warnings.iter().filter(|w| {
            !outcome.quality.warnings.contains(w)
                && !(report_printed && run.report_text.contains(*w))
        }) {
            eprintln!("warning: {w}");
        }
    }
    // what the quality checks found is printed even with --quiet: it must not be missed; when
    // the report was just printed on the terminal, the banner points to its [[Warnings]] instead
    // of repeating them
    use std::io::IsTerminal;
    quality_banner(
        &outcome.quality,
        report_printed && std::io::stdout().is_terminal(),
    );
    printed.with_context(|| match &out_path {
        Some(p) => format!("the outputs were written ({})", p.display()),
        None => "the fit ran (nothing was written)".to_string(),
    })
}

fn parse_tile(text: &str) -> Result<(u32, u32)> {
    let bad = || anyhow!("--tile {text}: expected I/N with 0 <= I < N (e.g. 3/16)");
    let (i, n) = text.split_once('/').ok_or_else(bad)?;
    let (i, n): (u32, u32) = (
        i.trim().parse().map_err(|_| bad())?,
        n.trim().parse().map_err(|_| bad())?,
    );
    if n == 0 || i >= n {
        return Err(bad());
    }
    Ok((i, n))
}

/// `fit --tile I/N`: the tile request of `args` (a fit's arguments, `req` their fit request).
pub fn run_tile(
    args: &FitArgs,
    req: crate::api::fit::FitRequest,
    tile: &str,
    inputs: &[PathBuf],
) -> Result<()> {
    let tile = parse_tile(tile)?;
    let t = tiles::run_tile(
        &TileRequest {
            data: req.data,
            config: req.config,
            load: req.load,
            globals: args
                .globals
                .clone()
                .expect("clap: --tile requires --globals"),
            dir: args.maps.clone().expect("clap: --tile requires --maps"),
            tile,
            progress: req.progress,
        },
        inputs,
    )?;
    if !args.quiet {
        eprintln!(
            "wrote {} (rows {}..{}, {} texels)",
            t.file.display(),
            t.rows.0,
            t.rows.1,
            t.tile.part.texels.len()
        );
    }
    Ok(())
}

/// The quality warnings as a banner on stderr (bold red on a terminal); `listed_above`: the
/// report on the terminal lists them already, so the banner names their count only.
pub fn quality_banner(q: &fit::quality::Quality, listed_above: bool) {
    use std::io::IsTerminal;
    if q.warnings.is_empty() && q.undetermined.is_empty() {
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
    if !q.undetermined.is_empty() {
        let names: Vec<String> = q.undetermined.iter().map(|u| format!("`{}`", u.label)).collect();
        eprintln!(
            "UNDETERMINED: {} value{} the data do not determine, used but not measured: {}",
            names.len(),
            if names.len() == 1 { "" } else { "s" },
            names.join(", ")
        );
    }
    if listed_above {
        let n = q.warnings.len();
        eprintln!(
            "{n} warning{}: see [[Warnings]] in the report above",
            if n == 1 { "" } else { "s" }
        );
    } else {
        for w in &q.warnings {
            eprintln!("WARNING: {w}");
        }
    }
    eprintln!("{rule}{off}");
}
