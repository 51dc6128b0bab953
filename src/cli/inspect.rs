//! `fibrefit inspect`: load measurements exactly as `fit` does and summarise them.

use super::data::LoadArgs;
use crate::load::{load_data, summary::Summary};
use anyhow::Result;
use clap::Args;
use std::path::PathBuf;

#[derive(Debug, Args)]
#[command(after_help = "\
DATA is a goniometric CSV (.csv: theta_i,phi_i,theta_o,phi_o in degrees and brdf or radiance with
irradiance) or an image capture description (.toml). Bad input gives the same errors as `fit`.")]
pub struct InspectArgs {
    /// Goniometric CSV or capture TOML
    pub data: PathBuf,
    /// Print the summary as JSON
    #[arg(long)]
    pub json: bool,
    #[command(flatten)]
    pub load: LoadArgs,
}

pub fn run(args: &InspectArgs) -> Result<()> {
    let samples = load_data(&args.data, &args.load.options()?)?;
    let summary = Summary::of(&samples);
    if args.json {
        super::print_out(&(serde_json::to_string_pretty(&summary)? + "\n"))?;
    } else {
        super::print_out(&summary.to_text())?;
    }
    Ok(())
}
