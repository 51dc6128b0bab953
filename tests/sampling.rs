//! Issue 21 item 2: importance sampling of every rung (`model::sampling`).
//!
//! - Chi-square goodness of fit of the sampled directions against `Sampler::pdf` (pbrt-v4 /
//!   Mitsuba style): the hemisphere binned in (cos theta, phi), `pdf` integrated over each bin by
//!   adaptive Gauss–Legendre cubature, bins expected below 5 pooled (with the draws that returned
//!   `None`, whose expected share is 1 - the integral), the statistic's p-value from the
//!   regularised incomplete gamma function, rejected below 0.01 / (number of tests) (Bonferroni).
//!   Every rung at normal, 45 and 80 degrees along and across the fibres, plus exponent 1e4, the
//!   isotropic and a partial fibre-direction spread, the fuzz layer, the Fresnel factor, a texel
//!   height, RGB albedos, a lobe without diffuse, Ward with narrow lobes.
//! - `weight` = f (N.l) / pdf at the sampled direction (relative 1e-12), with f from the model
//!   (at the texel's height when given); `pdf` of the sample equals `Sampler::pdf`; `pdf` is
//!   non-negative, finite, zero below the horizon and invariant under T -> -T; its integral is at
//!   most 1 and 1 where nothing falls below the horizon (every rung but ward and gltf).
//! - Determinism; the zero-variance cases (hast-diffuse, max-normal's diffuse); the variance gain
//!   over cosine sampling at exponent 1000.
//! - One instance per draw (`Sampler::sample_instance`): the instances weighted by their
//!   probabilities are the exact model (1e-12), they are drawn with those probabilities, an
//!   instance's weight is its f cos / pdf and a batch equals each draw alone, chi-square tests of
//!   one instance's directions and of an instance drawn per sample, the albedo estimate unbiased
//!   against the exact sampler's; `Material`'s instance API likewise.

mod common;

use common::Rng;
use fibrefit::model::frame::Local;
use fibrefit::model::lambert::Lambert;
use fibrefit::model::params::{ModelParams, RawParams};
use fibrefit::model::sampling::Sampler;
use fibrefit::model::{self, Albedos, DirectionPair, ModelId, ShadingModel};
use std::f64::consts::{PI, TAU};

fn params(text: &str, id: ModelId) -> ModelParams {
    let raw: RawParams = toml::from_str(text).unwrap();
    ModelParams::from_raw(&raw, id).unwrap().0
}

/// A view at polar angle `theta_deg` from N, along the fibres (in the (T, N) plane) or across
/// them (in the (B, N) plane), or at an azimuth `phi_deg` from T.
fn view(theta_deg: f64, phi_deg: f64) -> Local {
    let (st, ct) = theta_deg.to_radians().sin_cos();
    let (sp, cp) = phi_deg.to_radians().sin_cos();
    Local {
        t: st * cp,
        b: st * sp,
        n: ct,
    }
}

const ALONG: f64 = 0.0;
const ACROSS: f64 = 90.0;

/// One configuration: a rung, its parameter text, the view, a texel height.
struct Case {
    name: String,
    id: ModelId,
    text: String,
    v: Local,
    height: Option<f64>,
}

/// The rung's typical parameters from the registry, at exponent 200 where it has one.
fn base_text(id: ModelId) -> String {
    id.rung().example_text(Some(200.0))
}

fn cases() -> Vec<Case> {
    let mut out = Vec::new();
    let mut push = |name: &str, id: ModelId, text: String, v: Local, height: Option<f64>| {
        out.push(Case {
            name: format!("{id} {name}"),
            id,
            text,
            v,
            height,
        })
    };
    for id in ModelId::ALL {
        let t = base_text(id);
        push("normal", id, t.clone(), view(0.0, 0.0), None);
        push("45 along", id, t.clone(), view(45.0, ALONG), None);
        push("45 across", id, t.clone(), view(45.0, ACROSS), None);
        push("80 along", id, t.clone(), view(80.0, ALONG), None);
        push("80 across", id, t.clone(), view(80.0, ACROSS), None);
        push("60 oblique", id, t.clone(), view(60.0, 140.0), None);
    }
    use ModelId::*;
    for id in [MaxNormal, PoulinFournier, VaryingTopology] {
        let t = base_text(id).replace("exponent = 200", "exponent = 10000");
        push("e 1e4, 45 along", id, t.clone(), view(45.0, ALONG), None);
        push("e 1e4, 80 along", id, t.clone(), view(80.0, 200.0), None);
        push("e 1e4, normal", id, t.clone(), view(0.0, 0.0), None);
        let t = base_text(id).replace("exponent = 200", "exponent = 1");
        push("e 1, 60 oblique", id, t, view(60.0, 30.0), None);
    }
    for id in [MaxNormal, HastDiffuse, PoulinFournier, Reference] {
        let iso = format!(
            "{}azimuth_spread_deg = 180\nfibre_azimuth_deg = 25\n",
            base_text(id)
        );
        push(
            "spread 180, 45 along",
            id,
            iso.clone(),
            view(45.0, ALONG),
            None,
        );
        push("spread 180, 80 across", id, iso, view(80.0, ACROSS), None);
    }
    for id in [MaxNormal, PoulinFournier] {
        let partial = format!(
            "{}azimuth_spread_deg = 20\nazimuth_nodes = 9\n",
            base_text(id)
        );
        push("spread 20, 60 along", id, partial, view(60.0, ALONG), None);
    }
    for id in [Lambert, MaxNormal, PoulinFournier, Ward] {
        let fuzz = format!(
            "{}fuzz = 0.8\nfuzz_depth = 0.4\nfuzz_asymmetry = 0.7\n",
            base_text(id)
        );
        push("fuzz, 75 along", id, fuzz, view(75.0, ALONG), None);
    }
    for id in [MaxNormal, PoulinFournier, VaryingTopology] {
        let fresnel = format!("{}fresnel_ior = 1.5\n", base_text(id));
        push("fresnel, 70 along", id, fresnel, view(70.0, 10.0), None);
    }
    // the gltf rung's threejs variant: the same lobes, its own BRDF (and weights); a metal
    // below three.js's roughness floor too
    let threejs = format!("{}gltf_variant = \"threejs\"\n", base_text(Gltf));
    push(
        "threejs, 45 along",
        Gltf,
        threejs.clone(),
        view(45.0, ALONG),
        None,
    );
    push(
        "threejs, 80 across",
        Gltf,
        threejs,
        view(80.0, ACROSS),
        None,
    );
    push(
        "threejs metal at roughness 0.03, 60 oblique",
        Gltf,
        "gltf_variant = \"threejs\"\nkd = [0.9, 0.6, 0.3]\nmetallic = 1\nroughness = 0.03\n\
         anisotropy_strength = 0.5\n"
            .to_string(),
        view(60.0, 140.0),
        None,
    );
    for id in [VaryingTopology, Reference] {
        push(
            "texel height 1.3, 50 along",
            id,
            base_text(id).to_string(),
            view(50.0, 15.0),
            Some(1.3),
        );
    }
    push(
        "rgb, spread 40 + fresnel + fuzz, 65 across",
        PoulinFournier,
        "kd = [0.6, 0.2, 0.1]\nks = [0.1, 0.5, 0.9]\nsubstrate_albedo = [0.2, 0.3, 0.1]\nexponent = 500\n\
         spacing = 3\nazimuth_spread_deg = 40\nfresnel_ior = 1.4\nfuzz = [0.2, 0.4, 1.0]\nfuzz_depth = 0.2\n"
            .to_string(),
        view(65.0, 80.0),
        None,
    );
    push(
        "lobe only, 30 along",
        MaxNormal,
        "kd = 0\nks = 0.8\nexponent = 50\n".to_string(),
        view(30.0, ALONG),
        None,
    );
    push(
        "narrow, 70 oblique",
        Ward,
        "rho_d = 0.1\nrho_s = 0.9\nalpha_x = 0.01\nalpha_y = 0.02\n".to_string(),
        view(70.0, 30.0),
        None,
    );
    push(
        "round, 85 along",
        Ward,
        "rho_s = 0.5\nalpha_x = 0.5\nalpha_y = 0.5\n".to_string(),
        view(85.0, ALONG),
        None,
    );
    push(
        "narrow metal, anisotropic, 70 oblique",
        Gltf,
        "kd = [0.9, 0.6, 0.3]\nmetallic = 1\nroughness = 0.1\nanisotropy_strength = 0.8\n"
            .to_string(),
        view(70.0, 30.0),
        None,
    );
    push(
        "sheen, rough, 80 across",
        Gltf,
        "kd = 0.2\nroughness = 0.9\nsheen = 1\nsheen_roughness = 0.3\nfibre_azimuth_deg = 40\n"
            .to_string(),
        view(80.0, ACROSS),
        None,
    );
    out
}

