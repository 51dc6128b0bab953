//! `fibrefit bench`: measure the speed–accuracy trade and write a report.

use anyhow::{bail, Result};
use clap::Args;
use std::path::PathBuf;
use std::time::Instant;

#[derive(Debug, Args)]
#[command(after_help = "\
Writes OUT/speed_accuracy.md (tables), OUT/speed_accuracy_forward.csv, OUT/speed_accuracy_fit.csv,
OUT/pareto.png (error vs cost per rung, log axes) and OUT/fit_time_vs_error.png. The fit level
uses the shipped silk capture under ROOT/data_synthetic/silk and ROOT/configs/fit_silk.toml.")]
pub struct BenchArgs {
    /// Fewer directions, repeats, fractions and orders: finishes in well under a minute
    #[arg(long)]
    pub quick: bool,
    /// Output directory
    #[arg(long, value_name = "DIR", default_value = "reports")]
    pub out: PathBuf,
    /// Repository root holding data_synthetic/ and configs/
    #[arg(long, value_name = "DIR", default_value = ".")]
    pub root: PathBuf,
    /// No progress bar
    #[arg(long, short)]
    pub quiet: bool,
}

pub fn run(args: &BenchArgs) -> Result<()> {
    if !args.root.join("data_synthetic/silk/capture.toml").exists() {
        bail!(
            "{}: no data_synthetic/silk/capture.toml here; run from the repository root or pass --root",
            args.root.display()
        );
    }
    let t = Instant::now();
    let fits = if args.quick { 4 } else { 9 };
    let bar = crate::progress::bar(
        (crate::bench::SETS.len() * 3 + fits) as u64,
        "bench",
        args.quiet,
    );
    let forward = crate::bench::forward(args.quick, &bar)?;
    let fit = crate::bench::fit_level(&args.root, args.quick, &bar)?;
    bar.finish_and_clear();
    crate::export::speed_report::write(
        &args.out,
        &forward,
        &fit,
        args.quick,
        t.elapsed().as_secs_f64(),
    )?;
    if !args.quiet {
        eprintln!(
            "wrote {} in {:.1} s",
            args.out.join("speed_accuracy.md").display(),
            t.elapsed().as_secs_f64()
        );
    }
    Ok(())
}
