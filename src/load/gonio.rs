//! Goniometric samples: CSV with a header (docs/formats.md, "Goniometric CSV").
//!
//! Angles `theta_i,phi_i,theta_o,phi_o` in degrees (MODEL.md §1). Values as `brdf` (or
//! `brdf_r,brdf_g,brdf_b`), in 1/sr, or as `radiance` (or `radiance_r,radiance_g,radiance_b`)
//! with the `irradiance` that produced it, measured perpendicular to the light: then
//! f = radiance / (irradiance cos theta_i). Optional `sigma` (or `sigma_r,sigma_g,sigma_b`), the
//! standard deviation of each value in the same units as the values, or `weight`.
//!
//! The delimiter is read off the header line (comma, tab, semicolon or runs of whitespace:
//! [`Delimiter::sniff`]); a file's own column names map to these with
//! [`GonioOptions::columns`] (`--columns theta_i=theta_in,...`).

use super::samples::{DataKind, Dropped, Origin, Sample, Samples};
use crate::model::frame::direction_from_angles;
use anyhow::{anyhow, bail, Result};
use std::path::Path;

/// Options a user can set on loading.
#[derive(Clone, Debug, Default)]
pub struct GonioOptions {
    /// Skip rows with problems (and count them) instead of failing.
    pub skip_bad_rows: bool,
    /// The angles really are small degrees: do not stop on radian-looking data.
    pub small_angles_ok: bool,
    /// The file's own column names: (our name, the file's name), e.g. ("theta_i", "theta_in").
    pub columns: Vec<(String, String)>,
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

/// How the fields of a line are separated.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Delimiter {
    #[default]
    Comma,
    Tab,
    Semicolon,
    /// Runs of spaces or tabs.
    Whitespace,
}

impl Delimiter {
    pub fn name(self) -> &'static str {
        match self {
            Delimiter::Comma => "comma",
            Delimiter::Tab => "tab",
            Delimiter::Semicolon => "semicolon",
            Delimiter::Whitespace => "whitespace",
        }
    }

    /// The delimiter of a header line: the most frequent of tab, semicolon and comma (ties to
    /// tab, then comma), or whitespace when there is none of them but several words.
    pub fn sniff(header: &str) -> Self {
        let count = |c: char| header.matches(c).count();
        let (comma, tab, semi) = (count(','), count('\t'), count(';'));
        if tab > 0 && tab >= comma && tab >= semi {
            Delimiter::Tab
        } else if semi > comma {
            Delimiter::Semicolon
        } else if comma > 0 {
            Delimiter::Comma
        } else if header.split_ascii_whitespace().count() > 1 {
            Delimiter::Whitespace
        } else {
            Delimiter::Comma
        }
    }

    fn split(self, line: &str) -> Vec<String> {
        let clean = |h: &str| h.trim().trim_matches('"').to_owned();
        match self {
            Delimiter::Comma => line.split(',').map(clean).collect(),
            Delimiter::Tab => line.split('\t').map(clean).collect(),
            Delimiter::Semicolon => line.split(';').map(clean).collect(),
            Delimiter::Whitespace => line.split_ascii_whitespace().map(clean).collect(),
        }
    }

    /// The byte the CSV reader splits on (whitespace-separated lines are rewritten with commas).
    fn byte(self) -> u8 {
        match self {
            Delimiter::Tab => b'\t',
            Delimiter::Semicolon => b';',
            Delimiter::Comma | Delimiter::Whitespace => b',',
        }
    }
}

/// What a goniometric file's header says: its delimiter, the columns as read and as mapped.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Format {
    pub delimiter: Delimiter,
    /// The header's names as in the file.
    pub header: Vec<String>,
    /// (the file's name, ours) of every column mapped by [`GonioOptions::columns`].
    pub mapped: Vec<(String, String)>,
}

impl Format {
    /// One line for `inspect`.
    pub fn describe(&self) -> String {
        let mut t = format!(
            "{}-separated, columns {}",
            self.delimiter.name(),
            self.header.join(", ")
        );
        if !self.mapped.is_empty() {
            let m: Vec<String> = self
                .mapped
                .iter()
                .map(|(theirs, ours)| format!("{theirs} -> {ours}"))
                .collect();
            t += &format!(" (mapped: {})", m.join(", "));
        }
        t
    }
}