// ---- the chi-square machinery ----

/// ln Gamma(x) for x > 0 (Lanczos, g = 7, 9 terms: ~1e-15 relative).
fn ln_gamma(x: f64) -> f64 {
    const G: [f64; 9] = [
        0.999_999_999_999_809_9,
        676.520_368_121_885_1,
        -1_259.139_216_722_402_8,
        771.323_428_777_653_1,
        -176.615_029_162_140_6,
        12.507_343_278_686_905,
        -0.138_571_095_265_720_12,
        9.984_369_578_019_572e-6,
        1.505_632_735_149_311_6e-7,
    ];
    if x < 0.5 {
        return (PI / (PI * x).sin()).ln() - ln_gamma(1.0 - x);
    }
    let x = x - 1.0;
    let mut a = G[0];
    let t = x + 7.5;
    for (i, g) in G.iter().enumerate().skip(1) {
        a += g / (x + i as f64);
    }
    0.5 * TAU.ln() + (x + 0.5) * t.ln() - t + a.ln()
}

/// The regularised upper incomplete gamma function Q(a, x) (series below a + 1, Lentz's
/// continued fraction above; Numerical Recipes' gammq).
fn gamma_q(a: f64, x: f64) -> f64 {
    if x <= 0.0 {
        return 1.0;
    }
    let ln_pre = -x + a * x.ln() - ln_gamma(a);
    if x < a + 1.0 {
        let (mut sum, mut term, mut ap) = (1.0 / a, 1.0 / a, a);
        for _ in 0..100_000 {
            ap += 1.0;
            term *= x / ap;
            sum += term;
            if term.abs() < sum.abs() * 1e-16 {
                break;
            }
        }
        1.0 - sum * ln_pre.exp()
    } else {
        let tiny = 1e-300;
        let mut b = x + 1.0 - a;
        let mut c = 1.0 / tiny;
        let mut d = 1.0 / b;
        let mut h = d;
        for i in 1..100_000 {
            let an = -(i as f64) * (i as f64 - a);
            b += 2.0;
            d = an * d + b;
            if d.abs() < tiny {
                d = tiny;
            }
            c = b + an / c;
            if c.abs() < tiny {
                c = tiny;
            }
            d = 1.0 / d;
            let del = d * c;
            h *= del;
            if (del - 1.0).abs() < 1e-16 {
                break;
            }
        }
        ln_pre.exp() * h
    }
}

#[test]
fn the_incomplete_gamma_function_is_right() {
    // chi-square survival function: Q(k/2, x/2); known values
    assert!((gamma_q(0.5, 3.841_458_820_694_124 / 2.0) - 0.05).abs() < 1e-12);
    assert!((gamma_q(5.0, 23.209_251_158_954_36 / 2.0) - 0.01).abs() < 1e-12);
    assert!((gamma_q(1.0, 2.0) - (-2.0f64).exp()).abs() < 1e-15);
    // large dof: the median of chi-square(3000) is ~ 3000 (1 - 2/9000)^3
    let k: f64 = 3000.0;
    let median = k * (1.0 - 2.0 / (9.0 * k)).powi(3);
    assert!((gamma_q(k / 2.0, median / 2.0) - 0.5).abs() < 1e-3);
    assert!((ln_gamma(10.0) - 362_880f64.ln()).abs() < 1e-12);
}

const MU_BINS: usize = 40;
const PHI_BINS: usize = 80;

/// 4-point Gauss–Legendre on [-1, 1].
const GL4: [(f64, f64); 4] = [
    (-0.861_136_311_594_052_6, 0.347_854_845_137_453_86),
    (-0.339_981_043_584_856_3, 0.652_145_154_862_546_1),
    (0.339_981_043_584_856_3, 0.652_145_154_862_546_1),
    (0.861_136_311_594_052_6, 0.347_854_845_137_453_86),
];

fn direction(mu: f64, phi: f64) -> Local {
    let r = (1.0 - mu * mu).max(0.0).sqrt();
    Local {
        t: r * phi.cos(),
        b: r * phi.sin(),
        n: mu,
    }
}

fn cell(f: &dyn Fn(f64, f64) -> f64, m0: f64, m1: f64, p0: f64, p1: f64) -> f64 {
    let (hm, hp) = (0.5 * (m1 - m0), 0.5 * (p1 - p0));
    let mut s = 0.0;
    for (xm, wm) in GL4 {
        for (xp, wp) in GL4 {
            s += wm * wp * f(m0 + hm * (1.0 + xm), p0 + hp * (1.0 + xp));
        }
    }
    s * hm * hp
}

