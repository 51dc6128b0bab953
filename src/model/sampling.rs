//! Importance sampling of every rung (issue 21 item 2): a light direction l drawn for a view v
//! with a density close to the shaded intensity f(l, v) (N.l), and the exact density of the draw,
//! so that `weight = f (N.l) / pdf` is an unbiased, low-variance estimate of the reflected
//! radiance (a path tracer's BSDF sampling, or a directional albedo by Monte Carlo).
//!
//! Directions are in the fibre frame (T, B, N) of MODEL.md §1; only l with l.n > 0 is ever
//! produced, and every density here is per unit solid angle (1/sr).
//!
//! # The mixture
//!
//! ```text
//! pdf(l | v) = w_cos p_cos(l) + sum_j nu_j [ w_tube p_tube(l_j) + w_lobe p_lobe(l_j | v_j) ]
//! ```
//!
//! - `p_cos(l) = (N.l) / pi`: cosine-weighted hemisphere (Malley), for what is Lambertian in N:
//!   `kd` of lambert, ward's `rho_d`, the cross-section rungs' fibre diffuse and substrate, the
//!   fuzz layer (broad; its grazing forward peak is bounded under this density), and a part of
//!   hast-diffuse.
//! - `p_tube(l) = 2 |l_p| / pi^2`, |l_p| = sqrt(1 - (l.t)^2): the "tube" density, proportional
//!   to the diffuse intensity of a lone cylinder (max-normal: I_d = (kd/pi) |l_p|; hast-diffuse:
//!   I_d = (kd/pi^2)(|l_p| + N.l)). These diffuse terms do not vanish at the horizon, so under
//!   `p_cos` their weight grows like 1/(N.l) and its variance is infinite (logarithmically);
//!   under `p_tube` max-normal's diffuse weight is the constant kd pi/2, and hast-diffuse, with
//!   `p_tube` and `p_cos` mixed in the ratio of their albedos (1/2 : 1/pi), is sampled exactly in
//!   proportion to its intensity (zero variance: the weight is kd (1/2 + 1/pi)).
//! - `p_lobe`: the fibre highlight (max-normal, poulin-fournier, varying-topology, reference), or
//!   Ward's own half-vector sampling (ward), below.
//! - j runs over the fibre directions: with a fibre-direction spread, the nodes of
//!   [`super::azimuth_spread::spread_nodes`] with weights nu_j (a node is picked with the node
//!   weights, and its density is the node-weighted sum, so the mixture mirrors the spread's own
//!   quadrature; the isotropic limit is the same formula with nodes over the whole period); l_j,
//!   v_j are l, v in the frame of fibres turned by the node's angle. Without a spread: one node,
//!   the fibres themselves.
//!
//! The weights (w_cos, w_tube, w_lobe) are chosen per view from the albedos: each component's
//! albedo (mean over the channels) times an estimate of that component's directional albedo per
//! unit albedo at v (max-normal's lobe: pi cos(th_r) times the Wallis integral of cos^e; the
//! cross-section rungs' lobe, fibre diffuse and substrate: from the rung itself, tabulated per
//! view angle in the cross-section plane when the sampler is made, the lobe's times cos(th_r);
//! the Fresnel factor at N.v; the fuzz layer's attenuation, and its own part from its depth;
//! ward's lobe: 1). The weights only
//! change the variance, never the expectation, because `pdf` is the density of exactly this
//! mixture with exactly these weights. Guards: a lobe with a non-zero albedo gets at least
//! [`LOBE_MIN`] of the samples, and the diffuse techniques together at least [`DIFFUSE_MIN`]
//! (that floor bounds the variance of whatever the lobe does not follow).
//!
//! # The fibre lobe
//!
//! A fibre reflects a light direction into the cone about its tangent at the mirror longitude,
//! l.t = -v.t (the highlight of Banks, Kajiya-Kay and Marschner): in max-normal, I_s = ks
//! cos(th + th_v)^e with th, th_v the angles of l, v from the (B, N) plane; in the cross-section
//! rungs the peak over the fibre's normals of r.v is the same cos(th + th_v), so their lobe has
//! the same width in th, and what varies along the cone is visibility. Write
//!
//! ```text
//! l = sin(th) T + cos(th) (cos(phi) B + sin(phi) N),   th in [-pi/2, pi/2], phi in (0, pi),
//! ```
//!
//! spherical coordinates about T (th the latitude from the cross-section plane). T lies in the
//! swatch plane, so N.l = cos(th) sin(phi) > 0 exactly when phi is in (0, pi): drawing phi there
//! never leaves the hemisphere. The latitude is drawn through its sine s = sin th = l.t, in
//! which d omega = ds dphi (no Jacobian), and s and phi are drawn independently: s from a Cauchy
//! law about the mirror's s_r = -v.t, of width gamma_s = gamma sqrt(1 - s_r^2 + gamma^2) (the
//! lobe's width gamma = c / sqrt(e) in latitude times ds/dth = cos th_r at the mirror, kept above
//! gamma^2 where v runs along the fibre), truncated to [-1, 1]: with x_A,B = (-+1 - s_r) /
//! gamma_s, A = atan(x_A) and the truncated mass W = atan(x_B) - A = atan2(2 / gamma_s, 1 + x_A
//! x_B), s = s_r + gamma_s tan(A + u W), and
//!
//! ```text
//! g(s) = 1 / (W gamma_s (1 + ((s - s_r)/gamma_s)^2)),
//! p_lobe(l | v) = g(l.t) q(alpha_l | v),
//! ```
//!
//! with q the density (per radian) of the longitude, written by alpha_l = pi/2 - phi, the angle
//! of l's projection in the cross-section plane (MODEL.md §1). The density needs no arc tangent
//! but W's (in lane form: `Sampler`'s density sums the nodes of a spread eight at a time in
//! vector lanes); a draw whose s rounds outside [-1, 1] is returned as `None` (a few ulp of
//! mass).
//!
//! - max-normal: q = 1/pi, uniform: its lobe does not depend on the longitude at all.
//! - cross-section rungs: along the cone the lobe is shaped by hiding and shadowing, strongly
//!   so at grazing views (at 80 deg across the fibres it is zero over 40 % of the cone and peaks
//!   at the edge where the reflecting normals stop being visible). Its shape depends on v
//!   through alpha_v, the view's angle in the cross-section plane (the latitude only scales it:
//!   the cross-section sees projections), so `Sampler::new` tabulates it from the rung itself,
//!   in the half tangents x = tan(alpha / 2) = w.b / (|w_p| + w.n) (rational in the direction:
//!   no arc tangent to evaluate, and sin alpha = 2x / (1 + x^2), cos alpha = (1 - x^2) / (1 +
//!   x^2) to draw): [`CONE_ROWS`] / 2 views at latitude 0 with x_v >= 0 (row centres equally
//!   spaced in x_v, so finer in alpha_v towards grazing), and for each the lobe's intensity
//!   f_s (N.l) dalpha/dx at l in the plane at [`CONE_BINS`] + 1 equally spaced x_l in [-1, 1].
//!   The law of x_l is that profile interpolated linearly between the nodes, normalised, mixed
//!   with the uniform law of alpha_l ([`CONE_UNIFORM`] of it: other heights and latitudes, the
//!   Fresnel factor, the spread), and blended linearly between the two rows whose x_v bracket
//!   the view's (the lobe's edge moves fast with alpha_v at grazing views); q = its density
//!   times dx/dalpha = (1 + x_l^2) / 2. Rows for x_v < 0 are the mirror images, so q and
//!   the pdf are exactly invariant under T -> -T. Drawn by picking the row with the rescaled
//!   uniform, the bin by its cumulative mass, and the position in the bin by inverting the
//!   linear density's quadratic CDF in closed form. The reference is tabulated through
//!   varying-topology (equal to it to the quadrature error; the reference itself would take
//!   seconds); the table costs one batch of (CONE_ROWS / 2) (CONE_BINS + 65) evaluations of
//!   the rung when the sampler is made.
//!
//! cos(delta)^e ~ exp(-e delta^2/2) is a normal law of deviation 1/sqrt(e) (so it is on the
//! cross-section rungs too, measured); for a normal target the Cauchy width minimising the
//! second moment of the weight is sigma/sqrt(2) (at that width the weight's second moment is
//! sqrt(pi/2) = 1.25 times the ideal), hence c = [`LOBE_WIDTH`] = 1/sqrt(2); `fibrefit bench
//! --sampling` sweeps c on the rungs.
//! The Cauchy tails are heavier than the lobe's, so the ratio lobe / density stays bounded
//! everywhere: safe. `p_lobe` integrates to exactly 1 over the hemisphere (g and q each do).
//!
//! The tube density is the same parametrisation with phi uniform on (0, pi) and th drawn with
//! density cos^2(th) / (pi/2): its CDF is (y - sin y) / (2 pi) with y = 2 th + pi, inverted by
//! Newton's method (Kepler's equation with eccentricity 1); p_tube = cos^2(th) (2/pi) (1/pi) /
//! cos(th) = 2 |l_p| / pi^2.
//!
//! # Ward
//!
//! Walter 2005 ("Notes on the Ward BRDF"): the half vector h drawn with phi_h = atan2(ay sin 2 pi
//! u1, ax cos 2 pi u1) and tan^2 th_h = -ln(1 - u2) / (cos^2 phi_h / ax^2 + sin^2 phi_h / ay^2),
//! whose density is
//!
//! ```text
//! p_h(h) = exp(-((h.t/ax)^2 + (h.b/ay)^2) / (h.n)^2) / (pi ax ay (h.n)^3)   (integrates to 1),
//! ```
//!
//! and l = 2 (v.h) h - v, so p_lobe(l | v) = p_h(h) / (4 (l.h)) with h = (l + v) / |l + v|.
//! Reflections that fall below the horizon are returned as `None`: this lobe's density integrates
//! to less than 1 over the hemisphere (the mass lost is that of the draws rejected), which is the
//! exact density of the directions `sample` returns.
//!
//! # glTF's anisotropic GGX
//!
//! The `gltf` rung's lobe: its distribution of visible normals (Heitz 2018, "Sampling the GGX
//! Distribution of Visible Normals"): v stretched by (alpha_t, alpha_b), a point of the unit
//! disk warped onto the projected hemisphere, unstretched into h, and l = 2 (v.h) h - v. The
//! density of h is D_v(h) = G1(v) max(0, v.h) D(h) / (N.v), so that of l is
//!
//! ```text
//! p_lobe(l | v) = G1(v) D(h) / (4 N.v),   G1(v) = 1 / (1 + Lambda(v)),
//! ```
//!
//! D and Lambda the rung's own (`rungs::gltf::ggx_d`, `ggx_lambda`). As for Ward, reflections
//! below the horizon are returned as `None`.
//!
//! # Why the density is exact
//!
//! Every component is drawn by inverting its own closed-form CDF (the tube's by Newton to full
//! precision; the cone table's row by its exact cumulative masses and the quadratic within a
//! bin; the fibre lobe's Cauchy law with the same truncated mass W in the draw and the
//! density, so the rounding of its arc tangent moves the law's ends by ulps, never the density
//! of what is drawn), and `pdf` evaluates the same closed forms at l, for every component and node, not
//! only the one that drew l: the density of the mixture is the weighted sum of the densities of
//! its components whichever produced the sample. The component and node are chosen by rescaling
//! `u[0]` (the rescaled uniform is again uniform and independent of the choice), the cone
//! table's row by rescaling `u[1]`. The weights and the table's rows depend only on (albedos,
//! v), never on l, so they are the same in `sample` and `pdf`. `pdf` does not take the texel
//! height: the sampler is the same at every height (the weight's f is the height's). Tested
//! in `tests/sampling.rs` by chi-square goodness-of-fit tests of the directions against `pdf`.
//! Directions with N.l <= [`HORIZON_COS`] count as at the horizon in both.
//!
//! # One instance per draw
//!
//! A spread's N nodes and varying-topology's K heights make `sample`'s weight cost N K
//! evaluations of the aligned rung. [`Sampler::sample_instance`] draws one of those instances
//! with its weight (a third uniform, [`Sampler::instance`]) and samples and weighs it alone, its
//! density that instance's mixture (this one with a single node, in the turned frame): an
//! unbiased estimate of the same reflected radiance at the cost of one instance, with a larger
//! variance (`instance.rs` says why it is sound and how a path tracer uses it).
//!
//! Here: the sampler and its mixture (weights, draw, density); the fibre lobe and its cone table
//! in `lobe.rs`, the other components' closed-form draws and densities in `directions.rs`, one
//! instance per draw in `instance.rs`.

