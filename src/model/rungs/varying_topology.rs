//! `varying-topology` (seeds 001/002): MODEL.md §2 with the elevation phi from the topology,
//! closed-form diffuse over the exact visible-and-lit arcs, and N-point Gauss–Legendre for the
//! specular lobe.
//!
//! f(l, v) = [ sum over the period's 2 fibres of int_{vis & lit} f_fib (n.l)(n.v) dth
//!             + int_{vis & lit substrate} f_sub (N.l)(N.v) dx ] / (P (N.l)(N.v))
//!
//! With n.l = |l_p| cos(th - alpha_l) the |l_p||v_p| factors cancel against (N.l)(N.v), leaving
//! cos(alpha_l) cos(alpha_v) in the denominator. Using cos(th - a) cos(th - b) =
//! 1/2 [cos(a - b) + cos(2 th - a - b)] and r.v = 2 (n.l)(n.v) - l.v, each specular node costs
//! one cosine and one power. The specular rule covers the part of each arc inside the lobe
//! window, where r.v > exp(ln(1e-15)/e) of its peak (outside it (r.v)^e < 1e-15 of the peak),
//! with the same N Gauss–Legendre nodes on every arc: the result is then a smooth function of the
//! arc ends, hence of the parameters. (Allocating nodes in proportion to arc length was cheaper
//! but jumps whenever a node count changes, and finite-difference Jacobians amplify those jumps
//! a million-fold: the fit's standard errors depended on the start.) At H = 0 the two fibres of a
//! period have identical arcs, so one is computed and counted twice.

use crate::model::cross_section::{
    compact_gaps, for_each_seen_and_lit, lobe_half_width, substrate_fractions, DiffuseArc,
    DiffuseArcs, Fibre, FibreOcclusions, Pattern, Projected, SectionPair, SubstrateProblem,
};
use crate::model::frame::Local;
use crate::model::numerics::elementary;
use crate::model::numerics::lobe_quadrature::{LobeArc, LobeRule, LobeShape};
use crate::model::numerics::quadrature::GaussLegendre;
use crate::model::parameter::{Ability::*, Param};
use crate::model::rung::{Cost, LobeAlbedo, LobeSampling, Rung, Sampling, ShaderSection};
use crate::model::topology::elevation_from_height;
use crate::model::{Basis, DirectionPair, ShadingModel};
use std::f64::consts::{FRAC_1_PI, PI};

/// The rung.
pub static RUNG: Rung = Rung {
    name: "varying-topology",
    description: "fibres climbing on their neighbours, heights from a topology map",
    abilities: &[
        FibreDiffuse,
        SpecularLobe,
        Fresnel,
        CrossSection,
        crate::model::Ability::Topology,
        HeightHistogram,
        FibreDirection,
        DirectionSpread,
    ],
    build: |a| {
        Box::new(VaryingTopology::new(
            a.spacing,
            a.exponent,
            a.quadrature_order,
            a.topology.discretise(a.spacing, a.histogram_bins),
        ))
    },
    sampling: Sampling {
        lobe: LobeSampling::FibreCone,
        diffuse_tube: 0.0,
        diffuse_cosine: 1.0,
        lobe_albedo: LobeAlbedo::ConeTable,
        cone_from: Some(&RUNG),
    },
    shader: ShaderSection::Sections {
        sections: &["cross_section"],
        body: "    let sp = fibrefit_pair(l, v, p.shape.w);
    if (at_height) {
        return vec4<f32>(fibrefit_pattern(sp, p.shape.y, height, 1.0, p.shape.x), 0.0);
    }
    var heights = p.heights;
    var b = vec3<f32>(0.0);
    for (var k = 0u; k < FIBREFIT_HEIGHT_NODES; k++) {
        b += fibrefit_pattern(sp, p.shape.y, heights[k].x, heights[k].y, p.shape.x);
    }
    return vec4<f32>(b, 0.0);\n",
        material_rows: None,
    },
    cost: Cost::HeightHistogram,
    auto_rank: Some(5),
    example: EXAMPLE,
    symmetries: &[],
    renderer: None,
    auto_fuzz: true,
};

