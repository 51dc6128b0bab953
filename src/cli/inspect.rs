//! `fibrefit inspect`: load measurements exactly as `fit` does and summarise them.

use super::data::LoadArgs;
use crate::load::summary;
use anyhow::Result;
use clap::Args;
use std::path::PathBuf;

#[derive(Debug, Args)]
#[command(after_help = "\
DATA is a goniometric table (.csv, .tsv, .txt or .dat: theta_i,phi_i,theta_o,phi_o in degrees,
or radians with --angles rad, and brdf or radiance with irradiance; comma-, tab-, semicolon- or
whitespace-separated whatever the extension, the delimiter read off the header and named in the
summary; the file's own column names mapped with --columns) or an image capture description
(.toml). Bad input gives the same errors as `fit`.")]
pub struct InspectArgs {
    /// Goniometric table (.csv, .tsv, .txt, .dat) or capture TOML
    pub data: PathBuf,
    /// Print the summary as JSON
    #[arg(long)]
    pub json: bool,
    #[command(flatten)]
    pub load: LoadArgs,
}

pub fn run(args: &InspectArgs) -> Result<()> {
    let summary = summary::summarise(&args.data, &args.load.options()?)?;
    if args.json {
        super::print_out(&(serde_json::to_string_pretty(&summary)? + "\n"))?;
    } else {
        super::print_out(&summary.to_text())?;
    }
    Ok(())
}
