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
//! spherical coordinates about T (th the latitude from the cross-section plane), so d omega =
//! cos(th) dth dphi. T lies in the swatch plane, so N.l = cos(th) sin(phi) > 0 exactly when phi is
//! in (0, pi): drawing phi there never leaves the hemisphere. th and phi are drawn independently:
//! th = th_r + delta with the
//! mirror latitude th_r = -asin(v.t) and delta from a Cauchy law of width gamma = c / sqrt(e)
//! truncated to th in [-pi/2, pi/2]: with A = atan((-pi/2 - th_r)/gamma), B = atan((pi/2 -
//! th_r)/gamma), delta = gamma tan(A + u (B - A)) and its density is
//!
//! ```text
//! g(delta) = 1 / ((B - A) gamma (1 + (delta/gamma)^2)),
//! p_lobe(l | v) = g(th - th_r) q(alpha_l | v) / cos th,   th = atan2(l.t, |l_p|), cos th = |l_p|,
//! ```
//!
//! with q the density of the longitude, written by alpha_l = pi/2 - phi = atan2(l.b, l.n), the
//! angle of l's projection in the cross-section plane (MODEL.md §1).
//!
//! - max-normal: q = 1/pi, uniform: its lobe does not depend on the longitude at all.
//! - cross-section rungs: along the cone the lobe is shaped by hiding and shadowing, strongly
//!   so at grazing views (at 80 deg across the fibres it is zero over 40 % of the cone and peaks
//!   at the edge where the reflecting normals stop being visible). Its shape depends on v
//!   through alpha_v, the view's angle in the cross-section plane (the latitude only scales it:
//!   the cross-section sees projections), so `Sampler::new` tabulates it from the rung itself:
//!   [`CONE_ROWS`] / 2 views at latitude 0 with alpha_v >= 0, and for each the lobe's intensity
//!   f_s (N.l) at l in the plane at [`CONE_BINS`] + 1 equally spaced alpha_l. q is that profile
//!   interpolated linearly between the nodes, normalised, mixed with the uniform law
//!   ([`CONE_UNIFORM`] of it: other heights and latitudes, the Fresnel factor, the spread), and
//!   blended linearly between the two rows whose alpha_v bracket the view's (the lobe's edge moves
//!   fast with alpha_v at grazing views). Rows for alpha_v < 0 are the mirror images, so q and
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
//! # Why the density is exact
//!
//! Every component is drawn by inverting its own closed-form CDF (the tube's by Newton to full
//! precision; the cone table's row by its exact cumulative masses and the quadratic within a
//! bin), and `pdf` evaluates the same closed forms at l, for every component and node, not
//! only the one that drew l: the density of the mixture is the weighted sum of the densities of
//! its components whichever produced the sample. The component and node are chosen by rescaling
//! `u[0]` (the rescaled uniform is again uniform and independent of the choice), the cone
//! table's row by rescaling `u[1]`. The weights and the table's rows depend only on (albedos,
//! v), never on l, so they are the same in `sample` and `pdf`. `pdf` does not take the texel
//! height: the sampler is the same at every height (the weight's f is the height's). Tested
//! in `tests/sampling.rs` by chi-square goodness-of-fit tests of the directions against `pdf`.
//! Directions with N.l <= [`HORIZON_COS`] count as at the horizon in both.

use super::azimuth_spread::spread_nodes;
use super::frame::Local;
use super::fresnel::schlick;
use super::params::ModelParams;
use super::rung::{LobeAlbedo, LobeSampling, Rung};
use super::{Ability, Albedos, DirectionPair, ModelId, ShadingModel};
use std::f64::consts::{FRAC_1_PI, FRAC_PI_2, PI, TAU};

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
}

