//! The exported shader against the Rust model on a real GPU driver (the machine's Vulkan adapter:
//! llvmpipe on CI, installed by `.ci/run`), its translations, and the glTF export.
//!
//! These tests fail, with the reason, on a machine without a Vulkan adapter: an export nobody
//! ran is not proven.

use assert_cmd::Command;
use fibrefit::export::shader::{self, check, gpu::Gpu, Language};
use fibrefit::model::params::{ModelParams, RawParams};
use fibrefit::model::topology::max_height;
use fibrefit::model::{self, ModelId};
use std::path::Path;
use std::sync::OnceLock;

fn fibrefit() -> Command {
    Command::cargo_bin("fibrefit").expect("binary built")
}

/// One GPU device for the whole binary (tests in parallel share it).
fn gpu() -> &'static Gpu {
    static GPU: OnceLock<Gpu> = OnceLock::new();
    GPU.get_or_init(|| {
        Gpu::new().unwrap_or_else(|e| {
            panic!(
                "these tests run the exported shader on a GPU driver and found none: {e:#}. \
                 `.ci/run` installs llvmpipe (apt-get install mesa-vulkan-drivers)"
            )
        })
    })
}

/// Parameters from TOML text (relative paths from the repository root).
fn params(text: &str) -> (ModelId, ModelParams) {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("p.toml");
    let text = text.replace("@ROOT", env!("CARGO_MANIFEST_DIR"));
    std::fs::write(&path, text).unwrap();
    let raw = RawParams::load(&path).unwrap();
    let id: ModelId = raw.model.as_deref().unwrap().parse().unwrap();
    let (p, _) = ModelParams::from_raw(&raw, id).unwrap();
    (id, p)
}

/// Every rung, the optional components, and the extremes the Rust tests cover (spacing 2, both
/// elevation limits, exponent 1e4, isotropic spread).
const RUNGS: &[(&str, &str)] = &[
    ("lambert", "model = 'lambert'\nkd = [0.5, 0.3, 0.2]"),
    (
        "poulin-fournier, spread, smooth correction of degree 3",
        "model = 'poulin-fournier'\nkd = [0.5, 0.35, 0.2]\nks = 0.2\nexponent = 8\nazimuth_spread_deg = 20\n\
         [correction]\ndegree = 3\ncos_range = [0.15, 0.98]\n\
         log_range = [[-0.8, 0.9], [-0.6, 0.7], [-1.0, 1.1]]\n\
         coefficients = [[0.1, 0.05, -0.1], [0.2, 0.1, 0.0], [-0.15, 0.1, 0.05], [0.05, -0.1, 0.1], \
         [0.1, 0.1, 0.1], [-0.05, 0.02, 0.03], [0.08, -0.04, 0.02], [0.03, 0.06, -0.05], \
         [-0.07, 0.02, 0.04], [0.02, -0.03, 0.05], [0.06, 0.01, -0.02], [-0.04, 0.05, 0.01], \
         [0.05, -0.02, 0.03]]",
    ),
    (
        "max-normal, spread, Fresnel",
        "model = 'max-normal'\nkd = 0.4\nks = 0.3\nexponent = 40\nazimuth_spread_deg = 25\nfresnel_ior = 1.5",
    ),
    (
        "max-normal, exponent 1e4",
        "model = 'max-normal'\nkd = 0.4\nks = 0.3\nexponent = 1e4",
    ),
    (
        "hast-diffuse, spread",
        "model = 'hast-diffuse'\nkd = 0.6\nazimuth_spread_deg = 40\nfibre_azimuth_deg = 30",
    ),
    (
        "ward",
        "model = 'ward'\nrho_d = 0.3\nrho_s = [0.2, 0.1, 0.05]\nalpha_x = 0.08\nalpha_y = 0.5",
    ),
    (
        "poulin-fournier, spacing 2, Fresnel, fuzz",
        "model = 'poulin-fournier'\nkd = 0.5\nks = 0.3\nsubstrate_albedo = 0.2\nexponent = 60\nspacing = 2\nfresnel_ior = 1.6\nfuzz = 0.5\nfuzz_depth = 0.2\nfuzz_asymmetry = 0.6",
    ),
    (
        "poulin-fournier, wide gaps",
        "model = 'poulin-fournier'\nkd = 0.5\nks = 0.3\nsubstrate_albedo = 0.8\nexponent = 15\nspacing = 7",
    ),
    (
        "varying-topology, silk (topology map)",
        "model = 'varying-topology'\nkd = [0.55, 0.35, 0.30]\nks = 0.25\nexponent = 60\nspacing = 2\nheight = 0.9\nmap_scale = 0.25\ntopology_map = '@ROOT/data_synthetic/silk/topology.png'",
    ),
    (
        "varying-topology, upper elevation limit, exponent 1e4, spread, fuzz",
        "model = 'varying-topology'\nkd = 0.5\nks = 0.3\nexponent = 1e4\nspacing = 2\nelevation_deg = 60\nazimuth_spread_deg = 20\nfuzz = 0.4\nfuzz_depth = 0.3\nfuzz_asymmetry = 0.5",
    ),
    (
        "varying-topology, isotropic spread, uniform heights",
        "model = 'varying-topology'\nkd = [0.5, 0.3, 0.2]\nks = 0.3\nexponent = 40\nspacing = 3\nheight = 0.5\nmap_scale = 1\nazimuth_spread_deg = 180\nsubstrate_albedo = 0.7\nhistogram_bins = 8\nazimuth_nodes = 8",
    ),
    // the renderers' materials: Cycles' tables read between their nodes, the sheen's skew at
    // the range's low end, IOR level and tint remapping the Fresnel
    (
        "principled, anisotropic, IOR level, tint",
        "model = 'principled'\nkd = [0.5, 0.3, 0.2]\nroughness = 0.23\nanisotropic = 0.85\nior = 1.45\nspecular_ior_level = 0.7\nspecular_tint = 0.8\nsheen_weight = 0.9\nsheen_roughness = 0.3\nfibre_azimuth_deg = 30",
    ),
    (
        "principled, rough and isotropic, no sheen",
        "model = 'principled'\nkd = 0.6\nroughness = 1\nanisotropic = 0\nior = 1.6\nsheen_weight = 0",
    ),
    (
        "openpbr, anisotropic, half specular weight",
        "model = 'openpbr'\nkd = [0.5, 0.3, 0.2]\nspecular_weight = 0.5\nspecular_roughness = 0.2\nspecular_roughness_anisotropy = 0.9\nspecular_ior = 1.6\nfuzz_weight = 0.8\nfuzz_roughness = 0.05\nfibre_azimuth_deg = 30",
    ),
];

