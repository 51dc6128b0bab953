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

use anyhow::{anyhow, bail, Context, Result};
use std::fs::{File, OpenOptions};
use std::io::{Read, Seek, Write};
use std::os::unix::fs::{FileTypeExt, MetadataExt};
use std::path::{Path, PathBuf};
use std::sync::Mutex;

/// Temporary files of this process not yet committed or dropped (for the signal handler).
static LIVE: Mutex<Vec<PathBuf>> = Mutex::new(Vec::new());
/// Staging directories of this process (for the signal handler).
static LIVE_DIRS: Mutex<Vec<PathBuf>> = Mutex::new(Vec::new());
/// Directories this process created for outputs not yet committed (removed again if empty).
static MADE_DIRS: Mutex<Vec<PathBuf>> = Mutex::new(Vec::new());
/// Held while outputs are being put in place: the signal handler waits for it.
static COMMIT: Mutex<()> = Mutex::new(());
/// Outputs this process has put in place (for the signal handler's message).
static COMMITTED: Mutex<Vec<PathBuf>> = Mutex::new(Vec::new());
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

const PREFIX: &str = ".fibrefit-";
const SUFFIX: &str = ".tmp";

fn lock<T>(m: &Mutex<T>) -> std::sync::MutexGuard<'_, T> {
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

/// A staging directory `.fibrefit-<what>-<pid>-<random>` in `parent`: removed on drop, on
/// SIGINT/SIGTERM, and (after SIGKILL) by the next staging in the same place once its process is
/// gone.
pub struct Staging {
    path: PathBuf,
}

impl Staging {
    pub fn new(parent: &Path, what: &str) -> Result<Self> {
        let prefix = format!("{PREFIX}{what}-");
        if let Ok(entries) = std::fs::read_dir(parent) {
            for e in entries.flatten() {
                let name = e.file_name();
                let Some(rest) = name.to_str().and_then(|n| n.strip_prefix(&prefix)) else {
                    continue;
                };
                let pid = rest.split('-').next().and_then(|p| p.parse::<u32>().ok());
                if let Some(pid) = pid {
                    if e.file_type().is_ok_and(|t| t.is_dir())
                        && pid != std::process::id()
                        && !pid_alive(pid)
                    {
                        let _ = std::fs::remove_dir_all(e.path());
                    }
                }
            }
        }
        let path = parent.join(format!(
            "{prefix}{}-{:012x}",
            std::process::id(),
            temp_nonce() & 0xffff_ffff_ffff
        ));
        if crate::load::input::interrupted() {
            bail!(
                "{}: {}",
                parent.display(),
                crate::load::input::INTERRUPTED_MESSAGE
            );
        }
        lock(&LIVE_DIRS).push(path.clone());
        if let Err(e) = std::fs::create_dir(&path) {
            lock(&LIVE_DIRS).retain(|x| *x != path);
            return Err(anyhow!(
                "{}: cannot create a staging directory: {e}",
                parent.display()
            ));
        }
        Ok(Self { path })
    }

    pub fn path(&self) -> &Path {
        &self.path
    }
}

impl Drop for Staging {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.path);
        lock(&LIVE_DIRS).retain(|x| *x != self.path);
    }
}

/// The file a write to `path` should change: a symlink's final target (the link stays a link).
fn resolve(path: &Path) -> Result<PathBuf> {
    let mut p = path.to_path_buf();
    for _ in 0..40 {
        match std::fs::symlink_metadata(&p) {
            Ok(m) if m.file_type().is_symlink() => {
                let t = std::fs::read_link(&p)
                    .with_context(|| format!("{}: cannot read the link", p.display()))?;
                p = match p.parent() {
                    Some(dir) if t.is_relative() => dir.join(t),
                    _ => t,
                };
            }
            _ => return Ok(p),
        }
    }
    bail!("{}: too many levels of symbolic links", path.display())
}