/// int over [m0, m1] x [p0, p1] of f d mu d phi, adaptively (quadrisection to `depth`), to an
/// absolute error `tol`; `coarse` is the cell's own 4x4 estimate. The first `min_depth` levels
/// always split (a lobe narrower than the rule's node spacing would pass unseen).
#[allow(clippy::too_many_arguments)]
fn adaptive(
    f: &dyn Fn(f64, f64) -> f64,
    m0: f64,
    m1: f64,
    p0: f64,
    p1: f64,
    coarse: f64,
    tol: f64,
    depth: u32,
    min_depth: u32,
) -> f64 {
    let (mm, pm) = (0.5 * (m0 + m1), 0.5 * (p0 + p1));
    let parts = [
        (m0, mm, p0, pm),
        (mm, m1, p0, pm),
        (m0, mm, pm, p1),
        (mm, m1, pm, p1),
    ];
    let q: Vec<f64> = parts
        .iter()
        .map(|&(a, b, c, d)| cell(f, a, b, c, d))
        .collect();
    let fine: f64 = q.iter().sum();
    if depth == 0 || (min_depth == 0 && (fine - coarse).abs() <= tol) {
        return fine;
    }
    parts
        .iter()
        .zip(&q)
        .map(|(&(a, b, c, d), &qi)| {
            adaptive(
                f,
                a,
                b,
                c,
                d,
                qi,
                0.5 * tol,
                depth - 1,
                min_depth.saturating_sub(1),
            )
        })
        .sum()
}

/// The bins' probabilities under `pdf` (row-major in mu, then phi).
fn expected(pdf: &dyn Fn(&Local) -> f64, samples: usize, min_depth: u32) -> Vec<f64> {
    let f = |mu: f64, phi: f64| pdf(&direction(mu, phi));
    let (dm, dp) = (1.0 / MU_BINS as f64, TAU / PHI_BINS as f64);
    let mut out = Vec::with_capacity(MU_BINS * PHI_BINS);
    for i in 0..MU_BINS {
        for j in 0..PHI_BINS {
            let (m0, p0) = (i as f64 * dm, j as f64 * dp);
            let coarse = cell(&f, m0, m0 + dm, p0, p0 + dp);
            // the expected count is needed to well within its Poisson deviation
            let n = samples as f64;
            let tol = 0.05 * (coarse.max(5.0 / n) / n).sqrt();
            out.push(adaptive(
                &f,
                m0,
                m0 + dm,
                p0,
                p0 + dp,
                coarse,
                tol,
                7,
                min_depth,
            ));
        }
    }
    out
}

struct ChiSquare {
    p_value: f64,
    statistic: f64,
    dof: usize,
    integral: f64,
    rejected: usize,
}

/// Chi-square test of `samples` draws of the case against its pdf.
fn chi_square(case: &Case, samples: usize, seed: u64) -> ChiSquare {
    let p = params(&case.text, case.id);
    let sampler = Sampler::new(case.id, &p);
    let albedos = p.albedos;
    // the directions do not depend on the model (it only gives the weight): a cheap one
    let cheap = Lambert;
    let mut rng = Rng::new(seed);
    // lobes narrower than a bin's Gauss nodes (exponent 1e4, ward's alpha 0.01)
    let sharp = case.text.contains("exponent = 10000") || case.text.contains("alpha_x = 0.01");
    chi_square_of(
        &mut || {
            let u = [rng.uniform(), rng.uniform()];
            sampler
                .sample(&cheap, &albedos, case.height, &case.v, u)
                .map(|s| (s.l, s.pdf))
        },
        &|l| sampler.pdf(&albedos, &case.v, l),
        samples,
        sharp,
        &case.name,
    )
}

/// Chi-square test of `samples` directions from `draw` (with their densities; `None`: a
/// rejected draw) against the density `pdf`.
fn chi_square_of(
    draw: &mut dyn FnMut() -> Option<(Local, f64)>,
    pdf: &dyn Fn(&Local) -> f64,
    samples: usize,
    sharp: bool,
    name: &str,
) -> ChiSquare {
    let mut observed = vec![0usize; MU_BINS * PHI_BINS];
    let mut rejected = 0usize;
    for _ in 0..samples {
        match draw() {
            Some((l, density)) => {
                assert!(l.n > 0.0 && density > 0.0 && density.is_finite(), "{name}");
                let i = ((l.n * MU_BINS as f64) as usize).min(MU_BINS - 1);
                let phi = l.b.atan2(l.t).rem_euclid(TAU);
                let j = ((phi / TAU * PHI_BINS as f64) as usize).min(PHI_BINS - 1);
                observed[i * PHI_BINS + j] += 1;
            }
            None => rejected += 1,
        }
    }
    let probs = expected(pdf, samples, if sharp { 2 } else { 0 });
    let integral: f64 = probs.iter().sum();
    let n = samples as f64;
    // the draws that returned None are one more bin, expected 1 - integral
    let mut bins: Vec<(f64, usize)> = probs.iter().map(|&q| q * n).zip(observed).collect();
    bins.push(((1.0 - integral).max(0.0) * n, rejected));
    let (mut pooled_e, mut pooled_o) = (0.0, 0usize);
    let (mut stat, mut dof) = (0.0, 0usize);
    for &(e, o) in &bins {
        if e < 5.0 {
            pooled_e += e;
            pooled_o += o;
        } else {
            stat += (o as f64 - e).powi(2) / e;
            dof += 1;
        }
    }
    if pooled_e >= 5.0 {
        stat += (pooled_o as f64 - pooled_e).powi(2) / pooled_e;
        dof += 1;
    } else if pooled_o > 5 + 5 * pooled_e.ceil() as usize {
        // draws where the density says there are (almost) none
        stat = f64::INFINITY;
    }
    let dof = dof.saturating_sub(1).max(1);
    ChiSquare {
        p_value: gamma_q(0.5 * dof as f64, 0.5 * stat),
        statistic: stat,
        dof,
        integral,
        rejected,
    }
}

/// Rungs whose lobe reflects a drawn half vector (ward, gltf): its reflections below the horizon
/// are rejected, so their density integrates to less than 1.
fn reflects_half_vectors(id: ModelId) -> bool {
    use fibrefit::model::rungs::LobeSampling;
    matches!(
        id.rung().sampling.lobe,
        LobeSampling::Ward | LobeSampling::Ggx
    )
}

#[test]
fn sampled_directions_follow_the_pdf_chi_square() {
    let all = cases();
    let alpha = 0.01 / all.len() as f64;
    let samples = 200_000;
    let mut failures = Vec::new();
    let t = std::time::Instant::now();
    for (k, case) in all.iter().enumerate() {
        let r = chi_square(case, samples, 1000 + k as u64);
        eprintln!(
            "{:<48} chi2 {:>9.1} dof {:>5} p {:.3e}  int {:.6} none {}",
            case.name, r.statistic, r.dof, r.p_value, r.integral, r.rejected
        );
        if !(r.p_value >= alpha) {
            failures.push(format!("{}: p = {:.3e}", case.name, r.p_value));
        }
        // the pdf integrates to at most 1, and to 1 where nothing falls below the horizon
        assert!(r.integral <= 1.0 + 2e-3, "{}: {}", case.name, r.integral);
        if !reflects_half_vectors(case.id) {
            assert!(
                (r.integral - 1.0).abs() < 2e-3,
                "{}: {}",
                case.name,
                r.integral
            );
            assert_eq!(r.rejected, 0, "{}", case.name);
        }
    }
    eprintln!(
        "{} chi-square tests in {:.1} s",
        all.len(),
        t.elapsed().as_secs_f64()
    );
    assert!(failures.is_empty(), "rejected at {alpha:.1e}: {failures:?}");
}

