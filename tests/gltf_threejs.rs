//! Issue 38, item 3's last part: the `gltf` rung's `threejs` variant (`gltf_variant =
//! "threejs"`, `model/rungs/gltf/threejs.rs`), what stock three.js r187 renders for a direct
//! light. (Its render in three.js itself is `tests/browser/run.mjs`.)
//!
//! - Non-negative and finite, also at grazing angles; reciprocal where three.js is (no
//!   multiple-scattering factor: F0 = 0), and measurably not where that factor acts (it is a
//!   function of N.v alone).
//! - The whole BRDF against an implementation written here from three.js's GLSL (vectors, not
//!   the rung's columns), and each departure on its own: Epic's Fresnel, the multiple-scattering
//!   factor (its DFG table against a quadrature of the GGX albedo), V_Neubelt and D_Charlie's
//!   floor, the sheen albedo scaling from IBLSheenBRDF, the diffuse's F90, the roughness floor.
//! - Equal to the khronos variant where the departures vanish.
//! - A fit with `--gltf-variant threejs` recovers known parameters within 4 standard errors
//!   (metallic 0.5: the base colour solved as a quartic's minimum), and
//!   the variant reaches the result, `eval`, the GLB's extras and the shaders (GLSL ES too).

mod common;

use assert_cmd::Command;
use common::Rng;
use fibrefit::model::frame::Local;
use fibrefit::model::params::{GltfShape, ModelParams, RawParams};
use fibrefit::model::rungs::gltf::{threejs, Gltf, GltfVariant};
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
        variant: GltfVariant::Threejs,
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

/// f for base colour `c`: c A + B + c^2 Q (Q the substrate column, kd^2 its albedo).
fn brdf(m: &dyn ShadingModel, c: f64, l: Local, v: Local) -> f64 {
    let b = m.basis(&DirectionPair { l, v });
    c * b.diffuse + b.specular + c * c * b.substrate
}

fn materials() -> Vec<GltfShape> {
    let mut out = Vec::new();
    for metallic in [0.0, 0.4, 1.0] {
        for roughness in [0.03, 0.3, 0.7, 1.0] {
            for anisotropy in [0.0, 0.7] {
                for sheen in [0.0, 0.8] {
                    out.push(shape(metallic, roughness, anisotropy, sheen));
                }
            }
        }
    }
    out
}

fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// three.js r187's direct-light BRDF written from its GLSL (`lights_physical_fragment`,
/// `lights_fragment_begin`, `lights_physical_pars_fragment`, `common`), in vectors: n = z, the
/// anisotropy direction (three.js's `anisotropyT`) across the fibres, the fibres along x.
/// E_ss comes from the rung's reading of three.js's table (tested on its own below).
fn threejs_here(g: &GltfShape, c: f64, l: Local, v: Local) -> f64 {
    let saturate = |x: f64| x.clamp(0.0, 1.0);
    let (lv, vv) = ([l.t, l.b, l.n], [v.t, v.b, v.n]);
    let n = [0.0, 0.0, 1.0];
    let (at_dir, ab_dir) = ([0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]);
    let hs = [lv[0] + vv[0], lv[1] + vv[1], lv[2] + vv[2]];
    let hl = dot(hs, hs).sqrt();
    let h = [hs[0] / hl, hs[1] / hl, hs[2] / hl];
    // lights_physical_fragment
    let roughness = g.roughness.max(0.045).min(1.0);
    let sheen_roughness = g.sheen_roughness.clamp(0.0001, 1.0);
    let f90 = g.specular * (1.0 - g.metallic) + g.metallic;
    let f0d = (((g.ior - 1.0) / (g.ior + 1.0)).powi(2)).min(1.0) * g.specular;
    let f0b = f0d * (1.0 - g.metallic) + c * g.metallic;
    let alpha = roughness * roughness;
    let alpha_t = alpha + (1.0 - alpha) * g.anisotropy * g.anisotropy;
    // lights_fragment_begin: the multiple-scattering compensation
    let nv = saturate(dot(n, vv));
    let msc = 1.0 + f0b * (1.0 / threejs::e_ss(roughness, nv) - 1.0);
    // RE_Direct_Physical
    let nl = saturate(dot(n, lv));
    let mut irradiance = 1.0;
    let mut sheen_direct = 0.0;
    if g.sheen > 0.0 {
        let nh = saturate(dot(n, h));
        let a = sheen_roughness * sheen_roughness;
        let sin2h = (1.0 - nh * nh).max(0.0078125);
        let d = (2.0 + 1.0 / a) * sin2h.powf(0.5 / a) / (2.0 * PI);
        let vis = saturate(1.0 / (4.0 * (nl + nv - nl * nv)));
        sheen_direct = g.sheen * d * vis;
        let ibl = |mu: f64| {
            let r = sheen_roughness;
            let a = -1.9362 + 1.0678 * r + 0.4573 * r * r - 0.8469 / (r + 0.1);
            let b = -0.6014 + 0.5538 * r - 0.4670 * r * r - 0.1255 / (r + 0.1);
            saturate((a * mu + b).exp())
        };
        irradiance *= 1.0 - g.sheen * ibl(nv).max(ibl(nl));
    }
    let vh = saturate(dot(vv, h));
    let fresnel = ((-5.55473 * vh - 6.98316) * vh).exp2();
    let f_schlick = |f0: f64| f0 * (1.0 - fresnel) + f90 * fresnel;
    // BRDF_GGX, anisotropic (Filament's forms)
    let (tl, tv, th) = (dot(at_dir, lv), dot(at_dir, vv), dot(at_dir, h));
    let (bl, bv, bh) = (dot(ab_dir, lv), dot(ab_dir, vv), dot(ab_dir, h));
    let len = |x: [f64; 3]| dot(x, x).sqrt();
    let gv = nl * len([alpha_t * tv, alpha * bv, nv]);
    let gl = nv * len([alpha_t * tl, alpha * bl, nl]);
    let vis = 0.5 / (gv + gl);
    let a2 = alpha_t * alpha;
    let w = [alpha * th, alpha_t * bh, a2 * saturate(dot(n, h))];
    let w2 = a2 / dot(w, w);
    let d = a2 * w2 * w2 / PI;
    let specular = f_schlick(f0b) * vis * d * msc;
    let diffuse = c * (1.0 - g.metallic) / PI * (1.0 - f_schlick(f0d));
    sheen_direct + irradiance * (specular + diffuse)
}

#[test]
fn non_negative_finite_and_reciprocal_where_three_js_is() {
    let mut rng = Rng::new(38);
    let grazing = [dir(89.9, 10.0), dir(89.99, 200.0), dir(0.0, 0.0)];
    for g in materials() {
        let m = Gltf::new(&g);
        for k in 0..200 {
            let (l, v) = if k < 9 {
                (grazing[k / 3], grazing[k % 3])
            } else {
                (random_dir(&mut rng), random_dir(&mut rng))
            };
            for c in [0.0, 0.5, 1.0] {
                let f = brdf(&m, c, l, v);
                assert!(
                    f.is_finite() && f >= 0.0,
                    "{g:?} c {c} at {l:?}, {v:?}: {f}"
                );
            }
        }
    }
    // reciprocal without the multiple-scattering factor (F0 = 0: specular factor 0, metallic 0;
    // the sheen's V_Neubelt and max(E(N.v), E(N.l)) are symmetric)
    for sheen in [0.0, 0.8] {
        let g = GltfShape {
            specular: 0.0,
            ..shape(0.0, 0.4, 0.6, sheen)
        };
        let m = Gltf::new(&g);
        for _ in 0..200 {
            let (l, v) = (random_dir(&mut rng), random_dir(&mut rng));
            let (a, b) = (brdf(&m, 0.6, l, v), brdf(&m, 0.6, v, l));
            assert!((a - b).abs() <= 1e-12 * a.abs().max(1e-300), "{a} vs {b}");
        }
    }
    // not reciprocal where the factor 1 + F0 (1 / E_ss(r, N.v) - 1) acts: a rough metal, light
    // at the normal and view at 80 deg against the reverse
    let m = Gltf::new(&shape(1.0, 0.8, 0.0, 0.0));
    let (l, v) = (dir(0.0, 0.0), dir(80.0, 0.0));
    let (a, b) = (brdf(&m, 0.9, l, v), brdf(&m, 0.9, v, l));
    let asym = (a - b) / b;
    eprintln!("rough metal f(0 deg, 80 deg) / f(80 deg, 0 deg) - 1 = {asym:.4}");
    // measured -26 %: three.js's E_ss of a rough GGX is higher at grazing N.v than at the normal
    assert!(
        asym.abs() > 0.05,
        "the compensation's N.v dependence: {asym}"
    );
}