/// The directory holding `path` ("." for a bare name).
fn parent_of(path: &Path) -> PathBuf {
    match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
        _ => PathBuf::from("."),
    }
}

/// A fresh number for a temporary name: time, a counter and the pid, mixed (splitmix64).
fn temp_nonce() -> u64 {
    use std::sync::atomic::{AtomicU64, Ordering};
    static COUNTER: AtomicU64 = AtomicU64::new(0);
    let t = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_nanos() as u64);
    let mut z = t ^ (COUNTER.fetch_add(1, Ordering::Relaxed) << 32) ^ std::process::id() as u64;
    z = z.wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

fn pid_alive(pid: u32) -> bool {
    Path::new(&format!("/proc/{pid}")).exists()
}

/// Remove `.fibrefit-<pid>-<random>.tmp` regular files in `dir` whose process is gone.
fn sweep_stale(dir: &Path) {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return;
    };
    for e in entries.flatten() {
        let name = e.file_name();
        let Some(name) = name.to_str() else { continue };
        let Some(mid) = name
            .strip_prefix(PREFIX)
            .and_then(|r| r.strip_suffix(SUFFIX))
        else {
            continue;
        };
        let Some((pid, rand)) = mid.split_once('-') else {
            continue;
        };
        let (Ok(pid), true) = (
            pid.parse::<u32>(),
            rand.len() == 12 && rand.bytes().all(|b| b.is_ascii_hexdigit()),
        ) else {
            continue;
        };
        let regular = e.file_type().is_ok_and(|t| t.is_file());
        if regular && pid != std::process::id() && !pid_alive(pid) {
            let _ = std::fs::remove_file(e.path());
        }
    }
}

/// A new temporary file `.fibrefit-<pid>-<random>.tmp` in `dir`, registered for the signal
/// handler before it exists.
fn new_temp(dir: &Path) -> std::io::Result<(PathBuf, File)> {
    // once a signal came, nothing new is made (its handler is removing what there is)
    if crate::load::input::interrupted() {
        return Err(std::io::Error::other(
            crate::load::input::INTERRUPTED_MESSAGE,
        ));
    }
    let mut last = None;
    for _ in 0..16 {
        let temp = dir.join(format!(
            "{PREFIX}{}-{:012x}{SUFFIX}",
            std::process::id(),
            temp_nonce() & 0xffff_ffff_ffff
        ));
        lock(&LIVE).push(temp.clone());
        match OpenOptions::new()
            .write(true)
            .read(true)
            .create_new(true)
            .open(&temp)
        {
            Ok(f) => return Ok((temp, f)),
            Err(e) => {
                forget(&temp);
                if e.kind() != std::io::ErrorKind::AlreadyExists {
                    return Err(e);
                }
                last = Some(e);
            }
        }
    }
    Err(last.unwrap_or_else(|| std::io::Error::other("no free temporary name")))
}

fn forget(temp: &Path) {
    lock(&LIVE).retain(|p| p != temp);
}

/// The same I/O error with the file's name in front (its kind kept: a closed pipe stays one).
pub fn named(name: &Path, e: std::io::Error) -> std::io::Error {
    std::io::Error::new(e.kind(), format!("{}: {e}", name.display()))
}

/// A writer whose errors name the file.
pub struct Named<'a> {
    file: &'a mut File,
    name: &'a Path,
}

impl Write for Named<'_> {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        self.file.write(buf).map_err(|e| named(self.name, e))
    }
    fn flush(&mut self) -> std::io::Result<()> {
        self.file.flush().map_err(|e| named(self.name, e))
    }
}

impl Seek for Named<'_> {
    fn seek(&mut self, pos: std::io::SeekFrom) -> std::io::Result<u64> {
        self.file.seek(pos).map_err(|e| named(self.name, e))
    }
}