use super::azimuth_spread::spread_nodes;
use super::frame::Local;
use super::fresnel::schlick;
use super::params::ModelParams;
use super::rung::{Cost, LobeAlbedo, LobeSampling};
use super::{Ability, Albedos, Basis, DirectionPair, ModelId, ShadingModel};
use std::f64::consts::{FRAC_1_PI, PI};

mod directions;
mod instance;
mod lobe;

pub use instance::Instance;

use directions::{
    cosine_direction, ggx_direction, ggx_pdf, rescale, tube_direction, tube_pdf, turn, unturn,
    wallis, ward_direction, ward_pdf, ONE_BELOW,
};
use lobe::{
    fibre_lobe_density, fibre_lobe_direction, fibre_lobe_law, fibre_lobe_pdf, half_tangent,
    ConeTable,
};

/// Width c of the fibre lobe's Cauchy law in units of 1/sqrt(exponent).
pub const LOBE_WIDTH: f64 = std::f64::consts::FRAC_1_SQRT_2;
/// Least share of the samples the lobe gets when its albedo is not zero.
pub const LOBE_MIN: f64 = 0.05;
/// Least share of the samples the diffuse techniques (cosine and tube) get together.
pub const DIFFUSE_MIN: f64 = 0.1;
/// Longitude bins of the cross-section rungs' cone table (over alpha_l in (-pi/2, pi/2)).
pub const CONE_BINS: usize = 64;
/// Rows of the cone table (alpha_v in (-pi/2, pi/2)), half of them for alpha_v >= 0.
pub const CONE_ROWS: usize = 64;
/// The share of the cone's longitude law spread uniformly over the cone (what the table does
/// not follow: other heights, latitudes, the Fresnel factor, between the rows).
pub const CONE_UNIFORM: f64 = 0.2;
/// Directions with N.l at or below this count as at the horizon, in `sample` and `pdf` alike:
/// the rungs' 1/(N.l) factors overflow on subnormal cosines, and the density left out there is
/// below 1e-12.
pub const HORIZON_COS: f64 = 1e-14;

