//! What this process has live (temporary files, staging directories, directories made for
//! outputs, outputs committed), kept for its SIGINT/SIGTERM handler, and the handler itself.

use std::io::Write;
use std::path::PathBuf;
use std::sync::Mutex;

/// Temporary files of this process not yet committed or dropped (for the signal handler).
pub(super) static LIVE: Mutex<Vec<PathBuf>> = Mutex::new(Vec::new());
/// Staging directories of this process (for the signal handler).
pub(super) static LIVE_DIRS: Mutex<Vec<PathBuf>> = Mutex::new(Vec::new());
/// Directories this process created for outputs not yet committed (removed again if empty).
pub(super) static MADE_DIRS: Mutex<Vec<PathBuf>> = Mutex::new(Vec::new());
/// Held while outputs are being put in place: the signal handler waits for it.
pub(super) static COMMIT: Mutex<()> = Mutex::new(());
/// Outputs this process has put in place (for the signal handler's message).
pub(super) static COMMITTED: Mutex<Vec<PathBuf>> = Mutex::new(Vec::new());
/// What the signal handler writes before it exits (a run's finished part), if anything.
type InterruptHook = Box<dyn FnMut() + Send>;
static ON_INTERRUPT: Mutex<Option<InterruptHook>> = Mutex::new(None);

/// On SIGINT or SIGTERM, run `hook` (it writes what the run has finished, through its own
/// [`Outputs`]) before the cleanup and exit 130. Replaces any earlier hook.
pub fn set_interrupt_hook(hook: Box<dyn FnMut() + Send>) {
    *lock(&ON_INTERRUPT) = Some(hook);
}

/// No hook any more: the run goes on to write its real outputs. If the handler is running the
/// hook already, this waits for it (and the process then exits), so a partial output never
/// replaces the finished one.
pub fn clear_interrupt_hook() {
    lock(&ON_INTERRUPT).take();
}

pub(super) fn lock<T>(m: &Mutex<T>) -> std::sync::MutexGuard<'_, T> {
    m.lock().unwrap_or_else(|p| p.into_inner())
}

/// Remove this run's temporary files on SIGINT and SIGTERM, then exit with 130 (interrupted).
/// Call once, early in `main`.
pub fn install_signal_cleanup() {
    let _ = ctrlc::set_handler(|| {
        // what the run finished, written first; held until the exit, so the run cannot clear
        // it and commit its own outputs over the partial ones meanwhile
        let mut hook = lock(&ON_INTERRUPT);
        if let Some(h) = hook.as_mut() {
            h();
        }
        // a stream waiting on a full pipe, a wait on a FIFO input, stop now; nothing new is
        // made from here on (what the run finished is written above)
        crate::load::input::note_interrupt();
        // a commit in progress finishes first: outputs are all old or all new
        let _commit = lock(&COMMIT);
        remove_live_temporaries();
        let done = lock(&COMMITTED);
        let msg = if done.is_empty() {
            "\ninterrupted: no output was written".to_string()
        } else {
            format!(
                "\ninterrupted after the outputs were written: {}",
                done.iter()
                    .map(|p| p.display().to_string())
                    .collect::<Vec<_>>()
                    .join(", ")
            )
        };
        let _ = writeln!(std::io::stderr(), "{msg}");
        std::process::exit(130);
    });
}

fn remove_live_temporaries() {
    for p in lock(&LIVE).iter() {
        let _ = std::fs::remove_file(p);
    }
    for p in lock(&LIVE_DIRS).iter() {
        // the run may still be writing a file into it (it makes no new one once interrupted):
        // try again until it is gone
        for _ in 0..100 {
            match std::fs::remove_dir_all(p) {
                Err(e) if e.kind() != std::io::ErrorKind::NotFound => {
                    std::thread::sleep(std::time::Duration::from_millis(10))
                }
                _ => break,
            }
        }
    }
    for p in lock(&MADE_DIRS).iter().rev() {
        let _ = std::fs::remove_dir(p);
    }
}
