use super::*;
use crate::model::numerics::quadrature::adaptive_gk15;

/// Sort intervals and return the complement of their union within (lo, hi).
fn complement_within(shadows: &mut [(f64, f64)], lo: f64, hi: f64) -> Arcs {
    shadows.sort_unstable_by(|p, q| p.0.total_cmp(&q.0));
    let mut out = Arcs::default();
    let mut cursor = lo;
    for &(a, b) in shadows.iter() {
        if a > cursor {
            out.push(cursor, a.min(hi));
        }
        cursor = cursor.max(b);
        if cursor >= hi {
            return out;
        }
    }
    out.push(cursor, hi);
    out
}

/// The i-th pattern of a random test set: every fifth touching (d = 2), spacings up to
/// 2 + `spread` weighted towards 2, and every seventh at each elevation limit.
fn random_pattern(i: usize, spread: f64, u: &mut impl FnMut() -> f64) -> Pattern {
    let d = if i % 5 == 0 {
        2.0
    } else {
        2.0 + spread * u() * u()
    };
    let phi_max = (1.0 / d).acos();
    let phi = match i % 7 {
        0 => 0.0,
        1 => phi_max,
        _ => phi_max * u(),
    };
    Pattern::new(d, phi)
}

/// The previous form of [`Pattern::substrate_fraction`]: each row's arc cut at the period
/// boundary into up to two pieces, all pieces sorted, the gaps of their union summed.
fn substrate_fraction_by_pieces(pat: &Pattern, l: &Projected, v: &Projected) -> f64 {
    let p = pat.period;
    let mut pieces = vec![];
    for dir in [l, v] {
        let half = dir.sec;
        if 2.0 * half >= p {
            return 0.0;
        }
        for (cx, cy) in [(0.0, 0.0), (pat.step, pat.rise)] {
            let start = (cx - (1.0 + cy) * dir.tan - half).rem_euclid(p);
            let end = start + 2.0 * half;
            if end <= p {
                pieces.push((start, end));
            } else {
                pieces.push((start, p));
                pieces.push((0.0, end - p));
            }
        }
    }
    complement_within(&mut pieces, 0.0, p).total_length() / p
}

#[test]
fn substrate_fraction_matches_the_piecewise_form() {
    use rand::{Rng, SeedableRng};
    let mut rng = rand::rngs::StdRng::seed_from_u64(11);
    let mut u = move || rng.random::<f64>();
    let mut open = 0;
    let mut problems = vec![];
    for i in 0..40_000 {
        let p = random_pattern(i, 10.0, &mut u);
        let (d, phi) = (p.spacing, p.elevation);
        let mut angle = || match i % 13 {
            0 => 0.0,
            _ => (u() - 0.5) * std::f64::consts::PI * 0.999,
        };
        let (l, v) = (Projected::in_plane(angle()), Projected::in_plane(angle()));
        let got = p.substrate_fraction(&l, &v);
        let want = substrate_fraction_by_pieces(&p, &l, &v);
        assert!(
            (got - want).abs() < 1e-13,
            "d {d} phi {phi} l {} v {}: {got} vs {want}",
            l.alpha,
            v.alpha
        );
        open += (want > 0.0) as usize;
        problems.push(SubstrateProblem::new(&p, &l, &v));
    }
    // the lane pass gives the same bits
    let mut lanes = vec![0.0; problems.len()];
    substrate_fractions(&problems, &mut lanes);
    for (p, got) in problems.iter().zip(&lanes) {
        assert_eq!(got.to_bits(), p.fraction().to_bits(), "{p:?}");
    }
    // about a quarter of the cases see some substrate (the comparison is not all zeros)
    assert!(open > 8_000, "{open}");
}