/// The rung's lobe technique.
#[derive(Clone, Copy, Debug)]
enum Lobe {
    /// No lobe (lambert, hast-diffuse).
    None,
    /// The fibre highlight cone with Cauchy width `gamma` (radians).
    Fibre { gamma: f64 },
    /// Ward's half-vector sampling (Walter 2005).
    Ward { ax: f64, ay: f64 },
    /// The anisotropic GGX's visible normals (Heitz 2018), `at` along T, `ab` along B; for the
    /// weights, the glTF layers' Fresnel: the dielectric's weight (1 - metallic) specular, its
    /// F0, and the metallic factor.
    Ggx {
        at: f64,
        ab: f64,
        dielectric: f64,
        f0: f64,
        metal: f64,
    },
}

/// The importance sampler of one rung with its parameters.
#[derive(Clone, Debug)]
pub struct Sampler {
    lobe: Lobe,
    /// How the lobe's directional albedo is estimated.
    lobe_albedo: LobeAlbedo,
    /// The cone's longitude law (cross-section rungs; uniform without one).
    cone: Option<ConeTable>,
    exponent: f64,
    /// Fresnel index of refraction on the lobe (0: none).
    fresnel_ior: f64,
    /// Fuzz layer depth (0: none).
    fuzz_depth: f64,
    /// The fibre directions: (cos delta, sin delta, weight) of each node, delta the turn from T.
    nodes: Vec<(f64, f64, f64)>,
    /// Cumulative node weights (the last is 1).
    cumulative: Vec<f64>,
    /// The nodes again in blocks of [`NODE_LANES`] for the density's lane loop (padding:
    /// weight 0 at delta 0).
    node_blocks: Vec<NodeBlock>,
    /// Directional albedo per unit kd going to the tube and to the cosine technique.
    kd_tube: f64,
    kd_cos: f64,
    /// Directional albedo per unit kd going to the lobe technique (glTF's metal).
    kd_lobe: f64,
    /// The instances one is drawn from ([`Instance`]).
    instance_set: instance::Instances,
    /// The sampler of one instance (this one with the single node of the fibres), where this
    /// one has a spread's nodes.
    aligned: Option<Box<Sampler>>,
}

