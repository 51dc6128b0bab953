//! Issue 38 item 1: the `gltf` rung (glTF 2.0 metallic-roughness with KHR_materials_sheen,
//! _anisotropy, _specular and _ior; `model/rungs/gltf.rs`).
//!
//! - Reciprocity, T -> -T, non-negativity and finiteness, also at grazing angles.
//! - Energy: the white furnace (base colour 1) at most 1 for metallic 0 and 1 at several
//!   roughnesses, with and without sheen.
//! - Each lobe against an independent brute-force computation written here: the anisotropic GGX
//!   D and the Charlie D each integrate (h.n) to 1; the visible normals' density integrates to
//!   1 (so Smith's Lambda is the visibility's); the whole BRDF against a separate
//!   implementation (its own sheen albedo by a midpoint rule, not the rung's table).
//! - Parameter recovery: a gonio table synthesised from known parameters with 1 % noise, fitted
//!   by `fibrefit fit --model gltf` from the default starts, lands within a few standard errors.
//!
//! The sampler's chi-square and `weight = f cos / pdf` run for this rung in `tests/sampling.rs`
//! (every registered rung, plus two gltf cases), the shader against `eval` in
//! `tests/shader_export.rs` (every rung with a shader section).

mod common;

use assert_cmd::Command;
use common::Rng;
use fibrefit::model::frame::Local;
use fibrefit::model::params::{GltfShape, ModelParams, RawParams};
use fibrefit::model::rungs::gltf::{self, Gltf};
use fibrefit::model::{self, DirectionPair, ModelId, ShadingModel};
use std::f64::consts::PI;

fn shape(metallic: f64, roughness: f64, anisotropy: f64, sheen: f64) -> GltfShape {
    GltfShape {
        metallic,
        roughness,
        anisotropy,
        specular: 0.8,
        ior: 1.6,
        sheen,
        sheen_roughness: 0.5,
        variant: Default::default(),
    }
}

fn dir(theta_deg: f64, phi_deg: f64) -> Local {
    let (st, ct) = theta_deg.to_radians().sin_cos();
    let (sp, cp) = phi_deg.to_radians().sin_cos();
    Local {
        t: st * cp,
        b: st * sp,
        n: ct,
    }
}

fn random_dir(rng: &mut Rng) -> Local {
    let w = rng.hemisphere();
    Local {
        t: w.x,
        b: w.y,
        n: w.z,
    }
}

/// f for base colour `c` (the rung's basis: c times the diffuse column plus the layers').
fn brdf(m: &dyn ShadingModel, c: f64, l: Local, v: Local) -> f64 {
    let b = m.basis(&DirectionPair { l, v });
    c * b.diffuse + b.specular
}

fn materials() -> Vec<GltfShape> {
    let mut out = Vec::new();
    for metallic in [0.0, 0.4, 1.0] {
        for roughness in [0.05, 0.3, 0.7, 1.0] {
            for anisotropy in [0.0, 0.7, 1.0] {
                for sheen in [0.0, 0.8] {
                    out.push(shape(metallic, roughness, anisotropy, sheen));
                }
            }
        }
    }
    out
}

#[test]
fn reciprocal_non_negative_finite_and_even_in_t() {
    let mut rng = Rng::new(38);
    for g in materials() {
        let m = Gltf::new(&g);
        let mut dirs: Vec<Local> = (0..40).map(|_| random_dir(&mut rng)).collect();
        // grazing: N.l down to 1e-9, and the exact horizon
        for th in [89.0, 89.999, 90.0 - 1e-7] {
            dirs.push(dir(th, 0.0));
            dirs.push(dir(th, 90.0));
            dirs.push(dir(th, 211.0));
        }
        dirs.push(dir(90.0, 30.0));
        for l in &dirs {
            for v in &dirs {
                let a = brdf(&m, 0.7, *l, *v);
                let b = brdf(&m, 0.7, *v, *l);
                assert!(a.is_finite() && a >= 0.0, "{g:?}: f({l:?}, {v:?}) = {a}");
                assert!(
                    (a - b).abs() <= 1e-12 * a.abs().max(1.0),
                    "{g:?}: not reciprocal: {a} vs {b}"
                );
                let flip = |w: &Local| Local {
                    t: -w.t,
                    b: -w.b,
                    n: w.n,
                };
                let c = brdf(&m, 0.7, flip(l), flip(v));
                assert!((a - c).abs() <= 1e-12 * a.abs().max(1.0), "{g:?}: T -> -T");
            }
        }
    }
}