#[test]
fn the_variant_equals_three_js_written_from_its_glsl() {
    let mut rng = Rng::new(187);
    let mut gs = materials();
    gs.push(GltfShape {
        sheen_roughness: 0.3,
        ior: 2.4,
        specular: 0.3,
        ..shape(0.4, 0.2, 0.9, 1.0)
    });
    for g in gs {
        let m = Gltf::new(&g);
        for _ in 0..150 {
            let (l, v) = (random_dir(&mut rng), random_dir(&mut rng));
            for c in [0.1, 0.7, 1.0] {
                let (got, want) = (brdf(&m, c, l, v), threejs_here(&g, c, l, v));
                assert!(
                    (got - want).abs() <= 1e-10 * want.abs().max(1e-12),
                    "{g:?} c {c} at {l:?}, {v:?}: {got} vs {want}"
                );
            }
        }
    }
}

/// The directional albedo of the isotropic GGX with F = 1 (what three.js's DFG table's x + y
/// holds) at roughness r and N.v = mu, by a midpoint rule in (N.l, phi).
fn ggx_albedo(r: f64, mu: f64) -> f64 {
    let a = r * r;
    let v = dir(mu.acos().to_degrees(), 0.0);
    let n = 400;
    let mut sum = 0.0;
    for i in 0..n {
        let nl = (i as f64 + 0.5) / n as f64;
        for j in 0..n {
            let phi = (j as f64 + 0.5) / n as f64 * PI;
            let l = dir(nl.acos().to_degrees(), phi.to_degrees());
            let h = fibrefit::model::rungs::gltf::half_vector(&l, &v);
            let s = fibrefit::model::rungs::gltf::ggx_d(a, a, &h)
                * fibrefit::model::rungs::gltf::ggx_v(a, a, &l, &v);
            sum += s * nl;
        }
    }
    sum * (1.0 / n as f64) * (PI / n as f64) * 2.0
}

