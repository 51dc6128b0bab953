//! Issue 11: fibre-direction spread. Spread 0 is the aligned rung bit for bit; the isotropic
//! limit does not depend on psi; reciprocity and T -> -T hold; the quadrature converges to the
//! adaptive reference as nodes grow; the spread is recovered from noisy synthetic data; and on the
//! real felt a fibre rung with spread beats Ward on held-out data.

mod common;

use common::random_pairs;
use fibrefit::model::azimuth_spread::AzimuthSpread;
use fibrefit::model::frame::DirectionPair;
use fibrefit::model::params::{ModelParams, RawParams};
use fibrefit::model::{self, Albedos, ModelId, ShadingModel};

fn params(text: &str, id: ModelId) -> ModelParams {
    let raw: RawParams = toml::from_str(text).unwrap();
    ModelParams::from_raw(&raw, id).unwrap().0
}

fn grey(b: fibrefit::model::Basis) -> f64 {
    b.brdf(&Albedos::grey(0.5, 0.3, 0.4), 0)
}

const SHAPE: &str = "kd = 0.5\nks = 0.3\nexponent = 20\nspacing = 2.6\nheight = 0.8\n";

#[test]
fn spread_zero_is_the_aligned_rung_and_isotropic_ignores_psi() {
    let pairs = random_pairs(200, 3, 0.05);
    for id in [
        ModelId::MaxNormal,
        ModelId::HastDiffuse,
        ModelId::PoulinFournier,
        ModelId::VaryingTopology,
    ] {
        let aligned = model::build(id, &params(SHAPE, id)).unwrap();
        let zero =
            model::build(id, &params(&format!("{SHAPE}azimuth_spread_deg = 0\n"), id)).unwrap();
        for p in &pairs {
            assert_eq!(aligned.basis(p), zero.basis(p), "{id}");
        }
        // isotropic: the same value whatever the fibre azimuth (the pair is given in the
        // swatch frame, so psi enters through the frame)
        let iso = |psi: f64| {
            let p = params(
                &format!("{SHAPE}azimuth_spread_deg = 180\nfibre_azimuth_deg = {psi}\n"),
                id,
            );
            (model::build(id, &p).unwrap(), psi.to_radians())
        };
        let (m0, psi0) = iso(0.0);
        for psi in [37.0, -80.0] {
            let (m, r) = iso(psi);
            for p in pairs.iter().take(40) {
                let (l, v) = (swatch(p), swatch_v(p));
                let f0 = model::brdf_at_degrees(
                    m0.as_ref(),
                    &Albedos::grey(0.5, 0.3, 0.4),
                    psi0,
                    deg(&l, &v),
                    1,
                )[0];
                let f = model::brdf_at_degrees(
                    m.as_ref(),
                    &Albedos::grey(0.5, 0.3, 0.4),
                    r,
                    deg(&l, &v),
                    1,
                )[0];
                assert!(
                    (f - f0).abs() <= 1e-12 * f0.abs().max(1e-12),
                    "{id} psi {psi}: {f} vs {f0}"
                );
            }
        }
    }
}

type V = [f64; 3];
fn swatch(p: &DirectionPair) -> V {
    [p.l.t, p.l.b, p.l.n]
}
fn swatch_v(p: &DirectionPair) -> V {
    [p.v.t, p.v.b, p.v.n]
}
/// (theta_i, phi_i, theta_o, phi_o) in degrees of two unit vectors.
fn deg(l: &V, v: &V) -> [f64; 4] {
    let a = |d: &V| {
        (
            d[2].clamp(-1.0, 1.0).acos().to_degrees(),
            d[1].atan2(d[0]).to_degrees(),
        )
    };
    let ((ti, pi), (to, po)) = (a(l), a(v));
    [ti, pi, to, po]
}

#[test]
fn spread_keeps_reciprocity_and_fibre_symmetry() {
    let pairs = random_pairs(300, 5, 0.02);
    for id in [
        ModelId::PoulinFournier,
        ModelId::VaryingTopology,
        ModelId::MaxNormal,
    ] {
        let m = model::build(
            id,
            &params(&format!("{SHAPE}azimuth_spread_deg = 35\n"), id),
        )
        .unwrap();
        for p in &pairs {
            let f = grey(m.basis(p));
            let swapped = DirectionPair::from_local([p.v.t, p.v.b, p.v.n], [p.l.t, p.l.b, p.l.n]);
            let flipped =
                DirectionPair::from_local([-p.l.t, -p.l.b, p.l.n], [-p.v.t, -p.v.b, p.v.n]);
            assert!(f.is_finite() && f >= 0.0);
            // max-normal has no viewer (MODEL.md §3): not reciprocal, with or without spread
            if id != ModelId::MaxNormal {
                assert!(
                    (grey(m.basis(&swapped)) - f).abs() <= 1e-10 * f.max(1e-10),
                    "{id} reciprocity"
                );
            }
            assert!(
                (grey(m.basis(&flipped)) - f).abs() <= 1e-10 * f.max(1e-10),
                "{id} T -> -T"
            );
        }
    }
}

