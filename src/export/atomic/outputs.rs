//! [`Outputs`], the outputs of one run: each reserved (checked) before the work and staged in a
//! temporary file, written through writers whose errors name the file.

use super::signals::{lock, MADE_DIRS};
use super::temp::{forget, new_temp, sweep_stale};
use anyhow::{anyhow, bail, Context, Result};
use std::fs::{File, OpenOptions};
use std::io::{Seek, Write};
use std::os::unix::fs::{FileTypeExt, MetadataExt};
use std::path::{Path, PathBuf};

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

/// Open a FIFO or character device for writing without blocking (a FIFO with no reader fails
/// with ENXIO instead of waiting for one).
pub(super) fn open_stream(target: &Path) -> std::io::Result<File> {
    use std::os::unix::fs::OpenOptionsExt;
    OpenOptions::new()
        .write(true)
        .custom_flags(libc::O_NONBLOCK)
        .open(target)
}

/// Open the FIFO or character device `target` of the output `what` at its reservation, without
/// blocking: a FIFO with no reader is refused.
fn open_reserved_stream(target: &Path, what: &str) -> Result<File> {
    open_stream(target).map_err(|e| {
        if e.raw_os_error() == Some(libc::ENXIO) {
            anyhow!(
                "{what}: is a FIFO with no reader; start the program that reads it first (fibrefit does not wait for one)"
            )
        } else {
            anyhow!("{what}: cannot open for writing: {e}")
        }
    })
}

/// The temporary file that stages the output `what` of `kind`: in its directory `dir` (which
/// must exist; old leftovers there are swept), a stream's in the system's temporary directory.
fn stage(what: &str, kind: Kind, dir: PathBuf) -> Result<(PathBuf, File)> {
    let stage_dir = match kind {
        Kind::Stream => std::env::temp_dir(),
        _ => dir,
    };
    if kind != Kind::Stream {
        if !stage_dir.is_dir() {
            bail!(
                "{what}: cannot create output: directory {} does not exist",
                stage_dir.display()
            );
        }
        sweep_stale(&stage_dir);
    }
    new_temp(&stage_dir).map_err(|e| {
        anyhow!(
            "{what}: cannot create output (directory {} not writable or missing): {e}",
            stage_dir.display()
        )
    })
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
pub(super) enum Kind {
    /// A new file, or an existing one with one name: the staged file is renamed over it.
    Replace,
    /// An existing file with other hard links: rewritten in place, space reserved first.
    InPlace,
    /// A FIFO or character device: the content is streamed into it.
    Stream,
}

impl Kind {
    /// How an output reaches the existing file `m` (`what`: the output, for messages): refused
    /// for a directory, a block device or a socket.
    fn of(m: &std::fs::Metadata, what: &str) -> Result<Self> {
        let t = m.file_type();
        Ok(if m.is_dir() {
            bail!("{what}: is a directory, expected a file path")
        } else if t.is_fifo() || t.is_char_device() {
            Kind::Stream
        } else if t.is_block_device() || t.is_socket() {
            bail!(
                "{what}: is a {}; refusing to write an output there",
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
        })
    }
}

/// One reserved output: where it goes, how, and the temporary file that stages it.
pub(super) struct Entry {
    /// As the user gave it (messages).
    pub(super) shown: PathBuf,
    /// The file a write changes (symlinks resolved).
    pub(super) target: PathBuf,
    /// Canonical spelling of the target (for outputs that do not exist yet).
    pub(super) key: PathBuf,
    /// Device and inode of an existing target.
    pub(super) identity: Option<(u64, u64)>,
    pub(super) flag: String,
    pub(super) temp: PathBuf,
    pub(super) file: File,
    pub(super) kind: Kind,
    /// A FIFO or device, opened non-blocking when it was reserved.
    pub(super) stream: Option<File>,
}

/// Handle of one reserved output of an [`Outputs`] set.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct OutputId(usize);

/// The outputs of one run: reserved (checked) before the work, staged, committed together.
/// Dropped without [`Outputs::commit`], nothing is changed (directories it created for the
/// outputs are removed again when empty).
pub struct Outputs {
    inputs: Vec<((u64, u64), PathBuf)>,
    /// The reserved outputs by [`OutputId`] (`None`: discarded, or taken by the commit).
    pub(super) entries: Vec<Option<Entry>>,
    /// Directories made for the outputs (removed again if the set is dropped uncommitted).
    pub(super) made_dirs: Vec<PathBuf>,
}

/// `path` as named by the option `flag`, for messages.
pub(super) fn flagged(flag: &str, path: &Path) -> String {
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
        let what = flagged(flag, path);
        use std::os::unix::ffi::OsStrExt;
        let bytes = path.as_os_str().as_bytes();
        if bytes.is_empty() || bytes.ends_with(b"/") || path.file_name().is_none() {
            bail!("{what}: names a directory, expected a file path");
        }
        let target = resolve(path)?;
        let (kind, identity) = match std::fs::metadata(&target) {
            Err(_) => (Kind::Replace, None),
            Ok(m) => (Kind::of(&m, &what)?, Some((m.dev(), m.ino()))),
        };
        let dir = parent_of(&target);
        let key = std::fs::canonicalize(&dir)
            .unwrap_or_else(|_| dir.clone())
            .join(target.file_name().unwrap_or_default());
        self.refuse_clash(&what, kind, &key, identity)?;
        // a FIFO or device is opened now, without blocking: a FIFO with no reader is refused
        // before the work (a run never waits for one, nor hangs in its commit)
        let stream = match kind {
            Kind::Stream => Some(open_reserved_stream(&target, &what)?),
            _ => None,
        };
        let (temp, file) = stage(&what, kind, dir)?;
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

    /// Refuse an output (`what`, of `kind`, at `key`, with `identity` if it exists) that is an
    /// input of the run or, unless a stream, another of its outputs.
    fn refuse_clash(
        &self,
        what: &str,
        kind: Kind,
        key: &Path,
        identity: Option<(u64, u64)>,
    ) -> Result<()> {
        if let Some(id) = identity {
            if let Some((_, input)) = self.inputs.iter().find(|(i, _)| *i == id) {
                bail!(
                    "{what}: is an input of this run ({}); refusing to overwrite it",
                    input.display()
                );
            }
        }
        if kind != Kind::Stream {
            for other in self.entries.iter().flatten() {
                let same = other.key == key || (identity.is_some() && other.identity == identity);
                if same {
                    bail!(
                        "{what}: is also the output {} of this run; give the outputs different files",
                        flagged(&other.flag, &other.shown)
                    );
                }
            }
        }
        Ok(())
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
