//! Per-texel map recovery from image captures (`fibrefit fit CAPTURE --maps DIR`): the topology
//! (height H), the fibre direction psi and the albedos kd, ks per texel, beside the shared
//! global parameters.
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
//! Standard errors per texel come from the texel's Jacobian over all its unknowns, scaled by the
//! residual variance over all pixels (N - P degrees of freedom, P counting every texel's unknowns
//! and the globals): honest when the model fits within the noise, large (or infinite) where the
//! images leave a value undetermined, and widened to cover any other minimum or grid value whose
//! cost lies within [`AMBIGUITY_DELTA`] residual variances of the best. An optional smoothness
//! prior (`[maps] smoothness`, off by default) pulls H and psi towards their neighbours' mean.

use super::config::{FitConfig, MapsConfig};
use super::parameters::{Component, ParamSet, Shape};
use super::problem::{self, bounded_small_lsq, component_index, FitProblem, SampleMaps};
use super::{polish, wrap_azimuth, FitOutcome};
use crate::load::capture_store::CaptureStore;
use crate::load::samples::{DataKind, Origin, Sample, Samples};
use crate::model::frame::FibreFrame;
use crate::model::topology::max_height;
use crate::model::{Basis, DirectionPair, ShadingModel};
use anyhow::{bail, Result};
use nalgebra::{DMatrix, DVector};
use rayon::prelude::*;
use std::collections::HashMap;
use std::sync::{Arc, Mutex};

/// Grid minima a per-texel fit polishes (besides its start).
pub const TEXEL_STARTS: usize = 3;
/// Heights of the per-texel grid, from 0 to H_max.
pub const HEIGHT_GRID: usize = 17;
/// Azimuths of the per-texel grid, every 15 degrees from -90.
pub const PSI_GRID: usize = 12;
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
}

/// The recovered maps over the capture's pixel grid (texels without pixels are absent).
#[derive(Clone, Debug)]
pub struct TexelMaps {
    pub width: usize,
    pub height: usize,
    /// (x, y) of each texel with pixels, row-major order.
    pub texels: Vec<(u32, u32)>,
    pub values: Vec<TexelValues>,
    /// Standard errors, same layout (NaN or infinity where undetermined; 0 for values not
    /// mapped).
    pub std_errors: Vec<TexelValues>,
    /// RMS relative residual (model - data) / data over the texel's pixels and channels.
    pub residual: Vec<f64>,
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
}

