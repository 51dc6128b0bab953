//! Reading an input file: once, with a byte limit, hashed as it is read, and checked not to have
//! changed while it was read.
//!
//! Every loader reads its file through [`open`] (streamed: [`Input`] is a [`Read`]) or
//! [`read_input`] (into memory). Either way:
//! - a regular file larger than the limit is refused before any byte is read; anything else
//!   (a character device such as `/dev/zero`, a FIFO, a link to one) is read up to the limit and
//!   refused beyond it, so no input can make a loader read without end;
//! - the SHA-256 is taken of the very bytes the loader parsed, and recorded for this process:
//!   [`sha256_read`] gives it to whoever records where a result came from;
//! - a regular file whose size, modification or change time, or inode differ between the start
//!   and the end of the read (or that gave fewer or more bytes than its size said) is an error
//!   naming the file: it was written while this run read it, and what was read may be torn.
//!
//! A directory is refused. A FIFO or device is opened without blocking and read by polling, so
//! that a signal ([`interrupted`]: SIGINT/SIGTERM in the CLI, Ctrl-C in Python) stops the
//! wait at once, and an input that gives no byte for [`SPECIAL_WAIT`] (a FIFO nobody writes)
//! is an error naming it.

use anyhow::{anyhow, bail, Result};
use sha2::{Digest, Sha256};
use std::collections::HashMap;
use std::io::Read;
use std::path::{Path, PathBuf};
use std::sync::{Mutex, OnceLock};

/// The largest input file of any kind (goniometric CSV, query CSV, image, mesh): 4 GiB. A regular
/// file above it is refused unread; a device or FIFO is read up to it and refused beyond.
pub const MAX_INPUT_BYTES: u64 = 4 << 30;

/// How long a FIFO or device input may give no byte (no writer, or a writer that writes
/// nothing) before it is refused: 30 s.
pub const SPECIAL_WAIT: std::time::Duration = std::time::Duration::from_secs(30);

static INTERRUPTED: std::sync::atomic::AtomicBool = std::sync::atomic::AtomicBool::new(false);
static INTERRUPT_CHECK: OnceLock<fn() -> bool> = OnceLock::new();

/// Say that this process was interrupted (the CLI's signal handler, before it cleans up): every
/// wait on a FIFO or device, and every write into one, stops with an error.
pub fn note_interrupt() {
    INTERRUPTED.store(true, std::sync::atomic::Ordering::SeqCst);
}

/// Install a check asked while waiting on a FIFO or device (the Python module's: whether
/// Ctrl-C was pressed); at most one, the first.
pub fn set_interrupt_check(check: fn() -> bool) {
    let _ = INTERRUPT_CHECK.set(check);
}

/// Whether this process was interrupted ([`note_interrupt`], or the installed check says so).
pub fn interrupted() -> bool {
    INTERRUPTED.load(std::sync::atomic::Ordering::SeqCst)
        || INTERRUPT_CHECK.get().is_some_and(|check| check())
}

/// What a wait stopped by [`interrupted`] fails with.
pub const INTERRUPTED_MESSAGE: &str = "interrupted";

/// Wait (at most `wait`, checking [`interrupted`] every 50 ms) until `fd` is ready for
/// `events` (`libc::POLLIN` or `POLLOUT`) or hung up; `what` names it in errors.
#[cfg(unix)]
pub fn wait_ready(
    fd: std::os::fd::RawFd,
    events: libc::c_short,
    wait: Option<std::time::Duration>,
    what: &dyn Fn() -> String,
) -> std::io::Result<()> {
    let start = std::time::Instant::now();
    loop {
        if interrupted() {
            return Err(std::io::Error::other(INTERRUPTED_MESSAGE));
        }
        let mut p = libc::pollfd {
            fd,
            events,
            revents: 0,
        };
        // SAFETY: one valid pollfd, for the duration of the call
        let r = unsafe { libc::poll(&mut p, 1, 50) };
        if r > 0 {
            return Ok(());
        }
        if r < 0 {
            let e = std::io::Error::last_os_error();
            if e.kind() != std::io::ErrorKind::Interrupted {
                return Err(e);
            }
        }
        if let Some(w) = wait.filter(|w| start.elapsed() > *w) {
            return Err(std::io::Error::other(format!(
                "{}: nothing came for {} s (a FIFO with no writer?); refused",
                what(),
                w.as_secs()
            )));
        }
    }
}

/// The largest text description (capture TOML, JSON, configuration): 64 MiB.
pub const MAX_TEXT_BYTES: u64 = 64 << 20;

/// The largest measured BRDF file (`.bsdf`, `.binary`): 1 GiB (the RGL database's RGB files
/// are under 10 MB, a MERL file 35 MB).
pub const MAX_MEASURED_BYTES: u64 = 1 << 30;

