//! Model columns for texels whose directions vary across the capture (pinhole cameras, point
//! lights): every texel sees its own light and view directions, so no one [`ColumnTable`]
//! serves them all. Instead a lattice of nodes over the image, close enough that no image's
//! light or view direction turns by more than [`LATTICE_STEP_DEG`] between neighbouring nodes,
//! each node with the column table of the directions at its pixel (built the first time a texel
//! needs it), and a texel's columns blended bilinearly in its position from the four nodes
//! around it. The directions are smooth in the position (they point at a lamp and a lens), so
//! the blend is the model at the texel's own directions to second order in the node spacing:
//! `reports/camera_resolution.md` measures the blend against the model evaluated directly.
//!
//! As with the shared table, the blend only serves the grid and the coarse searches; the final
//! search, the polish and every reported value and error use the model at the texel's own
//! directions, and grid costs that could make a texel ambiguous are evaluated again with the
//! model ([`Texel::fit`]).

use super::*;
use crate::model::frame::Vec3;
use std::sync::OnceLock;

/// Largest angle (degrees) any image's light or view direction turns between neighbouring
/// lattice nodes: about the table's own azimuth spacing (0.9375 deg). At 0.5 deg (before) the
/// blend at the grid's nodes was within 0.3 % of the model, at 1 deg within 0.75 %, both below
/// the table's own interpolation between its nodes (6 %), and the recovered maps were the same
/// (RMS height error 0.0085 and 0.0086 radii on 160 x 160 captures of 20 and 30 mm swatches at
/// 300 mm) for a quarter of the tables.
pub const LATTICE_STEP_DEG: f64 = 1.0;
/// Fewest pixels between neighbouring nodes: a node's table (65 x 192 model batches) costs
/// what some 40 texels fitted directly cost, so a cell of 8 x 8 texels still pays for its node
/// (at 16, a 30 mm swatch seen at 160 x 160 px fell back to evaluating every texel directly:
/// 10.9 s against 3.0 s with orthographic cameras; now 4.6 s); closer nodes would not pay for
/// themselves and the texels are evaluated directly instead.
pub const LATTICE_MIN_CELL: usize = 8;
/// A texel's own directions must lie this close (degrees) to the blend of its nodes'
/// directions for the lattice to serve it (directions not smooth in the position, as a view
/// map's may be, are evaluated directly).
pub const LATTICE_DIRECTION_SLACK_DEG: f64 = 0.01;
/// Probes per axis when the lattice measures how fast the directions turn across the image.
const PROBES: usize = 9;

/// Light and view direction of every image at one pixel (`None` where an image has none).
type NodeDirections = Vec<Option<(Vec3, Vec3)>>;
/// The nodes around a texel with their weights, and the image each of its observations is in.
type Corners = (Vec<(usize, f64)>, Vec<usize>);

/// A lattice of column tables over the image ([module docs](self)).
pub(super) struct DirectionLattice {
    /// Node columns and rows (pixels), ascending, from 0 to the last pixel.
    xs: Vec<usize>,
    ys: Vec<usize>,
    /// Per node (row-major), per image: the light and view directions at the node's pixel.
    directions: Vec<NodeDirections>,
    /// Per node: its table, built on first use (`None` where an image has no direction there).
    tables: Vec<OnceLock<Option<Arc<ColumnTable>>>>,
    /// Whether the tables hold the grid's points alone ([`Self::grid_only`]).
    grid_only: bool,
}

/// The four nodes around a texel with their weights, and which table row (image) each of the
/// texel's observations reads.
pub(super) struct Blend {
    corners: Vec<(Arc<ColumnTable>, f64)>,
    rows: Vec<usize>,
}

/// Angle between unit vectors, degrees.
fn angle_deg(a: &Vec3, b: &Vec3) -> f64 {
    // atan2 of |a x b| and a . b: accurate for small angles, unlike acos
    a.cross(b).norm().atan2(a.dot(b)).to_degrees()
}