/// The varying-topology example (the reference shares it).
pub const EXAMPLE: &[(Param, f64)] = &[
    (Param::Kd, 0.3),
    (Param::Ks, 0.6),
    (Param::Exponent, 100.0),
    (Param::Spacing, 2.4),
    (Param::Height, 0.9),
    (Param::MapScale, 0.2),
];

/// Closed-form diffuse + Gauss–Legendre specular over one pattern.
#[derive(Clone, Debug)]
pub struct GaussSection {
    lobe_rule: LobeRule,
    exponent: f64,
    /// Phong normalisation (e + 2) / (2 pi).
    norm: f64,
    /// Fraction of the peak of r.v where the specular window ends.
    lobe_floor: f64,
}

impl GaussSection {
    pub fn new(exponent: f64, order: usize) -> Self {
        Self {
            lobe_rule: LobeRule::new(&GaussLegendre::new(order)),
            exponent,
            norm: (exponent + 2.0) / (2.0 * PI),
            lobe_floor: (1e-15f64.ln() / exponent).exp(),
        }
    }

    /// What the specular lobe needs from a light/view pair (the same for every height), one pair
    /// at a time: the definition [`GaussSection::prepare`] computes in lanes.
    fn lobe(&self, sp: &SectionPair) -> Lobe {
        Lobe {
            cos_delta: sp.cos_delta(),
            sigma: sp.l.alpha + sp.v.alpha,
            k2: 2.0 * sp.l.len * sp.v.len,
            window: sp.lobe_window(self.lobe_floor),
        }
    }

    /// The bases of `pairs` (written to `out`) for the mean over `patterns` ((pattern, weight)
    /// pairs). The work is split into passes over the whole batch so that everything with
    /// data-dependent branches or long latency (divisions, square roots, polynomials) runs as
    /// branch-free lane loops ([`crate::model::numerics::lanes::on_widest_lanes`]); only the arc bookkeeping stays
    /// scalar. Per (pair, pattern) "visit":
    /// 1. each pair's projections and lobe window, in lanes (`GaussSection::prepare`);
    /// 2. each fibre's occlusion problem seen along v and lit along l, solved in lanes
    ///    ([`FibreOcclusions::solve`]: four gap slots in s = sin(th - alpha)), then compacted
    ///    without branches;
    /// 3. the asin of every gap end, in lanes ([`elementary::asin_in_place`]);
    /// 4. per visit, scalar: the seen-and-lit arcs (merge of the two gap lists), each queued for
    ///    the diffuse kernel and, clipped to the lobe window, for the lobe: once per pair, the
    ///    lobe being the same at every height (a narrow lobe's window lies inside most heights'
    ///    arcs: 59-86 % of the clipped arcs repeat one of their pair's at exponents 30-1000);
    /// 5. the diffuse kernels ([`DiffuseArcs::kernels`]), the substrate fractions
    ///    ([`substrate_fractions`]) and the lobe integrals ([`LobeRule::integrals`]), each in
    ///    lanes, summed back per visit in the order of step 4.
    ///
    /// Each pair's result does not depend on the other pairs in the batch, bit for bit (tested).
    pub fn bases(&self, pairs: &[DirectionPair], patterns: &[(Pattern, f64)], out: &mut [Basis]) {
        self.bases_with(pairs, |_| patterns, out)
    }