/// Lanes of the mixture density's node loop.
const NODE_LANES: usize = 8;

/// [`NODE_LANES`] spread nodes: cos delta, sin delta and weight of each.
#[derive(Clone, Debug)]
struct NodeBlock {
    cos: [f64; NODE_LANES],
    sin: [f64; NODE_LANES],
    weight: [f64; NODE_LANES],
    /// The nodes that are not padding.
    count: usize,
}

/// One sampled direction.
#[derive(Clone, Copy, Debug)]
pub struct Sample {
    pub l: Local,
    pub pdf: f64,
    pub weight: [f64; 3],
}

impl Sample {
    /// The draw l with its density and weight[c] = f_c(l, v) l.n / pdf, f from `basis`.
    fn weighed(l: Local, pdf: f64, basis: &Basis, albedos: &Albedos) -> Self {
        let weight = std::array::from_fn(|c| basis.brdf(albedos, c) * l.n / pdf);
        Sample { l, pdf, weight }
    }
}

/// Pairs per call of the rung's batch evaluation in [`Sampler::sample_many`], counting a
/// spread's turned pairs.
const EVAL_PAIRS: usize = 64;

/// One draw of a batch ([`Sampler::sample_many`]): what [`Sampler::sample`] takes.
#[derive(Clone, Copy, Debug)]
pub struct Draw {
    /// The albedos at the draw's point (the mixture's weights follow them).
    pub albedos: Albedos,
    /// The fibres' height where a texel fixes one (rungs with a topology).
    pub height: Option<f64>,
    /// The view, in the fibre frame.
    pub v: Local,
    /// Two uniforms in [0, 1).
    pub u: [f64; 2],
}

/// The mixture weights for one view.
#[derive(Clone, Copy, Debug)]
struct Weights {
    cos: f64,
    tube: f64,
    lobe: f64,
}

/// The bases of `plain` pairs (`basis_many`) and of `high` pairs each at its height
/// (`basis_many_at_each_height`), in groups of `group` pairs: a batch's evaluations, in lanes.
fn evaluate_in_groups(
    model: &dyn ShadingModel,
    plain: &[DirectionPair],
    high: &[DirectionPair],
    heights: &[f64],
    group: usize,
) -> (Vec<Basis>, Vec<Basis>) {
    let mut bases = vec![Basis::default(); plain.len()];
    for (p, b) in plain.chunks(group).zip(bases.chunks_mut(group)) {
        model.basis_many(p, b);
    }
    let mut high_bases = vec![Basis::default(); high.len()];
    for ((p, h), b) in high
        .chunks(group)
        .zip(heights.chunks(group))
        .zip(high_bases.chunks_mut(group))
    {
        model.basis_many_at_each_height(p, h, b);
    }
    (bases, high_bases)
}