/// The previous, row-generic form of [`Pattern::unoccluded_arcs`] (both rows through the same
/// member-window code, std floor/ceil, a general sort): the specialised one must agree.
fn unoccluded_arcs_by_rows(p: &Pattern, fibre: Fibre, dir: &Projected) -> Arcs {
    let (sa, ca) = (dir.sin, dir.cos);
    let ds = 2.0 * p.step * ca;
    let da = 2.0 * p.step * sa;
    let rows = match fibre {
        Fibre::Even => [(0.0, 0.0), (p.step, p.rise)],
        Fibre::Odd => [(0.0, 0.0), (p.step, -p.rise)],
    };
    let mut shadows = vec![];
    for (x0, y0) in rows {
        let s0 = x0 * ca - y0 * sa;
        let a0 = x0 * sa + y0 * ca;
        let mut lo = ((-2.0 - s0) / ds).ceil();
        let mut hi = ((2.0 - s0) / ds).floor();
        if da > 0.0 {
            lo = lo.max((-a0 / da).floor() + 1.0);
        } else if da < 0.0 {
            hi = hi.min((-a0 / da).ceil() - 1.0);
        } else if a0 <= 0.0 {
            continue;
        }
        if !(lo <= hi) {
            continue;
        }
        if ds <= 2.0 {
            shadows.push((s0 + lo * ds - 1.0, s0 + hi * ds + 1.0));
        } else {
            let mut m = lo;
            while m <= hi {
                shadows.push((s0 + m * ds - 1.0, s0 + m * ds + 1.0));
                m += 1.0;
            }
        }
    }
    let gaps = complement_within(&mut shadows, -1.0, 1.0);
    let mut arcs = Arcs::default();
    for &(a, b) in gaps.as_slice() {
        arcs.push(
            dir.alpha + a.clamp(-1.0, 1.0).asin(),
            dir.alpha + b.clamp(-1.0, 1.0).asin(),
        );
    }
    arcs
}

#[test]
fn specialised_occlusion_matches_the_row_generic_form() {
    use rand::{Rng, SeedableRng};
    let mut rng = rand::rngs::StdRng::seed_from_u64(7);
    let mut u = move || rng.random::<f64>();
    let mut compared = 0;
    let mut problems = vec![];
    for i in 0..20_000 {
        let p = random_pattern(i, 6.0, &mut u);
        let (d, phi) = (p.spacing, p.elevation);
        let alpha = match i % 11 {
            0 => 0.0,
            1 => std::f64::consts::FRAC_PI_2 * (1.0 - 1e-9),
            _ => (u() - 0.5) * std::f64::consts::PI * 0.999_999,
        };
        let dir = Projected::in_plane(alpha);
        for fibre in [Fibre::Even, Fibre::Odd] {
            problems.push(p.occlusion(&dir).of(fibre));
            let got = p.unoccluded_arcs(fibre, &dir);
            let want = unoccluded_arcs_by_rows(&p, fibre, &dir);
            // intervals shorter than 1e-12 may appear on one side only (touching shadows)
            let keep = |a: &Arcs| -> Vec<(f64, f64)> {
                a.as_slice()
                    .iter()
                    .copied()
                    .filter(|(x, y)| y - x > 1e-12)
                    .collect()
            };
            let (g, w) = (keep(&got), keep(&want));
            assert_eq!(
                g.len(),
                w.len(),
                "d {d} phi {phi} alpha {alpha} {fibre:?}: {g:?} vs {w:?}"
            );
            for (x, y) in g.iter().zip(&w) {
                assert!(
                    (x.0 - y.0).abs() < 1e-12 && (x.1 - y.1).abs() < 1e-12,
                    "d {d} phi {phi} alpha {alpha} {fibre:?}: {g:?} vs {w:?}"
                );
            }
            compared += 1;
        }
    }
    assert_eq!(compared, 40_000);
    // the lane pass gives the same gap slots, bit for bit
    let mut many = FibreOcclusions::default();
    many.extend(&problems);
    many.solve();
    for (i, p) in problems.iter().enumerate() {
        assert_eq!(
            many.slots(i).map(f64::to_bits),
            p.gap_slots().map(f64::to_bits)
        );
    }
}

#[test]
fn floor_ceil_wrap_match_std() {
    for x in [
        -3.5,
        -3.0,
        -0.2,
        -0.0,
        0.0,
        0.7,
        2.0,
        2.9999999,
        1e17,
        -1e17,
        4.4e15 + 0.5,
        2_251_799_813_685_247.5,
        -2_251_799_813_685_247.5,
        2_251_799_813_685_248.5,
        0.5,
        -0.5,
        1.5,
        -2.5,
        1e-300,
        -1e-300,
    ] {
        assert_eq!(floor(x), x.floor(), "{x}");
        assert_eq!(ceil(x), x.ceil(), "{x}");
    }
    for (x, p) in [
        (-0.5, 4.0),
        (9.0, 4.0),
        (3.999999, 4.0),
        (-8.0, 4.0),
        (1e6 + 0.25, 2.0),
    ] {
        assert!(
            (wrap(x, p, 1.0 / p) - f64::rem_euclid(x, p)).abs() < 1e-9,
            "{x} {p}"
        );
    }
}

