//! The model columns of a texel's observations over a fine (H, psi) table, shared by every
//! texel that sees the same directions, and the cache of such tables.

use super::*;
use crate::model::frame::Vec3;
use std::sync::OnceLock;

/// Column tables kept at most, and direction sets tracked before giving up (texels whose
/// directions all differ, a pinhole camera's or a point light's, read a [`DirectionLattice`]
/// instead, or evaluate the model directly where there is none).
pub(super) const TABLE_ENTRIES: usize = 16;
pub(super) const TRACKED_KEYS: usize = 4096;
/// Table nodes per grid step: 4 in H (H_max / 64), 16 in psi (0.9375 degrees).
pub(super) const TABLE_H_PER_GRID: usize = 4;
pub(super) const TABLE_PSI_PER_GRID: usize = 16;

/// The model columns of a texel's observations over a fine (H, psi) table. They depend only on
/// the observations' light and view directions (and the texel's height or azimuth where those
/// are not mapped): with a directional light and an orthographic camera per image every texel
/// sees the same directions, so one table serves them all. The grid reads its nodes; the coarse
/// searches interpolate it (bilinear, periodic in psi); the final search and every reported
/// value use the model itself.
pub(super) struct ColumnTable {
    pub(super) nh: usize,
    pub(super) np: usize,
    pub(super) nobs: usize,
    pub(super) cols: Vec<[f64; 4]>,
    /// The columns at the grid's points alone ([`Self::at_grid`]), a copy of theirs in `cols`
    /// kept together: the grid reads every one of them for every texel, and read from `cols`
    /// they lie a whole psi grid step apart (4 kB at 8 observations), each cache line and
    /// page a miss where the texels read a lattice's four tables.
    grid: Vec<[f64; 4]>,
}

impl ColumnTable {
    /// The table of `nobs` observations at `nh` x `np` nodes, `cols` node-major.
    pub(super) fn new(nh: usize, np: usize, nobs: usize, cols: Vec<[f64; 4]>) -> Self {
        let (gh, gp) = Self::grid_dims(nh, np);
        let mut grid = Vec::with_capacity(gh * gp * nobs);
        for i in 0..gh {
            for l in 0..gp {
                let (j, k) = Self::grid_node(nh, np, i, l);
                let at = (j * np + k) * nobs;
                grid.extend_from_slice(&cols[at..at + nobs]);
            }
        }
        Self {
            nh,
            np,
            nobs,
            cols,
            grid,
        }
    }

    /// Grid points (H, psi) of a table of `nh` x `np` nodes: the grid's where a value is free.
    fn grid_dims(nh: usize, np: usize) -> (usize, usize) {
        (
            if nh > 1 { HEIGHT_GRID } else { 1 },
            if np > 1 { PSI_GRID } else { 1 },
        )
    }

    /// The table node of grid point (i, l): (i [`TABLE_H_PER_GRID`], l [`TABLE_PSI_PER_GRID`]).
    pub(super) fn grid_node(nh: usize, np: usize, i: usize, l: usize) -> (usize, usize) {
        (
            i * if nh > 1 { TABLE_H_PER_GRID } else { 0 },
            l * if np > 1 { TABLE_PSI_PER_GRID } else { 0 },
        )
    }

    /// The columns at grid point (i, l), node [`Self::grid_node`] (equal to [`Self::at`] there).
    pub(super) fn at_grid(&self, i: usize, l: usize) -> &[[f64; 4]] {
        let gp = Self::grid_dims(self.nh, self.np).1;
        let at = (i * gp + l) * self.nobs;
        &self.grid[at..at + self.nobs]
    }