impl Sampler {
    /// The sampler of rung `id` with validated parameters `p` (exponent, alpha_x/alpha_y, spread,
    /// nodes, fuzz...).
    pub fn new(id: ModelId, p: &ModelParams) -> Sampler {
        let rung = id.rung().sampling;
        let lobe = match rung.lobe {
            LobeSampling::None => Lobe::None,
            LobeSampling::Ward => Lobe::Ward {
                ax: p.alpha_x,
                ay: p.alpha_y,
            },
            LobeSampling::FibreCone => Lobe::Fibre {
                gamma: LOBE_WIDTH / p.exponent.max(1.0).sqrt(),
            },
            LobeSampling::Ggx if id.has(Ability::PrincipledMaterial) => {
                let q = &p.principled;
                let (ab, at) = super::rungs::principled::alphas(q.roughness, q.anisotropic);
                Lobe::Ggx {
                    at,
                    ab,
                    dielectric: 1.0,
                    f0: super::rungs::principled::f0_from_ior(q.ior),
                    metal: 0.0,
                }
            }
            LobeSampling::Ggx if id.has(Ability::OpenPbrMaterial) => {
                let q = &p.openpbr;
                let (ab, at) = super::rungs::openpbr::alphas(
                    q.specular_roughness,
                    q.specular_roughness_anisotropy,
                );
                Lobe::Ggx {
                    at,
                    ab,
                    dielectric: 1.0,
                    f0: super::rungs::openpbr::specular_f0(q),
                    metal: 0.0,
                }
            }
            LobeSampling::Ggx => {
                let g = &p.gltf;
                // the lobe the variant evaluates (three.js floors the roughness)
                let (roughness, _) = g.evaluated_roughnesses();
                let (at, ab) = super::rungs::gltf::ggx_alphas(roughness, g.anisotropy);
                Lobe::Ggx {
                    at,
                    ab,
                    dielectric: (1.0 - g.metallic) * g.specular,
                    f0: super::rungs::gltf::ior_f0(g.ior),
                    metal: g.metallic,
                }
            }
        };
        // the spread applies where `model::with_spread` applies it
        let spread = p.azimuth_spread_deg > 0.0 && id.has(Ability::DirectionSpread);
        let nodes = if spread {
            spread_nodes(p.azimuth_spread_deg, p.azimuth_nodes, p.fibre_azimuth)
        } else {
            vec![(1.0, 0.0, 1.0)]
        };
        let cumulative = instance::cumulative(nodes.iter().map(|n| n.2));
        let node_blocks = Self::node_blocks(&nodes);
        // directional albedo per unit kd of the diffuse term, by technique; glTF's base colour
        // is Lambertian for the dielectric, the metal's Fresnel on its GGX lobe for the metal
        let (kd_tube, mut kd_cos) = (rung.diffuse_tube, rung.diffuse_cosine);
        let mut kd_lobe = 0.0;
        if let Lobe::Ggx { metal, .. } = lobe {
            (kd_cos, kd_lobe) = (kd_cos * (1.0 - metal), metal);
        }
        let fresnel = p.fresnel_ior > 0.0 && id.has(Ability::Fresnel);
        let cone = rung.cone_from.and_then(|from| ConeTable::new(from, p));
        // the instances (`Instance`): the reference has one, itself (it integrates its spread
        // and heights adaptively)
        let exact_sums = id.rung().cost != Cost::Adaptive;
        let instance_set = match exact_sums {
            true if id.has(Ability::HeightHistogram) => instance::Instances::new(
                nodes.clone(),
                p.topology.discretise(p.spacing, p.histogram_bins),
            ),
            true => instance::Instances::new(nodes.clone(), Vec::new()),
            false => instance::Instances::whole(),
        };
        let mut sampler = Sampler {
            lobe_albedo: rung.lobe_albedo,
            lobe,
            cone,
            exponent: p.exponent,
            fresnel_ior: if fresnel { p.fresnel_ior } else { 0.0 },
            fuzz_depth: p.fuzz_depth,
            nodes,
            cumulative,
            node_blocks,
            kd_tube,
            kd_cos,
            kd_lobe,
            instance_set,
            aligned: None,
        };
        if exact_sums && sampler.nodes.len() > 1 {
            let one = vec![(1.0, 0.0, 1.0)];
            sampler.aligned = Some(Box::new(Sampler {
                node_blocks: Self::node_blocks(&one),
                nodes: one,
                cumulative: vec![1.0],
                aligned: None,
                ..sampler.clone()
            }));
        }
        sampler
    }