/// What identifies a version of a file: device, inode, size, modification and change times.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct Stamp {
    dev: u64,
    ino: u64,
    size: u64,
    mtime: (i64, i64),
    ctime: (i64, i64),
}

#[cfg(unix)]
fn stamp(m: &std::fs::Metadata) -> Stamp {
    use std::os::unix::fs::MetadataExt;
    Stamp {
        dev: m.dev(),
        ino: m.ino(),
        size: m.size(),
        mtime: (m.mtime(), m.mtime_nsec()),
        ctime: (m.ctime(), m.ctime_nsec()),
    }
}

#[cfg(not(unix))]
fn stamp(m: &std::fs::Metadata) -> Stamp {
    let t = |r: std::io::Result<std::time::SystemTime>| {
        r.ok()
            .and_then(|t| t.duration_since(std::time::UNIX_EPOCH).ok())
            .map_or((0, 0), |d| (d.as_secs() as i64, d.subsec_nanos() as i64))
    };
    Stamp {
        dev: 0,
        ino: 0,
        size: m.len(),
        mtime: t(m.modified()),
        ctime: (0, 0),
    }
}

fn registry() -> &'static Mutex<HashMap<PathBuf, String>> {
    static R: OnceLock<Mutex<HashMap<PathBuf, String>>> = OnceLock::new();
    R.get_or_init(|| Mutex::new(HashMap::new()))
}

fn record(path: &Path, hex: &str) {
    let mut r = registry().lock().unwrap_or_else(|e| e.into_inner());
    r.insert(path.to_path_buf(), hex.to_owned());
    if let Ok(c) = std::fs::canonicalize(path) {
        r.insert(c, hex.to_owned());
    }
}

/// The SHA-256 (hex) of the bytes a loader of this process last read from `path` (the path as
/// given to the loader, or any path naming the same file); `None` when no loader has read it.
pub fn sha256_read(path: &Path) -> Option<String> {
    let r = registry().lock().unwrap_or_else(|e| e.into_inner());
    if let Some(h) = r.get(path) {
        return Some(h.clone());
    }
    std::fs::canonicalize(path)
        .ok()
        .and_then(|c| r.get(&c).cloned())
}

/// Human form of a byte count (`64 MiB`).
pub fn bytes_text(n: u64) -> String {
    match n {
        n if n >= 1 << 30 && n % (1 << 30) == 0 => format!("{} GiB", n >> 30),
        n if n >= 1 << 20 && n % (1 << 20) == 0 => format!("{} MiB", n >> 20),
        n => format!("{n} bytes"),
    }
}

/// An input being read: a [`Read`] that counts, hashes and limits; [`Input::finish`] checks
/// that the file did not change and records the hash.
pub struct Input {
    path: PathBuf,
    file: std::fs::File,
    before: Option<Stamp>,
    limit: u64,
    read: u64,
    hasher: Sha256,
    /// How long a FIFO or device may give nothing.
    wait: std::time::Duration,
}

/// Open `path` for reading with at most `limit` bytes.
pub fn open(path: &Path, limit: u64) -> Result<Input> {
    open_as(path, limit, "")
}

/// [`open`], naming what the file is (`mask`, `topology map`) when it cannot be opened.
pub fn open_as(path: &Path, limit: u64, what: &str) -> Result<Input> {
    let name = path.display();
    let sep = if what.is_empty() { "" } else { " " };
    // never blocks: a FIFO with no writer is waited for by polling, in `read`
    let file = {
        use std::os::unix::fs::OpenOptionsExt;
        std::fs::OpenOptions::new()
            .read(true)
            .custom_flags(libc::O_NONBLOCK)
            .open(path)
            .map_err(|e| anyhow!("{name}: cannot open{sep}{what}: {e}"))?
    };
    let meta = file
        .metadata()
        .map_err(|e| anyhow!("{name}: cannot read: {e}"))?;
    if meta.is_dir() {
        bail!("{name}: is a directory, not a file");
    }
    let before = meta.is_file().then(|| stamp(&meta));
    if let Some(b) = before {
        if b.size > limit {
            bail!(
                "{name}: {} bytes; the largest input read is {} ({} bytes)",
                b.size,
                bytes_text(limit),
                limit
            );
        }
    }
    if before.is_some() {
        // a regular file reads as it always did
        // SAFETY: fcntl on the descriptor just opened
        unsafe {
            use std::os::fd::AsRawFd;
            let fd = file.as_raw_fd();
            let flags = libc::fcntl(fd, libc::F_GETFL);
            if flags >= 0 {
                libc::fcntl(fd, libc::F_SETFL, flags & !libc::O_NONBLOCK);
            }
        }
    }
    Ok(Input {
        path: path.to_path_buf(),
        file,
        before,
        limit,
        read: 0,
        hasher: Sha256::new(),
        wait: SPECIAL_WAIT,
    })
}