#[test]
fn a_wrong_density_is_rejected() {
    // the test has power: directions from one exponent against the pdf of another
    let case = Case {
        name: "mismatch".into(),
        id: ModelId::MaxNormal,
        text: base_text(ModelId::MaxNormal).into(),
        v: view(45.0, ALONG),
        height: None,
    };
    let p = params(&case.text, case.id);
    let wrong = params(&case.text.replace("200", "120"), case.id);
    let (good, bad) = (Sampler::new(case.id, &p), Sampler::new(case.id, &wrong));
    let mut rng = Rng::new(5);
    let mut observed = vec![0usize; MU_BINS * PHI_BINS];
    let n = 100_000;
    for _ in 0..n {
        let u = [rng.uniform(), rng.uniform()];
        let s = bad.sample(&Lambert, &p.albedos, None, &case.v, u).unwrap();
        let i = ((s.l.n * MU_BINS as f64) as usize).min(MU_BINS - 1);
        let phi = s.l.b.atan2(s.l.t).rem_euclid(TAU);
        observed[i * PHI_BINS + ((phi / TAU * PHI_BINS as f64) as usize).min(PHI_BINS - 1)] += 1;
    }
    let probs = expected(&|l| good.pdf(&p.albedos, &case.v, l), n, 0);
    let stat: f64 = probs
        .iter()
        .zip(&observed)
        .filter(|(q, _)| **q * n as f64 >= 5.0)
        .map(|(q, &o)| (o as f64 - q * n as f64).powi(2) / (q * n as f64))
        .sum();
    let dof = probs.iter().filter(|q| **q * n as f64 >= 5.0).count() - 1;
    let p_value = gamma_q(0.5 * dof as f64, 0.5 * stat);
    assert!(p_value < 1e-6, "p {p_value}");
}

// ---- weights, pdf properties, determinism ----

fn basis_of(m: &dyn ShadingModel, pair: &DirectionPair, height: Option<f64>) -> model::Basis {
    match height {
        Some(h) => m.basis_at_height(pair, h).unwrap_or_else(|| m.basis(pair)),
        None => m.basis(pair),
    }
}

fn flip(w: &Local) -> Local {
    Local {
        t: -w.t,
        b: -w.b,
        n: w.n,
    }
}

#[test]
fn weights_are_f_cos_over_pdf_and_the_pdf_is_sound() {
    for case in cases() {
        let p = params(&case.text, case.id);
        let m = model::build(case.id, &p).unwrap();
        let sampler = Sampler::new(case.id, &p);
        let a = p.albedos;
        let mut rng = Rng::new(77);
        // the reference integrates to 1e-9 (and adaptively over a spread: seconds a value), so
        // few of its samples are evaluated, none with a spread (its sampler is poulin-fournier's)
        let count = match case.id {
            ModelId::Reference if p.azimuth_spread_deg > 0.0 => 0,
            ModelId::Reference => 3,
            _ => 150,
        };
        for _ in 0..count {
            let u = [rng.uniform(), rng.uniform()];
            let Some(s) = sampler.sample(m.as_ref(), &a, case.height, &case.v, u) else {
                assert!(
                    reflects_half_vectors(case.id),
                    "{}: None above the horizon",
                    case.name
                );
                continue;
            };
            // determinism
            let again = sampler
                .sample(m.as_ref(), &a, case.height, &case.v, u)
                .unwrap();
            assert_eq!(
                (s.l, s.pdf.to_bits(), s.weight.map(f64::to_bits)),
                (again.l, again.pdf.to_bits(), again.weight.map(f64::to_bits)),
                "{}",
                case.name
            );
            let norm = s.l.t * s.l.t + s.l.b * s.l.b + s.l.n * s.l.n;
            assert!((norm - 1.0).abs() < 1e-13 && s.l.n > 0.0, "{}", case.name);
            let pdf = sampler.pdf(&a, &case.v, &s.l);
            assert!((pdf - s.pdf).abs() <= 1e-12 * pdf, "{}", case.name);
            let b = basis_of(
                m.as_ref(),
                &DirectionPair { l: s.l, v: case.v },
                case.height,
            );
            for c in 0..3 {
                let want = b.brdf(&a, c) * s.l.n / pdf;
                assert!(
                    (s.weight[c] - want).abs() <= 1e-12 * want.abs().max(1e-300),
                    "{} channel {c}: {} vs {want}",
                    case.name,
                    s.weight[c]
                );
                assert!(s.weight[c].is_finite() && s.weight[c] >= 0.0);
            }
        }
        // the pdf anywhere: finite, non-negative, 0 below the horizon, T -> -T invariant
        for _ in 0..300 {
            let z = 2.0 * rng.uniform() - 1.0;
            let r = (1.0 - z * z).sqrt();
            let ph = TAU * rng.uniform();
            let l = Local {
                t: r * ph.cos(),
                b: r * ph.sin(),
                n: z,
            };
            let q = sampler.pdf(&a, &case.v, &l);
            assert!(q.is_finite() && q >= 0.0, "{}: {q}", case.name);
            if z <= 0.0 {
                assert_eq!(q, 0.0, "{}", case.name);
            }
            let qf = sampler.pdf(&a, &flip(&case.v), &flip(&l));
            assert!((qf - q).abs() <= 1e-12 * q, "{}: {q} vs {qf}", case.name);
        }
        // views at or below the horizon: None and 0
        for v in [
            Local {
                n: 0.0,
                ..view(90.0, 30.0)
            },
            view(120.0, 10.0),
        ] {
            assert!(sampler
                .sample(m.as_ref(), &a, case.height, &v, [0.3, 0.6])
                .is_none());
            assert_eq!(sampler.pdf(&a, &v, &view(10.0, 0.0)), 0.0);
        }
    }
}

#[test]
fn samples_at_the_ends_of_the_unit_square_are_sound() {
    let ends = [
        0.0,
        1e-300,
        1e-12,
        0.5,
        1.0 - 1e-12,
        1.0 - f64::EPSILON / 2.0,
    ];
    for case in cases().into_iter().filter(|c| c.id != ModelId::Reference) {
        let p = params(&case.text, case.id);
        let m = model::build(case.id, &p).unwrap();
        let sampler = Sampler::new(case.id, &p);
        for u0 in ends {
            for u1 in ends {
                if let Some(s) = sampler.sample(m.as_ref(), &p.albedos, None, &case.v, [u0, u1]) {
                    assert!(
                        s.l.n > 0.0 && s.pdf.is_finite() && s.pdf > 0.0,
                        "{}",
                        case.name
                    );
                    assert!(
                        s.weight.iter().all(|w| w.is_finite() && *w >= 0.0),
                        "{} u {u0:e} {u1:e}: {s:?}",
                        case.name
                    );
                }
            }
        }
    }
}

