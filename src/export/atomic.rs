//! Safe file output: write into a temporary file beside the target, then put it in place.
//!
//! - Atomic: the target changes only on [`AtomicFile::commit`]; a failed or interrupted run
//!   leaves it as it was. SIGINT and SIGTERM remove the temporary files of the run before the
//!   process ends ([`install_signal_cleanup`]); files left by a run killed with SIGKILL (named
//!   `.fibrefit-<pid>-<random>.tmp`) are removed by the next run that writes into the same
//!   directory, once their process is gone.
//! - Through links: a symlinked target is written at the link's target (the link stays); a
//!   target with other hard links is rewritten in place after the new content is complete, so
//!   every link sees it.
//! - Permissions a user expects: a new file gets 0666 less the umask (as any program's would);
//!   an existing file keeps its mode, and its owner and group where the process may set them.
//! - Never over an input: [`refuse_inputs`] compares file identity (device and inode), so no
//!   spelling of a path, link or hard link lets an output replace a file the run reads.

use anyhow::{bail, Context, Result};
use std::fs::{File, OpenOptions};
use std::io::Write;
use std::os::unix::fs::MetadataExt;
use std::path::{Path, PathBuf};
use std::sync::Mutex;

/// Temporary files of this process not yet committed or dropped (for the signal handler).
static LIVE: Mutex<Vec<PathBuf>> = Mutex::new(Vec::new());
/// Staging directories of this process (for the signal handler).
static LIVE_DIRS: Mutex<Vec<PathBuf>> = Mutex::new(Vec::new());

const PREFIX: &str = ".fibrefit-";
const SUFFIX: &str = ".tmp";

/// Remove this run's temporary files on SIGINT and SIGTERM, then exit with 130 (interrupted).
/// Call once, early in `main`.
pub fn install_signal_cleanup() {
    let _ = ctrlc::set_handler(|| {
        remove_live_temporaries();
        eprintln!("\ninterrupted: no output was written");
        std::process::exit(130);
    });
}

fn remove_live_temporaries() {
    if let Ok(live) = LIVE.lock() {
        for p in live.iter() {
            let _ = std::fs::remove_file(p);
        }
    }
    if let Ok(live) = LIVE_DIRS.lock() {
        for p in live.iter() {
            let _ = std::fs::remove_dir_all(p);
        }
    }
}

/// A staging directory `.fibrefit-<what>-<pid>-<random>` in `parent`: removed on drop, on
/// SIGINT/SIGTERM, and (after SIGKILL) by the next staging in the same place once its process is
/// gone. [`Staging::keep`] hands it over.
pub struct Staging {
    path: Option<PathBuf>,
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
        LIVE_DIRS.lock().expect("not poisoned").push(path.clone());
        std::fs::create_dir(&path)
            .with_context(|| format!("{}: cannot create a staging directory", parent.display()))?;
        Ok(Self { path: Some(path) })
    }

    pub fn path(&self) -> &Path {
        self.path.as_deref().expect("held until keep")
    }

    /// Stop managing the directory (it has been, or is about to be, moved into place).
    pub fn keep(mut self) -> PathBuf {
        let p = self.path.take().expect("held until keep");
        if let Ok(mut live) = LIVE_DIRS.lock() {
            live.retain(|x| *x != p);
        }
        p
    }
}

impl Drop for Staging {
    fn drop(&mut self) {
        if let Some(p) = self.path.take() {
            let _ = std::fs::remove_dir_all(&p);
            if let Ok(mut live) = LIVE_DIRS.lock() {
                live.retain(|x| *x != p);
            }
        }
    }
}