#[test]
fn every_rung_equals_the_rust_model_on_the_gpu_within_f32_limits() {
    let gpu = gpu();
    eprintln!("adapter: {}", gpu.adapter);
    for (name, text) in RUNGS {
        let (id, p) = params(text);
        let src = shader::wgsl(id, &p, &[name.to_string()]).unwrap();
        // 10 000 random pairs and the extremes
        let cases = check::cases(10_000, 3, max_height(p.spacing));
        let (a, bound) = check::on_gpu(gpu, &src, id, &p, &cases).unwrap();
        eprintln!(
            "{name}: p99 {:.2e} (bound {:.1e}), max {:.2e}, worst/tolerance {:.3}",
            a.p99_relative, bound.p99, a.max_relative, a.worst_over_tolerance
        );
        assert!(
            bound.holds(&a),
            "{name}: {a:?} beyond {bound:?}; case {:?}",
            cases[a.worst.0]
        );
        // away from the horizon and the lobe's conditioning the agreement is much tighter than
        // the bound: typical values agree to ~1e-5
        if p.exponent <= 100.0 {
            assert!(a.p99_relative < 1e-4, "{name}: {a:?}");
        }
    }
}

/// Every registered rung with a shader section, at its registry example: a new rung is checked
/// on the GPU driver without being listed here.
#[test]
fn every_registered_rung_with_a_shader_equals_the_rust_model_at_its_example() {
    let gpu = gpu();
    for id in ModelId::ALL {
        let text = format!("model = '{id}'\n{}", id.rung().example_text(Some(60.0)));
        let (id, p) = params(&text);
        if matches!(
            id.rung().shader,
            fibrefit::model::rung::ShaderSection::None(_)
        ) {
            assert!(shader::wgsl(id, &p, &[]).is_err(), "{id} has no shader");
            continue;
        }
        let src = shader::wgsl(id, &p, &[id.to_string()]).unwrap();
        let cases = check::cases(10_000, 5, max_height(p.spacing));
        let (a, bound) = check::on_gpu(gpu, &src, id, &p, &cases).unwrap();
        assert!(bound.holds(&a), "{id}: {a:?} beyond {bound:?}");
    }
}

