//! `fibrefit eval`: a model's BRDF and intensity at given directions ([`crate::api::eval`]).

use crate::api::eval::Evaluation;
use crate::export::atomic::Outputs;
use anyhow::{Context, Result};
use clap::Args;
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
  metallic, roughness, anisotropy_strength, specular_factor, ior, sheen, sheen_roughness
                     gltf: glTF 2.0 metallic-roughness with KHR sheen (grey), anisotropy
                     (across the fibres), specular and ior; kd is the base colour
  gltf_variant       gltf: khronos (the specification, default) or threejs (what three.js
                     r187 renders: docs/web.md); a result's knobs.gltf_variant
  roughness, anisotropic, ior, specular_ior_level, specular_tint, sheen_weight,
  sheen_roughness    principled: Blender 5.0's Principled BSDF as Cycles renders it, by its
                     own names (tints grey; anisotropy across the fibres); kd is Base Color
  specular_roughness, specular_roughness_anisotropy, specular_ior, specular_weight,
  fuzz_weight, fuzz_roughness
                     openpbr: OpenPBR Surface as MaterialX 1.39 renders it, by its own names
                     (colours white; anisotropy across the fibres); kd is base_color
  azimuth_spread_deg spread of the fibre directions around psi, [0, 180] degrees
                     (default 0: parallel; 180: isotropic, felt); fibre rungs
  azimuth_nodes      nodes of the spread's quadrature N_psi            (default 16)
  fresnel_ior        Schlick Fresnel factor on the lobe, index in [0, 10] (default 0: off)
  fuzz, fuzz_depth, fuzz_asymmetry
                     fuzz layer over any rung: weight in [0, 50] (grey or RGB), optical
                     depth in [0.001, 10] (default 0: no layer), Henyey-Greenstein g in
                     [-0.9, 0.95] (> 0: forward scattering); docs/model.md, Optional components
  quadrature_order   specular Gauss-Legendre order N                 (default 16)
  histogram_bins     height histogram bins K                         (default 16)
  two_sided, ambient lambert's two-sided and ambient preview shading (intensity column only)
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
    /// reference, ward, gltf [default: the parameter file's `model`]
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

pub fn run(args: &EvalArgs) -> Result<()> {
    let eval = Evaluation::load(
        &args.params,
        args.model.as_deref(),
        &args.queries,
        &crate::progress::Progress::new(args.quiet),
    )?;
    // the output reserved before the work; it is never an input
    let mut outs = Outputs::new(&eval.inputs());
    let out = match &args.out {
        Some(path) => Some(outs.file(path, "--out")?),
        None => None,
    };
    let outcome = eval.run(&crate::progress::Progress::new(args.quiet))?;
    match out {
        Some(id) => {
            outcome.write(&mut outs.writer(id))?;
            outs.commit()?;
        }
        None => outcome
            .write(&mut std::io::stdout().lock())
            .context("standard output")?,
    }
    Ok(())
}
