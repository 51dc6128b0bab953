//! Issue 37 items 1 and 3 (MaterialX, USD): `fibrefit export --materialx FILE.mtlx --usd
//! FILE.usda` writes an `openpbr` result's values into an OpenPBR Surface exactly, by OpenPBR's
//! input names, with the tangent turned across the fibres; every other result, a fuzz layer, a
//! wrong extension, an output onto the input are refused (exit 2, nothing written). That
//! MaterialX validates and renders what the rung evaluates, and that USD opens and validates the
//! stage, is python/tests/test_materialx.py and tests/browser/materialx.mjs.

use assert_cmd::Command;

fn fibrefit() -> Command {
    Command::cargo_bin("fibrefit").expect("binary built")
}

const PARAMS: &str = r#"
model = "openpbr"
kd = [0.5, 0.3, 0.2]
specular_roughness = 0.45
specular_roughness_anisotropy = 0.6
specular_ior = 1.5
specular_weight = 0.9
fuzz_weight = 0.5
fuzz_roughness = 0.6
fibre_azimuth_deg = 20
"#;

/// The value attribute of input `key` in the document.
fn input<'a>(doc: &'a str, key: &str) -> &'a str {
    let line = doc
        .lines()
        .find(|l| l.contains(&format!("<input name=\"{key}\"")))
        .unwrap_or_else(|| panic!("no input {key}:\n{doc}"));
    line.split("value=\"")
        .nth(1)
        .unwrap()
        .split('"')
        .next()
        .unwrap()
}

#[test]
fn an_openpbr_result_is_written_exactly_by_openpbrs_names() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("green felt.toml");
    std::fs::write(&p, PARAMS).unwrap();
    let (mtlx, usda) = (dir.path().join("felt.mtlx"), dir.path().join("felt.usda"));
    let out = fibrefit()
        .arg("export")
        .arg(&p)
        .arg("--materialx")
        .arg(&mtlx)
        .arg("--usd")
        .arg(&usda)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{stderr}");
    assert!(
        stderr.contains("MaterialX material `green_felt`"),
        "{stderr}"
    );
    assert!(stderr.contains("UsdPreviewSurface fallback"), "{stderr}");
    assert!(stderr.contains("no error against data"), "{stderr}");
    let d = std::fs::read_to_string(&mtlx).unwrap();
    assert!(d.starts_with("<?xml version=\"1.0\"?>\n<materialx version=\"1.39\">"));
    assert!(d.contains("<surfacematerial name=\"green_felt\" type=\"material\">"));
    assert_eq!(input(&d, "base_color"), "0.5, 0.3, 0.2");
    assert_eq!(input(&d, "specular_roughness"), "0.45");
    assert_eq!(input(&d, "specular_roughness_anisotropy"), "0.6");
    assert_eq!(input(&d, "specular_ior"), "1.5");
    assert_eq!(input(&d, "specular_weight"), "0.9");
    assert_eq!(input(&d, "fuzz_weight"), "0.5");
    assert_eq!(input(&d, "fuzz_roughness"), "0.6");
    assert_eq!(input(&d, "coat_weight"), "0.0");
    // fibres at 20 deg: the tangent across them, rotate3d (clockwise) by -110 deg
    assert_eq!(input(&d, "amount"), "-110.0");
    // no `--` inside the comment (XML forbids it)
    let comment = &d[d.find("<!--").unwrap() + 4..d.find("-->").unwrap()];
    assert!(!comment.contains("--"), "{comment}");
    let u = std::fs::read_to_string(&usda).unwrap();
    assert!(u.starts_with("#usda 1.0"));
    assert!(u.contains("uniform token info:id = \"ND_open_pbr_surface_surfaceshader\""));
    assert!(u.contains("color3f inputs:base_color = (0.5, 0.3, 0.2)"));
    assert!(u.contains("float inputs:amount = -110.0"));
    assert!(u.contains("rel material:binding = </fibrefit/Materials/green_felt>"));
}

#[test]
fn other_results_and_bad_outputs_are_refused_and_nothing_is_written() {
    let dir = tempfile::tempdir().unwrap();
    let ward = dir.path().join("ward.toml");
    std::fs::write(
        &ward,
        "model = \"ward\"\nrho_d = 0.3\nrho_s = 0.1\nalpha_x = 0.2\nalpha_y = 0.3\n",
    )
    .unwrap();
    let opbr = dir.path().join("o.toml");
    std::fs::write(&opbr, PARAMS).unwrap();
    let fuzzy = dir.path().join("fuzzy.toml");
    std::fs::write(&fuzzy, format!("{PARAMS}fuzz = 0.3\nfuzz_depth = 0.5\n")).unwrap();
    let mtlx = dir.path().join("out.mtlx");
    let cases: Vec<(Vec<std::ffi::OsString>, &str)> = vec![
        (
            vec![
                ward.clone().into(),
                "--materialx".into(),
                mtlx.clone().into(),
            ],
            "--model openpbr",
        ),
        (
            vec![
                ward.clone().into(),
                "--usd".into(),
                dir.path().join("o.usda").into(),
            ],
            "--usd",
        ),
        (
            vec![
                fuzzy.clone().into(),
                "--materialx".into(),
                mtlx.clone().into(),
            ],
            "fuzz",
        ),
        (
            vec![
                opbr.clone().into(),
                "--materialx".into(),
                dir.path().join("o.xml").into(),
            ],
            ".mtlx",
        ),
        (
            vec![
                opbr.clone().into(),
                "--usd".into(),
                dir.path().join("o.usd").into(),
            ],
            ".usda",
        ),
        (
            vec![opbr.clone().into(), "--name".into(), "x".into()],
            "nothing to export",
        ),
        (
            vec![
                opbr.clone().into(),
                "--shader".into(),
                "wgsl".into(),
                "--out".into(),
                dir.path().join("s.wgsl").into(),
                "--name".into(),
                "x".into(),
            ],
            "--name",
        ),
    ];
    for (args, want) in cases {
        let out = fibrefit().arg("export").args(&args).output().unwrap();
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{args:?}: {stderr}");
        assert!(stderr.contains(want), "{args:?}: {stderr}");
    }
    let mut left: Vec<_> = std::fs::read_dir(dir.path())
        .unwrap()
        .map(|e| e.unwrap().file_name().into_string().unwrap())
        .collect();
    left.sort();
    assert_eq!(left, ["fuzzy.toml", "o.toml", "ward.toml"]);
}