/// Check that the rung of `cfg` can honour every requested map.
pub fn check_request(cfg: &FitConfig, req: &MapsConfig) -> Result<()> {
    let id = cfg.model_id()?;
    let names = id.parameter_names();
    if req.requested().is_empty() {
        bail!("--maps: [maps] in the config requests no map; set height, fibre_azimuth, kd or ks = true");
    }
    if req.height && !id.has_topology() {
        bail!("[maps] height = true: model `{id}` has no fibre topology (use varying-topology or reference)");
    }
    if req.fibre_azimuth && !names.contains(&"fibre_azimuth_deg") {
        bail!("[maps] fibre_azimuth = true: model `{id}` has no fibre direction");
    }
    if req.ks && !(names.contains(&"ks") || names.contains(&"rho_s")) {
        bail!("[maps] ks = true: model `{id}` has no specular lobe");
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
            Shape::Height | Shape::MapScale => req.height,
            Shape::Azimuth => req.fibre_azimuth,
            _ => false,
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

/// Everything a per-texel fit needs from the globals.
struct Globals<'m> {
    model: &'m dyn ShadingModel,
    has_topology: bool,
    h_max: f64,
    tied: bool,
    channels: usize,
    /// Global albedo per component index and channel (0 where absent).
    albedo: [[f64; 3]; 4],
    /// Model columns over (H, psi) by the texels' directions ([`ColumnTable`]).
    tables: TableCache,
}

/// Column tables kept at most, and direction sets tracked before giving up (texels whose
/// directions all differ, a pinhole camera's or a point light's, evaluate the model exactly).
const TABLE_ENTRIES: usize = 16;
const TRACKED_KEYS: usize = 4096;
/// Table nodes per grid step: 4 in H (H_max / 64), 16 in psi (0.9375 degrees).
const TABLE_H_PER_GRID: usize = 4;
const TABLE_PSI_PER_GRID: usize = 16;

/// The model columns of a texel's observations over a fine (H, psi) table. They depend only on
/// the observations' light and view directions (and the texel's height or azimuth where those
/// are not mapped): with a directional light and an orthographic camera per image every texel
/// sees the same directions, so one table serves them all. The grid reads its nodes; the coarse
/// searches interpolate it (bilinear, periodic in psi); the final search and every reported
/// value use the model itself.
struct ColumnTable {
    nh: usize,
    np: usize,
    nobs: usize,
    cols: Vec<[f64; 4]>,
}

impl ColumnTable {
    fn dims(free: Free) -> (usize, usize) {
        (
            if free.height {
                (HEIGHT_GRID - 1) * TABLE_H_PER_GRID + 1
            } else {
                1
            },
            if free.psi {
                PSI_GRID * TABLE_PSI_PER_GRID
            } else {
                1
            },
        )
    }

    /// (H, psi) of node (j, k); a fixed value comes from `start`.
    fn node(
        nh: usize,
        np: usize,
        g: &Globals,
        start: &TexelValues,
        j: usize,
        k: usize,
    ) -> (f64, f64) {
        (
            if nh > 1 {
                g.h_max * (j as f64 / (nh - 1) as f64)
            } else {
                start.height
            },
            if np > 1 {
                -90.0 + 180.0 * (k as f64 / np as f64)
            } else {
                start.psi
            },
        )
    }

    fn build(texel: &Texel, g: &Globals, start: &TexelValues) -> Self {
        let (nh, np) = Self::dims(texel.free);
        let mut cols = Vec::with_capacity(nh * np * texel.obs.len());
        for j in 0..nh {
            for k in 0..np {
                let (h, psi) = Self::node(nh, np, g, start, j, k);
                cols.extend(texel.columns(g, h, psi));
            }
        }
        Self {
            nh,
            np,
            nobs: texel.obs.len(),
            cols,
        }
    }

    fn at(&self, j: usize, k: usize) -> &[[f64; 4]] {
        let i = (j * self.np + k) * self.nobs;
        &self.cols[i..i + self.nobs]
    }

    /// Bilinear interpolation at (H, psi).
    fn interpolate(&self, g: &Globals, h: f64, psi: f64) -> Vec<[f64; 4]> {
        let (j0, t) = if self.nh > 1 {
            let f = (h.clamp(0.0, g.h_max) / g.h_max.max(1e-300)) * (self.nh - 1) as f64;
            let j0 = (f.floor() as usize).min(self.nh - 2);
            (j0, f - j0 as f64)
        } else {
            (0, 0.0)
        };
        let (k0, u) = if self.np > 1 {
            let f = (wrap_azimuth(psi) + 90.0) / 180.0 * self.np as f64;
            let k0 = (f.floor() as usize).min(self.np - 1);
            (k0, f - k0 as f64)
        } else {
            (0, 0.0)
        };
        let j1 = (j0 + 1).min(self.nh - 1);
        let k1 = (k0 + 1) % self.np;
        let (a, b, c, d) = (
            self.at(j0, k0),
            self.at(j0, k1),
            self.at(j1, k0),
            self.at(j1, k1),
        );
        (0..self.nobs)
            .map(|o| {
                std::array::from_fn(|m| {
                    (1.0 - t) * ((1.0 - u) * a[o][m] + u * b[o][m])
                        + t * ((1.0 - u) * c[o][m] + u * d[o][m])
                })
            })
            .collect()
    }
}

/// Column tables by direction set: a table is built the second time its directions are met
/// (a set met once, as a pinhole camera's texels each are, is not worth one).
#[derive(Default)]
struct TableCache {
    tables: Mutex<HashMap<Vec<u64>, Option<Arc<ColumnTable>>>>,
}

impl TableCache {
    fn get(&self, key: Vec<u64>, make: impl FnOnce() -> ColumnTable) -> Option<Arc<ColumnTable>> {
        {
            let mut tables = self.tables.lock().expect("table cache");
            match tables.get(&key) {
                Some(Some(t)) => return Some(t.clone()),
                Some(None) => {}
                None => {
                    if tables.len() < TRACKED_KEYS {
                        tables.insert(key, None);
                    }
                    return None;
                }
            }
            let built = tables.values().filter(|t| t.is_some()).count();
            if built >= TABLE_ENTRIES {
                return None;
            }
        }
        let table = Arc::new(make());
        let mut tables = self.tables.lock().expect("table cache");
        let slot = tables.entry(key).or_insert(None);
        Some(slot.get_or_insert_with(|| table.clone()).clone())
    }
}

/// The rung at the globals `set` with the knobs of `cfg` (no map: texels carry their height).
fn rung_of(set: &ParamSet, cfg: &FitConfig) -> Box<dyn ShadingModel> {
    problem::model_for(
        set,
        cfg.knobs.quadrature_order,
        cfg.knobs.histogram_bins,
        cfg.knobs.azimuth_nodes,
        None,
    )
}

impl<'m> Globals<'m> {
    fn of(set: &ParamSet, model: &'m dyn ShadingModel, channels: usize) -> Self {
        Self {
            model,
            has_topology: set.rung.has_topology(),
            h_max: max_height(set.shape_value(Shape::Spacing)),
            tied: set.substrate_tied,
            channels,
            albedo: globals_albedo(set),
            tables: TableCache::default(),
        }
    }
}

/// One texel's problem.
struct Texel {
    /// The texel's samples, one per image.
    obs: Vec<Sample>,
    /// Per observation and channel: residual weight (1/sigma or sqrt(weight)).
    scale: Vec<[f64; 3]>,
    free: Free,
    /// Prior: (weight, neighbour mean of H, neighbour mean of psi) when smoothing.
    prior: Option<(f64, f64, f64)>,
}

impl Texel {
    fn new(obs: Vec<Sample>, free: Free, prior: Option<(f64, f64, f64)>) -> Self {
        Self {
            scale: obs.iter().map(scale_of).collect(),
            obs,
            free,
            prior,
        }
    }

    /// What the grid's columns depend on besides the globals: every observation's directions,
    /// and the texel's height or azimuth where they are fixed.
    fn grid_key(&self, start: &TexelValues) -> Vec<u64> {
        let mut key: Vec<u64> = self
            .obs
            .iter()
            .flat_map(|s| [s.l.x, s.l.y, s.l.z, s.v.x, s.v.y, s.v.z].map(f64::to_bits))
            .collect();
        if !self.free.height {
            key.push(start.height.to_bits());
        }
        if !self.free.psi {
            key.push(start.psi.to_bits());
        }
        key
    }

    /// Columns of every observation at (H, psi).
    fn columns(&self, g: &Globals, h: f64, psi: f64) -> Vec<[f64; 4]> {
        let frame = FibreFrame::from_azimuth(psi.to_radians());
        let pairs: Vec<DirectionPair> = self
            .obs
            .iter()
            .map(|s| DirectionPair::new(&frame, &s.l, &s.v))
            .collect();
        // one texel is one pattern seen in every image: one batch
        let mut bases = vec![Basis::default(); pairs.len()];
        if !(g.has_topology
            && g.model
                .basis_many_at_height(&pairs, h.clamp(0.0, g.h_max), &mut bases))
        {
            g.model.basis_many(&pairs, &mut bases);
        }
        bases
            .iter()
            .map(|b| {
                if g.tied {
                    [b.diffuse + b.substrate, b.specular, 0.0, b.fuzz]
                } else {
                    [b.diffuse, b.specular, b.substrate, b.fuzz]
                }
            })
            .collect()
    }

    /// Albedos of the texel (mapped ones solved linearly, bounded to [0, 1]) and the weighted
    /// residuals, at fixed columns.
    fn solve(&self, g: &Globals, cols: &[[f64; 4]], v: &mut TexelValues) -> Vec<f64> {
        let mapped: Vec<usize> = [(0usize, self.free.kd), (1, self.free.ks)]
            .into_iter()
            .filter(|x| x.1)
            .map(|x| x.0)
            .collect();
        for c in 0..g.channels {
            if mapped.is_empty() {
                break;
            }
            let mut gm = [[0.0f64; 4]; 4];
            let mut hv = [0.0f64; 4];
            for ((s, col), sc) in self.obs.iter().zip(cols).zip(&self.scale) {
                let w2 = sc[c] * sc[c];
                let mut y = s.value[c];
                for (k, x) in col.iter().enumerate() {
                    if !mapped.contains(&k) {
                        y -= g.albedo[k][c] * x;
                    }
                }
                for &a in &mapped {
                    hv[a] += w2 * col[a] * y;
                    for &b in &mapped {
                        gm[a][b] += w2 * col[a] * col[b];
                    }
                }
            }
            let bounds = vec![(0.0, 1.0); mapped.len()];
            let sol = bounded_small_lsq(&gm, &hv, &mapped, &bounds);
            for (&a, x) in mapped.iter().zip(sol) {
                if a == 0 {
                    v.kd[c] = x;
                } else {
                    v.ks[c] = x;
                }
            }
        }
        self.residuals(g, cols, v)
    }

    fn albedo(&self, g: &Globals, v: &TexelValues, k: usize, c: usize) -> f64 {
        match k {
            0 if self.free.kd => v.kd[c],
            1 if self.free.ks => v.ks[c],
            _ => g.albedo[k][c],
        }
    }

    fn residuals(&self, g: &Globals, cols: &[[f64; 4]], v: &TexelValues) -> Vec<f64> {
        let mut r = Vec::with_capacity(self.obs.len() * g.channels + 2);
        for ((s, col), sc) in self.obs.iter().zip(cols).zip(&self.scale) {
            for (c, scale) in sc.iter().enumerate().take(g.channels) {
                let m: f64 = (0..4).map(|k| self.albedo(g, v, k, c) * col[k]).sum();
                r.push(scale * (m - s.value[c]));
            }
        }
        if let Some((w, hm, pm)) = self.prior {
            let sw = w.sqrt();
            if self.free.height {
                r.push(sw * (v.height - hm));
            }
            if self.free.psi {
                r.push(sw * wrap_azimuth(v.psi - pm) / 10.0);
            }
        }
        r
    }

    /// Cost and solved values at nonlinear values `u` (H and/or psi in that order).
    fn cost_at(&self, g: &Globals, base: &TexelValues, u: &[f64]) -> (f64, TexelValues) {
        let (r, v) = self.residuals_at(g, base, u);
        (r.iter().map(|x| x * x).sum(), v)
    }

    /// [`Texel::cost_at`] with the columns interpolated in `table`.
    fn table_cost_at(
        &self,
        g: &Globals,
        base: &TexelValues,
        u: &[f64],
        table: &ColumnTable,
    ) -> (f64, TexelValues) {
        let mut v = self.at_nonlinear(g, base, u);
        let cols = table.interpolate(g, v.height, v.psi);
        let r = self.solve(g, &cols, &mut v);
        (r.iter().map(|x| x * x).sum(), v)
    }

    /// `base` with the nonlinear values `u` (H clamped to [0, H_max], psi wrapped).
    fn at_nonlinear(&self, g: &Globals, base: &TexelValues, u: &[f64]) -> TexelValues {
        let mut v = *base;
        let mut k = 0;
        if self.free.height {
            v.height = u[k].clamp(0.0, g.h_max);
            k += 1;
        }
        if self.free.psi {
            v.psi = wrap_azimuth(u[k]);
        }
        v
    }

    /// Residuals and solved values at nonlinear values `u`.
    fn residuals_at(&self, g: &Globals, base: &TexelValues, u: &[f64]) -> (Vec<f64>, TexelValues) {
        let mut v = self.at_nonlinear(g, base, u);
        let cols = self.columns(g, v.height, v.psi);
        (self.solve(g, &cols, &mut v), v)
    }

    fn nonlinear(&self, v: &TexelValues) -> Vec<f64> {
        let mut u = Vec::new();
        if self.free.height {
            u.push(v.height);
        }
        if self.free.psi {
            u.push(v.psi);
        }
        u
    }

    /// Fit the texel from `start`: a grid over the nonlinear values (17 heights x 12 azimuths),
    /// a coarse compass search from the best [`TEXEL_STARTS`] of its local minima and `start`,
    /// the best of those searched on and polished by damped Gauss–Newton. Returns the best
    /// (never worse than `start`) and the other distinct minima found, best first.
    fn fit(&self, g: &Globals, start: &TexelValues) -> TexelFit {
        let u0 = self.nonlinear(start);
        let (c0, v0) = self.cost_at(g, start, &u0);
        if u0.is_empty() {
            return (v0, c0, vec![]);
        }
        let (th, tp) = ColumnTable::dims(self.free);
        let (nh, np) = (
            if self.free.height { HEIGHT_GRID } else { 1 },
            if self.free.psi { PSI_GRID } else { 1 },
        );
        // grid point (i, j) is table node (i TABLE_H_PER_GRID, j TABLE_PSI_PER_GRID)
        let node_of = |k: usize| {
            (
                (k / np) * if nh > 1 { TABLE_H_PER_GRID } else { 0 },
                (k % np) * if np > 1 { TABLE_PSI_PER_GRID } else { 0 },
            )
        };
        let point = |k: usize| {
            let (j, l) = node_of(k);
            let (h, psi) = ColumnTable::node(th, tp, g, start, j, l);
            let mut v = *start;
            v.height = h;
            v.psi = psi;
            v
        };
        let table = g
            .tables
            .get(self.grid_key(start), || ColumnTable::build(self, g, start));
        let grid: Vec<(f64, TexelValues)> = (0..nh * np)
            .map(|k| {
                let mut v = point(k);
                let r = match &table {
                    Some(t) => {
                        let (j, l) = node_of(k);
                        self.solve(g, t.at(j, l), &mut v)
                    }
                    None => {
                        let cols = self.columns(g, v.height, v.psi);
                        self.solve(g, &cols, &mut v)
                    }
                };
                (r.iter().map(|x| x * x).sum(), v)
            })
            .collect();
        // grid points no 4-neighbour undercuts (the azimuth wraps)
        let mut local: Vec<usize> = (0..nh * np)
            .filter(|&k| {
                let (i, j) = (k / np, k % np);
                let mut nb = Vec::new();
                if i > 0 {
                    nb.push(k - np);
                }
                if i + 1 < nh {
                    nb.push(k + np);
                }
                if np > 1 {
                    nb.push(i * np + (j + 1) % np);
                    nb.push(i * np + (j + np - 1) % np);
                }
                nb.iter().all(|&n| grid[n].0 >= grid[k].0)
            })
            .collect();
        local.sort_by(|a, b| grid[*a].0.total_cmp(&grid[*b].0));
        local.truncate(TEXEL_STARTS);
        // the start competes with the grid minima for the polishes (so the fit is never worse
        // than the start); each is searched to a coarse step, the best of them to the end
        let mut candidates: Vec<(TexelValues, f64)> =
            local.iter().map(|&k| (grid[k].1, grid[k].0)).collect();
        candidates.push((v0, c0));
        candidates.sort_by(|a, b| a.1.total_cmp(&b.1));
        candidates.truncate(TEXEL_STARTS);
        let same = |w: &TexelValues, v: &TexelValues| {
            (!self.free.height || (w.height - v.height).abs() <= 0.02 * g.h_max.max(1e-9))
                && (!self.free.psi || wrap_azimuth(w.psi - v.psi).abs() <= 1.0)
        };
        let mut minima: Vec<(TexelValues, f64)> = Vec::new();
        for (v, c) in candidates {
            // on the table where there is one, then the model's own cost there
            let (v, c) = self.compass(g, start, v, c, (1.0, COMPASS_COARSE), table.as_deref());
            let (v, c) = match table {
                Some(_) => {
                    let (c, v) = self.cost_at(g, start, &self.nonlinear(&v));
                    (v, c)
                }
                None => (v, c),
            };
            match minima.iter_mut().find(|m| same(&m.0, &v)) {
                Some(m) if c < m.1 => *m = (v, c),
                Some(_) => {}
                None => minima.push((v, c)),
            }
        }
        // searched on to the end: every minimum that could still be the best (coarse cost
        // within twice the lowest: a coarse step costs well under one noise variance, the
        // ambiguity margin is nine)
        let lowest = minima.iter().map(|m| m.1).fold(f64::INFINITY, f64::min);
        for m in minima.iter_mut().filter(|m| m.1 <= 2.0 * lowest) {
            let (v, c) = self.compass(g, start, m.0, m.1, (COMPASS_COARSE, COMPASS_FINE), None);
            *m = self.gauss_newton(g, start, v, c);
        }
        minima.sort_by(|a, b| a.1.total_cmp(&b.1));
        let (best, best_cost) = minima.remove(0);
        minima.retain(|m| !same(&m.0, &best));
        // the grid's profiles (best over the other value at each grid height, and at each grid
        // azimuth) count as other candidates too: a flat profile is an undetermined value even
        // where it has no separate minimum
        for i in 0..nh {
            if let Some(k) =
                (0..np).min_by(|a, b| grid[i * np + a].0.total_cmp(&grid[i * np + b].0))
            {
                let (c, v) = grid[i * np + k];
                minima.push((v, c));
            }
        }
        for j in 0..np {
            if let Some(i) =
                (0..nh).min_by(|a, b| grid[a * np + j].0.total_cmp(&grid[b * np + j].0))
            {
                let (c, v) = grid[i * np + j];
                minima.push((v, c));
            }
        }
        (best, best_cost, minima)
    }

    /// A compass search on the nonlinear values from `v` (cost `c`), albedos re-solved at every
    /// point: occlusion makes the cost kinked in H, where Gauss–Newton stalls. Steps halve from
    /// `from` to `to` times (H_max / 32, 3.75 degrees), half the grid's spacing.
    fn compass(
        &self,
        g: &Globals,
        start: &TexelValues,
        v: TexelValues,
        c: f64,
        (from, to): (f64, f64),
        table: Option<&ColumnTable>,
    ) -> (TexelValues, f64) {
        let (mut best, mut best_cost) = (v, c);
        let mut best_u = self.nonlinear(&best);
        let unit: Vec<f64> = (0..best_u.len())
            .map(|k| {
                if self.free.height && k == 0 {
                    g.h_max / 32.0
                } else {
                    3.75
                }
            })
            .collect();
        let mut scale = from;
        for _ in 0..400 {
            if scale < to {
                break;
            }
            let mut moved = false;
            for k in 0..best_u.len() {
                for sign in [1.0, -1.0] {
                    let mut u = best_u.clone();
                    u[k] += sign * scale * unit[k];
                    let (c, v) = match table {
                        Some(t) => self.table_cost_at(g, start, &u, t),
                        None => self.cost_at(g, start, &u),
                    };
                    if c < best_cost {
                        (best_cost, best) = (c, v);
                        best_u = self.nonlinear(&v);
                        moved = true;
                        break;
                    }
                }
            }
            if !moved {
                scale *= 0.5;
            }
        }
        (best, best_cost)
    }

    /// Damped Gauss–Newton on the nonlinear values from `v` (cost `c`); albedos re-solved at
    /// every point.
    fn gauss_newton(
        &self,
        g: &Globals,
        start: &TexelValues,
        v: TexelValues,
        c: f64,
    ) -> (TexelValues, f64) {
        let (mut best, mut best_cost) = (v, c);
        let mut best_u = self.nonlinear(&best);
        let n = best_u.len();
        let (mut r0, _) = self.residuals_at(g, start, &best_u);
        let mut lambda = 1e-3;
        for _ in 0..30 {
            let mut jac = DMatrix::zeros(r0.len(), n);
            for k in 0..n {
                let mut u = best_u.clone();
                let mut step = if self.free.height && k == 0 {
                    1e-4 * g.h_max.max(1e-3)
                } else {
                    1e-3
                };
                if self.free.height && k == 0 && u[0] + step > g.h_max {
                    step = -step;
                }
                u[k] += step;
                let (r, _) = self.residuals_at(g, start, &u);
                for (i, (a, b)) in r.iter().zip(&r0).enumerate() {
                    jac[(i, k)] = (a - b) / step;
                }
            }
            let jt = jac.transpose();
            let a = &jt * &jac;
            let grad = &jt * DVector::from_vec(r0.clone());
            let mut improved = false;
            for _ in 0..8 {
                let mut m = a.clone();
                for k in 0..n {
                    m[(k, k)] += lambda * a[(k, k)].max(1e-12);
                }
                let Some(step) = m.cholesky().map(|ch| ch.solve(&(-&grad))) else {
                    lambda *= 10.0;
                    continue;
                };
                let u: Vec<f64> = best_u.iter().zip(step.iter()).map(|(x, d)| x + d).collect();
                let (r, v) = self.residuals_at(g, start, &u);
                let c: f64 = r.iter().map(|x| x * x).sum();
                if c < best_cost {
                    let gain = (best_cost - c) / best_cost.max(1e-300);
                    (best_cost, best, r0) = (c, v, r);
                    best_u = self.nonlinear(&v);
                    lambda = (lambda * 0.3).max(1e-9);
                    improved = gain > GAUSS_NEWTON_GAIN;
                    break;
                }
                lambda *= 10.0;
            }
            if !improved {
                break;
            }
        }
        (best, best_cost)
    }

    /// Standard errors of the texel's unknowns from its Jacobian over all of them (nonlinear by
    /// differences, albedos analytic), scaled by `variance`.
    fn std_errors(&self, g: &Globals, v: &TexelValues, variance: f64) -> TexelValues {
        let mut se = TexelValues::default();
        let (jcols, which) = self.jacobian(g, v);
        let p = jcols.len();
        let mut jtj: DMatrix<f64> = DMatrix::zeros(p, p);
        for a in 0..p {
            for b in 0..p {
                jtj[(a, b)] = jcols[a].iter().zip(&jcols[b]).map(|(x, y)| x * y).sum();
            }
        }
        let cov = jtj.try_inverse();
        for (k, &(kind, c)) in which.iter().enumerate() {
            let s = match &cov {
                Some(m) if m[(k, k)] >= 0.0 => (variance * m[(k, k)]).sqrt(),
                _ => f64::INFINITY,
            };
            match kind {
                0 => se.height = s,
                1 => se.psi = s,
                2 => se.kd[c] = s,
                _ => se.ks[c] = s,
            }
        }
        se
    }

    /// The Jacobian of the texel's residuals (its pixels' rows, then any prior rows) over its
    /// unknowns (nonlinear by differences, albedos analytic), one column each, with what each
    /// column is: (0 height | 1 psi | 2 kd | 3 ks, channel).
    fn jacobian(&self, g: &Globals, v: &TexelValues) -> (Vec<Vec<f64>>, Vec<(u8, usize)>) {
        let cols = self.columns(g, v.height, v.psi);
        let r0 = self.residuals(g, &cols, v);
        let mut jcols: Vec<Vec<f64>> = Vec::new();
        let mut which: Vec<(u8, usize)> = Vec::new();
        let diff = |h: f64, psi: f64, step: f64| -> Vec<f64> {
            let mut w = *v;
            w.height = h;
            w.psi = psi;
            let c = self.columns(g, h, psi);
            let r = self.residuals(g, &c, &w);
            r.iter().zip(&r0).map(|(a, b)| (a - b) / step).collect()
        };
        if self.free.height {
            let step = 1e-5
                * g.h_max.max(1e-3)
                * if v.height + 1e-5 * g.h_max > g.h_max {
                    -1.0
                } else {
                    1.0
                };
            jcols.push(diff(v.height + step, v.psi, step));
            which.push((0, 0));
        }
        if self.free.psi {
            jcols.push(diff(v.height, v.psi + 1e-4, 1e-4));
            which.push((1, 0));
        }
        for (kind, comp, on) in [(2u8, 0usize, self.free.kd), (3, 1, self.free.ks)] {
            if !on {
                continue;
            }
            for c in 0..g.channels {
                let mut col = vec![0.0; r0.len()];
                for (i, (cl, sc)) in cols.iter().zip(&self.scale).enumerate() {
                    col[i * g.channels + c] = sc[c] * cl[comp];
                }
                jcols.push(col);
                which.push((kind, c));
            }
        }
        (jcols, which)
    }

    /// RMS relative residual over the texel's pixels and channels.
    fn relative_residual(&self, g: &Globals, v: &TexelValues) -> f64 {
        let cols = self.columns(g, v.height, v.psi);
        let (mut s, mut n) = (0.0, 0.0);
        for (o, col) in self.obs.iter().zip(&cols) {
            for c in 0..g.channels {
                let m: f64 = (0..4).map(|k| self.albedo(g, v, k, c) * col[k]).sum();
                s += ((m - o.value[c]) / o.value[c].abs().max(1e-12)).powi(2);
                n += 1.0;
            }
        }
        (s / n).sqrt()
    }
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
    let d = set.shape_value(Shape::Spacing);
    let topo = crate::model::topology::Topology {
        height: set.shape_value(Shape::Height),
        map_scale: set.shape_value(Shape::MapScale),
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
            .unwrap_or(set.shape_value(Shape::Azimuth)),
        kd: galb[0],
        ks: galb[1],
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
    }
}

/// Unknowns per texel.
fn per_texel_unknowns(free: Free, channels: usize) -> usize {
    usize::from(free.height)
        + usize::from(free.psi)
        + channels * (usize::from(free.kd) + usize::from(free.ks))
}

/// Stage 1: the globals, from alternating fits on a seeded sample of texels.
pub struct GlobalStage {
    /// The global fit given the sample's maps (uncertainties conditional on them).
    pub outcome: FitOutcome,
    /// Cost over the sampled texels: the plain global fit's, then after each round.
    pub costs: Vec<f64>,
    /// Residual variance per pixel value over the sampled texels, every unknown counted: what
    /// the texel stage expects of the whole capture ([`texel_stage`]'s `variance_hint`).
    pub texel_variance: f64,
    pub warnings: Vec<String>,
}

/// Stage 1 of map recovery: the global parameters, alternating per-texel fits and the global
/// LM on `[maps] global_texels` seeded texels until their cost stops falling.
pub fn global_stage(
    store: &CaptureStore,
    cfg: &FitConfig,
    req: &MapsConfig,
    quiet: bool,
) -> Result<GlobalStage> {
    check_request(cfg, req)?;
    if cfg.metric != super::config::Metric::Linear {
        bail!("--maps fits captures with the linear metric; set metric = \"linear\"");
    }
    let free = free_of(req);
    // the texels of the global stage, and the plain global fit on their pixels
    let chosen = store.sample_texels(req.global_texels, cfg.seed ^ 0x6d61_7073);
    // texel by texel (the order the stage was measured with: reports/maps_accuracy.md)
    let mut sub = store.samples_of(&[]);
    sub.samples = chosen
        .iter()
        .flat_map(|&t| store.texel_samples(t))
        .collect();
    let sub_layout = Layout::new(&sub)?;
    let first = super::fit(&sub, cfg, quiet)?;
    let mut set = fix_mapped(&first.set, req);
    let mut values = sub_layout.start_values(&sub, &set);
    let all: Vec<usize> = (0..sub_layout.texels.len()).collect();
    let bar = crate::progress::bar(req.rounds as u64, "maps: globals", quiet);
    let mut costs = vec![first.statistics.chi_square];
    let mut warnings = Vec::new();
    let mut converged = false;
    for round in 0..req.rounds {
        // per texel given the globals
        let model = rung_of(&set, cfg);
        let g = Globals::of(&set, model.as_ref(), sub.channels);
        let problems = sub_layout.problems(&sub, &all, &values, free, req.smoothness);
        let fitted: Vec<(TexelValues, f64)> = problems
            .par_iter()
            .zip(values.par_iter())
            .map(|(p, v)| {
                let r = p.fit(&g, v);
                (r.0, r.1)
            })
            .collect();
        values = fitted.iter().map(|x| x.0).collect();
        let after_texels: f64 = fitted.iter().map(|x| x.1).sum();
        // the globals given the maps; kept if the cost falls
        let (_, new_set) =
            global_given_maps(&sub, cfg, &set, &values, &sub_layout.members, &all, free)?;
        let total_new = if new_set != set {
            total_cost(&sub, cfg, &new_set, &values, &sub_layout.members, free)?
        } else {
            f64::INFINITY
        };
        let before = *costs.last().expect("non-empty");
        let now = if total_new < after_texels {
            set = new_set;
            total_new
        } else {
            after_texels
        };
        costs.push(now);
        bar.inc(1);
        if round > 0 && before - now <= 1e-6 * before {
            converged = true;
            break;
        }
    }
    bar.finish_and_clear();
    if !converged {
        warnings.push(format!(
            "map recovery: the cost of the global stage was still falling after {} rounds ([maps] rounds); the globals may not be final",
            req.rounds
        ));
    }
    let mut outcome = final_global(&sub, cfg, &set, &values, &sub_layout.members, free)?;
    // the globals' errors with the sampled texels' maps free too
    let inflation = map_inflation(&sub, &sub_layout, cfg, &set, &values, free)?;
    if let Some(w) = inflate_records(&mut outcome, &set, &inflation) {
        warnings.push(w);
    }
    let st = &outcome.statistics;
    let unknowns =
        per_texel_unknowns(free, sub.channels) * sub_layout.texels.len() + st.free_parameters;
    let texel_variance = st.chi_square / st.n.saturating_sub(unknowns).max(1) as f64;
    outcome.warnings.push(format!(
        "the global parameters come from {} sampled texels ([maps] global_texels) and their maps; their uncertainties include those texels' maps being free (joint covariance)",
        sub_layout.texels.len()
    ));
    Ok(GlobalStage {
        outcome,
        costs,
        texel_variance,
        warnings,
    })
}

/// How much each free global's variance grows when the sampled texels' maps are free as well:
/// the joint normal matrix of globals and texels is block-arrow shaped (each texel's unknowns
/// touch only its own pixels), so the globals' block of the joint covariance is the inverse of
/// the Schur complement S = A - sum_t B_t C_t^-1 B_t^T (A = J_g^T J_g, B_t = J_g,t^T J_t,
/// C_t = J_t^T J_t). Returns diag(S^-1) / diag(A^-1) per column of the global fit's full
/// parameter vector (free shapes, then free albedo channels); infinity where S is singular
/// there (the maps and that global trade off completely).
fn map_inflation(
    sub: &Samples,
    layout: &Layout,
    cfg: &FitConfig,
    set: &ParamSet,
    values: &[TexelValues],
    free: Free,
) -> Result<Vec<f64>> {
    let (subset, maps) = mapped_all(sub, values, &layout.members, free);
    let p = problem_on(cfg, set, &subset, maps);
    let cols = p.columns(set)?;
    let jg = p.full_jacobian(set, &cols)?;
    let ch = p.channels();
    let a = jg.transpose() * &jg;
    let mut schur = a.clone();
    let model = rung_of(set, cfg);
    let g = Globals::of(set, model.as_ref(), ch);
    let all: Vec<usize> = (0..layout.texels.len()).collect();
    let mut row = 0;
    for (t, texel) in layout
        .problems(sub, &all, values, free, 0.0)
        .iter()
        .enumerate()
    {
        let rows = texel.obs.len() * ch;
        let (jt, _) = texel.jacobian(&g, &values[t]);
        let jt = DMatrix::from_fn(rows, jt.len(), |i, k| jt[k][i]);
        let b = jg.rows(row, rows).transpose() * &jt;
        if let Some(ci) = (jt.transpose() * &jt).try_inverse() {
            schur -= &b * ci * b.transpose();
        }
        row += rows;
    }
    if row != jg.nrows() {
        bail!(
            "internal: the texels' rows ({row}) do not cover the global fit's ({})",
            jg.nrows()
        );
    }
    let (ai, si) = (a.try_inverse(), schur.try_inverse());
    Ok((0..jg.ncols())
        .map(|k| match (&ai, &si) {
            (Some(ai), Some(si)) if ai[(k, k)] > 0.0 && si[(k, k)] > 0.0 => {
                (si[(k, k)] / ai[(k, k)]).max(1.0)
            }
            _ => f64::INFINITY,
        })
        .collect())
}

/// Widen the global records' standard errors by the square root of `inflation` (per column of
/// the full parameter vector, as [`map_inflation`] gives it); a warning when any grows more than
/// twofold.
fn inflate_records(outcome: &mut FitOutcome, set: &ParamSet, inflation: &[f64]) -> Option<String> {
    let mut col = 0;
    let mut worst: (f64, String) = (1.0, String::new());
    let mut widen = |r: &mut super::ParamRecord, c: usize, f: f64| {
        // parameters at a bound have no standard error to widen
        if r.std_error[c].is_some() && f > worst.0 {
            worst = (f, r.name.clone());
        }
        r.std_error[c] = if f.is_finite() {
            r.std_error[c].map(|e| e * f.sqrt())
        } else {
            None
        };
    };
    let n_shapes = set.shapes.len();
    for (i, sh) in set.shapes.iter().enumerate() {
        if sh.vary {
            widen(&mut outcome.records[i], 0, inflation[col]);
            col += 1;
        }
    }
    for (i, a) in set.albedos.iter().enumerate() {
        if a.vary {
            for c in 0..outcome.records[n_shapes + i].std_error.len() {
                widen(&mut outcome.records[n_shapes + i], c, inflation[col]);
                col += 1;
            }
        }
    }
    (worst.0 > 4.0).then(|| {
        let factor = if worst.0.is_finite() {
            format!("{:.0} times", worst.0.sqrt())
        } else {
            "without bound".to_string()
        };
        format!(
            "the global parameters trade off with the maps: with the texels' values free too, the standard error of `{}` grows {factor} (the errors reported include that); per-texel errors do not include the globals' uncertainty, so treat them as too small: add light and view directions that separate the maps from the globals",
            worst.1
        )
    })
}

/// Sweeps of the per-texel stage with the smoothness prior on (the first without it).
pub const PRIOR_SWEEPS: usize = 2;

/// Stage 2 over some rows: every texel fitted independently given the globals (with the prior,
/// [`PRIOR_SWEEPS`] Jacobi sweeps after the first), standard errors before scaling by the
/// residual variance, which needs every row ([`finish_maps`]).
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize, PartialEq)]
pub struct TexelPart {
    /// Rows [first, last) of the capture this part covers.
    pub rows: [u32; 2],
    pub texels: Vec<(u32, u32)>,
    pub values: Vec<TexelValues>,
    /// sqrt of the diagonal of (J^T J)^-1 per value (infinity where singular).
    pub unscaled_std_errors: Vec<TexelValues>,
    /// Other minima of each texel: (cost above the best, |dH|, |dpsi| in degrees), those
    /// costing less than `minima_below` above the best (all when `None`).
    pub other_minima: Vec<Vec<[f64; 3]>>,
    #[serde(default)]
    pub minima_below: Option<f64>,
    pub residual: Vec<f64>,
    /// Per row of the part: (sum of squared weighted residuals, residual count).
    pub row_costs: Vec<(f64, usize)>,
}