/// The longitude law along the highlight cone of a cross-section rung: per row of alpha_v (the
/// view's angle in the cross-section plane), a piecewise-constant law of alpha_l, tabulated from
/// the rung's own lobe in the cross-section plane (where the cone's latitude is 0).
#[derive(Clone, Debug)]
struct ConeTable {
    /// Probability of each alpha_l bin, per row (each row sums to 1).
    /// The density (per radian) of alpha_l at the bin ends -pi/2 + j pi / CONE_BINS, per row;
    /// linear between them (continuous), integrating to 1.
    density: Vec<[f64; CONE_BINS + 1]>,
    /// Cumulative masses of the bins per row (the last is 1).
    cumulative: Vec<[f64; CONE_BINS]>,
    /// Per row, for the weights: the lobe's directional albedo per unit ks at latitude 0, and
    /// the diffuse and the substrate directional albedos per unit albedo.
    albedo: Vec<[f64; 3]>,
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
    /// Directional albedo per unit kd going to the tube and to the cosine technique.
    kd_tube: f64,
    kd_cos: f64,
}

/// One sampled direction.
#[derive(Clone, Copy, Debug)]
pub struct Sample {
    pub l: Local,
    pub pdf: f64,
    pub weight: [f64; 3],
}

/// The mixture weights for one view.
#[derive(Clone, Copy, Debug)]
struct Weights {
    cos: f64,
    tube: f64,
    lobe: f64,
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
        };
        // the spread applies where `model::with_spread` applies it
        let spread = p.azimuth_spread_deg > 0.0 && id.has(Ability::DirectionSpread);
        let nodes = if spread {
            spread_nodes(p.azimuth_spread_deg, p.azimuth_nodes, p.fibre_azimuth)
        } else {
            vec![(1.0, 0.0, 1.0)]
        };
        let mut acc = 0.0;
        let mut cumulative: Vec<f64> = nodes
            .iter()
            .map(|n| {
                acc += n.2;
                acc
            })
            .collect();
        if let Some(last) = cumulative.last_mut() {
            *last = 1.0;
        }
        // directional albedo per unit kd of the diffuse term, by technique
        let (kd_tube, kd_cos) = (rung.diffuse_tube, rung.diffuse_cosine);
        let fresnel = p.fresnel_ior > 0.0 && id.has(Ability::Fresnel);
        let cone = rung.cone_from.and_then(|from| ConeTable::new(from, p));
        Sampler {
            lobe_albedo: rung.lobe_albedo,
            lobe,
            cone,
            exponent: p.exponent,
            fresnel_ior: if fresnel { p.fresnel_ior } else { 0.0 },
            fuzz_depth: p.fuzz_depth,
            nodes,
            cumulative,
            kd_tube,
            kd_cos,
        }
    }

    /// The same sampler with the fibre lobe's Cauchy width c / sqrt(exponent) (default
    /// [`LOBE_WIDTH`]); for the width study of `fibrefit bench sampling`. No effect on rungs
    /// without a fibre lobe.
    pub fn with_lobe_width(mut self, c: f64) -> Sampler {
        if let Lobe::Fibre { gamma } = &mut self.lobe {
            *gamma = c / self.exponent.max(1.0).sqrt();
        }
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
        let mut weight = [0.0; 3];
        for (c, w) in weight.iter_mut().enumerate() {
            *w = basis.brdf(albedos, c) * l.n / pdf;
        }
        Some(Sample { l, pdf, weight })
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
                        fibre_lobe_direction(gamma, self.cone.as_ref(), &vj, [r, u1])
                    }
                    Lobe::Ward { ax, ay } => ward_direction(ax, ay, &turn(v, c, s), [r, u1]),
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
            let mut nodes = 0.0;
            for &(c, s, nu) in &self.nodes {
                let lj = turn(l, c, s);
                let mut q = w.tube * tube_pdf(&lj);
                if w.lobe > 0.0 {
                    let vj = turn(v, c, s);
                    q += w.lobe
                        * match self.lobe {
                            Lobe::Fibre { gamma } => {
                                fibre_lobe_pdf(gamma, self.cone.as_ref(), &vj, &lj)
                            }
                            Lobe::Ward { ax, ay } => ward_pdf(ax, ay, &vj, &lj),
                            Lobe::None => 0.0,
                        };
                }
                nodes += nu * q;
            }
            p += nodes;
        }
        p
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
        };
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

