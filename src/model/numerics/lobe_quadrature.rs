//! The specular lobe's Gauss–Legendre sum, written so the compiler vectorises it.
//!
//! Each node of the lobe quadrature (see `varying_topology.rs`) needs one cosine, one logarithm
//! and one exponential. Through libm those are three opaque calls per node and were about half
//! of a `varying-topology` evaluation. Here they are branch-free polynomials (Cody–Waite range
//! reduction, then Taylor for cos and exp and fdlibm's minimax for log), so a loop over the
//! nodes of an arc becomes straight-line SIMD code. On x86-64 CPUs with AVX-512 or AVX2, and
//! FMA (checked at run time) the loop is compiled for them: eight or four nodes per instruction,
//! fused multiply-adds (AVX-512 over AVX2: about 5 % less time per evaluation here). Elsewhere
//! the same code runs on the baseline instruction set. Measured (`cargo bench --bench forward`,
//! `varying-topology` N = 16): 1070 -> 650 ns per evaluation with AVX2.
//!
//! Accuracy: within 2 ulp of libm for the ranges used here (tested below against std over dense
//! samples); the quadrature stays a smooth function of the parameters, and its floor at high
//! order (N >= 32 against `reference`, `reports/speed_accuracy.md`) rose from ~4e-16 to ~5e-15
//! RMS relative (6e-14 at most), far below the error of any order one would choose.

use super::elementary::{estrin, Fused, MulAdd, Plain, COS_TAYLOR, ROUND_MAGIC};
use super::quadrature::GaussLegendre;

/// ln 2 in two parts (fdlibm): LN2_HI has trailing zero bits, so k * LN2_HI is exact.
const LN2_HI: f64 = 0.6931471803691238;
const LN2_LO: f64 = 1.9082149292705877e-10;

/// cos(u) for |u| < 1e6, absolute error ~1e-16.
#[inline(always)]
fn cos<M: MulAdd>(u: f64) -> f64 {
    // u = n pi + r, |r| <= pi/2; cos u = (-1)^n cos r. pi in three parts (Cody–Waite): the first
    // two have 32 significant bits, so n * part is exact for |n| < 2^20.
    const PI_A: f64 = 3.141_592_653_468_251_2;
    const PI_B: f64 = 1.215_420_101_260_793_2e-10;
    const PI_C: f64 = 4.044_532_497_591_901e-21;
    let t = u * std::f64::consts::FRAC_1_PI + ROUND_MAGIC;
    let n = t - ROUND_MAGIC;
    let r = M::mul_add(-n, PI_C, M::mul_add(-n, PI_B, M::mul_add(-n, PI_A, u)));
    // Taylor series of cos to r^22: truncation < 1.5708^24 / 24! < 1e-19.
    let c = estrin::<M, 12>(r * r, &COS_TAYLOR);
    // odd n flips the sign
    let sign = (t.to_bits() & 1) << 63;
    f64::from_bits(c.to_bits() ^ sign)
}

/// ln(x) for normal positive finite x, within ~1 ulp (fdlibm's e_log.c, branch-free).
#[inline(always)]
fn ln<M: MulAdd>(x: f64) -> f64 {
    const LG: [f64; 7] = [
        0.6666666666666735,
        0.3999999999940942,
        0.2857142874366239,
        0.22222198432149784,
        0.1818357216161805,
        0.15313837699209373,
        0.14798198605116586,
    ];
    let bits = x.to_bits();
    // x = 2^k m with m in [1, 2); move m into [sqrt(1/2), sqrt(2)).
    let mant = (bits & 0x000f_ffff_ffff_ffff) | 0x3ff0_0000_0000_0000;
    let biased = bits >> 52;
    let m1 = f64::from_bits(mant);
    let big = m1 > std::f64::consts::SQRT_2;
    let m = if big { 0.5 * m1 } else { m1 };
    let biased = biased + big as u64;
    // k as a float without an int->float conversion (AVX2 has none for 64-bit lanes)
    let k = f64::from_bits(0x4330_0000_0000_0000 | biased) - (4_503_599_627_370_496.0 + 1023.0);
    let f = m - 1.0;
    let s = f / (2.0 + f);
    let z = s * s;
    let r = z * estrin::<M, 7>(z, &LG);
    let hfsq = 0.5 * f * f;
    M::mul_add(
        k,
        LN2_HI,
        -((hfsq - M::mul_add(s, hfsq + r, k * LN2_LO)) - f),
    )
}

