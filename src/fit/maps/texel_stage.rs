//! Stage 2: every texel of a band of rows from the globals (the smoothness prior by Jacobi
//! sweeps), and the assembly of the bands into maps with their residual variance.

use super::*;

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
    /// Standard errors before scaling by the residual variance: sqrt of the diagonal of the
    /// texel's block of the joint covariance, C^-1 + C^-1 B^T S^-1 B C^-1 with the globals'
    /// Schur complement S ([`GlobalSchur`]), or of C^-1 alone when `globals_in_errors` is
    /// false; infinity where the data leave a value undetermined.
    pub unscaled_std_errors: Vec<TexelValues>,
    /// Whether the errors include the globals' uncertainty (false: fitted from globals without
    /// a Schur complement, e.g. a `--map-globals` file of an older fibrefit).
    #[serde(default)]
    pub globals_in_errors: bool,
    /// Other minima of each texel: (cost above the best, |dH|, |dpsi| in degrees), those
    /// costing less than `minima_below` above the best (all when `None`).
    pub other_minima: Vec<Vec<[f64; 3]>>,
    /// Other minima of each texel in its lobe: (cost above the best, |d roughness|,
    /// |d anisotropy strength|), kept as `other_minima` are (empty without lobe maps).
    #[serde(default)]
    pub other_lobe_minima: Vec<Vec<[f64; 3]>>,
    #[serde(default)]
    pub minima_below: Option<f64>,
    pub residual: Vec<f64>,
    /// Per row of the part: (sum of squared weighted residuals, residual count).
    pub row_costs: Vec<(f64, usize)>,
}

/// What [`texel_stage`] fits: a band of rows of a capture given the globals, and what the
/// global stage hands on to it.
#[derive(Clone, Copy)]
pub struct TexelStageRequest<'a> {
    /// The capture, texel by texel (no texel's samples are made before it is fitted, none kept
    /// after).
    pub store: &'a CaptureStore,
    pub cfg: &'a FitConfig,
    /// The maps asked for.
    pub req: &'a MapsConfig,
    /// The globals.
    pub set: &'a ParamSet,
    /// Rows [first, last) of the capture.
    pub rows: (u32, u32),
    /// The residual variance the global stage expects ([`GlobalStage`]): other minima costing
    /// more than [`MINIMA_MARGIN`] x [`AMBIGUITY_DELTA`] of it above the best are not kept (at
    /// camera resolution they are most of the memory); infinity keeps every one.
    pub variance_hint: f64,
    /// The global stage's Schur complement of the globals ([`GlobalStage::schur`]): with it each
    /// texel's errors include the globals' uncertainty (its cross block with the globals is made
    /// from its own pixels when its errors are, and dropped); without it they are conditional
    /// on the globals.
    pub schur: Option<&'a GlobalSchur>,
}

