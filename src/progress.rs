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
pub fn shown(quiet: bool) -> bool {
    !quiet && forced().unwrap_or_else(|| std::io::stderr().is_terminal())
}

pub fn bar(len: u64, what: &str, quiet: bool) -> ProgressBar {
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

/// One progress line on stderr (`progress: MSG`) when progress is [`shown`].
pub fn line(quiet: bool, msg: &str) {
    if shown(quiet) {
        eprintln!("progress: {msg}");
    }
}

/// [`line`], printed above `bar` (which is redrawn below it).
pub fn line_above(bar: &ProgressBar, quiet: bool, msg: &str) {
    if shown(quiet) {
        bar.suspend(|| eprintln!("progress: {msg}"));
    }
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
