//! [`Outputs::commit`]: every staged output put in place together, each the way its target
//! needs (streamed, renamed over, or rewritten in place).

use super::outputs::{flagged, open_stream, Entry, Kind, Outputs};
use super::signals::{lock, COMMIT, COMMITTED, LIVE_DIRS, MADE_DIRS};
use super::temp::forget;
use anyhow::{bail, Result};
use std::fs::OpenOptions;
use std::io::{Read, Seek, Write};
use std::os::unix::fs::MetadataExt;
use std::path::PathBuf;

impl Outputs {
    /// Put every output in place. A failure before the first output is changed leaves all as
    /// they were; the message says which were written and which were kept otherwise.
    pub fn commit(mut self) -> Result<()> {
        let _commit = lock(&COMMIT);
        let mut entries: Vec<Entry> = self.entries.iter_mut().filter_map(Option::take).collect();
        sync_staged(&mut entries)?;
        reserve_in_place(&mut entries)?;
        place(entries)?;
        // the directories made for the outputs are theirs now
        let mut made = lock(&MADE_DIRS);
        made.retain(|d| !self.made_dirs.contains(d));
        self.made_dirs.clear();
        Ok(())
    }
}

/// Step 1 of a commit: every staged file complete on disk (a full disk shows here, before any
/// change). On failure the staged files are removed.
fn sync_staged(entries: &mut Vec<Entry>) -> Result<()> {
    for i in 0..entries.len() {
        let e = &mut entries[i];
        if let Err(err) = e.file.flush().and_then(|_| e.file.sync_all()) {
            let msg = format!(
                "{}: cannot write output: {err}; no output was changed",
                flagged(&e.flag, &e.shown)
            );
            give_up(entries);
            bail!(msg);
        }
    }
    Ok(())
}

/// Step 2 of a commit: space for the in-place rewrites reserved before anything changes. On
/// failure the staged files are removed.
fn reserve_in_place(entries: &mut Vec<Entry>) -> Result<()> {
    for i in 0..entries.len() {
        if entries[i].kind == Kind::InPlace {
            if let Err(err) = reserve(&entries[i]) {
                let e = &entries[i];
                let msg = format!(
                    "{}: cannot write output: {err}; no output was changed",
                    flagged(&e.flag, &e.shown)
                );
                give_up(entries);
                bail!(msg);
            }
        }
    }
    Ok(())
}

/// Step 3 of a commit: streams, then renames, then the in-place rewrites, each output noted as
/// committed (for the signal handler) once in place. On failure the staged files left are
/// removed, and the message says which outputs were written and which were kept.
fn place(mut entries: Vec<Entry>) -> Result<()> {
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
    Ok(())
}

/// Remove the staged files of `entries` (after a failed commit).
fn give_up(entries: &mut Vec<Entry>) {
    for e in entries.drain(..) {
        let _ = std::fs::remove_file(&e.temp);
        forget(&e.temp);
    }
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