/// `n` node positions from 0 to `last`, evenly spread (rounded to pixels).
fn spread(last: usize, n: usize) -> Vec<usize> {
    if last == 0 || n < 2 {
        return vec![0];
    }
    (0..n)
        .map(|i| ((i as f64 * last as f64 / (n - 1) as f64).round() as usize).min(last))
        .collect()
}

/// The cell [`xs[i]`, `xs[i + 1]`] holding `x` and the weight of its upper end.
fn cell(xs: &[usize], x: usize) -> (usize, usize, f64) {
    if xs.len() < 2 {
        return (0, 0, 0.0);
    }
    let i = xs.partition_point(|&n| n <= x).clamp(1, xs.len() - 1) - 1;
    let (a, b) = (xs[i], xs[i + 1]);
    let t = ((x as f64 - a as f64) / (b - a).max(1) as f64).clamp(0.0, 1.0);
    (i, i + 1, t)
}

impl DirectionLattice {
    /// The lattice for a `width` x `height` capture of `images` images whose image `k` has the
    /// light and view directions `geometry(k, x, y)` at pixel (x, y); `None` when the texels
    /// share their directions (the shared table serves them), when the directions turn so fast
    /// that nodes would lie closer than [`LATTICE_MIN_CELL`] pixels, or when both H and psi
    /// are not free (a table then depends on the texel's own fixed value).
    pub(super) fn new(
        width: usize,
        height: usize,
        images: usize,
        free: Free,
        geometry: impl Fn(usize, usize, usize) -> Option<(Vec3, Vec3)>,
    ) -> Option<Self> {
        if !(free.height && free.psi) || width == 0 || height == 0 || images == 0 {
            return None;
        }
        let at = |x: usize, y: usize| -> NodeDirections {
            (0..images).map(|k| geometry(k, x, y)).collect()
        };
        // how fast the directions turn: the largest angle per pixel between neighbouring probes
        let (px, py) = (spread(width - 1, PROBES), spread(height - 1, PROBES));
        let probes: Vec<NodeDirections> = py
            .iter()
            .flat_map(|&y| px.iter().map(move |&x| (x, y)))
            .map(|(x, y)| at(x, y))
            .collect();
        let turn = |a: &NodeDirections, b: &NodeDirections| -> Option<f64> {
            a.iter()
                .zip(b)
                .map(|(a, b)| match (a, b) {
                    (Some((la, va)), Some((lb, vb))) => {
                        Some(angle_deg(la, lb).max(angle_deg(va, vb)))
                    }
                    _ => None,
                })
                .try_fold(0.0f64, |m, x| x.map(|x| m.max(x)))
        };
        let mut rate = 0.0f64;
        for j in 0..py.len() {
            for i in 0..px.len() {
                let here = &probes[j * px.len() + i];
                if i + 1 < px.len() {
                    let d = (px[i + 1] - px[i]).max(1) as f64;
                    rate = rate.max(turn(here, &probes[j * px.len() + i + 1])? / d);
                }
                if j + 1 < py.len() {
                    let d = (py[j + 1] - py[j]).max(1) as f64;
                    rate = rate.max(turn(here, &probes[(j + 1) * px.len() + i])? / d);
                }
            }
        }
        if !(rate > 1e-12) {
            return None;
        }
        let step = LATTICE_STEP_DEG / rate;
        if !(step >= LATTICE_MIN_CELL as f64) {
            return None;
        }
        let nodes = |n: usize| ((n - 1) as f64 / step).ceil() as usize + 1;
        let (xs, ys) = (
            spread(width - 1, nodes(width)),
            spread(height - 1, nodes(height)),
        );
        let directions: Vec<NodeDirections> = ys
            .iter()
            .flat_map(|&y| xs.iter().map(move |&x| (x, y)))
            .map(|(x, y)| at(x, y))
            .collect();
        let tables = (0..directions.len()).map(|_| OnceLock::new()).collect();
        Some(Self {
            xs,
            ys,
            directions,
            tables,
            grid_only: false,
        })
    }