impl ConeTable {
    /// The table of rung `id` (a cross-section rung: the reference's is varying-topology's,
    /// which is it to the quadrature error, as its [`super::rungs::Sampling::cone_from`] says)
    /// with parameters `p`, from the aligned rung (no spread, Fresnel or fuzz: those the
    /// mixture and the uniform share absorb), for v in the
    /// cross-section plane at the centre of each row with alpha_v >= 0: the lobe's intensity
    /// f_s (N.l) at l in the plane (latitude 0, the cone of v) at each alpha_l bin's centre, and
    /// the diffuse and substrate directional albedos per unit albedo by an 8 x 8 cosine-weighted
    /// product rule (at most 16 heights and 16 lobe nodes). The rows of alpha_v < 0 are their
    /// mirror images (T -> -T), exactly. `None` if the rung cannot be built (then the cone's
    /// longitude law is uniform).
    fn new(rung: &Rung, p: &ModelParams) -> Option<ConeTable> {
        let mut q = p.clone();
        q.azimuth_spread_deg = 0.0;
        q.fresnel_ior = 0.0;
        q.fuzz_depth = 0.0;
        // the table is a proposal's shape: 16 heights and 16 lobe nodes are plenty, and keep
        // its cost bounded whatever the rung's own knobs (up to 65536 heights)
        q.histogram_bins = q.histogram_bins.min(16);
        q.quadrature_order = q.quadrature_order.min(16);
        let m = super::build(ModelId::of(rung), &q).ok()?;
        const GRID: usize = 8;
        let half = CONE_ROWS / 2;
        let bin = PI / CONE_BINS as f64;
        let in_plane = |alpha: f64| {
            let (s, c) = alpha.sin_cos();
            Local { t: 0.0, b: s, n: c }
        };
        let per_row = CONE_BINS + 1 + GRID * GRID;
        let mut pairs = Vec::with_capacity(half * per_row);
        for i in 0..half {
            let v = in_plane((i as f64 + 0.5) * FRAC_PI_2 / half as f64);
            for j in 0..=CONE_BINS {
                let alpha = -FRAC_PI_2 + j as f64 * bin;
                pairs.push(DirectionPair {
                    l: in_plane(alpha),
                    v,
                });
            }
            for a in 0..GRID {
                for b in 0..GRID {
                    let u = [
                        (a as f64 + 0.5) / GRID as f64,
                        (b as f64 + 0.5) / GRID as f64,
                    ];
                    pairs.push(DirectionPair {
                        l: cosine_direction(u),
                        v,
                    });
                }
            }
        }
        let mut out = vec![super::Basis::default(); pairs.len()];
        m.basis_many(&pairs, &mut out);
        let finite = |x: f64| if x.is_finite() && x > 0.0 { x } else { 0.0 };
        let w = wallis(p.exponent);
        // per row with alpha_v >= 0: masses, lobe albedo, diffuse and substrate albedos
        let mut upper = Vec::with_capacity(half);
        for i in 0..half {
            let row = &out[i * per_row..(i + 1) * per_row];
            let row_pairs = &pairs[i * per_row..(i + 1) * per_row];
            let mut t = [0.0; CONE_BINS + 1];
            for (j, tj) in t.iter_mut().enumerate() {
                *tj = finite(row[j].specular * row_pairs[j].l.n);
            }
            // the integral of the linear interpolant
            let total: f64 = t.windows(2).map(|w| 0.5 * (w[0] + w[1]) * bin).sum();
            let floor = if total > 0.0 { CONE_UNIFORM } else { 1.0 };
            let density = t.map(|tj| {
                let share = if total > 0.0 { tj / total } else { 0.0 };
                (1.0 - floor) * share + floor * FRAC_1_PI
            });
            // cosine-weighted rule: a(v) = mean of pi f
            let grid = &row[CONE_BINS + 1..];
            let mean = |f: &dyn Fn(&super::Basis) -> f64| {
                PI * grid.iter().map(|b| finite(f(b))).sum::<f64>() / grid.len() as f64
            };
            upper.push(Row {
                density,
                // the lobe's albedo at latitude 0: its integral over alpha_l times its width
                // in latitude (cos^e)
                lobe: total * w,
                diffuse: mean(&|b| b.diffuse),
                substrate: mean(&|b| b.substrate),
            });
        }
        // rows k < half are the mirror images of rows CONE_ROWS - 1 - k
        let rows: Vec<Row> = (0..CONE_ROWS)
            .map(|k| {
                if k < half {
                    let mut r = upper[half - 1 - k].clone();
                    r.density.reverse();
                    r
                } else {
                    upper[k - half].clone()
                }
            })
            .collect();
        let cumulative = rows
            .iter()
            .map(|row| {
                let mut c = [0.0; CONE_BINS];
                let mut acc = 0.0;
                for (j, cj) in c.iter_mut().enumerate() {
                    acc += 0.5 * (row.density[j] + row.density[j + 1]) * bin;
                    *cj = acc;
                }
                // the masses sum to 1 up to rounding
                c.iter_mut().for_each(|x| *x /= acc);
                c[CONE_BINS - 1] = 1.0;
                c
            })
            .collect();
        Some(ConeTable {
            density: rows.iter().map(|r| r.density).collect(),
            cumulative,
            albedo: rows
                .iter()
                .map(|r| [r.lobe, r.diffuse, r.substrate])
                .collect(),
        })
    }
}