#[test]
fn reciprocity_and_t_to_minus_t_hold_in_the_shader_output() {
    let gpu = gpu();
    // max-normal and hast-diffuse have no viewer in their diffuse term, and the renderers'
    // materials weight their layers by the view's albedos: not reciprocal (in Rust either);
    // T -> -T holds for every rung
    for text in [
        RUNGS[1].1,
        RUNGS[4].1,
        RUNGS[5].1,
        RUNGS[7].1,
        RUNGS[RUNGS.len() - 3].1,
        RUNGS[RUNGS.len() - 1].1,
    ] {
        let (id, p) = params(text);
        let src = shader::wgsl(id, &p, &[]).unwrap();
        let base = check::cases(3000, 11, max_height(p.spacing));
        let swapped: Vec<_> = base
            .iter()
            .map(|c| check::Case {
                l: c.v,
                v: c.l,
                ..*c
            })
            .collect();
        let flipped: Vec<_> = base
            .iter()
            .map(|c| check::Case {
                t: c.t.map(|x| -x),
                // the azimuth offset turns the tangent; -T turned by the same angle is -(T turned)
                ..*c
            })
            .collect();
        let (o, s, f) = (
            gpu.evaluate(&src, &base).unwrap(),
            gpu.evaluate(&src, &swapped).unwrap(),
            gpu.evaluate(&src, &flipped).unwrap(),
        );
        // each difference against the equality bound's tolerance for the case (the grazing
        // allowance included: the two sides of a flip take different f32 roundings)
        let bound = check::Bound::for_exponent(p.exponent);
        let mut worst: (f64, f64) = (0.0, 0.0);
        let mut flip_away: f64 = 0.0;
        let peak = o
            .iter()
            .flat_map(|x| x.brdf)
            .fold(0.0f32, |a, b| a.max(b.abs())) as f64;
        for (((a, b), c), case) in o.iter().zip(&s).zip(&f).zip(&base) {
            let nz = |w: [f32; 3]| (w[0] * case.n[0] + w[1] * case.n[1] + w[2] * case.n[2]) as f64;
            let min_cos = nz(case.l).min(nz(case.v));
            if min_cos <= 0.0 {
                continue;
            }
            let tol = bound.case_tolerance(min_cos);
            for k in 0..3 {
                let x = a.brdf[k] as f64;
                let scale = x.abs().max(1e-4 * peak);
                worst.0 = worst.0.max((b.brdf[k] as f64 - x).abs() / scale / tol);
                let flip = (c.brdf[k] as f64 - x).abs() / scale;
                worst.1 = worst.1.max(flip / tol);
                if min_cos >= 0.05 {
                    flip_away = flip_away.max(flip);
                }
            }
        }
        eprintln!(
            "{id}: reciprocity {:.2e}, T -> -T {:.2e} of the tolerance; T -> -T away from the horizon {flip_away:.1e}",
            worst.0, worst.1
        );
        let reciprocal = id.is_cross_section() || id == ModelId::Ward;
        assert!(!reciprocal || worst.0 <= 1.0, "{id}: reciprocity {worst:?}");
        assert!(worst.1 <= 1.0, "{id}: T -> -T {worst:?}");
        assert!(
            flip_away < 1e-4,
            "{id}: T -> -T away from the horizon {flip_away}"
        );
        if !reciprocal {
            continue;
        }
        // away from the horizon, reciprocity to f32 precision
        let mut away: f64 = 0.0;
        for ((a, b), c) in o.iter().zip(&s).zip(&base) {
            let nz = |w: [f32; 3]| w[0] * c.n[0] + w[1] * c.n[1] + w[2] * c.n[2];
            if nz(c.l).min(nz(c.v)) < 0.05 {
                continue;
            }
            for k in 0..3 {
                let x = a.brdf[k] as f64;
                away = away.max((b.brdf[k] as f64 - x).abs() / x.abs().max(1e-4 * peak));
            }
        }
        assert!(
            away < 2e-3,
            "{id}: reciprocity away from the horizon {away}"
        );
    }
}

#[test]
fn a_uniform_buffer_of_the_parameters_gives_the_baked_values_bit_for_bit() {
    let gpu = gpu();
    for (_, text) in [RUNGS[4], RUNGS[7], RUNGS[9]] {
        let (id, p) = params(text);
        let src = shader::wgsl(id, &p, &[]).unwrap();
        // a host shader that takes the parameters from its own uniform: fibrefit_params()
        // returns the uniform instead of the constants
        let head = "fn fibrefit_params() -> FibrefitParams {\n    return FibrefitParams(";
        assert!(src.contains(head));
        let hosted = src.replace(
            head,
            "@group(0) @binding(2) var<uniform> host_material: FibrefitParams;\n\
             fn fibrefit_params() -> FibrefitParams {\n    return host_material;\n}\n\
             fn host_baked_params() -> FibrefitParams {\n    return FibrefitParams(",
        );
        let bytes = shader::params_uniform(id, &p).unwrap();
        let cases = check::cases(2000, 5, max_height(p.spacing));
        let baked = gpu.evaluate(&src, &cases).unwrap();
        let uniform = gpu
            .evaluate_with_uniform(&hosted, &cases, Some(&bytes))
            .unwrap();
        assert_eq!(baked, uniform, "{id}");
    }
}

/// Lines that are not comments.
fn code(src: &str) -> String {
    src.lines()
        .filter(|l| !l.trim_start().starts_with("//"))
        .collect::<Vec<_>>()
        .join("\n")
}

fn glslang() -> Option<std::path::PathBuf> {
    let found = std::env::var_os("PATH").and_then(|paths| {
        std::env::split_paths(&paths)
            .map(|d| d.join("glslangValidator"))
            .find(|p| p.is_file())
    });
    if found.is_none() && std::env::var_os("CI").is_some() {
        panic!("glslangValidator is missing on CI: `.ci/run` installs glslang-tools");
    }
    found
}