    /// `nodes` in blocks of [`NODE_LANES`] for the density's lane loop.
    fn node_blocks(nodes: &[(f64, f64, f64)]) -> Vec<NodeBlock> {
        nodes
            .chunks(NODE_LANES)
            .map(|chunk| {
                let mut b = NodeBlock {
                    cos: [1.0; NODE_LANES],
                    sin: [0.0; NODE_LANES],
                    weight: [0.0; NODE_LANES],
                    count: chunk.len(),
                };
                for (j, &(c, s, nu)) in chunk.iter().enumerate() {
                    (b.cos[j], b.sin[j], b.weight[j]) = (c, s, nu);
                }
                b
            })
            .collect()
    }

    /// The same sampler with the fibre lobe's Cauchy width c / sqrt(exponent) (default
    /// [`LOBE_WIDTH`]); for the width study of `fibrefit bench sampling`. No effect on rungs
    /// without a fibre lobe.
    pub fn with_lobe_width(mut self, c: f64) -> Sampler {
        if let Lobe::Fibre { gamma } = &mut self.lobe {
            *gamma = c / self.exponent.max(1.0).sqrt();
        }
        self.aligned = self.aligned.map(|a| Box::new(a.with_lobe_width(c)));
        self
    }

    /// Sample l for the view v (fibre frame) with mixture weights from `albedos`, two uniforms u
    /// in [0,1)^2. weight[c] = f_c(l, v) * l.n / pdf, with f from `model` (at `height` when Some,
    /// via basis_at_height; the plain basis for a model without a topology). None when v is
    /// at/below the horizon or the sampled l is (N.l <= [`HORIZON_COS`] counts as the horizon;
    /// the pdf then integrates to < 1 — allowed).
    pub fn sample(
        &self,
        model: &dyn ShadingModel,
        albedos: &Albedos,
        height: Option<f64>,
        v: &Local,
        u: [f64; 2],
    ) -> Option<Sample> {
        let (l, pdf) = self.sample_direction(albedos, v, u)?;
        let pair = DirectionPair { l, v: *v };
        let basis = match height {
            Some(h) => model
                .basis_at_height(&pair, h)
                .unwrap_or_else(|| model.basis(&pair)),
            None => model.basis(&pair),
        };
        Some(Sample::weighed(l, pdf, &basis, albedos))
    }

    /// [`Sampler::sample`] of every draw, into `out` (same length), bit for bit: the directions
    /// one by one, then the rung evaluated at all of them at once (`basis_many`, or
    /// `basis_many_at_each_height` for draws at a height), which the cross-section rungs run in
    /// lanes: one pair at a time their evaluation is latency-bound, about twice the time per
    /// pair. What a wavefront renderer (Mitsuba's variants, `Material.sample` on arrays) asks for.
    pub fn sample_many(&self, model: &dyn ShadingModel, draws: &[Draw], out: &mut [Option<Sample>]) {
        assert_eq!(draws.len(), out.len());
        let topology = model.rung().has(Ability::Topology);
        // the drawn directions: (draw, pair, pdf), at a height (with it) or not
        let (mut plain, mut high) = (Vec::new(), Vec::new());
        let (mut plain_pairs, mut high_pairs, mut heights) = (Vec::new(), Vec::new(), Vec::new());
        for (i, (d, o)) in draws.iter().zip(out.iter_mut()).enumerate() {
            *o = None;
            let Some((l, pdf)) = self.sample_direction(&d.albedos, &d.v, d.u) else {
                continue;
            };
            let pair = DirectionPair { l, v: d.v };
            match d.height {
                Some(h) if topology => {
                    high.push((i, pdf));
                    high_pairs.push(pair);
                    heights.push(h);
                }
                _ => {
                    plain.push((i, pdf));
                    plain_pairs.push(pair);
                }
            }
        }
        // in groups of about EVAL_PAIRS pairs as the rung sees them (a spread turns each pair
        // into one per node): larger groups only spill the rung's buffers out of the caches
        let group = (EVAL_PAIRS / self.nodes.len().max(1)).max(1);
        let (bases, high_bases) =
            evaluate_in_groups(model, &plain_pairs, &high_pairs, &heights, group);
        let done = plain
            .iter()
            .zip(plain_pairs.iter().zip(&bases))
            .chain(high.iter().zip(high_pairs.iter().zip(&high_bases)));
        for (&(i, pdf), (pair, basis)) in done {
            out[i] = Some(Sample::weighed(pair.l, pdf, basis, &draws[i].albedos));
        }
    }

    /// The exact density (1/sr, solid angle) of `sample` producing l given v (0 below the
    /// horizon).
    pub fn pdf(&self, albedos: &Albedos, v: &Local, l: &Local) -> f64 {
        if !(v.n > 0.0 && l.n > HORIZON_COS) {
            return 0.0;
        }
        self.mixture_pdf(&self.weights(albedos, v), v, l)
    }