/// One row of a [`ConeTable`] while it is built.
#[derive(Clone)]
struct Row {
    density: [f64; CONE_BINS + 1],
    lobe: f64,
    diffuse: f64,
    substrate: f64,
}

impl ConeTable {
    /// The two rows that bracket the view's cross-section angle `alpha_v` and the weight of the
    /// second: the law is the blend of the rows at the neighbouring row centres (linear in
    /// alpha_v; the lobe's edge moves fast with alpha_v at grazing views). Computed from
    /// |alpha_v| and its sign, so -alpha_v gives the mirror rows with the same weight.
    fn blend(&self, alpha_v: f64) -> (usize, usize, f64) {
        let half = CONE_ROWS / 2;
        // position among the row centres (i + 1/2) of the rows with alpha_v >= 0, in row units;
        // -1 is the mirror of row 0
        let q = alpha_v.abs() / FRAC_PI_2 * half as f64 - 0.5;
        let lo = q.floor().clamp(-1.0, half as f64 - 1.0);
        let w = (q - lo).clamp(0.0, 1.0);
        let lo = lo as isize;
        let hi = (lo + 1).min(half as isize - 1);
        let row = |j: isize| {
            if alpha_v.is_sign_negative() {
                (half as isize - 1 - j) as usize
            } else {
                (half as isize + j) as usize
            }
        };
        (row(lo), row(hi), w)
    }

    /// The row albedos (lobe, diffuse, substrate; see `albedo`) blended for the view v.
    fn albedos(&self, v: &Local) -> [f64; 3] {
        let (a, b, w) = self.blend(v.b.atan2(v.n));
        let (x, y) = (self.albedo[a], self.albedo[b]);
        [0, 1, 2].map(|k| (1.0 - w) * x[k] + w * y[k])
    }

    /// The density (per radian) of alpha_l given alpha_v.
    fn density(&self, alpha_v: f64, alpha_l: f64) -> f64 {
        let (a, b, w) = self.blend(alpha_v);
        // the nodes either side of alpha_l, from |alpha_l| and its sign (exact mirror images)
        let half = CONE_BINS / 2;
        let y = alpha_l.abs() / PI * CONE_BINS as f64;
        let k = (y.floor() as usize).min(half - 1);
        let f = (y - k as f64).clamp(0.0, 1.0);
        let (n0, n1) = if alpha_l.is_sign_negative() {
            (half - k, half - k - 1)
        } else {
            (half + k, half + k + 1)
        };
        let at = |d: &[f64; CONE_BINS + 1]| (1.0 - f) * d[n0] + f * d[n1];
        (1.0 - w) * at(&self.density[a]) + w * at(&self.density[b])
    }