#[test]
fn translations_are_libraries_that_compile_inside_a_host_shader() {
    for (name, text) in RUNGS {
        let (id, p) = params(text);
        let wgsl = shader::wgsl(id, &p, &[]).unwrap();
        // no entry points or bindings of its own
        let c = code(&wgsl);
        for bad in [
            "@compute",
            "@fragment",
            "@vertex",
            "@group",
            "@binding",
            "var<",
        ] {
            assert!(!c.contains(bad), "{name}: WGSL has {bad}");
        }
        // a host fragment shader with its own binding at group 0, binding 0 compiles with it
        let host = format!(
            "{wgsl}\n@group(0) @binding(0) var<uniform> material: FibrefitParams;\n\
             @fragment fn main(@location(0) l: vec3<f32>) -> @location(0) vec4<f32> {{\n\
             let n = vec3<f32>(0.0, 0.0, 1.0); let t = vec3<f32>(1.0, 0.0, 0.0);\n\
             return vec4<f32>(fibrefit_brdf(l, n, n, t) + fibrefit_brdf_with(material, l, n, n, t)\n\
             + fibrefit_brdf_at(l, n, n, t, 0.5, 0.1), 1.0);\n}}\n"
        );
        shader::validate(&host).unwrap_or_else(|e| panic!("{name}: {e:#}"));
        for lang in [Language::Glsl, Language::Hlsl, Language::Msl] {
            let t = shader::translate(&wgsl, lang).unwrap();
            let c = code(&t);
            for fun in [
                "fibrefit_brdf(",
                "fibrefit_brdf_at(",
                "fibrefit_basis(",
                "fibrefit_basis_at(",
                "fibrefit_brdf_with(",
            ] {
                assert!(c.contains(fun), "{name} {lang:?}: no {fun}");
            }
            let bad: &[&str] = match lang {
                Language::Glsl | Language::GlslEs => {
                    &["void main", "layout(", "#version", "buffer "]
                }
                Language::Hlsl => &["[numthreads", "register(", "RWByteAddressBuffer"],
                Language::Msl => &["kernel ", "[[buffer", "[[thread_position"],
                Language::Wgsl => &[],
            };
            for b in bad {
                assert!(!c.contains(b), "{name} {lang:?}: has {b}");
            }
            if lang == Language::Glsl {
                if let Some(glslang) = glslang() {
                    let dir = tempfile::tempdir().unwrap();
                    let f = dir.path().join("host.frag");
                    std::fs::write(
                        &f,
                        format!(
                            "#version 450 core\n{t}\nlayout(location = 0) in vec3 l;\n\
                             layout(location = 0) out vec4 colour;\n\
                             void main() {{ vec3 n = vec3(0.0, 0.0, 1.0); vec3 tt = vec3(1.0, 0.0, 0.0);\n\
                             colour = vec4(fibrefit_brdf(l, n, n, tt) + fibrefit_brdf_at(l, n, n, tt, 0.5, 0.1), 1.0); }}\n"
                        ),
                    )
                    .unwrap();
                    let out = std::process::Command::new(glslang)
                        .arg(&f)
                        .output()
                        .unwrap();
                    assert!(
                        out.status.success(),
                        "{name}: glslang rejects the GLSL: {}",
                        String::from_utf8_lossy(&out.stdout)
                    );
                }
            }
        }
    }
}

#[test]
fn the_glsl_es_translation_compiles_as_a_webgl2_fragment_shader() {
    // `--shader glsl-es`: GLSL ES 3.00 with its #version and precision lines first, for
    // three.js's ShaderMaterial / RawShaderMaterial; every rung, and the gltf rung's threejs
    // variant
    let gltf = "model = 'gltf'\nkd = [0.5, 0.3, 0.2]\nmetallic = 0.4\nroughness = 0.35\n\
                anisotropy_strength = 0.6\nsheen = 0.4\nfibre_azimuth_deg = 30";
    let threejs = format!("{gltf}\ngltf_variant = 'threejs'");
    let mut rungs = RUNGS.to_vec();
    rungs.extend([("gltf", gltf), ("gltf, threejs", threejs.as_str())]);
    for (name, text) in rungs {
        let (id, p) = params(text);
        let wgsl = shader::wgsl(id, &p, &[]).unwrap();
        let t = shader::translate(&wgsl, Language::GlslEs).unwrap();
        assert!(t.starts_with(shader::GLSL_ES_PRELUDE), "{name}");
        let c = code(&t);
        for bad in ["void main", "layout(", "_vs2fs", "_fs2p", "buffer "] {
            assert!(!c.contains(bad), "{name}: has {bad}");
        }
        let Some(glslang) = glslang() else { continue };
        let dir = tempfile::tempdir().unwrap();
        let f = dir.path().join("host.frag");
        std::fs::write(
            &f,
            format!(
                "{t}\nin vec3 l;\nout vec4 colour;\n\
                 void main() {{ vec3 n = vec3(0.0, 0.0, 1.0); vec3 tt = vec3(1.0, 0.0, 0.0);\n\
                 colour = vec4(fibrefit_brdf(l, n, n, tt) + fibrefit_brdf_at(l, n, n, tt, 0.5, 0.1), 1.0); }}\n"
            ),
        )
        .unwrap();
        let out = std::process::Command::new(glslang)
            .arg(&f)
            .output()
            .unwrap();
        assert!(
            out.status.success(),
            "{name}: glslang rejects the GLSL ES: {}",
            String::from_utf8_lossy(&out.stdout)
        );
    }
}

