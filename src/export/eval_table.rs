//! The `fibrefit eval` table: the query columns, then `brdf,intensity` (grey) or
//! `brdf_r,brdf_g,brdf_b,intensity_r,intensity_g,intensity_b` (RGB). BRDF in 1/sr, intensity
//! I = f (N.l) (MODEL.md §1).

use crate::load::queries::Queries;
use anyhow::Result;
use std::io::Write;

/// Per-row values: (brdf per channel, intensity per channel); `channels` is 1 or 3.
pub fn write(
    out: &mut impl Write,
    queries: &Queries,
    values: &[([f64; 3], [f64; 3])],
    channels: usize,
) -> Result<()> {
    let mut w = csv::Writer::from_writer(out);
    let mut header = queries.header.clone();
    if channels == 1 {
        header.extend(["brdf".into(), "intensity".into()]);
    } else {
        for c in ["r", "g", "b"] {
            header.push(format!("brdf_{c}"));
        }
        for c in ["r", "g", "b"] {
            header.push(format!("intensity_{c}"));
        }
    }
    let io = |e: csv::Error| -> anyhow::Error {
        match e.into_kind() {
            csv::ErrorKind::Io(err) => err.into(),
            other => anyhow::anyhow!("{other:?}"),
        }
    };
    w.write_record(&header).map_err(io)?;
    let mut record: Vec<String> = Vec::with_capacity(header.len());
    for (q, (brdf, intensity)) in queries.rows.iter().zip(values) {
        record.clear();
        record.extend(q.fields.iter().cloned());
        record.extend(brdf[..channels].iter().map(|v| v.to_string()));
        record.extend(intensity[..channels].iter().map(|v| v.to_string()));
        w.write_record(&record).map_err(io)?;
    }
    w.flush()?;
    Ok(())
}
