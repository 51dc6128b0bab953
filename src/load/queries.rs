//! Direction queries for `fibrefit eval`: CSV with header `theta_i,phi_i,theta_o,phi_o`
//! (degrees, MODEL.md §1) and optional per-texel columns, the values of recovered maps at the
//! row's texel: `height` (H, fibre radii), `fibre_azimuth_deg` (psi, degrees), `kd` and `ks`
//! (grey) or `kd_r,kd_g,kd_b` and `ks_r,ks_g,ks_b` (RGB).

use anyhow::{anyhow, bail, Result};
use std::path::Path;

/// One query row; `fields` keeps the input text so it can be echoed exactly.
#[derive(Clone, Debug, PartialEq)]
pub struct Query {
    /// Radians.
    pub theta_i: f64,
    pub phi_i: f64,
    pub theta_o: f64,
    pub phi_o: f64,
    pub height: Option<f64>,
    /// Radians.
    pub fibre_azimuth: Option<f64>,
    /// Per-channel albedo overrides of the row's texel.
    pub kd: Option<[f64; 3]>,
    pub ks: Option<[f64; 3]>,
    pub fields: Vec<String>,
    /// Line of the file (1: the header).
    pub line: u64,
}

#[derive(Clone, Debug, PartialEq)]
pub struct Queries {
    /// Column names in output order.
    pub header: Vec<String>,
    pub rows: Vec<Query>,
}

const ANGLES: [&str; 4] = ["theta_i", "phi_i", "theta_o", "phi_o"];
/// Every column a query file may have.
const COLUMNS: [&str; 14] = [
    "theta_i",
    "phi_i",
    "theta_o",
    "phi_o",
    "height",
    "fibre_azimuth_deg",
    "kd",
    "kd_r",
    "kd_g",
    "kd_b",
    "ks",
    "ks_r",
    "ks_g",
    "ks_b",
];

pub fn load(path: &Path) -> Result<Queries> {
    let name = path.display().to_string();
    let input = super::input::open_as(path, super::input::MAX_INPUT_BYTES, "query file")?;
    let mut guarded = super::input::LineLimited::new(input, &name);
    let q = read(&mut guarded, &name)?;
    guarded.into_inner().finish()?;
    Ok(q)
}

/// Most rows of one query file: 10 million (each row with its results several hundred bytes of
/// memory; about 4 GB at this limit).
pub const MAX_QUERIES: usize = 10_000_000;

/// Parse queries from any reader; `name` labels errors (`name:line: ...`).
pub fn read(input: impl std::io::Read, name: &str) -> Result<Queries> {
    let mut reader = csv::ReaderBuilder::new()
        .trim(csv::Trim::All)
        .comment(Some(b'#'))
        .from_reader(input);
    let header: Vec<String> = reader
        .headers()
        .map_err(|e| anyhow!("{name}: cannot read the header: {e}"))?
        .iter()
        .map(str::to_owned)
        .collect();
    let index = column_slots(name, &header)?;
    let mut rows = Vec::new();
    for record in reader.records() {
        let record = record.map_err(|e| {
            let line = e.position().map(|p| p.line()).unwrap_or(0);
            anyhow!("{name}:{line}: malformed row: {e}")
        })?;
        let line = record.position().map(|p| p.line()).unwrap_or(0);
        if rows.len() >= MAX_QUERIES {
            bail!("{name}:{line}: more than {MAX_QUERIES} queries; split the file");
        }
        let row = Row {
            name,
            line,
            record: &record,
            index: &index,
        };
        rows.push(row.query()?);
    }
    if rows.is_empty() {
        bail!("{name}: no query rows after the header");
    }
    Ok(Queries { header, rows })
}

/// For every column of [`COLUMNS`], its position in `header` (`usize::MAX`: absent); refused
/// when a column is unknown, repeated or missing, or an albedo is given both grey and RGB or in
/// part.
fn column_slots(name: &str, header: &[String]) -> Result<[usize; COLUMNS.len()]> {
    let mut index = [usize::MAX; COLUMNS.len()];
    for (i, col) in header.iter().enumerate() {
        let slot = COLUMNS.iter().position(|c| c == col).ok_or_else(|| {
            anyhow!(
                "{name}:1: unknown column `{col}`; expected theta_i, phi_i, theta_o, phi_o and optionally {}",
                COLUMNS[4..].join(", ")
            )
        })?;
        if index[slot] != usize::MAX {
            bail!("{name}:1: column `{col}` appears twice");
        }
        index[slot] = i;
    }
    for (slot, col) in ANGLES.iter().enumerate() {
        if index[slot] == usize::MAX {
            bail!("{name}:1: missing column `{col}` (header must hold theta_i, phi_i, theta_o, phi_o, in degrees)");
        }
    }
    for (grey, first) in [(6usize, 7usize), (10, 11)] {
        let rgb = (first..first + 3)
            .filter(|&k| index[k] != usize::MAX)
            .count();
        if index[grey] != usize::MAX && rgb > 0 {
            bail!(
                "{name}:1: give `{}` or `{}`, not both",
                COLUMNS[grey],
                COLUMNS[first..first + 3].join(",")
            );
        }
        if rgb != 0 && rgb != 3 {
            bail!(
                "{name}:1: give all of {}",
                COLUMNS[first..first + 3].join(", ")
            );
        }
    }
    Ok(index)
}

