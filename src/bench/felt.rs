//! `fibrefit bench --felt FILE`: every rung, with and without the fibre-direction spread, under
//! the linear and the log metric, fitted to a measured felt (the RGL database's acrylic felt in
//! `../shared/data/rgl`) on a seeded 80 % of 3000 direction pairs and measured on the other 20 %:
//! relative RMSE and log error (train and held-out), cost per evaluation, fit time, and which
//! rung `--model auto` would choose (log metric: the cheapest within 5 % of the best held-out log
//! error).

use crate::fit::config::FitConfig;
use crate::fit::selection::{heldout, model_values_on};
use crate::load::rgl::MeasuredOptions;
use crate::load::samples::Samples;
use crate::load::{load_data, LoadOptions};
use anyhow::Result;
use indicatif::ProgressBar;
use rand::seq::SliceRandom;
use rand::SeedableRng;
use std::path::Path;
use std::time::Instant;

#[derive(Clone, Debug, serde::Serialize)]
pub struct FeltRow {
    pub rung: String,
    /// "aligned" or "spread".
    pub fibres: String,
    pub metric: String,
    pub free_parameters: usize,
    pub train_relative_rmse: f64,
    pub train_log_error: f64,
    pub heldout_relative_rmse: f64,
    pub heldout_log_error: f64,
    pub ns_per_eval: f64,
    pub fit_seconds: f64,
    pub azimuth_spread_deg: Option<f64>,
    /// Held-out sum of data over sum of model where both theta_i and theta_o exceed 55 deg with
    /// light and view on opposite sides (the grazing forward peak); 1 = matched.
    pub grazing_forward_ratio: f64,
    /// The same where both thetas are below 30 deg.
    pub near_normal_ratio: f64,
    pub chosen: bool,
}

/// (grazing forward, near normal) ratios of data to model sums, all channels.
fn region_ratios(test: &Samples, model: &[[f64; 3]]) -> (f64, f64) {
    let (mut gd, mut gm, mut nd, mut nm) = (0.0, 0.0, 0.0, 0.0);
    for (s, m) in test.samples.iter().zip(model) {
        let (ti, to) = (s.l.z.acos().to_degrees(), s.v.z.acos().to_degrees());
        let opposite = s.l.x * s.v.x + s.l.y * s.v.y < 0.0;
        let (y, f): (f64, f64) = (s.value.iter().sum(), m.iter().sum());
        if ti > 55.0 && to > 55.0 && opposite {
            gd += y;
            gm += f;
        }
        if ti < 30.0 && to < 30.0 {
            nd += y;
            nm += f;
        }
    }
    (gd / gm, nd / nm)
}

fn split(s: &Samples, seed: u64) -> (Samples, Samples) {
    let mut idx: Vec<usize> = (0..s.samples.len()).collect();
    idx.shuffle(&mut rand::rngs::StdRng::seed_from_u64(seed));
    let n_test = s.samples.len() / 5;
    let pick = |ids: &[usize]| Samples {
        samples: ids.iter().map(|&i| s.samples[i].clone()).collect(),
        ..s.clone()
    };
    (pick(&idx[n_test..]), pick(&idx[..n_test]))
}

pub fn run(file: &Path, directions: usize, bar: &ProgressBar) -> Result<Vec<FeltRow>> {
    let data = load_data(
        file,
        &LoadOptions {
            measured: MeasuredOptions {
                directions,
                seed: 0,
                max_theta_deg: 78.0,
            },
            ..Default::default()
        },
    )?;
    let (train, test) = split(&data, 0x5e1ec7);
    let mut rows = Vec::new();
    for metric in ["linear", "log"] {
        let auto: FitConfig =
            toml::from_str(&format!("model = \"auto\"\nmetric = \"{metric}\"\n"))?;
        // the rungs `--model auto` tries by default, cheapest first
        for rung in auto.selection.rungs.iter().map(String::as_str) {
            let id = rung.parse().map_err(|e: String| anyhow::anyhow!(e))?;
            let fibre = !matches!(rung, "lambert" | "ward");
            for spread in if fibre {
                vec![false, true]
            } else {
                vec![false]
            } {
                bar.set_message(format!(
                    "felt: {rung} {metric}{}",
                    if spread { " spread" } else { "" }
                ));
                let mut cfg = auto.for_rung(id);
                if !spread {
                    cfg.parameters.remove("azimuth_spread_deg");
                }
                let t = Instant::now();
                let o = crate::fit::fit(&train, &cfg, true)?;
                let fit_seconds = t.elapsed().as_secs_f64();
                let (_, train_rel, train_log, _) = heldout(&o, &cfg, &train)?;
                let (_, rel, log, ns) = heldout(&o, &cfg, &test)?;
                let (grazing_forward_ratio, near_normal_ratio) =
                    region_ratios(&test, &model_values_on(&o, &cfg, &test)?.1);
                rows.push(FeltRow {
                    rung: rung.into(),
                    fibres: if spread { "spread" } else { "aligned" }.into(),
                    metric: metric.into(),
                    free_parameters: o.statistics.free_parameters,
                    train_relative_rmse: train_rel,
                    train_log_error: train_log,
                    heldout_relative_rmse: rel,
                    heldout_log_error: log,
                    ns_per_eval: ns,
                    fit_seconds,
                    azimuth_spread_deg: o
                        .records
                        .iter()
                        .find(|r| r.name == "azimuth_spread_deg" && !r.fixed)
                        .map(|r| r.value[0]),
                    grazing_forward_ratio,
                    near_normal_ratio,
                    chosen: false,
                });
                bar.inc(1);
            }
        }
    }
    // the auto rule under the log metric, among the log rows (cheapest first = table order)
    let best = rows
        .iter()
        .filter(|r| r.metric == "log")
        .map(|r| r.heldout_log_error)
        .fold(f64::INFINITY, f64::min);
    if let Some(r) = rows
        .iter_mut()
        .find(|r| r.metric == "log" && r.heldout_log_error <= 1.05 * best)
    {
        r.chosen = true;
    }
    Ok(rows)
}

/// Fits the report runs (for the progress bar).
pub fn fit_count() -> u64 {
    2 * (2 + 4 * 2)
}