/// int f (N.l) d omega_l by a product Gauss-Legendre rule in (N.l, phi) of order `n`.
fn albedo(f: &dyn Fn(Local) -> f64, n: usize) -> f64 {
    let gl = fibrefit::model::numerics::quadrature::GaussLegendre::new(n);
    let (x, w) = gl.nodes_and_weights();
    let mut sum = 0.0;
    for (xi, wi) in x.iter().zip(w) {
        let mu = 0.5 * (xi + 1.0);
        let s = (1.0 - mu * mu).sqrt();
        for (xj, wj) in x.iter().zip(w) {
            let phi = PI * (xj + 1.0);
            let l = Local {
                t: s * phi.cos(),
                b: s * phi.sin(),
                n: mu,
            };
            sum += wi * wj * f(l) * mu;
        }
    }
    sum * 0.5 * PI
}

/// The white furnace (base colour 1), by a 400 x 400 product rule.
fn furnace(g: &GltfShape, theta_deg: f64) -> f64 {
    let m = Gltf::new(g);
    let v = dir(theta_deg, 60.0);
    albedo(&|l| brdf(&m, 1.0, l, v), 400)
}

#[test]
fn the_white_furnace_is_at_most_one() {
    // metallic 1 (the conductor Fresnel times single-scattering GGX) and the sheen's layering
    // (f_sheen + (1 - sheen E) base) never gain energy: at most 1 at every view
    for roughness in [0.3, 0.5, 0.8, 1.0] {
        for sheen in [0.0, 1.0] {
            let g = GltfShape {
                specular: 1.0,
                ior: 1.5,
                ..shape(1.0, roughness, 0.5, sheen)
            };
            for th in [0.0, 45.0, 80.0] {
                let e = furnace(&g, th);
                assert!(e <= 1.0 + 1e-3, "{g:?} at {th} deg: albedo {e}");
                assert!(e > 0.2, "{g:?} at {th} deg: albedo {e}, too dark for white");
            }
        }
    }
    // metallic 0: Appendix B's fresnel_mix weighs the diffuse by 1 - F(V.H), and V.H differs
    // from light to light, so at grazing views the sum exceeds 1 (as
    // the_material_equals_an_independent_implementation shows, this is the specification's
    // formula, not an error here): at most 1 up to 45 deg, the measured excess at 80 deg
    for roughness in [0.3, 0.5, 0.8, 1.0] {
        for sheen in [0.0, 1.0] {
            let g = GltfShape {
                specular: 1.0,
                ior: 1.5,
                ..shape(0.0, roughness, 0.5, sheen)
            };
            for th in [0.0, 45.0] {
                let e = furnace(&g, th);
                assert!(e <= 1.0 + 1e-3, "{g:?} at {th} deg: albedo {e}");
                assert!(e > 0.5, "{g:?} at {th} deg: albedo {e}");
            }
            let e = furnace(&g, 80.0);
            eprintln!(
                "dielectric, roughness {roughness}, sheen {sheen}: white furnace at 80 deg {e:.4}"
            );
            assert!(e <= 1.08, "{g:?} at 80 deg: albedo {e}");
        }
    }
}

/// The anisotropic GGX D, written independently: 1 / (pi ax ay (t^2/ax^2 + b^2/ay^2 + n^2)^2).
fn ggx_d_here(ax: f64, ay: f64, h: &Local) -> f64 {
    let q = (h.t / ax).powi(2) + (h.b / ay).powi(2) + h.n * h.n;
    1.0 / (PI * ax * ay * q * q)
}