struct Layout {
    delimiter: Delimiter,
    angles: [usize; 4],
    values: Vec<usize>,
    irradiance: Option<usize>,
    sigma: Vec<usize>,
    weight: Option<usize>,
}

const ANGLES: [&str; 4] = ["theta_i", "phi_i", "theta_o", "phi_o"];

fn layout(header: &[String], name: &str) -> Result<Layout> {
    let find = |col: &str| header.iter().position(|h| h == col);
    for (i, h) in header.iter().enumerate() {
        if header[..i].contains(h) {
            bail!("{name}:1: column `{h}` appears twice");
        }
        if !COLUMNS.contains(&h.as_str()) {
            bail!(
                "{name}:1: unknown column `{h}`; expected theta_i, phi_i, theta_o, phi_o, then brdf \
                 (or brdf_r, brdf_g, brdf_b) or radiance (or radiance_r, _g, _b) with irradiance, \
                 and optionally sigma (or sigma_r, _g, _b) or weight"
            );
        }
    }
    let mut angles = [0; 4];
    for (k, col) in ANGLES.iter().enumerate() {
        angles[k] = find(col)
            .ok_or_else(|| anyhow!("{name}:1: missing column `{col}` (angles in degrees)"))?;
    }
    let group = |base: &str| -> Result<Vec<usize>> {
        let grey = find(base);
        let rgb: Vec<Option<usize>> = ["r", "g", "b"]
            .iter()
            .map(|c| find(&format!("{base}_{c}")))
            .collect();
        let n_rgb = rgb.iter().filter(|x| x.is_some()).count();
        match (grey, n_rgb) {
            (Some(_), n) if n > 0 => {
                bail!("{name}:1: give either `{base}` or `{base}_r,{base}_g,{base}_b`, not both")
            }
            (Some(g), _) => Ok(vec![g]),
            (None, 3) => Ok(rgb.into_iter().flatten().collect()),
            (None, 0) => Ok(vec![]),
            (None, _) => {
                bail!("{name}:1: `{base}_r`, `{base}_g` and `{base}_b` must all be present")
            }
        }
    };
    let brdf = group("brdf")?;
    let radiance = group("radiance")?;
    let irradiance = find("irradiance");
    let values = match (brdf.is_empty(), radiance.is_empty()) {
        (false, false) => bail!("{name}:1: give values either as brdf or as radiance, not both"),
        (false, true) => {
            if irradiance.is_some() {
                bail!("{name}:1: column `irradiance` only goes with radiance values, not brdf");
            }
            brdf
        }
        (true, false) => {
            if irradiance.is_none() {
                bail!("{name}:1: radiance values need an `irradiance` column (irradiance perpendicular to the light)");
            }
            radiance
        }
        (true, true) => bail!(
            "{name}:1: no value columns: expected `brdf` (or brdf_r, brdf_g, brdf_b) or `radiance` (or radiance_r, _g, _b) with `irradiance`"
        ),
    };
    let sigma = group("sigma")?;
    if !sigma.is_empty() && sigma.len() != values.len() {
        bail!("{name}:1: sigma columns must match the value columns (grey or r, g, b)");
    }
    let weight = find("weight");
    if weight.is_some() && !sigma.is_empty() {
        bail!("{name}:1: give either sigma or weight, not both");
    }
    Ok(Layout {
        delimiter: Delimiter::Comma,
        angles,
        values,
        irradiance,
        sigma,
        weight,
    })
}

fn field(record: &csv::ByteRecord, i: usize) -> &[u8] {
    record.get(i).unwrap_or(b"")
}

fn number(record: &csv::ByteRecord, i: usize, col: &str) -> std::result::Result<f64, String> {
    let raw = field(record, i).trim_ascii();
    // Parse bytes directly (no UTF-8 pass): this is most of the load time of big files.
    match fast_float2::parse::<f64, _>(raw) {
        Ok(v) if v.is_finite() => Ok(v),
        Ok(_) => Err(format!(
            "column `{col}` is {}; values must be finite numbers",
            String::from_utf8_lossy(raw)
        )),
        Err(_) => Err(format!(
            "column `{col}`: '{}' is not a number",
            String::from_utf8_lossy(raw)
        )),
    }
}

