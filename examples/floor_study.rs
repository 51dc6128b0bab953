//! Which nonparametric predictor makes the floor (`fit::floor`)? Measures the held-out error
//! (log metric) of k-nearest-neighbour predictors of the data themselves (weighted means and
//! local linear fits), in
//! each embedding, on the folds or split a named rung's fit of the data is measured on, and, for
//! a measured-BRDF file, 3000 directions predicting 1000 others.
//!
//!     cargo run --profile test --example floor_study -- DATA [more DATA ...]
//!
//! DATA: a goniometric table or a measured-BRDF file (3000 directions; 4000 for the 3000 -> 1000
//! comparison). docs/figures.md quotes its figures.
use fibrefit::fit::config::{Metric, Selection};
use fibrefit::fit::floor::knn::ALL;
use fibrefit::fit::floor::{floor_on, Choice, FloorRequest, Method};
use fibrefit::fit::selection::{splits_for, Split};
use fibrefit::load::{load_data, LoadOptions};
use std::path::Path;
use std::time::Instant;

fn main() -> anyhow::Result<()> {
    for arg in std::env::args().skip(1) {
        let path = Path::new(&arg);
        let mut opts = LoadOptions::default();
        let samples = load_data(path, &opts)?;
        let (splits, validation) = splits_for(samples.samples.len(), &Selection::default(), 0)?;
        println!("{arg}: {} samples, {validation}", samples.samples.len());
        study(&samples, &splits, &validation)?;
        if path.extension().is_some_and(|e| e == "bsdf") {
            opts.measured.directions = 4000;
            let more = load_data(path, &opts)?;
            let split = vec![Split {
                train: (0..3000).collect(),
                test: (3000..4000).collect(),
            }];
            println!("{arg}: 3000 directions -> 1000 others");
            study(&more, &split, "3000 -> 1000")?;
        }
    }
    Ok(())
}

fn study(
    samples: &fibrefit::load::samples::Samples,
    splits: &[Split],
    validation: &str,
) -> anyhow::Result<()> {
    for coordinates in std::iter::once(None).chain(ALL.map(Some)) {
        for (k, method) in [
            (8, Method::Weighted { power: 1.0 }),
            (8, Method::Weighted { power: 2.0 }),
            (8, Method::LocalLinear),
            (12, Method::LocalLinear),
            (16, Method::LocalLinear),
            (24, Method::LocalLinear),
        ] {
            {
                let t = Instant::now();
                let run = floor_on(
                    samples,
                    &FloorRequest {
                        splits,
                        metric: Metric::Log,
                        eps: None,
                        seed: 0,
                        validation: validation.into(),
                        choice: Choice {
                            k,
                            method,
                            coordinates,
                            reciprocal: false,
                        },
                    },
                )?;
                let f = &run.floor;
                println!(
                    "  {:<20} k {k:>2} {:<24}: floor {:.4} +/- {:.4} (predictor {:.4}; {:?}; {:.3} s){}",
                    coordinates.map_or("chosen".to_string(), |c| format!("{c:?}")),
                    method.text(),
                    f.error,
                    f.standard_error,
                    f.predictor_error,
                    f.coordinates,
                    t.elapsed().as_secs_f64(),
                    match (&f.reciprocal_pairs, &f.repeated_directions) {
                        (Some(r), _) => format!("  reciprocal pairs {} noise {:.4}", r.pairs, r.noise),
                        (_, Some(r)) => format!("  repeats {} noise {:.4}", r.pairs, r.noise),
                        _ => String::new(),
                    }
                );
            }
        }
    }
    Ok(())
}