/// Mean and variance of the directional albedo's one-sample estimate (channel 0) at v.
fn albedo_estimate(
    m: &dyn ShadingModel,
    a: &Albedos,
    v: &Local,
    n: usize,
    mut draw: impl FnMut([f64; 2]) -> Option<(Local, f64)>,
) -> (f64, f64) {
    let mut rng = Rng::new(99);
    let (mut s, mut s2) = (0.0, 0.0);
    for _ in 0..n {
        let w = draw([rng.uniform(), rng.uniform()])
            .map(|(l, pdf)| m.basis(&DirectionPair { l, v: *v }).brdf(a, 0) * l.n / pdf)
            .unwrap_or(0.0);
        s += w;
        s2 += w * w;
    }
    let mean = s / n as f64;
    (mean, s2 / n as f64 - mean * mean)
}

fn cosine(u: [f64; 2]) -> Option<(Local, f64)> {
    let r = u[0].sqrt();
    let (s, c) = (TAU * u[1]).sin_cos();
    let l = Local {
        t: r * c,
        b: r * s,
        n: (1.0 - u[0]).sqrt(),
    };
    (l.n > 0.0).then_some((l, l.n / PI))
}

#[test]
fn diffuse_only_fibre_rungs_are_sampled_with_zero_variance() {
    // hast-diffuse: tube and cosine in the ratio of their albedos give weight kd (1/2 + 1/pi);
    // max-normal without a lobe: the tube alone gives kd pi / 2
    for (id, text, want) in [
        (ModelId::HastDiffuse, "kd = 0.6\n", 0.6 * (0.5 + 1.0 / PI)),
        (ModelId::MaxNormal, "kd = 0.6\nks = 0\n", 0.6 * PI / 2.0),
    ] {
        let p = params(text, id);
        let m = model::build(id, &p).unwrap();
        let sampler = Sampler::new(id, &p);
        let mut rng = Rng::new(3);
        for _ in 0..2000 {
            let v = view(85.0 * rng.uniform(), 360.0 * rng.uniform());
            let u = [rng.uniform(), rng.uniform()];
            let s = sampler.sample(m.as_ref(), &p.albedos, None, &v, u).unwrap();
            assert!((s.weight[0] - want).abs() < 1e-12, "{id}: {}", s.weight[0]);
        }
    }
}

#[test]
fn the_lobe_lowers_the_variance_tenfold_at_exponent_1000() {
    for id in [ModelId::MaxNormal, ModelId::PoulinFournier] {
        let text = "kd = 0.3\nks = 0.6\nexponent = 1000\nspacing = 2.6\n";
        let p = params(text, id);
        let m = model::build(id, &p).unwrap();
        let sampler = Sampler::new(id, &p);
        for v in [view(30.0, ALONG), view(60.0, 35.0)] {
            let n = 20_000;
            let (mean_s, var_s) = albedo_estimate(m.as_ref(), &p.albedos, &v, n, |u| {
                sampler
                    .sample(&Lambert, &p.albedos, None, &v, u)
                    .map(|s| (s.l, s.pdf))
            });
            let (mean_c, var_c) = albedo_estimate(m.as_ref(), &p.albedos, &v, n, cosine);
            // the same albedo, within the cosine estimate's error
            let err = 4.0 * (var_c / n as f64).sqrt() + 4.0 * (var_s / n as f64).sqrt();
            assert!((mean_s - mean_c).abs() < err, "{id}: {mean_s} vs {mean_c}");
            assert!(
                var_c > 10.0 * var_s,
                "{id}: variance {var_s} vs cosine {var_c}"
            );
        }
    }
}

/// `sample_many` (the rung evaluated at a batch of draws at once, in lanes) gives every draw
/// what `sample` gives it alone, bit for bit: every rung but the reference, the speed table's
/// variants, draws at random views with and without a height each (varying-topology draws at
/// its texels' heights, the others ignore them), albedos varying per draw.
/// `n` random views (rows of unit vectors) up to `max_deg` from the normal, every azimuth.
fn view_rows(rng: &mut Rng, n: usize, max_deg: f64) -> Vec<[f64; 3]> {
    (0..n)
        .map(|_| {
            let d = view(max_deg * rng.uniform(), 360.0 * rng.uniform());
            [d.t, d.b, d.n]
        })
        .collect()
}

/// A sample's direction, density and weights as bits, to compare draws exactly.
fn sample_bits(s: &fibrefit::model::sampling::Sample) -> [u64; 7] {
    [
        s.l.t,
        s.l.b,
        s.l.n,
        s.pdf,
        s.weight[0],
        s.weight[1],
        s.weight[2],
    ]
    .map(f64::to_bits)
}

#[test]
fn a_batch_of_draws_is_each_draw_alone_bit_for_bit() {
    use fibrefit::bench::sampling::SPEED_VARIANTS;
    use fibrefit::model::sampling::Draw;
    let mut configs: Vec<(ModelId, String)> = ModelId::ALL
        .iter()
        .filter(|&&id| id != ModelId::Reference)
        .map(|&id| (id, base_text(id)))
        .collect();
    for &(id, _, extra) in &SPEED_VARIANTS {
        configs.push((id, base_text(id) + extra));
    }
    let mut rng = Rng::new(5);
    for (id, text) in configs {
        let p = params(&text, id);
        let m = model::build(id, &p).unwrap();
        let sampler = Sampler::new(id, &p);
        let top = fibrefit::model::topology::max_height(p.spacing);
        let draws: Vec<Draw> = (0..203)
            .map(|k| {
                let mut albedos = p.albedos;
                albedos.diffuse[0] *= 0.5 + rng.uniform();
                albedos.specular[0] *= 0.5 + rng.uniform();
                let h = rng.uniform();
                Draw {
                    albedos,
                    height: (k % 3 != 0).then_some(top * h),
                    // a few views at and below the horizon too
                    v: view(95.0 * rng.uniform(), 360.0 * rng.uniform()),
                    u: [rng.uniform(), rng.uniform()],
                }
            })
            .collect();
        let mut batch = vec![None; draws.len()];
        sampler.sample_many(m.as_ref(), &draws, &mut batch);
        let mut drawn = 0;
        for (d, b) in draws.iter().zip(&batch) {
            let alone = sampler.sample(m.as_ref(), &d.albedos, d.height, &d.v, d.u);
            match (alone, b) {
                (None, None) => {}
                (Some(a), Some(b)) => {
                    drawn += 1;
                    assert_eq!(sample_bits(&a), sample_bits(b), "{id} {text:?}: {d:?}");
                }
                (a, b) => panic!("{id} {text:?}: {d:?}: alone {a:?}, in the batch {b:?}"),
            }
        }
        assert!(drawn > 150, "{id}: {drawn} of 203 drawn");
    }
}

