//! Goniometric samples: CSV with a header (docs/formats.md, "Goniometric CSV").
//!
//! Angles `theta_i,phi_i,theta_o,phi_o` in degrees (MODEL.md §1). Values as `brdf` (or
//! `brdf_r,brdf_g,brdf_b`), in 1/sr, or as `radiance` (or `radiance_r,radiance_g,radiance_b`)
//! with the `irradiance` that produced it, measured perpendicular to the light: then
//! f = radiance / (irradiance cos theta_i). Optional `sigma` (or `sigma_r,sigma_g,sigma_b`), the
//! standard deviation of each value in the same units as the values, or `weight`.
//!
//! Angles in radians are read with [`GonioOptions::angles`] (`--angles rad`).
//!
//! The delimiter is read off the header line (comma, tab, semicolon or runs of whitespace:
//! [`Delimiter::sniff`]); a file's own column names map to these with
//! [`GonioOptions::columns`] (`--columns theta_i=theta_in,...`).
//!
//! Here: the options, the streaming of the file in blocks and the checks over all its rows
//! (negatives beyond noise, radian-looking angles); the header in `header.rs`, the rows (in
//! parallel chunks) in `rows.rs`.

use super::samples::{DataKind, Dropped, Origin, Sample, Samples};
use anyhow::{anyhow, bail, Result};
use std::path::Path;

mod header;
mod rows;
#[cfg(test)]
mod tests;

use header::{header_end, parse_header, Header, Layout};
#[cfg_attr(not(feature = "internals"), allow(unused_imports))] // for the tests and benchmarks
pub use header::{Delimiter, Format};
use rows::{parse_chunk, split_lines, Chunk};

/// Options a user can set on loading.
#[derive(Clone, Debug, Default)]
pub struct GonioOptions {
    /// Skip rows with problems (and count them) instead of failing.
    pub skip_bad_rows: bool,
    /// The angles really are small degrees: do not stop on radian-looking data.
    pub small_angles_ok: bool,
    /// The file's own column names: (our name, the file's name), e.g. ("theta_i", "theta_in").
    pub columns: Vec<(String, String)>,
    /// The unit of the angle columns (`--angles`, a fit config's `[data] angles`); radians are
    /// converted to degrees as the rows are read.
    pub angles: AngleUnit,
}

/// The unit of a goniometric table's angle columns: degrees (the default) or radians.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Deserialize, serde::Serialize)]
#[serde(try_from = "String", into = "String")]
pub enum AngleUnit {
    /// Degrees (what fibrefit's own files use).
    #[default]
    Deg,
    /// Radians, converted to degrees on loading.
    Rad,
}

impl AngleUnit {
    /// The unit's name as the flag and the config take it (`deg`, `rad`).
    pub fn name(self) -> &'static str {
        match self {
            AngleUnit::Deg => "deg",
            AngleUnit::Rad => "rad",
        }
    }

    /// An angle read in this unit, in degrees.
    pub fn to_degrees(self, x: f64) -> f64 {
        match self {
            AngleUnit::Deg => x,
            AngleUnit::Rad => x.to_degrees(),
        }
    }
}

impl std::str::FromStr for AngleUnit {
    type Err = String;
    fn from_str(s: &str) -> std::result::Result<Self, String> {
        match s.trim().to_ascii_lowercase().as_str() {
            "deg" | "degrees" => Ok(AngleUnit::Deg),
            "rad" | "radians" => Ok(AngleUnit::Rad),
            _ => Err(format!(
                "`{s}` is not an angle unit: give `deg` (degrees, the default) or `rad` (radians)"
            )),
        }
    }
}

impl TryFrom<String> for AngleUnit {
    type Error = String;
    fn try_from(s: String) -> std::result::Result<Self, String> {
        s.parse()
    }
}

impl From<AngleUnit> for String {
    fn from(u: AngleUnit) -> String {
        u.name().to_owned()
    }
}