/// Refuse an output that is one of the inputs (or a link to one).
pub fn refuse_inputs(out: &Path, inputs: &[PathBuf], flag: &str) -> Result<()> {
    let Ok(o) = std::fs::metadata(out) else {
        return Ok(());
    };
    for input in inputs {
        if let Ok(i) = std::fs::metadata(input) {
            if (i.dev(), i.ino()) == (o.dev(), o.ino()) {
                bail!(
                    "{flag} {}: is an input of this run ({}); refusing to overwrite it",
                    out.display(),
                    input.display()
                );
            }
        }
    }
    Ok(())
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

/// A file that appears at `path` only when [`AtomicFile::commit`] is called. Created up front so
/// an unwritable destination fails before any work is done. Dropped without commit, it vanishes.
pub struct AtomicFile {
    target: PathBuf,
    temp_path: PathBuf,
    file: Option<File>,
}

impl AtomicFile {
    pub fn create(path: &Path) -> Result<Self> {
        let target = resolve(path)?;
        if target.is_dir() {
            bail!("{}: is a directory, expected a file path", path.display());
        }
        let dir = match target.parent() {
            Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
            _ => PathBuf::from("."),
        };
        sweep_stale(&dir);
        let mut last_err = None;
        for _ in 0..16 {
            let rand = temp_nonce();
            let temp_path = dir.join(format!(
                "{PREFIX}{}-{:012x}{SUFFIX}",
                std::process::id(),
                rand & 0xffff_ffff_ffff
            ));
            // registered before it exists, so a signal in between cannot leave it behind
            LIVE.lock().expect("not poisoned").push(temp_path.clone());
            match OpenOptions::new()
                .write(true)
                .create_new(true)
                .open(&temp_path)
            {
                Ok(file) => {
                    return Ok(Self {
                        target,
                        temp_path,
                        file: Some(file),
                    })
                }
                Err(e) => {
                    forget(&temp_path);
                    if e.kind() != std::io::ErrorKind::AlreadyExists {
                        last_err = Some(e);
                        break;
                    }
                }
            }
        }
        Err(anyhow::Error::new(last_err.unwrap_or_else(|| {
            std::io::Error::other("no free temporary name")
        })))
        .with_context(|| {
            format!(
                "{}: cannot create output (directory {} not writable or missing)",
                path.display(),
                dir.display()
            )
        })
    }

    pub fn writer(&mut self) -> &mut impl Write {
        self.file.as_mut().expect("open until commit")
    }

    /// The temporary file itself, for encoders that seek.
    pub fn file(&mut self) -> &mut File {
        self.file.as_mut().expect("open until commit")
    }

    pub fn commit(mut self) -> Result<()> {
        let mut file = self.file.take().expect("open until commit");
        let fail = |e: std::io::Error| {
            anyhow::anyhow!("{}: cannot write output: {e}", self.target.display())
        };
        file.flush().map_err(fail)?;
        file.sync_all().ok();
        match std::fs::metadata(&self.target) {
            Ok(old) if old.nlink() > 1 => {
                // hard links: every name must see the new content, so it goes into this inode
                drop(file);
                let mut src = File::open(&self.temp_path).map_err(fail)?;
                let mut dst = OpenOptions::new()
                    .write(true)
                    .truncate(true)
                    .open(&self.target)
                    .map_err(fail)?;
                std::io::copy(&mut src, &mut dst).map_err(fail)?;
                dst.sync_all().ok();
                let _ = std::fs::remove_file(&self.temp_path);
            }
            Ok(old) => {
                // an existing file keeps its mode, owner and group
                let _ = file.set_permissions(old.permissions());
                let _ = std::os::unix::fs::fchown(&file, Some(old.uid()), Some(old.gid()));
                drop(file);
                std::fs::rename(&self.temp_path, &self.target).map_err(fail)?;
            }
            Err(_) => {
                drop(file);
                std::fs::rename(&self.temp_path, &self.target).map_err(fail)?;
            }
        }
        forget(&self.temp_path);
        Ok(())
    }
}

fn forget(temp: &Path) {
    if let Ok(mut live) = LIVE.lock() {
        live.retain(|p| p != temp);
    }
}

impl Drop for AtomicFile {
    fn drop(&mut self) {
        if self.file.is_some() {
            let _ = std::fs::remove_file(&self.temp_path);
            forget(&self.temp_path);
        }
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
            let e = refuse_inputs(&d.join(out), &inputs, "--out").unwrap_err();
            assert!(e.to_string().contains("is an input"), "{e}");
        }
        refuse_inputs(&d.join("result.json"), &inputs, "--out").unwrap();
    }
}