/// How a staged output reaches its target.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Kind {
    /// A new file, or an existing one with one name: the staged file is renamed over it.
    Replace,
    /// An existing file with other hard links: rewritten in place, space reserved first.
    InPlace,
    /// A FIFO or character device: the content is streamed into it.
    Stream,
}

struct Entry {
    /// As the user gave it (messages).
    shown: PathBuf,
    /// The file a write changes (symlinks resolved).
    target: PathBuf,
    /// Canonical spelling of the target (for outputs that do not exist yet).
    key: PathBuf,
    /// Device and inode of an existing target.
    identity: Option<(u64, u64)>,
    flag: String,
    temp: PathBuf,
    file: File,
    kind: Kind,
    /// A FIFO or device, opened non-blocking when it was reserved.
    stream: Option<File>,
}

/// Handle of one reserved output of an [`Outputs`] set.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct OutputId(usize);

/// The outputs of one run: reserved (checked) before the work, staged, committed together.
/// Dropped without [`Outputs::commit`], nothing is changed (directories it created for the
/// outputs are removed again when empty).
pub struct Outputs {
    inputs: Vec<((u64, u64), PathBuf)>,
    entries: Vec<Option<Entry>>,
    made_dirs: Vec<PathBuf>,
}

fn flagged(flag: &str, path: &Path) -> String {
    if flag.is_empty() {
        path.display().to_string()
    } else {
        format!("{flag} {}", path.display())
    }
}

impl Outputs {
    /// A set whose outputs may not be any of `inputs` (by identity: links and hard links too).
    pub fn new(inputs: &[PathBuf]) -> Self {
        let inputs = inputs
            .iter()
            .filter_map(|p| {
                std::fs::metadata(p)
                    .ok()
                    .map(|m| ((m.dev(), m.ino()), p.clone()))
            })
            .collect();
        Self {
            inputs,
            entries: Vec::new(),
            made_dirs: Vec::new(),
        }
    }

    /// Also refuse outputs that are `path` (read by the run after the set was made).
    pub fn add_input(&mut self, path: &Path) {
        if let Ok(m) = std::fs::metadata(path) {
            self.inputs.push(((m.dev(), m.ino()), path.to_path_buf()));
        }
    }

    /// Make sure `dir` is a directory the outputs can go into: created (with its missing
    /// parents) if it does not exist, and removed again if the run writes nothing into it.
    /// Returns the directory itself (a symlink followed; the link stays).
    pub fn dir(&mut self, dir: &Path, flag: &str) -> Result<PathBuf> {
        let dir = resolve(dir)?;
        match std::fs::metadata(&dir) {
            Ok(m) if m.is_dir() => return Ok(dir),
            Ok(_) => bail!("{}: exists and is not a directory", flagged(flag, &dir)),
            Err(_) => {}
        }
        let mut missing = vec![];
        let mut up = Some(dir.as_path());
        while let Some(p) = up {
            if p.as_os_str().is_empty() {
                break;
            }
            if std::fs::symlink_metadata(p).is_ok() {
                if !p.is_dir() {
                    bail!(
                        "{}: {} is not a directory",
                        flagged(flag, &dir),
                        p.display()
                    );
                }
                break;
            }
            missing.push(p.to_path_buf());
            up = p.parent();
        }
        for p in missing.into_iter().rev() {
            lock(&MADE_DIRS).push(p.clone());
            match std::fs::create_dir(&p) {
                Ok(()) => self.made_dirs.push(p),
                Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists && p.is_dir() => {
                    lock(&MADE_DIRS).retain(|x| *x != p);
                }
                Err(e) => {
                    lock(&MADE_DIRS).retain(|x| *x != p);
                    bail!(
                        "{}: cannot create the directory {}: {e}",
                        flagged(flag, &dir),
                        p.display()
                    );
                }
            }
        }
        Ok(dir)
    }