    /// alpha_l drawn from the blend for alpha_v with the uniform `u` (the row by its rescaled
    /// value, then the bin by inversion, uniform within the bin).
    fn sample(&self, alpha_v: f64, u: f64) -> f64 {
        let (a, b, w) = self.blend(alpha_v);
        let (row, u) = if u < 1.0 - w {
            (a, rescale(u, 0.0, 1.0 - w))
        } else {
            (b, rescale(u, 1.0 - w, 1.0))
        };
        let cumulative = &self.cumulative[row];
        let j = cumulative.partition_point(|&c| c <= u).min(CONE_BINS - 1);
        let lo = if j == 0 { 0.0 } else { cumulative[j - 1] };
        let r = rescale(u, lo, cumulative[j]);
        // within the bin the density runs linearly from a to b: its CDF a x + (b - a) x^2 / 2
        // = r (a + b) / 2 solved in the cancellation-free form
        let (a, b) = (self.density[row][j], self.density[row][j + 1]);
        let root = (a * a * (1.0 - r) + b * b * r).sqrt();
        let x = if a + root > 0.0 {
            (r * (a + b) / (a + root)).clamp(0.0, 1.0)
        } else {
            r
        };
        -FRAC_PI_2 + (j as f64 + x) * (PI / CONE_BINS as f64)
    }
}

/// The Wallis integral int_{-pi/2}^{pi/2} cos^e(x) dx, approximately (2 % at e = 1, exact as
/// e grows): the lobe's width in latitude, for the weights only.
fn wallis(e: f64) -> f64 {
    (TAU / (e + 0.5)).sqrt()
}

/// The largest f64 below 1.
const ONE_BELOW: f64 = 1.0 - f64::EPSILON / 2.0;

/// (u - lo) / (hi - lo) in [0, 1): a uniform on [lo, hi) rescaled to the unit interval.
fn rescale(u: f64, lo: f64, hi: f64) -> f64 {
    if !(hi > lo) {
        return 0.0;
    }
    ((u - lo) / (hi - lo)).clamp(0.0, ONE_BELOW)
}

/// w in the frame of fibres turned by delta (cos c, sin s) about N (as the spread turns them).
fn turn(w: &Local, c: f64, s: f64) -> Local {
    Local {
        t: w.t * c + w.b * s,
        b: -w.t * s + w.b * c,
        n: w.n,
    }
}

/// The inverse of [`turn`].
fn unturn(w: &Local, c: f64, s: f64) -> Local {
    Local {
        t: w.t * c - w.b * s,
        b: w.t * s + w.b * c,
        n: w.n,
    }
}

/// Cosine-weighted hemisphere direction from two uniforms (Malley: a uniform disk point lifted).
fn cosine_direction(u: [f64; 2]) -> Local {
    let r2 = u[0];
    let r = r2.sqrt();
    let (s, c) = (TAU * u[1]).sin_cos();
    Local {
        t: r * c,
        b: r * s,
        n: (1.0 - r2).max(0.0).sqrt(),
    }
}

/// The direction at latitude th (given as sin, cos) about T and longitude phi in (0, pi).
fn about_tangent(sin_th: f64, cos_th: f64, phi: f64) -> Local {
    let (sp, cp) = phi.sin_cos();
    Local {
        t: sin_th,
        b: cos_th * cp,
        n: cos_th * sp,
    }
}

/// y - sin y, accurate for small y.
fn y_minus_sin(y: f64) -> f64 {
    if y < 0.25 {
        let y2 = y * y;
        // y^3/3! - y^5/5! + y^7/7! - y^9/9! + y^11/11!
        y * y2
            * (1.0 / 6.0
                - y2 * (1.0 / 120.0
                    - y2 * (1.0 / 5040.0 - y2 * (1.0 / 362_880.0 - y2 / 39_916_800.0))))
    } else {
        y - y.sin()
    }
}

