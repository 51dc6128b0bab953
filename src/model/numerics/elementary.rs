//! Inline elementary functions for the forward model's hot path.
//!
//! libm's functions are opaque calls with general-purpose argument handling; on the cross-section
//! path (two atan2, a few asin, an acos and the diffuse kernel's sines and cosines per pair) they
//! were a quarter of the instructions of a `varying-topology` evaluation. These versions cover
//! only the argument ranges the model produces, inline into their callers, and are tested below
//! against std to a few ulp, so results do not move beyond rounding.
//!
//! - `atan2` for x >= 0: fdlibm's s_atan.c (four reduction intervals, an 11-term odd
//!   polynomial), arranged to need one division.
//! - `atan`, `acos`: through that `atan2`, with 1 - x^2 formed as (1 - x)(1 + x) so no
//!   accuracy is lost near +-1.
//! - `asin`: a polynomial and one square root, no division (division and square root share one
//!   unit, and a batch takes thousands of asin: that unit was the limit).
//! - `MulAdd` and `estrin`: the polynomial evaluation shared with the lobe kernel.
//! - `sin_cos`: Cody–Waite reduction by pi/2 in three parts and Taylor kernels on [-pi/4, pi/4]
//!   (relative accuracy, also near the zeros).

use std::f64::consts::FRAC_PI_2;

/// Multiply-add: fused where the CPU has FMA, plain otherwise (a software fma would be slow).
pub(crate) trait MulAdd {
    fn mul_add(a: f64, b: f64, c: f64) -> f64;
}

pub(crate) struct Fused;
pub(crate) struct Plain;

impl MulAdd for Fused {
    #[inline(always)]
    fn mul_add(a: f64, b: f64, c: f64) -> f64 {
        a.mul_add(b, c)
    }
}

impl MulAdd for Plain {
    #[inline(always)]
    fn mul_add(a: f64, b: f64, c: f64) -> f64 {
        a * b + c
    }
}

/// Estrin evaluation of sum c[k] x^k for K <= 16 (c in increasing powers): pairs of
/// terms combined with x, then pairs of pairs with x^2, and so on, written out so the lane loop
/// still vectorises. The dependency chain is ~log2(K) multiply-adds deep instead of K for Horner
/// (measured ~3 % less time per evaluation than Horner).
#[inline(always)]
pub(crate) fn estrin<M: MulAdd, const K: usize>(x: f64, c: &[f64; K]) -> f64 {
    let at = |k: usize| if k < K { c[k] } else { 0.0 };
    let x2 = x * x;
    let x4 = x2 * x2;
    let x8 = x4 * x4;
    let p = |k: usize| M::mul_add(at(k + 1), x, at(k));
    let q = |k: usize| M::mul_add(p(k + 2), x2, p(k));
    let lo = M::mul_add(q(4), x4, q(0));
    if K <= 8 {
        return lo;
    }
    let hi = M::mul_add(q(12), x4, q(8));
    M::mul_add(hi, x8, lo)
}

/// 1.5 * 2^52: adding it rounds |x| < 2^51 to the nearest integer, which sits in the low bits.
pub(crate) const ROUND_MAGIC: f64 = 6_755_399_441_055_744.0;

// Per reduction (none, then fdlibm's four): atan of the breakpoint in two parts, and the
// coefficients of t = (a |y| + b x) / (c |y| + d x).
const ATAN_HI: [f64; 5] = [
    0.0,
    4.636_476_090_008_061e-1,
    std::f64::consts::FRAC_PI_4,
    9.827_937_232_473_29e-1,
    FRAC_PI_2,
];
const ATAN_LO: [f64; 5] = [
    0.0,
    2.269_877_745_296_168_7e-17,
    3.061_616_997_868_383e-17,
    1.390_331_103_123_099_8e-17,
    6.123_233_995_736_766e-17,
];
const ABCD: [[f64; 4]; 5] = [
    [1.0, 0.0, 0.0, 1.0],
    [2.0, -1.0, 1.0, 2.0],
    [1.0, -1.0, 1.0, 1.0],
    [1.0, -1.5, 1.5, 1.0],
    [0.0, -1.0, 1.0, 0.0],
];
const AT: [f64; 11] = [
    3.333_333_333_333_293e-1,
    -1.999_999_999_987_648_3e-1,
    1.428_571_427_250_346_6e-1,
    -1.111_111_040_546_235_6e-1,
    9.090_887_133_436_507e-2,
    -7.691_876_205_044_83e-2,
    6.661_073_137_387_531e-2,
    -5.833_570_133_790_573_5e-2,
    4.976_877_994_615_932_4e-2,
    -3.653_157_274_421_691_6e-2,
    1.628_582_011_536_578_2e-2,
];

