//! The albedos solved for a shape: bounded linear least squares, one small system per
//! channel (with a grey albedo shared by the channels).

#[allow(unused_imports)]
use super::*;

/// The albedos of every channel when one of them, `free[shared]`, is a single value for all
/// channels (a grey `ks` beside per-channel `kd`): min over s and a_c of
/// sum_c [a_c s]^T G_c [a_c s] - 2 [a_c s]^T h_c, all within bounds. For a fixed s each channel's
/// a_c is a small bounded problem ([`bounded_small_lsq`] with s moved to the data side); the cost
/// F(s) minimised over them is convex, with derivative (envelope theorem)
/// F'(s) = 2 sum_c (G_c[s,s] s - h_c[s] + G_c[s,.] a_c(s)), nondecreasing, so s is the root of F'
/// in its bounds (or the bound where F' does not change sign), found by bisection and made exact
/// by one secant step on the linear piece where both ends share the channels' active sets.
/// Returns per channel the values of `free`, in its order (the shared one equal in all).
pub(crate) fn solve_with_shared(
    grams: &[([[f64; 4]; 4], [f64; 4])],
    free: &[usize],
    bounds: &[(f64, f64)],
    shared: usize,
) -> Vec<Vec<f64>> {
    let sk = free[shared];
    let others: Vec<usize> = (0..free.len()).filter(|&k| k != shared).collect();
    let other_free: Vec<usize> = others.iter().map(|&k| free[k]).collect();
    let other_bounds: Vec<(f64, f64)> = others.iter().map(|&k| bounds[k]).collect();
    // the other albedos of every channel at s, and F'(s) / 2
    let inner = |s: f64| -> (Vec<Vec<f64>>, f64) {
        let mut d = 0.0;
        let sols = grams
            .iter()
            .map(|(g, h)| {
                let mut h2 = *h;
                for &a in &other_free {
                    h2[a] -= g[a][sk] * s;
                }
                let sol = bounded_small_lsq(g, &h2, &other_free, &other_bounds);
                d += g[sk][sk] * s - h[sk];
                for (k, &a) in other_free.iter().enumerate() {
                    d += g[sk][a] * sol[k];
                }
                sol
            })
            .collect();
        (sols, d)
    };
    let active = |sols: &[Vec<f64>]| -> Vec<Vec<i8>> {
        sols.iter()
            .map(|sol| {
                sol.iter()
                    .zip(&other_bounds)
                    .map(|(&v, &(lo, hi))| {
                        if v <= lo {
                            -1
                        } else if v >= hi {
                            1
                        } else {
                            0
                        }
                    })
                    .collect()
            })
            .collect()
    };
    let (lo, hi) = bounds[shared];
    let (sol_lo, d_lo) = inner(lo);
    let s = if d_lo >= 0.0 {
        lo
    } else {
        let (sol_hi, d_hi) = inner(hi);
        if d_hi <= 0.0 {
            hi
        } else {
            let (mut a, mut b) = (lo, hi);
            let (mut da, mut db) = (d_lo, d_hi);
            let (mut act_a, mut act_b) = (active(&sol_lo), active(&sol_hi));
            let mut root = None;
            for _ in 0..200 {
                // F' is linear between a and b when both share the active sets (and the point
                // the secant gives does too): its root, exactly; else bisect
                let m = if act_a == act_b {
                    (a - da * (b - a) / (db - da)).clamp(a, b)
                } else {
                    0.5 * (a + b)
                };
                if !(m > a && m < b) {
                    break; // the bracket is as narrow as f64 allows
                }
                let (sol_m, dm) = inner(m);
                if act_a == act_b && active(&sol_m) == act_a {
                    root = Some(m);
                    break;
                }
                if dm == 0.0 {
                    root = Some(m);
                    break;
                }
                if dm < 0.0 {
                    (a, da, act_a) = (m, dm, active(&sol_m));
                } else {
                    (b, db, act_b) = (m, dm, active(&sol_m));
                }
            }
            root.unwrap_or(0.5 * (a + b))
        }
    };
    let (sols, _) = inner(s);
    sols.into_iter()
        .map(|sol| {
            let mut out = vec![0.0; free.len()];
            out[shared] = s;
            for (k, &o) in others.iter().enumerate() {
                out[o] = sol[k];
            }
            out
        })
        .collect()
}

/// min over a of a^T G a - 2 a^T h with a_k in bounds, for the `free` indices (at most 3):
/// every assignment of each variable to {free, lower, upper} is tried and the best feasible kept.
pub(crate) fn bounded_small_lsq(
    g: &[[f64; 4]; 4],
    h: &[f64; 4],
    free: &[usize],
    bounds: &[(f64, f64)],
) -> Vec<f64> {
    let m = free.len();
    if m == 0 {
        return vec![];
    }
    let objective = |a: &[f64]| -> f64 {
        let mut v = 0.0;
        for i in 0..m {
            v -= 2.0 * a[i] * h[free[i]];
            for j in 0..m {
                v += a[i] * a[j] * g[free[i]][free[j]];
            }
        }
        v
    };
    let mut best: Option<(f64, Vec<f64>)> = None;
    for code in 0..3usize.pow(m as u32) {
        let mut state = [0usize; 4];
        let mut x = code;
        for s in state.iter_mut().take(m) {
            *s = x % 3;
            x /= 3;
        }
        let mut a = vec![0.0; m];
        let open: Vec<usize> = (0..m).filter(|&i| state[i] == 0).collect();
        for i in 0..m {
            a[i] = match state[i] {
                1 => bounds[i].0,
                2 => bounds[i].1,
                _ => 0.0,
            };
        }
        if !open.is_empty() {
            let k = open.len();
            let mut mat = DMatrix::zeros(k, k);
            let mut rhs = DVector::zeros(k);
            for (p, &i) in open.iter().enumerate() {
                rhs[p] = h[free[i]];
                for (q, &j) in open.iter().enumerate() {
                    mat[(p, q)] = g[free[i]][free[j]];
                }
                for j in 0..m {
                    if state[j] != 0 {
                        rhs[p] -= g[free[i]][free[j]] * a[j];
                    }
                }
            }
            let Some(sol) = mat.lu().solve(&rhs) else {
                continue;
            };
            let mut feasible = true;
            for (p, &i) in open.iter().enumerate() {
                let v = sol[p];
                if !v.is_finite() || v < bounds[i].0 - 1e-12 || v > bounds[i].1 + 1e-12 {
                    feasible = false;
                }
                a[i] = v.clamp(bounds[i].0, bounds[i].1);
            }
            if !feasible {
                continue;
            }
        }
        let f = objective(&a);
        if best.as_ref().is_none_or(|(bf, _)| f < *bf) {
            best = Some((f, a));
        }
    }
    best.map(|b| b.1)
        .unwrap_or_else(|| bounds.iter().map(|b| b.0).collect())
}