    /// The same lattice with no table built yet, whose tables hold the grid's points alone
    /// ([`ColumnTable::build_grid_for`]): for the global stage, whose few hundred sampled
    /// texels would not pay for the full tables of every node at every round (each a model
    /// batch per table node), but whose grids, read from the model texel by texel, cost most
    /// of its extra time over orthographic cameras. The coarse searches then evaluate the
    /// model.
    pub(super) fn grid_only(&self) -> Self {
        Self {
            xs: self.xs.clone(),
            ys: self.ys.clone(),
            directions: self.directions.clone(),
            tables: (0..self.directions.len()).map(|_| OnceLock::new()).collect(),
            grid_only: true,
        }
    }

    /// The lattice of a capture (its geometry per pixel, [`CaptureStore::geometry`]).
    pub(super) fn of_store(store: &CaptureStore, free: Free) -> Option<Self> {
        Self::new(
            store.width,
            store.height,
            store.images(),
            free,
            |k, x, y| store.geometry(k, x, y).map(|(l, v, _)| (l, v)),
        )
    }

    /// Nodes of the lattice (columns, rows).
    pub(super) fn nodes(&self) -> (usize, usize) {
        (self.xs.len(), self.ys.len())
    }

    fn table(&self, g: &Globals, node: usize) -> Option<Arc<ColumnTable>> {
        self.tables[node]
            .get_or_init(|| {
                let dirs: Option<Vec<(Vec3, Vec3)>> =
                    self.directions[node].iter().copied().collect();
                let free = Free {
                    height: true,
                    psi: true,
                    kd: false,
                    ks: false,
                    roughness: false,
                    anisotropy: false,
                };
                let start = TexelValues::default();
                dirs.map(|d| {
                    Arc::new(if self.grid_only {
                        ColumnTable::build_grid_for(&d, free, g, &start)
                    } else {
                        ColumnTable::build_for(&d, free, g, &start)
                    })
                })
            })
            .clone()
    }

    /// The nodes around `texel` with their weights, and the image of each of its
    /// observations, or `None` where the lattice cannot serve it (no pixel origin, a node
    /// without directions in some image, or the texel's own directions off the blend of its
    /// nodes' by more than [`LATTICE_DIRECTION_SLACK_DEG`]). Builds no table.
    fn corners(&self, texel: &Texel) -> Option<Corners> {
        let (x, y, rows) = {
            let mut xy = None;
            let mut rows = Vec::with_capacity(texel.obs.len());
            for s in &texel.obs {
                match s.origin {
                    Origin::Pixel { image, x, y } => {
                        if xy.is_some_and(|p| p != (x, y)) {
                            return None;
                        }
                        xy = Some((x, y));
                        rows.push(image as usize);
                    }
                    Origin::Line(_) => return None,
                }
            }
            let (x, y) = xy?;
            (x as usize, y as usize, rows)
        };
        let (i0, i1, tx) = cell(&self.xs, x);
        let (j0, j1, ty) = cell(&self.ys, y);
        let nx = self.xs.len();
        let mut weighted = vec![
            (j0 * nx + i0, (1.0 - tx) * (1.0 - ty)),
            (j0 * nx + i1, tx * (1.0 - ty)),
            (j1 * nx + i0, (1.0 - tx) * ty),
            (j1 * nx + i1, tx * ty),
        ];
        // a corner on the cell's far edge (or a single node) carries no weight
        weighted.retain(|c| c.1 > 0.0);
        weighted.dedup_by_key(|c| c.0);
        if weighted.is_empty() {
            weighted.push((j0 * nx + i0, 1.0));
        }
        // the texel's own directions against the blend of its nodes'
        let slack = LATTICE_DIRECTION_SLACK_DEG;
        for (s, &k) in texel.obs.iter().zip(&rows) {
            let (mut l, mut v) = (Vec3::zeros(), Vec3::zeros());
            for &(n, w) in &weighted {
                let (ln, vn) = self.directions[n].get(k).copied().flatten()?;
                l += w * ln;
                v += w * vn;
            }
            if !(angle_deg(&l.normalize(), &s.l) <= slack
                && angle_deg(&v.normalize(), &s.v) <= slack)
            {
                return None;
            }
        }
        // a node's table needs every image's directions there
        if weighted
            .iter()
            .any(|&(n, _)| self.directions[n].iter().any(Option::is_none))
        {
            return None;
        }
        Some((weighted, rows))
    }