/// `Material::sample_many` (blocks of rows, each block's rung evaluated at once) gives every
/// row what `Material::sample` gives it alone, bit for bit: the silk's truth (its topology map:
/// a height per texel), the loose capture's truth with its tangent map (a fibre azimuth per
/// texel), a corrected poulin-fournier with a spread (the correction's factor in the weight).
#[test]
fn a_materials_rows_sampled_at_once_are_each_row_alone_bit_for_bit() {
    use fibrefit::api::material::Material;
    use fibrefit::model::Vec3;
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    let dir = tempfile::tempdir().unwrap();
    let silk = Material::load(&root.join("data_synthetic/silk/truth.json"), None)
        .unwrap()
        .0;
    let loose = Material::load(&root.join("data_synthetic/loose/truth.json"), None)
        .unwrap()
        .0
        .with_capture(&root.join("data_synthetic/loose/capture.toml"))
        .unwrap();
    let c = 1.2f64.ln();
    let corrected = dir.path().join("pf.toml");
    std::fs::write(
        &corrected,
        format!(
            "model = \"poulin-fournier\"\n{}azimuth_spread_deg = 40\n[correction]\ndegree = 1\n\
             coefficients = [[{c}, {c}, {c}], [0.1, -0.1, 0.05], [0.2, 0.1, 0.0]]\n\
             cos_range = [0.0, 1.0]\nlog_range = [[-1.0, 1.0], [-1.0, 1.0], [-1.0, 1.0]]\n",
            base_text(ModelId::PoulinFournier)
        ),
    )
    .unwrap();
    let corrected = Material::load(&corrected, None).unwrap().0;
    let mut rng = Rng::new(11);
    for (name, m, with_uv) in [
        ("silk", &silk, true),
        ("loose", &loose, true),
        ("corrected", &corrected, false),
    ] {
        let n = 700; // more than two blocks
        let v = view_rows(&mut rng, n, 88.0);
        let u: Vec<[f64; 2]> = (0..n).map(|_| [rng.uniform(), rng.uniform()]).collect();
        let uv: Vec<[f64; 2]> = (0..n).map(|_| [rng.uniform(), rng.uniform()]).collect();
        let uv = with_uv.then_some(&uv[..]);
        let many = m.sample_many(&v, &u, uv, None).unwrap();
        let mut drawn = 0;
        for i in 0..n {
            // as `sample_many` takes a row: divided by its length
            let d = Vec3::new(v[i][0], v[i][1], v[i][2]);
            let alone = m.sample(&(d / d.norm()), u[i], uv.map(|c| c[i]));
            drawn += (alone.pdf > 0.0) as usize;
            let bits = |s: &fibrefit::api::material::Sampled| {
                [s.l, s.weight, [s.pdf; 3]]
                    .concat()
                    .iter()
                    .map(|x| x.to_bits())
                    .collect::<Vec<_>>()
            };
            assert_eq!(bits(&alone), bits(&many[i]), "{name}, row {i}");
        }
        assert!(drawn > n / 2, "{name}: {drawn} drawn");
    }
}

/// A material with lobe maps (a renderer's own material fitted per texel: its roughness and
/// anisotropy at each texel): `Material.sample`'s weight is `eval` cos / pdf at every texel,
/// the texel's own lobe in both, one row at a time and in blocks.
#[test]
fn a_texels_own_lobe_is_in_the_sampled_weight() {
    use fibrefit::api::material::Material;
    use fibrefit::model::Vec3;
    let dir = tempfile::tempdir().unwrap();
    let maps = dir.path().join("maps");
    std::fs::create_dir(&maps).unwrap();
    let n = 8;
    let map = |name: &str, f: &dyn Fn(usize, usize) -> f64| {
        let data: Vec<f32> = (0..n * n).map(|i| f(i % n, i / n) as f32).collect();
        fibrefit::export::images::write_exr(&maps.join(name), n, n, 1, &data).unwrap();
    };
    map("roughness.exr", &|x, _| {
        0.08 + 0.8 * x as f64 / (n - 1) as f64
    });
    map("anisotropic.exr", &|_, y| 0.9 * y as f64 / (n - 1) as f64);
    let params = dir.path().join("principled.toml");
    std::fs::write(
        &params,
        "model = \"principled\"\nkd = 0.4\nroughness = 0.4\nanisotropic = 0.3\n",
    )
    .unwrap();
    let m = Material::load(&params, Some(&maps)).unwrap().0;
    let mut rng = Rng::new(3);
    let rows = 300;
    let v = view_rows(&mut rng, rows, 85.0);
    let u: Vec<[f64; 2]> = (0..rows).map(|_| [rng.uniform(), rng.uniform()]).collect();
    let uv: Vec<[f64; 2]> = (0..rows).map(|_| [rng.uniform(), rng.uniform()]).collect();
    let many = m.sample_many(&v, &u, Some(&uv), None).unwrap();
    let mut checked = 0;
    for i in 0..rows {
        let d = Vec3::new(v[i][0], v[i][1], v[i][2]);
        let d = d / d.norm();
        let alone = m.sample(&d, u[i], Some(uv[i]));
        assert_eq!(alone.weight, many[i].weight, "row {i}");
        if alone.pdf > 0.0 {
            let l = Vec3::new(alone.l[0], alone.l[1], alone.l[2]);
            let f = m.eval(&l, &d, Some(uv[i]));
            for c in 0..3 {
                let want = f[c] * l.z / alone.pdf;
                assert!(
                    (alone.weight[c] - want).abs() <= 1e-9 * want.abs().max(1e-12),
                    "row {i} at uv {:?}: weight {} against eval cos / pdf {want}",
                    uv[i],
                    alone.weight[c]
                );
            }
            checked += 1;
        }
    }
    assert!(checked > rows / 2, "{checked}");
}

// ---- one instance of the material per draw (issue 41 item 2) ----

/// Materials that mix several instances: spreads (partial, isotropic, with the fuzz layer and
/// the Fresnel factor), varying-topology's height histogram, and both at once.
fn instance_cases() -> Vec<(String, ModelId, String)> {
    let with = |id: ModelId, extra: &str| (format!("{id} {extra:?}"), id, base_text(id) + extra);
    vec![
        with(ModelId::MaxNormal, "azimuth_spread_deg = 180\n"),
        with(ModelId::HastDiffuse, "azimuth_spread_deg = 40\n"),
        with(ModelId::PoulinFournier, "azimuth_spread_deg = 20\n"),
        with(
            ModelId::PoulinFournier,
            "azimuth_spread_deg = 180\nfuzz = 0.5\nfuzz_depth = 0.3\nfresnel_ior = 1.5\nfibre_azimuth_deg = 30\n",
        ),
        with(ModelId::VaryingTopology, ""),
        with(
            ModelId::VaryingTopology,
            "azimuth_spread_deg = 30\nfuzz = 0.5\nfuzz_depth = 0.3\nhistogram_bins = 6\n",
        ),
    ]
}

