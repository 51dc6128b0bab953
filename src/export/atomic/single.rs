//! Outputs written on their own: [`Sink`] (where an encoded picture goes) and [`AtomicFile`]
//! (one file, an [`Outputs`] set of one).

use super::outputs::{Named, OutputId, Outputs};
use anyhow::{anyhow, Result};
use std::fs::File;
use std::io::{Seek, Write};
use std::path::{Path, PathBuf};

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