    /// Reserve the output `path` (`flag`: the option that named it, for messages): refused when
    /// it is an input, another output of this run, a directory, a block device or a socket;
    /// its directory must exist and be writable. Returns the handle to write it through.
    pub fn file(&mut self, path: &Path, flag: &str) -> Result<OutputId> {
        let shown = path.to_path_buf();
        use std::os::unix::ffi::OsStrExt;
        let bytes = path.as_os_str().as_bytes();
        if bytes.is_empty() || bytes.ends_with(b"/") || path.file_name().is_none() {
            bail!(
                "{}: names a directory, expected a file path",
                flagged(flag, path)
            );
        }
        let target = resolve(path)?;
        let meta = std::fs::metadata(&target).ok();
        let (kind, identity) = match &meta {
            None => (Kind::Replace, None),
            Some(m) => {
                let t = m.file_type();
                let kind = if m.is_dir() {
                    bail!(
                        "{}: is a directory, expected a file path",
                        flagged(flag, path)
                    )
                } else if t.is_fifo() || t.is_char_device() {
                    Kind::Stream
                } else if t.is_block_device() || t.is_socket() {
                    bail!(
                        "{}: is a {}; refusing to write an output there",
                        flagged(flag, path),
                        if t.is_socket() {
                            "socket"
                        } else {
                            "block device"
                        }
                    )
                } else if m.nlink() > 1 {
                    Kind::InPlace
                } else {
                    Kind::Replace
                };
                (kind, Some((m.dev(), m.ino())))
            }
        };
        let dir = parent_of(&target);
        let key = std::fs::canonicalize(&dir)
            .unwrap_or_else(|_| dir.clone())
            .join(target.file_name().unwrap_or_default());
        if let Some(id) = identity {
            if let Some((_, input)) = self.inputs.iter().find(|(i, _)| *i == id) {
                bail!(
                    "{}: is an input of this run ({}); refusing to overwrite it",
                    flagged(flag, path),
                    input.display()
                );
            }
        }
        if kind != Kind::Stream {
            for other in self.entries.iter().flatten() {
                let same = other.key == key || (identity.is_some() && other.identity == identity);
                if same {
                    bail!(
                        "{}: is also the output {} of this run; give the outputs different files",
                        flagged(flag, path),
                        flagged(&other.flag, &other.shown)
                    );
                }
            }
        }
        // a FIFO or device is opened now, without blocking: a FIFO with no reader is refused
        // before the work (a run never waits for one, nor hangs in its commit)
        let stream = match kind {
            Kind::Stream => Some(open_stream(&target).map_err(|e| {
                if e.raw_os_error() == Some(libc::ENXIO) {
                    anyhow!(
                        "{}: is a FIFO with no reader; start the program that reads it first (fibrefit does not wait for one)",
                        flagged(flag, path)
                    )
                } else {
                    anyhow!("{}: cannot open for writing: {e}", flagged(flag, path))
                }
            })?),
            _ => None,
        };
        let stage_dir = match kind {
            Kind::Stream => std::env::temp_dir(),
            _ => dir.clone(),
        };
        if kind != Kind::Stream {
            if !stage_dir.is_dir() {
                bail!(
                    "{}: cannot create output: directory {} does not exist",
                    flagged(flag, path),
                    stage_dir.display()
                );
            }
            sweep_stale(&stage_dir);
        }
        let (temp, file) = new_temp(&stage_dir).map_err(|e| {
            anyhow!(
                "{}: cannot create output (directory {} not writable or missing): {e}",
                flagged(flag, path),
                stage_dir.display()
            )
        })?;
        self.entries.push(Some(Entry {
            shown,
            target,
            key,
            identity,
            flag: flag.to_string(),
            temp,
            file,
            kind,
            stream,
        }));
        Ok(OutputId(self.entries.len() - 1))
    }

    fn entry(&mut self, id: OutputId) -> &mut Entry {
        self.entries[id.0]
            .as_mut()
            .expect("a discarded output is not written")
    }

