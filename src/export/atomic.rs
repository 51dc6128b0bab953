//! Atomic file output: write into a temporary file beside the target, rename on success.

use anyhow::{Context, Result};
use std::io::Write;
use std::path::{Path, PathBuf};

/// A file that appears at `path` only when [`AtomicFile::commit`] is called. Created up front so
/// an unwritable destination fails before any work is done. Dropped without commit, it vanishes.
pub struct AtomicFile {
    target: PathBuf,
    temp: tempfile::NamedTempFile,
}

impl AtomicFile {
    pub fn create(path: &Path) -> Result<Self> {
        let dir = match path.parent() {
            Some(p) if !p.as_os_str().is_empty() => p,
            _ => Path::new("."),
        };
        if path.is_dir() {
            anyhow::bail!("{}: is a directory, expected a file path", path.display());
        }
        let temp = tempfile::Builder::new()
            .prefix(".fibrefit-")
            .suffix(".tmp")
            .tempfile_in(dir)
            .with_context(|| {
                format!(
                    "{}: cannot create output (directory {} not writable or missing)",
                    path.display(),
                    dir.display()
                )
            })?;
        Ok(Self {
            target: path.to_path_buf(),
            temp,
        })
    }

    pub fn writer(&mut self) -> &mut impl Write {
        self.temp.as_file_mut()
    }

    pub fn commit(mut self) -> Result<()> {
        self.temp.as_file_mut().flush()?;
        self.temp.as_file().sync_all().ok();
        self.temp.persist(&self.target).map_err(|e| {
            anyhow::anyhow!(
                "{}: cannot write output: {}",
                self.target.display(),
                e.error
            )
        })?;
        Ok(())
    }
}