/// Stage 2 for the texels in the rows of `r` given its globals, texel by texel from the compact
/// store ([`TexelStageRequest`]).
pub fn texel_stage(
    r: &TexelStageRequest,
    progress: &crate::progress::Progress,
) -> Result<TexelPart> {
    let TexelStageRequest {
        store,
        cfg,
        req,
        rows,
        variance_hint,
        schur,
        ..
    } = *r;
    let minima_below = (variance_hint.is_finite() && variance_hint > 0.0)
        .then_some(MINIMA_MARGIN * AMBIGUITY_DELTA * variance_hint);
    check_request(cfg, req)?;
    let free = free_of(req);
    let set = fix_mapped(r.set, req);
    let model = rung_of(&set, cfg);
    let g = Globals::of(&set, model.as_ref(), store.channels)
        .with_lattice(store, free)
        .with_variance(variance_hint);
    // the globals free in the global stage are those its Schur complement names (a result read
    // back holds every global fixed)
    let steps = GlobalSteps::new(&freed(&set, schur), cfg);
    if let Some(s) = schur {
        check_schur(s, &steps)?;
    }
    let sweeps = sweeps_of(req);
    let band = Band::new(store, &set, free, rows, sweeps);
    // the texels' keys from the starts they are fitted from
    let plan = plan_tables(store, &g, free, &|t| band.start_of(t));
    let g = g.with_tables(plan);
    let side = GlobalSide::new(&steps, store.channels, schur);
    let mut swept = band.sweep(&g, req.smoothness, sweeps, minima_below, progress);
    let smoothness = req.smoothness * f64::from(u8::from(sweeps > 1));
    let keep: Vec<usize> = (band.t0..band.t1).filter(|&t| band.kept(t)).collect();
    let details = band.details(&g, &side, &swept, &keep, smoothness);
    let row_costs = band.row_costs(&keep, &swept, &details);
    let (t0, texels) = (band.t0, band.texels);
    Ok(TexelPart {
        rows: [rows.0, rows.1],
        texels: keep.iter().map(|&t| texels[t]).collect(),
        values: keep.iter().map(|&t| swept.fits[t - t0].0).collect(),
        unscaled_std_errors: details.iter().map(|d| d.0).collect(),
        other_minima: keep
            .iter()
            .map(|&t| std::mem::take(&mut swept.fits[t - t0].2))
            .collect(),
        other_lobe_minima: keep
            .iter()
            .map(|&t| std::mem::take(&mut swept.fits[t - t0].3))
            .collect(),
        residual: details.iter().map(|d| d.1).collect(),
        globals_in_errors: schur.is_some(),
        minima_below,
        row_costs,
    })
}

/// Sweeps of the texel stage for `req`: 1, or 1 + [`PRIOR_SWEEPS`] with the smoothness prior.
pub(super) fn sweeps_of(req: &MapsConfig) -> usize {
    if req.smoothness > 0.0 {
        1 + PRIOR_SWEEPS
    } else {
        1
    }
}

/// Refuse a Schur complement `s` that is not over the globals `steps` frees.
fn check_schur(s: &GlobalSchur, steps: &GlobalSteps) -> Result<()> {
    let n = s.names.len();
    if s.names != steps.names || s.matrix.len() != n * n || s.reference.len() != n {
        bail!(
            "the globals' Schur complement (maps.method.global_schur) is over [{}], but these globals have [{}] to free: fit the texels with the globals and config it was made with",
            s.names.join(", "),
            steps.names.join(", ")
        );
    }
    Ok(())
}

/// A texel's fit in the texel stage: best values, cost, other minima (pruned: [`prune_minima`]).
/// A texel's fit in the texel stage: best values, cost, other minima in (H, psi) and in the
/// lobe (pruned: [`prune_minima`]).
type BandFit = (TexelValues, f64, Vec<[f64; 3]>, Vec<[f64; 3]>);

/// What the sweeps of a band leave: per texel of the band, the last sweep's values and fits.
struct Swept {
    values: Vec<TexelValues>,
    fits: Vec<BandFit>,
}

/// The texels a part fits: those of its rows and, with the prior, a halo of one row per later
/// sweep around them, so a part's texels are what a single run gives.
struct Band<'a> {
    store: &'a CaptureStore,
    /// Every texel of the capture, row-major.
    texels: &'a [(u32, u32)],
    /// The globals with the mapped parameters fixed.
    set: &'a ParamSet,
    free: Free,
    /// Rows [first, last) the part keeps.
    rows: (u32, u32),
    /// The texels fitted, rows and halo: ids [t0, t1).
    t0: usize,
    t1: usize,
}

impl<'a> Band<'a> {
    fn new(
        store: &'a CaptureStore,
        set: &'a ParamSet,
        free: Free,
        rows: (u32, u32),
        sweeps: usize,
    ) -> Self {
        // a halo of one row per later sweep makes a part's texels what a single run gives
        let halo = (sweeps - 1) as u32;
        let lo = rows.0.saturating_sub(halo);
        let hi = rows.1.saturating_add(halo);
        let texels = store.texels();
        // texels are row-major: those of rows [lo, hi) are the ids [t0, t1)
        let t0 = texels.partition_point(|t| t.1 < lo);
        let t1 = texels.partition_point(|t| t.1 < hi);
        Self {
            store,
            texels,
            set,
            free,
            rows,
            t0,
            t1,
        }
    }