    /// [`GaussSection::bases`] with pair i averaged over `patterns(i)` (one pattern each: a
    /// sampler's draws at their texels' heights); each pair's result is its `bases` with its
    /// own patterns, bit for bit.
    fn bases_with<'p>(
        &self,
        pairs: &[DirectionPair],
        patterns: impl Fn(usize) -> &'p [(Pattern, f64)],
        out: &mut [Basis],
    ) {
        assert_eq!(pairs.len(), out.len());
        SCRATCH.with(|scratch| {
            let mut scratch = scratch.borrow_mut();
            let BatchScratch {
                prepared,
                visits,
                problems,
                substrates,
                fractions,
                ends,
                gap_counts,
                diffuse_arcs,
                diffuse_dest,
                arcs,
                dest,
                values,
            } = &mut *scratch;
            self.prepare(pairs, prepared);
            visits.clear();
            problems.clear();
            substrates.clear();
            for (i, (pair, (sp, _))) in pairs.iter().zip(prepared.iter()).enumerate() {
                if !pair.above_horizon() {
                    continue;
                }
                for &(pattern, weight) in patterns(i) {
                    if !(pattern.period * sp.cos_alpha_product() > 0.0) {
                        continue;
                    }
                    let (view, light) = (pattern.occlusion(&sp.v), pattern.occlusion(&sp.l));
                    // per fibre in the order of `fibres`: seen along v, lit along l
                    let (even, odd) = (Fibre::Even, Fibre::Odd);
                    let four = [view.of(even), light.of(even), view.of(odd), light.of(odd)];
                    problems.extend(&four[..2 * fibres(&pattern).len()]);
                    substrates.push(SubstrateProblem::new(&pattern, &sp.l, &sp.v));
                    visits.push(Visit {
                        pair: i,
                        pattern,
                        weight,
                        diffuse: 0.0,
                        substrate: 0.0,
                    });
                }
            }
            problems.solve();
            ends.clear();
            gap_counts.clear();
            for p in 0..problems.len() {
                let at = ends.len();
                ends.resize(at + 8, 0.0);
                let window: &mut [f64; 8] = (&mut ends[at..]).try_into().expect("8 ends");
                let n = compact_gaps(&problems.slots(p), window);
                ends.truncate(at + 2 * n);
                gap_counts.push(n as u8);
            }
            elementary::asin_in_place(ends);
            diffuse_arcs.clear();
            diffuse_dest.clear();
            arcs.clear();
            dest.clear();
            let (mut at, mut problem) = (0, 0);
            // (pair, its first arc in `arcs`): visits come pair by pair
            let mut pair_arcs = (usize::MAX, 0);
            for (v, visit) in visits.iter_mut().enumerate() {
                let (sp, lobe) = &prepared[visit.pair];
                let (pattern, weight) = (&visit.pattern, &visit.weight);
                let counts = &gap_counts[problem..problem + 2 * fibres(pattern).len()];
                problem += counts.len();
                let one = OneVisit {
                    pattern,
                    sp,
                    lobe,
                    weight: *weight,
                    gap_counts: counts,
                    ends: &ends[at..],
                };
                at += self.visit_arcs(
                    &one,
                    &mut |arc, count| {
                        diffuse_arcs.push(arc);
                        diffuse_dest.push((v, count));
                    },
                    &mut |arc, factor| {
                        // the pair's lobe is the same at every height: an arc it already has
                        // (most often the whole window) has the same integral
                        if pair_arcs.0 != visit.pair {
                            pair_arcs = (visit.pair, arcs.len());
                        }
                        let same = arcs[pair_arcs.1..]
                            .iter()
                            .position(|a| a.a == arc.a && a.b == arc.b);
                        let k = match same {
                            Some(j) => pair_arcs.1 + j,
                            None => {
                                arcs.push(arc);
                                arcs.len() - 1
                            }
                        };
                        dest.push((visit.pair, factor, k));
                    },
                );
            }
            let fractions = grown(fractions, substrates.len());
            substrate_fractions(substrates, fractions);
            for (visit, f) in visits.iter_mut().zip(fractions.iter()) {
                visit.substrate = *f;
            }
            let kernels = grown(values, diffuse_arcs.len());
            diffuse_arcs.kernels(kernels);
            for (&(v, count), k) in diffuse_dest.iter().zip(kernels.iter()) {
                visits[v].diffuse += count * k;
            }
            out.fill(Basis::default());
            for visit in visits.iter() {
                let (sp, _) = &prepared[visit.pair];
                let (pattern, weight) = (&visit.pattern, &visit.weight);
                let denom = pattern.period * sp.cos_alpha_product();
                let b = Basis {
                    diffuse: weight * FRAC_1_PI * visit.diffuse / denom,
                    specular: 0.0,
                    substrate: weight * FRAC_1_PI * visit.substrate,
                    fuzz: 0.0,
                };
                out[visit.pair] = out[visit.pair] + b;
            }
            let integrals = grown(values, arcs.len());
            self.lobe_rule.integrals(arcs, integrals);
            for &(i, factor, k) in dest.iter() {
                out[i].specular += factor * integrals[k];
            }
        })
    }

    /// [`SectionPair::new`] and [`GaussSection::lobe`] of every pair, eight pairs at a time in
    /// lanes ([`crate::model::numerics::lanes::on_widest_lanes`]): one at a time, their two atan2, acos, square
    /// roots and divisions per pair were latency-bound scalar code. A batch shorter than eight
    /// (a single-pair `basis` call) goes the scalar way. Pairs below the horizon get finite
    /// placeholders (the caller skips them).
    fn prepare(&self, pairs: &[DirectionPair], out: &mut Vec<(SectionPair, Lobe)>) {
        crate::model::numerics::lanes::on_widest_lanes(
            #[inline(always)]
            |_| self.prepare_lanes(pairs, out),
        )
    }

    #[inline(always)]
    fn prepare_lanes(&self, pairs: &[DirectionPair], out: &mut Vec<(SectionPair, Lobe)>) {
        const L: usize = 8;
        out.clear();
        let mut chunks = pairs.chunks_exact(L);
        for chunk in &mut chunks {
            // components, lane j = pair j
            let (mut lt, mut lb, mut ln) = ([0.0; L], [0.0; L], [0.0; L]);
            let (mut vt, mut vb, mut vn) = ([0.0; L], [0.0; L], [0.0; L]);
            for (j, p) in chunk.iter().enumerate() {
                (lt[j], lb[j], ln[j]) = (p.l.t, p.l.b, p.l.n);
                (vt[j], vb[j], vn[j]) = (p.v.t, p.v.b, p.v.n);
            }
            let mut proj = [[0.0; 6]; 2 * L]; // alpha, sin, cos, len, tan, sec
            for j in 0..2 * L {
                let (b, n) = if j < L {
                    (lb[j], ln[j])
                } else {
                    (vb[j - L], vn[j - L])
                };
                let n = n.max(f64::MIN_POSITIVE);
                let len = (b * b + n * n).sqrt();
                let (inv_len, inv_n) = (1.0 / len, 1.0 / n);
                proj[j] = [
                    elementary::atan2_right_half_lanes(b, n),
                    b * inv_len,
                    n * inv_len,
                    len,
                    b * inv_n,
                    len * inv_n,
                ];
            }
            let mut lobe = [[0.0; 3]; L]; // cos_lv, half, window exists
            for j in 0..L {
                let (l, v) = (proj[j], proj[j + L]);
                let cos_lv = lt[j] * vt[j] + lb[j] * vb[j] + ln[j] * vn[j];
                let cos_delta = l[2] * v[2] + l[1] * v[1];
                let (half, some) = lobe_half_width(
                    l[3] * v[3],
                    cos_delta,
                    cos_lv,
                    self.lobe_floor,
                    elementary::atan2_right_half_lanes,
                );
                lobe[j] = [cos_lv, half, some as u8 as f64];
            }
            for j in 0..L {
                let p = |a: [f64; 6]| Projected {
                    alpha: a[0],
                    sin: a[1],
                    cos: a[2],
                    len: a[3],
                    tan: a[4],
                    sec: a[5],
                };
                let sp = SectionPair {
                    l: p(proj[j]),
                    v: p(proj[j + L]),
                    cos_lv: lobe[j][0],
                };
                let (half, some) = (lobe[j][1], lobe[j][2] != 0.0);
                let sigma = sp.l.alpha + sp.v.alpha;
                let centre = 0.5 * sigma;
                out.push((
                    sp,
                    Lobe {
                        cos_delta: sp.cos_delta(),
                        sigma,
                        k2: 2.0 * sp.l.len * sp.v.len,
                        window: some.then_some((centre - half, centre + half)),
                    },
                ));
            }
        }
        // a short batch or the tail: one pair at a time (the same values, bit for bit); pairs
        // below the horizon get the values of a pair along N
        const UP: Local = Local {
            t: 0.0,
            b: 0.0,
            n: 1.0,
        };
        for pair in chunks.remainder() {
            let sp = if pair.above_horizon() {
                SectionPair::new(&pair.l, &pair.v)
            } else {
                SectionPair::new(&UP, &UP)
            };
            out.push((sp, self.lobe(&sp)));
        }
    }

    /// Step 4 of [`GaussSection::bases`] for one visit: its seen-and-lit arcs from
    /// the gap ends' asin (`ends`, starting at this pattern's). Each arc goes to `diffuse` with
    /// its fibre's count, and its part inside the lobe window to `specular` with the factor that
    /// turns its lobe integral into its share of `Basis::specular`. Returns how many ends it
    /// used.
    #[inline]
    fn visit_arcs(
        &self,
        visit: &OneVisit,
        diffuse: &mut impl FnMut(DiffuseArc, f64),
        specular: &mut impl FnMut(LobeArc, f64),
    ) -> usize {
        let OneVisit {
            pattern,
            sp,
            lobe,
            weight,
            gap_counts,
            ends,
        } = *visit;
        let denom = pattern.period * sp.cos_alpha_product();
        let (al, av) = (sp.l.alpha, sp.v.alpha);
        let Lobe {
            cos_delta,
            sigma,
            k2,
            window,
        } = *lobe;
        let shape = LobeShape {
            cos_delta,
            sigma,
            k2,
            cos_lv: sp.cos_lv,
            exponent: self.exponent,
        };
        let mut at = 0;
        for (counts, &(_, count)) in gap_counts.chunks_exact(2).zip(fibres(pattern)) {
            let (n_seen, n_lit) = (counts[0], counts[1]);
            let seen = &ends[at..at + 2 * n_seen as usize];
            at += seen.len();
            let lit = &ends[at..at + 2 * n_lit as usize];
            at += lit.len();
            let factor = weight * count * self.norm / denom;
            for_each_seen_and_lit(seen, av, lit, al, |a, b| {
                let arc = DiffuseArc {
                    t0: a,
                    t1: b,
                    a: al,
                    b: av,
                    cos_ab: cos_delta,
                };
                diffuse(arc, count);
                if let Some((w0, w1)) = window {
                    let (a, b) = (a.max(w0), b.min(w1));
                    if b > a {
                        specular(LobeArc { a, b, shape }, factor);
                    }
                }
            });
        }
        at
    }
}