/// Stage 2 for the texels in rows [`rows.0`, `rows.1`) given the globals `set`, texel by
/// texel from the compact store (no texel's samples are made before it is fitted, none kept
/// after).
///
/// `variance_hint` is the residual variance the global stage expects ([`GlobalStage`]): other
/// minima costing more than [`MINIMA_MARGIN`] x [`AMBIGUITY_DELTA`] of it above the best are
/// not kept (at camera resolution they are most of the memory); infinity keeps every one.
pub fn texel_stage(
    store: &CaptureStore,
    cfg: &FitConfig,
    req: &MapsConfig,
    set: &ParamSet,
    rows: (u32, u32),
    variance_hint: f64,
    quiet: bool,
) -> Result<TexelPart> {
    let minima_below = (variance_hint.is_finite() && variance_hint > 0.0)
        .then_some(MINIMA_MARGIN * AMBIGUITY_DELTA * variance_hint);
    check_request(cfg, req)?;
    let free = free_of(req);
    let set = fix_mapped(set, req);
    let model = rung_of(&set, cfg);
    let g = Globals::of(&set, model.as_ref(), store.channels);
    let sweeps = if req.smoothness > 0.0 {
        1 + PRIOR_SWEEPS
    } else {
        1
    };
    // a halo of one row per later sweep makes a part's texels what a single run gives
    let halo = (sweeps - 1) as u32;
    let lo = rows.0.saturating_sub(halo);
    let hi = rows.1.saturating_add(halo);
    let texels = store.texels();
    // texels are row-major: those of rows [lo, hi) are the ids [t0, t1)
    let t0 = texels.partition_point(|t| t.1 < lo);
    let t1 = texels.partition_point(|t| t.1 < hi);
    let start_of = |t: usize| -> TexelValues {
        let s = (0..store.images())
            .find_map(|k| store.sample(t, k))
            .expect("a stored texel has a sample");
        start_value(&s, &set)
    };
    let start: Vec<TexelValues> = (t0..t1).into_par_iter().map(start_of).collect();
    let neighbours = |t: usize| -> Vec<usize> {
        let (x, y) = (texels[t].0 as i64, texels[t].1 as i64);
        [(-1i64, 0i64), (1, 0), (0, -1), (0, 1)]
            .iter()
            .filter_map(|(dx, dy)| store.texel_at(x + dx, y + dy))
            .collect()
    };
    let problem = |t: usize, values: &[TexelValues], smoothness: f64| -> Texel {
        let nbs: Vec<TexelValues> = neighbours(t)
            .into_iter()
            .map(|j| match j.checked_sub(t0) {
                Some(k) if j < t1 => values[k],
                _ => start_of(j),
            })
            .collect();
        Texel::new(store.texel_samples(t), free, prior_of(&nbs, smoothness))
    };
    let mut values = start.clone();
    let bar = crate::progress::bar((sweeps * (t1 - t0)) as u64, "maps: texels", quiet);
    let kept = |t: usize| (rows.0..rows.1).contains(&texels[t].1);
    // per texel: best values, cost, other minima (pruned; last sweep, kept texels only)
    let mut fits: Vec<(TexelValues, f64, Vec<[f64; 3]>)> = Vec::new();
    for sweep in 0..sweeps {
        let smoothness = if sweep == 0 { 0.0 } else { req.smoothness };
        let last = sweep + 1 == sweeps;
        fits = (t0..t1)
            .into_par_iter()
            .map(|t| {
                let (v, cost, others) = problem(t, &values, smoothness).fit(&g, &start[t - t0]);
                bar.inc(1);
                let others = if last && kept(t) {
                    prune_minima(&v, cost, &others, minima_below.unwrap_or(f64::INFINITY))
                } else {
                    vec![]
                };
                (v, cost, others)
            })
            .collect();
        for (k, f) in fits.iter().enumerate() {
            values[k] = f.0;
        }
    }
    bar.finish_and_clear();
    let smoothness = req.smoothness * f64::from(u8::from(sweeps > 1));
    let keep: Vec<usize> = (t0..t1).filter(|&t| kept(t)).collect();
    // standard errors before scaling, relative residual, residual count
    let details: Vec<(TexelValues, f64, usize)> = keep
        .par_iter()
        .map(|&t| {
            let p = problem(t, &values, smoothness);
            let v = &fits[t - t0].0;
            (
                p.std_errors(&g, v, 1.0),
                p.relative_residual(&g, v),
                p.obs.len() * store.channels,
            )
        })
        .collect();
    let n_rows = (rows.1 - rows.0) as usize;
    let mut row_costs = vec![(0.0, 0usize); n_rows];
    for (&t, d) in keep.iter().zip(&details) {
        let r = &mut row_costs[(texels[t].1 - rows.0) as usize];
        r.0 += fits[t - t0].1;
        r.1 += d.2;
    }
    Ok(TexelPart {
        rows: [rows.0, rows.1],
        texels: keep.iter().map(|&t| texels[t]).collect(),
        values: keep.iter().map(|&t| fits[t - t0].0).collect(),
        unscaled_std_errors: details.iter().map(|d| d.0).collect(),
        other_minima: keep
            .iter()
            .map(|&t| std::mem::take(&mut fits[t - t0].2))
            .collect(),
        residual: details.iter().map(|d| d.1).collect(),
        minima_below,
        row_costs,
    })
}