/// Values (BRDF, sigma, weight) beyond this magnitude are refused: their squares would overflow.
const MAX_MAGNITUDE: f64 = 1e100;
/// Sigmas below this are refused: their inverse squares would overflow.
const MIN_SIGMA: f64 = 1e-100;

/// Negative values up to this many standard deviations are noise; beyond, an error.
const NEGATIVE_SIGMAS: f64 = 4.0;
/// Without sigmas, negatives down to this fraction of the largest value are noise.
const NEGATIVE_FRACTION: f64 = 0.01;

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
    let mut state = parse_header(&buf, name, opts)?;
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

/// What one chunk of rows yields.
#[derive(Default)]
struct Chunk {
    samples: Vec<Sample>,
    negatives: Vec<(u64, f64, usize)>,
    skipped: u64,
    examples: Vec<String>,
    error: Option<String>,
}

fn parse_chunk(
    bytes: &[u8],
    first_line: u64,
    lay: &Layout,
    header: &[String],
    name: &str,
    opts: &GonioOptions,
) -> Chunk {
    // rows ~ bytes / bytes per line, so the sample vector is allocated once
    let per_line = memchr::memchr(b'\n', bytes)
        .map_or(bytes.len(), |p| p + 1)
        .max(8);
    let mut out = Chunk {
        samples: Vec::with_capacity(bytes.len() / per_line + 16),
        ..Chunk::default()
    };
    // whitespace-separated lines are read as comma-separated ones (line breaks kept)
    let rewritten;
    let bytes = if lay.delimiter == Delimiter::Whitespace {
        rewritten = commas_for_whitespace(bytes);
        &rewritten[..]
    } else {
        bytes
    };
    let mut reader = csv::ReaderBuilder::new()
        .has_headers(false)
        .delimiter(lay.delimiter.byte())
        .comment(Some(b'#'))
        .flexible(true)
        .from_reader(bytes);
    let mut record = csv::ByteRecord::new();
    let note = |out: &mut Chunk, msg: String| -> bool {
        if opts.skip_bad_rows {
            out.skipped += 1;
            if out.examples.len() < 5 {
                out.examples.push(msg);
            }
            true
        } else {
            out.error = Some(msg);
            false
        }
    };
    loop {
        match reader.read_byte_record(&mut record) {
            Ok(false) => break,
            Ok(true) => {
                // blank lines and indented comments are not rows
                let first = field(&record, 0).trim_ascii_start();
                if first.starts_with(b"#") || (record.len() == 1 && first.is_empty()) {
                    continue;
                }
                let line = first_line + record.position().map(|p| p.line()).unwrap_or(1) - 1;
                match parse_row(&record, lay, header) {
                    Ok((sample, neg)) => {
                        if let Some((value, channel)) = neg {
                            out.negatives.push((line, value, channel));
                        }
                        out.samples.push(Sample {
                            origin: Origin::Line(line),
                            ..sample
                        });
                    }
                    Err(problem) => {
                        if !note(&mut out, format!("{name}:{line}: {problem}")) {
                            return out;
                        }
                    }
                }
            }
            Err(e) => {
                let line = first_line + e.position().map(|p| p.line()).unwrap_or(1) - 1;
                if !note(&mut out, format!("{name}:{line}: malformed row: {e}")) {
                    return out;
                }
            }
        }
    }
    out
}

/// `bytes` with every run of spaces and tabs inside a line replaced by one comma (and the runs
/// at a line's ends dropped), line breaks kept: whitespace-separated rows as CSV rows.
fn commas_for_whitespace(bytes: &[u8]) -> Vec<u8> {
    let mut out = Vec::with_capacity(bytes.len());
    for (k, line) in bytes.split(|&b| b == b'\n').enumerate() {
        if k > 0 {
            out.push(b'\n');
        }
        let mut first = true;
        for word in line
            .split(|b| matches!(b, b' ' | b'\t' | b'\r'))
            .filter(|w| !w.is_empty())
        {
            if !first {
                out.push(b',');
            }
            out.extend_from_slice(word);
            first = false;
        }
    }
    out
}

