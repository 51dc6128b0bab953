//! The header of a goniometric CSV: its delimiter, the columns it names (mapped by
//! [`GonioOptions::columns`]) and where each column this loader reads stands.

use super::{AngleUnit, GonioOptions, COLUMNS};
use anyhow::{anyhow, bail, Result};

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

    /// The fields of a header line, trimmed and unquoted.
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
    pub(super) fn byte(self) -> u8 {
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

/// Where the columns this loader reads stand in a row.
pub(super) struct Layout {
    pub delimiter: Delimiter,
    pub angles: [usize; 4],
    /// The unit of the angle columns.
    pub unit: AngleUnit,
    /// The value columns (grey, or r, g, b).
    pub values: Vec<usize>,
    pub irradiance: Option<usize>,
    pub sigma: Vec<usize>,
    pub weight: Option<usize>,
}

pub(super) const ANGLES: [&str; 4] = ["theta_i", "phi_i", "theta_o", "phi_o"];

/// The layout of the columns `header` names (ours); refused when a column is unknown, repeated
/// or missing, or the value, sigma and weight columns do not go together.
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
        unit: AngleUnit::Deg,
        values,
        irradiance,
        sigma,
        weight,
    })
}

/// End of the header line (after its newline) in `bytes`, once the header is complete.
pub(super) fn header_end(bytes: &[u8]) -> Option<usize> {
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

/// What a header gives: the names (mapped to ours), the format as read, the layout, and where
/// the rows start.
pub(super) struct Header {
    pub header: Vec<String>,
    pub format: Format,
    pub lay: Layout,
    /// Where the rows start in the first buffer.
    pub body_start: usize,
    /// File line number of the first row.
    pub next_line: u64,
}

/// Read the header: the first line that is not blank or a comment, its delimiter sniffed and
/// the file's own names mapped to ours.
pub(super) fn parse_header(bytes: &[u8], name: &str, opts: &GonioOptions) -> Result<Header> {
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
    lay.unit = opts.angles;
    Ok(Header {
        header,
        format: Format {
            delimiter,
            header: read_header,
            mapped,
        },
        lay,
        body_start: header_end,
        next_line: line + 1,
    })
}

/// Names as `a`, `b`, `c` (a long header cut after 12).
fn quoted(names: &[String]) -> String {
    let mut v: Vec<String> = names.iter().take(12).map(|h| format!("`{h}`")).collect();
    if names.len() > 12 {
        v.push(format!("... ({} more)", names.len() - 12));
    }
    v.join(", ")
}