    /// A writer for the output whose errors name it.
    pub fn writer(&mut self, id: OutputId) -> Named<'_> {
        let e = self.entry(id);
        Named {
            file: &mut e.file,
            name: &e.shown,
        }
    }

    /// The staged file itself (for encoders that seek), and the output's name for errors.
    pub fn file_and_name(&mut self, id: OutputId) -> (&mut File, &Path) {
        let e = self.entry(id);
        (&mut e.file, &e.shown)
    }

    /// The path the output was given as.
    pub fn name(&self, id: OutputId) -> &Path {
        &self.entries[id.0].as_ref().expect("not discarded").shown
    }

    /// Write `bytes` as the whole content of the output.
    pub fn put(&mut self, id: OutputId, bytes: &[u8]) -> Result<()> {
        self.writer(id).write_all(bytes)?;
        Ok(())
    }

    /// Give up one output: its old file stays as it was; the others are still committed.
    pub fn discard(&mut self, id: OutputId) {
        if let Some(e) = self.entries[id.0].take() {
            drop(e.file);
            let _ = std::fs::remove_file(&e.temp);
            forget(&e.temp);
        }
    }

    /// Put every output in place. A failure before the first output is changed leaves all as
    /// they were; the message says which were written and which were kept otherwise.
    pub fn commit(mut self) -> Result<()> {
        let _commit = lock(&COMMIT);
        let mut entries: Vec<Entry> = self.entries.iter_mut().filter_map(Option::take).collect();
        // 1. every staged file complete on disk (a full disk shows here, before any change)
        for i in 0..entries.len() {
            let e = &mut entries[i];
            if let Err(err) = e.file.flush().and_then(|_| e.file.sync_all()) {
                let msg = format!(
                    "{}: cannot write output: {err}; no output was changed",
                    flagged(&e.flag, &e.shown)
                );
                give_up(&mut entries);
                bail!(msg);
            }
        }
        // 2. space for the in-place rewrites reserved before anything changes
        for i in 0..entries.len() {
            if entries[i].kind == Kind::InPlace {
                if let Err(err) = reserve(&entries[i]) {
                    let e = &entries[i];
                    let msg = format!(
                        "{}: cannot write output: {err}; no output was changed",
                        flagged(&e.flag, &e.shown)
                    );
                    give_up(&mut entries);
                    bail!(msg);
                }
            }
        }
        // 3. streams, then renames, then the in-place rewrites
        entries.sort_by_key(|e| match e.kind {
            Kind::Stream => 0,
            Kind::Replace => 1,
            Kind::InPlace => 2,
        });
        let mut written: Vec<PathBuf> = vec![];
        for i in 0..entries.len() {
            let e = &mut entries[i];
            let result = match e.kind {
                Kind::Stream => stream(e),
                Kind::Replace => replace(e),
                Kind::InPlace => rewrite_in_place(e),
            };
            match result {
                Ok(()) => {
                    let _ = std::fs::remove_file(&e.temp);
                    forget(&e.temp);
                    written.push(e.shown.clone());
                    // a file put into a staging directory is not yet an output
                    if !lock(&LIVE_DIRS).iter().any(|d| e.target.starts_with(d)) {
                        lock(&COMMITTED).push(e.shown.clone());
                    }
                }
                Err(err) => {
                    let what = flagged(&e.flag, &e.shown);
                    let kept: Vec<String> = entries[i + 1..]
                        .iter()
                        .map(|e| e.shown.display().to_string())
                        .collect();
                    give_up(&mut entries);
                    bail!(
                        "{what}: cannot write output: {err}; {}{}",
                        if written.is_empty() {
                            "no other output was written".to_string()
                        } else {
                            format!(
                                "written: {}",
                                written
                                    .iter()
                                    .map(|p| p.display().to_string())
                                    .collect::<Vec<_>>()
                                    .join(", ")
                            )
                        },
                        if kept.is_empty() {
                            String::new()
                        } else {
                            format!("; kept as they were: {}", kept.join(", "))
                        }
                    );
                }
            }
        }
        // the directories made for the outputs are theirs now
        let mut made = lock(&MADE_DIRS);
        made.retain(|d| !self.made_dirs.contains(d));
        self.made_dirs.clear();
        Ok(())
    }
}