/// Views and lights over the hemisphere, grazing included.
fn instance_pairs() -> Vec<DirectionPair> {
    let mut pairs = Vec::new();
    for tv in [0.0, 35.0, 70.0, 88.0] {
        for pv in [0.0, 50.0, 130.0] {
            for tl in [10.0, 45.0, 80.0] {
                for pl in [20.0, 110.0, 200.0, 290.0] {
                    pairs.push(DirectionPair {
                        l: view(tl, pl),
                        v: view(tv, pv),
                    });
                }
            }
        }
    }
    pairs
}

#[test]
fn the_instances_weighted_by_their_probabilities_are_the_exact_model() {
    for (name, id, text) in instance_cases() {
        let p = params(&text, id);
        let exact = model::build(id, &p).unwrap();
        let aligned = model::build_instance(id, &p).unwrap();
        let sampler = Sampler::new(id, &p);
        let all = sampler.instances_with_probabilities();
        assert_eq!(all.len(), sampler.instances(), "{name}");
        assert!(sampler.instances() > 1, "{name}");
        let total: f64 = all.iter().map(|a| a.1).sum();
        assert!((total - 1.0).abs() < 1e-12, "{name}: {total}");
        for pair in instance_pairs() {
            let want = exact.basis(&pair);
            let mut got = model::Basis::default();
            for (inst, w) in &all {
                got = got + inst.basis(aligned.as_ref(), &pair).scaled(*w);
            }
            for (g, w, part) in [
                (got.diffuse, want.diffuse, "diffuse"),
                (got.specular, want.specular, "specular"),
                (got.substrate, want.substrate, "substrate"),
                (got.fuzz, want.fuzz, "fuzz"),
            ] {
                assert!(
                    (g - w).abs() <= 1e-12 * w.abs().max(1e-6),
                    "{name} {part} at {pair:?}: instances {g}, exact {w}"
                );
            }
        }
    }
}

#[test]
fn the_reference_is_one_instance_itself() {
    // it integrates its spread and heights adaptively: no node of its sampler is an instance
    let text = base_text(ModelId::Reference) + "azimuth_spread_deg = 30\n";
    let sampler = Sampler::new(ModelId::Reference, &params(&text, ModelId::Reference));
    assert_eq!(sampler.instances(), 1);
    let inst = sampler.instance(0.7, None);
    assert_eq!((inst.cos, inst.sin, inst.height), (1.0, 0.0, None));
}

#[test]
fn instances_are_picked_with_their_probabilities() {
    for (name, id, text) in instance_cases() {
        let p = params(&text, id);
        let sampler = Sampler::new(id, &p);
        let all = sampler.instances_with_probabilities();
        // evenly spaced uniforms: each instance's share within one step of its probability
        let n = 200_000;
        let mut counts = vec![0usize; all.len()];
        for k in 0..n {
            let inst = sampler.instance((k as f64 + 0.5) / n as f64, None);
            let i = all
                .iter()
                .position(|a| a.0 == inst)
                .expect("a listed instance");
            counts[i] += 1;
        }
        for ((inst, w), c) in all.iter().zip(&counts) {
            let share = *c as f64 / n as f64;
            assert!(
                (share - w).abs() <= 2.0 / n as f64,
                "{name}: {inst:?} drawn {share}, probability {w}"
            );
        }
        // a texel's height is kept; only the direction is drawn
        if id.has_topology() {
            let inst = sampler.instance(0.7, Some(0.42));
            assert_eq!(inst.height, Some(0.42), "{name}");
        }
    }
}

#[test]
fn an_instances_weight_is_its_f_cos_over_its_pdf_and_a_batch_is_each_draw_alone() {
    use fibrefit::model::sampling::Draw;
    for (name, id, text) in instance_cases() {
        let p = params(&text, id);
        let aligned = model::build_instance(id, &p).unwrap();
        let sampler = Sampler::new(id, &p);
        let mut rng = Rng::new(41);
        let (mut draws, mut insts, mut alone) = (Vec::new(), Vec::new(), Vec::new());
        for _ in 0..400 {
            let v = view(88.0 * rng.uniform(), 360.0 * rng.uniform());
            let u = [rng.uniform(), rng.uniform()];
            let inst = sampler.instance(rng.uniform(), None);
            let s = sampler.sample_instance(aligned.as_ref(), &p.albedos, &inst, &v, u);
            if let Some(s) = s {
                let pdf = sampler.pdf_instance(&p.albedos, &inst, &v, &s.l);
                assert!(
                    (pdf - s.pdf).abs() <= 1e-10 * s.pdf,
                    "{name}: pdf {pdf} against the draw's {}",
                    s.pdf
                );
                let f = inst.basis(aligned.as_ref(), &DirectionPair { l: s.l, v });
                for c in 0..3 {
                    let want = f.brdf(&p.albedos, c) * s.l.n / s.pdf;
                    assert!(
                        (s.weight[c] - want).abs() <= 1e-12 * want.abs().max(1e-300),
                        "{name}: weight {} against f cos / pdf {want}",
                        s.weight[c]
                    );
                }
            }
            draws.push(Draw {
                albedos: p.albedos,
                height: None,
                v,
                u,
            });
            insts.push(inst);
            alone.push(s);
        }
        let mut many = vec![None; draws.len()];
        sampler.sample_many_instances(aligned.as_ref(), &draws, &insts, &mut many);
        let bits = |s: &Option<fibrefit::model::sampling::Sample>| s.as_ref().map(sample_bits);
        for (i, (a, m)) in alone.iter().zip(&many).enumerate() {
            assert_eq!(bits(a), bits(m), "{name}, draw {i}");
        }
    }
}