/// The other minima of a texel fitted to `v` at `cost`, those at most `below` above it, as
/// (cost above the best, |dH|, |dpsi| in degrees), keeping only those no other one dominates
/// (as good or better in cost and as far or farther in both H and psi): [`finish_maps`] widens
/// the standard errors by the farthest minimum within a cost margin, which the kept ones give
/// for any margin.
fn prune_minima(
    v: &TexelValues,
    cost: f64,
    others: &[(TexelValues, f64)],
    below: f64,
) -> Vec<[f64; 3]> {
    let all: Vec<[f64; 3]> = others
        .iter()
        .filter(|(_, c)| c - cost <= below)
        .map(|(w, c)| {
            [
                c - cost,
                (w.height - v.height).abs(),
                wrap_azimuth(w.psi - v.psi).abs(),
            ]
        })
        .collect();
    let mut kept: Vec<[f64; 3]> = Vec::new();
    for (i, a) in all.iter().enumerate() {
        let dominated = all.iter().enumerate().any(|(j, b)| {
            j != i && b[0] <= a[0] && b[1] >= a[1] && b[2] >= a[2] && (b != a || j < i)
        });
        if !dominated {
            kept.push(*a);
        }
    }
    kept
}

/// Assemble parts covering every row into the maps: the residual variance over all pixel values
/// less every unknown (each texel's and `global_free` globals'), the standard errors scaled by
/// it and widened where another minimum is as good within [`AMBIGUITY_DELTA`] variances.
pub fn finish_maps(
    parts: Vec<TexelPart>,
    width: usize,
    height: usize,
    channels: usize,
    req: &MapsConfig,
    global_free: usize,
    h_max: f64,
) -> Result<(TexelMaps, f64, Vec<String>)> {
    let free = free_of(req);
    let mut parts = parts;
    parts.sort_by_key(|p| p.rows[0]);
    let mut next = 0u32;
    for p in &parts {
        if p.rows[0] != next {
            bail!(
                "the map parts do not cover rows {next}..{} exactly (a part starts at row {})",
                height,
                p.rows[0]
            );
        }
        next = p.rows[1];
    }
    if next as usize != height {
        bail!("the map parts end at row {next}, the capture has {height} rows");
    }
    // sums in row order: the same bits however the rows were split
    let (mut cost, mut n) = (0.0, 0usize);
    for p in &parts {
        for &(c, k) in &p.row_costs {
            cost += c;
            n += k;
        }
    }
    let texels: usize = parts.iter().map(|p| p.texels.len()).sum();
    let params = per_texel_unknowns(free, channels) * texels + global_free;
    if n <= params {
        bail!("--maps: {n} pixel values cannot determine {params} unknowns; use more images");
    }
    let variance = cost / (n - params) as f64;
    let scale = variance.sqrt();
    let mut maps = TexelMaps {
        width,
        height,
        texels: Vec::with_capacity(texels),
        values: Vec::with_capacity(texels),
        std_errors: Vec::with_capacity(texels),
        residual: Vec::with_capacity(texels),
        channels,
    };
    let mut ambiguous = 0;
    let mut minima_cut = false;
    // each part moved into the maps and dropped, so the maps never exist twice
    for mut p in parts {
        minima_cut |= p
            .minima_below
            .is_some_and(|b| b < AMBIGUITY_DELTA * variance);
        for k in 0..p.texels.len() {
            let u = &p.unscaled_std_errors[k];
            let mut se = TexelValues {
                height: u.height * scale,
                psi: u.psi * scale,
                kd: u.kd.map(|x| x * scale),
                ks: u.ks.map(|x| x * scale),
            };
            let mut amb = false;
            for &[dc, dh, dp] in &p.other_minima[k] {
                if dc <= AMBIGUITY_DELTA * variance {
                    amb = true;
                    if free.height {
                        se.height = se.height.max(dh);
                    }
                    if free.psi {
                        se.psi = se.psi.max(dp);
                    }
                }
            }
            ambiguous += usize::from(amb);
            maps.std_errors.push(se);
        }
        maps.texels.append(&mut p.texels);
        maps.values.append(&mut p.values);
        maps.residual.append(&mut p.residual);
    }
    let mut warnings = Vec::new();
    if minima_cut {
        warnings.push(format!(
            "the residual variance over every pixel ({variance:.3e}) is far above what the global stage's texels gave: other minima beyond {MINIMA_MARGIN} x {AMBIGUITY_DELTA} of that were not kept, so some ambiguous texels may not be flagged; raise [maps] global_texels"
        ));
    }
    let undetermined = |pick: fn(&TexelValues) -> f64, half_range: f64| {
        maps.std_errors
            .iter()
            .filter(|e| !(pick(e) < half_range))
            .count()
    };
    for (on, name, count, range) in [
        (
            free.height,
            "height H",
            undetermined(|e| e.height, h_max / 2.0),
            "H_max / 2",
        ),
        (
            free.psi,
            "fibre azimuth",
            undetermined(|e| e.psi, 45.0),
            "45 deg",
        ),
    ] {
        if on && count > 0 {
            warnings.push(format!(
                "the images leave the {name} undetermined in {count} of {texels} texels (standard error at or above {range}): add light and view directions that separate it (grazing light across the fibres, views on both sides), or set [maps] smoothness"
            ));
        }
    }
    if ambiguous > 0 {
        warnings.push(format!(
            "{ambiguous} of {texels} texels have another minimum within {AMBIGUITY_DELTA} residual variances of the best (a height or fibre azimuth fitting the images as well): their standard errors cover the distance between the minima"
        ));
    }
    Ok((maps, variance, warnings))
}