#[test]
fn each_departure_against_its_form() {
    // Epic's Fresnel: exp2((-5.55473 x - 6.98316) x), within 0.01 of (1 - x)^5
    for k in 0..=20 {
        let x = k as f64 / 20.0;
        let e = threejs::epic_fresnel(x);
        assert_eq!(e, 2f64.powf((-5.55473 * x - 6.98316) * x));
        assert!((e - (1.0 - x).powi(5)).abs() < 0.01, "{x}: {e}");
    }
    // the DFG table: E_ss at its texel centres (u the roughness, v = N.v) is the GGX albedo
    for (i, j) in [
        (5, 4),
        (5, 10),
        (10, 4),
        (10, 15),
        (15, 10),
        (15, 15),
        (8, 8),
    ] {
        let (r, mu) = ((i as f64 + 0.5) / 16.0, (j as f64 + 0.5) / 16.0);
        let (e, want) = (threejs::e_ss(r, mu), ggx_albedo(r, mu));
        eprintln!("E_ss({r:.4}, {mu:.4}) = {e:.4}, quadrature {want:.4}");
        assert!((e - want).abs() < 0.02, "E_ss({r}, {mu}) {e} vs {want}");
    }
    // V_Neubelt and D_Charlie with its floor 2^-7 on sin^2(h)
    for (nv, nl) in [(1.0f64, 1.0f64), (0.5, 0.2), (0.05, 0.9)] {
        let want = (1.0 / (4.0 * (nl + nv - nl * nv))).min(1.0);
        assert_eq!(threejs::v_neubelt(nv, nl), want);
    }
    let (r, a) = (0.5, 0.25);
    let d = |s2: f64| (2.0 + 1.0 / a) * s2.powf(0.5 / a) / (2.0 * PI);
    assert_eq!(threejs::d_charlie(r, 1.0), d(2f64.powi(-7)));
    assert!((threejs::d_charlie(r, 0.6) - d(1.0 - 0.36)).abs() < 1e-15);
    // the sheen alone (base colour 0, specular factor 0, metallic 0): the layers' column is
    // sheen D_Charlie V_Neubelt, the base colour's is (1 - sheen max(E(N.v), E(N.l))) / pi
    // with E = IBLSheenBRDF's exp(A mu + B)
    let g = GltfShape {
        specular: 0.0,
        sheen_roughness: 0.5,
        ..shape(0.0, 0.5, 0.0, 0.7)
    };
    let m = Gltf::new(&g);
    let (l, v) = (dir(80.0, 30.0), dir(80.0, 30.0));
    let b = m.basis(&DirectionPair { l, v });
    let h = fibrefit::model::rungs::gltf::half_vector(&l, &v);
    let vn = 1.0 / (4.0 * (l.n + v.n - l.n * v.n));
    assert!((b.specular - 0.7 * d(1.0 - h.n * h.n) * vn).abs() < 1e-12 * b.specular);
    let e = |mu: f64| {
        let ea = -1.9362 + 1.0678 * 0.5 + 0.4573 * 0.25 - 0.8469 / 0.6;
        let eb = -0.6014 + 0.5538 * 0.5 - 0.4670 * 0.25 - 0.1255 / 0.6;
        (ea * mu + eb).exp()
    };
    assert!((b.diffuse * PI - (1.0 - 0.7 * e(l.n).max(e(v.n)))).abs() < 1e-12);
    // the diffuse's Fresnel weight takes F90 = mix(specular, 1, metallic) (light and view at
    // the normal: V.H = 1, so F = F0 (1 - e(1)) + F90 e(1))
    let g = GltfShape {
        specular: 0.6,
        ..shape(0.4, 0.5, 0.0, 0.0)
    };
    let m = Gltf::new(&g);
    let (l, v) = (dir(0.0, 0.0), dir(0.0, 0.0));
    let b = m.basis(&DirectionPair { l, v });
    let f0d = (0.6f64 / 2.6).powi(2) * 0.6;
    let e1 = threejs::epic_fresnel(1.0);
    let fd = f0d * (1.0 - e1) + (0.6 * 0.6 + 0.4) * e1;
    let s = fibrefit::model::rungs::gltf::ggx_d(0.25, 0.25, &l)
        * fibrefit::model::rungs::gltf::ggx_v(0.25, 0.25, &l, &v);
    let gm = 1.0 / threejs::e_ss(0.5, 1.0) - 1.0;
    let p = 0.6 * f0d * (1.0 - e1) + (0.6 * 0.6 + 0.4) * e1;
    let r = 1.0 + 0.6 * f0d * gm;
    let want = 0.6 * (1.0 - fd) / PI + s * 0.4 * (p * gm + (1.0 - e1) * r);
    assert!(
        (b.diffuse - want).abs() < 1e-12 * want,
        "{} vs {want}",
        b.diffuse
    );
    // the roughness floor: below 0.045 three.js evaluates 0.045
    let (lo, at) = (
        Gltf::new(&shape(0.0, 0.03, 0.3, 0.3)),
        Gltf::new(&shape(0.0, 0.045, 0.3, 0.3)),
    );
    let (l, v) = (dir(40.0, 10.0), dir(41.0, 190.0));
    assert_eq!(brdf(&lo, 0.5, l, v), brdf(&at, 0.5, l, v));
}