/// The tube technique: th with density cos^2(th) / (pi/2), phi uniform on (0, pi).
fn tube_direction(u: [f64; 2]) -> Local {
    // F(th) = (y - sin y) / (2 pi) with y = 2 th + pi in [0, 2 pi]; solve for y in [0, pi] by
    // symmetry (y -> 2 pi - y is th -> -th)
    let m = TAU * u[0];
    let upper = m > PI;
    let m = if upper { TAU - m } else { m };
    // y - sin y <= y^3 / 6: cbrt(6 m) is at or left of the root; y - sin y is convex on [0, pi],
    // so Newton's first step lands right of it and the iterates fall to it monotonically
    let mut y = (6.0 * m).cbrt().min(PI);
    for _ in 0..40 {
        let slope = 2.0 * (0.5 * y).sin().powi(2); // 1 - cos y
        if !(slope > 0.0) {
            break;
        }
        let step = (y_minus_sin(y) - m) / slope;
        let next = (y - step).clamp(0.0, PI);
        let done = (next - y).abs() <= 4.0 * f64::EPSILON * y.max(f64::MIN_POSITIVE);
        y = next;
        if done {
            break;
        }
    }
    // th = y/2 - pi/2: cos th = sin(y/2), sin th = -cos(y/2)
    let (s, c) = (0.5 * y).sin_cos();
    let sin_th = if upper { c } else { -c };
    about_tangent(sin_th, s, PI * u[1])
}

/// Density of [`tube_direction`] at l (above the horizon, in the fibres' frame).
fn tube_pdf(l: &Local) -> f64 {
    2.0 * l.projected_len() * FRAC_1_PI * FRAC_1_PI
}

/// The mirror latitude th_r = -asin(v.t) and the Cauchy law's truncation (A, B - A).
fn fibre_lobe_law(gamma: f64, v: &Local) -> (f64, f64, f64) {
    let th_r = -v.t.atan2(v.projected_len());
    let a = ((-FRAC_PI_2 - th_r) / gamma).atan();
    let b = ((FRAC_PI_2 - th_r) / gamma).atan();
    (th_r, a, b - a)
}

/// The fibre lobe technique for the view v (fibre frame of the node): the latitude from the
/// Cauchy law, the longitude uniform or from the cone table's row `row`.
fn fibre_lobe_direction(gamma: f64, cone: Option<&ConeTable>, v: &Local, u: [f64; 2]) -> Local {
    let (th_r, a, width) = fibre_lobe_law(gamma, v);
    let delta = gamma * (a + u[0] * width).tan();
    let th = (th_r + delta).clamp(-FRAC_PI_2, FRAC_PI_2);
    let (s, c) = th.sin_cos();
    // alpha_l = pi/2 - phi, the longitude's angle in the cross-section plane from N
    // alpha_l = pi/2 - phi, the longitude's angle in the cross-section plane from N
    let alpha = match cone {
        None => FRAC_PI_2 - PI * u[1],
        Some(table) => table.sample(v.b.atan2(v.n), u[1]),
    };
    let (sa, ca) = alpha.sin_cos();
    Local {
        t: s,
        b: c * sa,
        n: c * ca,
    }
}

/// Density of [`fibre_lobe_direction`] at l (above the horizon).
fn fibre_lobe_pdf(gamma: f64, cone: Option<&ConeTable>, v: &Local, l: &Local) -> f64 {
    let (th_r, _, width) = fibre_lobe_law(gamma, v);
    let lp = l.projected_len();
    let th = l.t.atan2(lp);
    let x = (th - th_r) / gamma;
    let g = 1.0 / (width * gamma * (1.0 + x * x));
    // the longitude's density per radian
    let longitude = match cone {
        None => FRAC_1_PI,
        Some(table) => table.density(v.b.atan2(v.n), l.b.atan2(l.n)),
    };
    g * longitude / lp
}

/// Walter's half vector for Ward, reflected: l (may be below the horizon).
fn ward_direction(ax: f64, ay: f64, v: &Local, u: [f64; 2]) -> Local {
    let (s, c) = (TAU * u[1]).sin_cos();
    let phi = (ay * s).atan2(ax * c);
    let (sp, cp) = phi.sin_cos();
    let q = cp * cp / (ax * ax) + sp * sp / (ay * ay);
    let tan2 = -(-u[0]).ln_1p() / q;
    let cos_h = 1.0 / (1.0 + tan2).sqrt();
    let sin_h = (tan2 / (1.0 + tan2)).sqrt();
    let h = Local {
        t: sin_h * cp,
        b: sin_h * sp,
        n: cos_h,
    };
    let vh = v.dot(&h);
    Local {
        t: 2.0 * vh * h.t - v.t,
        b: 2.0 * vh * h.b - v.b,
        n: 2.0 * vh * h.n - v.n,
    }
}