/// floor(x) without a libm call or a branch (baseline x86-64 has no rounding instruction, and
/// `x as i64` would add Rust's saturation checks), exact for every f64: adding 2^52 to |x| < 2^52
/// rounds it to an integer, then one step down where that rounded up; larger |x| are integers.
/// Branch-free, so lane loops vectorise it.
#[inline(always)]
pub fn floor(x: f64) -> f64 {
    const TWO_52: f64 = 4_503_599_627_370_496.0;
    let r = ((x.abs() + TWO_52) - TWO_52).copysign(x);
    let r = r - (r > x) as u8 as f64;
    if x.abs() < TWO_52 {
        r
    } else {
        x
    }
}

/// atan2(y, x) for x >= 0 (not both zero): in [-pi/2, pi/2], within ~2 ulp.
///
/// fdlibm's s_atan.c applied to y/x, with each of its reductions t = (a ax + b)/(c ax + d)
/// written as (a |y| + b x)/(c |y| + d x): one division in all, and the interval tests
/// compare |y| with multiples of x. Each reduction's numerator subtracts numbers within a
/// factor two of each other, so it is exact (Sterbenz), as in fdlibm.
#[inline]
pub fn atan2_right_half(y: f64, x: f64) -> f64 {
    debug_assert!(x >= 0.0);
    let ay = y.abs();
    // the interval by counting, not by branching: the branches mispredict on varied inputs
    let id = (ay >= 0.4375 * x) as usize
        + (ay >= 0.6875 * x) as usize
        + (ay >= 1.1875 * x) as usize
        + (ay >= 2.4375 * x) as usize;
    let [a, b, c, d] = ABCD[id];
    let t = (a * ay + b * x) / (c * ay + d * x);
    let r = atan_reduced(t, ATAN_HI[id], ATAN_LO[id]);
    r.copysign(y)
}

/// atan2_right_half with the reduction chosen by selects instead of a table index, for lane
/// loops the compiler vectorises (a table lookup per lane would be a gather). Same result.
#[inline(always)]
pub fn atan2_right_half_lanes(y: f64, x: f64) -> f64 {
    let ay = y.abs();
    let mut k = [
        ABCD[0][0], ABCD[0][1], ABCD[0][2], ABCD[0][3], ATAN_HI[0], ATAN_LO[0],
    ];
    for (id, bound) in [0.4375, 0.6875, 1.1875, 2.4375].into_iter().enumerate() {
        let hit = ay >= bound * x;
        let [a, b, c, d] = ABCD[id + 1];
        for (kj, new) in k
            .iter_mut()
            .zip([a, b, c, d, ATAN_HI[id + 1], ATAN_LO[id + 1]])
        {
            *kj = if hit { new } else { *kj };
        }
    }
    let t = (k[0] * ay + k[1] * x) / (k[2] * ay + k[3] * x);
    atan_reduced(t, k[4], k[5]).copysign(y)
}

/// fdlibm's atan after the reduction: atan(t) + (hi + lo), with hi + lo = atan of the breakpoint.
#[inline(always)]
fn atan_reduced(t: f64, hi: f64, lo: f64) -> f64 {
    let z = t * t;
    let w = z * z;
    // fdlibm's odd/even split, each half by Estrin's scheme (shorter dependency chains; this
    // sits on the latency path of every arc end)
    let w2 = w * w;
    let w4 = w2 * w2;
    let s1 = z * ((AT[0] + w * AT[2]) + w2 * (AT[4] + w * AT[6]) + w4 * (AT[8] + w * AT[10]));
    let s2 = w * ((AT[1] + w * AT[3]) + w2 * (AT[5] + w * AT[7]) + w4 * AT[9]);
    hi - ((t * (s1 + s2) - lo) - t)
}

/// atan(x) for finite x.
#[inline]
pub fn atan(x: f64) -> f64 {
    atan2_right_half(x, 1.0)
}

/// asin(s) for s in [-1, 1], within 2 eps relative of std (1.9 measured on a dense grid), with one
/// square root, no division and no branch (so lane loops vectorise it): s + s^3 P(s^2) on
/// |s| <= 1/2, and above, asin |s| = pi/2 - 2 asin(sqrt((1 - |s|)/2)) (fdlibm's reduction;
/// 1 - |s| is exact there). P is a 13-term Chebyshev fit on [0, 1/4] (mpmath `chebyfit` of
/// (asin(x) - x)/x^3 in x^2, absolute error 1.5e-17), evaluated with plain (unfused)
/// multiply-adds so every instruction set gives the same bits. asin(+-1) = +-pi/2 exactly.
#[inline(always)]
pub fn asin(s: f64) -> f64 {
    const P: [f64; 13] = [
        0.16666666666666669,
        0.07499999999998433,
        0.04464285714635543,
        0.030381944138531247,
        0.02237217294214989,
        0.017352392720869973,
        0.013971212973552933,
        0.011479177415184906,
        0.01032281435018578,
        0.005457506718640358,
        0.01740087944269402,
        -0.014851887071247204,
        0.028757851367421566,
    ];
    const PIO2_LO: f64 = 6.123_233_995_736_766e-17;
    let a = s.abs();
    let big = a > 0.5;
    let half_rest = (0.5 * (1.0 - a)).max(0.0);
    let z = if big { half_rest } else { a * a };
    let x = if big { half_rest.sqrt() } else { a };
    let r = x + x * z * estrin::<Plain, 13>(z, &P);
    let r = if big {
        FRAC_PI_2 - (2.0 * r - PIO2_LO)
    } else {
        r
    };
    r.copysign(s)
}