    /// The direction and its density, without evaluating a model.
    fn sample_direction(&self, albedos: &Albedos, v: &Local, u: [f64; 2]) -> Option<(Local, f64)> {
        if !(v.n > 0.0) {
            return None;
        }
        let w = self.weights(albedos, v);
        let u0 = u[0].clamp(0.0, ONE_BELOW);
        let u1 = u[1].clamp(0.0, ONE_BELOW);
        let l = if u0 < w.cos || w.tube + w.lobe <= 0.0 {
            cosine_direction([rescale(u0, 0.0, w.cos), u1])
        } else {
            let tube = u0 < w.cos + w.tube || w.lobe <= 0.0;
            let r = if tube {
                rescale(u0, w.cos, w.cos + w.tube)
            } else {
                rescale(u0, w.cos + w.tube, 1.0)
            };
            // the node, by the rescaled uniform
            let j = self
                .cumulative
                .partition_point(|&c| c <= r)
                .min(self.nodes.len() - 1);
            let lo = if j == 0 { 0.0 } else { self.cumulative[j - 1] };
            let r = rescale(r, lo, self.cumulative[j]);
            let (c, s, _) = self.nodes[j];
            let local = if tube {
                tube_direction([r, u1])
            } else {
                match self.lobe {
                    Lobe::Fibre { gamma } => {
                        let vj = turn(v, c, s);
                        fibre_lobe_direction(gamma, self.cone.as_ref(), &vj, [r, u1])?
                    }
                    Lobe::Ward { ax, ay } => ward_direction(ax, ay, &turn(v, c, s), [r, u1]),
                    Lobe::Ggx { at, ab, .. } => {
                        ggx_direction(at, ab, &turn(v, c, s), [r, u1])
                    }
                    Lobe::None => unreachable!("a lobe weight without a lobe"),
                }
            };
            unturn(&local, c, s)
        };
        if !(l.n > HORIZON_COS) {
            return None;
        }
        let pdf = self.mixture_pdf(&w, v, &l);
        (pdf > 0.0 && pdf.is_finite()).then_some((l, pdf))
    }

    /// The mixture's density at l (both above the horizon).
    fn mixture_pdf(&self, w: &Weights, v: &Local, l: &Local) -> f64 {
        let mut p = w.cos * l.n * FRAC_1_PI;
        if w.tube > 0.0 || w.lobe > 0.0 {
            if let Lobe::Fibre { gamma } = self.lobe {
                return p + self.fibre_nodes_pdf(gamma, w, v, l);
            }
            let mut nodes = 0.0;
            for &(c, s, nu) in &self.nodes {
                let lj = turn(l, c, s);
                let mut q = w.tube * tube_pdf(&lj);
                if w.lobe > 0.0 {
                    let vj = turn(v, c, s);
                    q += w.lobe
                        * match self.lobe {
                            Lobe::Ward { ax, ay } => ward_pdf(ax, ay, &vj, &lj),
                            Lobe::Ggx { at, ab, .. } => ggx_pdf(at, ab, &vj, &lj),
                            Lobe::Fibre { .. } | Lobe::None => 0.0,
                        };
                }
                nodes += nu * q;
            }
            p += nodes;
        }
        p
    }

    /// The fibre rungs' node sum of the mixture's density (tube and lobe at every spread node),
    /// [`NODE_LANES`] nodes at a time in lanes on the widest vector instructions: no libm call
    /// per node (the lobe's law has one lane arc tangent, the cone table's coordinates are half
    /// tangents), so with a spread's 16 nodes the density costs about what one node's did.
    fn fibre_nodes_pdf(&self, gamma: f64, w: &Weights, v: &Local, l: &Local) -> f64 {
        if let [(c, s, nu)] = self.nodes[..] {
            // one node (no spread): the same terms without the lanes
            let (lj, vj) = (turn(l, c, s), turn(v, c, s));
            return nu
                * (w.tube * tube_pdf(&lj)
                    + w.lobe * fibre_lobe_pdf(gamma, self.cone.as_ref(), &vj, &lj));
        }
        crate::model::numerics::lanes::on_widest_lanes(
            #[inline(always)]
            |_| match &self.cone {
                None => self.node_sum::<false>(gamma, w, v, l),
                Some(_) => self.node_sum::<true>(gamma, w, v, l),
            },
        )
    }

