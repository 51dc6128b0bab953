//! `fibrefit view` (issue 38 item 4): the page is one self-contained file (nothing loaded from
//! anywhere else), carries both shaders (which compile as GLSL ES 3.00 with the page's preamble,
//! where glslangValidator is installed), the meshes and the table; the measured-against-fitted
//! grid is there for gonio data with enough directions and its absence explained otherwise;
//! `fit --report DIR` writes it too; bad input is refused with exit 2 and nothing written. The
//! page's drawing is tested in headless Chromium (tests/browser/view.mjs).

use assert_cmd::Command;
use std::path::{Path, PathBuf};

fn fibrefit() -> Command {
    Command::cargo_bin("fibrefit").expect("binary built")
}

const PARAMS: &str = "model = \"poulin-fournier\"\nkd = [0.55, 0.35, 0.30]\nks = 0.25\nexponent = 60\nspacing = 2.0\nfibre_azimuth_deg = 20\n";

/// The JSON the page carries.
fn page_data(html: &str) -> serde_json::Value {
    let start = html
        .find("id=\"fibrefit-data\">")
        .expect("the data element")
        + "id=\"fibrefit-data\">".len();
    let end = start + html[start..].find("</script>").expect("its end");
    serde_json::from_str(&html[start..end].replace("<\\/", "</")).expect("the data is JSON")
}

fn gonio_fit(dir: &Path) -> PathBuf {
    let data = dir.join("gonio.csv");
    std::fs::copy("data_synthetic/silk/gonio.csv", &data).unwrap();
    let out = dir.join("fit.json");
    fibrefit()
        .args([
            "fit",
            data.to_str().unwrap(),
            "--model",
            "lambert",
            "--quiet",
        ])
        .args(["--out", out.to_str().unwrap()])
        .assert()
        .success();
    out
}

#[test]
fn the_page_is_self_contained_and_carries_both_routes() {
    let dir = tempfile::tempdir().unwrap();
    let params = dir.path().join("pf.toml");
    std::fs::write(&params, PARAMS).unwrap();
    let out = dir.path().join("pf.html");
    fibrefit()
        .args([
            "view",
            params.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
            "-q",
        ])
        .assert()
        .success();
    let html = std::fs::read_to_string(&out).unwrap();
    // nothing fetched: no external script, style, image or address
    for needle in [
        "<script src",
        "<link",
        "<img",
        "http://",
        "https://",
        "import ",
    ] {
        assert!(!html.contains(needle), "the page holds {needle:?}");
    }
    let d = page_data(&html);
    assert_eq!(d["model"], "poulin-fournier");
    for side in ["exact", "gltf"] {
        assert!(d["shaders"][side]
            .as_str()
            .unwrap()
            .contains("vec3 fibrefit_brdf("));
    }
    assert_eq!(d["gltf_route"]["kind"], "converted");
    let names: Vec<&str> = d["meshes"]
        .as_array()
        .unwrap()
        .iter()
        .map(|m| m["name"].as_str().unwrap())
        .collect();
    assert_eq!(names, ["swatch", "sphere", "torus", "cloth"]);
    // a parameter file: no data, and the page says so
    assert_eq!(d["comparison"]["available"], false);
    assert!(d["comparison"]["note"]
        .as_str()
        .unwrap()
        .contains("parameter file"));
    assert_eq!(d["result"]["fitted"], false);
    glsl_es_compiles(&d, dir.path());
}

/// Each shader with the page's preamble and a fragment shader's main compiles as GLSL ES 3.00.
fn glsl_es_compiles(d: &serde_json::Value, dir: &Path) {
    let Some(glslang) = std::env::var_os("PATH").and_then(|paths| {
        std::env::split_paths(&paths)
            .map(|d| d.join("glslangValidator"))
            .find(|p| p.is_file())
    }) else {
        eprintln!("glslangValidator not installed: the GLSL ES compile check is skipped");
        return;
    };
    for side in ["exact", "gltf"] {
        let src = format!(
            "{}{}\nout vec4 o;\nvoid main() {{ o = vec4(fibrefit_brdf_at(vec3(0.0, 0.6, 0.8), vec3(0.0, 0.0, 1.0), vec3(0.0, 0.0, 1.0), vec3(1.0, 0.0, 0.0), 0.5, 0.1) + fibrefit_brdf(vec3(0.0, 0.6, 0.8), vec3(0.0, 0.0, 1.0), vec3(0.0, 0.0, 1.0), vec3(1.0, 0.0, 0.0)), 1.0); }}\n",
            d["glsl_es_preamble"].as_str().unwrap(),
            d["shaders"][side].as_str().unwrap()
        );
        let file = dir.join(format!("{side}.frag"));
        std::fs::write(&file, src).unwrap();
        let out = std::process::Command::new(&glslang)
            .arg(&file)
            .output()
            .unwrap();
        assert!(
            out.status.success(),
            "{side}: {}",
            String::from_utf8_lossy(&out.stdout)
        );
    }
}