/// Recover the maps `req` asks for, with the globals of `cfg`: [`global_stage`], then
/// [`texel_stage`] over every row and [`finish_maps`].
/// The outcome's `fitted` values are those of the global stage's samples (`global.fitted`
/// follows their order); [`fitted_all`] gives any others.
pub fn recover(
    store: &CaptureStore,
    cfg: &FitConfig,
    req: &MapsConfig,
    quiet: bool,
) -> Result<MapOutcome> {
    let stage = global_stage(store, cfg, req, quiet)?;
    let (w, h) = (store.width, store.height);
    let part = texel_stage(
        store,
        cfg,
        req,
        &stage.outcome.set,
        (0, h as u32),
        stage.texel_variance,
        quiet,
    )?;
    let global_free = stage.outcome.statistics.free_parameters;
    let h_max = max_height(stage.outcome.set.shape_value(Shape::Spacing));
    let (maps, variance, mut warnings) =
        finish_maps(vec![part], w, h, store.channels, req, global_free, h_max)?;
    warnings.splice(0..0, stage.warnings.iter().cloned());
    let global = stage.outcome;
    Ok(MapOutcome {
        global,
        maps,
        costs: stage.costs,
        residual_variance: variance,
        warnings,
    })
}

/// The model at every pixel (sample order) with its texel's values and the globals `set`.
pub fn fitted_all(
    samples: &Samples,
    cfg: &FitConfig,
    req: &MapsConfig,
    set: &ParamSet,
    maps: &TexelMaps,
) -> Result<Vec<[f64; 3]>> {
    let layout = Layout::new(samples)?;
    let index: HashMap<(u32, u32), usize> = maps
        .texels
        .iter()
        .enumerate()
        .map(|(i, t)| (*t, i))
        .collect();
    let values = layout
        .texels
        .iter()
        .map(|t| match index.get(t) {
            Some(&i) => Ok(maps.values[i]),
            None => bail!(
                "the maps do not belong to these samples (no texel ({}, {}))",
                t.0,
                t.1
            ),
        })
        .collect::<Result<Vec<_>>>()?;
    let set = fix_mapped(set, req);
    let (subset, smaps) = mapped_all(samples, &values, &layout.members, free_of(req));
    let p = problem_on(cfg, &set, &subset, smaps);
    let values = p.model_values(&p.columns(&set)?, &set);
    let mut fitted = vec![[0.0; 3]; samples.samples.len()];
    for (i, v) in layout.members.iter().flatten().zip(values) {
        fitted[*i] = v;
    }
    Ok(fitted)
}