    /// The lane loop of [`Sampler::fibre_nodes_pdf`]; with `CONE`, the cone table's
    /// coordinates in the lanes, then its lookups one node at a time (padding skipped).
    #[inline(always)]
    fn node_sum<const CONE: bool>(&self, gamma: f64, w: &Weights, v: &Local, l: &Local) -> f64 {
        let mut total = 0.0;
        for block in &self.node_blocks {
            let (mut q, mut lobe) = ([0.0; NODE_LANES], [0.0; NODE_LANES]);
            let (mut x_l, mut x_v) = ([0.0; NODE_LANES], [0.0; NODE_LANES]);
            for j in 0..NODE_LANES {
                let (c, s) = (block.cos[j], block.sin[j]);
                let lj = turn(l, c, s);
                let vj = turn(v, c, s);
                q[j] = w.tube * tube_pdf(&lj);
                lobe[j] = w.lobe * fibre_lobe_density(fibre_lobe_law(gamma, vj.t), lj.t);
                if CONE {
                    x_l[j] = half_tangent(lj.b, lj.n);
                    x_v[j] = half_tangent(vj.b, vj.n);
                }
            }
            match &self.cone {
                Some(t) if CONE => (0..block.count)
                    .for_each(|j| q[j] += lobe[j] * t.density_per_radian(x_v[j], x_l[j])),
                _ => (0..NODE_LANES).for_each(|j| q[j] += lobe[j] * FRAC_1_PI),
            }
            for j in 0..NODE_LANES {
                total += block.weight[j] * q[j];
            }
        }
        total
    }

    /// The mixture weights for the view v (above the horizon) from the albedos.
    fn weights(&self, albedos: &Albedos, v: &Local) -> Weights {
        let mean = |a: &[f64; 3]| (a[0] + a[1] + a[2]) / 3.0;
        let (kd, ks, sub, fuzz) = (
            mean(&albedos.diffuse),
            mean(&albedos.specular),
            mean(&albedos.substrate),
            mean(&albedos.fuzz),
        );
        // the fuzz layer: the rung attenuated (light at normal incidence), the layer's own part
        let (attenuation, fuzz_albedo) = if self.fuzz_depth > 0.0 {
            let a = (-self.fuzz_depth * (1.0 + 1.0 / v.n)).exp();
            (a, 0.1 * (1.0 - a) * fuzz)
        } else {
            (1.0, 0.0)
        };
        // the cross-section rungs' diffuse and substrate albedos from their table
        let (kd_cos, sub_albedo) = match &self.cone {
            Some(t) => {
                let a = t.albedos(v);
                (a[1], a[2])
            }
            None => (self.kd_cos, 1.0),
        };
        let tube = kd * self.kd_tube * attenuation;
        let cos = (kd * kd_cos + sub * sub_albedo) * attenuation + fuzz_albedo;
        let lobe_albedo = if ks > 0.0 {
            ks * attenuation * self.lobe_albedo(v)
        } else {
            0.0
        } + kd * self.kd_lobe * attenuation;
        let has_lobe = !matches!(self.lobe, Lobe::None) && lobe_albedo > 0.0;
        let diffuse = tube + cos;
        let lobe = if !has_lobe {
            0.0
        } else if diffuse > 0.0 {
            (lobe_albedo / (lobe_albedo + diffuse)).clamp(LOBE_MIN, 1.0 - DIFFUSE_MIN)
        } else {
            1.0 - DIFFUSE_MIN
        };
        let rest = 1.0 - lobe;
        let tube_share = if diffuse > 0.0 {
            tube / diffuse
        } else if self.kd_tube > 0.0 && self.kd_cos == 0.0 {
            1.0
        } else {
            0.0
        };
        let tube = rest * tube_share;
        Weights {
            cos: rest - tube,
            tube,
            lobe,
        }
    }

    /// A rough directional albedo of the lobe per unit specular albedo at the view v: only
    /// the mixture weights depend on it.
    fn lobe_albedo(&self, v: &Local) -> f64 {
        let fresnel = if self.fresnel_ior > 0.0 {
            schlick(v.n, self.fresnel_ior)
        } else {
            1.0
        };
        let shape = match (self.lobe, self.lobe_albedo) {
            (Lobe::None, _) => 0.0,
            // glTF's layers: Schlick's Fresnel at N.v on the dielectric's and the metal's lobe
            (
                Lobe::Ggx {
                    dielectric,
                    f0,
                    metal,
                    ..
                },
                _,
            ) => {
                let x = (1.0 - v.n).clamp(0.0, 1.0).powi(5);
                dielectric * (f0 + (1.0 - f0) * x) + metal * x
            }
            // int cos^e(th - th_r) cos(th) dth dphi ~ pi cos(th_r) W(e), W the Wallis integral
            (_, LobeAlbedo::Wallis) => {
                let w = wallis(self.exponent);
                PI * w * v.projected_len().max(0.5 * w)
            }
            // the cross-section rungs: the lobe at latitude 0 times cos(th_r) (the lobe's
            // integral over the fibre's normals goes like 1 / sqrt(|l_p| |v_p|))
            (_, LobeAlbedo::ConeTable) => match &self.cone {
                Some(t) => t.albedos(v)[0] * v.projected_len(),
                None => 1.0,
            },
            // normalised lobes
            (_, LobeAlbedo::Normalised) => 1.0,
        };
        fresnel * shape
    }
}
