//! The white furnace of a fitted material (`api::energy`): its directional albedo at 18 views,
//! from its own importance sampler, and the fit's warning when it reflects more light than it
//! receives.

use fibrefit::api::energy::{furnace, gain_warning, STRATA};
use fibrefit::api::fit::{FitOptions, LoadFlags, Maps};
use fibrefit::api::material::Material;
use fibrefit::model::ModelId;
use std::path::Path;

/// How the fit's warning begins.
const GAIN: &str = "the material reflects more light than it receives";

fn material(dir: &Path, name: &str, text: &str) -> Material {
    let p = dir.join(format!("{name}.toml"));
    std::fs::write(&p, text).unwrap();
    Material::load(&p, None).unwrap().0
}

/// A Lambertian reflects kd at every view: the cosine sampler's weight is kd exactly.
#[test]
fn a_lambertian_furnace_is_its_albedo() {
    let dir = tempfile::tempdir().unwrap();
    let m = material(dir.path(), "lambert", "model = \"lambert\"\nkd = 0.8\n");
    let rows = furnace(&m, STRATA);
    assert_eq!(rows.len(), 18);
    for r in &rows {
        assert!((r.albedo[0] - 0.8).abs() < 1e-12, "{r:?}");
        assert!(r.se[0] < 1e-12, "{r:?}");
    }
    assert!(gain_warning(&rows, m.channels).is_none());
    // a white Lambertian under a correction of 1.3 everywhere gains energy at every view,
    // normal incidence included (albedos are bounded by 1, a correction's factor is not)
    let c = 1.3f64.ln();
    let text = format!(
        "model = \"lambert\"\nkd = 1.0\n[correction]\ndegree = 0\ncoefficients = [[{c}, {c}, {c}]]\n\
         cos_range = [0.0, 1.0]\nlog_range = [[{c}, {c}], [{c}, {c}], [{c}, {c}]]\n"
    );
    let bright = material(dir.path(), "bright", &text);
    let w = gain_warning(&furnace(&bright, STRATA), 1).expect("a warning");
    assert!(
        w.starts_with(GAIN) && w.contains("1.300") && w.contains("normal incidence"),
        "{w}"
    );
}

/// Every rung at its registry example (albedos at most 0.6, exponent 1000 where it has one)
/// keeps the energy it receives at every view, within the check's error: the check does not cry
/// wolf on the ladder's own materials.
#[test]
fn no_rung_at_its_example_gains_energy() {
    let dir = tempfile::tempdir().unwrap();
    for id in ModelId::ALL {
        if id == ModelId::Reference {
            continue;
        }
        let text = format!("model = \"{id}\"\n{}", id.rung().example_text(Some(1000.0)));
        let m = material(dir.path(), id.as_str(), &text);
        let rows = furnace(&m, STRATA);
        let most = rows.iter().map(|r| r.albedo[0]).fold(0.0, f64::max);
        eprintln!("{id}: largest directional albedo {most:.4}");
        assert!(rows
            .iter()
            .all(|r| r.albedo[0].is_finite() && r.albedo[0] >= 0.0));
        assert!(gain_warning(&rows, m.channels).is_none(), "{id}: {rows:?}");
    }
}

/// Data a user scaled wrongly (a Lambertian of 0.5 / sr: a directional albedo of pi / 2): the
/// rung's albedo stops at its bound 1, the smooth correction (log metric) makes up the rest, and
/// the fit says loudly that the material it delivers gains energy, in its warnings, its result
/// and its report.
#[test]
fn data_brighter_than_any_material_are_flagged() {
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("bright.csv");
    let mut text = String::from("theta_i,phi_i,theta_o,phi_o,brdf\n");
    let mut k = 0u64;
    for ti in [0.0, 15.0, 30.0, 45.0, 60.0, 75.0] {
        for to in [0.0, 20.0, 40.0, 60.0, 80.0] {
            for po in [0.0, 60.0, 120.0, 180.0] {
                k += 1;
                // 1 % of deterministic scatter
                let v = 0.5 * (1.0 + 0.01 * ((k * 7919 % 101) as f64 / 50.0 - 1.0));
                text += &format!("{ti},0,{to},{po},{v}\n");
            }
        }
    }
    std::fs::write(&data, text).unwrap();
    let opts = FitOptions {
        config: None,
        model: Some("lambert".into()),
        metric: Some("log".into()),
        fuzz: Some(false),
        load: LoadFlags::default(),
        maps: Maps::None,
        progress: fibrefit::progress::Progress::quiet(),
        gltf_variant: None,
        correction: None,
    };
    let run = fibrefit::api::fit::fit(&opts.request(&data).unwrap()).unwrap();
    let flagged = |w: &String| w.starts_with(GAIN) && w.contains("normal incidence");
    assert!(run.warnings.iter().any(flagged), "{:?}", run.warnings);
    assert!(
        run.result.warnings.iter().any(flagged),
        "{:?}",
        run.result.warnings
    );
    assert!(run.report_text.contains(GAIN), "{}", run.report_text);
}