/// exp(x) for x <= 709; 0 below -708 (where it is < 3e-308), within ~1 ulp.
#[inline(always)]
fn exp<M: MulAdd>(x: f64) -> f64 {
    let xc = x.max(-708.0);
    let t = M::mul_add(xc, std::f64::consts::LOG2_E, ROUND_MAGIC);
    let n = t - ROUND_MAGIC;
    let r = M::mul_add(-n, LN2_LO, M::mul_add(-n, LN2_HI, xc));
    // Taylor to r^13 on |r| <= 0.347: truncation < 0.347^14 / 14! < 5e-18.
    const C: [f64; 14] = [
        1.0,
        1.0,
        1.0 / 2.0,
        1.0 / 6.0,
        1.0 / 24.0,
        1.0 / 120.0,
        1.0 / 720.0,
        1.0 / 5_040.0,
        1.0 / 40_320.0,
        1.0 / 362_880.0,
        1.0 / 3_628_800.0,
        1.0 / 39_916_800.0,
        1.0 / 479_001_600.0,
        1.0 / 6_227_020_800.0,
    ];
    let p = estrin::<M, 14>(r, &C);
    // 2^n from the rounded integer in t's low bits (n in [-1022, 1023] here).
    let scale = f64::from_bits(
        (t.to_bits()
            .wrapping_sub(ROUND_MAGIC.to_bits())
            .wrapping_add(1023))
            << 52,
    );
    if x < -708.0 {
        0.0
    } else {
        p * scale
    }
}

/// x^e for e > 0 through this module's [`ln`] and [`exp`] in plain arithmetic (no fused
/// multiply-add, so a scalar call and a lane loop give the same bits): branch-free, so loops
/// over many pairs vectorise (libm's `pow` is an opaque call per value). 0 for x below the
/// smallest normal (where x^e, e >= 1, is itself below it). Relative error within a few ulp
/// times max(1, |e ln x|) (the product's rounding), against libm: tested below.
#[inline(always)]
pub fn pow_positive(x: f64, e: f64) -> f64 {
    let ok = x >= f64::MIN_POSITIVE;
    let p = exp::<Plain>(e * ln::<Plain>(if ok { x } else { 1.0 }));
    if ok {
        p
    } else {
        0.0
    }
}

/// What one light/view pair's specular lobe needs at a node th:
/// cc(th) = (cos(delta) + cos(2 th - sigma)) / 2 and r.v(th) = k2 cc(th) - l.v.
#[derive(Clone, Copy, Debug, Default)]
pub struct LobeShape {
    pub cos_delta: f64,
    pub sigma: f64,
    pub k2: f64,
    pub cos_lv: f64,
    pub exponent: f64,
}

/// Lanes per block of nodes: the rule is padded with zero-weight nodes to a multiple of this, and
/// each block is written as independent lanes so the compiler can use SIMD registers (a plain
/// running sum would be a serial dependency it may not reorder).
const LANES: usize = 8;

/// A Gauss–Legendre rule on [-1, 1] laid out for [`LobeRule::integrals`].
#[derive(Clone, Debug, PartialEq)]
pub struct LobeRule {
    /// Padded to a multiple of [`LANES`] with (node 0, weight 0).
    nodes: Vec<[f64; LANES]>,
    weights: Vec<[f64; LANES]>,
}

impl LobeRule {
    pub fn new(rule: &GaussLegendre) -> Self {
        let (x, w) = rule.nodes_and_weights();
        let blocks = x.len().div_ceil(LANES);
        let mut nodes = vec![[0.0; LANES]; blocks];
        let mut weights = vec![[0.0; LANES]; blocks];
        for i in 0..x.len() {
            nodes[i / LANES][i % LANES] = x[i];
            weights[i / LANES][i % LANES] = w[i];
        }
        Self { nodes, weights }
    }