/// Chunks of whole lines for parallel parsing: (bytes, number of the chunk's first line).
/// Only when no field can span lines (no quote characters); otherwise one chunk.
fn split_lines(body: &[u8], first_line: u64) -> Vec<(&[u8], u64)> {
    const MIN_CHUNK: usize = 1 << 20;
    let parts = rayon::current_num_threads().max(1) * 4;
    if body.len() < 2 * MIN_CHUNK || memchr::memchr(b'"', body).is_some() {
        return vec![(body, first_line)];
    }
    let target = (body.len() / parts).max(MIN_CHUNK);
    let mut chunks = Vec::new();
    let (mut start, mut line) = (0usize, first_line);
    while start < body.len() {
        let mut end = (start + target).min(body.len());
        if end < body.len() {
            end = memchr::memchr(b'\n', &body[end - 1..]).map_or(body.len(), |p| end + p);
        }
        chunks.push((&body[start..end], line));
        line += memchr::memchr_iter(b'\n', &body[start..end]).count() as u64;
        start = end;
    }
    chunks
}

/// End of the header line (after its newline) in `bytes`, once the header is complete.
fn header_end(bytes: &[u8]) -> Option<usize> {
    let bytes_nobom = bytes.strip_prefix(b"\xEF\xBB\xBF").unwrap_or(bytes);
    let bom = bytes.len() - bytes_nobom.len();
    let mut offset = 0;
    loop {
        let p = memchr::memchr(b'\n', &bytes_nobom[offset..])?;
        let l = bytes_nobom[offset..offset + p].trim_ascii();
        if !(l.is_empty() || l.starts_with(b"#")) {
            return Some(bom + offset + p + 1);
        }
        offset += p + 1;
    }
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

fn parse_header(bytes: &[u8], name: &str, opts: &GonioOptions) -> Result<ParseState> {
    // A UTF-8 byte-order mark (spreadsheet exports) is not part of the first column's name.
    let bom = if bytes.starts_with(b"\xEF\xBB\xBF") {
        3
    } else {
        0
    };
    // The header: the first line that is not blank or a comment (indented or not).
    let mut offset = bom;
    let mut line = 1u64;
    let skippable = |rest: &[u8]| {
        let end = memchr::memchr(b'\n', rest).unwrap_or(rest.len());
        let l = rest[..end].trim_ascii();
        !rest.is_empty() && (l.is_empty() || l.starts_with(b"#"))
    };
    while skippable(&bytes[offset..]) {
        match bytes[offset..].iter().position(|&b| b == b'\n') {
            Some(p) => {
                offset += p + 1;
                line += 1;
            }
            None => {
                offset = bytes.len();
            }
        }
    }
    let header_end = bytes[offset..]
        .iter()
        .position(|&b| b == b'\n')
        .map(|p| offset + p + 1)
        .unwrap_or(bytes.len());
    let text = String::from_utf8_lossy(&bytes[offset..header_end]);
    let text = text.trim_end_matches(['\n', '\r']);
    let delimiter = Delimiter::sniff(text);
    let read_header = delimiter.split(text);
    if read_header.is_empty() || (read_header.len() == 1 && read_header[0].is_empty()) {
        bail!("{name}: empty file; expected a header line");
    }
    // the file's own names mapped to ours
    let mut header = read_header.clone();
    let mut mapped = Vec::new();
    for (ours, theirs) in &opts.columns {
        match read_header.iter().position(|h| h == theirs) {
            Some(i) => {
                header[i] = ours.clone();
                mapped.push((theirs.clone(), ours.clone()));
            }
            None => bail!(
                "{name}:{line}: --columns {ours}={theirs}: the header has no column `{theirs}`; \
                 the header read ({}-separated): {}",
                delimiter.name(),
                quoted(&read_header)
            ),
        }
    }
    let mut lay = layout(&header, name).map_err(|e| {
        let msg = e
            .to_string()
            .replacen(&format!("{name}:1:"), &format!("{name}:{line}:"), 1);
        anyhow!(
            "{msg}\n  the header read ({}-separated, {} column{}): {}\n  expected the columns: \
             {}\n  (fibrefit reads comma-, tab-, semicolon- or whitespace-separated files; map \
             the file's own names with --columns OURS=THEIRS,..., e.g. --columns \
             theta_i=theta_in,phi_i=phi_in)",
            delimiter.name(),
            read_header.len(),
            if read_header.len() == 1 { "" } else { "s" },
            quoted(&read_header),
            COLUMNS.join(", ")
        )
    })?;
    lay.delimiter = delimiter;
    Ok(ParseState {
        header,
        format: Format {
            delimiter,
            header: read_header,
            mapped,
        },
        lay,
        body_start: header_end,
        next_line: line + 1,
        samples: Vec::new(),
        negatives: Vec::new(),
        dropped: Dropped::default(),
        examples: Vec::new(),
    })
}

impl ParseState {
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
        if !opts.small_angles_ok {
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
        })
    }
}