/// int over the hemisphere of f(h) d omega_h: Gauss-Legendre panels in theta (split where
/// narrow lobes need it) and 32 panels in phi (narrow anisotropic lobes).
fn over_hemisphere(f: &dyn Fn(Local) -> f64) -> f64 {
    let gl = fibrefit::model::numerics::quadrature::GaussLegendre::new(64);
    let mut sum = 0.0;
    let edges = [0.0, 0.02, 0.1, 0.3, 0.6, 1.0, PI / 2.0];
    let panels = 32;
    for k in 0..edges.len() - 1 {
        sum += gl.integrate(edges[k], edges[k + 1], |th| {
            let (st, ct) = th.sin_cos();
            let mut ring = 0.0;
            for j in 0..panels {
                let (a, b) = (
                    2.0 * PI * j as f64 / panels as f64,
                    2.0 * PI * (j + 1) as f64 / panels as f64,
                );
                ring += gl.integrate(a, b, |phi| {
                    f(Local {
                        t: st * phi.cos(),
                        b: st * phi.sin(),
                        n: ct,
                    })
                });
            }
            ring * st
        });
    }
    sum
}

#[test]
fn the_lobes_are_normalised_and_equal_independent_forms() {
    for (ax, ay) in [(0.1, 0.1), (0.05, 0.6), (0.3, 1.0), (1.0, 1.0), (0.7, 0.2)] {
        let mut rng = Rng::new(7);
        for _ in 0..50 {
            let h = random_dir(&mut rng);
            let (a, b) = (gltf::ggx_d(ax, ay, &h), ggx_d_here(ax, ay, &h));
            assert!((a - b).abs() <= 1e-12 * b, "D({ax}, {ay}): {a} vs {b}");
        }
        let norm = over_hemisphere(&|h| gltf::ggx_d(ax, ay, &h) * h.n);
        assert!(
            (norm - 1.0).abs() < 1e-6,
            "GGX D ({ax}, {ay}): int D h.n = {norm}"
        );
        // the visible normals for a view: int G1(v) max(0, v.h) D(h) / v.n = 1 (Heitz 2018), so
        // the sampler's density and the visibility's Lambda are one
        for v in [dir(0.0, 0.0), dir(50.0, 20.0), dir(85.0, 100.0)] {
            let g1 = 1.0 / (1.0 + gltf::ggx_lambda(ax, ay, &v));
            let dv = over_hemisphere(&|h| {
                let vh = (v.t * h.t + v.b * h.b + v.n * h.n).max(0.0);
                g1 * vh * gltf::ggx_d(ax, ay, &h) / v.n
            });
            assert!((dv - 1.0).abs() < 1e-5, "D_v ({ax}, {ay}) at {v:?}: {dv}");
        }
        // the visibility is the height-correlated G2 / (4 N.l N.v) with that Lambda
        let (l, v) = (dir(30.0, 10.0), dir(70.0, 250.0));
        let g2 = 1.0 / (1.0 + gltf::ggx_lambda(ax, ay, &l) + gltf::ggx_lambda(ax, ay, &v));
        let want = g2 / (4.0 * l.n * v.n);
        let got = gltf::ggx_v(ax, ay, &l, &v);
        assert!((got - want).abs() < 1e-12 * want, "V: {got} vs {want}");
    }
    for r in [0.3, 0.5, 0.8, 1.0] {
        let a: f64 = r * r;
        // Charlie, written here: (2 + 1/a) sin^(1/a) / (2 pi)
        let d = |h: Local| (2.0 + 1.0 / a) * (1.0 - h.n * h.n).sqrt().powf(1.0 / a) / (2.0 * PI);
        let norm = over_hemisphere(&|h| d(h) * h.n);
        assert!((norm - 1.0).abs() < 1e-6, "Charlie D at r {r}: {norm}");
        let h = dir(40.0, 0.0);
        assert!((gltf::charlie_d(a, h.n) - d(h)).abs() < 1e-12);
    }
}