#[test]
fn fitted_results_of_every_shipped_dataset_export_and_check_from_the_cli() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let dir = tempfile::tempdir().unwrap();
    for data in ["silk", "brushed", "loose"] {
        let result = dir.path().join(format!("{data}.json"));
        fibrefit()
            .args(["fit", "-q"])
            .arg(root.join(format!("data_synthetic/{data}/gonio.csv")))
            .arg("--config")
            .arg(root.join(format!("configs/fit_{data}.toml")))
            .arg("--out")
            .arg(&result)
            .assert()
            .success();
        let out = dir.path().join(format!("{data}.wgsl"));
        let assert = fibrefit()
            .args(["export"])
            .arg(&result)
            .args(["--shader", "wgsl", "--check", "--out"])
            .arg(&out)
            .assert()
            .success();
        let stderr = String::from_utf8_lossy(&assert.get_output().stderr).to_string();
        assert!(stderr.contains("checked on"), "{stderr}");
        // and at the result's own 20 check values
        assert!(stderr.contains("the result's 20 check values"), "{stderr}");
        let text = std::fs::read_to_string(&out).unwrap();
        assert!(
            text.contains("// checked on") && text.contains("sha256"),
            "{data}"
        );
        for lang in ["glsl", "hlsl", "msl"] {
            let o = dir.path().join(format!("{data}.{lang}"));
            fibrefit()
                .args(["export", "-q"])
                .arg(&result)
                .args(["--shader", lang, "--out"])
                .arg(&o)
                .assert()
                .success();
            assert!(std::fs::read_to_string(&o)
                .unwrap()
                .contains("fibrefit_brdf_at"));
        }
        let glb = dir.path().join(format!("{data}.glb"));
        fibrefit()
            .args(["export", "-q"])
            .arg(&result)
            .args(["--gltf"])
            .arg(&glb)
            .assert()
            .success();
        // the gltf material the fit recorded, fitted to the same data (not a conversion)
        let r: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(&result).unwrap()).unwrap();
        let recorded = r["renderer_materials"]
            .as_array()
            .unwrap()
            .iter()
            .find(|m| m["model"] == "gltf")
            .unwrap();
        let bytes = std::fs::read(&glb).unwrap();
        let raw: serde_json::Value = {
            let glb = gltf::binary::Glb::from_slice(&bytes).unwrap();
            serde_json::from_slice(&glb.json).unwrap()
        };
        let e = &raw["materials"][0]["extras"]["fibrefit"];
        assert!(
            e["route"].as_str().unwrap().starts_with("recorded"),
            "{data}: {e}"
        );
        assert_eq!(
            e["error_against_data"]["relative_rms_error"], recorded["statistics"]["relative_rmse"],
            "{data}"
        );
        let rough = raw["materials"][0]["pbrMetallicRoughness"]["roughnessFactor"]
            .as_f64()
            .unwrap();
        let want = recorded["parameters"]["roughness"]["value"]
            .as_f64()
            .unwrap();
        assert!((rough - want).abs() < 1e-6, "{data}: {rough} vs {want}");
    }
}

/// The renderers' own materials fitted to data (issue 37 item 1): `principled` and `openpbr`
/// fits of the shipped brushed table export shader code checked on the GPU driver against the
/// model and at the result's own check values, and `view` draws them with that shader.
#[test]
fn fitted_renderer_materials_export_checked_shaders_and_view_pages() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let dir = tempfile::tempdir().unwrap();
    for model in ["principled", "openpbr"] {
        let result = dir.path().join(format!("{model}.json"));
        fibrefit()
            .args(["fit", "-q", "--model", model])
            .arg(root.join("data_synthetic/brushed/gonio.csv"))
            .arg("--out")
            .arg(&result)
            .assert()
            .success();
        let out = dir.path().join(format!("{model}.glsl"));
        let assert = fibrefit()
            .args(["export"])
            .arg(&result)
            .args(["--shader", "glsl", "--check", "--out"])
            .arg(&out)
            .assert()
            .success();
        let stderr = String::from_utf8_lossy(&assert.get_output().stderr).to_string();
        assert!(stderr.contains("checked on"), "{model}: {stderr}");
        assert!(
            stderr.contains("the result's 20 check values"),
            "{model}: {stderr}"
        );
        let text = std::fs::read_to_string(&out).unwrap();
        assert!(text.contains(&format!("fibrefit_{model}(")), "{model}");
        let page = dir.path().join(format!("{model}.html"));
        fibrefit()
            .args(["view", "-q"])
            .arg(&result)
            .arg("--out")
            .arg(&page)
            .assert()
            .success();
        let html = std::fs::read_to_string(&page).unwrap();
        assert!(html.contains(&format!("fibrefit_{model}(")), "{model}");
    }
}

