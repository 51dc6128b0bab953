//! Per-texel map recovery from image captures (`fibrefit fit CAPTURE --maps DIR`): the topology
//! (height H), the fibre direction psi, the albedos kd, ks and, for the `gltf` rung, the lobe's
//! roughness and anisotropy strength per texel, beside the shared global parameters.
//!
//! Two stages:
//! 1. [`global_stage`]: on a seeded sample of texels (`[maps] global_texels`), alternate (a) per
//!    texel, given the globals, the texel's mapped values from its own pixels (one per image):
//!    the nonlinear ones (H in [0, H_max(d)], psi over its period) from a grid (17 heights x 12
//!    azimuths), the best grid minima and the current values each searched by compass (the cost
//!    is kinked in H where occlusion changes) to a coarse step, on a table of model columns
//!    shared by every texel that sees the same directions ([`ColumnTable`]), those that can
//!    still win on to the end with the model itself and damped Gauss–Newton, the mapped
//!    albedos solved linearly (bounded to [0, 1]) at every step; (b) the globals given the maps,
//!    the usual bounded LM with the mapped parameters held fixed, kept only if the cost falls.
//!    Each keeps the current values unless it finds a lower cost, so the cost never rises.
//! 2. [`texel_stage`]: every texel as in (a), independently, from the globals' values (with the
//!    smoothness prior: Jacobi sweeps with the neighbours' previous values), over any band of
//!    rows, so tiles can be fitted apart; [`finish_maps`] assembles the bands.
//!
//! Standard errors per texel are the texel's block of the joint covariance of the globals and the
//! maps: the texel's own (its Jacobian over all its unknowns) plus what the globals' uncertainty
//! moves it by (the Schur-complement term, [`uncertainty`]), scaled by the residual variance over
//! all pixels (N - P degrees of freedom, P counting every texel's unknowns and the globals):
//! honest when the model fits within the noise, large (or infinite) where the images leave a
//! value undetermined, and widened to cover any other minimum or grid value whose cost lies
//! within [`AMBIGUITY_DELTA`] residual variances of the best. An optional smoothness
//! prior (`[maps] smoothness`, off by default) pulls H and psi towards their neighbours' mean.
//!
//! Files: `texel.rs` (one texel's search and errors), `column_table.rs` (the shared model
//! columns), `global_stage.rs` (stage 1 and the globals' widened errors), `texel_stage.rs`
//! (stage 2 and the assembly of bands), `uncertainty.rs` (texel errors with the globals' Schur complement, the globals' widening),
//! `outputs.rs` (the whole recovery, the model at every sample, the result's `method` block); this file: the types, the request check and the
//! helpers they share.

use super::config::{FitConfig, MapsConfig};
use super::parameters::{Component, Param, ParamSet};
use super::problem::{self, bounded_small_lsq, component_index, FitProblem, SampleMaps};
use super::{polish, wrap_azimuth, FitOutcome};
use crate::load::capture_store::CaptureStore;
use crate::load::samples::{DataKind, Origin, Sample, Samples};
use crate::model::frame::FibreFrame;
use crate::model::topology::max_height;
use crate::model::{Basis, DirectionPair, ModelId, ShadingModel};
use anyhow::{bail, Result};
use nalgebra::{DMatrix, DVector};
use rayon::prelude::*;
use std::collections::HashMap;
use std::sync::Arc;

mod column_table;
mod direction_lattice;
mod global_stage;
mod outputs;
mod texel;
mod texel_stage;
mod uncertainty;

use column_table::*;
use direction_lattice::*;
#[cfg_attr(not(feature = "internals"), allow(unused_imports))] // for the tests and benchmarks
pub use direction_lattice::{
    blend_error, lattice_nodes, BlendError, LATTICE_MIN_CELL, LATTICE_STEP_DEG,
};
pub use global_stage::*;
pub use outputs::*;
use texel::*;
pub use texel_stage::*;
pub use uncertainty::GlobalSchur;
use uncertainty::*;

