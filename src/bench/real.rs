//! `fibrefit bench real FILE... [--curet DIR]`: real fabrics against what their data allow
//! (issue 39). Each file (measured files at seeded direction pairs, as `bench felt` draws them)
//! and each CUReT sample is fitted as `fibrefit fit DATA --model auto --metric log` runs it:
//! every candidate's held-out log error on the same folds or split, the choice, the floor (the
//! nonparametric predictor's held-out error on the same splits, `fit::floor`), the chosen
//! model's ratio to it, where its excess lies, the better of the simple fits (lambert, ward) and
//! the wall time.

use crate::bench::selection::auto_fit;
use crate::fit::config::{FitConfig, Metric};
use crate::fit::floor::FloorCheck;
use crate::fit::selection::Candidate;
use crate::fit::FitOutcome;
use crate::load::rgl::MeasuredOptions;
use crate::load::samples::Samples;
use crate::load::{load_data, LoadOptions};
use anyhow::{anyhow, Result};
use std::path::{Path, PathBuf};

/// The simple fits the issue measures auto against: the better of these (held out).
pub const SIMPLE: [&str; 2] = ["lambert", "ward"];

/// CUReT samples that are not fibrous (the controls).
pub const CURET_CONTROLS: [u32; 2] = [4, 15];

/// One real data set's run.
#[derive(Clone, Debug)]
pub struct RealRow {
    /// The data's name: the file's stem, or "CUReT N (name)".
    pub data: String,
    /// Where it came from.
    pub source: PathBuf,
    /// A fibrous material (false for the CUReT controls).
    pub fibrous: bool,
    /// "measured file", "CUReT" or "table".
    pub kind: &'static str,
    pub samples: usize,
    pub validation: String,
    pub metric: String,
    pub candidates: Vec<Candidate>,
    pub chosen: String,
    /// The floor check of the chosen candidate, with its smooth correction where one was kept
    /// (None: it could not be measured, `floor_error`).
    pub floor: Option<FloorCheck>,
    /// The smooth correction kept on the chosen candidate (`fit::correction`), if any.
    pub correction: Option<crate::fit::correction::CorrectionFit>,
    pub floor_error: Option<String>,
    /// The better of [`SIMPLE`]: its name and held-out error.
    pub simple: Option<(String, f64)>,
    /// Wall time of selection + the final fit + the floor, s.
    pub seconds: f64,
}

impl RealRow {
    /// The chosen candidate.
    pub fn chosen_candidate(&self) -> Option<&Candidate> {
        self.candidates.iter().find(|c| c.chosen)
    }

    /// The chosen model's held-out error (with its correction, where one was kept).
    pub fn heldout_error(&self) -> Option<f64> {
        match &self.floor {
            Some(f) => Some(f.heldout_error),
            None => self.chosen_candidate().map(|c| c.cv_error),
        }
    }

    /// The chosen model's held-out error over the better simple fit's.
    pub fn simple_ratio(&self) -> Option<f64> {
        let e = self.heldout_error()?;
        self.simple.as_ref().map(|(_, s)| e / s)
    }
}

/// The run: a row per data set, and the first measured file's final fit (for its figures).
pub struct RealRun {
    pub rows: Vec<RealRow>,
    /// (row index, the chosen fit, its config, the fitted samples) of the first measured file.
    pub drawn: Option<(usize, FitOutcome, FitConfig, Samples)>,
}

/// `f` as the real-data studies read it: a measured file at `directions` seeded pairs (seed 23,
/// theta up to 78 deg), a table as it is.
pub fn load_drawn(f: &Path, directions: usize) -> Result<Samples> {
    let opts = LoadOptions {
        measured: MeasuredOptions {
            directions,
            seed: 23,
            max_theta_deg: 78.0,
        },
        ..Default::default()
    };
    load_data(f, &opts)
}

/// Data sets to run: (name, source, fibrous, kind, samples).
type Set = (String, PathBuf, bool, &'static str, Samples);

fn sets(files: &[PathBuf], curet: Option<&Path>, directions: usize) -> Result<Vec<Set>> {
    let mut out = Vec::new();
    for f in files {
        let s = load_drawn(f, directions)?;
        let kind = match s.kind {
            crate::load::samples::DataKind::Measured => "measured file",
            _ => "table",
        };
        let name = f
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_else(|| f.display().to_string());
        out.push((name, f.clone(), true, kind, s));
    }
    if let Some(dir) = curet {
        if !crate::load::curet::is_curet_dir(dir) {
            return Err(anyhow!(
                "{}: not a CUReT folder (it needs {} and {})",
                dir.display(),
                crate::load::curet::TABLE,
                crate::load::curet::VALUES
            ));
        }
        for (n, s) in crate::load::curet::load_dir(dir)? {
            let name = match crate::load::curet::sample_name(n) {
                Some(m) => format!("CUReT {n} ({m})"),
                None => format!("CUReT {n}"),
            };
            out.push((name, dir.to_path_buf(), !CURET_CONTROLS.contains(&n), "CUReT", s));
        }
    }
    Ok(out)
}

/// The study on `files` (measured files drawn at `directions` pairs) and the samples of the
/// CUReT folder `curet`, each with `--model auto --metric log`.
pub fn run(
    files: &[PathBuf],
    curet: Option<&Path>,
    directions: usize,
    progress: &crate::progress::Progress,
) -> Result<RealRun> {
    let mut rows = Vec::new();
    let mut drawn = None;
    for (name, source, fibrous, kind, data) in sets(files, curet, directions)? {
        progress.line(&format!(
            "bench real: {name}, {} samples",
            data.samples.len()
        ));
        let t = std::time::Instant::now();
        let quiet = crate::progress::Progress::quiet();
        let (s, mut o, cfg, _, _) = auto_fit(&data, false, Some(Metric::Log), &quiet)?;
        // the floor and the smooth correction, as a fit measures them
        let warned = o.warnings.len();
        crate::fit::floor::judge::fit_stage(&data, &cfg, &mut o, Some(&s), &quiet);
        let floor = o.quality.floor.clone().ok_or_else(|| {
            anyhow!(
                "{}",
                o.warnings.get(warned).map_or("not measured", String::as_str)
            )
        });
        let simple = s
            .candidates
            .iter()
            .filter(|c| SIMPLE.contains(&c.name.as_str()))
            .min_by(|a, b| a.cv_error.total_cmp(&b.cv_error))
            .map(|c| (c.name.clone(), c.cv_error));
        let row = RealRow {
            data: name,
            source,
            fibrous,
            kind,
            samples: data.samples.len(),
            validation: s.validation.clone(),
            metric: s.metric.clone(),
            chosen: s.chosen.clone(),
            floor_error: floor.as_ref().err().map(|e| format!("{e:#}")),
            floor: floor.ok(),
            correction: o.correction.clone(),
            candidates: s.candidates,
            simple,
            seconds: t.elapsed().as_secs_f64(),
        };
        progress.line(&format!(
            "bench real: {}: chose {}, {:.1} s",
            row.data, row.chosen, row.seconds
        ));
        if drawn.is_none() && kind == "measured file" {
            drawn = Some((rows.len(), o, cfg, data));
        }
        rows.push(row);
    }
    Ok(RealRun { rows, drawn })
}

/// The median of `x` (NaN when empty).
pub fn median(mut x: Vec<f64>) -> f64 {
    if x.is_empty() {
        return f64::NAN;
    }
    x.sort_by(f64::total_cmp);
    let n = x.len();
    match n % 2 {
        1 => x[n / 2],
        _ => 0.5 * (x[n / 2 - 1] + x[n / 2]),
    }
}
