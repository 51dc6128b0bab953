//! Many swatches: fit every input into its own folder of one output folder, with a summary
//! (`fibrefit fit A B C --out-dir DIR`). Each input gets `DIR/NAME/result.json` and its report
//! (`DIR/NAME/report.md` and figures), NAME being its file name without the extension, and a
//! row in `DIR/summary.csv` (`summary_csv`). An input that fails writes
//! nothing of its own and is a `failed` row; the others go on.

use super::fit::{self as fit_api, FitOptions, FitRun, FitTargets, Maps};
use crate::export::atomic::Outputs;
use crate::export::summary_csv::{self, Row};
use anyhow::{bail, Result};
use std::path::{Path, PathBuf};

/// The result file's name in an input's folder.
pub const RESULT: &str = "result.json";

/// A batch of fits.
#[derive(Clone, Debug)]
pub struct Batch {
    /// The data files, in the order they are fitted.
    pub inputs: Vec<PathBuf>,
    /// How each is fitted (the same for all; `maps` must be [`Maps::None`]).
    pub options: FitOptions,
    /// The output folder (created when missing).
    pub out_dir: PathBuf,
    /// Leave out inputs whose folder already holds a result and whose summary row says `ok`
    /// (a rerun after an interruption, a requeued job).
    pub skip_done: bool,
}

/// One input of a batch, finished.
pub struct Done<'a> {
    /// Its position (from 0) and the batch's size.
    pub index: usize,
    /// How many inputs the batch has.
    pub of: usize,
    /// Its summary row.
    pub row: &'a Row,
    /// The fit (`None` when it failed or was skipped).
    pub run: Option<&'a FitRun>,
    /// Left out: done by an earlier run (`skip_done`).
    pub skipped: bool,
}

impl Batch {
    /// Check the batch before any work: every input a readable file, no two with the same
    /// name (their folders would collide), the options valid, the output folder usable and
    /// any summary there one this version writes. Returns the inputs' folder names.
    pub fn plan(&self) -> Result<Vec<String>> {
        // a plan alone leaves no folder behind: the check's folder is removed again
        self.checked().map(|(names, _)| names)
    }

    /// [`Batch::plan`]'s checks; the output folder, made if missing, is held by the returned
    /// outputs (removed when they are dropped uncommitted, kept once committed).
    fn checked(&self) -> Result<(Vec<String>, Outputs)> {
        if self.options.maps != Maps::None {
            bail!("--out-dir fits global parameters only: per-texel maps of many captures are fitted one `fit --maps` at a time (or in tiles: docs/guide/fit.md)");
        }
        let mut names: Vec<(String, &Path)> = Vec::new();
        for input in &self.inputs {
            match std::fs::metadata(input) {
                Ok(m) if m.is_file() => {}
                Ok(_) => bail!("{}: is not a file", input.display()),
                Err(e) => bail!("{}: cannot read: {e}", input.display()),
            }
            let name = name_of(input)?;
            if let Some((_, other)) = names.iter().find(|(n, _)| *n == name) {
                bail!(
                    "{} and {} would both be written into {}: give them different file names, or fit them into different --out-dir folders",
                    other.display(),
                    input.display(),
                    self.out_dir.join(&name).display()
                );
            }
            names.push((name, input));
        }
        if let Some(first) = self.inputs.first() {
            fit_api::check(&self.options.request(first)?)?;
        }
        let mut outs = Outputs::new(&self.inputs);
        outs.dir(&self.out_dir, "--out-dir")?;
        summary_csv::read(&self.out_dir)?;
        Ok((names.into_iter().map(|(n, _)| n).collect(), outs))
    }

    /// Fit every input in turn (after [`Batch::plan`]), updating the summary after each;
    /// `done` hears of each input as it finishes. Returns the rows of this batch.
    pub fn run(&self, done: &mut dyn FnMut(Done)) -> Result<Vec<Row>> {
        let (names, folder) = self.checked()?;
        // the folder is kept from here on, never made and removed again: runs sharing it
        // (`parallel fibrefit fit {} --out-dir F`) would otherwise race, one removing the empty
        // folder another has just found there
        folder.commit()?;
        let earlier = summary_csv::read(&self.out_dir)?;
        let mut rows = Vec::with_capacity(names.len());
        for (index, (input, name)) in self.inputs.iter().zip(&names).enumerate() {
            let of = self.inputs.len();
            if let Some(row) = self.done_before(&earlier, name) {
                done(Done {
                    index,
                    of,
                    row: &row,
                    run: None,
                    skipped: true,
                });
                rows.push(row);
                continue;
            }
            let start = std::time::Instant::now();
            let fitted = self.fit_one(input, name);
            // milliseconds are plenty for a summary
            let seconds = (start.elapsed().as_secs_f64() * 1e3).round() / 1e3;
            let row = match &fitted {
                Ok(run) => row_of(run, input, name, seconds),
                Err(e) => failed_row(input, name, seconds, e),
            };
            summary_csv::update(&self.out_dir, &row, &self.inputs)?;
            done(Done {
                index,
                of,
                row: &row,
                run: fitted.as_ref().ok(),
                skipped: false,
            });
            rows.push(row);
        }
        Ok(rows)
    }