/// Every column name fibrefit reads.
pub const COLUMNS: [&str; 18] = [
    "theta_i",
    "phi_i",
    "theta_o",
    "phi_o",
    "brdf",
    "brdf_r",
    "brdf_g",
    "brdf_b",
    "radiance",
    "radiance_r",
    "radiance_g",
    "radiance_b",
    "irradiance",
    "sigma",
    "sigma_r",
    "sigma_g",
    "sigma_b",
    "weight",
];

/// Parse `--columns theta_i=theta_in,phi_i=phi_in,...`: pairs of our name and the file's.
pub fn parse_columns(text: &str) -> Result<Vec<(String, String)>> {
    let mut out = Vec::new();
    for part in text.split(',').map(str::trim).filter(|p| !p.is_empty()) {
        let (ours, theirs) = part.split_once('=').ok_or_else(|| {
            anyhow!("--columns {text}: `{part}` is not OURS=THEIRS (e.g. theta_i=theta_in)")
        })?;
        out.push((ours.trim().to_owned(), theirs.trim().to_owned()));
    }
    Ok(out)
}

/// Refuse a column map that names no column of ours, maps one twice, or maps two to one.
pub fn check_columns(columns: &[(String, String)]) -> Result<()> {
    for (k, (ours, theirs)) in columns.iter().enumerate() {
        if !COLUMNS.contains(&ours.as_str()) {
            bail!(
                "column map (--columns or [columns]) {ours}={theirs}: `{ours}` is not a column fibrefit reads; the columns are {}",
                COLUMNS.join(", ")
            );
        }
        if theirs.is_empty() {
            bail!("column map (--columns or [columns]) {ours}=: give the file's name of the column `{ours}`");
        }
        if columns[..k].iter().any(|(o, _)| o == ours) {
            bail!("column map (--columns or [columns]): `{ours}` is mapped twice");
        }
        if columns[..k].iter().any(|(_, t)| t == theirs) {
            bail!(
                "column map (--columns or [columns]): the file's column `{theirs}` is mapped twice"
            );
        }
    }
    Ok(())
}

/// Values (BRDF, sigma, weight) beyond this magnitude are refused: their squares would overflow.
pub(crate) const MAX_MAGNITUDE: f64 = 1e100;

/// Without sigmas, negatives down to this fraction of the largest value are noise.
pub(crate) const NEGATIVE_FRACTION: f64 = 0.01;

/// Sigmas below this are refused: their inverse squares would overflow.
pub(crate) const MIN_SIGMA: f64 = 1e-100;

/// Negative values up to this many standard deviations are noise; beyond, an error.
pub(crate) const NEGATIVE_SIGMAS: f64 = 4.0;

/// Most rows of one goniometric CSV: 10 million (each sample is held in memory, with the fit's
/// own per-sample arrays several hundred bytes in all; about 5 GB at this limit).
pub const MAX_ROWS: usize = 10_000_000;

pub fn load(path: &Path, opts: &GonioOptions) -> Result<Samples> {
    Ok(load_with_format(path, opts)?.0)
}

/// [`load`], and what the header said (delimiter, columns as read and as mapped).
pub fn load_with_format(path: &Path, opts: &GonioOptions) -> Result<(Samples, Format)> {
    // read once through load::input: limited, hashed as parsed, checked unchanged at the end
    // (a file cut or rewritten while it was read is an error, not a partial sample set)
    let mut input = super::input::open(path, super::input::MAX_INPUT_BYTES)?;
    let (mut s, format) = read_with_format(&mut input, &path.display().to_string(), opts)?;
    input.finish()?;
    s.source = path.to_path_buf();
    Ok((s, format))
}

/// Bytes read per block: memory for loading is this plus the samples kept, whatever the file size.
const BLOCK: usize = 32 << 20;

/// Parse from any reader, streaming it in blocks; `name` labels errors as `name:line: problem`.
/// (A quoted field may not span lines across a block boundary; numeric CSVs have none.)
pub fn read(input: impl std::io::Read, name: &str, opts: &GonioOptions) -> Result<Samples> {
    Ok(read_with_format(input, name, opts)?.0)
}

