//! `fibrefit bench --quick` produces its report from measurements (structure checked, errors
//! fall as N grows), and `fit --report` writes its pictures.

use assert_cmd::Command;
use std::path::PathBuf;

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

#[test]
fn bench_quick_writes_a_measured_report_and_errors_fall_with_n() {
    let dir = tempfile::tempdir().unwrap();
    let o = Command::cargo_bin("fibrefit")
        .unwrap()
        .args(["bench", "--quick", "-q", "--out"])
        .arg(dir.path())
        .arg("--root")
        .arg(root())
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let md = std::fs::read_to_string(dir.path().join("speed_accuracy.md")).unwrap();
    for needle in [
        "# Speed and accuracy",
        "## Forward ladder",
        "### flat",
        "### climbing",
        "### gapped",
        "### sharp",
        "## Fit level",
        "pareto.png",
        "fit_time_vs_error.png",
        "| rung | knob | ns / eval | RMS rel. error | max rel. error |",
    ] {
        assert!(md.contains(needle), "report lacks {needle}");
    }
    for f in ["pareto.png", "fit_time_vs_error.png"] {
        let img = image::open(dir.path().join(f)).unwrap();
        assert_eq!((img.width(), img.height()), (900, 600));
    }
    // the forward CSV: every rung and knob on every set, errors falling as N grows
    let mut r = csv::Reader::from_path(dir.path().join("speed_accuracy_forward.csv")).unwrap();
    let headers = r.headers().unwrap().clone();
    assert_eq!(
        headers.iter().collect::<Vec<_>>(),
        [
            "set",
            "rung",
            "knob",
            "ns_per_eval",
            "rms_rel_error",
            "max_rel_error"
        ]
    );
    let rows: Vec<csv::StringRecord> = r.records().map(|x| x.unwrap()).collect();
    for set in ["flat", "climbing", "gapped", "sharp"] {
        let rms = |knob: &str| -> f64 {
            rows.iter()
                .find(|x| &x[0] == set && &x[1] == "varying-topology" && &x[2] == knob)
                .unwrap()[4]
                .parse()
                .unwrap()
        };
        let errs: Vec<f64> = [2, 4, 8, 16, 32, 64]
            .iter()
            .map(|n| rms(&format!("N={n} K=16")))
            .collect();
        assert!(errs[5] < 0.01 * errs[0], "{set}: {errs:?}");
        for w in errs.windows(2) {
            assert!(
                w[1] <= w[0] * 1.5 + 1e-12,
                "{set}: error grew with N: {errs:?}"
            );
        }
        for rung in [
            "lambert",
            "hast-diffuse",
            "max-normal",
            "ward",
            "poulin-fournier",
            "reference",
        ] {
            assert!(
                rows.iter().any(|x| &x[0] == set && &x[1] == rung),
                "{set}: no {rung} row"
            );
        }
        let ns: f64 = rows
            .iter()
            .find(|x| &x[0] == set && &x[1] == "lambert")
            .unwrap()[3]
            .parse()
            .unwrap();
        assert!(ns > 0.0);
    }
    let fit = std::fs::read_to_string(dir.path().join("speed_accuracy_fit.csv")).unwrap();
    assert!(fit.starts_with(
        "fraction,quadrature_order,samples,seconds,iterations,max_param_rel_error,param_rel_errors"
    ));
    assert!(fit.lines().count() >= 5);
}

#[test]
fn fit_report_has_its_pictures() {
    let dir = tempfile::tempdir().unwrap();
    let rep = dir.path().join("report");
    let o = Command::cargo_bin("fibrefit")
        .unwrap()
        .arg("fit")
        .arg(root().join("data_synthetic/loose/capture.toml"))
        .arg("--config")
        .arg(root().join("configs/fit_loose.toml"))
        .arg("--out")
        .arg(dir.path().join("r.json"))
        .arg("--report")
        .arg(&rep)
        .args(["-q", "--stride", "2"])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let md = std::fs::read_to_string(rep.join("report.md")).unwrap();
    for needle in [
        "[[Variables]]",
        "+/-",
        "residuals.png",
        "residual_map_000.png",
        "## Slices",
        "slices.png",
        "## Hemisphere maps",
        "hemispheres.png",
    ] {
        assert!(md.contains(needle), "report lacks {needle}");
    }
    for k in 0..4 {
        assert!(rep.join(format!("residual_map_{k:03}.png")).exists());
    }
    for png in ["residuals.png", "slices.png", "hemispheres.png"] {
        let img = image::open(rep.join(png)).unwrap();
        assert!(img.width() > 500 && img.height() > 500, "{png}");
    }
}

#[test]
fn bench_photos_quick_measures_calibrate_and_says_it_is_not_the_goals_size() {
    let dir = tempfile::tempdir().unwrap();
    let o = Command::cargo_bin("fibrefit")
        .unwrap()
        .args(["bench", "photos", "--quick", "-q", "--out"])
        .arg(dir.path())
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let md = std::fs::read_to_string(dir.path().join("photo_speed.md")).unwrap();
    assert!(
        md.contains("fibrefit bench photos --quick")
            && md.contains("| 4 | jpeg |")
            && md.contains("| 4 | dng |")
            && md.contains("RAW against JPEG"),
        "{md}"
    );
    assert!(md.contains("not the goal's size"), "{md}");
    let csv = std::fs::read_to_string(dir.path().join("photo_speed.csv")).unwrap();
    for (line, format) in [(1, "jpeg"), (2, "dng")] {
        let row: Vec<&str> = csv.lines().nth(line).unwrap().split(',').collect();
        assert_eq!(row[1], format, "{csv}");
        let (wall, peak, worst): (f64, f64, f64) = (
            row[5].parse().unwrap(),
            row[7].parse().unwrap(),
            row[8].parse().unwrap(),
        );
        assert!(wall > 0.0 && peak > 0.0, "{csv}");
        // the calibration itself is right: cameras within a millimetre
        assert!(worst < 1.0, "{csv}");
    }
}
