//! The lights of a photo set (`fibrefit calibrate --lights lights.toml`): which photos the
//! camera's flash lit and which a lamp at a measured position, and the ambient frames (the same
//! pose with the light off) to subtract. Without the file every photo is lit by the flash.
//!
//! ```toml
//! lamp_mm = [150.0, -100.0, 400.0]  # optional: photos not listed are lit by this lamp (board
//!                                   # frame, mm), not by the flash
//! [[photo]]
//! file = "IMG_0003.jpg"             # a photo given to calibrate (its file name, or its path)
//! lamp_mm = [0.0, 200.0, 300.0]     # its lamp; or `flash = true`; neither: as the default
//! ambient = "IMG_0003_off.jpg"      # optional, relative to this file: subtracted
//! ```

use anyhow::{anyhow, bail, Result};
use serde::Deserialize;
use std::path::{Path, PathBuf};

/// What lights a photo.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum PhotoLight {
    /// The camera's flash, at the flash offset from the lens.
    Flash,
    /// A lamp at this position in the board frame (mm).
    Lamp([f64; 3]),
}

/// Each photo's light and ambient frame, in the order the photos were given.
#[derive(Clone, Debug, PartialEq)]
pub struct PhotoLights {
    pub light: Vec<PhotoLight>,
    pub ambient: Vec<Option<PathBuf>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct LightsFile {
    lamp_mm: Option<[f64; 3]>,
    #[serde(default)]
    photo: Vec<PhotoEntry>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct PhotoEntry {
    file: PathBuf,
    lamp_mm: Option<[f64; 3]>,
    flash: Option<bool>,
    ambient: Option<PathBuf>,
}

/// A lamp position that can be: finite, above the board (z > 0), within 10 m.
fn check_lamp(file: &Path, at: &str, p: [f64; 3]) -> Result<[f64; 3]> {
    if p.iter().all(|c| c.is_finite() && c.abs() <= 10_000.0) && p[2] > 0.0 {
        return Ok(p);
    }
    bail!(
        "{}: {at} lamp_mm = {p:?}: expected a position in the board frame, mm, above the board (z > 0) and within 10 m",
        file.display()
    )
}

impl PhotoLights {
    /// Every photo lit by the flash, no ambient frames.
    pub fn flash(photos: usize) -> Self {
        Self {
            light: vec![PhotoLight::Flash; photos],
            ambient: vec![None; photos],
        }
    }

    /// The lights file at `path` for `photos` (as given to calibrate): every entry names one of
    /// them, once.
    pub fn read(path: &Path, photos: &[PathBuf]) -> Result<Self> {
        let text = super::input::read_text_as(path, "lights file")?;
        let file: LightsFile =
            toml::from_str(&text).map_err(|e| anyhow!("{}: {e}", path.display()))?;
        let default = match file.lamp_mm {
            Some(p) => PhotoLight::Lamp(check_lamp(path, "", p)?),
            None => PhotoLight::Flash,
        };
        let mut out = Self {
            light: vec![default; photos.len()],
            ambient: vec![None; photos.len()],
        };
        let mut named = vec![false; photos.len()];
        let folder = path.parent().unwrap_or(Path::new(""));
        for (i, e) in file.photo.iter().enumerate() {
            let at = format!("[[photo]] {} (file = {:?}):", i + 1, e.file.display());
            let k = which_photo(&e.file, photos).ok_or_else(|| {
                anyhow!(
                    "{}: {at} names none of the photos given ({})",
                    path.display(),
                    photos
                        .iter()
                        .map(|p| p.display().to_string())
                        .collect::<Vec<_>>()
                        .join(", ")
                )
            })?;
            if std::mem::replace(&mut named[k], true) {
                bail!("{}: {at} the photo is listed twice", path.display());
            }
            out.light[k] = match (e.lamp_mm, e.flash) {
                (Some(_), Some(true)) => {
                    bail!("{}: {at} give lamp_mm or flash = true, not both", path.display())
                }
                (Some(p), _) => PhotoLight::Lamp(check_lamp(path, &at, p)?),
                (None, Some(true)) => PhotoLight::Flash,
                (None, _) => default,
            };
            out.ambient[k] = e.ambient.as_ref().map(|a| folder.join(a));
        }
        Ok(out)
    }
}

/// The photo `file` names: the one whose path is `file`, else the only one with its file name.
fn which_photo(file: &Path, photos: &[PathBuf]) -> Option<usize> {
    if let Some(k) = photos.iter().position(|p| p == file) {
        return Some(k);
    }
    let name = file.file_name()?;
    let mut hits = photos
        .iter()
        .enumerate()
        .filter(|(_, p)| p.file_name() == Some(name));
    match (hits.next(), hits.next()) {
        (Some((k, _)), None) => Some(k),
        _ => None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn read(text: &str) -> Result<PhotoLights> {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("lights.toml");
        std::fs::write(&p, text).unwrap();
        let photos = ["a/p0.jpg", "a/p1.jpg", "b/p2.jpg"].map(PathBuf::from);
        PhotoLights::read(&p, &photos).map_err(|e| anyhow!("{e:#}"))
    }

    #[test]
    fn entries_set_their_photos_and_the_rest_take_the_default() {
        let l = read(
            "lamp_mm = [100, 0, 300]\n[[photo]]\nfile = \"p1.jpg\"\nflash = true\nambient = \"off1.jpg\"\n[[photo]]\nfile = \"b/p2.jpg\"\nlamp_mm = [0, 50, 200]\n",
        )
        .unwrap();
        assert_eq!(
            l.light,
            vec![
                PhotoLight::Lamp([100.0, 0.0, 300.0]),
                PhotoLight::Flash,
                PhotoLight::Lamp([0.0, 50.0, 200.0])
            ]
        );
        assert!(l.ambient[1].as_ref().unwrap().ends_with("off1.jpg"));
        assert_eq!(l.ambient[0], None);
    }

    #[test]
    fn bad_entries_are_refused_naming_them() {
        for (text, want) in [
            ("[[photo]]\nfile = \"nope.jpg\"\n", "names none of the photos"),
            ("[[photo]]\nfile = \"p0.jpg\"\n[[photo]]\nfile = \"a/p0.jpg\"\n", "listed twice"),
            ("lamp_mm = [0, 0, -5]\n", "above the board"),
            ("[[photo]]\nfile = \"p0.jpg\"\nlamp_mm = [1, 2, 3]\nflash = true\n", "not both"),
            ("lamp = [0, 0, 5]\n", "unknown field"),
            ("[[photo]]\nfile = \"p0.jpg\"\nlamp_mm = [1, 2, nan]\n", "lamp_mm"),
        ] {
            let err = read(text).unwrap_err().to_string();
            assert!(err.contains(want) && err.contains("lights.toml"), "{text}: {err}");
        }
    }
}