fn too_long(path: &Path, limit: u64) -> anyhow::Error {
    anyhow!(
        "{}: not a regular file and longer than {} ({limit} bytes), the largest input read; refused",
        path.display(),
        bytes_text(limit)
    )
}

impl Read for Input {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        // one byte past the limit may be read, so that an input of exactly the limit ends cleanly
        let room = (self.limit + 1).saturating_sub(self.read);
        if room == 0 {
            return Err(std::io::Error::other(too_long(&self.path, self.limit)));
        }
        let want = buf.len().min(usize::try_from(room).unwrap_or(usize::MAX));
        let n = if self.before.is_some() {
            self.file.read(&mut buf[..want])?
        } else {
            self.read_special(&mut buf[..want])?
        };
        self.read += n as u64;
        if self.read > self.limit {
            return Err(std::io::Error::other(too_long(&self.path, self.limit)));
        }
        self.hasher.update(&buf[..n]);
        Ok(n)
    }
}

impl Input {
    /// A read of a FIFO or device (opened non-blocking): wait for data by polling, so that a
    /// signal stops the wait and a FIFO nobody writes is refused after [`SPECIAL_WAIT`].
    fn read_special(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        use std::os::fd::AsRawFd;
        let fd = self.file.as_raw_fd();
        let path = self.path.clone();
        let what = move || path.display().to_string();
        // a FIFO whose writer has not come yet reads as its end: wait until it has data or
        // its writer has come and gone
        wait_ready(fd, libc::POLLIN, Some(self.wait), &what)?;
        loop {
            match self.file.read(buf) {
                Ok(n) => return Ok(n),
                Err(e) if e.kind() == std::io::ErrorKind::WouldBlock => {
                    wait_ready(fd, libc::POLLIN, Some(self.wait), &what)?
                }
                Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
                Err(e) => return Err(e),
            }
        }
    }

    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Bytes read so far.
    pub fn bytes_read(&self) -> u64 {
        self.read
    }

    /// Lower the limit (once a header has said how long the input should be).
    pub fn limit_to(&mut self, limit: u64) {
        self.limit = self.limit.min(limit);
    }

    /// Whether the input is a regular file (its size known before reading).
    pub fn size(&self) -> Option<u64> {
        self.before.map(|b| b.size)
    }

    /// The end of the read: for a regular file, every byte must have been read and the file must
    /// be as it was when opened (and still be what `path` names). Records and returns the hash.
    pub fn finish(self) -> Result<String> {
        let name = self.path.display();
        if let Some(before) = self.before {
            let changed = || {
                anyhow!(
                    "{name}: changed while it was being read ({} bytes when opened, {} read); \
                     what was read may be torn; run again once the file is complete",
                    before.size,
                    self.read
                )
            };
            let now = self.file.metadata().map(|m| stamp(&m)).ok();
            if now != Some(before) || self.read != before.size {
                return Err(changed());
            }
            // the name still names the file read (not replaced while it was read)
            match std::fs::metadata(&self.path) {
                Ok(m) if stamp(&m) == before => {}
                _ => return Err(changed()),
            }
        }
        let hex: String = self
            .hasher
            .finalize()
            .iter()
            .map(|b| format!("{b:02x}"))
            .collect();
        record(&self.path, &hex);
        Ok(hex)
    }

    /// The rest of the input into memory (the limit applies).
    pub fn read_rest(&mut self, into: &mut Vec<u8>) -> Result<()> {
        if let Some(size) = self.size() {
            into.reserve(usize::try_from(size.saturating_sub(self.read)).unwrap_or(0));
        }
        self.read_to_end(into)
            .map(|_| ())
            .map_err(|e| io_error(&self.path, e))
    }
}

/// The longest line a text input (CSV) may have: 16 MiB.
pub const MAX_LINE_BYTES: usize = 16 << 20;

/// A text reader that fails once more than [`MAX_LINE_BYTES`] pass without a newline (a device
/// such as `/dev/zero`, a binary file), so that a line-based parser never buffers without end.
pub struct LineLimited<R> {
    inner: R,
    name: String,
    since_newline: usize,
}

impl<R: Read> LineLimited<R> {
    pub fn new(inner: R, name: &str) -> Self {
        Self {
            inner,
            name: name.to_owned(),
            since_newline: 0,
        }
    }

    pub fn into_inner(self) -> R {
        self.inner
    }
}

impl<R: Read> Read for LineLimited<R> {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        let n = self.inner.read(buf)?;
        match memchr::memrchr(b'\n', &buf[..n]) {
            Some(p) => self.since_newline = n - p - 1,
            None => self.since_newline += n,
        }
        if self.since_newline > MAX_LINE_BYTES {
            return Err(std::io::Error::other(anyhow!(
                "{}: a line longer than {} (is this a text file?)",
                self.name,
                bytes_text(MAX_LINE_BYTES as u64)
            )));
        }
        Ok(n)
    }
}