#[test]
fn the_quadrature_converges_to_the_adaptive_reference() {
    let pairs = random_pairs(12, 9, 0.1);
    let p = params(SHAPE, ModelId::Reference);
    let reference = AzimuthSpread::new(model::build(ModelId::Reference, &p).unwrap(), 30.0, 1, 0.0);
    let truth: Vec<f64> = pairs.iter().map(|q| grey(reference.basis(q))).collect();
    let mut errors = Vec::new();
    for n in [4, 16, 64] {
        let pf = model::build(
            ModelId::VaryingTopology,
            &params(SHAPE, ModelId::VaryingTopology),
        )
        .unwrap();
        let m = AzimuthSpread::new(pf, 30.0, n, 0.0);
        let e = pairs
            .iter()
            .zip(&truth)
            .map(|(q, t)| ((grey(m.basis(q)) - t) / t).abs())
            .fold(0.0, f64::max);
        errors.push(e);
    }
    // the integrand has kinks (occlusion cases change with the azimuth): algebraic convergence
    eprintln!("largest relative error vs the adaptive reference, N = 4, 16, 64: {errors:?}");
    assert!(
        errors[0] > errors[1] && errors[1] > errors[2] && errors[2] < 1e-3,
        "{errors:?}"
    );
}

#[test]
fn the_spread_is_recovered_from_noisy_data() {
    let dir = tempfile::tempdir().unwrap();
    let synth = dir.path().join("s.toml");
    std::fs::write(
        &synth,
        "model = \"poulin-fournier\"\n[params]\nkd = 0.4\nks = 0.3\nexponent = 40\nspacing = 2.4\n\
         fibre_azimuth_deg = 25\nazimuth_spread_deg = 30\n[gonio]\nrandom = { count = 900, seed = 2, max_theta_deg = 80 }\n\
         [noise]\nrelative = 0.01\nseed = 4\n",
    )
    .unwrap();
    fibrefit::synth::run(
        &synth,
        &dir.path().join("d"),
        &fibrefit::progress::Progress::quiet(),
    )
    .unwrap();
    let data =
        fibrefit::load::load_data(&dir.path().join("d/gonio.csv"), &Default::default()).unwrap();
    let cfg: fibrefit::fit::config::FitConfig = toml::from_str(
        "model = \"poulin-fournier\"\n[parameters]\nspacing = { value = 3, min = 2, max = 6 }\n\
         fibre_azimuth_deg = { value = 0 }\nazimuth_spread_deg = { value = 60 }\nexponent = { value = 10, max = 1000 }\n",
    )
    .unwrap();
    let o = fibrefit::fit::fit(&data, &cfg, &fibrefit::progress::Progress::quiet()).unwrap();
    let r = o
        .records
        .iter()
        .find(|r| r.name == "azimuth_spread_deg")
        .unwrap();
    let se = r.std_error[0].expect("a standard error");
    assert!(
        (r.value[0] - 30.0).abs() < 4.0 * se + 0.5,
        "spread {} +/- {se}",
        r.value[0]
    );
    assert_eq!(
        o.quality.verdict, "fits within the noise",
        "{:?}",
        o.quality.warnings
    );
}

#[test]
fn on_real_felt_a_fibre_rung_with_spread_beats_ward() {
    // a fast version of the felt comparison: 1200 directions, poulin-fournier (with the fuzz
    // layer) against Ward, both with the log metric, scored on 600 other directions
    let auto: fibrefit::fit::config::FitConfig =
        toml::from_str("model = \"auto\"\nmetric = \"log\"\n[knobs]\nazimuth_nodes = 12\n")
            .unwrap();
    let ward = common::felt_heldout(&auto.for_rung(ModelId::Ward));
    // the fibres' surface term is grey (issue 23 item 5): the felt's coloured broad lobe, light
    // scattered inside the dyed fibres, is the fuzz layer's (without it poulin-fournier predicts
    // 0.457 against Ward's 0.419; with a coloured ks 0.327: docs/figures.md)
    let fuzzed: fibrefit::fit::config::FitConfig = toml::from_str(
        "model = \"auto\"\nmetric = \"log\"\n[knobs]\nazimuth_nodes = 12\n[parameters]\nfuzz_depth = {}\n",
    )
    .unwrap();
    let pf = common::felt_heldout(&fuzzed.for_rung(ModelId::PoulinFournier));
    eprintln!("felt held-out: ward {ward:?}; poulin-fournier {pf:?}");
    assert!(
        pf.log_error <= 0.85 * ward.log_error,
        "log error {} vs Ward {}",
        pf.log_error,
        ward.log_error
    );
    assert!(
        pf.relative_rmse <= ward.relative_rmse,
        "relative RMSE {} vs Ward {}",
        pf.relative_rmse,
        ward.relative_rmse
    );
}