#[test]
fn equal_to_khronos_where_the_departures_vanish() {
    let mut rng = Rng::new(5);
    for (specular, ior) in [(0.0, 1.5), (1.0, 1.01)] {
        let t = GltfShape {
            specular,
            ior,
            ..shape(0.0, 0.5, 0.6, 0.0)
        };
        let k = GltfShape {
            variant: GltfVariant::Khronos,
            ..t
        };
        let (mt, mk) = (Gltf::new(&t), Gltf::new(&k));
        let mut worst: f64 = 0.0;
        for _ in 0..300 {
            let (l, v) = (random_dir(&mut rng), random_dir(&mut rng));
            let (a, b) = (brdf(&mt, 0.6, l, v), brdf(&mk, 0.6, l, v));
            worst = worst.max(((a - b) / b).abs());
        }
        eprintln!("specular {specular}, ior {ior}: threejs vs khronos worst {worst:.2e}");
        // specular 0: no Fresnel, no compensation, no sheen: the same Lambert, exactly; ior
        // 1.01 (F0 2.5e-5): only Epic's fit of (1 - x)^5 on F90 x remains (measured 2.25 % of f
        // at worst, near grazing)
        let tol = if specular == 0.0 { 1e-14 } else { 0.025 };
        assert!(worst <= tol, "specular {specular}: {worst}");
    }
}

fn synthesise(text: &str, n: usize, noise: f64) -> String {
    let raw: RawParams = toml::from_str(text).unwrap();
    let (p, _) = ModelParams::from_raw(&raw, ModelId::Gltf).unwrap();
    assert_eq!(p.gltf.variant, GltfVariant::Threejs);
    let m = model::build(ModelId::Gltf, &p).unwrap();
    let mut rng = Rng::new(2187);
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
        let ((ti, pi), (to, po)) = (deg(&l), deg(&v));
        if ti > 80.0 || to > 80.0 {
            continue;
        }
        let f =
            model::brdf_at_degrees(m.as_ref(), &p.albedos, p.fibre_azimuth, [ti, pi, to, po], 3);
        let mut row = format!("{ti},{pi},{to},{po}");
        let mut sig = String::new();
        for y in &f {
            let (u1, u2) = (rng.uniform().max(1e-300), rng.uniform());
            let z = (-2.0 * u1.ln()).sqrt() * (2.0 * PI * u2).cos();
            row.push_str(&format!(",{}", y + noise * y * z));
            sig.push_str(&format!(",{}", noise * y));
        }
        out.push_str(&format!("{row}{sig}\n"));
        k += 1;
    }
    out
}

fn fibrefit() -> Command {
    Command::cargo_bin("fibrefit").unwrap()
}

#[test]
fn a_threejs_fit_recovers_known_parameters_and_carries_its_variant() {
    let truth = [
        ("fibre_azimuth_deg", 30.0),
        ("metallic", 0.5),
        ("roughness", 0.4),
        ("anisotropy_strength", 0.7),
        ("specular_factor", 0.8),
        ("ior", 1.6),
        ("sheen", 0.5),
        ("sheen_roughness", 0.6),
    ];
    // metallic 0.5: three.js's BRDF is quadratic in the base colour, solved exactly per channel
    let mut text = String::from("gltf_variant = \"threejs\"\nkd = [0.5, 0.3, 0.2]\n");
    for (name, v) in truth {
        text.push_str(&format!("{name} = {v}\n"));
    }
    let dir = tempfile::tempdir().unwrap();
    let csv = dir.path().join("gonio.csv");
    std::fs::write(&csv, synthesise(&text, 2500, 0.01)).unwrap();
    let out = dir.path().join("result.json");
    fibrefit()
        .args(["fit", csv.to_str().unwrap(), "--model", "gltf"])
        .args(["--gltf-variant", "threejs", "--quiet", "--out"])
        .arg(&out)
        .assert()
        .success();
    let result: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&out).unwrap()).unwrap();
    assert_eq!(result["knobs"]["gltf_variant"], "threejs");
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
    carried_by_eval_export_and_shaders(&out, dir.path());
}