/// A read error as a message naming the file (the limit's own message kept as it is).
pub fn io_error(path: &Path, e: std::io::Error) -> anyhow::Error {
    if e.kind() == std::io::ErrorKind::Other {
        if let Some(inner) = e.get_ref() {
            if inner.to_string().starts_with(&path.display().to_string()) {
                return anyhow!("{inner}");
            }
        }
    }
    anyhow!("{}: cannot read: {e}", path.display())
}

/// An input read into memory, with the SHA-256 of its bytes.
#[derive(Debug)]
pub struct InputBytes {
    pub path: PathBuf,
    pub bytes: Vec<u8>,
    /// SHA-256 of `bytes`, hex.
    pub sha256: String,
}

/// Read all of `path` (at most `limit` bytes), checked not to have changed while read; the
/// hash is recorded for [`sha256_read`].
pub fn read_input(path: &Path, limit: u64) -> Result<InputBytes> {
    read_input_as(path, limit, "")
}

/// [`read_input`], naming what the file is when it cannot be opened.
pub fn read_input_as(path: &Path, limit: u64, what: &str) -> Result<InputBytes> {
    let mut input = open_as(path, limit, what)?;
    let mut bytes = Vec::new();
    input.read_rest(&mut bytes)?;
    let sha256 = input.finish()?;
    Ok(InputBytes {
        path: path.to_path_buf(),
        bytes,
        sha256,
    })
}

/// A text input (at most [`MAX_TEXT_BYTES`]) as UTF-8.
pub fn read_text(path: &Path) -> Result<String> {
    Ok(read_text_hashed(path, "")?.0)
}

/// [`read_text`] naming what the file is (`parameter file`) when it cannot be opened.
pub fn read_text_as(path: &Path, what: &str) -> Result<String> {
    Ok(read_text_hashed(path, what)?.0)
}

/// [`read_text_as`] and the SHA-256 of the bytes read (hex).
pub fn read_text_hashed(path: &Path, what: &str) -> Result<(String, String)> {
    let b = read_input_as(path, MAX_TEXT_BYTES, what)?;
    let sha256 = b.sha256;
    String::from_utf8(b.bytes)
        .map(|t| (t, sha256))
        .map_err(|e| {
            anyhow!(
                "{}: not UTF-8 text (byte {} is invalid)",
                path.display(),
                e.utf8_error().valid_up_to() + 1
            )
        })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_fifo_nobody_writes_is_refused_after_the_wait_and_one_written_is_read() {
        let d = tempfile::tempdir().unwrap();
        let p = d.path().join("f.csv");
        let c = std::ffi::CString::new(p.to_str().unwrap()).unwrap();
        // SAFETY: a valid C string
        assert_eq!(unsafe { libc::mkfifo(c.as_ptr(), 0o644) }, 0);
        // opening never blocks; reading waits at most `wait`
        let mut input = open(&p, 100).unwrap();
        input.wait = std::time::Duration::from_millis(300);
        let start = std::time::Instant::now();
        let e = input.read_rest(&mut Vec::new()).unwrap_err().to_string();
        assert!(e.contains("f.csv") && e.contains("nothing came"), "{e}");
        assert!(start.elapsed() < std::time::Duration::from_secs(5));
        // a writer that comes later is waited for, and its bytes read to the end
        let q = p.clone();
        let writer = std::thread::spawn(move || {
            std::thread::sleep(std::time::Duration::from_millis(200));
            std::fs::write(q, "abc").unwrap();
        });
        let b = read_input(&p, 100).unwrap();
        writer.join().unwrap();
        assert_eq!(b.bytes, b"abc");
    }

    #[test]
    fn hash_limit_and_devices() {
        let d = tempfile::tempdir().unwrap();
        let p = d.path().join("a.txt");
        std::fs::write(&p, "abc").unwrap();
        let b = read_input(&p, 3).unwrap();
        assert_eq!(
            b.sha256,
            "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad"
        );
        assert_eq!(sha256_read(&p).as_deref(), Some(b.sha256.as_str()));
        let e = read_input(&p, 2).unwrap_err().to_string();
        assert!(e.contains("a.txt") && e.contains("largest input"), "{e}");
        let e = read_input(d.path(), 10).unwrap_err().to_string();
        assert!(e.contains("directory"), "{e}");
        if Path::new("/dev/zero").exists() {
            let e = read_input(Path::new("/dev/zero"), 1 << 20)
                .unwrap_err()
                .to_string();
            assert!(e.contains("/dev/zero") && e.contains("1 MiB"), "{e}");
        }
    }
}