/// Read a written GLB back with the gltf crate and check what renderers rely on.
fn check_glb(path: &Path, vertices: usize) -> serde_json::Value {
    let bytes = std::fs::read(path).unwrap();
    let g = gltf::Gltf::from_slice(&bytes).expect("a valid glTF");
    let blob = g.blob.as_ref().expect("a BIN chunk");
    let prim = g.meshes().next().unwrap().primitives().next().unwrap();
    let reader = prim.reader(|_| Some(blob));
    let pos: Vec<[f32; 3]> = reader.read_positions().unwrap().collect();
    let normals: Vec<[f32; 3]> = reader.read_normals().unwrap().collect();
    let tangents: Vec<[f32; 4]> = reader.read_tangents().unwrap().collect();
    let uvs: Vec<[f32; 2]> = reader.read_tex_coords(0).unwrap().into_f32().collect();
    assert_eq!(pos.len(), vertices);
    assert_eq!(normals.len(), vertices);
    assert_eq!(tangents.len(), vertices);
    assert_eq!(uvs.len(), vertices);
    let idx: Vec<u32> = reader.read_indices().unwrap().into_u32().collect();
    assert!(idx.len() % 3 == 0 && idx.iter().all(|&i| (i as usize) < vertices));
    for (n, t) in normals.iter().zip(&tangents) {
        let nn = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
        let tn = (t[0] * t[0] + t[1] * t[1] + t[2] * t[2]).sqrt();
        assert!((nn - 1.0).abs() < 1e-5 && (tn - 1.0).abs() < 1e-5);
        assert!((n[0] * t[0] + n[1] * t[1] + n[2] * t[2]).abs() < 1e-5);
        assert!(t[3] == 1.0 || t[3] == -1.0);
    }
    assert!(uvs
        .iter()
        .all(|u| u.iter().all(|x| (0.0..=1.0).contains(x))));
    let mat = prim.material();
    let pbr = mat.pbr_metallic_roughness();
    assert_eq!(pbr.metallic_factor(), 0.0);
    assert!((0.0..=1.0).contains(&pbr.roughness_factor()));
    assert!(pbr
        .base_color_factor()
        .iter()
        .all(|c| (0.0..=1.0).contains(c)));
    // the extensions' fields, from the JSON chunk
    let raw: serde_json::Value = {
        let glb = gltf::binary::Glb::from_slice(&bytes).unwrap();
        serde_json::from_slice(&glb.json).unwrap()
    };
    let used: Vec<&str> = raw["extensionsUsed"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_str().unwrap())
        .collect();
    assert!(used.contains(&"KHR_materials_anisotropy") && used.contains(&"KHR_materials_ior"));
    let m = &raw["materials"][0];
    let an = &m["extensions"]["KHR_materials_anisotropy"];
    let s = an["anisotropyStrength"].as_f64().unwrap();
    assert!((0.0..=1.0).contains(&s));
    assert!(an["anisotropyRotation"].as_f64().unwrap().is_finite());
    assert!(
        m["extensions"]["KHR_materials_ior"]["ior"]
            .as_f64()
            .unwrap()
            >= 1.0
    );
    let e = &m["extras"]["fibrefit"];
    let rel = e["relative_rms_error"].as_f64().unwrap();
    assert!((0.0..1.0).contains(&rel), "{e}");
    assert!(e["relative_rms_error_without_anisotropy"].as_f64().unwrap() >= rel - 1e-12);
    // the sheen layer is there exactly when it gains 10 % of the error
    let (with, without) = (
        e["relative_rms_error_with_sheen"].as_f64().unwrap(),
        e["relative_rms_error_without_sheen"].as_f64().unwrap(),
    );
    let sheen = &m["extensions"]["KHR_materials_sheen"];
    if sheen.is_null() {
        assert!(with > 0.9 * without && rel == without, "{e}");
        assert!(!used.contains(&"KHR_materials_sheen"));
    } else {
        assert!(with <= 0.9 * without && rel == with, "{e}");
        assert!(used.contains(&"KHR_materials_sheen"));
        let c = sheen["sheenColorFactor"].as_array().unwrap();
        assert!(c.len() == 3 && c.iter().all(|x| (0.0..=1.0).contains(&x.as_f64().unwrap())));
        assert!((0.0..=1.0).contains(&sheen["sheenRoughnessFactor"].as_f64().unwrap()));
    }
    raw
}

#[test]
fn gltf_previews_of_every_object() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let dir = tempfile::tempdir().unwrap();
    let silk = root.join("configs/silk_params.toml");
    for (object, vertices) in [
        ("torus", 129 * 65),
        ("sphere", 97 * 49),
        ("swatch", 17 * 17),
    ] {
        let glb = dir.path().join(format!("{object}.glb"));
        fibrefit()
            .args(["export", "-q"])
            .arg(&silk)
            .args(["--gltf"])
            .arg(&glb)
            .args(["--object", object])
            .assert()
            .success();
        check_glb(&glb, vertices);
    }
    // an OBJ: a cylinder, whose curvature-aligned tangents run round it (k1 = 1/r)
    let mut obj = String::new();
    let (nu, nv) = (48, 8);
    for j in 0..=nv {
        for i in 0..nu {
            let a = std::f64::consts::TAU * i as f64 / nu as f64;
            obj += &format!(
                "v {} {} {}\nvt {} {}\n",
                a.cos(),
                a.sin(),
                j as f64 / nv as f64,
                i as f64 / nu as f64,
                j as f64 / nv as f64
            );
        }
    }
    let id = |i: usize, j: usize| j * nu + (i % nu) + 1;
    for j in 0..nv {
        for i in 0..nu {
            let (a, b, c, d) = (id(i, j), id(i + 1, j), id(i + 1, j + 1), id(i, j + 1));
            obj += &format!("f {a}/{a} {b}/{b} {c}/{c} {d}/{d}\n");
        }
    }
    let obj_path = dir.path().join("cyl.obj");
    std::fs::write(&obj_path, obj).unwrap();
    let glb = dir.path().join("cyl.glb");
    fibrefit()
        .args(["export", "-q"])
        .arg(&silk)
        .arg("--gltf")
        .arg(&glb)
        .arg("--object")
        .arg(&obj_path)
        .assert()
        .success();
    check_glb(&glb, nu * (nv + 1));
    let bytes = std::fs::read(&glb).unwrap();
    let g = gltf::Gltf::from_slice(&bytes).unwrap();
    let blob = g.blob.as_ref().unwrap();
    let prim = g.meshes().next().unwrap().primitives().next().unwrap();
    let reader = prim.reader(|_| Some(blob));
    let pos: Vec<[f32; 3]> = reader.read_positions().unwrap().collect();
    let tangents: Vec<[f32; 4]> = reader.read_tangents().unwrap().collect();
    // interior rows: horizontal tangents (round the cylinder)
    for (p, t) in pos.iter().zip(&tangents) {
        if p[2] > 0.2 && p[2] < 0.8 {
            assert!(t[2].abs() < 0.05, "{p:?} {t:?}");
        }
    }
}