    /// Texel `t`'s start, from any of its samples.
    fn start_of(&self, t: usize) -> TexelValues {
        let s = (0..self.store.images())
            .find_map(|k| self.store.sample(t, k))
            .expect("a stored texel has a sample");
        start_value(&s, self.set)
    }

    /// Whether texel `t` lies in the part's own rows (not the halo).
    fn kept(&self, t: usize) -> bool {
        (self.rows.0..self.rows.1).contains(&self.texels[t].1)
    }

    /// Texel `t`'s problem with the prior of weight `smoothness` from its neighbours' `values`
    /// (those of the band; their starts outside it).
    fn problem(&self, t: usize, values: &[TexelValues], smoothness: f64) -> Texel {
        let (x, y) = (self.texels[t].0 as i64, self.texels[t].1 as i64);
        let neighbours: Vec<usize> = [(-1i64, 0i64), (1, 0), (0, -1), (0, 1)]
            .iter()
            .filter_map(|(dx, dy)| self.store.texel_at(x + dx, y + dy))
            .collect();
        let nbs: Vec<TexelValues> = neighbours
            .into_iter()
            .map(|j| match j.checked_sub(self.t0) {
                Some(k) if j < self.t1 => values[k],
                _ => self.start_of(j),
            })
            .collect();
        Texel::new(
            self.store.texel_samples(t),
            self.free,
            prior_of(&nbs, smoothness),
        )
    }

    /// Every texel of the band fitted `sweeps` times from its start: the first sweep without
    /// the prior, the later ones with it (Jacobi: the neighbours' values of the sweep before).
    /// Other minima are kept in the last sweep for the part's own texels, those costing at most
    /// `minima_below` above the best ([`prune_minima`]).
    fn sweep(
        &self,
        g: &Globals,
        smoothness: f64,
        sweeps: usize,
        minima_below: Option<f64>,
        progress: &crate::progress::Progress,
    ) -> Swept {
        let (t0, t1) = (self.t0, self.t1);
        let start: Vec<TexelValues> = (t0..t1).into_par_iter().map(|t| self.start_of(t)).collect();
        let mut values = start.clone();
        let bar = progress.bar((sweeps * (t1 - t0)) as u64, "maps: texels");
        // per texel: best values, cost, other minima (pruned; last sweep, kept texels only)
        let mut fits: Vec<BandFit> = Vec::new();
        for sweep in 0..sweeps {
            let smoothness = if sweep == 0 { 0.0 } else { smoothness };
            let last = sweep + 1 == sweeps;
            fits = (t0..t1)
                .into_par_iter()
                .map(|t| {
                    let (v, cost, others) =
                        self.problem(t, &values, smoothness).fit(g, &start[t - t0]);
                    bar.inc(1);
                    let (shape, lobe) = if last && self.kept(t) {
                        let below = minima_below.unwrap_or(f64::INFINITY);
                        (
                            prune_minima(&v, cost, &others, below, shape_distance),
                            prune_minima(&v, cost, &others, below, lobe_distance),
                        )
                    } else {
                        (vec![], vec![])
                    };
                    (v, cost, shape, lobe)
                })
                .collect();
            for (k, f) in fits.iter().enumerate() {
                values[k] = f.0;
            }
        }
        bar.finish_and_clear();
        Swept { values, fits }
    }