/// The fibres of a pattern's period with the number of times each is counted. At H = 0 the odd
/// row is the even row moved by one step: both fibres have the same arcs, so one fibre is
/// computed and counted twice.
fn fibres(pattern: &Pattern) -> &'static [(Fibre, f64)] {
    if pattern.rise == 0.0 {
        &[(Fibre::Even, 2.0)]
    } else {
        &[(Fibre::Even, 1.0), (Fibre::Odd, 1.0)]
    }
}

/// What [`GaussSection::visit_arcs`] reads of one visit: its pattern and the pattern's weight,
/// its pair's section geometry and lobe, and its fibres' gap counts (seen, then lit, per fibre)
/// with the gap ends' asin from this visit's on.
#[derive(Clone, Copy)]
struct OneVisit<'a> {
    pattern: &'a Pattern,
    sp: &'a SectionPair,
    lobe: &'a Lobe,
    weight: f64,
    gap_counts: &'a [u8],
    ends: &'a [f64],
}

/// One (pair, pattern) of a batch that contributes (pair above the horizon, non-zero
/// denominator).
struct Visit {
    pair: usize,
    pattern: Pattern,
    weight: f64,
    /// Sum over its seen-and-lit arcs of count * diffuse kernel (step 5).
    diffuse: f64,
    /// Seen-and-lit fraction of the substrate (step 5).
    substrate: f64,
}