/// Names as `a`, `b`, `c` (a long header cut after 12).
fn quoted(names: &[String]) -> String {
    let mut v: Vec<String> = names.iter().take(12).map(|h| format!("`{h}`")).collect();
    if names.len() > 12 {
        v.push(format!("... ({} more)", names.len() - 12));
    }
    v.join(", ")
}

type Negative = Option<(f64, usize)>;

fn parse_row(
    record: &csv::ByteRecord,
    lay: &Layout,
    header: &[String],
) -> std::result::Result<(Sample, Negative), String> {
    if record.len() != header.len() {
        return Err(format!(
            "malformed row: {} fields, the header has {}",
            record.len(),
            header.len()
        ));
    }
    let mut deg = [0.0; 4];
    for k in 0..4 {
        deg[k] = number(record, lay.angles[k], ANGLES[k])?;
    }
    for k in [0, 2] {
        if deg[k] < 0.0 {
            return Err(format!("column `{}` = {} is negative; theta is measured from the normal, in [0, 90) degrees", ANGLES[k], deg[k]));
        }
        if deg[k] >= 90.0 {
            return Err(format!(
                "column `{}` = {} is at or below the horizon; theta must be < 90 degrees",
                ANGLES[k], deg[k]
            ));
        }
    }
    for k in [1, 3] {
        if !(-360.0..=360.0).contains(&deg[k]) {
            return Err(format!(
                "column `{}` = {} is outside [-360, 360] degrees",
                ANGLES[k], deg[k]
            ));
        }
    }
    let cos_i = deg[0].to_radians().cos();
    let scale = match lay.irradiance {
        Some(i) => {
            let e = number(record, i, "irradiance")?;
            if e <= 0.0 {
                return Err(format!("column `irradiance` = {e} must be positive"));
            }
            1.0 / (e * cos_i)
        }
        None => 1.0,
    };
    let mut value = [0.0; 3];
    for (c, &i) in lay.values.iter().enumerate() {
        value[c] = number(record, i, &header[i])? * scale;
        if !(value[c].abs() <= MAX_MAGNITUDE) {
            return Err(format!(
                "column `{}` gives a BRDF of {:e} 1/sr, outside the range fibrefit computes with (|f| <= {MAX_MAGNITUDE:e}){}",
                header[i],
                value[c],
                if lay.irradiance.is_some() { "; check the irradiance" } else { "" }
            ));
        }
    }
    let channels = lay.values.len();
    if channels == 1 {
        value = [value[0]; 3];
    }
    let sigma = if lay.sigma.is_empty() {
        None
    } else {
        let mut s = [0.0; 3];
        for (c, &i) in lay.sigma.iter().enumerate() {
            s[c] = number(record, i, &header[i])?;
            if s[c] <= 0.0 {
                return Err(format!(
                    "column `{}` = {} must be positive",
                    header[i], s[c]
                ));
            }
            s[c] *= scale;
            if !(s[c] >= MIN_SIGMA && s[c] <= MAX_MAGNITUDE) {
                return Err(format!(
                    "column `{}` gives a sigma of {:e} 1/sr, outside [{MIN_SIGMA:e}, {MAX_MAGNITUDE:e}]",
                    header[i], s[c]
                ));
            }
        }
        if channels == 1 {
            s = [s[0]; 3];
        }
        Some(s)
    };
    let weight = match lay.weight {
        Some(i) => {
            let w = number(record, i, "weight")?;
            if !(0.0..=MAX_MAGNITUDE).contains(&w) {
                return Err(format!(
                    "column `weight` = {w} must lie in [0, {MAX_MAGNITUDE:e}]"
                ));
            }
            w
        }
        None => 1.0,
    };
    let mut negative = None;
    for c in 0..channels {
        if value[c] < 0.0 {
            match sigma {
                Some(s) if value[c] < -NEGATIVE_SIGMAS * s[c] => {
                    return Err(format!(
                        "column `{}` = {} is negative beyond noise (more than {NEGATIVE_SIGMAS} sigma)",
                        header[lay.values[c]],
                        value[c]
                    ));
                }
                Some(_) => {}
                None => negative = Some((value[c], c)),
            }
        }
    }
    let sample = Sample {
        l: direction_from_angles(deg[0].to_radians(), deg[1].to_radians()),
        v: direction_from_angles(deg[2].to_radians(), deg[3].to_radians()),
        fibre_azimuth: None,
        map_value: None,
        texel_height: None,
        value,
        sigma,
        weight,
        origin: Origin::Line(0),
    };
    Ok((sample, negative))
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
             fibrefit reads degrees; convert the file, or pass --small-angles-ok if these really are degrees",
            samples.len()
        );
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(text: &str) -> Result<Samples> {
        read(text.as_bytes(), "g.csv", &GonioOptions::default())
    }

    #[test]
    fn byte_order_mark_blank_lines_and_indented_comments_are_not_data() {
        let s = parse(
            "\u{feff}\n  \n  # exported by a spreadsheet\ntheta_i,phi_i,theta_o,phi_o,brdf\n  # indented\n30,0,30,180,0.2\n\n   \n40,10,20,90,0.3\n",
        )
        .unwrap();
        assert_eq!(s.samples.len(), 2);
        assert_eq!(s.samples[0].origin, Origin::Line(6));
        assert_eq!(s.samples[1].origin, Origin::Line(9));
        // and an error after them still names the right line
        let e = parse("\n# c\ntheta_i,phi_i,theta_o,phi_o,brdf\n30,0,30,x,0.2\n")
            .unwrap_err()
            .to_string();
        assert!(e.contains("g.csv:4") && e.contains("phi_o"), "{e}");
    }

    #[test]
    fn brdf_and_radiance_forms_agree() {
        let a = parse("theta_i,phi_i,theta_o,phi_o,brdf\n60,0,10,90,0.2\n").unwrap();
        // radiance = f E cos(theta_i) = 0.2 * 3 * 0.5
        let b =
            parse("theta_i,phi_i,theta_o,phi_o,radiance,irradiance\n60,0,10,90,0.3,3\n").unwrap();
        assert!((a.samples[0].value[0] - b.samples[0].value[0]).abs() < 1e-15);
        assert_eq!(a.channels, 1);
    }

    #[test]
    fn rgb_with_sigma() {
        let s = parse("theta_i,phi_i,theta_o,phi_o,brdf_r,brdf_g,brdf_b,sigma_r,sigma_g,sigma_b\n10,0,20,0,0.1,0.2,0.3,0.01,0.01,0.02\n").unwrap();
        assert_eq!(s.channels, 3);
        assert_eq!(s.samples[0].value, [0.1, 0.2, 0.3]);
        assert_eq!(s.samples[0].sigma, Some([0.01, 0.01, 0.02]));
    }

    #[test]
    fn radians_are_caught() {
        let mut text = String::from("theta_i,phi_i,theta_o,phi_o,brdf\n");
        for i in 0..20 {
            text += &format!(
                "{},{},{},{},0.1\n",
                0.05 * i as f64,
                0.3 * i as f64,
                1.2,
                3.0
            );
        }
        let e = parse(&text).unwrap_err().to_string();
        assert!(e.contains("look like radians"), "{e}");
        assert!(read(
            text.as_bytes(),
            "g.csv",
            &GonioOptions {
                small_angles_ok: true,
                ..Default::default()
            }
        )
        .is_ok());
    }

    #[test]
    fn skipping_counts_bad_rows() {
        let text = "theta_i,phi_i,theta_o,phi_o,brdf\n10,0,10,0,0.1\n10,0,95,0,0.1\n10,x,10,0,0.1\n10,0,10\n20,0,10,0,0.2\n";
        let e = parse(text).unwrap_err().to_string();
        assert!(e.contains("g.csv:3") && e.contains("horizon"), "{e}");
        let s = read(
            text.as_bytes(),
            "g.csv",
            &GonioOptions {
                skip_bad_rows: true,
                ..Default::default()
            },
        )
        .unwrap();
        assert_eq!(s.samples.len(), 2);
        assert_eq!(s.dropped.skipped_rows, 3);
    }

    #[test]
    fn negative_beyond_noise() {
        let e = parse("theta_i,phi_i,theta_o,phi_o,brdf\n10,0,10,0,0.5\n10,0,20,0,-0.2\n")
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("g.csv:3") && e.contains("negative beyond noise"),
            "{e}"
        );
        assert!(
            parse("theta_i,phi_i,theta_o,phi_o,brdf\n10,0,10,0,0.5\n10,0,20,0,-0.001\n").is_ok()
        );
        let e = parse(
            "theta_i,phi_i,theta_o,phi_o,brdf,sigma\n10,0,10,0,0.5,0.01\n10,0,20,0,-0.1,0.01\n",
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("sigma"), "{e}");
    }

    #[test]
    fn delimiters_are_sniffed_and_columns_mapped() {
        let comma =
            parse("theta_i,phi_i,theta_o,phi_o,brdf\n30,0,30,180,0.2\n40,10,20,90,0.3\n").unwrap();
        for (text, d) in [
            ("theta_i\tphi_i\ttheta_o\tphi_o\tbrdf\n30\t0\t30\t180\t0.2\n40\t10\t20\t90\t0.3\n", Delimiter::Tab),
            ("theta_i;phi_i;theta_o;phi_o;brdf\n30;0;30;180;0.2\n40;10;20;90;0.3\n", Delimiter::Semicolon),
            ("# c\ntheta_i  phi_i theta_o phi_o brdf\n  30 0\t  30 180 0.2\n# x y\n40 10 20 90 0.3  \n", Delimiter::Whitespace),
        ] {
            let (s, f) = read_with_format(text.as_bytes(), "g.csv", &GonioOptions::default())
                .unwrap();
            assert_eq!(f.delimiter, d, "{text}");
            assert_eq!(s.samples.len(), 2);
            for (a, b) in s.samples.iter().zip(&comma.samples) {
                assert_eq!((a.l, a.v, a.value), (b.l, b.v, b.value));
            }
        }
        let opts = GonioOptions {
            columns: parse_columns("theta_i=ti, phi_i=pi,theta_o=to,phi_o=po,brdf=f").unwrap(),
            ..Default::default()
        };
        check_columns(&opts.columns).unwrap();
        let (s, f) = read_with_format(
            "ti,pi,to,po,f\n30,0,30,180,0.2\n".as_bytes(),
            "g.csv",
            &opts,
        )
        .unwrap();
        assert_eq!(s.samples[0].value, comma.samples[0].value);
        assert!(f.describe().contains("ti -> theta_i"), "{}", f.describe());
        let e = parse("theta_in,phi_in,theta_out,phi_out,f\n30,0,30,180,0.2\n")
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("unknown column `theta_in`")
                && e.contains("`phi_out`")
                && e.contains("theta_i, phi_i"),
            "{e}"
        );
        assert!(check_columns(&parse_columns("theta=x").unwrap()).is_err());
        assert!(parse_columns("theta_i").is_err());
    }
}