/// `eval` of the result is the threejs variant's (not khronos's), the GLB's extras name the
/// engine, and the shaders (WGSL, GLSL ES) export and compile.
fn carried_by_eval_export_and_shaders(result: &std::path::Path, dir: &std::path::Path) {
    let q = dir.join("q.csv");
    std::fs::write(&q, "theta_i,phi_i,theta_o,phi_o\n0,0,80,120\n80,120,0,0\n").unwrap();
    let e = dir.join("e.csv");
    fibrefit()
        .args(["eval", "--params"])
        .arg(result)
        .args([
            "--queries",
            q.to_str().unwrap(),
            "--out",
            e.to_str().unwrap(),
            "-q",
        ])
        .assert()
        .success();
    let text = std::fs::read_to_string(&e).unwrap();
    let rows: Vec<Vec<f64>> = text
        .lines()
        .skip(1)
        .map(|r| r.split(',').map(|x| x.parse().unwrap()).collect())
        .collect();
    // the compensation makes it non-reciprocal only with F0 > 0: it is here (F0 from ior 1.6)
    assert!(rows[0][4] != rows[1][4], "{text}");
    let glb = dir.join("t.glb");
    fibrefit()
        .arg("export")
        .arg(result)
        .args(["--gltf", glb.to_str().unwrap(), "-q"])
        .assert()
        .success();
    let bytes = std::fs::read(&glb).unwrap();
    let len = u32::from_le_bytes(bytes[12..16].try_into().unwrap()) as usize;
    let doc: serde_json::Value = serde_json::from_slice(&bytes[20..20 + len]).unwrap();
    let extras = &doc["materials"][0]["extras"]["fibrefit"];
    assert_eq!(extras["gltf_variant"], "threejs", "{extras}");
    assert!(extras["exact_in"]
        .as_str()
        .unwrap()
        .contains("three.js r187"));
    for lang in ["wgsl", "glsl-es"] {
        let out = dir.join(format!("t.{lang}"));
        fibrefit()
            .arg("export")
            .arg(result)
            .args(["--shader", lang, "--out", out.to_str().unwrap(), "-q"])
            .assert()
            .success();
        let src = std::fs::read_to_string(&out).unwrap();
        assert!(src.contains("fibrefit_gltf_threejs"), "{lang}");
        if lang == "glsl-es" {
            assert!(src.starts_with("#version 300 es\nprecision highp float;\n"));
            compile_glsl_es(&src, dir);
        }
    }
}

/// The GLSL ES export inside a WebGL2 fragment shader, compiled by glslangValidator where it is
/// installed (CI installs it).
fn compile_glsl_es(src: &str, dir: &std::path::Path) {
    let found = std::env::var_os("PATH").and_then(|paths| {
        std::env::split_paths(&paths)
            .map(|d| d.join("glslangValidator"))
            .find(|p| p.is_file())
    });
    let Some(glslang) = found else {
        assert!(
            std::env::var_os("CI").is_none(),
            "glslangValidator is missing on CI"
        );
        return;
    };
    let f = dir.join("host.frag");
    std::fs::write(
        &f,
        format!(
            "{src}\nin vec3 l;\nout vec4 colour;\n\
             void main() {{ vec3 n = vec3(0.0, 0.0, 1.0); vec3 t = vec3(1.0, 0.0, 0.0);\n\
             colour = vec4(fibrefit_brdf(l, n, n, t), 1.0); }}\n"
        ),
    )
    .unwrap();
    let out = std::process::Command::new(glslang)
        .arg(&f)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "glslangValidator: {}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
}

