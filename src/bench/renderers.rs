//! `fibrefit bench renderers [FILE...]`: per route a renderer takes, its error against the data
//! (issue 37's figures). Each data set (default: the shipped felt, silk and brushed sets) is
//! fitted as `fibrefit fit DATA --model auto --metric log` runs it, so every candidate's held-out
//! log error is on the same folds or split: the choice (the exact fibre model: the Mitsuba plugin
//! and the exported shader carry it), `principled` (Blender's own material: `export --blender`),
//! `openpbr` (MaterialX / USD pipelines' OpenPBR Surface: `export --materialx`, `--usd`),
//! `gltf` (web engines' own: `export --gltf`), `ward`; and the old route, the glTF material
//! fitted to the chosen model (`export --gltf` of a non-gltf result), whose error against the data
//! is measured on every sample (it is fitted to the model, not to the data; the choice's own
//! error on every sample stands beside it).

use crate::bench::real::median;
use crate::bench::selection::auto_fit;
use crate::fit::config::Metric;
use crate::fit::selection::Candidate;
use crate::model::frame::{DirectionPair, FibreFrame};
use crate::model::Param;
use anyhow::Result;
use std::path::{Path, PathBuf};

/// The candidates the report names per route (without the fuzz layer: what a renderer's own
/// material can carry).
pub const ROUTES: [&str; 4] = ["principled", "openpbr", "gltf", "ward"];

/// One data set's routes.
#[derive(Clone, Debug)]
pub struct RendererRow {
    pub data: String,
    pub samples: usize,
    pub validation: String,
    /// Every candidate of `--model auto`.
    pub candidates: Vec<Candidate>,
    pub chosen: String,
    /// The old glTF conversion of the chosen fit: (relative RMSE, log error) against every
    /// sample; and the chosen fit's own on every sample.
    pub conversion: Option<(f64, f64)>,
    pub chosen_in_sample: Option<(f64, f64)>,
    pub conversion_error: Option<String>,
    /// Wall time of one fit of each route's rung alone (`fit DATA --model R --metric log`), s,
    /// in [`ROUTES`] order (None: it failed).
    pub route_fit_seconds: Vec<Option<f64>>,
    /// Wall time of the whole run on this data set, s.
    pub seconds: f64,
}

impl RendererRow {
    /// The candidate called `name`.
    pub fn candidate(&self, name: &str) -> Option<&Candidate> {
        self.candidates
            .iter()
            .find(|c| c.name == name && c.error.is_none())
    }
}

/// The default data: the shipped felt (RGL), silk and brushed goniometric tables under `root`.
pub fn default_files(root: &Path) -> Vec<PathBuf> {
    vec![
        root.join("tests/data/rgl/acrylic_felt_green_rgb.bsdf"),
        root.join("data_synthetic/silk/gonio.csv"),
        root.join("data_synthetic/brushed/gonio.csv"),
    ]
}

/// The study on `files` (measured files drawn at `directions` pairs).
pub fn run(
    files: &[PathBuf],
    directions: usize,
    progress: &crate::progress::Progress,
) -> Result<Vec<RendererRow>> {
    let mut rows = Vec::new();
    for f in files {
        let data = crate::bench::real::load_drawn(f, directions)?;
        let name = f
            .parent()
            .filter(|_| f.file_stem().is_some_and(|s| s == "gonio"))
            .and_then(|p| p.file_name())
            .or(f.file_stem())
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_else(|| f.display().to_string());
        progress.line(&format!(
            "bench renderers: {name}, {} samples",
            data.samples.len()
        ));
        let t = std::time::Instant::now();
        let quiet = crate::progress::Progress::quiet();
        let (s, o, cfg, _, _) = auto_fit(&data, false, Some(Metric::Log), &quiet)?;
        // the chosen fit on every sample, and the glTF material fitted to its model
        let refs: Vec<&crate::load::samples::Sample> = data.samples.iter().collect();
        let chosen_in_sample = crate::fit::selection::model_values_on(&o, &cfg, &data)
            .ok()
            .map(|(_, values)| {
                let (_, rel, log) = crate::fit::selection::plain_errors(&values, &refs, o.channels);
                (rel, log)
            });
        let problem = crate::fit::selection::problem_at(&o, &cfg, &data);
        let model = problem.model_for(&o.set);
        let albedos = crate::fit::problem::albedos_of(&o.set);
        let (conversion, conversion_error) =
            match crate::fit::gltf_material::fit(&*model, &albedos, cfg.seed) {
                Ok(m) => {
                    let frame = FibreFrame::from_azimuth(
                        o.set.shape_value(Param::Azimuth).to_radians(),
                    );
                    let values: Vec<[f64; 3]> = data
                        .samples
                        .iter()
                        .map(|x| {
                            let pair = DirectionPair::new(&frame, &x.l, &x.v);
                            if pair.above_horizon() {
                                crate::fit::gltf_material::pbr_brdf(&m.material, &pair)
                            } else {
                                [0.0; 3]
                            }
                        })
                        .collect();
                    let (_, rel, log) =
                        crate::fit::selection::plain_errors(&values, &refs, o.channels);
                    (Some((rel, log)), None)
                }
                Err(e) => (None, Some(format!("{e:#}"))),
            };
        // each route's rung fitted alone, as `fit DATA --model R --metric log` runs it
        let mut auto: crate::fit::config::FitConfig = toml::from_str("model = \"auto\"\n")?;
        auto.metric = Metric::Log;
        let route_fit_seconds = ROUTES
            .iter()
            .map(|r| {
                let id: crate::model::ModelId = r.parse().ok()?;
                let t = std::time::Instant::now();
                crate::fit::fit_with_hints(&data, &auto.for_rung(id), &quiet, &[]).ok()?;
                Some(t.elapsed().as_secs_f64())
            })
            .collect();
        let row = RendererRow {
            data: name,
            route_fit_seconds,
            samples: data.samples.len(),
            validation: s.validation.clone(),
            chosen: s.chosen.clone(),
            candidates: s.candidates,
            conversion,
            chosen_in_sample,
            conversion_error,
            seconds: t.elapsed().as_secs_f64(),
        };
        progress.line(&format!(
            "bench renderers: {}: chose {}, {:.1} s",
            row.data, row.chosen, row.seconds
        ));
        rows.push(row);
    }
    Ok(rows)
}

/// The median fit time of candidate `name` over `rows`, s.
pub fn median_fit_seconds(rows: &[RendererRow], name: &str) -> f64 {
    median(
        rows.iter()
            .filter_map(|r| r.candidate(name).map(|c| c.fit_seconds))
            .collect(),
    )
}
