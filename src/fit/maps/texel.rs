//! One texel's problem: its mapped values from its own pixels given the globals (grid,
//! compass search on the column table, damped Gauss-Newton with the model, albedos solved
//! linearly), with its standard errors and other minima.

use super::*;
use crate::model::frame::Vec3;
use crate::model::Lobe;

/// Everything a per-texel fit needs from the globals.
pub(super) struct Globals<'m> {
    pub(super) model: &'m dyn ShadingModel,
    pub(super) has_topology: bool,
    pub(super) h_max: f64,
    /// Bounds of the lobe's roughness (the parameter's), for a roughness map.
    pub(super) roughness_range: [f64; 2],
    pub(super) tied: bool,
    pub(super) channels: usize,
    /// Global albedo per component index and channel (0 where absent).
    pub(super) albedo: [[f64; 3]; 4],
    /// Model columns over (H, psi) by the texels' directions ([`ColumnTable`]), for the
    /// direction sets a [`TablePlan`] chose: [`Globals::with_tables`].
    pub(super) tables: TableCache,
    /// Column tables over the image for texels with directions of their own (pinhole
    /// cameras, point lights): [`Globals::with_lattice`].
    pub(super) lattice: Option<DirectionLattice>,
    /// The residual variance the texel stage expects of a texel ([`Globals::with_variance`]):
    /// a texel fitting far worse searches again on a finer grid ([`RESEARCH_ABOVE`]).
    pub(super) variance: Option<f64>,
}

/// The bounds of the roughness in `set` (the parameter's range where the set has none).
pub(super) fn roughness_range(set: &ParamSet) -> [f64; 2] {
    set.lobe_shape(crate::model::LobeRole::Roughness)
        .map_or([0.0, 1.0], |s| [s.min, s.max])
}

/// A nonlinear value of a texel.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Nonlinear {
    Height,
    Psi,
    Roughness,
    Anisotropy,
}

/// The rung at the globals `set` with the knobs of `cfg` (no map: texels carry their height).
pub(super) fn rung_of(set: &ParamSet, cfg: &FitConfig) -> Box<dyn ShadingModel> {
    problem::model_for(
        set,
        cfg.knobs.quadrature_order,
        cfg.knobs.histogram_bins,
        cfg.knobs.azimuth_nodes,
        None,
    )
}

impl<'m> Globals<'m> {
    pub(super) fn of(set: &ParamSet, model: &'m dyn ShadingModel, channels: usize) -> Self {
        Self {
            model,
            has_topology: set.rung.has_topology(),
            h_max: max_height(set.shape_value(Param::Spacing)),
            roughness_range: roughness_range(set),
            tied: set.substrate_tied,
            channels,
            albedo: globals_albedo(set),
            tables: TableCache::default(),
            lattice: None,
            variance: None,
        }
    }

    /// Expecting the residual variance `variance` of a texel (none where it is not positive
    /// and finite).
    pub(super) fn with_variance(mut self, variance: f64) -> Self {
        self.variance = (variance.is_finite() && variance > 0.0).then_some(variance);
        self
    }

    /// With the [`DirectionLattice`] of `store` where its texels' directions vary across the
    /// image (pinhole cameras, point lights) and both H and psi are mapped: their grids and
    /// coarse searches then read blended node tables instead of evaluating the model.
    pub(super) fn with_lattice(mut self, store: &CaptureStore, free: Free) -> Self {
        self.lattice = DirectionLattice::of_store(store, free);
        self
    }

    /// With a grid-only copy of `lattice` ([`DirectionLattice::grid_only`]), where there is
    /// one: the global stage's.
    pub(super) fn with_grid_lattice(mut self, lattice: Option<&DirectionLattice>) -> Self {
        self.lattice = lattice.map(DirectionLattice::grid_only);
        self
    }

    /// With the column tables of `plan` (none without one: every texel then evaluates the
    /// model in its grid and coarse searches).
    pub(super) fn with_tables(mut self, plan: TablePlan) -> Self {
        self.tables = plan.into_cache();
        self
    }