/// A glTF material as a rung (diffuse = (1 - F)/pi per unit base colour, specular = F D V with
/// weight 1): the fit must find it again.
struct PbrRung(fibrefit::fit::gltf_material::PbrMaterial);

impl model::ShadingModel for PbrRung {
    fn rung(&self) -> &'static model::Rung {
        ModelId::Ward.rung()
    }
    fn basis_above_horizon(&self, pair: &model::DirectionPair) -> model::Basis {
        let m = &self.0;
        let (spec, diff) = fibrefit::fit::gltf_material::pbr_terms(
            m.roughness,
            m.anisotropy_strength,
            m.anisotropy_rotation,
            m.ior,
            pair,
        );
        model::Basis {
            diffuse: diff,
            specular: spec,
            ..Default::default()
        }
    }
}

#[test]
fn the_gltf_material_fit_recovers_a_gltf_material_and_states_its_error_honestly() {
    use fibrefit::fit::gltf_material::{fit, PbrMaterial};
    let truth = PbrMaterial {
        base_color: [0.6, 0.4, 0.2],
        roughness: 0.35,
        anisotropy_strength: 0.7,
        anisotropy_rotation: std::f64::consts::FRAC_PI_2,
        ior: 1.8,
        sheen: None,
    };
    let albedos = model::Albedos {
        diffuse: truth.base_color,
        specular: [1.0; 3],
        substrate: [0.0; 3],
        fuzz: [0.0; 3],
        rgb: true,
    };
    let f = fit(&PbrRung(truth), &albedos, 3).unwrap();
    let m = f.material;
    assert!(f.relative_rms_error < 1e-3, "{f:?}");
    assert!((m.roughness - truth.roughness).abs() < 0.01, "{m:?}");
    assert!(
        (m.anisotropy_strength - truth.anisotropy_strength).abs() < 0.02,
        "{m:?}"
    );
    assert!((m.ior - truth.ior).abs() < 0.05, "{m:?}");
    for c in 0..3 {
        assert!(
            (m.base_color[c] - truth.base_color[c]).abs() < 0.01,
            "{m:?}"
        );
    }
    // on a fibre model, the stated error holds on directions the fit never saw
    let (id, p) = params(RUNGS[7].1);
    let rung = model::build(id, &p).unwrap();
    let f = fit(rung.as_ref(), &p.albedos, 1).unwrap();
    let (mut num, mut den) = (0.0, 0.0);
    let mut s = 99u64;
    let mut u = || {
        s ^= s << 13;
        s ^= s >> 7;
        s ^= s << 17;
        (s >> 11) as f64 / (1u64 << 53) as f64
    };
    let cos_max = 80f64.to_radians().cos();
    for _ in 0..3000 {
        let mut dir = || {
            let z = cos_max + (1.0 - cos_max) * u();
            let r = (1.0 - z * z).sqrt();
            let ph = std::f64::consts::TAU * u();
            [r * ph.cos(), r * ph.sin(), z]
        };
        let pair = model::DirectionPair::from_local(dir(), dir());
        let b = rung.basis(&pair);
        let g = fibrefit::fit::gltf_material::pbr_brdf(&f.material, &pair);
        for (c, gc) in g.iter().enumerate() {
            let y = b.brdf(&p.albedos, c) * pair.l.n;
            num += ((gc * pair.l.n) - y).powi(2);
            den += y * y;
        }
    }
    let fresh = (num / den).sqrt();
    eprintln!(
        "stated {:.3}, on fresh directions {fresh:.3}",
        f.relative_rms_error
    );
    assert!(
        (fresh / f.relative_rms_error - 1.0).abs() < 0.3,
        "{fresh} vs {f:?}"
    );
    // anisotropy along the fibres' cross-section helps a fibre model
    assert!(f.relative_rms_error < f.isotropic_relative_rms_error);
}