/// The first `n` entries of a buffer the caller overwrites entirely: grown (zero-filled) only
/// when too short, so a batch does not pay for clearing it.
fn grown(buf: &mut Vec<f64>, n: usize) -> &mut [f64] {
    if buf.len() < n {
        buf.resize(n, 0.0);
    }
    &mut buf[..n]
}

/// Per-thread buffers of [`GaussSection::bases`], reused between calls (a single-pair call must
/// not pay for an allocation).
#[derive(Default)]
struct BatchScratch {
    prepared: Vec<(SectionPair, Lobe)>,
    visits: Vec<Visit>,
    /// Per visit and fibre: the fibre seen along v, then lit along l.
    problems: FibreOcclusions,
    /// Per visit: the substrate's problem and seen-and-lit fraction.
    substrates: Vec<SubstrateProblem>,
    fractions: Vec<f64>,
    /// The non-empty gaps' ends of all problems, in s, then their asin; how many per problem.
    ends: Vec<f64>,
    gap_counts: Vec<u8>,
    /// Seen-and-lit arcs for the diffuse kernel, with (visit, count).
    diffuse_arcs: DiffuseArcs,
    diffuse_dest: Vec<(usize, f64)>,
    /// The distinct lobe arcs of each pair, and per arc found (pair, factor, its arc in `arcs`).
    arcs: Vec<LobeArc>,
    dest: Vec<(usize, f64, usize)>,
    values: Vec<f64>,
}

