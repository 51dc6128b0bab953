//! Temporary files and staging directories: fresh names, registered for the signal handler
//! before they exist, and those left by a killed run swept once its process is gone.

use super::signals::{lock, LIVE, LIVE_DIRS};
use anyhow::{anyhow, bail, Result};
use std::fs::{File, OpenOptions};
use std::path::{Path, PathBuf};

const PREFIX: &str = ".fibrefit-";
const SUFFIX: &str = ".tmp";

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
pub(super) fn sweep_stale(dir: &Path) {
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
pub(super) fn new_temp(dir: &Path) -> std::io::Result<(PathBuf, File)> {
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

pub(super) fn forget(temp: &Path) {
    lock(&LIVE).retain(|p| p != temp);
}