#[test]
fn bad_input_exits_2_and_writes_nothing() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let out = d.join("out.wgsl");
    std::fs::write(&out, "keep").unwrap();
    let run = |args: &[&str], needle: &str| {
        let a = fibrefit().current_dir(d).args(args).assert().code(2);
        let err = String::from_utf8_lossy(&a.get_output().stderr).to_string();
        assert!(
            err.contains(needle),
            "{args:?}: wanted '{needle}' in: {err}"
        );
        assert_eq!(std::fs::read_to_string(&out).unwrap(), "keep", "{args:?}");
        assert!(
            !d.join("new.wgsl").exists() && !d.join("new.glb").exists(),
            "{args:?}"
        );
    };
    // a result of a future schema
    let result = d.join("r.json");
    fibrefit()
        .args(["fit", "-q"])
        .arg(root.join("data_synthetic/loose/gonio.csv"))
        .arg("--config")
        .arg(root.join("configs/fit_loose.toml"))
        .arg("--out")
        .arg(&result)
        .assert()
        .success();
    let text = std::fs::read_to_string(&result).unwrap();
    std::fs::write(
        d.join("future.json"),
        text.replace("fibrefit-result/1", "fibrefit-result/2"),
    )
    .unwrap();
    run(
        &[
            "export",
            "future.json",
            "--shader",
            "wgsl",
            "--out",
            "out.wgsl",
        ],
        "fibrefit-result/2",
    );
    run(&["export", "future.json", "--gltf", "new.glb"], "schema");
    // an unknown rung, by flag and in the file
    run(
        &[
            "export", "r.json", "--model", "velvet", "--shader", "wgsl", "--out", "out.wgsl",
        ],
        "unknown model id 'velvet'",
    );
    std::fs::write(d.join("v.toml"), "model = 'velvet'\nkd = 0.5\n").unwrap();
    run(
        &["export", "v.toml", "--shader", "wgsl", "--out", "out.wgsl"],
        "velvet",
    );
    // the reference has no shader
    std::fs::write(
        d.join("ref.toml"),
        "model = 'reference'\nkd = 0.5\nks = 0.2\nexponent = 20\n",
    )
    .unwrap();
    run(
        &[
            "export", "ref.toml", "--shader", "wgsl", "--out", "out.wgsl",
        ],
        "reference",
    );
    // a missing topology map
    std::fs::write(
        d.join("m.toml"),
        "model = 'varying-topology'\nkd = 0.5\nks = 0.2\nexponent = 20\nmap_scale = 0.3\ntopology_map = 'missing.png'\n",
    )
    .unwrap();
    run(
        &["export", "m.toml", "--shader", "wgsl", "--out", "new.wgsl"],
        "missing.png",
    );
    run(&["export", "m.toml", "--gltf", "new.glb"], "missing.png");
    // a missing result, an unknown language, a wrong glTF name, an output that is the input
    run(
        &[
            "export",
            "nothere.json",
            "--shader",
            "wgsl",
            "--out",
            "new.wgsl",
        ],
        "nothere.json",
    );
    run(
        &["export", "r.json", "--shader", "spirv", "--out", "new.wgsl"],
        "unknown shader language",
    );
    run(&["export", "r.json", "--gltf", "new.gltf"], ".glb");
    run(
        &["export", "r.json", "--object", "cube", "--gltf", "new.glb"],
        "--object cube",
    );
    run(
        &["export", "r.json", "--shader", "wgsl", "--out", "r.json"],
        "input",
    );
    run(&["export", "r.json"], "nothing to export");
    // no GPU driver: --check says so and writes nothing
    let a = fibrefit()
        .current_dir(d)
        .env("VK_ICD_FILENAMES", "/nonexistent.json")
        .env("VK_DRIVER_FILES", "/nonexistent.json")
        .args([
            "export", "r.json", "--shader", "wgsl", "--check", "--out", "new.wgsl",
        ])
        .assert()
        .code(2);
    let err = String::from_utf8_lossy(&a.get_output().stderr).to_string();
    assert!(
        err.contains("no GPU adapter") && err.contains("mesa-vulkan-drivers"),
        "{err}"
    );
    assert!(!d.join("new.wgsl").exists());
    assert!(text == std::fs::read_to_string(&result).unwrap());
}

#[test]
fn bench_shader_quick_measures_every_rung() {
    let dir = tempfile::tempdir().unwrap();
    fibrefit()
        .args(["bench", "shader", "--quick", "-q", "--out"])
        .arg(dir.path())
        .assert()
        .success();
    let md = std::fs::read_to_string(dir.path().join("shader_cost.md")).unwrap();
    assert!(md.contains("Generated by `fibrefit bench shader --quick`"));
    let mut rdr = csv::Reader::from_path(dir.path().join("shader_cost.csv")).unwrap();
    let headers = rdr.headers().unwrap().clone();
    let col = |name: &str| headers.iter().position(|h| h == name).unwrap();
    let rows: Vec<csv::StringRecord> = rdr.records().map(|r| r.unwrap()).collect();
    assert_eq!(rows.len(), 11);
    let num = |r: &csv::StringRecord, c: &str| r[col(c)].parse::<f64>().unwrap();
    for r in &rows {
        for c in [
            "gpu_evals_per_second",
            "cpu_all_threads_evals_per_second",
            "ratio_gpu_to_cpu",
        ] {
            let x = num(r, c);
            assert!(x.is_finite() && x > 0.0, "{c} {x}");
        }
        assert!(num(r, "spirv_instructions") > 100.0);
    }
    // the cross-section rungs carry more code than the closed forms, and a histogram of 16
    // heights costs more per evaluation than one height
    assert!(
        num(&rows[5], "spirv_instructions_of_the_rung")
            > 10.0 * num(&rows[3], "spirv_instructions_of_the_rung")
    );
    assert!(num(&rows[6], "gpu_evals_per_second") < num(&rows[5], "gpu_evals_per_second"));
}
