//! `eval`: a model's BRDF and intensity at given directions. [`Evaluation::load`] reads the
//! parameters and queries (so the caller can reserve its outputs knowing every input),
//! [`Evaluation::run`] evaluates them, [`EvalOutcome::write`] writes the table.

use crate::export::eval_table;
use crate::load::queries::{self, Queries};
use crate::model::frame::{direction_from_angles, FibreFrame};
use crate::model::lambert::preview_intensity;
use crate::model::params::{ModelParams, RawParams};
use crate::model::topology::max_height;
use crate::model::{self, DirectionPair, ModelId};
use anyhow::{bail, Result};
use rayon::prelude::*;
use std::path::{Path, PathBuf};

/// A parameter file (TOML, JSON or a fitted result) with its rung (`model`, else the file's),
/// validated; its warnings reported through `progress`, and for a result each value its data
/// did not determine (`parameters.*.determined` false: used as given, not measured).
pub fn load_params(
    path: &std::path::Path,
    model: Option<&str>,
    progress: &crate::progress::Progress,
) -> Result<(RawParams, ModelId, ModelParams)> {
    // a result's values the data did not determine are used as given, and said so
    let undetermined = crate::export::result_json::undetermined_of(path);
    let raw = crate::export::result_json::read_params(path)?;
    let (id, params, warnings) =
        crate::export::result_json::checked_params(&raw, model, &path.display().to_string())?;
    for w in &warnings {
        progress.warn(&format!("{}: {w}", path.display()));
    }
    for u in &undetermined {
        progress.warn(&format!(
            "{}: {}; used as given, not a measurement",
            path.display(),
            crate::fit::determined::warning(u)
        ));
    }
    Ok((raw, id, params))
}

/// Parameters and queries, loaded and checked against each other.
pub struct Evaluation {
    /// The parameter file read (TOML, JSON or a fitted result).
    pub params_file: PathBuf,
    /// The queries file read (CSV of directions, angles in degrees).
    pub queries_file: PathBuf,
    /// The parameter file's values as written (columns of the queries may replace some).
    pub raw: RawParams,
    /// The rung evaluated.
    pub model: ModelId,
    /// The validated parameters of the rung.
    pub params: ModelParams,
    /// The queries, one row per direction pair.
    pub queries: Queries,
}

/// The evaluated queries: per row (BRDF in 1/sr, intensity f cos theta_i) per channel.
pub struct EvalOutcome {
    /// The queries evaluated, in their order.
    pub queries: Queries,
    /// Per query: the BRDF f (1/sr) and the intensity f cos(theta_i) (1/sr), per channel.
    pub values: Vec<([f64; 3], [f64; 3])>,
    /// Channels of the table: 3 when the parameters or any albedo column are RGB, else 1.
    pub channels: usize,
}

impl Evaluation {
    /// Load the parameter file (`model` overrides its rung; warnings through `progress`) and
    /// the queries, refusing a `height` column the rung cannot use or beyond H_max.
    pub fn load(
        params: &Path,
        model: Option<&str>,
        queries: &Path,
        progress: &crate::progress::Progress,
    ) -> Result<Self> {
        let (raw, id, p) = load_params(params, model, progress)?;
        let q = queries::load(queries)?;
        if q.rows.iter().any(|q| q.height.is_some()) {
            if !id.has_topology() {
                bail!("{}: a `height` column needs a model with a topology (varying-topology or reference), not `{id}`", queries.display());
            }
            let h_max = max_height(p.spacing);
            if let Some(row) = q
                .rows
                .iter()
                .find(|r| r.height.is_some_and(|h| h > h_max * (1.0 + 1e-9)))
            {
                bail!(
                    "{}:{}: column `height` = {} exceeds H_max = sqrt(d^2 - 1) = {h_max} for spacing {}",
                    queries.display(),
                    row.line,
                    row.height.unwrap_or_default(),
                    p.spacing
                );
            }
        }
        Ok(Self {
            params_file: params.to_path_buf(),
            queries_file: queries.to_path_buf(),
            raw,
            model: id,
            params: p,
            queries: q,
        })
    }

    /// Every file the evaluation reads (none may be an output).
    pub fn inputs(&self) -> Vec<PathBuf> {
        let mut v = vec![self.params_file.clone(), self.queries_file.clone()];
        v.extend(self.raw.topology_map.iter().cloned());
        v
    }

    /// Evaluate every query (in parallel, with a progress bar).
    pub fn run(self, progress: &crate::progress::Progress) -> Result<EvalOutcome> {
        let (id, params) = (self.model, &self.params);
        let shading = model::build(id, params)?;
        let raw = &self.raw;
        let frame = FibreFrame::from_azimuth(params.fibre_azimuth);
        let albedos = params.albedos;
        // a kd column replaces the substrate's albedo too when it shares kd
        let tied = raw.substrate_albedo.is_none();
        let preview = (id.has(crate::model::Ability::PreviewLighting)
            && (params.preview.two_sided || params.preview.ambient > 0.0))
            .then_some(params.preview);
        let bar = progress.bar(self.queries.rows.len() as u64, "eval");
        let values: Vec<([f64; 3], [f64; 3])> = self
            .queries
            .rows
            .par_iter()
            .map(|q| {
                let l = direction_from_angles(q.theta_i, q.phi_i);
                let v = direction_from_angles(q.theta_o, q.phi_o);
                let pair = match q.fibre_azimuth {
                    Some(psi) => DirectionPair::new(&FibreFrame::from_azimuth(psi), &l, &v),
                    None => DirectionPair::new(&frame, &l, &v),
                };
                let mut albedos = albedos;
                if let Some(kd) = q.kd {
                    albedos.diffuse = kd;
                    if tied {
                        albedos.substrate = kd;
                    }
                }
                if let Some(ks) = q.ks {
                    albedos.specular = ks;
                }
                let basis = match q.height {
                    Some(h) => shading.basis_at_height(&pair, h).unwrap_or_default(),
                    None => shading.basis(&pair),
                };
                let factor = match &params.correction {
                    Some(k) => k.factor(&pair),
                    None => [1.0; 3],
                };
                let mut brdf = [0.0; 3];
                let mut intensity = [0.0; 3];
                for c in 0..3 {
                    brdf[c] = basis.brdf(&albedos, c) * factor[c];
                    intensity[c] = match &preview {
                        Some(p) => albedos.diffuse[c] * preview_intensity(p, l.z),
                        None => model::intensity(brdf[c], &pair),
                    };
                }
                bar.inc(1);
                (brdf, intensity)
            })
            .collect();
        bar.finish_and_clear();
        if let Some(bad) = values
            .iter()
            .position(|(b, i)| b.iter().chain(i).any(|x| !x.is_finite()))
        {
            bail!(
                "model `{id}` gave a non-finite value at query row {} ({})",
                bad + 1,
                self.queries.rows[bad].fields.join(",")
            );
        }
        let rgb_columns = self.queries.rows.iter().any(|q| {
            [q.kd, q.ks]
                .iter()
                .flatten()
                .any(|a| a[0] != a[1] || a[1] != a[2])
        });
        let channels = if rgb_columns { 3 } else { albedos.channels() };
        Ok(EvalOutcome {
            queries: self.queries,
            values,
            channels,
        })
    }
}

impl EvalOutcome {
    /// The table (query columns, then brdf and intensity per channel) as CSV.
    pub fn write(&self, out: &mut impl std::io::Write) -> Result<()> {
        eval_table::write(out, &self.queries, &self.values, self.channels)
    }
}
