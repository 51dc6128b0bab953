//! Numerical quadrature: fixed-order Gauss–Legendre (the speed knob N) and globally adaptive
//! Gauss–Kronrod 7/15 (the reference, after QUADPACK's QAG).

/// Gauss–Legendre rule of order `n` on [-1, 1]; nodes and weights computed once by Newton's
/// method on the Legendre recurrence.
#[derive(Clone, Debug, PartialEq)]
pub struct GaussLegendre {
    nodes: Vec<f64>,
    weights: Vec<f64>,
}

impl GaussLegendre {
    pub fn new(n: usize) -> Self {
        assert!(n >= 1, "Gauss–Legendre order must be >= 1");
        let mut nodes = vec![0.0; n];
        let mut weights = vec![0.0; n];
        let m = n.div_ceil(2);
        let nf = n as f64;
        for i in 0..m {
            // Tricomi's initial guess, then Newton.
            let mut x = (std::f64::consts::PI * (i as f64 + 0.75) / (nf + 0.5)).cos();
            let mut dp = 1.0;
            for _ in 0..100 {
                let (p, d) = legendre_with_derivative(n, x);
                dp = d;
                let dx = p / d;
                x -= dx;
                if dx.abs() < 1e-16 {
                    break;
                }
            }
            let (_, d) = legendre_with_derivative(n, x);
            dp = if d != 0.0 { d } else { dp };
            let w = 2.0 / ((1.0 - x * x) * dp * dp);
            nodes[i] = -x;
            nodes[n - 1 - i] = x;
            weights[i] = w;
            weights[n - 1 - i] = w;
        }
        if n % 2 == 1 {
            nodes[n / 2] = 0.0;
        }
        Self { nodes, weights }
    }

    pub fn order(&self) -> usize {
        self.nodes.len()
    }

    /// Nodes and weights on [-1, 1].
    pub fn nodes_and_weights(&self) -> (&[f64], &[f64]) {
        (&self.nodes, &self.weights)
    }

    /// Integral of `f` over [a, b].
    #[inline]
    pub fn integrate(&self, a: f64, b: f64, mut f: impl FnMut(f64) -> f64) -> f64 {
        let half = 0.5 * (b - a);
        let mid = 0.5 * (a + b);
        let mut sum = 0.0;
        for (x, w) in self.nodes.iter().zip(&self.weights) {
            sum += w * f(mid + half * x);
        }
        sum * half
    }
}

fn legendre_with_derivative(n: usize, x: f64) -> (f64, f64) {
    let mut p0 = 1.0;
    let mut p1 = x;
    for k in 2..=n {
        let kf = k as f64;
        let p2 = ((2.0 * kf - 1.0) * x * p1 - (kf - 1.0) * p0) / kf;
        p0 = p1;
        p1 = p2;
    }
    let p = if n == 0 { 1.0 } else { p1 };
    let d = n as f64 * (x * p - p0) / (x * x - 1.0);
    (p, d)
}

// Gauss–Kronrod 7/15 nodes and weights (QUADPACK qk15).
const XGK: [f64; 8] = [
    0.991_455_371_120_812_6,
    0.949_107_912_342_758_5,
    0.864_864_423_359_769_1,
    0.741_531_185_599_394_4,
    0.586_087_235_467_691_1,
    0.405_845_151_377_397_2,
    0.207_784_955_007_898_5,
    0.0,
];
const WGK: [f64; 8] = [
    0.022_935_322_010_529_22,
    0.063_092_092_629_978_55,
    0.104_790_010_322_250_2,
    0.140_653_259_715_525_9,
    0.169_004_726_639_267_9,
    0.190_350_578_064_785_4,
    0.204_432_940_075_298_9,
    0.209_482_141_084_727_8,
];
const WG: [f64; 4] = [
    0.129_484_966_168_869_7,
    0.279_705_391_489_276_7,
    0.381_830_050_505_118_9,
    0.417_959_183_673_469_4,
];

/// One Gauss–Kronrod 15 panel of a vector integrand: (Kronrod estimate, |K15 - G7| per component).
fn gk15<const N: usize>(
    a: f64,
    b: f64,
    f: &mut impl FnMut(f64) -> [f64; N],
) -> ([f64; N], [f64; N]) {
    let half = 0.5 * (b - a);
    let mid = 0.5 * (a + b);
    let fc = f(mid);
    let mut k = [0.0; N];
    let mut g = [0.0; N];
    for c in 0..N {
        k[c] = WGK[7] * fc[c];
        g[c] = WG[3] * fc[c];
    }
    for j in 0..7 {
        let dx = half * XGK[j];
        let (f1, f2) = (f(mid - dx), f(mid + dx));
        for c in 0..N {
            let s = f1[c] + f2[c];
            k[c] += WGK[j] * s;
            if j % 2 == 1 {
                g[c] += WG[j / 2] * s;
            }
        }
    }
    let mut err = [0.0; N];
    for c in 0..N {
        err[c] = ((k[c] - g[c]) * half).abs();
        k[c] *= half;
    }
    (k, err)
}