    /// Per texel of `keep`: standard errors before scaling, relative residual, residual count,
    /// at the values `swept` reached (the prior of weight `smoothness`).
    fn details(
        &self,
        g: &Globals,
        side: &GlobalSide,
        swept: &Swept,
        keep: &[usize],
        smoothness: f64,
    ) -> Vec<(TexelValues, f64, usize)> {
        keep.par_iter()
            .map(|&t| {
                let p = self.problem(t, &swept.values, smoothness);
                let v = &swept.fits[t - self.t0].0;
                (
                    p.std_errors(g, v, Some(side), 1.0),
                    p.relative_residual(g, v),
                    p.obs.len() * self.store.channels,
                )
            })
            .collect()
    }

    /// Per row of the part: (sum of its texels' costs, their residual count), in texel order.
    fn row_costs(
        &self,
        keep: &[usize],
        swept: &Swept,
        details: &[(TexelValues, f64, usize)],
    ) -> Vec<(f64, usize)> {
        let n_rows = (self.rows.1 - self.rows.0) as usize;
        let mut row_costs = vec![(0.0, 0usize); n_rows];
        for (&t, d) in keep.iter().zip(details) {
            let r = &mut row_costs[(self.texels[t].1 - self.rows.0) as usize];
            r.0 += swept.fits[t - self.t0].1;
            r.1 += d.2;
        }
        row_costs
    }
}

/// `set` with exactly the globals `schur` names free (unchanged without one).
fn freed(set: &ParamSet, schur: Option<&GlobalSchur>) -> ParamSet {
    let Some(s) = schur else {
        return set.clone();
    };
    let mut out = set.clone();
    for sh in &mut out.shapes {
        sh.vary = s.names.iter().any(|n| n == sh.kind.name());
    }
    for a in 0..out.albedos.len() {
        let on = (0..out.channels).any(|c| s.names.contains(&problem::albedo_label(set, a, c)));
        out.albedos[a].vary = on;
    }
    out
}

/// (|dH|, |dpsi| in degrees) between two texel values.
pub(super) fn shape_distance(w: &TexelValues, v: &TexelValues) -> [f64; 2] {
    [(w.height - v.height).abs(), wrap_azimuth(w.psi - v.psi).abs()]
}

/// (|d roughness|, |d anisotropy strength|) between two texel values.
pub(super) fn lobe_distance(w: &TexelValues, v: &TexelValues) -> [f64; 2] {
    [
        (w.roughness - v.roughness).abs(),
        (w.anisotropy - v.anisotropy).abs(),
    ]
}

