//! The rows of a goniometric CSV: chunks of whole lines parsed in parallel, each row checked
//! and turned into a [`Sample`].

use super::header::{Delimiter, Layout, ANGLES};
use super::{AngleUnit, GonioOptions, MAX_MAGNITUDE, MIN_SIGMA, NEGATIVE_SIGMAS};
use crate::load::samples::{Origin, Sample};
use crate::model::frame::direction_from_angles;

/// Field `i` of `record` (empty where the row is short).
fn field(record: &csv::ByteRecord, i: usize) -> &[u8] {
    record.get(i).unwrap_or(b"")
}

/// The finite number in field `i` of `record`, `col` naming it in the error.
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



#[derive(Default)]
pub(super) struct Chunk {
    pub samples: Vec<Sample>,
    /// (line, value, channel) of rows with a negative value and no sigma.
    pub negatives: Vec<(u64, f64, usize)>,
    pub skipped: u64,
    pub examples: Vec<String>,
    pub error: Option<String>,
}

/// Parse the rows of `bytes` (whole lines, the first numbered `first_line`): their samples, or
/// the first problem (skipped and counted with `--skip-bad-rows`).
pub(super) fn parse_chunk(
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
pub(super) fn split_lines(body: &[u8], first_line: u64) -> Vec<(&[u8], u64)> {
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

/// A negative value with no sigma to judge it by: (value, channel), judged against the file's
/// largest value once every row is read.
type Negative = Option<(f64, usize)>;

/// The sample of one row (its origin set by the caller), and its negative value if any.
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
    let row = Row {
        record,
        lay,
        header,
    };
    let deg = row.angles()?;
    let cos_i = deg[0].to_radians().cos();
    let scale = row.scale(cos_i)?;
    let value = row.values(scale)?;
    let sigma = row.sigma(scale)?;
    let weight = row.weight()?;
    let negative = row.negative(&value, sigma)?;
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

/// One row of the file, read through its layout.
struct Row<'a> {
    record: &'a csv::ByteRecord,
    lay: &'a Layout,
    header: &'a [String],
}

impl Row<'_> {
    /// theta_i, phi_i, theta_o, phi_o in degrees (converted from the file's unit): thetas in
    /// [0, 90), phis in [-360, 360].
    fn angles(&self) -> std::result::Result<[f64; 4], String> {
        let unit = self.lay.unit;
        let mut raw = [0.0; 4];
        for k in 0..4 {
            raw[k] = number(self.record, self.lay.angles[k], ANGLES[k])?;
        }
        let deg = raw.map(|x| unit.to_degrees(x));
        // the value as the file gives it (and in degrees, when it gives radians)
        let shown = |k: usize| match unit {
            AngleUnit::Deg => format!("{}", raw[k]),
            AngleUnit::Rad => format!("{} rad ({:.3} degrees)", raw[k], deg[k]),
        };
        for k in [0, 2] {
            if deg[k] < 0.0 {
                return Err(format!("column `{}` = {} is negative; theta is measured from the normal, in [0, 90) degrees", ANGLES[k], shown(k)));
            }
            if deg[k] >= 90.0 {
                return Err(format!(
                    "column `{}` = {} is at or below the horizon; theta must be < 90 degrees",
                    ANGLES[k],
                    shown(k)
                ));
            }
        }
        for k in [1, 3] {
            if !(-360.0..=360.0).contains(&deg[k]) {
                return Err(format!(
                    "column `{}` = {} is outside [-360, 360] degrees",
                    ANGLES[k],
                    shown(k)
                ));
            }
        }
        Ok(deg)
    }

    /// What turns the row's values into BRDF values: 1 / (irradiance cos theta_i) for
    /// radiance, 1 for BRDF values.
    fn scale(&self, cos_i: f64) -> std::result::Result<f64, String> {
        Ok(match self.lay.irradiance {
            Some(i) => {
                let e = number(self.record, i, "irradiance")?;
                if e <= 0.0 {
                    return Err(format!("column `irradiance` = {e} must be positive"));
                }
                1.0 / (e * cos_i)
            }
            None => 1.0,
        })
    }

    /// The BRDF value per channel (grey repeated), within [`MAX_MAGNITUDE`].
    fn values(&self, scale: f64) -> std::result::Result<[f64; 3], String> {
        let (lay, header) = (self.lay, self.header);
        let mut value = [0.0; 3];
        for (c, &i) in lay.values.iter().enumerate() {
            value[c] = number(self.record, i, &header[i])? * scale;
            if !(value[c].abs() <= MAX_MAGNITUDE) {
                return Err(format!(
                    "column `{}` gives a BRDF of {:e} 1/sr, outside the range fibrefit computes with (|f| <= {MAX_MAGNITUDE:e}){}",
                    header[i],
                    value[c],
                    if lay.irradiance.is_some() { "; check the irradiance" } else { "" }
                ));
            }
        }
        if lay.values.len() == 1 {
            value = [value[0]; 3];
        }
        Ok(value)
    }

    /// The sigma per channel (grey repeated) in 1/sr, if the file gives sigmas: positive, in
    /// [[`MIN_SIGMA`], [`MAX_MAGNITUDE`]].
    fn sigma(&self, scale: f64) -> std::result::Result<Option<[f64; 3]>, String> {
        let (lay, header) = (self.lay, self.header);
        if lay.sigma.is_empty() {
            return Ok(None);
        }
        let mut s = [0.0; 3];
        for (c, &i) in lay.sigma.iter().enumerate() {
            s[c] = number(self.record, i, &header[i])?;
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
        if lay.values.len() == 1 {
            s = [s[0]; 3];
        }
        Ok(Some(s))
    }

    /// The row's weight in [0, [`MAX_MAGNITUDE`]], 1 without a weight column.
    fn weight(&self) -> std::result::Result<f64, String> {
        Ok(match self.lay.weight {
            Some(i) => {
                let w = number(self.record, i, "weight")?;
                if !(0.0..=MAX_MAGNITUDE).contains(&w) {
                    return Err(format!(
                        "column `weight` = {w} must lie in [0, {MAX_MAGNITUDE:e}]"
                    ));
                }
                w
            }
            None => 1.0,
        })
    }

    /// Negative values: refused beyond [`NEGATIVE_SIGMAS`] sigma; without sigmas, the last
    /// negative channel is returned for judging against the whole file.
    fn negative(
        &self,
        value: &[f64; 3],
        sigma: Option<[f64; 3]>,
    ) -> std::result::Result<Negative, String> {
        let mut negative = None;
        for c in 0..self.lay.values.len() {
            if value[c] < 0.0 {
                match sigma {
                    Some(s) if value[c] < -NEGATIVE_SIGMAS * s[c] => {
                        return Err(format!(
                            "column `{}` = {} is negative beyond noise (more than {NEGATIVE_SIGMAS} sigma)",
                            self.header[self.lay.values[c]],
                            value[c]
                        ));
                    }
                    Some(_) => {}
                    None => negative = Some((value[c], c)),
                }
            }
        }
        Ok(negative)
    }
}