#[test]
fn an_instances_directions_follow_its_pdf_chi_square() {
    // one instance held (a turned node, a drawn height), and an instance drawn per sample
    // against the probability-weighted sum of the instances' densities
    let cases = instance_cases();
    let alpha = 0.01 / (2 * cases.len()) as f64;
    let samples = 100_000;
    for (k, (name, id, text)) in cases.iter().enumerate() {
        let p = params(text, *id);
        let sampler = Sampler::new(*id, &p);
        let a = p.albedos;
        let v = view(60.0, 35.0);
        let inst = sampler.instance(0.37, None);
        let mut rng = Rng::new(500 + k as u64);
        let held = chi_square_of(
            &mut || {
                let u = [rng.uniform(), rng.uniform()];
                sampler
                    .sample_instance(&Lambert, &a, &inst, &v, u)
                    .map(|s| (s.l, s.pdf))
            },
            &|l| sampler.pdf_instance(&a, &inst, &v, l),
            samples,
            false,
            name,
        );
        let all = sampler.instances_with_probabilities();
        let mut rng = Rng::new(600 + k as u64);
        let drawn = chi_square_of(
            &mut || {
                let u = [rng.uniform(), rng.uniform()];
                let inst = sampler.instance(rng.uniform(), None);
                sampler
                    .sample_instance(&Lambert, &a, &inst, &v, u)
                    .map(|s| (s.l, s.pdf))
            },
            &|l| {
                all.iter()
                    .map(|(i, w)| w * sampler.pdf_instance(&a, i, &v, l))
                    .sum()
            },
            samples,
            false,
            name,
        );
        for (what, r) in [("held", held), ("drawn", drawn)] {
            eprintln!(
                "{name} {what}: chi2 {:.1} dof {} p {:.3e} int {:.6}",
                r.statistic, r.dof, r.p_value, r.integral
            );
            assert!(r.p_value >= alpha, "{name} {what}: p = {:.3e}", r.p_value);
            assert!(
                (r.integral - 1.0).abs() < 2e-3,
                "{name} {what}: {}",
                r.integral
            );
            assert_eq!(r.rejected, 0, "{name} {what}");
        }
    }
}

#[test]
fn one_instance_per_draw_estimates_the_exact_albedo() {
    // both estimators of the directional albedo at exponent 200 agree within 4.5 standard
    // errors; the instance's weight variance is larger, but by a bounded factor
    for (name, id, text) in instance_cases() {
        let p = params(&text, id);
        let exact = model::build(id, &p).unwrap();
        let aligned = model::build_instance(id, &p).unwrap();
        let sampler = Sampler::new(id, &p);
        let n = if id == ModelId::VaryingTopology {
            20_000
        } else {
            100_000
        };
        for v in [view(20.0, 10.0), view(70.0, 80.0)] {
            let mut rng = Rng::new(7);
            let moments = |w: &mut dyn FnMut() -> f64| {
                let (mut s, mut s2) = (0.0, 0.0);
                for _ in 0..n {
                    let x = w();
                    s += x;
                    s2 += x * x;
                }
                let mean = s / n as f64;
                (mean, (s2 / n as f64 - mean * mean).max(0.0))
            };
            let (m_exact, var_exact) = moments(&mut || {
                let u = [rng.uniform(), rng.uniform()];
                sampler
                    .sample(exact.as_ref(), &p.albedos, None, &v, u)
                    .map_or(0.0, |s| s.weight[0])
            });
            let (m_inst, var_inst) = moments(&mut || {
                let u = [rng.uniform(), rng.uniform()];
                let inst = sampler.instance(rng.uniform(), None);
                sampler
                    .sample_instance(aligned.as_ref(), &p.albedos, &inst, &v, u)
                    .map_or(0.0, |s| s.weight[0])
            });
            let se = ((var_exact + var_inst) / n as f64).sqrt();
            assert!(
                (m_exact - m_inst).abs() <= 4.5 * se,
                "{name} at {v:?}: exact {m_exact}, one instance {m_inst} (se {se})"
            );
            assert!(
                var_inst < 20.0 * var_exact + 1e-12,
                "{name}: {var_inst} vs {var_exact}"
            );
        }
    }
}

/// `Material`'s instance API: the mean over instance uniforms of `eval_instance` is `eval`,
/// `sample_instance`'s weight is `eval_instance` cos / `pdf_instance` of the same uniform, and
/// rows sampled at once equal each row alone.
#[test]
fn a_materials_instances_average_to_it_and_weigh_their_samples() {
    use fibrefit::api::material::Material;
    use fibrefit::model::Vec3;
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("felt.toml");
    std::fs::write(
        &file,
        format!(
            "model = \"poulin-fournier\"\n{}azimuth_spread_deg = 180\nfuzz = 0.4\nfuzz_depth = 0.2\n",
            base_text(ModelId::PoulinFournier)
        ),
    )
    .unwrap();
    let m = Material::load(&file, None).unwrap().0;
    assert_eq!(m.instances(), 16);
    let n = m.instances();
    let mut rng = Rng::new(19);
    for _ in 0..50 {
        let (l, v) = (
            view(80.0 * rng.uniform(), 360.0 * rng.uniform()),
            view(80.0 * rng.uniform(), 360.0 * rng.uniform()),
        );
        let (l, v) = (Vec3::new(l.t, l.b, l.n), Vec3::new(v.t, v.b, v.n));
        let want = m.eval(&l, &v, None);
        // the nodes' weights are equal in the isotropic limit: one uniform per node
        let mut mean = [0.0; 3];
        for k in 0..n {
            let f = m.eval_instance(&l, &v, None, Some((k as f64 + 0.5) / n as f64));
            for c in 0..3 {
                mean[c] += f[c] / n as f64;
            }
        }
        for c in 0..3 {
            assert!(
                (mean[c] - want[c]).abs() <= 1e-12 * want[c].abs().max(1e-9),
                "{mean:?} vs {want:?}"
            );
        }
    }
    let rows = 600;
    let v = view_rows(&mut rng, rows, 85.0);
    let u: Vec<[f64; 2]> = (0..rows).map(|_| [rng.uniform(), rng.uniform()]).collect();
    let r: Vec<f64> = (0..rows).map(|_| rng.uniform()).collect();
    let many = m.sample_many(&v, &u, None, Some(&r)).unwrap();
    let mut checked = 0;
    for i in 0..rows {
        // as `sample_many` takes a row: divided by its length
        let d = Vec3::new(v[i][0], v[i][1], v[i][2]);
        let d = d / d.norm();
        let alone = m.sample_instance(&d, u[i], None, Some(r[i]));
        assert_eq!(alone, many[i], "row {i}");
        if alone.pdf > 0.0 {
            let l = Vec3::new(alone.l[0], alone.l[1], alone.l[2]);
            let pdf = m.pdf_instance(&d, &l, None, Some(r[i]));
            assert!(
                (pdf - alone.pdf).abs() <= 1e-10 * pdf,
                "row {i}: {pdf} vs {}",
                alone.pdf
            );
            let f = m.eval_instance(&l, &d, None, Some(r[i]));
            for c in 0..3 {
                let want = f[c] * l.z / alone.pdf;
                assert!(
                    (alone.weight[c] - want).abs() <= 1e-9 * want.abs().max(1e-12),
                    "row {i}"
                );
            }
            checked += 1;
        }
    }
    assert!(checked > rows / 2, "{checked}");
    // a uniform outside [0, 1) is refused, naming the row
    let e = m
        .sample_many(&v[..2], &u[..2], None, Some(&[0.5, 1.0]))
        .unwrap_err();
    assert!(e.to_string().contains("instance row 1"), "{e}");
}
