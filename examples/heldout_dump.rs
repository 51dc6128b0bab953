//! The samples `bench real` fits, with the fold each is held out in, and each set's floor: the
//! input of `scripts/correction_study.py` (issue 39's probe of smooth corrections).
//!
//!     cargo run --release --features internals --example heldout_dump -- OUTDIR FILE.bsdf [CURET_DIR]
//!
//! Writes OUTDIR/<set>.csv (a goniometric table: theta_i, phi_i, theta_o, phi_o in degrees,
//! brdf_r, brdf_g, brdf_b in 1/sr, and `fold`: the split whose held-out part holds the sample,
//! -1 where it only trains) and OUTDIR/floors.csv (set, samples, floor, the reciprocal floor:
//! what a material can reach, validation). A measured
//! file is drawn as `bench real` draws it (3000 pairs, seed 23, theta up to 78 deg); a CUReT
//! folder gives each of its samples. The splits and the floor are `--model auto`'s (seed 0).
use fibrefit::fit::config::{Metric, Selection};
use fibrefit::fit::floor::{floor_on, Choice, FloorRequest};
use fibrefit::fit::selection::splits_for;
use fibrefit::load::samples::Samples;
use std::io::Write;
use std::path::Path;

fn dump(s: &Samples, dir: &Path, name: &str, floors: &mut std::fs::File) -> anyhow::Result<()> {
    let (splits, validation) = splits_for(s.samples.len(), &Selection::default(), 0)?;
    let mut fold = vec![-1i64; s.samples.len()];
    for (k, split) in splits.iter().enumerate() {
        for &i in &split.test {
            fold[i] = k as i64;
        }
    }
    let mut f = std::io::BufWriter::new(std::fs::File::create(dir.join(format!("{name}.csv")))?);
    writeln!(f, "theta_i,phi_i,theta_o,phi_o,brdf_r,brdf_g,brdf_b,fold")?;
    let angles = |d: &fibrefit::model::frame::Vec3| {
        let phi = d.y.atan2(d.x).to_degrees().rem_euclid(360.0);
        (d.z.clamp(-1.0, 1.0).acos().to_degrees(), phi)
    };
    for (x, k) in s.samples.iter().zip(&fold) {
        let ((ti, pi), (to, po)) = (angles(&x.l), angles(&x.v));
        let [r, g, b] = x.value;
        writeln!(f, "{ti:.9},{pi:.9},{to:.9},{po:.9},{r:e},{g:e},{b:e},{k}")?;
    }
    let run = floor_on(
        s,
        &FloorRequest {
            splits: &splits,
            metric: Metric::Log,
            eps: None,
            seed: 0,
            validation: validation.clone(),
            choice: Choice::default(),
        },
    )?;
    // what a material can reach: the same predictor among the reciprocal charts
    let reciprocal = match run.floor.coordinates.is_reciprocal() {
        true => run.floor.error,
        false => {
            let choice = Choice {
                reciprocal: true,
                ..Choice::default()
            };
            let req = FloorRequest {
                splits: &splits,
                metric: Metric::Log,
                eps: None,
                seed: 0,
                validation: validation.clone(),
                choice,
            };
            floor_on(s, &req)?.floor.error
        }
    };
    writeln!(
        floors,
        "{name},{},{:.6},{reciprocal:.6},\"{validation}\"",
        s.samples.len(),
        run.floor.error
    )?;
    eprintln!(
        "{name}: {} samples, {validation}, floor {:.4}, reciprocal floor {reciprocal:.4}",
        s.samples.len(),
        run.floor.error
    );
    Ok(())
}

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let [dir, file, rest @ ..] = args.as_slice() else {
        anyhow::bail!("usage: heldout_dump OUTDIR FILE.bsdf [CURET_DIR]");
    };
    let dir = Path::new(dir);
    std::fs::create_dir_all(dir)?;
    let mut floors = std::fs::File::create(dir.join("floors.csv"))?;
    writeln!(floors, "set,samples,floor,reciprocal_floor,validation")?;
    let path = Path::new(file);
    let name = path
        .file_stem()
        .map_or("file".into(), |s| s.to_string_lossy().into_owned());
    dump(
        &fibrefit::bench::real::load_drawn(path, 3000)?,
        dir,
        &name,
        &mut floors,
    )?;
    if let Some(curet) = rest.first() {
        for (n, s) in fibrefit::load::curet::load_dir(Path::new(curet))? {
            dump(&s, dir, &format!("curet{n}"), &mut floors)?;
        }
    }
    Ok(())
}