#[test]
fn bad_variants_are_refused_naming_what() {
    let data = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/data_synthetic/brushed/gonio.csv"
    );
    let cases: [(&[&str], &str); 3] = [
        (
            &["--model", "gltf", "--gltf-variant", "three"],
            "--gltf-variant",
        ),
        (
            &["--model", "ward", "--gltf-variant", "threejs"],
            "knob of the gltf rung",
        ),
        (
            &["--model", "auto", "--gltf-variant", "threejs"],
            "--model gltf",
        ),
    ];
    for (args, says) in cases {
        let out = fibrefit()
            .args(["fit", data])
            .args(args)
            .arg("-q")
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{args:?}: {err}");
        assert!(err.contains(says), "{args:?}: {err}");
    }
    let dir = tempfile::tempdir().unwrap();
    let cfg = dir.path().join("c.toml");
    // with per-texel maps (solved linearly in the base colour) metallic is held at 0
    std::fs::write(
        &cfg,
        "model = \"gltf\"\n[knobs]\ngltf_variant = \"threejs\"\n[parameters]\nmetallic = { value = 0.3 }\n\
         [maps]\nkd = true\n",
    )
    .unwrap();
    let out = fibrefit()
        .args(["fit", data, "--config", cfg.to_str().unwrap(), "-q"])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(err.contains("parameters.metallic"), "{err}");
}

#[test]
fn score_of_a_threejs_result_with_metallic_is_its_eval() {
    // a result's values rendered as three.js renders them (knobs.gltf_variant = threejs) with
    // metallic > 0: score must carry the base colour squared's term as eval does
    let dir = tempfile::tempdir().unwrap();
    let csv = dir.path().join("gonio.csv");
    let text =
        "gltf_variant = \"threejs\"\nkd = [0.8, 0.5, 0.3]\nmetallic = 0.6\nroughness = 0.5\n\
                anisotropy_strength = 0.4\nsheen = 0.2\nfibre_azimuth_deg = 20\n";
    std::fs::write(&csv, synthesise(text, 400, 0.01)).unwrap();
    let out = dir.path().join("k.json");
    fibrefit()
        .args([
            "fit",
            csv.to_str().unwrap(),
            "--model",
            "gltf",
            "-q",
            "--out",
        ])
        .arg(&out)
        .assert()
        .success();
    let mut result: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&out).unwrap()).unwrap();
    assert!(result["parameters"]["metallic"]["value"].as_f64().unwrap() > 0.1);
    result["knobs"]["gltf_variant"] = "threejs".into();
    let swapped = dir.path().join("t.json");
    std::fs::write(&swapped, result.to_string()).unwrap();
    let score = fibrefit()
        .args([
            "score",
            swapped.to_str().unwrap(),
            csv.to_str().unwrap(),
            "--json",
        ])
        .output()
        .unwrap();
    assert!(
        score.status.success(),
        "{}",
        String::from_utf8_lossy(&score.stderr)
    );
    let score: serde_json::Value = serde_json::from_slice(&score.stdout).unwrap();
    let rows = |p: &std::path::Path| -> Vec<Vec<f64>> {
        let t = std::fs::read_to_string(p).unwrap();
        t.lines()
            .skip(1)
            .map(|r| r.split(',').map(|x| x.parse().unwrap()).collect())
            .collect()
    };
    let data = rows(&csv);
    let (q, e) = (dir.path().join("q.csv"), dir.path().join("e.csv"));
    let mut queries = String::from("theta_i,phi_i,theta_o,phi_o\n");
    for d in &data {
        queries.push_str(&format!("{},{},{},{}\n", d[0], d[1], d[2], d[3]));
    }
    std::fs::write(&q, queries).unwrap();
    fibrefit()
        .args(["eval", "--params", swapped.to_str().unwrap(), "--queries"])
        .args([q.to_str().unwrap(), "--out", e.to_str().unwrap(), "-q"])
        .assert()
        .success();
    let model = rows(&e);
    let mut sum = 0.0;
    for (d, m) in data.iter().zip(&model) {
        for c in 0..3 {
            sum += (m[4 + c] - d[4 + c]).powi(2);
        }
    }
    let rmse = (sum / (3 * data.len()) as f64).sqrt();
    let got = score["statistics"]["rmse"].as_f64().unwrap();
    assert!(
        (got - rmse).abs() <= 1e-9 * rmse,
        "score {got} vs eval {rmse}"
    );
}