/// [`mapped_samples`] of every texel.
fn mapped_all(
    samples: &Samples,
    values: &[TexelValues],
    members: &[Vec<usize>],
    free: Free,
) -> (Vec<Sample>, SampleMaps) {
    let all: Vec<usize> = (0..members.len()).collect();
    mapped_samples(samples, values, members, &all, free)
}

/// Copies of the samples of `texel_ids` with each texel's azimuth (when mapped), and the
/// per-sample map values for a [`FitProblem`].
fn mapped_samples(
    samples: &Samples,
    values: &[TexelValues],
    members: &[Vec<usize>],
    texel_ids: &[usize],
    free: Free,
) -> (Vec<Sample>, SampleMaps) {
    let mut out = Vec::new();
    let (mut hs, mut kd, mut ks) = (Vec::new(), Vec::new(), Vec::new());
    for &t in texel_ids {
        for &i in &members[t] {
            let mut s = samples.samples[i].clone();
            if free.psi {
                s.fibre_azimuth = Some(values[t].psi.to_radians());
            }
            out.push(s);
            hs.push(values[t].height);
            kd.push(values[t].kd);
            ks.push(values[t].ks);
        }
    }
    let mut maps = SampleMaps::default();
    if free.height {
        maps.height = Some(hs);
    }
    if free.kd {
        maps.albedo[0] = Some(kd);
    }
    if free.ks {
        maps.albedo[1] = Some(ks);
    }
    (out, maps)
}