/// [`asin`] of every element of `xs`, in place, in lanes (AVX-512 or AVX2 when the CPU has it):
/// the batched cross-section path collects its arc ends' sines and takes their asin here in
/// one pass, instead of one latency-bound call per arc end.
pub fn asin_in_place(xs: &mut [f64]) {
    super::lanes::on_widest_lanes(
        #[inline(always)]
        |_| {
            for x in xs.iter_mut() {
                *x = asin(*x);
            }
        },
    )
}

/// acos(c) for c in [-1, 1].
#[inline]
pub fn acos(c: f64) -> f64 {
    // acos c = 2 atan2(sqrt(1 - c), sqrt(1 + c))
    2.0 * atan2_right_half((1.0 - c).max(0.0).sqrt(), (1.0 + c).max(0.0).sqrt())
}

/// Taylor coefficients of cos in powers of x^2: (-1)^k / (2k)!, k = 0..11.
pub(crate) const COS_TAYLOR: [f64; 12] = [
    1.0,
    -1.0 / 2.0,
    1.0 / 24.0,
    -1.0 / 720.0,
    1.0 / 40_320.0,
    -1.0 / 3_628_800.0,
    1.0 / 479_001_600.0,
    -1.0 / 87_178_291_200.0,
    1.0 / 20_922_789_888_000.0,
    -1.0 / 6_402_373_705_728_000.0,
    1.0 / 2_432_902_008_176_640_000.0,
    -1.0 / 1_124_000_727_777_607_680_000.0,
];

/// (sin x, cos x) for |x| < 1e5, within ~1 ulp also near the zeros.
#[inline]
pub fn sin_cos(x: f64) -> (f64, f64) {
    // pi/2 in three parts with 32 significant bits in the first two: n * part is exact for
    // |n| < 2^20.
    const P1: f64 = 1.570_796_326_734_125_6;
    const P2: f64 = 6.077_100_506_303_966e-11;
    const P3: f64 = 2.022_266_248_795_950_6e-21;
    let t = x * std::f64::consts::FRAC_2_PI + ROUND_MAGIC;
    let n = t - ROUND_MAGIC;
    let r = ((x - n * P1) - n * P2) - n * P3;
    let q = t.to_bits() & 3;
    let z = r * r;
    // Taylor kernels on |r| <= pi/4 (+ rounding), truncation < 1e-19 relative; the
    // corrections by Estrin's scheme in z, z^2, z^4 (short dependency chains).
    let z2 = z * z;
    let z4 = z2 * z2;
    const S: [f64; 8] = [
        -1.0 / 6.0,
        1.0 / 120.0,
        -1.0 / 5_040.0,
        1.0 / 362_880.0,
        -1.0 / 39_916_800.0,
        1.0 / 6_227_020_800.0,
        -1.0 / 1_307_674_368_000.0,
        1.0 / 355_687_428_096_000.0,
    ];
    let c8: &[f64; 8] = COS_TAYLOR[2..10].try_into().expect("8 terms");
    let est = |k: &[f64; 8]| {
        ((k[0] + z * k[1]) + z2 * (k[2] + z * k[3]))
            + z4 * ((k[4] + z * k[5]) + z2 * (k[6] + z * k[7]))
    };
    let s = r + r * z * est(&S);
    let c = 1.0 + z * (-0.5 + z * est(c8));
    // quadrant q: (sin, cos) = (s, c), (c, -s), (-s, -c), (-c, s), without branches
    let (sv, cv) = if q & 1 == 0 { (s, c) } else { (c, s) };
    let sin_sign = (q & 2) << 62;
    let cos_sign = ((q + 1) & 2) << 62;
    (
        f64::from_bits(sv.to_bits() ^ sin_sign),
        f64::from_bits(cv.to_bits() ^ cos_sign),
    )
}

#[inline]
pub fn cos(x: f64) -> f64 {
    sin_cos(x).1
}