/// [`read`], and what the header said.
pub fn read_with_format(
    mut input: impl std::io::Read,
    name: &str,
    opts: &GonioOptions,
) -> Result<(Samples, Format)> {
    let mut buf: Vec<u8> = Vec::with_capacity(BLOCK);
    let mut eof = false;
    // fill `buf` with up to BLOCK more bytes; false at the end of the input
    let mut fill = |buf: &mut Vec<u8>, eof: &mut bool| -> Result<()> {
        let start = buf.len();
        buf.resize(start + BLOCK, 0);
        let mut got = 0;
        while got < BLOCK {
            match input.read(&mut buf[start + got..]) {
                Ok(0) => {
                    *eof = true;
                    break;
                }
                Ok(n) => got += n,
                Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
                Err(e) => {
                    // the input's own messages (its limit) already name the file
                    let text = e.to_string();
                    return Err(if text.starts_with(name) {
                        anyhow!("{text}")
                    } else {
                        anyhow!("{name}: cannot read: {e}")
                    });
                }
            }
        }
        buf.truncate(start + got);
        Ok(())
    };
    // the header, and everything before it, must be in the buffer
    fill(&mut buf, &mut eof)?;
    loop {
        match header_end(&buf) {
            Some(_) => break,
            None if eof => break,
            None if buf.len() >= BLOCK => bail!(
                "{name}: no header line within the first {} MiB (is this a text CSV?)",
                BLOCK >> 20
            ),
            None => fill(&mut buf, &mut eof)?,
        }
    }
    let mut state = ParseState::new(parse_header(&buf, name, opts)?);
    let mut rest = buf.split_off(state.body_start);
    drop(buf);
    loop {
        if !eof && memchr::memrchr(b'\n', &rest).is_none() {
            if rest.len() >= BLOCK {
                bail!(
                    "{name}:{}: a line longer than {} MiB (is this a text CSV?)",
                    state.next_line,
                    BLOCK >> 20
                );
            }
            fill(&mut rest, &mut eof)?;
            continue;
        }
        let complete = if eof {
            rest.len()
        } else {
            memchr::memrchr(b'\n', &rest).map_or(0, |p| p + 1)
        };
        state.parse_lines(&rest[..complete], name, opts)?;
        rest.drain(..complete);
        if eof {
            break;
        }
        fill(&mut rest, &mut eof)?;
    }
    let format = state.format.clone();
    Ok((state.finish(name, opts)?, format))
}

/// What parsing has gathered so far.
struct ParseState {
    header: Vec<String>,
    format: Format,
    lay: Layout,
    /// Where the rows start in the first buffer.
    body_start: usize,
    /// File line number of the next row.
    next_line: u64,
    samples: Vec<Sample>,
    negatives: Vec<(u64, f64, usize)>,
    dropped: Dropped,
    examples: Vec<String>,
}

impl ParseState {
    /// Nothing gathered yet, after `head`.
    fn new(head: Header) -> Self {
        Self {
            header: head.header,
            format: head.format,
            lay: head.lay,
            body_start: head.body_start,
            next_line: head.next_line,
            samples: Vec::new(),
            negatives: Vec::new(),
            dropped: Dropped::default(),
            examples: Vec::new(),
        }
    }