/// The other minima of a texel fitted to `v` at `cost`, those at most `below` above it, as
/// (cost above the best, the two `distance`s: [`shape_distance`] or [`lobe_distance`]),
/// keeping only those no other one dominates (as good or better in cost and as far or farther
/// in both): [`finish_maps`] widens the standard errors by the farthest minimum within a cost
/// margin, which the kept ones give for any margin.
pub(super) fn prune_minima(
    v: &TexelValues,
    cost: f64,
    others: &[(TexelValues, f64)],
    below: f64,
    distance: fn(&TexelValues, &TexelValues) -> [f64; 2],
) -> Vec<[f64; 3]> {
    let all: Vec<[f64; 3]> = others
        .iter()
        .filter(|(_, c)| c - cost <= below)
        .map(|(w, c)| {
            let [a, b] = distance(w, v);
            [c - cost, a, b]
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

/// The capture whose parts [`finish_maps`] assembles, and what its residual variance counts.
#[derive(Clone, Copy)]
pub struct Assembly<'a> {
    /// Texels across the capture.
    pub width: usize,
    /// Rows of the capture: the parts must cover them exactly.
    pub height: usize,
    pub channels: usize,
    /// The maps asked for.
    pub req: &'a MapsConfig,
    /// Globals the global stage fitted: unknowns of the residual variance besides the texels'.
    pub global_free: usize,
    /// H_max at the globals: a height error at or above half of it leaves the height
    /// undetermined.
    pub h_max: f64,
}

/// Assemble parts covering every row into the maps: the residual variance over all pixel values
/// less every unknown (each texel's and the globals' `a.global_free`), the standard errors scaled
/// by it and widened where another minimum is as good within [`AMBIGUITY_DELTA`] variances.
pub fn finish_maps(parts: Vec<TexelPart>, a: &Assembly) -> Result<(TexelMaps, f64, Vec<String>)> {
    let free = free_of(a.req);
    let mut parts = parts;
    parts.sort_by_key(|p| p.rows[0]);
    check_cover(&parts, a.height)?;
    let texels: usize = parts.iter().map(|p| p.texels.len()).sum();
    let variance = residual_variance(&parts, texels, free, a)?;
    let (maps, flags) = scaled_maps(parts, texels, variance, free, a);
    let warnings = finish_warnings(&maps, &flags, variance, free, a.h_max);
    Ok((maps, variance, warnings))
}

/// Refuse parts (sorted by their first row) that do not cover rows 0..`height` exactly.
fn check_cover(parts: &[TexelPart], height: usize) -> Result<()> {
    let mut next = 0u32;
    for p in parts {
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
    Ok(())
}

/// The residual variance over every pixel value of `parts` (holding `texels` texels), less
/// every unknown; refused when the pixel values cannot determine them.
fn residual_variance(parts: &[TexelPart], texels: usize, free: Free, a: &Assembly) -> Result<f64> {
    // sums in row order: the same bits however the rows were split
    let (mut cost, mut n) = (0.0, 0usize);
    for p in parts {
        for &(c, k) in &p.row_costs {
            cost += c;
            n += k;
        }
    }
    let params = per_texel_unknowns(free, a.channels) * texels + a.global_free;
    if n <= params {
        bail!("--maps: {n} pixel values cannot determine {params} unknowns; use more images");
    }
    Ok(cost / (n - params) as f64)
}

/// What the assembled maps warn of.
#[derive(Default)]
struct Flags {
    /// Some part's errors leave out the globals' uncertainty.
    conditional: bool,
    /// Some part kept fewer other minima than the ambiguity margin needs.
    minima_cut: bool,
    /// Texels with another minimum within the ambiguity margin.
    ambiguous: usize,
}

/// The maps of `parts` (`texels` texels) with their standard errors scaled by the residual
/// `variance` and widened by their other minima; each part moved into the maps and dropped, so
/// the maps never exist twice.
fn scaled_maps(
    parts: Vec<TexelPart>,
    texels: usize,
    variance: f64,
    free: Free,
    a: &Assembly,
) -> (TexelMaps, Flags) {
    let scale = variance.sqrt();
    let mut maps = TexelMaps {
        width: a.width,
        height: a.height,
        texels: Vec::with_capacity(texels),
        values: Vec::with_capacity(texels),
        std_errors: Vec::with_capacity(texels),
        residual: Vec::with_capacity(texels),
        ambiguous: Vec::with_capacity(texels),
        channels: a.channels,
    };
    let mut flags = Flags {
        conditional: parts.iter().any(|p| !p.globals_in_errors),
        ..Flags::default()
    };
    for mut p in parts {
        flags.minima_cut |= p
            .minima_below
            .is_some_and(|b| b < AMBIGUITY_DELTA * variance);
        for k in 0..p.texels.len() {
            let lobe = p.other_lobe_minima.get(k).map_or(&[][..], |m| &m[..]);
            let (se, amb) = widened(
                &p.unscaled_std_errors[k],
                [&p.other_minima[k], lobe],
                (scale, variance),
                free,
            );
            flags.ambiguous += usize::from(amb);
            maps.ambiguous.push(amb);
            maps.std_errors.push(se);
        }
        maps.texels.append(&mut p.texels);
        maps.values.append(&mut p.values);
        maps.residual.append(&mut p.residual);
    }
    (maps, flags)
}

/// A texel's standard errors: `unscaled` times `scale` (the residual variance's square root),
/// H and psi, and the lobe's roughness and anisotropy strength, widened to the farthest of its
/// other minima (`others`: in (H, psi) and in the lobe, as [`prune_minima`] keeps them) within
/// [`AMBIGUITY_DELTA`] x `variance` of the best; and whether there was one.
fn widened(
    unscaled: &TexelValues,
    [others, lobe]: [&[[f64; 3]]; 2],
    (scale, variance): (f64, f64),
    free: Free,
) -> (TexelValues, bool) {
    let u = unscaled;
    let mut se = TexelValues {
        height: u.height * scale,
        psi: u.psi * scale,
        kd: u.kd.map(|x| x * scale),
        ks: u.ks.map(|x| x * scale),
        roughness: u.roughness * scale,
        anisotropy: u.anisotropy * scale,
    };
    let mut amb = false;
    for &[dc, dh, dp] in others {
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
    for &[dc, dr, da] in lobe {
        if dc <= AMBIGUITY_DELTA * variance {
            amb = true;
            if free.roughness {
                se.roughness = se.roughness.max(dr);
            }
            if free.anisotropy {
                se.anisotropy = se.anisotropy.max(da);
            }
        }
    }
    (se, amb)
}

/// The warnings of the assembled `maps`: errors without the globals' uncertainty, other minima
/// cut, values the images leave undetermined, ambiguous texels.
fn finish_warnings(
    maps: &TexelMaps,
    flags: &Flags,
    variance: f64,
    free: Free,
    h_max: f64,
) -> Vec<String> {
    let texels = maps.texels.len();
    let mut warnings = Vec::new();
    if flags.conditional {
        warnings.push(
            "per-texel standard errors leave out the globals' uncertainty (the globals came without their Schur complement, maps.method.global_schur: a `--map-globals` result of an older fibrefit), so they are too small where the globals trade off with the maps: refit the globals with `--map-globals`".to_string(),
        );
    }
    if flags.minima_cut {
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
        (
            free.roughness,
            "roughness",
            undetermined(|e| e.roughness, 0.5),
            "0.5",
        ),
        (
            free.anisotropy,
            "anisotropy strength",
            undetermined(|e| e.anisotropy, 0.5),
            "0.5",
        ),
    ] {
        if on && count > 0 {
            warnings.push(format!(
                "the images leave the {name} undetermined in {count} of {texels} texels (standard error at or above {range}): add light and view directions that separate it (grazing light across the fibres, views on both sides), or set [maps] smoothness"
            ));
        }
    }
    let ambiguous = flags.ambiguous;
    if ambiguous > 0 {
        warnings.push(format!(
            "{ambiguous} of {texels} texels have another minimum within {AMBIGUITY_DELTA} residual variances of the best (a height or fibre azimuth fitting the images as well): their standard errors cover the distance between the minima"
        ));
    }
    warnings
}

/// The [`TablePlan`] of the whole capture, texel by texel in order (not of `rows` alone: a tile
/// fitted in a process of its own then tables the texels a single run tables, and fits them to
/// the same bit). Texels the lattice serves read no shared table and have no say.
fn plan_tables(
    store: &CaptureStore,
    g: &Globals,
    free: Free,
    start_of: &(impl Fn(usize) -> TexelValues + Sync),
) -> TablePlan {
    // keys in parallel, a chunk at a time, met in order; stops once the plan is full
    const CHUNK: usize = 4096;
    let mut plan = TablePlan::default();
    if free.lobe() {
        // the tables hold the globals' lobe: texels with their own evaluate the model
        return plan;
    }
    let n = store.texels().len();
    for lo in (0..n).step_by(CHUNK) {
        let keys: Vec<Option<Vec<u64>>> = (lo..(lo + CHUNK).min(n))
            .into_par_iter()
            .map(|t| {
                let texel = Texel::new(store.texel_samples(t), free, None);
                (!g.lattice_serves(&texel)).then(|| texel.grid_key(&start_of(t)))
            })
            .collect();
        for key in keys.into_iter().flatten() {
            plan.meet(key);
        }
        if plan.is_full() {
            break;
        }
    }
    plan
}