/// A texel whose best cost is above this many times the residual variance the texel stage
/// expects (over its degrees of freedom) searches again from the minima of a grid
/// [`FINE_PSI`] times finer in psi: a chi-square of ~20 degrees of freedom passes 3x its mean
/// about once in 10^5 texels, while a texel of the pinhole benchmark whose true minimum lay
/// between the grid's azimuths was left 20x above it (`reports/camera_resolution.md`).
pub const RESEARCH_ABOVE: f64 = 3.0;
/// Azimuths of the finer grid per azimuth of the grid (3.75 degrees apart).
pub const FINE_PSI: usize = 4;
/// Grid minima a per-texel fit polishes (besides its start).
pub const TEXEL_STARTS: usize = 3;
/// Heights of the per-texel grid, from 0 to H_max.
pub const HEIGHT_GRID: usize = 17;
/// Azimuths of the per-texel grid, every 15 degrees from -90.
pub const PSI_GRID: usize = 12;
/// The lobe's grid per texel (roughness and anisotropy strength maps): roughness values over
/// its bounds x anisotropy strengths over [0, 1], evenly spaced.
pub const LOBE_GRID: [usize; 2] = [9, 6];
/// Other minima are kept up to this many times the ambiguity margin of the expected variance.
pub const MINIMA_MARGIN: f64 = 16.0;
/// Compass search of a texel: every candidate to steps of this fraction of half the grid's
/// spacing, the best on to [`COMPASS_FINE`] (H_max / 1600, 0.075 degrees), then Gauss–Newton.
const COMPASS_COARSE: f64 = 0.125;
const COMPASS_FINE: f64 = 0.02;
/// Gauss–Newton stops when an iteration lowers the cost by less than this fraction.
const GAUSS_NEWTON_GAIN: f64 = 1e-10;
/// Another minimum of a texel within this many residual variances of the best makes the texel
/// ambiguous: its standard errors grow to cover the distance between the minima.
pub const AMBIGUITY_DELTA: f64 = 9.0;

/// One texel's values (external units: H in fibre radii, psi in degrees).
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct TexelValues {
    pub height: f64,
    pub psi: f64,
    pub kd: [f64; 3],
    pub ks: [f64; 3],
    /// The lobe's roughness and anisotropy strength (the `gltf` rung's; 0 for other rungs).
    #[serde(default)]
    pub roughness: f64,
    #[serde(default)]
    pub anisotropy: f64,
}

/// The recovered maps over the capture's pixel grid (texels without pixels are absent).
#[derive(Clone, Debug)]
pub struct TexelMaps {
    /// Width of the capture's pixel grid.
    pub width: usize,
    /// Height of the capture's pixel grid.
    pub height: usize,
    /// (x, y) of each texel with pixels, row-major order.
    pub texels: Vec<(u32, u32)>,
    /// The recovered values of each texel (height in fibre radii, azimuth in degrees, albedos),
    /// same layout as `texels`.
    pub values: Vec<TexelValues>,
    /// Standard errors, same layout (NaN or infinity where undetermined; 0 for values not
    /// mapped).
    pub std_errors: Vec<TexelValues>,
    /// RMS relative residual (model - data) / data over the texel's pixels and channels.
    pub residual: Vec<f64>,
    /// Texels with another minimum within `AMBIGUITY_DELTA` residual variances of the best
    /// (their standard errors widened to cover it), same layout.
    pub ambiguous: Vec<bool>,
    /// Channels of the albedo maps: 1 or 3.
    pub channels: usize,
}

pub struct MapOutcome {
    /// The global fit given the final maps (its uncertainties are conditional on the maps).
    pub global: FitOutcome,
    pub maps: TexelMaps,
    /// Total cost (sum of squared weighted residuals) after each round, the initial global fit
    /// first.
    pub costs: Vec<f64>,
    /// Residual variance per pixel and channel used for the per-texel standard errors.
    pub residual_variance: f64,
    /// Warnings (undetermined texels, rounds exhausted).
    pub warnings: Vec<String>,
}

/// Which values of a texel are free.
#[derive(Clone, Copy, Debug)]
struct Free {
    height: bool,
    psi: bool,
    kd: bool,
    ks: bool,
    roughness: bool,
    anisotropy: bool,
}

impl Free {
    /// Whether the texels have a lobe of their own (a roughness or anisotropy map).
    fn lobe(&self) -> bool {
        self.roughness || self.anisotropy
    }
}