#[test]
fn diffuse_kernel_matches_quadrature_on_long_and_short_arcs() {
    for &(t0, t1, a, b) in &[
        (-1.2, 1.3, 0.2, -0.4),
        (0.0, 0.05, 0.3, 0.3),
        (-1.5, -1.49, 0.07, 0.0),
        (0.3, 0.3 + 1e-6, 0.1, 0.2),
        (0.2, 0.69, -0.5, 0.4),
        (1.0, 1.51, 0.0, 0.0),
        (-1.5706, -1.5, 0.0, 0.0),
        (1.07, 1.0707963, -0.5, 0.5),
    ] {
        let want = adaptive_gk15(&[t0, t1], 1e-14, 0.0, |t: f64| {
            (t - a).cos() * (t - b).cos()
        })
        .value[0];
        let got = diffuse_kernel(t0, t1, a, b, (a - b).cos());
        assert!(
            (got - want).abs() <= 1e-13 * want.abs().max(1e-300),
            "{got} vs {want}"
        );
    }
}

#[test]
fn lane_diffuse_kernels_equal_the_scalar_kernel_bit_for_bit() {
    use rand::{Rng, SeedableRng};
    let mut rng = rand::rngs::StdRng::seed_from_u64(3);
    let mut arcs = vec![];
    for i in 0..10_003 {
        let t0 = rng.random_range(-3.1..3.1);
        // long and short arcs, down to slivers
        let d = match i % 3 {
            0 => rng.random_range(0.0..3.0),
            1 => rng.random_range(0.4..0.6),
            _ => 10f64.powf(rng.random_range(-12.0..0.0)),
        };
        let (a, b) = (rng.random_range(-1.57..1.57), rng.random_range(-1.57..1.57));
        arcs.push(DiffuseArc {
            t0,
            t1: t0 + d,
            a,
            b,
            cos_ab: (a - b).cos(),
        });
    }
    let mut many = DiffuseArcs::default();
    for arc in &arcs {
        many.push(*arc);
    }
    let mut out = vec![0.0; arcs.len()];
    many.kernels(&mut out);
    for (arc, got) in arcs.iter().zip(&out) {
        let want = diffuse_kernel(arc.t0, arc.t1, arc.a, arc.b, arc.cos_ab);
        assert_eq!(got.to_bits(), want.to_bits(), "{arc:?}");
    }
}

#[test]
fn vertical_light_on_touching_flat_fibres_sees_upper_halves() {
    let p = Pattern::flat(2.0);
    let dir = Projected::in_plane(0.0);
    let arcs = p.unoccluded_arcs(Fibre::Even, &dir);
    assert_eq!(arcs.as_slice().len(), 1);
    let (a, b) = arcs.as_slice()[0];
    assert!(
        (a + std::f64::consts::FRAC_PI_2).abs() < 1e-12
            && (b - std::f64::consts::FRAC_PI_2).abs() < 1e-12
    );
    assert_eq!(p.substrate_fraction(&dir, &dir), 0.0);
}

#[test]
fn gapped_fibres_show_substrate_from_above() {
    // d = 4, flat: fibres of width 2 every 4 radii, so half the substrate shows.
    let p = Pattern::flat(4.0);
    let dir = Projected::in_plane(0.0);
    assert!((p.substrate_fraction(&dir, &dir) - 0.5).abs() < 1e-15);
}

#[test]
fn grazing_light_lights_only_a_sliver_and_stays_finite() {
    let p = Pattern::flat(2.0);
    let a: f64 = std::f64::consts::FRAC_PI_2 - 3e-8;
    let dir = Projected::in_plane(a);
    let arcs = p.unoccluded_arcs(Fibre::Even, &dir);
    let len = arcs.total_length();
    assert!(len > 0.0 && len < 1e-3, "{len}");
}
