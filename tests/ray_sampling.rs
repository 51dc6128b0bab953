//! The reference against an independent dense ray-sampling of the same geometry (MODEL.md §2).
//! The sampler below shares no code with the interval solver: it marches every surface point,
//! casts rays against brute-force lists of fibres and the substrate, and sums with the midpoint
//! rule.

mod common;
use common::*;
use fibrefit::model::DirectionPair;

struct Scene {
    kd: f64,
    ks: f64,
    ksub: f64,
    e: f64,
    d: f64,
    phi: f64,
}

/// Does the ray p + t u (t > 0) hit any fibre other than `own`?
fn blocked(p: (f64, f64), u: (f64, f64), own: Option<i64>, h: f64, rise: f64) -> bool {
    // fibres the ray can meet lie within the horizontal reach between y = -1 and the top
    let top = rise + 1.0;
    let reach = if u.1 > 0.0 {
        (top - p.1).max(0.0) * (u.0 / u.1).abs()
    } else {
        f64::INFINITY
    };
    let (lo, hi) = if u.0 >= 0.0 {
        (p.0 - 2.0, p.0 + reach + 2.0)
    } else {
        (p.0 - reach - 2.0, p.0 + 2.0)
    };
    let (k0, k1) = ((lo / h).floor() as i64, (hi / h).ceil() as i64);
    for k in k0..=k1 {
        if Some(k) == own {
            continue;
        }
        let c = (k as f64 * h, if k.rem_euclid(2) == 1 { rise } else { 0.0 });
        let w = (c.0 - p.0, c.1 - p.1);
        let tca = w.0 * u.0 + w.1 * u.1;
        if tca <= 0.0 {
            continue;
        }
        let d2 = w.0 * w.0 + w.1 * w.1 - tca * tca;
        if d2 < 1.0 {
            return true;
        }
    }
    false
}

fn sampled(scene: &Scene, pair: &DirectionPair, samples: usize) -> f64 {
    let (l, v) = (pair.l, pair.v);
    let h = scene.d * scene.phi.cos();
    let rise = scene.d * scene.phi.sin();
    let period = 2.0 * h;
    let norm = |b: f64, n: f64| {
        let len = (b * b + n * n).sqrt();
        (b / len, n / len)
    };
    let (lu, vu) = (norm(l.b, l.n), norm(v.b, v.n));
    let lv = l.dot(&v);
    let mut sum = 0.0;
    let dth = 2.0 * std::f64::consts::PI / samples as f64;
    for (k, centre) in [(0i64, (0.0, 0.0)), (1, (h, rise))] {
        for i in 0..samples {
            let th = -std::f64::consts::PI + (i as f64 + 0.5) * dth;
            let (nb, nn) = (th.sin(), th.cos());
            let nl = nb * l.b + nn * l.n;
            let nv = nb * v.b + nn * v.n;
            if nl <= 0.0 || nv <= 0.0 {
                continue;
            }
            let p = (centre.0 + nb, centre.1 + nn);
            if blocked(p, lu, Some(k), h, rise) || blocked(p, vu, Some(k), h, rise) {
                continue;
            }
            let rv = 2.0 * nl * nv - lv;
            let spec = if rv > 0.0 { rv.powf(scene.e) } else { 0.0 };
            let f = scene.kd / std::f64::consts::PI
                + scene.ks * (scene.e + 2.0) / (2.0 * std::f64::consts::PI) * spec;
            sum += f * nl * nv * dth;
        }
    }
    let dx = period / samples as f64;
    for i in 0..samples {
        let p = ((i as f64 + 0.5) * dx, -1.0);
        if blocked(p, lu, None, h, rise) || blocked(p, vu, None, h, rise) {
            continue;
        }
        sum += scene.ksub / std::f64::consts::PI * l.n * v.n * dx;
    }
    sum / (period * l.n * v.n)
}

#[test]
fn reference_agrees_with_dense_ray_sampling() {
    let pairs = random_pairs(10, 99, 0.15);
    let mut worst: f64 = 0.0;
    for s in sections().into_iter().filter(|s| s.exponent <= 100.0) {
        let reference = reference(&s);
        let phi = (s.height / s.spacing).asin();
        let scene = Scene {
            kd: 0.6,
            ks: 0.3,
            ksub: 0.8,
            e: s.exponent,
            d: s.spacing,
            phi,
        };
        for pair in &pairs {
            let b = reference.basis(pair);
            let exact = 0.6 * b.diffuse + 0.3 * b.specular + 0.8 * b.substrate;
            let rays = sampled(&scene, pair, 40_000);
            let err = rel_diff(exact, rays);
            worst = worst.max(err);
            assert!(
                err < 1e-3,
                "{s:?} {pair:?}: reference {exact} vs rays {rays} (rel {err:.2e})"
            );
        }
    }
    eprintln!("worst relative difference reference vs rays: {worst:.2e}");
}

#[test]
fn grazing_light_across_the_fibres_agrees_with_ray_sampling() {
    // Long shadows reach many fibres: the solver must use all of them, not only neighbours.
    let s = Section {
        spacing: 3.0,
        height: 1.5,
        exponent: 10.0,
    };
    let reference = reference(&s);
    let scene = Scene {
        kd: 1.0,
        ks: 0.0,
        ksub: 1.0,
        e: 10.0,
        d: 3.0,
        phi: (0.5f64).asin(),
    };
    for (lb, ln) in [(0.99, 0.141), (-0.995, 0.0999), (0.9, 0.3)] {
        let pair = DirectionPair::from_local([0.1, lb, ln], [0.0, -0.2, 1.0]);
        let b = reference.basis(&pair);
        let exact = b.diffuse + b.substrate;
        let rays = sampled(&scene, &pair, 40_000);
        assert!(rel_diff(exact, rays) < 1e-3, "{pair:?}: {exact} vs {rays}");
    }
}
