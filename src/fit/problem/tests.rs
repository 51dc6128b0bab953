//! Tests of the problem: Jacobians, shared albedos, NaN handling.

mod tests {
    use super::super::*;

    #[test]
    fn the_log_floor_is_relative_to_the_data() {
        let v: Vec<[f64; 3]> = (1..=101).map(|k| [k as f64 * 0.01, 5.0, 0.0]).collect();
        // median 0.51 -> 1 % of it; a constant channel; an all-zero channel keeps a tiny floor
        assert!((log_floor(&v, 0) - 0.0051).abs() < 1e-15);
        assert!((log_floor(&v, 1) - 0.05).abs() < 1e-15);
        assert_eq!(log_floor(&v, 2), 1e-12);
        // scaling the data scales the floor: the metric is relative
        let w: Vec<[f64; 3]> = v.iter().map(|x| [1e3 * x[0], 0.0, 0.0]).collect();
        assert!((log_floor(&w, 0) / log_floor(&v, 0) - 1e3).abs() < 1e-9);
    }

    #[test]
    fn bounded_lsq_matches_unconstrained_inside_and_clips_outside() {
        // G = I, h = (0.3, 0.7): unconstrained a = h
        let mut g = [[0.0; 4]; 4];
        (0..4).for_each(|i| g[i][i] = 1.0);
        let a = bounded_small_lsq(
            &g,
            &[0.3, 0.7, 0.0, 0.0],
            &[0, 1],
            &[(0.0, 1.0), (0.0, 1.0)],
        );
        assert!((a[0] - 0.3).abs() < 1e-15 && (a[1] - 0.7).abs() < 1e-15);
        let a = bounded_small_lsq(
            &g,
            &[-0.3, 1.7, 0.0, 0.0],
            &[0, 1],
            &[(0.0, 1.0), (0.0, 1.0)],
        );
        assert_eq!(a, vec![0.0, 1.0]);
        // correlated columns: optimum with one at its bound re-solves the other
        let g = [
            [2.0, 1.0, 0.0, 0.0],
            [1.0, 2.0, 0.0, 0.0],
            [0.0, 0.0, 1.0, 0.0],
            [0.0, 0.0, 0.0, 1.0],
        ];
        let a = bounded_small_lsq(
            &g,
            &[2.0, -1.0, 0.0, 0.0],
            &[0, 1],
            &[(0.0, 1.0), (0.0, 1.0)],
        );
        // with a1 = 0: 2 a0 = 2 -> a0 = 1
        assert!((a[0] - 1.0).abs() < 1e-12 && a[1].abs() < 1e-12, "{a:?}");
    }
}

mod shared_albedo_tests {
    use super::super::*;
    use rand::{Rng, SeedableRng};

    /// sum_c of the joint objective and its gradient for per-channel values `x[c]` (in `free`'s
    /// order).
    fn objective(
        grams: &[([[f64; 4]; 4], [f64; 4])],
        free: &[usize],
        x: &[Vec<f64>],
    ) -> (f64, Vec<Vec<f64>>) {
        let mut f = 0.0;
        let mut grad = Vec::new();
        for ((g, h), xc) in grams.iter().zip(x) {
            let mut gc = vec![0.0; free.len()];
            for (i, &a) in free.iter().enumerate() {
                f -= 2.0 * xc[i] * h[a];
                gc[i] -= 2.0 * h[a];
                for (j, &b) in free.iter().enumerate() {
                    f += xc[i] * xc[j] * g[a][b];
                    gc[i] += 2.0 * g[a][b] * xc[j];
                }
            }
            grad.push(gc);
        }
        (f, grad)
    }

