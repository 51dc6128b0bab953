//! Safe file output: every file a command writes goes through one checked writer, [`Outputs`].
//!
//! - One rule for every output (result JSON, report plots, maps, AOVs, previews, shaders): each
//!   is reserved before the work ([`Outputs::file`]), which checks where it goes, and staged in a
//!   temporary file; [`Outputs::commit`] puts all of a run's outputs in place together at its
//!   end. A failure or a signal at any point before leaves every old output as it was; a failure
//!   during the commit says which outputs were written and which were kept.
//! - Never over an input, never two outputs on one file: file identity (device and inode; for a
//!   file not there yet, its canonical path) is compared, so no spelling of a path, symlink or
//!   hard link lets an output replace a file the run reads or another output of the same run.
//! - Through links: a symlinked target is written at the link's target (the link stays); a
//!   target with other hard links is rewritten in place after the new content is complete and
//!   its space is reserved (`fallocate`), so every link sees it and a full disk leaves it whole.
//! - Special files are never replaced: a FIFO or character device (`/dev/null`, `/dev/stdout`)
//!   is written as a stream, at the commit; a block device or socket is refused.
//! - Signals: SIGINT and SIGTERM remove the run's temporary files and exit 130; a signal during
//!   the commit waits for it to finish, so the outputs are all old or all new, and the message
//!   says which. A run may register what it has finished so far ([`set_interrupt_hook`]: an
//!   interrupted `fit --model auto` writes its finished rungs, marked partial); the hook runs
//!   first, its own outputs committed the same way. Files left by a run killed with SIGKILL (`.fibrefit-<pid>-<random>.tmp`) are
//!   removed by the next run that writes into the same directory, once their process is gone.
//! - Permissions a user expects: a new file gets 0666 less the umask; an existing file keeps its
//!   mode, and its owner and group where the process may set them.
//! - Every I/O error names the file.
//!
//! The parts: `outputs` reserves and stages (the checks above), `commit` puts the staged outputs
//! in place, `temp` names and sweeps the temporary files and staging directories, `signals`
//! keeps what the process has live for its SIGINT/SIGTERM handler, and `single` writes one file
//! on its own ([`AtomicFile`], [`Sink`]).

mod commit;
mod outputs;
mod signals;
mod single;
mod temp;
#[cfg(test)]
mod tests;

#[cfg_attr(not(feature = "internals"), allow(unused_imports))] // for the tests and benchmarks
pub use outputs::{named, Named, OutputId, Outputs};
pub use signals::{clear_interrupt_hook, install_signal_cleanup, set_interrupt_hook};
#[cfg_attr(not(feature = "internals"), allow(unused_imports))] // for the tests and benchmarks
pub use single::{AtomicFile, Sink, WriteSeek};
pub use temp::Staging;
