//! `fibrefit score`: a fitted result against any dataset `fit` accepts.

use super::data::LoadArgs;
use crate::fit::score;
use anyhow::Result;
use clap::Args;
use std::path::PathBuf;

#[derive(Debug, Args)]
#[command(after_help = "\
Evaluates RESULT (a `fibrefit fit` JSON) exactly as the fit did (rung, knobs, topology map,
residual metric) on DATA (goniometric table or capture TOML) and prints: residual and sample
counts, chi-square and reduced chi-square when DATA has sigmas (else the sum of squares), RMSE
in 1/sr and relative RMSE (RMSE / RMS data), per channel RMSE, relative RMSE and log error
(RMS of ln(m + eps) - ln(y + eps), eps = 1 % of the channel's median value), and the mean residual in
bins of the half-vector angle and of its azimuth from the fibres (* = systematic, > 4 standard
errors), the floor of DATA (what a nonparametric predictor of the data themselves reaches,
cross-validated on them; not for captures), and ends with the verdict in the fit report's words:
\"fits within the noise\" or \"does not fit within the noise\" (sigmas, neighbouring pixels);
without sigmas, judged against the floor: \"within 1.2x of what the data allow\" or \"misses
structure the data hold: ...\". Scoring a fit's own training data reproduces its statistics;
scoring held-out data is how a fit is checked. Writes nothing.")]
pub struct ScoreArgs {
    /// Result JSON written by `fibrefit fit`
    pub result: PathBuf,
    /// Goniometric table (.csv, .tsv, .txt, .dat) or capture TOML
    pub data: PathBuf,
    /// Print the score as JSON on stdout
    #[arg(long)]
    pub json: bool,
    #[command(flatten)]
    pub load: LoadArgs,
}

pub fn run(args: &ScoreArgs) -> Result<()> {
    let s = crate::api::score::score(&args.result, &args.data, &args.load.options()?)?;
    if args.json {
        super::print_out(&(serde_json::to_string_pretty(&s)? + "\n"))?;
    } else {
        super::print_out(&score::text(&s))?;
    }
    Ok(())
}