#[inline]
pub fn sin(x: f64) -> f64 {
    sin_cos(x).0
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::PI;

    fn ulps(got: f64, want: f64) -> f64 {
        if got == want {
            return 0.0;
        }
        let scale = want.abs().max(f64::MIN_POSITIVE);
        (got - want).abs() / scale / f64::EPSILON
    }

    fn grid(lo: f64, hi: f64, n: usize) -> impl Iterator<Item = f64> {
        (0..=n).map(move |i| lo + (hi - lo) * (i as f64 / n as f64))
    }

    #[test]
    fn atan_and_atan2_within_two_ulp() {
        let xs = grid(-3.0, 3.0, 300_000)
            .chain(grid(-1e-6, 1e-6, 10_000))
            .chain((0..4000).map(|i| 10f64.powf(-300.0 + 0.15 * i as f64)))
            .chain([0.4375, 0.6875, 1.1875, 2.4375, 1e300, -1e300]);
        for x in xs {
            assert!(
                ulps(atan(x), x.atan()) <= 1.0,
                "atan({x}): {} vs {}",
                atan(x),
                x.atan()
            );
            assert!(ulps(atan(-x), (-x).atan()) <= 1.0, "atan({})", -x);
        }
        for a in grid(-FRAC_PI_2 * (1.0 - 1e-9), FRAC_PI_2 * (1.0 - 1e-9), 200_000) {
            let (y, x) = (a.sin(), a.cos());
            let (got, want) = (atan2_right_half(y, x), y.atan2(x));
            assert!(ulps(got, want) <= 2.0, "atan2({y}, {x}): {got} vs {want}");
        }
        assert_eq!(atan(0.0), 0.0);
        assert_eq!(atan2_right_half(0.0, 1.0), 0.0);
    }

    #[test]
    fn lane_form_of_atan2_is_the_same_function() {
        for a in grid(-FRAC_PI_2, FRAC_PI_2, 100_000) {
            for r in [1e-300, 0.3, 1.0, 7.0] {
                let (y, x) = (r * a.sin(), r * a.cos().max(0.0));
                assert_eq!(
                    atan2_right_half_lanes(y, x).to_bits(),
                    atan2_right_half(y, x).to_bits(),
                    "atan2({y}, {x})"
                );
            }
        }
    }

    #[test]
    fn asin_acos_within_three_ulp_up_to_the_ends() {
        let xs = grid(-1.0, 1.0, 400_000)
            .chain(grid(1.0 - 1e-9, 1.0, 10_000))
            .chain(grid(-1.0, -1.0 + 1e-9, 10_000))
            .chain((0..2000).map(|i| 10f64.powf(-300.0 + 0.15 * i as f64)));
        for x in xs {
            assert!(
                ulps(asin(x), x.asin()) <= 3.0,
                "asin({x}): {} vs {}",
                asin(x),
                x.asin()
            );
            assert!(
                ulps(acos(x), x.acos()) <= 3.0,
                "acos({x}): {} vs {}",
                acos(x),
                x.acos()
            );
        }
        assert_eq!(asin(1.0), FRAC_PI_2);
        // the in-place lane form gives the same bits (a length that leaves a remainder)
        let xs: Vec<f64> = grid(-1.0, 1.0, 100_002)
            .chain(grid(1.0 - 1e-9, 1.0, 1_000))
            .chain([-1.0, -0.0, 0.0, 1e-300])
            .collect();
        let mut lanes = xs.clone();
        asin_in_place(&mut lanes);
        for (x, got) in xs.iter().zip(&lanes) {
            assert_eq!(got.to_bits(), asin(*x).to_bits(), "asin({x})");
        }
        assert_eq!(asin(-1.0), -FRAC_PI_2);
        assert_eq!(acos(1.0), 0.0);
        assert_eq!(acos(-1.0), PI);
    }

    #[test]
    fn sin_cos_within_two_ulp_including_near_zeros() {
        let mut xs: Vec<f64> = grid(-30.0, 30.0, 600_000).collect();
        for k in -8..=8 {
            let z = k as f64 * FRAC_PI_2;
            xs.extend(grid(z - 1e-7, z + 1e-7, 2_000));
        }
        xs.extend((0..2000).map(|i| 10f64.powf(-300.0 + 0.15 * i as f64)));
        for x in xs {
            let (s, c) = sin_cos(x);
            // near a zero, measure against the argument's own rounding: |error| <= 2 ulp of 1
            // times |x| (pi's representation error is below that)
            let tol = |v: f64| 2.0f64.max(1e-16 * x.abs() / v.abs().max(1e-300) / f64::EPSILON);
            assert!(
                ulps(s, x.sin()) <= tol(x.sin()),
                "sin({x}): {s} vs {}",
                x.sin()
            );
            assert!(
                ulps(c, x.cos()) <= tol(x.cos()),
                "cos({x}): {c} vs {}",
                x.cos()
            );
        }
    }
}