#[test]
fn a_gonio_fit_gets_its_data_compared_and_fit_report_writes_the_page() {
    let dir = tempfile::tempdir().unwrap();
    let result = gonio_fit(dir.path());
    let out = dir.path().join("view.html");
    fibrefit()
        .args([
            "view",
            result.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
            "-q",
        ])
        .assert()
        .success();
    let d = page_data(&std::fs::read_to_string(&out).unwrap());
    assert_eq!(
        d["comparison"]["available"], true,
        "{}",
        d["comparison"]["note"]
    );
    let nodes = d["comparison"]["nodes"].as_array().unwrap();
    assert!(nodes.len() >= 6);
    assert!(nodes
        .iter()
        .all(|n| n["samples"].as_array().unwrap().len() >= 12));
    assert_eq!(d["result"]["fitted"], true);
    assert!(d["result"]["parameters"]
        .as_array()
        .unwrap()
        .iter()
        .any(|p| p["name"] == "kd"));
    assert!(d["result"]["verdict"].is_string());

    // never onto the data the page was built from
    let data = dir.path().join("gonio.csv");
    let before = std::fs::read(&data).unwrap();
    fibrefit()
        .args([
            "view",
            result.to_str().unwrap(),
            "--out",
            data.to_str().unwrap(),
            "-q",
        ])
        .assert()
        .code(2);
    assert_eq!(std::fs::read(&data).unwrap(), before);

    // the data beside the result changed: the page says it is not the file fitted
    std::fs::write(
        dir.path().join("gonio.csv"),
        "theta_i,phi_i,theta_o,phi_o,brdf\n10,0,20,180,0.1\n",
    )
    .unwrap();
    let again = dir.path().join("again.html");
    fibrefit()
        .args([
            "view",
            result.to_str().unwrap(),
            "--out",
            again.to_str().unwrap(),
            "-q",
        ])
        .assert()
        .success();
    let d = page_data(&std::fs::read_to_string(&again).unwrap());
    assert_eq!(d["comparison"]["available"], false);
    assert!(d["comparison"]["note"]
        .as_str()
        .unwrap()
        .contains("not the file fitted"));

    // fit --report DIR writes view.html beside report.md
    let report = dir.path().join("report");
    std::fs::copy(
        "data_synthetic/silk/gonio.csv",
        dir.path().join("gonio.csv"),
    )
    .unwrap();
    fibrefit()
        .args([
            "fit",
            dir.path().join("gonio.csv").to_str().unwrap(),
            "--model",
            "lambert",
            "--quiet",
        ])
        .args(["--report", report.to_str().unwrap()])
        .assert()
        .success();
    let d = page_data(&std::fs::read_to_string(report.join("view.html")).unwrap());
    assert_eq!(d["comparison"]["available"], true);
    assert_eq!(d["model"], "lambert");
}

#[test]
fn bad_input_is_refused_with_nothing_written() {
    let dir = tempfile::tempdir().unwrap();
    let params = dir.path().join("pf.toml");
    std::fs::write(&params, PARAMS).unwrap();
    let out = dir.path().join("x.html");
    // a missing result, a broken one, missing --data: exit 2 naming the file, nothing written
    let missing = dir.path().join("missing.json");
    let broken = dir.path().join("broken.toml");
    std::fs::write(&broken, "model = \"poulin-fournier\"\nkd = \"red\"\n").unwrap();
    for (args, names) in [
        (vec![missing.to_str().unwrap()], "missing.json"),
        (vec![broken.to_str().unwrap()], "broken.toml"),
        (
            vec![params.to_str().unwrap(), "--data", "nowhere.csv"],
            "nowhere.csv",
        ),
    ] {
        let a = fibrefit()
            .arg("view")
            .args(&args)
            .args(["--out", out.to_str().unwrap()])
            .assert()
            .code(2);
        let err = String::from_utf8_lossy(&a.get_output().stderr).into_owned();
        assert!(err.contains(names), "{args:?}: {err}");
        assert!(!out.exists(), "{args:?} wrote the page");
    }
    // the output is never an input
    let before = std::fs::read(&params).unwrap();
    fibrefit()
        .args([
            "view",
            params.to_str().unwrap(),
            "--out",
            params.to_str().unwrap(),
            "-q",
        ])
        .assert()
        .code(2);
    assert_eq!(std::fs::read(&params).unwrap(), before);
    let files: Vec<_> = std::fs::read_dir(dir.path()).unwrap().collect();
    assert_eq!(files.len(), 2, "only the two inputs are there");
}
