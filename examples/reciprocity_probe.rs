//! How far is a measured file from reciprocal? Evaluates an RGL `.bsdf` at the direction pairs
//! `bench real` draws (3000, seed 23, theta up to 78 deg; both directions within the file's
//! measured incidence) both ways, f(l, v) and f(v, l), and prints the RMS of ln f(l, v) -
//! ln f(v, l) per channel: a reciprocal model's log error on pairs and their swaps is at least
//! half of it (docs/fit-method.md quotes it for the felt).
//!
//!     cargo run --release --features internals --example reciprocity_probe -- FILE.bsdf
use fibrefit::load::rgl::RglBsdf;
use std::path::Path;

fn main() -> anyhow::Result<()> {
    let Some(arg) = std::env::args().nth(1) else {
        anyhow::bail!("usage: reciprocity_probe FILE.bsdf");
    };
    let path = Path::new(&arg);
    let b = RglBsdf::load(path)?;
    let drawn = fibrefit::bench::real::load_drawn(path, 3000)?;
    let (mut sum, mut n) = ([0.0; 3], 0usize);
    for s in &drawn.samples {
        if s.v.z.acos() > b.max_theta_i {
            continue;
        }
        let (a, c) = (b.brdf(&s.l, &s.v), b.brdf(&s.v, &s.l));
        if a.iter().chain(&c).any(|x| !(*x > 0.0)) {
            continue;
        }
        for k in 0..3 {
            sum[k] += (a[k] / c[k]).ln().powi(2);
        }
        n += 1;
    }
    let rms = sum.map(|x| (x / n.max(1) as f64).sqrt());
    let all = (sum.iter().sum::<f64>() / (3 * n.max(1)) as f64).sqrt();
    println!(
        "{arg}: {n} pairs; RMS of ln f(l, v) - ln f(v, l): {:.4}, {:.4}, {:.4} (all channels {all:.4}); \
         no reciprocal model's RMS log error comes below about {:.4}",
        rms[0],
        rms[1],
        rms[2],
        all / 2.0
    );
    Ok(())
}