    /// `name`'s row from an earlier run, when `skip_done` and its result is there.
    fn done_before(&self, earlier: &[Row], name: &str) -> Option<Row> {
        let row = earlier
            .iter()
            .find(|r| r.name == name && r.status == "ok")?;
        (self.skip_done && self.out_dir.join(name).join(RESULT).is_file()).then(|| row.clone())
    }

    /// Fit `input` into `DIR/name/`: the result and the report, committed together.
    fn fit_one(&self, input: &Path, name: &str) -> Result<FitRun> {
        let req = self.options.request(input)?;
        fit_api::check(&req)?;
        let folder = self.out_dir.join(name);
        let mut outs = Outputs::new(&self.options.inputs(&req));
        for other in &self.inputs {
            outs.add_input(other);
        }
        outs.dir(&folder, "--out-dir")?;
        let json = folder.join(RESULT);
        let targets = FitTargets::reserve(&mut outs, &req, Some(&json), Some(&folder))?;
        let mut run = fit_api::fit(&req)?;
        run.write(&mut outs, &targets)?;
        outs.commit()?;
        Ok(run)
    }
}

/// An input's folder name: its file name without the extension.
fn name_of(input: &Path) -> Result<String> {
    match input.file_stem().and_then(|s| s.to_str()) {
        Some(s) if !s.is_empty() && !s.starts_with('.') => Ok(s.to_string()),
        _ => bail!(
            "{}: its file name cannot name an output folder (give it a plain UTF-8 name)",
            input.display()
        ),
    }
}

/// The summary row of a finished fit of `input` into the folder `name`.
fn row_of(run: &FitRun, input: &Path, name: &str, seconds: f64) -> Row {
    let s = &run.outcome.statistics;
    let chosen = run
        .selection
        .as_ref()
        .and_then(|sel| sel.candidates.iter().find(|c| c.chosen).map(|c| (sel, c)));
    let floor = run.outcome.quality.floor.as_ref();
    let fuzz = match run.config.listed_fuzz_parameter() {
        Some(_) => " + fuzz",
        None => "",
    };
    let fuzz = match &run.outcome.correction {
        Some(c) => format!("{fuzz} + correction (degree {})", c.correction.degree),
        None => fuzz.to_string(),
    };
    Row {
        name: name.to_string(),
        input: input.display().to_string(),
        status: "ok".into(),
        model: format!("{}{fuzz}", run.model),
        verdict: run.outcome.quality.verdict.clone(),
        heldout_error: floor
            .map(|f| f.heldout_error)
            .or(chosen.map(|(_, c)| c.cv_error)),
        heldout_metric: match (floor, chosen) {
            (Some(f), _) => f.estimate.metric.clone(),
            (None, Some((sel, _))) => sel.metric.clone(),
            (None, None) => String::new(),
        },
        heldout_relative_rmse: chosen.map(|(_, c)| c.heldout_relative_rmse),
        floor: floor.map(|f| f.floor),
        floor_ratio: floor.map(|f| f.ratio),
        rmse: Some(s.rmse),
        relative_rmse: Some(s.relative_rmse),
        samples: Some(run.samples.samples.len()),
        seconds,
        result: format!("{name}/{RESULT}"),
        report: format!("{name}/report.md"),
        warnings: run.warnings.len(),
        error: String::new(),
    }
}

/// The summary row of an input whose fit failed with `e`.
fn failed_row(input: &Path, name: &str, seconds: f64, e: &anyhow::Error) -> Row {
    Row {
        name: name.to_string(),
        input: input.display().to_string(),
        status: "failed".into(),
        seconds,
        error: format!("{e:#}").replace('\n', " "),
        ..Row::default()
    }
}