thread_local! {
    static SCRATCH: std::cell::RefCell<BatchScratch> = std::cell::RefCell::new(BatchScratch::default());
}

/// Per-pair quantities of the specular lobe (see `GaussSection::lobe`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Lobe {
    cos_delta: f64,
    sigma: f64,
    k2: f64,
    window: Option<(f64, f64)>,
}

/// The `varying-topology` rung: the mean over a discretised height distribution.
#[derive(Clone, Debug)]
pub struct VaryingTopology {
    spacing: f64,
    section: GaussSection,
    /// (pattern, weight) per histogram node.
    nodes: Vec<(Pattern, f64)>,
}

impl VaryingTopology {
    /// `heights`: (H, weight) pairs from [`crate::model::topology::Topology::discretise`].
    pub fn new(spacing: f64, exponent: f64, order: usize, heights: Vec<(f64, f64)>) -> Self {
        let nodes = heights
            .into_iter()
            .map(|(h, w)| (Pattern::new(spacing, elevation_from_height(h, spacing)), w))
            .collect();
        Self {
            spacing,
            section: GaussSection::new(exponent, order),
            nodes,
        }
    }

    pub fn nodes(&self) -> usize {
        self.nodes.len()
    }
}

impl ShadingModel for VaryingTopology {
    fn rung(&self) -> &'static Rung {
        &RUNG
    }

    fn basis_above_horizon(&self, pair: &DirectionPair) -> Basis {
        let mut out = [Basis::default()];
        self.section
            .bases(std::slice::from_ref(pair), &self.nodes, &mut out);
        out[0]
    }

    fn basis_many(&self, pairs: &[DirectionPair], out: &mut [Basis]) {
        self.section.bases(pairs, &self.nodes, out);
    }

    fn basis_at_height_above_horizon(&self, pair: &DirectionPair, height: f64) -> Option<Basis> {
        let mut out = [Basis::default()];
        self.basis_many_at_height(std::slice::from_ref(pair), height, &mut out);
        Some(out[0])
    }

    fn basis_many_at_height(
        &self,
        pairs: &[DirectionPair],
        height: f64,
        out: &mut [Basis],
    ) -> bool {
        let pattern = Pattern::new(self.spacing, elevation_from_height(height, self.spacing));
        self.section.bases(pairs, &[(pattern, 1.0)], out);
        true
    }

    fn basis_many_at_each_height(
        &self,
        pairs: &[DirectionPair],
        heights: &[f64],
        out: &mut [Basis],
    ) -> bool {
        assert_eq!(pairs.len(), heights.len());
        let patterns: Vec<[(Pattern, f64); 1]> = heights
            .iter()
            .map(|&h| [(Pattern::new(self.spacing, elevation_from_height(h, self.spacing)), 1.0)])
            .collect();
        self.section.bases_with(pairs, |i| &patterns[i], out);
        true
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::frame::{direction_from_angles, FibreFrame};

    /// n x n pairs in the fibre frame of azimuth 0.3: theta of l and v up to `theta_max` (radians)
    /// on a grid, their azimuths spread by incommensurate steps.
    fn grid_pairs(n: usize, theta_max: f64) -> Vec<DirectionPair> {
        let frame = FibreFrame::from_azimuth(0.3);
        let mut pairs = vec![];
        for i in 0..n {
            for j in 0..n {
                let (a, b) = (i as f64, j as f64);
                let l = direction_from_angles((a / n as f64) * theta_max, b * 0.37);
                let v = direction_from_angles((b / n as f64) * theta_max, a * 0.71 + 1.0);
                pairs.push(DirectionPair::new(&frame, &l, &v));
            }
        }
        pairs
    }

    #[test]
    fn lane_preparation_equals_the_scalar_definitions_bit_for_bit() {
        let section = GaussSection::new(60.0, 16);
        let mut pairs = grid_pairs(40, 1.57);
        // a batch length that is not a multiple of the lane count
        pairs.truncate(1597);
        let mut prepared = vec![];
        section.prepare(&pairs, &mut prepared);
        assert_eq!(prepared.len(), pairs.len());
        for (pair, (sp, lobe)) in pairs.iter().zip(&prepared) {
            if !pair.above_horizon() {
                continue;
            }
            let want = SectionPair::new(&pair.l, &pair.v);
            for (got, want) in [(sp.l, want.l), (sp.v, want.v)] {
                let g = [got.alpha, got.sin, got.cos, got.len, got.tan, got.sec];
                let w = [want.alpha, want.sin, want.cos, want.len, want.tan, want.sec];
                assert_eq!(g.map(f64::to_bits), w.map(f64::to_bits), "{pair:?}");
            }
            assert_eq!(sp.cos_lv.to_bits(), want.cos_lv.to_bits());
            assert_eq!(*lobe, section.lobe(&want), "{pair:?}");
        }
    }

    #[test]
    fn a_lobe_arc_shared_by_heights_is_integrated_once_with_the_same_result() {
        // the mean over 16 heights, where most heights' clipped arcs are the whole lobe window,
        // against each height evaluated alone and weighted: one integral per distinct arc of a
        // pair must give every visit its own arc's integral
        let pairs = grid_pairs(30, 1.5);
        for exponent in [30.0, 1000.0] {
            let heights: Vec<(f64, f64)> = (0..16).map(|k| (0.05 * k as f64, 1.0 / 16.0)).collect();
            let model = VaryingTopology::new(2.4, exponent, 16, heights.clone());
            let mut together = vec![Basis::default(); pairs.len()];
            model.basis_many(&pairs, &mut together);
            let mut alone = vec![Basis::default(); pairs.len()];
            let mut one = vec![Basis::default(); pairs.len()];
            for &(h, w) in &heights {
                model.basis_many_at_height(&pairs, h, &mut one);
                for (a, o) in alone.iter_mut().zip(&one) {
                    *a = *a + o.scaled(w);
                }
            }
            let peak = together.iter().map(|b| b.specular).fold(0.0, f64::max);
            assert!(peak > 0.0);
            for ((t, a), pair) in together.iter().zip(&alone).zip(&pairs) {
                let tol = 1e-12 * t.specular.abs().max(1e-9 * peak);
                assert!((t.specular - a.specular).abs() <= tol, "{pair:?}: {t:?} {a:?}");
                assert!((t.diffuse - a.diffuse).abs() <= 1e-12 * t.diffuse.abs().max(1e-12));
            }
        }
    }
}