/// Remove the staged files of `entries` (after a failed commit).
fn give_up(entries: &mut Vec<Entry>) {
    for e in entries.drain(..) {
        let _ = std::fs::remove_file(&e.temp);
        forget(&e.temp);
    }
}

impl Drop for Outputs {
    fn drop(&mut self) {
        for e in self.entries.iter_mut().filter_map(Option::take) {
            let _ = std::fs::remove_file(&e.temp);
            forget(&e.temp);
        }
        for d in self.made_dirs.iter().rev() {
            let _ = std::fs::remove_dir(d);
        }
        let mut made = lock(&MADE_DIRS);
        made.retain(|d| !self.made_dirs.contains(d));
    }
}

/// Open a FIFO or character device for writing without blocking (a FIFO with no reader fails
/// with ENXIO instead of waiting for one).
fn open_stream(target: &Path) -> std::io::Result<File> {
    use std::os::unix::fs::OpenOptionsExt;
    OpenOptions::new()
        .write(true)
        .custom_flags(libc::O_NONBLOCK)
        .open(target)
}

/// Stream the staged content into a FIFO or character device (never replaced), opened when it
/// was reserved; a full pipe is waited on by polling, so a signal stops the wait.
fn stream(e: &mut Entry) -> std::io::Result<()> {
    use std::os::fd::AsRawFd;
    let mut dst = match e.stream.take() {
        Some(f) => f,
        None => open_stream(&e.target)?,
    };
    e.file.seek(std::io::SeekFrom::Start(0))?;
    let shown = e.shown.clone();
    let what = move || shown.display().to_string();
    let mut buf = vec![0u8; 1 << 16];
    loop {
        let n = match e.file.read(&mut buf) {
            Ok(0) => return Ok(()),
            Ok(n) => n,
            Err(err) if err.kind() == std::io::ErrorKind::Interrupted => continue,
            Err(err) => return Err(err),
        };
        let mut at = 0;
        while at < n {
            match dst.write(&buf[at..n]) {
                Ok(0) => return Err(std::io::ErrorKind::WriteZero.into()),
                Ok(k) => at += k,
                Err(err) if err.kind() == std::io::ErrorKind::WouldBlock => {
                    crate::load::input::wait_ready(dst.as_raw_fd(), libc::POLLOUT, None, &what)?
                }
                Err(err) if err.kind() == std::io::ErrorKind::Interrupted => {}
                Err(err) => return Err(err),
            }
        }
    }
}

/// Rename the staged file over the target; an existing file keeps its mode, owner and group.
fn replace(e: &mut Entry) -> std::io::Result<()> {
    if let Ok(old) = std::fs::metadata(&e.target) {
        let _ = e.file.set_permissions(old.permissions());
        let _ = std::os::unix::fs::fchown(&e.file, Some(old.uid()), Some(old.gid()));
    }
    std::fs::rename(&e.temp, &e.target)
}