/// Result of an adaptive integration.
#[derive(Clone, Copy, Debug)]
pub struct Adaptive<const N: usize> {
    pub value: [f64; N],
    pub error: [f64; N],
    pub evaluations: usize,
}

/// Globally adaptive Gauss–Kronrod integration of a vector integrand `f` over the panels between
/// consecutive `breaks` (which should include every kink of `f`). Bisects the panel with the
/// largest error (relative to each component's tolerance) until, for every component,
/// the total error is below `max(rel_tol * |value|, abs_tol)`.
pub fn adaptive_gk15_vec<const N: usize>(
    breaks: &[f64],
    rel_tol: f64,
    abs_tol: f64,
    mut f: impl FnMut(f64) -> [f64; N],
) -> Adaptive<N> {
    const MAX_PANELS: usize = 4000;
    struct Panel<const N: usize> {
        a: f64,
        b: f64,
        value: [f64; N],
        error: [f64; N],
    }
    let mut panels: Vec<Panel<N>> = Vec::with_capacity(64);
    let mut evaluations = 0;
    for w in breaks.windows(2) {
        if w[1] > w[0] {
            let (value, error) = gk15(w[0], w[1], &mut f);
            evaluations += 15;
            panels.push(Panel {
                a: w[0],
                b: w[1],
                value,
                error,
            });
        }
    }
    loop {
        let mut value = [0.0; N];
        let mut error = [0.0; N];
        for p in &panels {
            for c in 0..N {
                value[c] += p.value[c];
                error[c] += p.error[c];
            }
        }
        let mut tol = [0.0; N];
        for c in 0..N {
            tol[c] = (rel_tol * value[c].abs())
                .max(abs_tol)
                .max(f64::MIN_POSITIVE);
        }
        let converged = (0..N).all(|c| error[c] <= tol[c]);
        if converged || panels.len() >= MAX_PANELS {
            return Adaptive {
                value,
                error,
                evaluations,
            };
        }
        let score = |p: &Panel<N>| (0..N).map(|c| p.error[c] / tol[c]).fold(0.0, f64::max);
        let worst = (0..panels.len())
            .max_by(|&x, &y| score(&panels[x]).total_cmp(&score(&panels[y])))
            .expect("error above tolerance implies at least one panel");
        let (a, b) = (panels[worst].a, panels[worst].b);
        let m = 0.5 * (a + b);
        if !(m > a && m < b) {
            // The panel can no longer be split in floating point: accept what it holds.
            panels[worst].error = [0.0; N];
            continue;
        }
        let (v1, e1) = gk15(a, m, &mut f);
        let (v2, e2) = gk15(m, b, &mut f);
        evaluations += 30;
        panels[worst] = Panel {
            a,
            b: m,
            value: v1,
            error: e1,
        };
        panels.push(Panel {
            a: m,
            b,
            value: v2,
            error: e2,
        });
    }
}

/// Scalar form of [`adaptive_gk15_vec`].
pub fn adaptive_gk15(
    breaks: &[f64],
    rel_tol: f64,
    abs_tol: f64,
    mut f: impl FnMut(f64) -> f64,
) -> Adaptive<1> {
    adaptive_gk15_vec(breaks, rel_tol, abs_tol, |x| [f(x)])
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn gauss_legendre_is_exact_for_polynomials_of_degree_2n_minus_1() {
        for n in [1usize, 2, 3, 4, 7, 16, 64] {
            let rule = GaussLegendre::new(n);
            let deg = 2 * n - 1;
            let got = rule.integrate(0.0, 1.0, |x| x.powi(deg as i32));
            let want = 1.0 / (deg as f64 + 1.0);
            assert!((got - want).abs() < 1e-13, "n={n}: {got} vs {want}");
            let wsum: f64 = rule.weights.iter().sum();
            assert!((wsum - 2.0).abs() < 1e-13);
        }
    }

    #[test]
    fn gk15_adaptive_reaches_tight_tolerance_on_kinked_and_peaked_functions() {
        let r = adaptive_gk15(&[0.0, 1.0, 3.0], 1e-12, 0.0, |x: f64| (x - 1.0).abs());
        assert!((r.value[0] - 2.5).abs() < 1e-12, "{:?}", r.value);
        // sharp Gaussian peak: integral of exp(-x^2/(2 s^2)) over R = s sqrt(2 pi)
        let s = 1e-3;
        let r = adaptive_gk15(&[-1.0, 0.0, 1.0], 1e-12, 0.0, |x: f64| {
            (-x * x / (2.0 * s * s)).exp()
        });
        let want = s * (2.0 * std::f64::consts::PI).sqrt();
        assert!(
            (r.value[0] - want).abs() / want < 1e-11,
            "{:?} vs {want}",
            r.value
        );
        let r = adaptive_gk15(&[0.0, std::f64::consts::PI], 1e-13, 0.0, f64::sin);
        assert!((r.value[0] - 2.0).abs() < 1e-12);
    }
}