/// Check that the rung of `cfg` can honour every requested map.
pub fn check_request(cfg: &FitConfig, req: &MapsConfig) -> Result<()> {
    let id = cfg.model_id()?;
    if req.requested().is_empty() {
        bail!("--maps: [maps] in the config requests no map; set height, fibre_azimuth, kd, ks, or the lobe's roughness or anisotropy (by the rung's own names: roughness, anisotropy_strength, anisotropic, specular_roughness, specular_roughness_anisotropy) = true");
    }
    if req.height && !id.has_topology() {
        bail!("[maps] height = true: model `{id}` has no fibre topology (use varying-topology or reference)");
    }
    if req.fibre_azimuth && !id.reads(Param::Azimuth) {
        bail!("[maps] fibre_azimuth = true: model `{id}` has no fibre direction");
    }
    if req.ks && !(id.reads(Param::Ks) || id.reads(Param::RhoS)) {
        bail!("[maps] ks = true: model `{id}` has no specular lobe");
    }
    for (role, key) in req.lobe_maps() {
        match id.lobe_param(role) {
            Some(p) if p.name() == key => {}
            Some(p) => bail!(
                "[maps] {key} = true: model `{id}` calls this value `{}`; set {} = true",
                p.name(),
                p.name()
            ),
            None => bail!(
                "[maps] {key} = true: model `{id}` has no such lobe (the renderers' materials \
                 have: {})",
                ModelId::with_lobe_maps()
            ),
        }
    }
    if req.ks && !cfg.components.specular {
        bail!("[maps] ks = true, but [components] specular = false switches the lobe off");
    }
    if !(req.smoothness >= 0.0 && req.smoothness.is_finite()) {
        bail!(
            "[maps] smoothness = {}: must be a finite weight >= 0",
            req.smoothness
        );
    }
    if req.rounds == 0 || req.global_texels == 0 {
        bail!("[maps] rounds and global_texels must be at least 1");
    }
    Ok(())
}

/// Samples grouped by texel, row-major: (texel (x, y) list, sample indices per texel).
type Grouped = (Vec<(u32, u32)>, Vec<Vec<usize>>);

/// A texel's fit: best values, its cost, and the other distinct minima with their costs.
type TexelFit = (TexelValues, f64, Vec<(TexelValues, f64)>);

fn group(samples: &Samples) -> Result<Grouped> {
    if samples.kind != DataKind::Capture {
        bail!("--maps needs an image capture (a capture TOML): per-texel maps come from pixels");
    }
    let mut keyed: Vec<((u32, u32), usize)> = samples
        .samples
        .iter()
        .enumerate()
        .map(|(i, s)| match s.origin {
            Origin::Pixel { x, y, .. } => Ok(((y, x), i)),
            _ => bail!("--maps: sample {i} is not a pixel"),
        })
        .collect::<Result<_>>()?;
    keyed.sort_unstable();
    let (mut texels, mut members): (Vec<(u32, u32)>, Vec<Vec<usize>>) = (vec![], vec![]);
    for ((y, x), i) in keyed {
        if texels.last() != Some(&(x, y)) {
            texels.push((x, y));
            members.push(Vec::new());
        }
        members.last_mut().expect("pushed").push(i);
    }
    Ok((texels, members))
}

/// The globals with the mapped parameters held fixed (their values come from the maps).
fn fix_mapped(set: &ParamSet, req: &MapsConfig) -> ParamSet {
    let mut s = set.clone();
    for sh in &mut s.shapes {
        let mapped = match sh.kind {
            Param::Height | Param::MapScale => req.height,
            Param::Azimuth => req.fibre_azimuth,
            p => p.lobe_role().is_some_and(|r| req.lobe(r)),
        };
        if mapped {
            sh.vary = false;
        }
    }
    for a in &mut s.albedos {
        if (a.component == Component::Diffuse && req.kd)
            || (a.component == Component::Specular && req.ks)
        {
            a.vary = false;
        }
    }
    s
}

fn globals_albedo(set: &ParamSet) -> [[f64; 3]; 4] {
    let mut a = [[0.0; 3]; 4];
    for p in &set.albedos {
        a[component_index(p.component)] = p.value;
    }
    a
}

/// Texels with pixels, their sample indices and neighbours, and the start values from the
/// globals (or the capture's input maps).
struct Layout {
    texels: Vec<(u32, u32)>,
    members: Vec<Vec<usize>>,
    neighbours: Vec<Vec<usize>>,
}

