//! Direction queries for `fibrefit eval`: CSV with header `theta_i,phi_i,theta_o,phi_o`
//! (degrees, MODEL.md §1) and an optional `height` column (H of one texel, in fibre radii).

use anyhow::{anyhow, bail, Context, Result};
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

pub fn load(path: &Path) -> Result<Queries> {
    let file = std::fs::File::open(path)
        .with_context(|| format!("{}: cannot open query file", path.display()))?;
    read(file, &path.display().to_string())
}

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
    let mut index = [usize::MAX; 5];
    for (i, col) in header.iter().enumerate() {
        let slot = match col.as_str() {
            "theta_i" => 0,
            "phi_i" => 1,
            "theta_o" => 2,
            "phi_o" => 3,
            "height" => 4,
            other => bail!(
                "{name}:1: unknown column `{other}`; expected theta_i, phi_i, theta_o, phi_o and optionally height"
            ),
        };
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
    let mut rows = Vec::new();
    for record in reader.records() {
        let record = record.map_err(|e| {
            let line = e.position().map(|p| p.line()).unwrap_or(0);
            anyhow!("{name}:{line}: malformed row: {e}")
        })?;
        let line = record.position().map(|p| p.line()).unwrap_or(0);
        let number = |slot: usize| -> Result<f64> {
            let col = if slot < 4 { ANGLES[slot] } else { "height" };
            let text = record.get(index[slot]).unwrap_or("");
            let v: f64 = text
                .parse()
                .map_err(|_| anyhow!("{name}:{line}: column `{col}`: '{text}' is not a number"))?;
            if !v.is_finite() {
                bail!("{name}:{line}: column `{col}` is {v}; values must be finite");
            }
            Ok(v)
        };
        let mut angles = [0.0; 4];
        for (slot, a) in angles.iter_mut().enumerate() {
            *a = number(slot)?;
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
            let h = number(4)?;
            if h < 0.0 {
                bail!("{name}:{line}: column `height` = {h} is negative");
            }
            Some(h)
        } else {
            None
        };
        rows.push(Query {
            theta_i: angles[0].to_radians(),
            phi_i: angles[1].to_radians(),
            theta_o: angles[2].to_radians(),
            phi_o: angles[3].to_radians(),
            height,
            fields: record.iter().map(str::to_owned).collect(),
            line,
        });
    }
    if rows.is_empty() {
        bail!("{name}: no query rows after the header");
    }
    Ok(Queries { header, rows })
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
