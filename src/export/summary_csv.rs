//! The summary of fits run into one output folder (`fibrefit fit A B C --out-dir DIR`):
//! `DIR/summary.csv`, one row per input with its rung, verdict, held-out error and time.
//!
//! Runs that share the folder (a Slurm job array, GNU parallel, a rerun with more inputs) each
//! update their own rows: the file is read, merged and replaced under an exclusive lock on
//! `DIR/.summary.csv.lock` (`flock`, which Linux NFS clients honour as well), so no row is
//! lost when two runs finish at once. Rows are sorted by name; the file is replaced atomically.

use super::atomic::Outputs;
use anyhow::{anyhow, bail, Context, Result};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// The summary's file name inside the output folder.
pub const FILE: &str = "summary.csv";

/// The lock file beside it.
const LOCK: &str = ".summary.csv.lock";

/// One input's line: what was fitted and how well, or why it failed.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Row {
    /// The input's folder under DIR (its file name without the extension): the row's key.
    pub name: String,
    /// The input file as given.
    pub input: String,
    /// `ok`, or `failed` (then `error` says why and nothing was written for it).
    pub status: String,
    /// The rung fitted (auto's choice, `+ fuzz` with the fuzz layer, `+ correction (degree d)`
    /// with a smooth correction kept on it).
    pub model: String,
    /// The fit quality verdict (as `fit --json`'s `verdict`).
    pub verdict: String,
    /// The held-out error of the fitted model in the fit metric's units (the report's
    /// `[[Quality]]`: the same folds or split as auto's; residuals in standard deviations when
    /// the data give sigmas); empty where it was not measured (per-texel maps).
    pub heldout_error: Option<f64>,
    /// The metric of `heldout_error` (`log`: ln(f + eps) residuals; `linear`: BRDF residuals;
    /// `cosine`: shaded-intensity residuals).
    pub heldout_metric: String,
    /// The held-out RMSE relative to the RMS of the held-out values (comparable across files
    /// and metrics).
    pub heldout_relative_rmse: Option<f64>,
    /// What the data themselves allow on the same held-out samples (a nonparametric
    /// predictor's error, same metric).
    pub floor: Option<f64>,
    /// heldout_error / floor (within 1.2: the model fits as well as the data allow).
    pub floor_ratio: Option<f64>,
    /// The fit's RMSE on all samples, 1/sr.
    pub rmse: Option<f64>,
    /// The fit's RMSE relative to the RMS of the values.
    pub relative_rmse: Option<f64>,
    /// The samples fitted.
    pub samples: Option<usize>,
    /// Wall-clock seconds for this input (loading, fitting, writing).
    pub seconds: f64,
    /// The result JSON, relative to DIR.
    pub result: String,
    /// The report, relative to DIR.
    pub report: String,
    /// How many warnings the fit gave (the report lists them).
    pub warnings: usize,
    /// Why the input failed (empty when it did not).
    pub error: String,
}

/// The columns, in order.
pub const COLUMNS: [&str; 18] = [
    "name",
    "input",
    "status",
    "model",
    "verdict",
    "heldout_error",
    "heldout_metric",
    "heldout_relative_rmse",
    "floor",
    "floor_ratio",
    "rmse",
    "relative_rmse",
    "samples",
    "seconds",
    "result",
    "report",
    "warnings",
    "error",
];

/// The rows of the summary in `dir` (none when there is no summary yet); an error when the
/// file there is not a summary this version writes.
pub fn read(dir: &Path) -> Result<Vec<Row>> {
    let path = dir.join(FILE);
    let text = match std::fs::read(&path) {
        Ok(t) => t,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(Vec::new()),
        Err(e) => bail!("{}: cannot read: {e}", path.display()),
    };
    let mut rd = csv::Reader::from_reader(text.as_slice());
    let header: Vec<String> = rd
        .headers()
        .map_err(|e| anyhow!("{}: {e}", path.display()))?
        .iter()
        .map(str::to_string)
        .collect();
    if header != COLUMNS {
        bail!(
            "{}: exists and is not a fibrefit fit summary (its header is `{}`); choose another --out-dir, or move the file",
            path.display(),
            header.join(",")
        );
    }
    rd.deserialize()
        .enumerate()
        .map(|(k, r)| r.map_err(|e| anyhow!("{}:{}: {e}", path.display(), k + 2)))
        .collect()
}

