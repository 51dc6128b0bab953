//! `fibrefit eval`: a model's BRDF and intensity at given directions.

use crate::export::{atomic::Outputs, eval_table};
use crate::load::queries;
use crate::model::frame::{direction_from_angles, FibreFrame};
use crate::model::lambert::preview_intensity;
use crate::model::params::{ModelParams, RawParams};
use crate::model::topology::max_height;
use crate::model::{self, DirectionPair, ModelId};
use anyhow::{anyhow, bail, Context, Result};
use clap::Args;
use rayon::prelude::*;
use std::path::PathBuf;

#[derive(Debug, Args)]
#[command(after_help = "\
PARAMETERS (TOML or JSON; names of MODEL.md §5):
  kd, ks, substrate_albedo, rho_d, rho_s   albedos in [0, 1], grey (0.5) or RGB ([0.5, 0.4, 0.3])
  exponent        Phong exponent e in [1, 1e4]                       (default 1)
  spacing         fibre centre distance d in fibre radii, [2, 20]    (default 2: touching)
  height          climbing height H0 in [0, sqrt(d^2-1)] fibre radii (default 0), or
  elevation_deg   elevation phi in [0, acos(1/d)] degrees
  map_scale       topology map scale s in [0, sqrt(d^2-1)]           (default 0)
  topology_map    grayscale PNG (8/16 bit) or EXR map, relative to the parameter file
  fibre_azimuth_deg  fibre direction psi in [-90, 90] degrees       (default 0: along x)
  alpha_x, alpha_y   Ward roughness in (0.001, 1] (x along the fibres)
  azimuth_spread_deg spread of the fibre directions around psi, [0, 180] degrees
                     (default 0: parallel; 180: isotropic, felt); fibre rungs
  azimuth_nodes      nodes of the spread's quadrature N_psi            (default 16)
  fresnel_ior        Schlick Fresnel factor on the lobe, index in [0, 10] (default 0: off)
  fuzz, fuzz_depth, fuzz_asymmetry
                     fuzz layer over any rung: weight in [0, 50] (grey or RGB), optical
                     depth in [0.001, 10] (default 0: no layer), Henyey-Greenstein g in
                     [-0.9, 0.95] (> 0: forward scattering); README, Optional components
  quadrature_order   specular Gauss-Legendre order N                 (default 16)
  histogram_bins     height histogram bins K                         (default 16)
  two_sided, ambient lambert preview shading of seed 003 (intensity column only)
  model           model id (used when --model is not given)

QUERIES: CSV with header theta_i,phi_i,theta_o,phi_o in degrees (theta from the normal, phi from
the swatch x axis) and optional per-texel columns (the values of recovered maps, `fit --maps`, at
the row's texel): `height`, the H of one texel in fibre radii, which replaces the height
distribution for that row (varying-topology and reference only); `fibre_azimuth_deg`, psi in
[-90, 90] degrees; `kd`, `ks` (grey) or `kd_r,kd_g,kd_b`, `ks_r,ks_g,ks_b` (RGB) in [0, 1].

OUTPUT: the query columns, then brdf,intensity (1/sr; I = f cos theta_i) for grey parameters or
brdf_r,brdf_g,brdf_b,intensity_r,intensity_g,intensity_b for RGB ones.")]
pub struct EvalArgs {
    /// Model id: lambert, max-normal, hast-diffuse, poulin-fournier, varying-topology,
    /// reference, ward [default: the parameter file's `model`]
    #[arg(long, value_name = "ID")]
    pub model: Option<String>,
    /// Parameter file (.toml or .json)
    #[arg(long, value_name = "FILE")]
    pub params: PathBuf,
    /// Query directions (CSV, degrees)
    #[arg(long, value_name = "FILE")]
    pub queries: PathBuf,
    /// Output CSV [default: standard output]. Written atomically: a failed run leaves no file.
    #[arg(long, value_name = "FILE")]
    pub out: Option<PathBuf>,
    /// No progress bar or warnings
    #[arg(long, short)]
    pub quiet: bool,
}

/// A parameter file (TOML, JSON or a fitted result) with its rung (`model`, else the file's),
/// validated; its warnings printed unless `quiet`.
pub(crate) fn load_params(
    path: &std::path::Path,
    model: Option<&str>,
    quiet: bool,
) -> Result<(RawParams, ModelId, ModelParams)> {
    let raw = RawParams::load(path)?;
    let id_text = model
        .map(str::to_string)
        .or_else(|| raw.model.clone())
        .ok_or_else(|| {
            anyhow!(
                "no model given: pass --model ID or set `model` in {}",
                path.display()
            )
        })?;
    let id: ModelId = id_text.parse().map_err(|e: String| anyhow!(e))?;
    let (params, warnings) =
        ModelParams::from_raw(&raw, id).map_err(|e| anyhow!("{}: {e:#}", path.display()))?;
    if !quiet {
        for w in &warnings {
            eprintln!("warning: {}: {w}", path.display());
        }
    }
    Ok((raw, id, params))
}

pub fn run(args: &EvalArgs) -> Result<()> {
    let (raw, id, params) = load_params(&args.params, args.model.as_deref(), args.quiet)?;
    let shading = model::build(id, &params)?;
    let queries = queries::load(&args.queries)?;
    if queries.rows.iter().any(|q| q.height.is_some()) {
        if !id.has_topology() {
            bail!("{}: a `height` column needs a model with a topology (varying-topology or reference), not `{id}`", args.queries.display());
        }
        let h_max = max_height(params.spacing);
        if let Some(q) = queries
            .rows
            .iter()
            .find(|q| q.height.is_some_and(|h| h > h_max * (1.0 + 1e-9)))
        {
            bail!(
                "{}:{}: column `height` = {} exceeds H_max = sqrt(d^2 - 1) = {h_max} for spacing {}",
                args.queries.display(),
                q.line,
                q.height.unwrap_or_default(),
                params.spacing
            );
        }
    }
    // Create the output first: a bad path fails before the work; it is never an input.
    let mut inputs = vec![args.params.clone(), args.queries.clone()];
    inputs.extend(raw.topology_map.iter().cloned());
    let mut outs = Outputs::new(&inputs);
    let out = match &args.out {
        Some(path) => Some(outs.file(path, "--out")?),
        None => None,
    };

    let frame = FibreFrame::from_azimuth(params.fibre_azimuth);
    let albedos = params.albedos;
    // a kd column replaces the substrate's albedo too when it shares kd
    let tied = raw.substrate_albedo.is_none();
    let preview = (id == ModelId::Lambert
        && (params.preview.two_sided || params.preview.ambient > 0.0))
        .then_some(params.preview);
    let bar = crate::progress::bar(queries.rows.len() as u64, "eval", args.quiet);
    let values: Vec<([f64; 3], [f64; 3])> = queries
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
            let mut brdf = [0.0; 3];
            let mut intensity = [0.0; 3];
            for c in 0..3 {
                brdf[c] = basis.brdf(&albedos, c);
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
            queries.rows[bad].fields.join(",")
        );
    }
    let rgb_columns = queries.rows.iter().any(|q| {
        [q.kd, q.ks]
            .iter()
            .flatten()
            .any(|a| a[0] != a[1] || a[1] != a[2])
    });
    let channels = if rgb_columns { 3 } else { albedos.channels() };
    match out {
        Some(id) => {
            eval_table::write(&mut outs.writer(id), &queries, &values, channels)?;
            outs.commit()?;
        }
        None => eval_table::write(&mut std::io::stdout().lock(), &queries, &values, channels)
            .context("standard output")?,
    }
    Ok(())
}