    /// Whether [`Self::blend`] serves `texel` (without building a table).
    pub(super) fn serves(&self, texel: &Texel) -> bool {
        self.corners(texel).is_some()
    }

    /// The blend serving `texel`, or `None` where the lattice cannot ([`Self::serves`]);
    /// builds the tables of its nodes on first use.
    pub(super) fn blend(&self, texel: &Texel, g: &Globals) -> Option<Blend> {
        let (weighted, rows) = self.corners(texel)?;
        let corners = weighted
            .into_iter()
            .map(|(n, w)| self.table(g, n).map(|t| (t, w)))
            .collect::<Option<Vec<_>>>()?;
        Some(Blend { corners, rows })
    }
}

impl Blend {
    /// The texel's columns at table node (j, k): the nodes' columns there, blended.
    pub(super) fn at(&self, j: usize, k: usize) -> Vec<[f64; 4]> {
        self.blended(|t| t.at(j, k))
    }

    /// [`Self::at`] grid point (i, l) (table node [`ColumnTable::grid_node`]), read from the
    /// tables' grid copies.
    pub(super) fn at_grid(&self, i: usize, l: usize) -> Vec<[f64; 4]> {
        self.blended(|t| t.at_grid(i, l))
    }

    /// The nodes' columns `of` each table, blended.
    fn blended<'a>(&'a self, of: impl Fn(&'a ColumnTable) -> &'a [[f64; 4]]) -> Vec<[f64; 4]> {
        let mut out = vec![[0.0; 4]; self.rows.len()];
        for (t, w) in &self.corners {
            let cols = of(t);
            for (o, &r) in out.iter_mut().zip(&self.rows) {
                for m in 0..4 {
                    o[m] += w * cols[r][m];
                }
            }
        }
        out
    }

    /// Whether the blend can interpolate between the grid's points (not a grid-only lattice's).
    pub(super) fn interpolates(&self) -> bool {
        self.corners.iter().all(|(t, _)| t.interpolates())
    }

    /// The texel's columns at (H, psi): each node's table interpolated there, blended.
    pub(super) fn interpolate(&self, g: &Globals, h: f64, psi: f64) -> Vec<[f64; 4]> {
        let mut out = vec![[0.0; 4]; self.rows.len()];
        let Some((first, _)) = self.corners.first() else {
            return out;
        };
        // the tables share their nodes: one lookup serves them all
        let around = first.around(g, h, psi);
        for (t, w) in &self.corners {
            t.accumulate(around, &self.rows, *w, &mut out);
        }
        out
    }
}

/// The nodes (columns, rows) of the lattice map recovery of `store` with the maps `req` uses
/// for its texels' columns; `None` where it has none (shared directions: one table serves
/// them; directions that turn too fast: the model is evaluated directly).
pub fn lattice_nodes(store: &CaptureStore, req: &MapsConfig) -> Option<(usize, usize)> {
    DirectionLattice::of_store(store, free_of(req)).map(|l| l.nodes())
}

/// How well the lattice's blend stands in for the model at a texel's own directions
/// (`fibrefit bench camera`): the relative error of the modelled value (kd diffuse + ks
/// specular + ..., at the globals' albedos) over texels and (H, psi) points.
#[derive(Clone, Debug, Default, serde::Serialize)]
pub struct BlendError {
    /// Lattice nodes (columns x rows), 0 when the capture has no lattice.
    pub nodes: (usize, usize),
    /// Texels measured and points per texel.
    pub texels: usize,
    pub points: usize,
    /// At the grid's nodes (the blend in position only): max and RMS relative error.
    pub grid_max: f64,
    pub grid_rms: f64,
    /// At random (H, psi) between the nodes (the blend and the table's bilinear interpolation).
    pub between_max: f64,
    pub between_rms: f64,
    /// The same random points read from a table of the texel's own directions (what a shared
    /// table's interpolation costs an orthographic capture), for comparison.
    pub own_table_max: f64,
    pub own_table_rms: f64,
}