fn problem_on<'a>(
    cfg: &FitConfig,
    set: &ParamSet,
    subset: &'a [Sample],
    maps: SampleMaps,
) -> FitProblem<'a> {
    FitProblem::new(
        subset.iter().collect(),
        set.clone(),
        cfg.metric,
        cfg.knobs.quadrature_order,
        cfg.knobs.histogram_bins,
        None,
        cfg.optimizer.separable,
    )
    .with_azimuth_nodes(cfg.knobs.azimuth_nodes)
    .with_sample_maps(Arc::new(maps))
}

/// Stage 2: LM from the current globals on the texels `order`, maps fixed.
fn global_given_maps(
    samples: &Samples,
    cfg: &FitConfig,
    set: &ParamSet,
    values: &[TexelValues],
    members: &[Vec<usize>],
    order: &[usize],
    free: Free,
) -> Result<(f64, ParamSet)> {
    let (subset, maps) = mapped_samples(samples, values, members, order, free);
    let p = problem_on(cfg, set, &subset, maps);
    if p.dim() == 0 {
        return Ok((f64::NAN, set.clone()));
    }
    let bar = indicatif::ProgressBar::hidden();
    let (theta, cost, _) = polish::run_lm(
        &p,
        set,
        p.theta_of(set),
        cfg.optimizer.max_iterations,
        cfg.optimizer.tolerance,
        &bar,
    )?;
    let mut new = p.set_at(&theta, set);
    if p.separable {
        let cols = p.columns(&new)?;
        p.solve_albedos(&cols, &mut new);
    }
    Ok((cost, new))
}

