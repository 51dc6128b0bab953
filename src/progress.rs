//! Progress on stderr: bars and stage lines that hide themselves when stderr is not a terminal
//! (or with `--quiet`). `FIBREFIT_PROGRESS=1` shows the stage lines even when stderr is not a
//! terminal (logs, tests); `FIBREFIT_PROGRESS=0` hides them on a terminal too.

use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use std::io::IsTerminal;

/// The environment variable that forces progress lines on (`1`) or off (`0`).
pub const FORCE_ENV: &str = "FIBREFIT_PROGRESS";

fn forced() -> Option<bool> {
    match std::env::var(FORCE_ENV).ok()?.trim() {
        "1" | "yes" | "always" | "true" => Some(true),
        "0" | "no" | "never" | "false" => Some(false),
        _ => None,
    }
}

/// Whether progress is shown: not `quiet`, and stderr a terminal unless [`FORCE_ENV`] says.
fn shown(quiet: bool) -> bool {
    !quiet && forced().unwrap_or_else(|| std::io::stderr().is_terminal())
}

/// The one place a run speaks: progress lines and bars (shown on a terminal, or when
/// `FORCE_ENV` says), notes and warnings (on stderr unless quiet). The library takes one
/// of these instead of printing; `Progress::quiet()` says nothing at all.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Progress {
    quiet: bool,
}

impl Progress {
    /// Progress, notes and warnings on stderr.
    pub fn stderr() -> Self {
        Self { quiet: false }
    }

    /// Nothing on stderr (`--quiet`).
    pub fn quiet() -> Self {
        Self { quiet: true }
    }

    /// [`Progress::quiet`] when `quiet`, else [`Progress::stderr`].
    pub fn new(quiet: bool) -> Self {
        Self { quiet }
    }

    /// Whether notes and warnings are printed (not `--quiet`).
    pub fn is_quiet(&self) -> bool {
        self.quiet
    }

    /// Whether progress lines are shown: not quiet, and stderr a terminal unless `FORCE_ENV`
    /// says otherwise.
    pub fn shown(&self) -> bool {
        shown(self.quiet)
    }

    /// A bar of `len` steps labelled `what` (hidden unless shown on a terminal).
    pub fn bar(&self, len: u64, what: &str) -> ProgressBar {
        bar(len, what, self.quiet)
    }

    /// One progress line (`progress: MSG`) when progress is [`Progress::shown`].
    pub fn line(&self, msg: &str) {
        if self.shown() {
            eprintln!("progress: {msg}");
        }
    }

    /// [`Progress::line`], printed above `bar` (which is redrawn below it).
    pub fn line_above(&self, bar: &ProgressBar, msg: &str) {
        if self.shown() {
            bar.suspend(|| eprintln!("progress: {msg}"));
        }
    }

    /// A warning (`warning: MSG`) unless quiet.
    pub fn warn(&self, msg: &str) {
        if !self.quiet {
            eprintln!("warning: {msg}");
        }
    }

    /// A warning (`warning: MSG`) printed even when quiet: a loss the user must see (an
    /// optional output that could not be written).
    pub fn alert(&self, msg: &str) {
        eprintln!("warning: {msg}");
    }

    /// Text as it is (a table, a note) unless quiet.
    pub fn say(&self, text: &str) {
        if !self.quiet {
            eprintln!("{text}");
        }
    }
}

/// A bar of `len` steps labelled `what`, hidden when `quiet` or stderr is no terminal.
fn bar(len: u64, what: &str, quiet: bool) -> ProgressBar {
    if !shown(quiet) || !std::io::stderr().is_terminal() {
        return ProgressBar::with_draw_target(Some(len), ProgressDrawTarget::hidden());
    }
    let pb = ProgressBar::new(len);
    pb.set_style(
        ProgressStyle::with_template("{msg} [{bar:30}] {pos}/{len} ({eta} left)")
            .expect("static template")
            .progress_chars("=> "),
    );
    pb.set_message(what.to_owned());
    pb
}

/// Seconds as `0.4 s`, `12 s`, `3 min 05 s`.
pub fn seconds(s: f64) -> String {
    if !s.is_finite() || s < 0.0 {
        "?".into()
    } else if s < 10.0 {
        format!("{s:.1} s")
    } else if s < 60.0 {
        format!("{s:.0} s")
    } else {
        let m = (s / 60.0).floor();
        format!("{m:.0} min {:02.0} s", s - 60.0 * m)
    }
}