/// The whole material, written again from the specifications (see the rung's doc): per lobe,
/// with its own sheen albedo by a midpoint rule.
fn brdf_here(g: &GltfShape, c: f64, l: Local, v: Local) -> f64 {
    let alpha = g.roughness * g.roughness;
    let (ax, ay) = (alpha, alpha + (1.0 - alpha) * g.anisotropy * g.anisotropy);
    let hv = [l.t + v.t, l.b + v.b, l.n + v.n];
    let len = (hv[0] * hv[0] + hv[1] * hv[1] + hv[2] * hv[2]).sqrt();
    let h = Local {
        t: hv[0] / len,
        b: hv[1] / len,
        n: hv[2] / len,
    };
    let lam = |w: &Local| {
        0.5 * ((1.0 + ((ax * w.t).powi(2) + (ay * w.b).powi(2)) / (w.n * w.n)).sqrt() - 1.0)
    };
    let s = ggx_d_here(ax, ay, &h) / ((1.0 + lam(&l) + lam(&v)) * 4.0 * l.n * v.n);
    let x = (1.0 - (v.t * h.t + v.b * h.b + v.n * h.n)).powi(5);
    let f0 = ((g.ior - 1.0) / (g.ior + 1.0)).powi(2);
    let fr = f0 + (1.0 - f0) * x;
    let dielectric = (1.0 - g.specular * fr) * c / PI + g.specular * fr * s;
    let metal = s * (c + (1.0 - c) * x);
    let base = (1.0 - g.metallic) * dielectric + g.metallic * metal;
    if g.sheen == 0.0 {
        return base;
    }
    let a = g.sheen_roughness * g.sheen_roughness;
    let sheen_lobe = |l: &Local, v: &Local| {
        let hn =
            (l.n + v.n) / ((l.t + v.t).powi(2) + (l.b + v.b).powi(2) + (l.n + v.n).powi(2)).sqrt();
        gltf::charlie_d(a, hn) * gltf::sheen_v(l.n, v.n, a)
    };
    // E(mu) by a 400 x 400 midpoint rule
    let e = |mu: f64| {
        let v = Local {
            t: (1.0 - mu * mu).sqrt(),
            b: 0.0,
            n: mu,
        };
        let n = 400;
        let mut sum = 0.0;
        for i in 0..n {
            let nl = (i as f64 + 0.5) / n as f64;
            let sl = (1.0 - nl * nl).sqrt();
            for j in 0..n {
                let phi = 2.0 * PI * (j as f64 + 0.5) / n as f64;
                let l = Local {
                    t: sl * phi.cos(),
                    b: sl * phi.sin(),
                    n: nl,
                };
                sum += sheen_lobe(&l, &v) * nl;
            }
        }
        sum * 2.0 * PI / (n * n) as f64
    };
    let scaling = (1.0 - g.sheen * e(v.n)).min(1.0 - g.sheen * e(l.n));
    g.sheen * sheen_lobe(&l, &v) + scaling * base
}

#[test]
fn the_material_equals_an_independent_implementation() {
    let mut rng = Rng::new(3);
    for g in [
        shape(0.0, 0.5, 0.0, 0.0),
        shape(1.0, 0.3, 0.8, 0.0),
        shape(0.3, 0.6, 0.5, 0.7),
        shape(0.0, 0.9, 1.0, 1.0),
    ] {
        let m = Gltf::new(&g);
        for _ in 0..6 {
            let (l, v) = (random_dir(&mut rng), random_dir(&mut rng));
            let (got, want) = (brdf(&m, 0.6, l, v), brdf_here(&g, 0.6, l, v));
            // the rung interpolates its sheen table linearly: 1e-3 of the sheen's share
            let tol = if g.sheen > 0.0 {
                2e-3 * want
            } else {
                1e-12 * want
            };
            assert!((got - want).abs() <= tol, "{g:?}: {got} vs {want}");
        }
    }
}