    /// Whether [`Texel::fit`] reads `texel`'s columns from the lattice rather than from a
    /// shared table (so the texel has no say in the [`TablePlan`]).
    pub(super) fn lattice_serves(&self, texel: &Texel) -> bool {
        self.lattice.as_ref().is_some_and(|l| l.serves(texel))
    }
}

/// Columns [diffuse, specular, substrate, fuzz] (diffuse + substrate in the first where tied)
/// of observations with light and view directions `dirs` at (H, psi) and, where given, the
/// texel's own lobe (roughness and anisotropy maps), one model batch.
pub(super) fn model_columns<'a>(
    g: &Globals,
    dirs: impl Iterator<Item = (&'a Vec3, &'a Vec3)>,
    h: f64,
    psi: f64,
    lobe: Option<Lobe>,
) -> Vec<[f64; 4]> {
    let frame = FibreFrame::from_azimuth(psi.to_radians());
    let pairs: Vec<DirectionPair> = dirs
        .map(|(l, v)| DirectionPair::new(&frame, l, v))
        .collect();
    // one texel is one pattern seen in every image: one batch
    let mut bases = vec![Basis::default(); pairs.len()];
    if let Some(lobe) = lobe {
        let m = g
            .model
            .with_lobe(lobe)
            .expect("checked by check_request: the rung has a lobe");
        m.basis_many(&pairs, &mut bases);
    } else if !(g.has_topology
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

/// One texel's problem.
pub(super) struct Texel {
    /// The texel's samples, one per image.
    pub(super) obs: Vec<Sample>,
    /// Per observation and channel: residual weight (1/sigma or sqrt(weight)).
    pub(super) scale: Vec<[f64; 3]>,
    pub(super) free: Free,
    /// Prior: (weight, neighbour mean of H, neighbour mean of psi) when smoothing.
    pub(super) prior: Option<(f64, f64, f64)>,
}

impl Texel {
    pub(super) fn new(obs: Vec<Sample>, free: Free, prior: Option<(f64, f64, f64)>) -> Self {
        Self {
            scale: obs.iter().map(scale_of).collect(),
            obs,
            free,
            prior,
        }
    }

    /// What the grid's columns depend on besides the globals: every observation's directions,
    /// and the texel's height or azimuth where they are fixed.
    pub(super) fn grid_key(&self, start: &TexelValues) -> Vec<u64> {
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

    /// Columns of every observation at the texel's values `v` (H, psi and its lobe).
    pub(super) fn columns(&self, g: &Globals, v: &TexelValues) -> Vec<[f64; 4]> {
        model_columns(
            g,
            self.obs.iter().map(|s| (&s.l, &s.v)),
            v.height,
            v.psi,
            self.lobe_of(v),
        )
    }

    /// Columns of every observation at (H, psi), the lobe the globals' (a table's nodes:
    /// there are none where the lobe is mapped).
    pub(super) fn columns_at(&self, g: &Globals, h: f64, psi: f64) -> Vec<[f64; 4]> {
        debug_assert!(!self.free.lobe());
        model_columns(g, self.obs.iter().map(|s| (&s.l, &s.v)), h, psi, None)
    }

    /// The texel's own lobe where it is mapped.
    pub(super) fn lobe_of(&self, v: &TexelValues) -> Option<Lobe> {
        self.free.lobe().then_some(Lobe {
            roughness: v.roughness,
            anisotropy: v.anisotropy,
        })
    }

    /// Albedos of the texel (mapped ones solved linearly, bounded to [0, 1]) and the weighted
    /// residuals, at fixed columns.
    pub(super) fn solve(&self, g: &Globals, cols: &[[f64; 4]], v: &mut TexelValues) -> Vec<f64> {
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

    pub(super) fn albedo(&self, g: &Globals, v: &TexelValues, k: usize, c: usize) -> f64 {
        match k {
            0 if self.free.kd => v.kd[c],
            1 if self.free.ks => v.ks[c],
            _ => g.albedo[k][c],
        }
    }

    pub(super) fn residuals(&self, g: &Globals, cols: &[[f64; 4]], v: &TexelValues) -> Vec<f64> {
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
    pub(super) fn cost_at(&self, g: &Globals, base: &TexelValues, u: &[f64]) -> (f64, TexelValues) {
        let (r, v) = self.residuals_at(g, base, u);
        (r.iter().map(|x| x * x).sum(), v)
    }

    /// [`Texel::cost_at`] with the columns interpolated in `table`.
    pub(super) fn table_cost_at(
        &self,
        g: &Globals,
        base: &TexelValues,
        u: &[f64],
        table: &Tabled,
    ) -> (f64, TexelValues) {
        let mut v = self.at_nonlinear(g, base, u);
        let cols = table.interpolate(g, v.height, v.psi);
        let r = self.solve(g, &cols, &mut v);
        (r.iter().map(|x| x * x).sum(), v)
    }

    /// `base` with the nonlinear values `u` (H clamped to [0, H_max], psi wrapped, the lobe's
    /// roughness and anisotropy strength clamped to their bounds).
    pub(super) fn at_nonlinear(&self, g: &Globals, base: &TexelValues, u: &[f64]) -> TexelValues {
        let mut v = *base;
        let mut k = 0;
        if self.free.height {
            v.height = u[k].clamp(0.0, g.h_max);
            k += 1;
        }
        if self.free.psi {
            v.psi = wrap_azimuth(u[k]);
            k += 1;
        }
        if self.free.roughness {
            v.roughness = u[k].clamp(g.roughness_range[0], g.roughness_range[1]);
            k += 1;
        }
        if self.free.anisotropy {
            v.anisotropy = u[k].clamp(0.0, 1.0);
        }
        v
    }

    /// Residuals and solved values at nonlinear values `u`.
    pub(super) fn residuals_at(
        &self,
        g: &Globals,
        base: &TexelValues,
        u: &[f64],
    ) -> (Vec<f64>, TexelValues) {
        let mut v = self.at_nonlinear(g, base, u);
        let cols = self.columns(g, &v);
        (self.solve(g, &cols, &mut v), v)
    }

    pub(super) fn nonlinear(&self, v: &TexelValues) -> Vec<f64> {
        let mut u = Vec::new();
        if self.free.height {
            u.push(v.height);
        }
        if self.free.psi {
            u.push(v.psi);
        }
        if self.free.roughness {
            u.push(v.roughness);
        }
        if self.free.anisotropy {
            u.push(v.anisotropy);
        }
        u
    }

    /// What each nonlinear value is, in [`Texel::nonlinear`]'s order.
    pub(super) fn nonlinear_kinds(&self) -> Vec<Nonlinear> {
        [
            (Nonlinear::Height, self.free.height),
            (Nonlinear::Psi, self.free.psi),
            (Nonlinear::Roughness, self.free.roughness),
            (Nonlinear::Anisotropy, self.free.anisotropy),
        ]
        .into_iter()
        .filter(|x| x.1)
        .map(|x| x.0)
        .collect()
    }

    /// Fit the texel from `start`: a grid over the nonlinear values (17 heights x 12 azimuths),
    /// a coarse compass search from the best [`TEXEL_STARTS`] of its local minima and `start`,
    /// the best of those searched on and polished by damped Gauss–Newton. Returns the best
    /// (never worse than `start`) and the other distinct minima found, best first.
    pub(super) fn fit(&self, g: &Globals, start: &TexelValues) -> TexelFit {
        let u0 = self.nonlinear(start);
        let (c0, v0) = self.cost_at(g, start, &u0);
        if u0.is_empty() {
            return (v0, c0, vec![]);
        }
        let table = self.table(g, start);
        let grid = self.grid(g, start, table.as_ref());
        // the start competes with the grid minima for the polishes (so the fit is never worse
        // than the start); each is searched to a coarse step, the best of them to the end
        let mut candidates: Vec<(TexelValues, f64)> = grid
            .local_minima()
            .iter()
            .map(|&k| (grid.points[k].1, grid.points[k].0))
            .collect();
        candidates.push((v0, c0));
        candidates.sort_by(|a, b| a.1.total_cmp(&b.1));
        candidates.truncate(TEXEL_STARTS);
        // the lobe's own grid at the best candidate, whose local minima are searched too: one
        // value at a time, the compass stalls in the valley where roughness and anisotropy
        // strength trade off, and sparse directions leave a sharp and a broad lobe apart
        let lobe_grids: Vec<LobeGrid> = if self.free.lobe() {
            vec![self.lobe_grid(g, start, &candidates[0].0)]
        } else {
            vec![]
        };
        for l in &lobe_grids {
            candidates.extend(l.local_minima());
        }
        let mut minima = self.searched(g, start, candidates, table.as_ref());
        // a texel fitting far worse than the noise may have its minimum between the grid's
        // azimuths (a sharp lobe seen in few directions has valleys narrower than 15 degrees):
        // the minima of a grid four times finer in psi are searched too
        let lowest = minima.iter().map(|m| m.1).fold(f64::INFINITY, f64::min);
        if self.fits_poorly(g, lowest) {
            let fine = self.fine_grid(g, start, table.as_ref());
            let more: Vec<(TexelValues, f64)> = fine
                .local_minima()
                .iter()
                .map(|&k| (fine.points[k].1, fine.points[k].0))
                .filter(|c| !minima.iter().any(|m| self.same(g, &m.0, &c.0)))
                .collect();
            minima.extend(self.searched(g, start, more, table.as_ref()));
        }
        minima.sort_by(|a, b| a.1.total_cmp(&b.1));
        let (best, best_cost) = minima.remove(0);
        minima.retain(|m| !self.same(g, &m.0, &best));
        // the grid's profiles (best over the other value at each grid height, and at each grid
        // azimuth) count as other candidates too: a flat profile is an undetermined value even
        // where it has no separate minimum
        let profiles = minima.len();
        grid.push_profiles(&mut minima);
        for l in &lobe_grids {
            l.push_profiles(&mut minima);
        }
        // a blended table is the model only to within its blend: the profile's costs that could
        // make the texel ambiguous are the model's own
        if table.as_ref().is_some_and(|t| !t.exact_at_nodes()) {
            self.exact_profiles(g, start, &mut minima[profiles..], best_cost);
        }
        (best, best_cost, minima)
    }

    /// The lobe's grid ([`LOBE_GRID`]: roughness over its bounds x anisotropy strength over
    /// [0, 1], of those mapped) at `v`'s other values.
    fn lobe_grid(&self, g: &Globals, start: &TexelValues, v: &TexelValues) -> LobeGrid {
        let [lo, hi] = g.roughness_range;
        let (nr, na) = (
            if self.free.roughness { LOBE_GRID[0] } else { 1 },
            if self.free.anisotropy { LOBE_GRID[1] } else { 1 },
        );
        let at = |k: usize, n: usize| k as f64 / (n - 1).max(1) as f64;
        let mut points = Vec::with_capacity(nr * na);
        for i in 0..nr {
            for j in 0..na {
                let mut w = *v;
                if self.free.roughness {
                    w.roughness = lo + (hi - lo) * at(i, nr);
                }
                if self.free.anisotropy {
                    w.anisotropy = at(j, na);
                }
                let (c, w) = self.cost_at(g, start, &self.nonlinear(&w));
                points.push((w, c));
            }
        }
        LobeGrid { na, points }
    }

    /// Where the texel's grid and coarse searches read their columns: the lattice's blend for a
    /// texel with directions of its own where there is a lattice; else the table shared by the
    /// texels with its directions (none for a direction set met once, nor where the lobe is
    /// mapped: the tables hold the globals' lobe).
    fn table(&self, g: &Globals, start: &TexelValues) -> Option<Tabled> {
        if self.free.lobe() {
            return None;
        }
        match g.lattice.as_ref().and_then(|l| l.blend(self, g)) {
            Some(b) => Some(Tabled::Blend(b)),
            None => g
                .tables
                .get(&self.grid_key(start), || ColumnTable::build(self, g, start))
                .map(Tabled::Shared),
        }
    }

    /// The grid of the fit: the cost and solved values at every grid point, read from `table`
    /// where there is one, else from the model.
    fn grid(&self, g: &Globals, start: &TexelValues, table: Option<&Tabled>) -> Grid {
        let (th, tp) = ColumnTable::dims(self.free);
        let (nh, np) = (
            if self.free.height { HEIGHT_GRID } else { 1 },
            if self.free.psi { PSI_GRID } else { 1 },
        );
        // grid point k = (k / np, k % np) is table node ColumnTable::grid_node of it
        self.grid_over(
            g,
            start,
            (nh, np),
            |k| ColumnTable::grid_node(th, tp, k / np, k % np),
            |k, _| table.map(|t| t.at_grid(k / np, k % np)),
        )
    }

    /// The cost and solved values at `nh` x `np` points, point k at table node `node(k)`, its
    /// columns `read(k, node)` where that gives them, else the model's.
    fn grid_over<'t>(
        &self,
        g: &Globals,
        start: &TexelValues,
        (nh, np): (usize, usize),
        node: impl Fn(usize) -> (usize, usize),
        read: impl Fn(usize, (usize, usize)) -> Option<std::borrow::Cow<'t, [[f64; 4]]>>,
    ) -> Grid {
        let (th, tp) = ColumnTable::dims(self.free);
        let points = (0..nh * np)
            .map(|k| {
                let (j, l) = node(k);
                let (h, psi) = ColumnTable::node(th, tp, g, start, j, l);
                let mut v = *start;
                v.height = h;
                v.psi = psi;
                let r = match read(k, (j, l)) {
                    Some(cols) => self.solve(g, &cols, &mut v),
                    None => {
                        let cols = self.columns(g, &v);
                        self.solve(g, &cols, &mut v)
                    }
                };
                (r.iter().map(|x| x * x).sum(), v)
            })
            .collect();
        Grid { nh, np, points }
    }

    /// Whether a texel's best cost `cost` is above [`RESEARCH_ABOVE`] times the residual
    /// variance the stage expects over its degrees of freedom (never without an expected
    /// variance, nor with the lobe mapped, nor without a free azimuth).
    fn fits_poorly(&self, g: &Globals, cost: f64) -> bool {
        let Some(variance) = g.variance else {
            return false;
        };
        if !self.free.psi || self.free.lobe() {
            return false;
        }
        cost > RESEARCH_ABOVE * variance * self.dof(g) as f64
    }

    /// The texel's residuals less its unknowns (at least 1).
    fn dof(&self, g: &Globals) -> usize {
        let residuals = self.obs.len() * g.channels;
        residuals
            .saturating_sub(per_texel_unknowns(self.free, g.channels))
            .max(1)
    }

    /// The grid with [`FINE_PSI`] times as many azimuths (every 3.75 degrees, a table node
    /// in four), read from `table` where it has those nodes, else from the model.
    fn fine_grid(&self, g: &Globals, start: &TexelValues, table: Option<&Tabled>) -> Grid {
        let (th, tp) = ColumnTable::dims(self.free);
        let nh = if self.free.height { HEIGHT_GRID } else { 1 };
        let np = PSI_GRID * FINE_PSI;
        let step = TABLE_PSI_PER_GRID / FINE_PSI;
        let table = table.filter(|t| t.interpolates());
        self.grid_over(
            g,
            start,
            (nh, np),
            |k| (ColumnTable::grid_node(th, tp, k / np, 0).0, (k % np) * step),
            |_, (j, l)| table.map(|t| t.at(j, l)),
        )
    }

    /// Whether `w` and `v` are one minimum: H within 2% of H_max, psi within a degree, the
    /// lobe's roughness and anisotropy strength within 0.02 (of those mapped).
    fn same(&self, g: &Globals, w: &TexelValues, v: &TexelValues) -> bool {
        (!self.free.height || (w.height - v.height).abs() <= 0.02 * g.h_max.max(1e-9))
            && (!self.free.psi || wrap_azimuth(w.psi - v.psi).abs() <= 1.0)
            && (!self.free.roughness || (w.roughness - v.roughness).abs() <= 0.02)
            && (!self.free.anisotropy || (w.anisotropy - v.anisotropy).abs() <= 0.02)
    }

    /// The distinct minima from `candidates`: each searched to a coarse step (on `table` where
    /// there is one, then the model's own cost there), the best of those that could still win
    /// searched on to the end and polished.
    fn searched(
        &self,
        g: &Globals,
        start: &TexelValues,
        candidates: Vec<(TexelValues, f64)>,
        table: Option<&Tabled>,
    ) -> Vec<(TexelValues, f64)> {
        let mut minima: Vec<(TexelValues, f64)> = Vec::new();
        // a grid-only table serves the grid alone
        let table = table.filter(|t| t.interpolates());
        for (v, c) in candidates {
            // on the table where there is one, then the model's own cost there
            let (v, c) = self.compass(g, start, v, c, (1.0, COMPASS_COARSE), table);
            let (v, c) = match table {
                Some(_) => {
                    let (c, v) = self.cost_at(g, start, &self.nonlinear(&v));
                    (v, c)
                }
                None => (v, c),
            };
            match minima.iter_mut().find(|m| self.same(g, &m.0, &v)) {
                Some(m) if c < m.1 => *m = (v, c),
                Some(_) => {}
                None => minima.push((v, c)),
            }
        }
        // searched on to the end: every minimum that could still be the best (coarse cost
        // within twice the lowest: a coarse step costs well under one noise variance, the
        // ambiguity margin is nine); with the lobe mapped, every one: its valleys (roughness and
        // anisotropy strength trading off) are narrower than a coarse step where the images are
        // sharp
        let lowest = minima.iter().map(|m| m.1).fold(f64::INFINITY, f64::min);
        let reach = if self.free.lobe() { f64::INFINITY } else { 2.0 };
        for m in minima.iter_mut().filter(|m| m.1 <= reach * lowest) {
            let (v, c) = self.compass(g, start, m.0, m.1, (COMPASS_COARSE, COMPASS_FINE), None);
            *m = self.gauss_newton(g, start, v, c);
        }
        minima
    }

    /// The model's own costs of the grid `profiles` (read from a blended table) that could make
    /// the texel ambiguous: within what the texel stage keeps of other minima, in this texel's
    /// own residual variance, of `best_cost`.
    fn exact_profiles(
        &self,
        g: &Globals,
        start: &TexelValues,
        profiles: &mut [(TexelValues, f64)],
        best_cost: f64,
    ) {
        let margin = MINIMA_MARGIN * AMBIGUITY_DELTA * best_cost / self.dof(g) as f64;
        for m in profiles.iter_mut().filter(|m| m.1 - best_cost <= margin) {
            let (c, v) = self.cost_at(g, start, &self.nonlinear(&m.0));
            *m = (v, c);
        }
    }

    /// A compass search on the nonlinear values from `v` (cost `c`), albedos re-solved at every
    /// point: occlusion makes the cost kinked in H, where Gauss–Newton stalls. Steps halve from
    /// `from` to `to` times (H_max / 32, 3.75 degrees), half the grid's spacing.
    pub(super) fn compass(
        &self,
        g: &Globals,
        start: &TexelValues,
        v: TexelValues,
        c: f64,
        (from, to): (f64, f64),
        table: Option<&Tabled>,
    ) -> (TexelValues, f64) {
        let (mut best, mut best_cost) = (v, c);
        let mut best_u = self.nonlinear(&best);
        let unit: Vec<f64> = self
            .nonlinear_kinds()
            .iter()
            .map(|k| match k {
                Nonlinear::Height => g.h_max / 32.0,
                Nonlinear::Psi => 3.75,
                // a 32nd of the range, as H's
                Nonlinear::Roughness | Nonlinear::Anisotropy => 1.0 / 32.0,
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
    pub(super) fn gauss_newton(
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
        let kinds = self.nonlinear_kinds();
        for _ in 0..30 {
            let mut jac = DMatrix::zeros(r0.len(), n);
            for k in 0..n {
                let mut u = best_u.clone();
                let (mut step, upper) = match kinds[k] {
                    Nonlinear::Height => (1e-4 * g.h_max.max(1e-3), g.h_max),
                    Nonlinear::Psi => (1e-3, f64::INFINITY),
                    Nonlinear::Roughness => (1e-4, g.roughness_range[1]),
                    Nonlinear::Anisotropy => (1e-4, 1.0),
                };
                // a one-sided difference inside the bounds
                if u[k] + step > upper {
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

    /// RMS relative residual over the texel's pixels and channels.
    pub(super) fn relative_residual(&self, g: &Globals, v: &TexelValues) -> f64 {
        let cols = self.columns(g, v);
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

/// A texel's grid: `nh` heights x `np` azimuths (1 of a value not mapped), row-major by
/// height, with each point's cost and solved values.
struct Grid {
    nh: usize,
    np: usize,
    points: Vec<(f64, TexelValues)>,
}

/// A texel's lobe grid: roughness x anisotropy strength (`na` of them), row-major by
/// roughness, with each point's values and cost.
struct LobeGrid {
    na: usize,
    points: Vec<(TexelValues, f64)>,
}

impl LobeGrid {
    /// Grid points no 4-neighbour undercuts, the best [`TEXEL_STARTS`] of them, best first.
    fn local_minima(&self) -> Vec<(TexelValues, f64)> {
        let na = self.na;
        let nr = self.points.len() / na;
        let c = |i: usize, j: usize| self.points[i * na + j].1;
        let mut local: Vec<(TexelValues, f64)> = Vec::new();
        for i in 0..nr {
            for j in 0..na {
                let mut nb = Vec::new();
                if i > 0 {
                    nb.push(c(i - 1, j));
                }
                if i + 1 < nr {
                    nb.push(c(i + 1, j));
                }
                if j > 0 {
                    nb.push(c(i, j - 1));
                }
                if j + 1 < na {
                    nb.push(c(i, j + 1));
                }
                if nb.iter().all(|&x| x >= c(i, j)) {
                    local.push(self.points[i * na + j]);
                }
            }
        }
        local.sort_by(|a, b| a.1.total_cmp(&b.1));
        local.truncate(TEXEL_STARTS);
        local
    }

    /// The grid's profiles onto `minima`: the best point at each roughness, then at each
    /// anisotropy strength (a flat profile is a value the images leave undetermined).
    fn push_profiles(&self, minima: &mut Vec<(TexelValues, f64)>) {
        let na = self.na;
        let nr = self.points.len() / na;
        let best_of = |ks: &mut dyn Iterator<Item = usize>| {
            ks.map(|k| self.points[k])
                .min_by(|a, b| a.1.total_cmp(&b.1))
                .expect("a row has points")
        };
        for i in 0..nr {
            minima.push(best_of(&mut (i * na..(i + 1) * na)));
        }
        for j in 0..na {
            minima.push(best_of(&mut (0..nr).map(|i| i * na + j)));
        }
    }
}

impl Grid {
    /// Grid points no 4-neighbour undercuts (the azimuth wraps), the best [`TEXEL_STARTS`] of
    /// them, best first.
    fn local_minima(&self) -> Vec<usize> {
        let (nh, np, grid) = (self.nh, self.np, &self.points);
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
        local
    }

    /// The grid's profiles onto `minima` as (values, cost): the best point at each grid height,
    /// then at each grid azimuth.
    fn push_profiles(&self, minima: &mut Vec<(TexelValues, f64)>) {
        let (nh, np, grid) = (self.nh, self.np, &self.points);
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
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Texel (144, 365) of `fibrefit bench camera`'s 512 x 512 pinhole capture (light and view
    /// directions, measured RGB): its true H 0.690, psi -10.24 deg lie between the grid's
    /// azimuths (-15, 0), where a sharp lobe seen in eight directions leaves a valley a few
    /// degrees wide.
    const PINHOLE_TEXEL: [([f64; 3], [f64; 3], [f64; 3]); 8] = [
        ([0.14624701368312723, 0.014103080579746748, 0.989147569428813], [0.014515224360332096, 0.0142548615915369, 0.999793032173547], [0.24405931255020122, 0.2239890216609798, 0.19911193384079165]),
        ([-0.1345026647505178, 0.8584283766900168, 0.49498460104164094], [0.18627661987477934, -0.4574260948292943, 0.8695184809175986], [0.2999958833933796, 0.28517745114882903, 0.2738128267252294]),
        ([0.6701257286012398, 0.2527623915904316, 0.6978844325990821], [-0.6584867573711963, -0.2305780346566017, 0.7164000002098453], [0.35932716228961814, 0.3396640015758804, 0.315733968919346]),
        ([0.48659563815717344, -0.8032227394838125, 0.3435955699693064], [-0.10214429974450075, 0.334618871335634, 0.9368013412542555], [0.07473604161513168, 0.05933242945148824, 0.04114567753311297]),
        ([-0.7598655865715307, 0.014416025488282877, 0.6499203555462967], [0.7718674399050225, 0.014098984771810015, 0.6356271500202542], [0.43309622693370164, 0.4056003235681694, 0.3795072403763342]),
        ([-0.30877322348336184, -0.10335516460445072, 0.9455034671587835], [0.8151791185854798, 0.3055322268754301, 0.4920701809322947], [0.1005020149440868, 0.07784985943644568, 0.055921273286141104]),
        ([-0.44654836955975113, -0.7845293834334975, 0.4302420251125922], [0.33168995448740346, 0.5637522163475926, 0.7564160314637185], [0.22764650089377902, 0.21069636310445353, 0.19708314526951495]),
        ([0.5690832010242795, -0.30600387313066846, 0.7632207674984933], [-0.6978623419349663, 0.4256478259795349, 0.5760313185478195], [0.2304739711281076, 0.207071737352611, 0.180287908568878]),
    ];

    #[test]
    fn a_texel_fitting_far_worse_than_the_noise_searches_a_finer_grid_and_finds_its_minimum() {
        let cfg: FitConfig = toml::from_str(
            r#"model = "varying-topology"
[parameters]
kd = { value = [0.44991, 0.35028, 0.24997] }
ks = { value = 0.29995 }
exponent = { value = 40.035 }
spacing = { value = 2.0, vary = false }
height = { value = 1.2 }
fibre_azimuth_deg = { value = 3.96 }
[maps]
height = true
fibre_azimuth = true
"#,
        )
        .unwrap();
        let free = free_of(&cfg.maps);
        let set = fix_mapped(&ParamSet::from_config(&cfg, 3).unwrap(), &cfg.maps);
        let model = rung_of(&set, &cfg);
        let obs = PINHOLE_TEXEL
            .iter()
            .enumerate()
            .map(|(k, (l, v, value))| Sample {
                l: Vec3::new(l[0], l[1], l[2]),
                v: Vec3::new(v[0], v[1], v[2]),
                fibre_azimuth: None,
                map_value: None,
                texel_height: None,
                value: *value,
                sigma: None,
                weight: 1.0,
                origin: Origin::Pixel {
                    image: k as u32,
                    x: 144,
                    y: 365,
                },
            })
            .collect();
        let texel = Texel::new(obs, free, None);
        let start = TexelValues {
            height: 1.2,
            psi: 3.96,
            ..TexelValues::default()
        };
        let near_truth = |v: &TexelValues| {
            (v.height - 0.690).abs() < 0.03 && wrap_azimuth(v.psi + 10.24).abs() < 1.0
        };
        // without an expected variance: the grid's minima only, a wrong one (H at its bound)
        let g = Globals::of(&set, model.as_ref(), 3);
        let (wrong, wrong_cost, _) = texel.fit(&g, &start);
        assert!(!near_truth(&wrong), "{wrong:?}");
        // the capture's noise (1 % of values ~0.25): ~6e-6 per residual; the wrong minimum
        // costs 20x that, so the finer grid is searched and the true minimum found
        let g = g.with_variance(6e-6);
        assert!(texel.fits_poorly(&g, wrong_cost));
        let (best, cost, _) = texel.fit(&g, &start);
        assert!(near_truth(&best), "{best:?}");
        assert!(cost < wrong_cost / 10.0, "{cost} against {wrong_cost}");
        assert!(!texel.fits_poorly(&g, cost));
    }
}