    pub(super) fn dims(free: Free) -> (usize, usize) {
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
    pub(super) fn node(
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

    pub(super) fn build(texel: &Texel, g: &Globals, start: &TexelValues) -> Self {
        let dirs: Vec<(Vec3, Vec3)> = texel.obs.iter().map(|s| (s.l, s.v)).collect();
        Self::build_for(&dirs, texel.free, g, start)
    }

    /// The table of observations with light and view directions `dirs` (swatch frame).
    pub(super) fn build_for(
        dirs: &[(Vec3, Vec3)],
        free: Free,
        g: &Globals,
        start: &TexelValues,
    ) -> Self {
        let (nh, np) = Self::dims(free);
        let nodes = (0..nh).flat_map(|j| (0..np).map(move |k| (j, k)));
        let cols = Self::columns_at(dirs, g, nodes.map(|(j, k)| Self::node(nh, np, g, start, j, k)));
        Self::new(nh, np, dirs.len(), cols)
    }

    /// The model columns of the observations `dirs` at each (H, psi) of `points`, in turn.
    fn columns_at(
        dirs: &[(Vec3, Vec3)],
        g: &Globals,
        points: impl Iterator<Item = (f64, f64)>,
    ) -> Vec<[f64; 4]> {
        let mut cols = Vec::new();
        for (h, psi) in points {
            cols.extend(model_columns(g, dirs.iter().map(|(l, v)| (l, v)), h, psi, None));
        }
        cols
    }

    /// [`Self::build_for`] at the grid's points alone ([`Self::at_grid`]; [`Self::at`] and the
    /// interpolation have no nodes to read): what a grid needs, for ~1/60 of the model
    /// batches, where few texels read the table (the global stage's sample).
    pub(super) fn build_grid_for(
        dirs: &[(Vec3, Vec3)],
        free: Free,
        g: &Globals,
        start: &TexelValues,
    ) -> Self {
        let (nh, np) = Self::dims(free);
        let (gh, gp) = Self::grid_dims(nh, np);
        let points = (0..gh).flat_map(|i| (0..gp).map(move |l| (i, l)));
        let grid = Self::columns_at(
            dirs,
            g,
            points.map(|(i, l)| {
                let (j, k) = Self::grid_node(nh, np, i, l);
                Self::node(nh, np, g, start, j, k)
            }),
        );
        Self {
            nh,
            np,
            nobs: dirs.len(),
            cols: Vec::new(),
            grid,
        }
    }

    /// Whether the table has its nodes between the grid's points ([`Self::interpolate`]).
    pub(super) fn interpolates(&self) -> bool {
        !self.cols.is_empty()
    }

    pub(super) fn at(&self, j: usize, k: usize) -> &[[f64; 4]] {
        let i = (j * self.np + k) * self.nobs;
        &self.cols[i..i + self.nobs]
    }

    /// The four nodes around (H, psi) with their weights: (j0, j1, t in H; k0, k1, u in psi).
    pub(super) fn around(
        &self,
        g: &Globals,
        h: f64,
        psi: f64,
    ) -> (usize, usize, f64, usize, usize, f64) {
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
        (j0, (j0 + 1).min(self.nh - 1), t, k0, (k0 + 1) % self.np, u)
    }

    /// Bilinear interpolation at (H, psi).
    pub(super) fn interpolate(&self, g: &Globals, h: f64, psi: f64) -> Vec<[f64; 4]> {
        let (j0, j1, t, k0, k1, u) = self.around(g, h, psi);
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

    /// Add `weight` times the interpolation at (H, psi) of the observations `rows` to `out`
    /// (one entry per row), the nodes `around` it ([`Self::around`]): the lattice's blend
    /// ([`DirectionLattice`]), whose tables share their nodes, so that is found once for all.
    pub(super) fn accumulate(
        &self,
        around: (usize, usize, f64, usize, usize, f64),
        rows: &[usize],
        weight: f64,
        out: &mut [[f64; 4]],
    ) {
        let (j0, j1, t, k0, k1, u) = around;
        let (a, b, c, d) = (
            self.at(j0, k0),
            self.at(j0, k1),
            self.at(j1, k0),
            self.at(j1, k1),
        );
        let w = [
            weight * (1.0 - t) * (1.0 - u),
            weight * (1.0 - t) * u,
            weight * t * (1.0 - u),
            weight * t * u,
        ];
        for (o, &r) in out.iter_mut().zip(rows) {
            for m in 0..4 {
                o[m] += w[0] * a[r][m] + w[1] * b[r][m] + w[2] * c[r][m] + w[3] * d[r][m];
            }
        }
    }
}

/// The shared table or the lattice's blend: where a texel's grid and coarse searches read
/// their model columns.
pub(super) enum Tabled {
    /// One table for every texel that sees the same directions: exact at its nodes.
    Shared(Arc<ColumnTable>),
    /// The lattice's blend for a texel with directions of its own: approximate at the nodes
    /// too, so grid costs that matter are evaluated again with the model.
    Blend(Blend),
}

impl Tabled {
    /// The columns at table node (j, k) (a table that [`Self::interpolates`]).
    pub(super) fn at(&self, j: usize, k: usize) -> std::borrow::Cow<'_, [[f64; 4]]> {
        match self {
            Tabled::Shared(t) => std::borrow::Cow::Borrowed(t.at(j, k)),
            Tabled::Blend(b) => std::borrow::Cow::Owned(b.at(j, k)),
        }
    }

    /// The columns at grid point (i, l) (table node [`ColumnTable::grid_node`]).
    pub(super) fn at_grid(&self, i: usize, l: usize) -> std::borrow::Cow<'_, [[f64; 4]]> {
        match self {
            Tabled::Shared(t) => std::borrow::Cow::Borrowed(t.at_grid(i, l)),
            Tabled::Blend(b) => std::borrow::Cow::Owned(b.at_grid(i, l)),
        }
    }

    pub(super) fn interpolate(&self, g: &Globals, h: f64, psi: f64) -> Vec<[f64; 4]> {
        match self {
            Tabled::Shared(t) => t.interpolate(g, h, psi),
            Tabled::Blend(b) => b.interpolate(g, h, psi),
        }
    }

    /// Whether the coarse searches can interpolate the table (not a grid-only lattice's).
    pub(super) fn interpolates(&self) -> bool {
        match self {
            Tabled::Shared(t) => t.interpolates(),
            Tabled::Blend(b) => b.interpolates(),
        }
    }

    /// Whether the table's node columns are the model's own (the shared table's are).
    pub(super) fn exact_at_nodes(&self) -> bool {
        matches!(self, Tabled::Shared(_))
    }
}

/// Which direction sets get a column table, decided before any texel is fitted, in texel
/// order: a set is tabled when it is met a second time (a set met once, as a pinhole camera's
/// texels each are, is not worth a table), for the first [`TABLE_ENTRIES`] sets to be met twice
/// among the first [`TRACKED_KEYS`] met. Deciding it up front, over every texel of the capture,
/// makes a texel's fit independent of the order the threads reach the texels in and of how
/// the image is cut into tiles: a texel fitted with a table and the same texel fitted without
/// one land on the same minimum, but not to the last bit.
#[derive(Default)]
pub(super) struct TablePlan {
    /// Direction sets met, and whether each has been met twice.
    met: HashMap<Vec<u64>, bool>,
    /// The tabled sets, in the order their second meeting came.
    tabled: Vec<Vec<u64>>,
}

impl TablePlan {
    /// Whether no more sets can be tabled (no later texel changes the plan).
    pub(super) fn is_full(&self) -> bool {
        self.tabled.len() >= TABLE_ENTRIES
    }