/// The gonio table of `text`'s material at `n` random direction pairs with relative noise
/// `noise` (seeded), as CSV with sigmas.
fn synthesise(text: &str, n: usize, noise: f64) -> String {
    let raw: RawParams = toml::from_str(text).unwrap();
    let (p, _) = ModelParams::from_raw(&raw, ModelId::Gltf).unwrap();
    let m = model::build(ModelId::Gltf, &p).unwrap();
    let mut rng = Rng::new(2038);
    let mut out =
        String::from("theta_i,phi_i,theta_o,phi_o,brdf_r,brdf_g,brdf_b,sigma_r,sigma_g,sigma_b\n");
    let deg = |w: &fibrefit::model::Vec3| {
        (
            w.z.clamp(-1.0, 1.0).acos().to_degrees(),
            w.y.atan2(w.x).to_degrees().rem_euclid(360.0),
        )
    };
    let mut k = 0;
    while k < n {
        let (l, v) = (rng.hemisphere(), rng.hemisphere());
        let (ti, pi) = deg(&l);
        let (to, po) = deg(&v);
        if ti > 80.0 || to > 80.0 {
            continue;
        }
        let f =
            model::brdf_at_degrees(m.as_ref(), &p.albedos, p.fibre_azimuth, [ti, pi, to, po], 3);
        let mut row = format!("{ti},{pi},{to},{po}");
        let mut sig = String::new();
        for y in &f {
            // a Gaussian by Box-Muller
            let (u1, u2) = (rng.uniform().max(1e-300), rng.uniform());
            let z = (-2.0 * u1.ln()).sqrt() * (2.0 * PI * u2).cos();
            let s = noise * y;
            row.push_str(&format!(",{}", y + s * z));
            sig.push_str(&format!(",{s}"));
        }
        out.push_str(&row);
        out.push_str(&sig);
        out.push('\n');
        k += 1;
    }
    out
}

#[test]
fn a_fit_recovers_known_parameters_within_their_errors() {
    let truth = [
        ("fibre_azimuth_deg", 30.0),
        ("metallic", 0.2),
        ("roughness", 0.4),
        ("anisotropy_strength", 0.7),
        ("specular_factor", 0.8),
        ("ior", 1.6),
        ("sheen", 0.5),
        ("sheen_roughness", 0.6),
    ];
    let mut text = String::from("kd = [0.5, 0.3, 0.2]\n");
    for (name, v) in truth {
        text.push_str(&format!("{name} = {v}\n"));
    }
    let dir = tempfile::tempdir().unwrap();
    let csv = dir.path().join("gonio.csv");
    std::fs::write(&csv, synthesise(&text, 2500, 0.01)).unwrap();
    let out = dir.path().join("result.json");
    Command::cargo_bin("fibrefit")
        .unwrap()
        .args([
            "fit",
            csv.to_str().unwrap(),
            "--model",
            "gltf",
            "--quiet",
            "--out",
        ])
        .arg(&out)
        .assert()
        .success();
    let result: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&out).unwrap()).unwrap();
    let params = &result["parameters"];
    let mut report = Vec::new();
    for (name, want) in truth {
        let got = params[name]["value"].as_f64().unwrap();
        let se = params[name]["std_error"].as_f64();
        report.push(format!("{name} {got} +/- {se:?} (truth {want})"));
        eprintln!("{}", report.last().unwrap());
        let se = se.unwrap_or_else(|| panic!("{name}: no standard error: {report:?}"));
        assert!(
            (got - want).abs() <= 4.0 * se + 1e-9,
            "{name}: {got} +/- {se}, truth {want}: {report:#?}"
        );
    }
    for (c, want) in [0.5, 0.3, 0.2].iter().enumerate() {
        let got = params["kd"]["value"][c].as_f64().unwrap();
        let se = params["kd"]["std_error"][c].as_f64().unwrap();
        assert!((got - want).abs() <= 4.0 * se, "kd[{c}] {got} +/- {se}");
    }
}

#[test]
fn base_colour_and_fibre_direction_maps_run_for_the_gltf_rung() {
    let dir = tempfile::tempdir().unwrap();
    let cfg = dir.path().join("maps.toml");
    let capture = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/data_synthetic/silk/capture.toml"
    );
    let maps = dir.path().join("maps");
    let fit = |text: &str| {
        std::fs::write(&cfg, text).unwrap();
        Command::cargo_bin("fibrefit")
            .unwrap()
            .args(["fit", capture, "--quiet", "--config"])
            .arg(&cfg)
            .arg("--maps")
            .arg(&maps)
            .arg("--out")
            .arg(dir.path().join("result.json"))
            .output()
            .unwrap()
    };
    let out = fit("model = \"gltf\"\n[maps]\nkd = true\nfibre_azimuth = true\n");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    for f in ["kd.exr", "fibre_azimuth.exr", "kd_std_error.exr"] {
        assert!(maps.join(f).is_file(), "{f}");
    }
    // the specular column is glTF's layers (weight 1), not a lobe weight a map could carry
    let out = fit("model = \"gltf\"\n[maps]\nks = true\n");
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("no specular lobe"), "{err}");
}
