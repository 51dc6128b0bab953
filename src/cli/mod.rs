//! Command line: parse, validate into real objects, run. Errors carry their whole context and
//! map to exit code 2 in `main`.

pub mod bench;
pub mod board;
pub mod calibrate;
pub mod data;
pub mod eval;
pub mod export;
pub mod fit;
pub mod inspect;
pub mod map_tiles;
pub mod render;
pub mod score;
pub mod synth;
pub mod tangents;
pub mod view;

use anyhow::Result;
use clap::{Parser, Subcommand};
use std::ffi::OsString;

#[derive(Debug, Parser)]
#[command(
    name = "fibrefit",
    version,
    about = "Fit fibre reflectance models to goniometric and image measurements",
    long_about = "Fit fibre reflectance models to goniometric and image measurements.\n\n\
        Conventions (MODEL.md): swatch normal N = +z; angles in degrees in files, theta from N, \
        phi from the swatch x axis towards y; BRDF f in 1/sr; shaded intensity I = f (N.l)."
)]
pub struct Cli {
    #[command(subcommand)]
    pub command: Command,
}

#[derive(Debug, Subcommand)]
pub enum Command {
    /// Fit a model to measurements and export renderer JSON (the main job).
    Fit(fit::FitArgs),
    /// Evaluate a model's BRDF and intensity at given light/view directions.
    Eval(eval::EvalArgs),
    /// Score a fitted result against measurements (held-out data, another capture).
    Score(score::ScoreArgs),
    /// Load measurements as `fit` would and summarise them (counts, ranges, coverage, drops).
    Inspect(inspect::InspectArgs),
    /// Measure the speed-accuracy trade of every rung and knob; write tables and plots.
    Bench(bench::BenchArgs),
    /// Render synthetic measurements (gonio CSV, image captures) from known parameters.
    Synth(synth::SynthArgs),
    /// Render a material on an object (torus, sphere, swatch) as an image and its AOVs.
    Render(render::RenderArgs),
    /// The fitted model as shader code (WGSL, GLSL, HLSL, MSL) or a glTF preview with a fitted material.
    Export(export::ExportArgs),
    /// Principal curvature directions of a mesh (the tangent field of principal-curvature-aligned shading) as CSV or glTF.
    Tangents(tangents::TangentsArgs),
    /// A self-contained HTML page with a WebGL2 viewer of a fitted result (exact model beside the glTF route, measured against fitted).
    View(view::ViewArgs),
    /// A printable calibration board (markers, swatch window, grey patch, scale bar) for photos.
    Board(board::BoardArgs),
    /// Photos of a swatch on the printed board into a capture: markers, intrinsics, poses, rectified linear images.
    Calibrate(calibrate::CalibrateArgs),
    /// Assemble the per-texel map tiles of `fit --tile` into maps and a result JSON.
    MergeMaps(map_tiles::MergeMapsArgs),
}

/// The command line, with `fit --help` listing the rungs from the registry (id and what each
/// accounts for).
fn command() -> clap::Command {
    use clap::CommandFactory;
    Cli::command().mut_subcommand("fit", |c| {
        let base = c
            .get_after_help()
            .map(|s| s.to_string())
            .unwrap_or_default();
        let rungs: String = crate::model::ModelId::ALL
            .iter()
            .map(|id| format!("  {:<18}{}\n", id.as_str(), id.rung().description))
            .collect();
        c.after_long_help(format!(
            "{base}\n\nRUNGS (--model ID; cheapest first; docs/model.md):\n{rungs}"
        ))
    })
}

/// Parse `args` and run. Returns the process exit code (help and version print and return 0).
pub fn run<I, T>(args: I) -> Result<()>
where
    I: IntoIterator<Item = T>,
    T: Into<OsString> + Clone,
{
    let parsed = command()
        .try_get_matches_from(args)
        .and_then(|m| <Cli as clap::FromArgMatches>::from_arg_matches(&m));
    let cli = match parsed {
        Ok(cli) => cli,
        Err(e) => {
            let code = e.exit_code();
            let printed = e.print();
            if code == 0 {
                // help and version on stdout: a full disk is an error, a closed pipe is not
                return printed.map_err(|e| named_stdout(e).into());
            }
            return Err(UsageError.into());
        }
    };
    match cli.command {
        Command::Fit(args) => fit::run(&args),
        Command::Eval(args) => eval::run(&args),
        Command::Inspect(args) => inspect::run(&args),
        Command::Score(args) => score::run(&args),
        Command::Synth(args) => synth::run(&args),
        Command::Bench(args) => bench::run(&args),
        Command::MergeMaps(args) => map_tiles::run_merge(&args),
        Command::Render(args) => render::run(&args),
        Command::Tangents(args) => tangents::run(&args),
        Command::Export(args) => export::run(&args),
        Command::View(args) => view::run(&args),
        Command::Board(args) => board::run(&args),
        Command::Calibrate(args) => calibrate::run(&args),
    }
}

/// Write `text` to standard output and flush it: a closed pipe comes back as `BrokenPipe` (exit
/// 0 in `main`, as Unix tools do), a full disk as an error naming standard output (exit 2).
pub fn print_out(text: &str) -> Result<()> {
    use std::io::Write;
    let mut out = std::io::stdout().lock();
    out.write_all(text.as_bytes())
        .and_then(|_| out.flush())
        .map_err(|e| named_stdout(e).into())
}

fn named_stdout(e: std::io::Error) -> std::io::Error {
    std::io::Error::new(e.kind(), format!("standard output: {e}"))
}

/// A usage error already printed by clap.
#[derive(Debug)]
pub struct UsageError;

impl std::fmt::Display for UsageError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("invalid command line")
    }
}

impl std::error::Error for UsageError {}

/// The command line's `main`: signal cleanup installed, the command run, its exit code.
pub fn main() -> std::process::ExitCode {
    use std::process::ExitCode;

    crate::export::atomic::install_signal_cleanup();
    let outcome = crate::cli::run(std::env::args_os());
    if crate::load::input::interrupted() {
        // SIGINT/SIGTERM came (a wait it stopped may be why the run failed): its handler
        // cleans up and exits 130; the run's own outcome is not the exit code
        loop {
            std::thread::sleep(std::time::Duration::from_secs(1));
        }
    }
    match outcome {
        Ok(()) => ExitCode::SUCCESS,
        // a reader that stops early (`| head`) is not an error
        Err(e)
            if e.chain().any(|c| {
                c.downcast_ref::<std::io::Error>()
                    .is_some_and(|io| io.kind() == std::io::ErrorKind::BrokenPipe)
            }) =>
        {
            ExitCode::SUCCESS
        }
        Err(e) => {
            if !e.is::<crate::cli::UsageError>() {
                // a closed or full stderr loses the message, not the exit code
                use std::io::Write;
                let _ = writeln!(std::io::stderr(), "error: {e:#}");
            }
            ExitCode::from(2)
        }
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn clap_definition_is_consistent() {
        super::command().debug_assert();
    }

    #[test]
    fn fit_help_lists_every_rung_with_its_description() {
        let help = super::command()
            .find_subcommand_mut("fit")
            .expect("fit")
            .render_long_help()
            .to_string();
        for id in crate::model::ModelId::ALL {
            assert!(help.contains(id.rung().description), "{id}: {help}");
        }
    }
}
