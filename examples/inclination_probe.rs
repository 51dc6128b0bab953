//! Does a spread of fibre *inclination* help the real felt? (issue 11 item 1: "consider ... keep it
//! if it measurably helps real data"; the README quotes this probe's figures.)
//!
//!     cargo run --release --example inclination_probe [-- fuzz]
//!
//! Fits poulin-fournier with the azimuth spread (and, with `fuzz`, the fuzz layer) to the same
//! 80 % of 3000 felt directions as `fibrefit bench --felt`, then averages the fitted model over
//! patches tilted by +-b about 8 horizontal axes (weights (l.N')(v.N') / ((l.N)(v.N))), refits
//! the four linear weights per channel in the log metric, and prints the held-out log error per b.
//! Run from the repository root (it reads ../shared/data/rgl).
use fibrefit::fit::config::FitConfig;
use fibrefit::load::samples::Samples;
use fibrefit::model::{DirectionPair, Vec3};

/// Fit nonneg weights per channel in the log metric; return weights.
fn fit_w(cols: &[Vec<f64>], ys: &[[f64; 3]], eps: [f64; 3]) -> Vec<[f64; 3]> {
    let k = cols[0].len();
    let mut w = vec![[0.01; 3]; k];
    for c in 0..3 {
        let mut lam = 1e-3;
        let cost = |w: &Vec<[f64; 3]>| -> f64 {
            cols.iter()
                .zip(ys)
                .map(|(col, y)| {
                    let m: f64 = (0..k).map(|j| w[j][c] * col[j]).sum();
                    ((m.max(0.0) + eps[c]).ln() - (y[c].max(0.0) + eps[c]).ln()).powi(2)
                })
                .sum()
        };
        let mut cur = cost(&w);
        for _ in 0..200 {
            let mut g = nalgebra::DMatrix::<f64>::zeros(k, k);
            let mut h = nalgebra::DVector::<f64>::zeros(k);
            for (col, y) in cols.iter().zip(ys) {
                let m: f64 = (0..k).map(|j| w[j][c] * col[j]).sum();
                let r = (m.max(0.0) + eps[c]).ln() - (y[c].max(0.0) + eps[c]).ln();
                for a in 0..k {
                    let ja = col[a] / (m + eps[c]);
                    h[a] -= ja * r;
                    for b in 0..k {
                        g[(a, b)] += ja * col[b] / (m + eps[c]);
                    }
                }
            }
            for a in 0..k {
                g[(a, a)] *= 1.0 + lam;
                g[(a, a)] += 1e-12;
            }
            let step = match g.clone().cholesky() {
                Some(ch) => ch.solve(&h),
                None => break,
            };
            let mut w2 = w.clone();
            for a in 0..k {
                w2[a][c] = (w[a][c] + step[a]).max(0.0);
            }
            let nc = cost(&w2);
            if nc < cur {
                w = w2;
                let done = cur - nc < 1e-12 * cur;
                cur = nc;
                lam *= 0.3;
                if done {
                    break;
                }
            } else {
                lam *= 10.0;
                if lam > 1e12 {
                    break;
                }
            }
        }
    }
    w
}

fn main() {
    let felt = std::path::Path::new("../shared/data/rgl/acrylic_felt_green_rgb.bsdf");
    let opts = fibrefit::load::LoadOptions {
        measured: fibrefit::load::rgl::MeasuredOptions {
            directions: 3000,
            seed: 0,
            max_theta_deg: 78.0,
        },
        ..Default::default()
    };
    let data = fibrefit::load::load_data(felt, &opts).unwrap();
    let (train, test) = fibrefit::bench::felt::split(&data, fibrefit::bench::felt::SPLIT_SEED);
    let fuzz = std::env::args().nth(1).is_some();
    let auto: FitConfig = toml::from_str("model = \"auto\"\nmetric = \"log\"\n").unwrap();
    let mut cfg = auto.for_rung("poulin-fournier".parse().unwrap());
    if fuzz {
        cfg.parameters
            .insert("fuzz_depth".into(), Default::default());
    }
    let o = fibrefit::fit::fit(&train, &cfg, &fibrefit::progress::Progress::quiet()).unwrap();
    eprintln!("{}", fibrefit::fit::problem::describe(&o.set));
    let m = fibrefit::fit::problem::model_for(&o.set, 16, 16, 16, None);
    let all: Vec<[f64; 3]> = data.samples.iter().map(|s| s.value).collect();
    let eps = [0, 1, 2].map(|c| fibrefit::fit::problem::log_floor(&all, c));
    // basis columns with tilt b (deg): patches tilted by +-b about axes at 8 azimuths
    let cols = |s: &Samples, b: f64| -> Vec<Vec<f64>> {
        s.samples
            .iter()
            .map(|x| {
                let mut acc = [0.0f64; 4];
                let tilts: Vec<(f64, f64)> = if b == 0.0 {
                    vec![(0.0, 1.0)]
                } else {
                    vec![(b, 0.5), (-b, 0.5)]
                };
                let naz = if b == 0.0 { 1 } else { 8 };
                for &(t, wt) in &tilts {
                    for k in 0..naz {
                        let a = k as f64 * std::f64::consts::PI / naz as f64;
                        // patch normal tilted by t about the axis at azimuth a
                        let axis = Vec3::new(a.cos(), a.sin(), 0.0);
                        let rot = nalgebra::Rotation3::from_axis_angle(
                            &nalgebra::Unit::new_normalize(axis),
                            t.to_radians(),
                        );
                        let (l, v) = (rot.inverse() * x.l, rot.inverse() * x.v);
                        if l.z <= 0.0 || v.z <= 0.0 {
                            continue;
                        }
                        let bb = m.basis(&DirectionPair::new(
                            &fibrefit::model::FibreFrame::from_azimuth(0.0),
                            &l,
                            &v,
                        ));
                        let g = l.z * v.z / (x.l.z * x.v.z) * wt / naz as f64;
                        acc[0] += bb.diffuse * g;
                        acc[1] += bb.specular * g;
                        acc[2] += bb.substrate * g;
                        acc[3] += bb.fuzz * g;
                    }
                }
                acc.to_vec()
            })
            .collect()
    };
    let err = |c: &[Vec<f64>], s: &Samples, w: &[[f64; 3]; 4]| -> f64 {
        let (mut t, mut n) = (0.0, 0.0);
        for (col, x) in c.iter().zip(&s.samples) {
            for ch in 0..3 {
                let mv: f64 = (0..4).map(|j| w[j][ch] * col[j]).sum();
                t += ((mv.max(0.0) + eps[ch]).ln() - (x.value[ch] + eps[ch]).ln()).powi(2);
                n += 1.0;
            }
        }
        (t / n).sqrt()
    };
    let ytr: Vec<[f64; 3]> = train.samples.iter().map(|s| s.value).collect();
    for b in [0.0, 10.0, 20.0, 30.0, 45.0] {
        let ctr = cols(&train, b);
        let cte = cols(&test, b);
        let w = fit_w(&ctr, &ytr, eps);
        let w4 = [w[0], w[1], w[2], w[3]];
        println!(
            "tilt {b:>4}: train {:.4} test {:.4}",
            err(&ctr, &train, &w4),
            err(&cte, &test, &w4)
        );
    }
}