    /// Gram matrices of random columns (kd, ks, fuzz) and data of three channels.
    fn grams(seed: u64, truth: &[[f64; 3]; 3], correlated: f64) -> Vec<([[f64; 4]; 4], [f64; 4])> {
        let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
        let cols: Vec<[f64; 4]> = (0..200)
            .map(|_| {
                let d: f64 = rng.random_range(0.1..1.0);
                let s: f64 = correlated * d + (1.0 - correlated) * rng.random_range(0.0..2.0);
                [d, s, 0.0, rng.random_range(0.0..0.5)]
            })
            .collect();
        (0..3)
            .map(|c| {
                let mut g = [[0.0; 4]; 4];
                let mut h = [0.0; 4];
                for col in &cols {
                    let noise: f64 = rng.random_range(-0.01..0.01);
                    let y =
                        truth[0][c] * col[0] + truth[1][c] * col[1] + truth[2][c] * col[3] + noise;
                    for a in [0, 1, 3] {
                        h[a] += col[a] * y;
                        for b in [0, 1, 3] {
                            g[a][b] += col[a] * col[b];
                        }
                    }
                }
                (g, h)
            })
            .collect()
    }

    #[test]
    fn a_shared_albedo_meets_the_joint_optimality_conditions() {
        let free = [0usize, 1, 3];
        let bounds = [(0.0, 1.0), (0.0, 1.0), (0.0, 1.0)];
        // kd per channel, ks (grey truth or not), fuzz per channel; the last case pushes kd[b]
        // and the fuzz to their bounds and has a ks whose best grey value is inside
        let cases: [([[f64; 3]; 3], f64); 4] = [
            ([[0.5, 0.1, 0.05], [0.3, 0.3, 0.3], [0.2, 0.1, 0.3]], 0.0),
            ([[0.5, 0.1, 0.05], [0.6, 0.2, 0.1], [0.2, 0.1, 0.3]], 0.0),
            ([[0.5, 0.1, 0.02], [0.3, 0.3, 0.3], [0.0, 0.1, 0.0]], 0.9),
            ([[0.6, 0.2, -0.3], [0.5, 0.4, 0.6], [-0.2, 0.4, 1.4]], 0.5),
        ];
        for (k, (truth, corr)) in cases.iter().enumerate() {
            let g = grams(k as u64, truth, *corr);
            let x = solve_with_shared(&g, &free, &bounds, 1);
            assert!(
                x.iter().all(|xc| xc[1] == x[0][1]),
                "case {k}: shared value differs"
            );
            let (f, grad) = objective(&g, &free, &x);
            let scale: f64 = g.iter().map(|(gc, _)| gc[0][0]).sum::<f64>();
            let tol = 1e-9 * scale;
            // KKT: per-channel variables and the shared one (its gradient summed over channels)
            let check = |v: f64, d: f64, (lo, hi): (f64, f64), what: &str| {
                if v <= lo {
                    assert!(
                        d >= -tol,
                        "case {k}: {what} at its lower bound with gradient {d}"
                    );
                } else if v >= hi {
                    assert!(
                        d <= tol,
                        "case {k}: {what} at its upper bound with gradient {d}"
                    );
                } else {
                    assert!(
                        d.abs() <= tol,
                        "case {k}: {what} = {v} inside with gradient {d}"
                    );
                }
            };
            for c in 0..3 {
                for i in [0usize, 2] {
                    check(
                        x[c][i],
                        grad[c][i],
                        bounds[i],
                        &format!("channel {c} albedo {i}"),
                    );
                }
            }
            let d_shared: f64 = grad.iter().map(|gc| gc[1]).sum();
            check(x[0][1], d_shared, bounds[1], "the shared albedo");
            // and no nearby feasible point is better (a coarse scan of the shared value)
            for t in 0..=40 {
                let s = t as f64 / 40.0;
                let mut y = x.clone();
                for (c, (gc, hc)) in g.iter().enumerate() {
                    let mut h2 = *hc;
                    for a in [0usize, 3] {
                        h2[a] -= gc[a][1] * s;
                    }
                    let sol = bounded_small_lsq(gc, &h2, &[0, 3], &[bounds[0], bounds[2]]);
                    y[c] = vec![sol[0], s, sol[1]];
                }
                assert!(
                    objective(&g, &free, &y).0 >= f - tol,
                    "case {k}: s = {s} beats the solution"
                );
            }
        }
        // the grey truth is recovered where the data allow
        let g = grams(0, &cases[0].0, 0.0);
        let x = solve_with_shared(&g, &free, &bounds, 1);
        assert!((x[0][1] - 0.3).abs() < 0.01, "{}", x[0][1]);
    }
}

mod nan_tests {
    use super::super::*;
    use crate::fit::config::FitConfig;
    use crate::load::samples::Origin;
    use crate::model::frame::direction_from_angles;