impl Layout {
    fn new(samples: &Samples) -> Result<Self> {
        let (texels, members) = group(samples)?;
        let index: std::collections::HashMap<(u32, u32), usize> =
            texels.iter().enumerate().map(|(i, t)| (*t, i)).collect();
        let neighbours = texels
            .iter()
            .map(|&(x, y)| {
                [(-1i64, 0i64), (1, 0), (0, -1), (0, 1)]
                    .iter()
                    .filter_map(|(dx, dy)| {
                        let (nx, ny) = (x as i64 + dx, y as i64 + dy);
                        (nx >= 0 && ny >= 0)
                            .then(|| index.get(&(nx as u32, ny as u32)).copied())
                            .flatten()
                    })
                    .collect()
            })
            .collect();
        Ok(Self {
            texels,
            members,
            neighbours,
        })
    }

    /// Start values of every texel ([`start_value`]).
    fn start_values(&self, samples: &Samples, set: &ParamSet) -> Vec<TexelValues> {
        self.members
            .iter()
            .map(|m| start_value(&samples.samples[m[0]], set))
            .collect()
    }

    /// The per-texel problems of `ids`, with the smoothness prior from `values` when on.
    fn problems(
        &self,
        samples: &Samples,
        ids: &[usize],
        values: &[TexelValues],
        free: Free,
        smoothness: f64,
    ) -> Vec<Texel> {
        ids.iter()
            .map(|&t| {
                let nbs: Vec<TexelValues> = self.neighbours[t].iter().map(|&j| values[j]).collect();
                Texel::new(
                    self.members[t]
                        .iter()
                        .map(|&i| samples.samples[i].clone())
                        .collect(),
                    free,
                    prior_of(&nbs, smoothness),
                )
            })
            .collect()
    }
}

/// A texel's start: the capture's own maps where it has them (height or topology map, tangent
/// or azimuth map), else the globals `set`; `s` is any of its samples.
fn start_value(s: &Sample, set: &ParamSet) -> TexelValues {
    let d = set.shape_value(Param::Spacing);
    let topo = crate::model::topology::Topology {
        height: set.shape_value(Param::Height),
        map_scale: set.shape_value(Param::MapScale),
        map: None,
    };
    let galb = globals_albedo(set);
    TexelValues {
        height: s
            .texel_height
            .or(s.map_value.map(|mv| topo.texel_height(mv, d)))
            .unwrap_or(topo.height),
        psi: s
            .fibre_azimuth
            .map(|p| p.to_degrees())
            .unwrap_or(set.shape_value(Param::Azimuth)),
        kd: galb[0],
        ks: galb[1],
        roughness: set.lobe_value(crate::model::LobeRole::Roughness),
        anisotropy: set.lobe_value(crate::model::LobeRole::Anisotropy),
    }
}

/// The smoothness prior from the neighbours' values: (weight, mean H, circular mean of the
/// axial azimuths); none when off or without neighbours.
fn prior_of(neighbours: &[TexelValues], smoothness: f64) -> Option<(f64, f64, f64)> {
    (smoothness > 0.0 && !neighbours.is_empty()).then(|| {
        let n = neighbours.len() as f64;
        let hm = neighbours.iter().map(|v| v.height).sum::<f64>() / n;
        let (sx, sy) = neighbours.iter().fold((0.0, 0.0), |(a, b), v| {
            let th = (2.0 * v.psi).to_radians();
            (a + th.cos(), b + th.sin())
        });
        (smoothness, hm, sy.atan2(sx).to_degrees() / 2.0)
    })
}

fn scale_of(s: &Sample) -> [f64; 3] {
    let mut k = [0.0; 3];
    for (c, kc) in k.iter_mut().enumerate() {
        *kc = match s.sigma {
            Some(sig) => 1.0 / sig[c],
            None => s.weight.sqrt(),
        };
    }
    k
}

fn free_of(req: &MapsConfig) -> Free {
    Free {
        height: req.height,
        psi: req.fibre_azimuth,
        kd: req.kd,
        ks: req.ks,
        roughness: req.lobe(crate::model::LobeRole::Roughness),
        anisotropy: req.lobe(crate::model::LobeRole::Anisotropy),
    }
}

/// Unknowns per texel.
fn per_texel_unknowns(free: Free, channels: usize) -> usize {
    usize::from(free.height)
        + usize::from(free.psi)
        + usize::from(free.roughness)
        + usize::from(free.anisotropy)
        + channels * (usize::from(free.kd) + usize::from(free.ks))
}