/// Density of [`ward_direction`] at l (both above the horizon).
fn ward_pdf(ax: f64, ay: f64, v: &Local, l: &Local) -> f64 {
    let (ht, hb, hn) = (l.t + v.t, l.b + v.b, l.n + v.n);
    let norm = (ht * ht + hb * hb + hn * hn).sqrt();
    if !(norm > 0.0 && hn > 0.0) {
        return 0.0;
    }
    let (ht, hb, hn) = (ht / norm, hb / norm, hn / norm);
    let e = ((ht / ax).powi(2) + (hb / ay).powi(2)) / (hn * hn);
    let p_h = (-e).exp() / (PI * ax * ay * hn * hn * hn);
    // l.h = |l + v| / 2
    p_h / (2.0 * norm)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tube_inversion_reaches_the_cdf() {
        for k in 0..=1000 {
            let u = k as f64 / 1000.0 * ONE_BELOW;
            let l = tube_direction([u, 0.3]);
            let th = l.t.atan2(l.projected_len());
            let y = 2.0 * th + PI;
            let f = y_minus_sin(y) / TAU;
            assert!((f - u).abs() < 1e-13, "u {u}: F {f}");
            assert!(((l.t * l.t + l.b * l.b + l.n * l.n) - 1.0).abs() < 1e-14);
        }
    }

    #[test]
    fn the_cone_law_integrates_to_one_and_its_draws_invert_its_cdf() {
        let raw: crate::model::params::RawParams =
            toml::from_str("kd = 0.3\nks = 0.6\nexponent = 300\nspacing = 2.6\n").unwrap();
        let p = ModelParams::from_raw(&raw, ModelId::PoulinFournier)
            .unwrap()
            .0;
        let sampler = Sampler::new(ModelId::PoulinFournier, &p);
        let table = sampler
            .cone
            .as_ref()
            .expect("a cross-section rung has a table");
        let bin = PI / CONE_BINS as f64;
        for row in 0..CONE_ROWS {
            let d = &table.density[row];
            let total: f64 = d.windows(2).map(|w| 0.5 * (w[0] + w[1]) * bin).sum();
            assert!((total - 1.0).abs() < 1e-12, "row {row}: {total}");
            // the mirror row
            let mut m = table.density[CONE_ROWS - 1 - row];
            m.reverse();
            assert_eq!(&m, d);
        }
        // at a row's centre the law is that row alone: F(draw(u)) = u
        for i in [0usize, 5, 20, 31] {
            let alpha_v = (i as f64 + 0.5) * FRAC_PI_2 / (CONE_ROWS / 2) as f64;
            let (lo, hi, w) = table.blend(alpha_v);
            // one of the two rows, to rounding
            let a = if w < 0.5 { lo } else { hi };
            assert!(w.min(1.0 - w) < 1e-9, "{w}");
            let d = &table.density[a];
            let cdf = |alpha: f64| {
                let x = (alpha + FRAC_PI_2) / bin;
                let j = (x.floor() as usize).min(CONE_BINS - 1);
                let f = x - j as f64;
                let full: f64 = (0..j).map(|k| 0.5 * (d[k] + d[k + 1]) * bin).sum();
                full + (d[j] * f + 0.5 * (d[j + 1] - d[j]) * f * f) * bin
            };
            for k in 0..200 {
                let u = (k as f64 + 0.5) / 200.0;
                let alpha = table.sample(alpha_v, u);
                assert!(
                    (cdf(alpha) - u).abs() < 1e-9,
                    "row {a} u {u}: {}",
                    cdf(alpha)
                );
                // the density at the draw is the blend's
                let q = table.density(alpha_v, alpha);
                assert!(q > 0.0 && q.is_finite());
            }
        }
    }

    #[test]
    fn turning_is_undone() {
        let w = Local {
            t: 0.3,
            b: -0.5,
            n: 0.81f64.sqrt(),
        };
        let (s, c) = 0.7f64.sin_cos();
        let back = unturn(&turn(&w, c, s), c, s);
        assert!((back.t - w.t).abs() < 1e-15 && (back.b - w.b).abs() < 1e-15);
    }
}