/// [`BlendError`] of the capture in `store` at the globals of `cfg` (its start values), on
/// `texels` seeded texels with `points` random (H, psi) each.
pub fn blend_error(
    store: &CaptureStore,
    cfg: &FitConfig,
    texels: usize,
    points: usize,
    seed: u64,
) -> Result<BlendError> {
    use rand::{Rng, SeedableRng};
    let req = &cfg.maps;
    check_request(cfg, req)?;
    let free = free_of(req);
    let set = fix_mapped(&ParamSet::from_config(cfg, store.channels)?, req);
    let model = rung_of(&set, cfg);
    let g = Globals::of(&set, model.as_ref(), store.channels);
    let Some(lattice) = DirectionLattice::of_store(store, free) else {
        return Ok(BlendError::default());
    };
    // the modelled value of the first channel at the globals' albedos
    let value =
        |cols: &[[f64; 4]], o: usize| -> f64 { (0..4).map(|k| g.albedo[k][0] * cols[o][k]).sum() };
    let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
    let ids = store.sample_texels(texels, seed);
    let (mut grid, mut between, mut own) = (vec![], vec![], vec![]);
    let (th, tp) = ColumnTable::dims(free);
    for &t in &ids {
        let texel = Texel::new(store.texel_samples(t), free, None);
        let Some(blend) = lattice.blend(&texel, &g) else {
            continue;
        };
        let own_table = ColumnTable::build(&texel, &g, &TexelValues::default());
        let push = |out: &mut Vec<f64>, approx: &[[f64; 4]], exact: &[[f64; 4]]| {
            for o in 0..texel.obs.len() {
                let e = value(exact, o);
                if e.abs() > 1e-12 {
                    out.push((value(approx, o) - e) / e);
                }
            }
        };
        for _ in 0..points {
            // a grid node, then a random point
            let (j, k) = (
                rng.random_range(0..HEIGHT_GRID) * TABLE_H_PER_GRID,
                rng.random_range(0..PSI_GRID) * TABLE_PSI_PER_GRID,
            );
            let (h, psi) = ColumnTable::node(th, tp, &g, &TexelValues::default(), j, k);
            push(&mut grid, &blend.at(j, k), &texel.columns_at(&g, h, psi));
            let (h, psi) = (
                rng.random_range(0.0..=g.h_max),
                rng.random_range(-90.0..90.0),
            );
            let exact = texel.columns_at(&g, h, psi);
            push(&mut between, &blend.interpolate(&g, h, psi), &exact);
            push(&mut own, &own_table.interpolate(&g, h, psi), &exact);
        }
    }
    let stats = |e: &[f64]| {
        let max = e.iter().fold(0.0f64, |m, x| m.max(x.abs()));
        let rms = (e.iter().map(|x| x * x).sum::<f64>() / e.len().max(1) as f64).sqrt();
        (max, rms)
    };
    let ((grid_max, grid_rms), (between_max, between_rms), (own_table_max, own_table_rms)) =
        (stats(&grid), stats(&between), stats(&own));
    Ok(BlendError {
        nodes: lattice.nodes(),
        texels: ids.len(),
        points,
        grid_max,
        grid_rms,
        between_max,
        between_rms,
        own_table_max,
        own_table_rms,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::load::capture::{light_at, pixel_position, view_at, Camera, Light};

    /// A 512 x 512 capture of a 20 mm swatch, four images of point lights and pinhole cameras
    /// 300 mm away (one a flash beside the lens): per image, the light and camera.
    fn rig() -> Vec<(Light, Camera)> {
        let at = |t: f64, p: f64| {
            let d =
                crate::model::frame::direction_from_angles(t.to_radians(), p.to_radians()) * 300.0;
            [d.x, d.y, d.z]
        };
        [
            (30.0, 110.0, 0.0, 0.0),
            (60.0, 100.0, 30.0, 290.0),
            (45.0, 20.0, 45.0, 200.0),
        ]
        .into_iter()
        .map(|(lt, lp, vt, vp)| {
            (
                Light::Point {
                    position_mm: at(lt, lp),
                    intensity: 0.09,
                },
                Camera::Pinhole {
                    position_mm: at(vt, vp),
                },
            )
        })
        .chain([(
            Light::Point {
                position_mm: [40.0, 0.0, 300.0],
                intensity: 0.09,
            },
            Camera::Pinhole {
                position_mm: [0.0, 0.0, 300.0],
            },
        )])
        .collect()
    }

    const SIZE: usize = 512;

    fn geometry(rig: &[(Light, Camera)], k: usize, x: usize, y: usize) -> Option<(Vec3, Vec3)> {
        let p = pixel_position([20.0, 20.0], SIZE, SIZE, x, y);
        Some((light_at(&rig[k].0, &p).0, view_at(&rig[k].1, &p)?))
    }

    fn texel(rig: &[(Light, Camera)], x: usize, y: usize) -> Texel {
        let obs = (0..rig.len())
            .map(|k| {
                let (l, v) = geometry(rig, k, x, y).unwrap();
                Sample {
                    l,
                    v,
                    fibre_azimuth: None,
                    map_value: None,
                    texel_height: None,
                    value: [0.1; 3],
                    sigma: None,
                    weight: 1.0,
                    origin: Origin::Pixel {
                        image: k as u32,
                        x: x as u32,
                        y: y as u32,
                    },
                }
            })
            .collect();
        Texel::new(obs, FREE, None)
    }

    const FREE: Free = Free {
        height: true,
        psi: true,
        kd: false,
        ks: false,
        roughness: false,
        anisotropy: false,
    };

    /// The relative error of the modelled value (kd 0.4, ks 0.3: the columns weighted as the
    /// fit weights them), largest over the observations.
    fn error(approx: &[[f64; 4]], exact: &[[f64; 4]]) -> f64 {
        let value = |c: &[f64; 4]| 0.4 * c[0] + 0.3 * c[1] + 0.4 * c[2] + c[3];
        approx
            .iter()
            .zip(exact)
            .map(|(a, e)| ((value(a) - value(e)) / value(e)).abs())
            .fold(0.0, f64::max)
    }

    #[test]
    fn the_blend_of_node_tables_is_the_model_at_the_texels_own_directions() {
        let cfg: FitConfig = toml::from_str(
            "model = \"varying-topology\"\nmetric = \"linear\"\n[parameters]\nkd = { value = 0.4 }\nks = { value = 0.3 }\nexponent = { value = 40 }\nspacing = { value = 2.0, vary = false }\nheight = { value = 0.9 }\nfibre_azimuth_deg = { value = 0 }\n",
        )
        .unwrap();
        let set = ParamSet::from_config(&cfg, 1).unwrap();
        let model = rung_of(&set, &cfg);
        let g = Globals::of(&set, model.as_ref(), 1);
        let rig = rig();
        let lattice = DirectionLattice::new(SIZE, SIZE, rig.len(), FREE, |k, x, y| {
            geometry(&rig, k, x, y)
        })
        .expect("directions that turn ~4 degrees over 512 pixels get a lattice");
        // 20 mm at 300 mm: ~0.0075 degrees per pixel at most, nodes <= 1 deg apart
        let (nx, ny) = lattice.nodes();
        assert!(
            (3..=12).contains(&nx) && (3..=12).contains(&ny),
            "{nx} x {ny}"
        );
        let (th, tp) = ColumnTable::dims(FREE);
        let (mut grid_worst, mut between_worst, mut own_worst) = (0.0f64, 0.0f64, 0.0f64);
        let mut rng = 0x2545_f491_4f6c_dd1du64;
        let mut uniform = move || {
            rng ^= rng << 13;
            rng ^= rng >> 7;
            rng ^= rng << 17;
            (rng >> 11) as f64 / (1u64 << 53) as f64
        };
        // texels in the middle of cells, on their edges and at the image's corners
        for (x, y) in [
            (0, 0),
            (511, 511),
            (37, 300),
            (256, 256),
            (100, 480),
            (444, 13),
        ] {
            let t = texel(&rig, x, y);
            let blend = lattice.blend(&t, &g).expect("smooth directions are served");
            assert_eq!(blend.rows, vec![0, 1, 2, 3]);
            for j in (0..th).step_by(TABLE_H_PER_GRID) {
                for k in (0..tp).step_by(TABLE_PSI_PER_GRID) {
                    let (h, psi) = ColumnTable::node(th, tp, &g, &TexelValues::default(), j, k);
                    grid_worst = grid_worst.max(error(&blend.at(j, k), &t.columns_at(&g, h, psi)));
                }
            }
            let own = ColumnTable::build(&t, &g, &TexelValues::default());
            for _ in 0..100 {
                let (h, psi) = (uniform() * g.h_max, -90.0 + 180.0 * uniform());
                let exact = t.columns_at(&g, h, psi);
                between_worst = between_worst.max(error(&blend.interpolate(&g, h, psi), &exact));
                own_worst = own_worst.max(error(&own.interpolate(&g, h, psi), &exact));
            }
        }
        eprintln!("relative error: grid {grid_worst:.2e}, between {between_worst:.2e}, own table {own_worst:.2e}");
        // at the grid's nodes only the blend in position is off: second order in the nodes'
        // spacing, below the 1 % noise (measured 1.9e-3 here; bench camera: 2.8e-3 worst of
        // 256 texels x 8 nodes)
        assert!(grid_worst < 1.2e-2, "{grid_worst}");
        // between the nodes the table's own interpolation dominates: the blend adds little
        assert!(
            between_worst < own_worst + 2e-3,
            "{between_worst} vs {own_worst}"
        );
    }

    #[test]
    fn shared_or_unsmooth_directions_get_no_lattice_and_strays_are_served_directly() {
        // every texel sees the same directions: the shared table serves them
        let same = |_: usize, _: usize, _: usize| {
            Some((Vec3::new(0.0, 0.6, 0.8), Vec3::new(0.0, 0.0, 1.0)))
        };
        assert!(DirectionLattice::new(SIZE, SIZE, 1, FREE, same).is_none());
        // a fixed azimuth: a table depends on the texel's own value
        let rig = rig();
        let fixed = Free { psi: false, ..FREE };
        assert!(
            DirectionLattice::new(SIZE, SIZE, 4, fixed, |k, x, y| geometry(&rig, k, x, y))
                .is_none()
        );
        // directions that turn too fast for nodes 16 pixels apart: direct evaluation
        assert!(DirectionLattice::new(16, 16, 4, FREE, |k, x, y| geometry(
            &rig,
            k,
            x * 32,
            y * 32
        ))
        .is_none());
        // a texel whose directions are not the smooth ones at its pixel (a view map's noise)
        let cfg: FitConfig = toml::from_str(
            "model = \"varying-topology\"\nmetric = \"linear\"\n[parameters]\nexponent = { value = 40 }\nspacing = { value = 2.0, vary = false }\nfibre_azimuth_deg = { value = 0 }\n",
        )
        .unwrap();
        let set = ParamSet::from_config(&cfg, 1).unwrap();
        let model = rung_of(&set, &cfg);
        let g = Globals::of(&set, model.as_ref(), 1);
        let lattice =
            DirectionLattice::new(SIZE, SIZE, 4, FREE, |k, x, y| geometry(&rig, k, x, y)).unwrap();
        let mut t = texel(&rig, 200, 300);
        assert!(lattice.blend(&t, &g).is_some());
        t.obs[2].v = (t.obs[2].v + Vec3::new(0.01, 0.0, 0.0)).normalize();
        assert!(lattice.blend(&t, &g).is_none());
    }
}