/// One record of a query file, with what its errors name.
struct Row<'a> {
    name: &'a str,
    line: u64,
    record: &'a csv::StringRecord,
    /// [`column_slots`].
    index: &'a [usize; COLUMNS.len()],
}

impl Row<'_> {
    /// The query this row holds, its values checked.
    fn query(&self) -> Result<Query> {
        let (name, line) = (self.name, self.line);
        let index = self.index;
        let mut angles = [0.0; 4];
        for (slot, a) in angles.iter_mut().enumerate() {
            *a = self.number(slot)?;
        }
        for slot in [0, 2] {
            if !(0.0..=180.0).contains(&angles[slot]) {
                bail!(
                    "{name}:{line}: column `{}` = {} is outside [0, 180] degrees",
                    ANGLES[slot],
                    angles[slot]
                );
            }
        }
        let height = if index[4] != usize::MAX {
            let h = self.number(4)?;
            if h < 0.0 {
                bail!("{name}:{line}: column `height` = {h} is negative");
            }
            Some(h)
        } else {
            None
        };
        let fibre_azimuth = if index[5] != usize::MAX {
            let psi = self.number(5)?;
            if !(-90.0..=90.0).contains(&psi) {
                bail!("{name}:{line}: column `fibre_azimuth_deg` = {psi} is outside [-90, 90] degrees");
            }
            Some(psi.to_radians())
        } else {
            None
        };
        let (kd, ks) = (self.albedo(6, 7)?, self.albedo(10, 11)?);
        Ok(Query {
            theta_i: angles[0].to_radians(),
            phi_i: angles[1].to_radians(),
            theta_o: angles[2].to_radians(),
            phi_o: angles[3].to_radians(),
            height,
            fibre_azimuth,
            kd,
            ks,
            fields: self.record.iter().map(str::to_owned).collect(),
            line,
        })
    }

    /// The finite number in column `slot` of [`COLUMNS`].
    fn number(&self, slot: usize) -> Result<f64> {
        let (name, line) = (self.name, self.line);
        let col = COLUMNS[slot];
        let text = self.record.get(self.index[slot]).unwrap_or("");
        let v: f64 = text
            .parse()
            .map_err(|_| anyhow!("{name}:{line}: column `{col}`: '{text}' is not a number"))?;
        if !v.is_finite() {
            bail!("{name}:{line}: column `{col}` is {v}; values must be finite");
        }
        Ok(v)
    }

    /// The albedo in column `grey` or the three from `first`, each in [0, 1]; `None` where the
    /// file has neither.
    fn albedo(&self, grey: usize, first: usize) -> Result<Option<[f64; 3]>> {
        let (name, line) = (self.name, self.line);
        let v = if self.index[grey] != usize::MAX {
            [self.number(grey)?; 3]
        } else if self.index[first] != usize::MAX {
            [
                self.number(first)?,
                self.number(first + 1)?,
                self.number(first + 2)?,
            ]
        } else {
            return Ok(None);
        };
        if let Some(x) = v.iter().find(|x| !(0.0..=1.0).contains(*x)) {
            bail!(
                "{name}:{line}: albedo column `{}` = {x} is outside [0, 1]",
                COLUMNS[grey]
            );
        }
        Ok(Some(v))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(text: &str) -> Result<Queries> {
        read(text.as_bytes(), "q.csv")
    }

    #[test]
    fn reads_degrees_and_optional_height() {
        let q = parse("theta_i,phi_i,theta_o,phi_o,height\n30,90,30,90,0.5\n").unwrap();
        assert_eq!(q.rows.len(), 1);
        assert!((q.rows[0].theta_i - 30f64.to_radians()).abs() < 1e-15);
        assert_eq!(q.rows[0].height, Some(0.5));
    }

    #[test]
    fn errors_name_line_and_column() {
        let e = parse("theta_i,phi_i,theta_o,phi_o\n10,0,10,0\n10,x,10,0\n")
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("q.csv:3") && e.contains("phi_i") && e.contains("'x'"),
            "{e}"
        );
        let e = parse("theta_i,phi_i,theta_o,phi_o\n10,0,NaN,0\n")
            .unwrap_err()
            .to_string();
        assert!(e.contains("q.csv:2") && e.contains("theta_o"), "{e}");
        let e = parse("theta_i,phi_i,theta_o\n10,0,10\n")
            .unwrap_err()
            .to_string();
        assert!(e.contains("missing column `phi_o`"), "{e}");
        let e = parse("theta_i,phi_i,theta_o,phi_o,theta_i\n")
            .unwrap_err()
            .to_string();
        assert!(e.contains("twice"), "{e}");
        let e = parse("theta_i,phi_i,theta_o,phi_o\n10,0,10\n")
            .unwrap_err()
            .to_string();
        assert!(e.contains("q.csv:2") && e.contains("malformed"), "{e}");
        let e = parse("theta_i,phi_i,theta_o,phi_o\n200,0,10,0\n")
            .unwrap_err()
            .to_string();
        assert!(e.contains("outside [0, 180]"), "{e}");
    }
}