/// Sum of squared weighted residuals over every pixel at `set` and the maps.
fn total_cost(
    samples: &Samples,
    cfg: &FitConfig,
    set: &ParamSet,
    values: &[TexelValues],
    members: &[Vec<usize>],
    free: Free,
) -> Result<f64> {
    let (subset, maps) = mapped_all(samples, values, members, free);
    let p = problem_on(cfg, set, &subset, maps);
    let cols = p.columns(set)?;
    Ok(p.residuals(&cols, set).norm_squared())
}

/// The global outcome at `set` given the maps of the texels `members` (held fixed); refused when
/// their pixels cannot determine every texel's unknowns and the globals.
fn final_global(
    samples: &Samples,
    cfg: &FitConfig,
    set: &ParamSet,
    values: &[TexelValues],
    members: &[Vec<usize>],
    free: Free,
) -> Result<FitOutcome> {
    let (subset, maps) = mapped_all(samples, values, members, free);
    let p = problem_on(cfg, set, &subset, maps);
    let view = Samples {
        samples: subset.clone(),
        channels: samples.channels,
        kind: samples.kind,
        source: samples.source.clone(),
        dropped: samples.dropped.clone(),
        skipped_examples: samples.skipped_examples.clone(),
        image_size: samples.image_size,
    };
    let cost = {
        let cols = p.columns(set)?;
        p.residuals(&cols, set).norm_squared()
    };
    let mut outcome =
        super::finish::finish(&p, &view, set.channels, &[(set.clone(), cost)], vec![])?;
    let per_texel = usize::from(free.height)
        + usize::from(free.psi)
        + set.channels * (usize::from(free.kd) + usize::from(free.ks));
    let n = p.residual_count();
    let params = per_texel * members.len() + p.dim();
    if n <= params {
        bail!(
            "--maps: {n} pixel values cannot determine {params} unknowns ({per_texel} per texel and {} globals); use more images",
            p.dim()
        );
    }
    // the outcome's fitted values follow the subset order; put them back in sample order
    let mut fitted = vec![[0.0; 3]; samples.samples.len()];
    let mut k = 0;
    for m in members {
        for &i in m {
            fitted[i] = outcome.fitted[k];
            k += 1;
        }
    }
    outcome.fitted = fitted;
    Ok(outcome)
}

/// The `method` block of a result's `maps`.
pub fn method(cfg: &FitConfig, costs: &[f64], texel_variance: f64) -> serde_json::Value {
    serde_json::json!({
        "texel_variance": texel_variance,
        "global_stage_rounds": costs.len().saturating_sub(1),
        "global_stage_cost_per_round": costs,
        "global_texels": cfg.maps.global_texels,
        "smoothness": cfg.maps.smoothness,
        "prior_sweeps": if cfg.maps.smoothness > 0.0 { PRIOR_SWEEPS } else { 0 },
    })
}