    #[test]
    fn a_nan_residual_is_an_error_naming_the_parameters() {
        let s = Sample {
            l: direction_from_angles(0.3, 0.0),
            v: direction_from_angles(0.5, 2.0),
            fibre_azimuth: None,
            map_value: None,
            texel_height: None,
            value: [f64::NAN; 3],
            sigma: None,
            weight: 1.0,
            origin: Origin::Line(7),
        };
        let cfg: FitConfig = toml::from_str(
            "model = \"poulin-fournier\"\n[parameters]\nexponent = { value = 12 }\n",
        )
        .unwrap();
        let set = ParamSet::from_config(&cfg, 1).unwrap();
        let p = FitProblem::new(
            vec![&s],
            set.clone(),
            Settings {
                metric: Metric::Linear,
                quadrature_order: 16,
                histogram_bins: 16,
                separable: false,
            },
            None,
        );
        let theta = p.theta_of(&set);
        let err = p.evaluate(&theta, &set).unwrap_err().to_string();
        assert!(
            err.contains("not finite") && err.contains("exponent = 12"),
            "{err}"
        );
        // and through the whole fit: an error, not a result
        let data = crate::load::samples::Samples {
            samples: vec![s.clone(); 12],
            channels: 1,
            kind: crate::load::samples::DataKind::Gonio,
            source: "nan".into(),
            dropped: Default::default(),
            skipped_examples: vec![],
            image_size: None,
            scale_rel_se: None,
        };
        assert!(crate::fit::fit(&data, &cfg, &crate::progress::Progress::quiet()).is_err());
    }
}

mod fuzz_reuse_tests {
    use super::super::*;
    use crate::fit::config::FitConfig;
    use crate::load::samples::Origin;
    use crate::model::frame::direction_from_angles;

    #[test]
    fn the_fuzz_layers_columns_reuse_the_bases_under_it_bit_for_bit() {
        // samples all over the hemisphere, some below the horizon
        let samples: Vec<Sample> = (0..40)
            .map(|k| Sample {
                l: direction_from_angles(0.04 * k as f64, 0.7 * k as f64),
                v: direction_from_angles(1.6 - 0.035 * k as f64, 2.0 + 0.3 * k as f64),
                fibre_azimuth: None,
                map_value: None,
                texel_height: None,
                value: [0.1 + 0.01 * k as f64; 3],
                sigma: None,
                weight: 1.0,
                origin: Origin::Line(k + 2),
            })
            .collect();
        let cfg: FitConfig = toml::from_str(
            "model = \"poulin-fournier\"\n[parameters]\nexponent = { value = 12 }\n\
             spacing = { value = 2.5 }\nfuzz_depth = { value = 0.3 }\n\
             fuzz_asymmetry = { value = 0.4 }\n",
        )
        .unwrap();
        let set = ParamSet::from_config(&cfg, 1).unwrap();
        let settings = Settings {
            metric: Metric::Log,
            quadrature_order: 16,
            histogram_bins: 16,
            separable: false,
        };
        let problem = || FitProblem::new(samples.iter().collect(), set.clone(), settings, None);
        let kept = problem();
        let theta = kept.theta_of(&set);
        let names = kept.theta_names();
        let at = |p: &str| names.iter().position(|n| n.contains(p)).unwrap();
        let depth = at("fuzz_depth");
        let g = at("fuzz_asymmetry");
        let exponent = at("exponent");
        kept.evaluate_keeping(&theta, &set, true).unwrap();
        assert!(kept.under_fuzz.lock().unwrap().is_some());
        // the layer's columns from the kept bases; another parameter's from a fresh evaluation
        for (k, h) in [(depth, 1e-3), (g, -2e-3), (exponent, 1e-2)] {
            let mut t = theta.clone();
            t[k] += h;
            let (reused, _) = kept.evaluate(&t, &set).unwrap();
            let (fresh, _) = problem().evaluate(&t, &set).unwrap();
            assert_eq!(reused, fresh, "{}", names[k]);
            assert_ne!(reused, kept.evaluate(&theta, &set).unwrap().0, "{}", names[k]);
        }
    }
}