    /// `out[i]` = the lobe integral over `arcs[i]` = [a, b]: the sum over the nodes (x_i, w_i)
    /// mapped to [a, b] of w_i max(0, r.v)^e cc, times (b - a)/2; each arc on its own. Callers collect the arcs of many pairs and integrate them in one call: with the
    /// vector kernel no longer interleaved with the scalar geometry code, a `varying-topology`
    /// evaluation took ~10 % less time (measured; keeping two or four arcs in flight at once
    /// made no measurable further difference).
    pub fn integrals(&self, arcs: &[LobeArc], out: &mut [f64]) {
        assert_eq!(arcs.len(), out.len());
        #[cfg(target_arch = "x86_64")]
        {
            if std::is_x86_feature_detected!("avx512f")
                && std::is_x86_feature_detected!("avx512dq")
                && std::is_x86_feature_detected!("fma")
            {
                // SAFETY: the CPU has the features the function is compiled for.
                return unsafe { self.integrals_avx512(arcs, out) };
            }
            if std::is_x86_feature_detected!("avx2") && std::is_x86_feature_detected!("fma") {
                // SAFETY: the CPU has the features the function is compiled for.
                return unsafe { self.integrals_avx2_fma(arcs, out) };
            }
        }
        self.integrals_with::<Plain>(arcs, out)
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx512f,avx512dq,avx2,fma")]
    fn integrals_avx512(&self, arcs: &[LobeArc], out: &mut [f64]) {
        self.integrals_with::<Fused>(arcs, out)
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma")]
    fn integrals_avx2_fma(&self, arcs: &[LobeArc], out: &mut [f64]) {
        self.integrals_with::<Fused>(arcs, out)
    }

    #[inline(always)]
    fn integrals_with<M: MulAdd>(&self, arcs: &[LobeArc], out: &mut [f64]) {
        for (arc, o) in arcs.iter().zip(out.iter_mut()) {
            let p = ArcNodes::new(arc);
            let mut acc = [0.0; LANES];
            for (xs, ws) in self.nodes.iter().zip(&self.weights) {
                for j in 0..LANES {
                    acc[j] += p.term::<M>(xs[j], ws[j]);
                }
            }
            *o = p.half * acc.iter().sum::<f64>();
        }
    }
}

/// One arc of a lobe integral with its pair's lobe shape.
#[derive(Clone, Copy, Debug, Default)]
pub struct LobeArc {
    pub a: f64,
    pub b: f64,
    pub shape: LobeShape,
}

/// An arc's node mapping: th = mid + half x.
struct ArcNodes {
    half: f64,
    two_mid_minus_sigma: f64,
    s: LobeShape,
}

impl ArcNodes {
    #[inline(always)]
    fn new(arc: &LobeArc) -> Self {
        Self {
            half: 0.5 * (arc.b - arc.a),
            two_mid_minus_sigma: (arc.a + arc.b) - arc.shape.sigma,
            s: arc.shape,
        }
    }

    /// w max(0, r.v)^e cc at the node x.
    #[inline(always)]
    fn term<M: MulAdd>(&self, x: f64, w: f64) -> f64 {
        let s = &self.s;
        // 2 th - sigma with th = mid + half x
        let u = M::mul_add(2.0 * self.half, x, self.two_mid_minus_sigma);
        let cc = 0.5 * (s.cos_delta + cos::<M>(u));
        let rv = M::mul_add(s.k2, cc, -s.cos_lv);
        let ok = rv >= f64::MIN_POSITIVE;
        let p = exp::<M>(s.exponent * ln::<M>(if ok { rv } else { 1.0 }));
        if ok {
            w * p * cc
        } else {
            0.0
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ulps(a: f64, b: f64) -> f64 {
        ((a - b) / b.abs().max(f64::MIN_POSITIVE)).abs() / f64::EPSILON
    }

    /// Dense deterministic samples of [lo, hi].
    fn grid(lo: f64, hi: f64, n: usize) -> impl Iterator<Item = f64> {
        (0..=n).map(move |i| lo + (hi - lo) * (i as f64 / n as f64))
    }

    #[test]
    fn cos_matches_std_in_absolute_terms() {
        for u in grid(-40.0, 40.0, 400_000) {
            for got in [cos::<Plain>(u), cos::<Fused>(u)] {
                assert!(
                    (got - u.cos()).abs() < 4e-16,
                    "cos({u}) = {got} vs {}",
                    u.cos()
                );
            }
        }
    }

    #[test]
    fn ln_matches_std_within_two_ulp() {
        let xs = grid(1e-3, 1.2, 300_000)
            .chain(grid(0.999, 1.001, 100_000))
            .chain((0..2000).map(|i| 10f64.powf(-300.0 + 0.15 * i as f64)));
        for x in xs {
            if x == 1.0 {
                assert_eq!(ln::<Plain>(x), 0.0);
                continue;
            }
            for got in [ln::<Plain>(x), ln::<Fused>(x)] {
                assert!(ulps(got, x.ln()) <= 2.0, "ln({x}) = {got} vs {}", x.ln());
            }
        }
    }

    #[test]
    fn exp_matches_std_within_two_ulp_and_underflows_to_zero() {
        for x in grid(-707.0, 1.0, 400_000).chain(grid(-1.0, 0.0, 100_000)) {
            for got in [exp::<Plain>(x), exp::<Fused>(x)] {
                assert!(ulps(got, x.exp()) <= 2.0, "exp({x}) = {got} vs {}", x.exp());
            }
        }
        for x in [-708.5, -745.0, -1e4, -1e300, f64::NEG_INFINITY] {
            assert_eq!(exp::<Plain>(x), 0.0);
            assert_eq!(exp::<Fused>(x), 0.0);
        }
    }

    #[test]
    fn pow_matches_libm_within_its_bound() {
        for e in [1.0, 2.5, 60.0, 1000.0, 20000.0] {
            for x in grid(1e-4, 1.0, 200_000).chain([0.5, 0.999_999_9, 1.0]) {
                let (got, want) = (pow_positive(x, e), x.powf(e));
                if want < 1e-300 {
                    assert!(got < 1e-299, "{x}^{e} = {got} vs {want}");
                    continue;
                }
                let bound = 4.0 * (e * x.ln()).abs().max(1.0);
                assert!(ulps(got, want) <= bound, "{x}^{e} = {got} vs {want}");
            }
            assert_eq!(pow_positive(0.0, e), 0.0);
            assert_eq!(pow_positive(1.0, e), 1.0);
        }
    }

    #[test]
    fn dispatched_sum_matches_a_libm_sum() {
        for order in [1, 5, 16, 23] {
            dispatched_sum_matches_at_order(order);
        }
    }

    fn dispatched_sum_matches_at_order(order: usize) {
        let rule = GaussLegendre::new(order);
        let s = LobeShape {
            cos_delta: 0.3f64.cos(),
            sigma: 0.4,
            k2: 1.6,
            cos_lv: 0.1,
            exponent: 60.0,
        };
        let arcs = [(-0.9, 0.1), (0.2, 1.2), (1.25, 1.3)];
        let lobe = LobeRule::new(&rule);
        let jobs: Vec<LobeArc> = arcs
            .iter()
            .map(|&(a, b)| LobeArc { a, b, shape: s })
            .collect();
        let each = |f: &dyn Fn(&mut [f64])| {
            let mut out = vec![0.0; jobs.len()];
            f(&mut out);
            out.iter().sum::<f64>()
        };
        let got = each(&|out| lobe.integrals(&jobs, out));
        // every path, whichever the dispatch takes on this machine
        let plain = each(&|out| lobe.integrals_with::<Plain>(&jobs, out));
        assert!(
            (plain - got).abs() < 1e-14 * got,
            "N {order}: {plain} vs {got}"
        );
        #[cfg(target_arch = "x86_64")]
        if std::is_x86_feature_detected!("avx2") && std::is_x86_feature_detected!("fma") {
            // SAFETY: checked just above.
            let fused = each(&|out| unsafe { lobe.integrals_avx2_fma(&jobs, out) });
            assert!(
                (fused - got).abs() < 1e-14 * got,
                "N {order}: {fused} vs {got}"
            );
        }
        #[cfg(target_arch = "x86_64")]
        if std::is_x86_feature_detected!("avx512f")
            && std::is_x86_feature_detected!("avx512dq")
            && std::is_x86_feature_detected!("fma")
        {
            // SAFETY: checked just above.
            let wide = each(&|out| unsafe { lobe.integrals_avx512(&jobs, out) });
            assert!(
                (wide - got).abs() < 1e-14 * got,
                "N {order}: {wide} vs {got}"
            );
        }
        let want: f64 = arcs
            .iter()
            .map(|&(a, b)| {
                rule.integrate(a, b, |th| {
                    let cc = 0.5 * (s.cos_delta + (2.0 * th - s.sigma).cos());
                    let rv = s.k2 * cc - s.cos_lv;
                    if rv > 0.0 {
                        rv.powf(s.exponent) * cc
                    } else {
                        0.0
                    }
                })
            })
            .sum();
        assert!(want > 0.0);
        assert!(
            (got - want).abs() < 1e-13 * want,
            "N {order}: {got} vs {want}"
        );
    }
}