/// Reserve the blocks an in-place rewrite of a hard-linked target needs, without changing it.
fn reserve(e: &Entry) -> std::io::Result<()> {
    use std::os::fd::AsRawFd;
    let len = e.file.metadata()?.len();
    let dst = OpenOptions::new().write(true).open(&e.target)?;
    // SAFETY: a valid open descriptor; KEEP_SIZE changes neither the content nor the size
    let r = unsafe {
        libc::fallocate(
            dst.as_raw_fd(),
            libc::FALLOC_FL_KEEP_SIZE,
            0,
            len as libc::off_t,
        )
    };
    if r == 0 {
        return Ok(());
    }
    let err = std::io::Error::last_os_error();
    if err.raw_os_error() != Some(libc::EOPNOTSUPP) {
        return Err(err);
    }
    // no fallocate here: the free space must hold what the new content adds
    let old = dst.metadata()?.len();
    let mut st: libc::statvfs = unsafe { std::mem::zeroed() };
    // SAFETY: a valid descriptor and a zeroed out-parameter
    if unsafe { libc::fstatvfs(dst.as_raw_fd(), &mut st) } == 0 {
        let free = st.f_bavail as u64 * st.f_frsize as u64;
        if len.saturating_sub(old) > free {
            return Err(std::io::Error::from_raw_os_error(libc::ENOSPC));
        }
    }
    Ok(())
}

/// Rewrite a hard-linked target in place (every name sees the new content).
fn rewrite_in_place(e: &mut Entry) -> std::io::Result<()> {
    let len = e.file.metadata()?.len();
    let mut dst = OpenOptions::new().write(true).open(&e.target)?;
    e.file.seek(std::io::SeekFrom::Start(0))?;
    let mut src = (&mut e.file).take(len);
    std::io::copy(&mut src, &mut dst)?;
    dst.set_len(len)?;
    dst.sync_all()
}

/// Where an encoded picture goes: a file of its own (written atomically), or a reserved output
/// of a run's [`Outputs`] set (committed with the others).
pub enum Sink<'a> {
    File(&'a Path),
    Staged(&'a mut Outputs, OutputId),
}

impl Sink<'_> {
    /// The output's name, for messages.
    pub fn name(&self) -> PathBuf {
        match self {
            Sink::File(p) => p.to_path_buf(),
            Sink::Staged(set, id) => set.name(*id).to_path_buf(),
        }
    }

    /// Write an RGB image as PNG.
    pub fn png(self, img: &image::RgbImage) -> Result<()> {
        let name = self.name();
        let encode = |w: &mut dyn WriteSeek| -> Result<()> {
            let mut b = std::io::BufWriter::new(w);
            img.write_to(&mut b, image::ImageFormat::Png)
                .map_err(|e| anyhow!("{}: cannot write PNG: {e}", name.display()))?;
            b.flush()
                .map_err(|e| anyhow!("{}: cannot write PNG: {e}", name.display()))
        };
        match self {
            Sink::File(p) => {
                let mut f = AtomicFile::create(p)?;
                encode(&mut f.writer())?;
                f.commit()
            }
            Sink::Staged(set, id) => encode(&mut set.writer(id)),
        }
    }
}

/// Write + Seek as one object type (PNG encoding).
pub trait WriteSeek: Write + Seek {}
impl<T: Write + Seek> WriteSeek for T {}

/// One output file on its own: an [`Outputs`] set of one. Created up front so an unwritable
/// destination fails before any work is done; dropped without commit, it vanishes.
pub struct AtomicFile {
    set: Outputs,
    id: OutputId,
}

impl AtomicFile {
    pub fn create(path: &Path) -> Result<Self> {
        let mut set = Outputs::new(&[]);
        let id = set.file(path, "")?;
        Ok(Self { set, id })
    }