    /// Parse whole lines (in parallel chunks) and keep their samples.
    fn parse_lines(&mut self, body: &[u8], name: &str, opts: &GonioOptions) -> Result<()> {
        use rayon::prelude::*;
        let (lay, header) = (&self.lay, &self.header);
        let chunks: Vec<Chunk> = split_lines(body, self.next_line)
            .into_par_iter()
            .map(|(b, first)| parse_chunk(b, first, lay, header, name, opts))
            .collect();
        self.next_line += memchr::memchr_iter(b'\n', body).count() as u64;
        let rows = self.samples.len() + chunks.iter().map(|c| c.samples.len()).sum::<usize>();
        if rows > MAX_ROWS {
            bail!(
                "{name}: more than {MAX_ROWS} rows (by line {}): split the file or subsample it",
                self.next_line
            );
        }
        self.samples
            .reserve(chunks.iter().map(|c| c.samples.len()).sum());
        for c in chunks {
            if let Some(e) = c.error {
                bail!(e);
            }
            self.samples.extend(c.samples);
            self.negatives.extend(c.negatives);
            self.dropped.skipped_rows += c.skipped;
            if self.examples.len() < 5 {
                self.examples.extend(c.examples);
            }
        }
        Ok(())
    }

    /// The samples: negatives beyond noise refused (or skipped), radian-looking angles refused.
    fn finish(self, name: &str, opts: &GonioOptions) -> Result<Samples> {
        let ParseState {
            header,
            lay,
            mut samples,
            negatives,
            mut dropped,
            mut examples,
            ..
        } = self;
        let channels = lay.values.len();
        examples.truncate(5);
        if samples.is_empty() {
            bail!("{name}: no usable rows after the header");
        }
        if lay.weight.is_some() && samples.iter().all(|s| s.weight == 0.0) {
            bail!("{name}: every row has weight 0: there is nothing to fit");
        }
        let largest = samples
            .iter()
            .flat_map(|s| s.value[..channels].iter().copied())
            .fold(0.0, f64::max);
        let mut bad_lines = Vec::new();
        for (line, value, channel) in negatives {
            if value < -NEGATIVE_FRACTION * largest {
                let col = header[lay.values[channel]].as_str();
                let msg = format!(
                "{name}:{line}: column `{col}` = {value} is negative beyond noise (more than {} % of the largest value {largest}); give `sigma` if this is noise",
                NEGATIVE_FRACTION * 100.0
            );
                if !opts.skip_bad_rows {
                    bail!(msg);
                }
                dropped.skipped_rows += 1;
                if examples.len() < 5 {
                    examples.push(msg);
                }
                bad_lines.push(line);
            }
        }
        if !bad_lines.is_empty() {
            samples.retain(|s| !matches!(s.origin, Origin::Line(l) if bad_lines.contains(&l)));
        }
        // a file said to be in radians is not second-guessed
        if !opts.small_angles_ok && opts.angles == AngleUnit::Deg {
            check_not_radians(&samples, name)?;
        }
        Ok(Samples {
            samples,
            channels,
            kind: DataKind::Gonio,
            source: name.into(),
            dropped,
            skipped_examples: examples,
            image_size: None,
            scale_rel_se: None,
        })
    }
}

/// Stop on data whose angles all look like radians.
fn check_not_radians(samples: &[Sample], name: &str) -> Result<()> {
    const MIN_ROWS: usize = 8;
    if samples.len() < MIN_ROWS {
        return Ok(());
    }
    // theta <= pi/2 "degrees" for every direction, compared on cosines (no acos per row)
    let min_cos = samples.iter().map(|s| s.l.z.min(s.v.z)).fold(1.0, f64::min);
    let theta_max = min_cos.clamp(-1.0, 1.0).acos().to_degrees();
    let phi_in_radian_range = samples
        .iter()
        .flat_map(|s| [s.l, s.v])
        .filter(|w| w.z < 1.0 - 1e-12)
        .all(|w| {
            let phi = w.y.atan2(w.x).to_degrees();
            (-std::f64::consts::PI..=std::f64::consts::TAU).contains(&phi)
        });
    if theta_max <= std::f64::consts::FRAC_PI_2 && phi_in_radian_range {
        bail!(
            "{name}: every theta is at most {theta_max:.3} degrees over {} rows: the angles look like radians. \
             fibrefit reads degrees unless told: give --angles rad (or `[data] angles = \"rad\"` in the fit config; \
             Python: angles=\"rad\"), or pass --small-angles-ok if these really are degrees",
            samples.len()
        );
    }
    Ok(())
}