    /// Meets the next texel's direction set (its [`Texel::grid_key`]).
    pub(super) fn meet(&mut self, key: Vec<u64>) {
        if self.is_full() {
            return;
        }
        match self.met.get_mut(&key) {
            Some(twice) => {
                if !*twice {
                    *twice = true;
                    self.tabled.push(key);
                }
            }
            None => {
                if self.met.len() < TRACKED_KEYS {
                    self.met.insert(key, false);
                }
            }
        }
    }

    /// The plan's tables, each built by the first texel that needs it.
    pub(super) fn into_cache(self) -> TableCache {
        TableCache {
            tables: self
                .tabled
                .into_iter()
                .map(|k| (k, OnceLock::new()))
                .collect(),
        }
    }
}

/// Column tables by direction set, for the sets a [`TablePlan`] chose (none by default).
/// A table depends only on its directions and the globals, so whichever texel builds it
/// builds the same table.
#[derive(Default)]
pub(super) struct TableCache {
    tables: HashMap<Vec<u64>, OnceLock<Arc<ColumnTable>>>,
}

impl TableCache {
    /// The table of direction set `key` (built with `make` on first use), or `None` where the
    /// plan gave the set none.
    pub(super) fn get(
        &self,
        key: &[u64],
        make: impl FnOnce() -> ColumnTable,
    ) -> Option<Arc<ColumnTable>> {
        self.tables
            .get(key)
            .map(|slot| slot.get_or_init(|| Arc::new(make())).clone())
    }

    /// Direction sets with a table, built or not.
    #[cfg(test)]
    pub(super) fn planned(&self) -> usize {
        self.tables.len()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::atomic::{AtomicUsize, Ordering};

    fn key(i: u64) -> Vec<u64> {
        vec![i, i ^ 0xff]
    }

    #[test]
    fn a_set_is_tabled_when_met_twice_for_the_first_sets_met_twice() {
        let mut plan = TablePlan::default();
        // 0..40 once each (a pinhole camera's texels), then set 39 again, then 0..40 again
        for i in 0..40 {
            plan.meet(key(i));
        }
        assert!(plan.tabled.is_empty(), "a set met once has no table");
        plan.meet(key(39));
        for i in 0..40 {
            plan.meet(key(i));
        }
        assert!(plan.is_full());
        let mut want = vec![key(39)];
        want.extend((0..TABLE_ENTRIES as u64 - 1).map(key));
        assert_eq!(
            plan.tabled, want,
            "tabled in the order of their second meeting"
        );
        let cache = plan.into_cache();
        assert_eq!(cache.planned(), TABLE_ENTRIES);
        assert!(cache.get(&key(20), || unreachable!()).is_none());
    }

    #[test]
    fn sets_met_after_the_tracker_is_full_are_never_tabled() {
        let mut plan = TablePlan::default();
        for i in 0..TRACKED_KEYS as u64 + 5 {
            plan.meet(key(i));
        }
        let late = key(TRACKED_KEYS as u64 + 2);
        plan.meet(late.clone());
        plan.meet(late.clone());
        plan.meet(key(7));
        assert_eq!(plan.tabled, vec![key(7)]);
    }

    #[test]
    fn a_planned_table_is_built_once_whichever_thread_asks_first() {
        let mut plan = TablePlan::default();
        plan.meet(key(1));
        plan.meet(key(1));
        let cache = plan.into_cache();
        let built = AtomicUsize::new(0);
        let make = || {
            built.fetch_add(1, Ordering::SeqCst);
            ColumnTable::new(1, 1, 1, vec![[0.5; 4]])
        };
        let tables: Vec<Arc<ColumnTable>> = (0..16)
            .into_par_iter()
            .map(|_| cache.get(&key(1), make).expect("planned"))
            .collect();
        assert_eq!(built.load(Ordering::SeqCst), 1);
        assert!(tables.iter().all(|t| Arc::ptr_eq(t, &tables[0])));
    }
}