/// Put `row` into the summary in `dir` (replacing the row of the same name), under the lock;
/// `inputs`: files the summary may not replace.
pub fn update(dir: &Path, row: &Row, inputs: &[PathBuf]) -> Result<()> {
    let _lock = Lock::take(&dir.join(LOCK))?;
    let mut rows = read(dir)?;
    rows.retain(|r| r.name != row.name);
    rows.push(row.clone());
    rows.sort_by(|a, b| a.name.cmp(&b.name));
    let path = dir.join(FILE);
    let mut outs = Outputs::new(inputs);
    let id = outs.file(&path, "--out-dir")?;
    {
        let mut w = csv::Writer::from_writer(outs.writer(id));
        for r in &rows {
            w.serialize(r)
                .with_context(|| format!("{}: cannot write", path.display()))?;
        }
        w.flush()
            .with_context(|| format!("{}: cannot write", path.display()))?;
    }
    outs.commit()
}

/// An exclusive `flock` on a file, released when dropped (the file closed).
struct Lock(#[allow(dead_code)] std::fs::File);

impl Lock {
    /// Wait for the exclusive lock on `path` (created if missing).
    fn take(path: &Path) -> Result<Self> {
        use std::os::fd::AsRawFd;
        let f = std::fs::OpenOptions::new()
            .create(true)
            .truncate(false)
            .write(true)
            .open(path)
            .with_context(|| format!("{}: cannot open the summary's lock", path.display()))?;
        loop {
            // SAFETY: flock on a descriptor this function owns; no memory is passed.
            let r = unsafe { libc::flock(f.as_raw_fd(), libc::LOCK_EX) };
            if r == 0 {
                return Ok(Self(f));
            }
            let e = std::io::Error::last_os_error();
            if e.kind() != std::io::ErrorKind::Interrupted {
                bail!("{}: cannot lock: {e}", path.display());
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn row(name: &str, seconds: f64) -> Row {
        Row {
            name: name.into(),
            input: format!("in/{name}.csv"),
            status: "ok".into(),
            model: "lambert".into(),
            verdict: "good".into(),
            heldout_error: Some(0.125),
            heldout_metric: "log".into(),
            seconds,
            result: format!("{name}/result.json"),
            ..Row::default()
        }
    }

    #[test]
    fn rows_merge_by_name_and_read_back() {
        let dir = tempfile::tempdir().unwrap();
        update(dir.path(), &row("b", 1.0), &[]).unwrap();
        update(dir.path(), &row("a", 2.0), &[]).unwrap();
        update(dir.path(), &row("b", 3.0), &[]).unwrap();
        let rows = read(dir.path()).unwrap();
        assert_eq!(rows, vec![row("a", 2.0), row("b", 3.0)]);
        let text = std::fs::read_to_string(dir.path().join(FILE)).unwrap();
        assert_eq!(text.lines().next().unwrap(), COLUMNS.join(","));
    }

    #[test]
    fn concurrent_updates_lose_no_row() {
        let dir = tempfile::tempdir().unwrap();
        std::thread::scope(|s| {
            for k in 0..8 {
                let d = dir.path();
                s.spawn(move || update(d, &row(&format!("s{k}"), k as f64), &[]).unwrap());
            }
        });
        assert_eq!(read(dir.path()).unwrap().len(), 8);
    }

    #[test]
    fn a_foreign_file_is_refused() {
        let dir = tempfile::tempdir().unwrap();
        std::fs::write(dir.path().join(FILE), "a,b\n1,2\n").unwrap();
        let e = update(dir.path(), &row("a", 1.0), &[]).unwrap_err();
        assert!(format!("{e:#}").contains("not a fibrefit fit summary"), "{e:#}");
        assert_eq!(
            std::fs::read_to_string(dir.path().join(FILE)).unwrap(),
            "a,b\n1,2\n"
        );
    }
}
