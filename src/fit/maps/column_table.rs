//! The model columns of a texel's observations over a fine (H, psi) table, shared by every
//! texel that sees the same directions, and the cache of such tables.

use super::*;
use crate::model::frame::Vec3;

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
}

impl ColumnTable {
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
        let mut cols = Vec::with_capacity(nh * np * dirs.len());
        for j in 0..nh {
            for k in 0..np {
                let (h, psi) = Self::node(nh, np, g, start, j, k);
                cols.extend(model_columns(g, dirs.iter().map(|(l, v)| (l, v)), h, psi));
            }
        }
        Self {
            nh,
            np,
            nobs: dirs.len(),
            cols,
        }
    }

    pub(super) fn at(&self, j: usize, k: usize) -> &[[f64; 4]] {
        let i = (j * self.np + k) * self.nobs;
        &self.cols[i..i + self.nobs]
    }

    /// The four nodes around (H, psi) with their weights: (j0, j1, t in H; k0, k1, u in psi).
    fn around(&self, g: &Globals, h: f64, psi: f64) -> (usize, usize, f64, usize, usize, f64) {
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
    /// (one entry per row): the lattice's blend ([`DirectionLattice`]).
    pub(super) fn accumulate(
        &self,
        g: &Globals,
        h: f64,
        psi: f64,
        rows: &[usize],
        weight: f64,
        out: &mut [[f64; 4]],
    ) {
        let (j0, j1, t, k0, k1, u) = self.around(g, h, psi);
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
    pub(super) fn at(&self, j: usize, k: usize) -> std::borrow::Cow<'_, [[f64; 4]]> {
        match self {
            Tabled::Shared(t) => std::borrow::Cow::Borrowed(t.at(j, k)),
            Tabled::Blend(b) => std::borrow::Cow::Owned(b.at(j, k)),
        }
    }

    pub(super) fn interpolate(&self, g: &Globals, h: f64, psi: f64) -> Vec<[f64; 4]> {
        match self {
            Tabled::Shared(t) => t.interpolate(g, h, psi),
            Tabled::Blend(b) => b.interpolate(g, h, psi),
        }
    }

    /// Whether the table's node columns are the model's own (the shared table's are).
    pub(super) fn exact_at_nodes(&self) -> bool {
        matches!(self, Tabled::Shared(_))
    }
}

/// Column tables by direction set: a table is built the second time its directions are met
/// (a set met once, as a pinhole camera's texels each are, is not worth one).
#[derive(Default)]
pub(super) struct TableCache {
    pub(super) tables: Mutex<HashMap<Vec<u64>, Option<Arc<ColumnTable>>>>,
}

impl TableCache {
    pub(super) fn get(
        &self,
        key: Vec<u64>,
        make: impl FnOnce() -> ColumnTable,
    ) -> Option<Arc<ColumnTable>> {
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