    /// A writer whose errors name the file.
    pub fn writer(&mut self) -> Named<'_> {
        self.set.writer(self.id)
    }

    /// The temporary file itself, for encoders that seek.
    pub fn file(&mut self) -> &mut File {
        self.set.file_and_name(self.id).0
    }

    pub fn commit(self) -> Result<()> {
        self.set.commit()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::os::unix::fs::PermissionsExt;

    fn write(path: &Path, text: &str) -> Result<()> {
        let mut f = AtomicFile::create(path)?;
        f.writer().write_all(text.as_bytes())?;
        f.commit()
    }

    /// The process umask (Linux: /proc/self/status), which a new file's mode must respect.
    fn umask() -> u32 {
        let status = std::fs::read_to_string("/proc/self/status").unwrap();
        let line = status.lines().find(|l| l.starts_with("Umask:")).unwrap();
        u32::from_str_radix(line["Umask:".len()..].trim(), 8).unwrap()
    }

    #[test]
    fn links_modes_and_leftovers() {
        let dir = tempfile::tempdir().unwrap();
        let d = dir.path();
        // a symlink stays a link; its target gets the content
        std::fs::write(d.join("real.json"), "old").unwrap();
        std::os::unix::fs::symlink("real.json", d.join("link.json")).unwrap();
        write(&d.join("link.json"), "new").unwrap();
        assert!(std::fs::symlink_metadata(d.join("link.json"))
            .unwrap()
            .file_type()
            .is_symlink());
        assert_eq!(std::fs::read_to_string(d.join("real.json")).unwrap(), "new");
        // hard links all see the new content
        std::fs::hard_link(d.join("real.json"), d.join("hard.json")).unwrap();
        write(&d.join("real.json"), "newer").unwrap();
        assert_eq!(
            std::fs::read_to_string(d.join("hard.json")).unwrap(),
            "newer"
        );
        // an existing file keeps its mode
        std::fs::write(d.join("m.csv"), "x").unwrap();
        std::fs::set_permissions(d.join("m.csv"), std::fs::Permissions::from_mode(0o640)).unwrap();
        write(&d.join("m.csv"), "y").unwrap();
        let mode = std::fs::metadata(d.join("m.csv"))
            .unwrap()
            .permissions()
            .mode();
        assert_eq!(mode & 0o777, 0o640);
        // a new file is 0666 less the umask (not 0600 whatever the umask)
        write(&d.join("new.csv"), "z").unwrap();
        let mode = std::fs::metadata(d.join("new.csv"))
            .unwrap()
            .permissions()
            .mode()
            & 0o777;
        assert_eq!(mode, 0o666 & !umask(), "mode {mode:o}");
        // a stale temporary of a dead process is swept; one of ours and foreign names are not
        let stale = d.join(".fibrefit-999999999-0123456789ab.tmp");
        let foreign = d.join(".fibrefit-notours.tmp");
        std::fs::write(&stale, "").unwrap();
        std::fs::write(&foreign, "").unwrap();
        write(&d.join("other.json"), "w").unwrap();
        assert!(!stale.exists());
        assert!(foreign.exists());
        // dropped without commit: nothing left, target untouched
        {
            let mut f = AtomicFile::create(&d.join("m.csv")).unwrap();
            f.writer().write_all(b"half").unwrap();
        }
        assert_eq!(std::fs::read_to_string(d.join("m.csv")).unwrap(), "y");
        let left: Vec<_> = std::fs::read_dir(d)
            .unwrap()
            .flatten()
            .filter(|e| {
                let n = e.file_name();
                let n = n.to_string_lossy();
                n.starts_with(".fibrefit-") && n != ".fibrefit-notours.tmp"
            })
            .collect();
        assert!(left.is_empty(), "{left:?}");
    }

    #[test]
    fn an_input_is_never_an_output() {
        let dir = tempfile::tempdir().unwrap();
        let d = dir.path();
        std::fs::write(d.join("data.csv"), "x").unwrap();
        std::os::unix::fs::symlink("data.csv", d.join("alias.csv")).unwrap();
        std::fs::hard_link(d.join("data.csv"), d.join("hard.csv")).unwrap();
        let inputs = vec![d.join("data.csv")];
        for out in ["data.csv", "alias.csv", "hard.csv", "./data.csv"] {
            let e = Outputs::new(&inputs)
                .file(&d.join(out), "--out")
                .err()
                .unwrap();
            assert!(e.to_string().contains("is an input"), "{e}");
        }
        Outputs::new(&inputs)
            .file(&d.join("result.json"), "--out")
            .unwrap();
    }
}
