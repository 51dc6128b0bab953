//! `fibrefit render`: a Lambert sphere's pixels are kd/pi E max(0, n.l) at the normal the AOV
//! gives; a varying-topology torus's pixels are what `fibrefit eval` gives at that pixel's
//! light, view, fibre tangent and height; nothing is drawn outside the object; seed 001's grid;
//! bad input refused with nothing written.

use assert_cmd::Command;
use fibrefit::load::image_io;
use std::path::Path;

fn fibrefit() -> Command {
    Command::cargo_bin("fibrefit").expect("binary built")
}

fn dir_of(theta: f64, phi: f64) -> [f64; 3] {
    let (t, p) = (theta.to_radians(), phi.to_radians());
    [t.sin() * p.cos(), t.sin() * p.sin(), t.cos()]
}

fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// An open cylinder of radius 1 about z, z in [-1, 1], as OBJ: `nu` quads round, `nv` along.
fn cylinder_obj(nu: usize, nv: usize) -> String {
    let mut obj = String::new();
    for j in 0..=nv {
        for i in 0..nu {
            let ph = std::f64::consts::TAU * i as f64 / nu as f64;
            obj += &format!(
                "v {} {} {}\n",
                ph.cos(),
                ph.sin(),
                2.0 * j as f64 / nv as f64 - 1.0
            );
        }
    }
    let id = |i: usize, j: usize| j * nu + (i % nu) + 1;
    for j in 0..nv {
        for i in 0..nu {
            obj += &format!(
                "f {} {} {} {}\n",
                id(i, j),
                id(i + 1, j),
                id(i + 1, j + 1),
                id(i, j + 1)
            );
        }
    }
    obj
}

/// Alpha channel of a rendered EXR.
fn alpha(path: &Path) -> Vec<f32> {
    let img = exr::prelude::read_first_flat_layer_from_file(path).unwrap();
    let a = img
        .layer_data
        .channel_data
        .list
        .iter()
        .find(|c| c.name.to_string() == "A")
        .expect("an alpha channel");
    a.sample_data.values_as_f32().collect()
}

fn vec3(img: &image_io::LinearImage, i: usize) -> [f64; 3] {
    let p = &img.data[3 * i..3 * i + 3];
    [p[0] as f64, p[1] as f64, p[2] as f64]
}

#[test]
fn a_lambert_sphere_is_kd_over_pi_times_the_cosine_at_its_normals() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(
        dir.path().join("p.toml"),
        "model = \"lambert\"\nkd = [0.6, 0.4, 0.2]\n",
    )
    .unwrap();
    fibrefit()
        .current_dir(dir.path())
        .args(["render", "--params", "p.toml", "--object", "sphere"])
        .args([
            "--light", "30,60", "--camera", "20,200", "--size", "48", "40",
        ])
        // the key light only: the pixels are checked against it
        .args(["--fill", "0"])
        .args([
            "--supersample",
            "1",
            "--out",
            "s.exr",
            "--aovs",
            "aov",
            "-q",
        ])
        .assert()
        .success();
    let img = image_io::read(&dir.path().join("s.exr"), None, None).unwrap();
    let normal = image_io::read(&dir.path().join("aov/normal.exr"), None, None).unwrap();
    let a = alpha(&dir.path().join("s.exr"));
    assert_eq!((img.width, img.height), (48, 40));
    assert!(
        !dir.path().join("aov/height.exr").exists(),
        "lambert has no height"
    );
    let l = dir_of(30.0, 60.0);
    let (mut inside, mut outside) = (0, 0);
    for y in 1..39 {
        for x in 1..47 {
            let i = y * 48 + x;
            let interior = [i - 1, i + 1, i - 48, i + 48, i]
                .iter()
                .all(|&j| a[j] == 1.0);
            if a[i] == 0.0 {
                outside += 1;
                assert_eq!(&img.data[3 * i..3 * i + 3], &[0.0, 0.0, 0.0]);
                assert_eq!(vec3(&normal, i), [0.0; 3]);
                continue;
            }
            if !interior {
                continue;
            }
            inside += 1;
            let n = vec3(&normal, i);
            let cos = dot(n, l).max(0.0);
            for (c, kd) in [0.6, 0.4, 0.2].iter().enumerate() {
                let want = kd / std::f64::consts::PI * cos;
                let got = img.data[3 * i + c] as f64;
                assert!(
                    (got - want).abs() <= 2e-6 * (1.0 + want),
                    "pixel ({x}, {y}) channel {c}: {got} vs {want}"
                );
            }
        }
    }
    assert!(inside > 800 && outside > 200, "{inside} {outside}");
}

#[test]
fn a_fibre_torus_pixel_is_eval_at_its_own_light_view_tangent_and_height() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::write(
        d.join("p.toml"),
        "model = \"varying-topology\"\nkd = 0.5\nks = 0.4\nexponent = 30\nspacing = 2.0\n",
    )
    .unwrap();
    fibrefit()
        .current_dir(d)
        .args(["render", "--params", "p.toml", "--object", "torus"])
        .args(["--fill", "0"])
        .args([
            "--light", "40,120", "--camera", "50,270", "--size", "40", "40",
        ])
        .args([
            "--supersample",
            "1",
            "--out",
            "t.exr",
            "--aovs",
            "aov",
            "-q",
        ])
        .assert()
        .success();
    let img = image_io::read(&d.join("t.exr"), None, None).unwrap();
    let read = |n: &str| image_io::read(&d.join("aov").join(n), None, None).unwrap();
    let (normal, tangent, height) = (read("normal.exr"), read("tangent.exr"), read("height.exr"));
    let a = alpha(&d.join("t.exr"));
    let (l, v) = (dir_of(40.0, 120.0), dir_of(50.0, 270.0));
    // the pixels' local directions as eval queries (fibres along x of the local frame)
    let mut csv = String::from("theta_i,phi_i,theta_o,phi_o,height\n");
    let mut pixels = Vec::new();
    for (i, &ai) in a.iter().enumerate() {
        if ai != 1.0 {
            assert!(height.data[i].is_nan() || ai > 0.0);
            continue;
        }
        let (n, t) = (vec3(&normal, i), vec3(&tangent, i));
        let b = [
            n[1] * t[2] - n[2] * t[1],
            n[2] * t[0] - n[0] * t[2],
            n[0] * t[1] - n[1] * t[0],
        ];
        let local = |w: [f64; 3]| {
            let (x, y, z) = (dot(w, t), dot(w, b), dot(w, n));
            let r = (x * x + y * y + z * z).sqrt();
            (
                (z / r).clamp(-1.0, 1.0).acos().to_degrees(),
                y.atan2(x).to_degrees(),
            )
        };
        let ((ti, pi), (to, po)) = (local(l), local(v));
        if ti >= 89.0 || to >= 89.0 {
            continue;
        }
        csv += &format!("{ti},{pi},{to},{po},{}\n", height.data[i]);
        pixels.push(i);
    }
    assert!(pixels.len() > 300, "{}", pixels.len());
    std::fs::write(d.join("q.csv"), csv).unwrap();
    fibrefit()
        .current_dir(d)
        .args([
            "eval",
            "--params",
            "p.toml",
            "--queries",
            "q.csv",
            "--out",
            "e.csv",
            "-q",
        ])
        .assert()
        .success();
    let mut rd = csv::Reader::from_path(d.join("e.csv")).unwrap();
    let heads = rd.headers().unwrap().clone();
    let col = heads.iter().position(|h| h == "intensity").unwrap();
    let mut worst: f64 = 0.0;
    for (row, &i) in rd.records().zip(&pixels) {
        let want: f64 = row.unwrap()[col].parse().unwrap();
        let got = img.data[3 * i] as f64;
        // the AOVs are f32: their rounding moves a sharp lobe by ~1e-6 relative
        worst = worst.max((got - want).abs() / want.abs().max(1e-3));
    }
    assert!(worst < 1e-4, "worst relative difference {worst}");
}

#[test]
fn seed_001_grid_and_bad_input() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    fibrefit()
        .current_dir(d)
        .args(["render", "--paper-figures", "--out", "grid.png", "-q"])
        .assert()
        .success();
    let grid = image::open(d.join("grid.png")).unwrap().to_rgb8();
    // 2 x 4 tiles of 256 px, a margin for the row labels (left) and the column labels (top)
    assert_eq!((grid.width(), grid.height()), (512 + 200, 1024 + 44));
    let dark = |x0: u32, x1: u32, y0: u32, y1: u32| {
        (x0..x1)
            .flat_map(|x| (y0..y1).map(move |y| (x, y)))
            .filter(|&(x, y)| grid.get_pixel(x, y).0.iter().all(|&c| c < 100))
            .count()
    };
    // text in the margins: each row's label, the columns' labels
    for r in 0..4 {
        let y = 44 + r * 256 + 128;
        assert!(dark(0, 200, y - 12, y + 12) > 20, "row {r} has no label");
    }
    assert!(dark(200, 712, 0, 44) > 40, "no column labels");
    std::fs::write(d.join("p.toml"), "model = \"lambert\"\nkd = 0.5\n").unwrap();
    for (args, says) in [
        (vec!["--light", "abc"], "THETA,PHI"),
        (vec!["--light", "200,0"], "outside [0, 180]"),
        (vec!["--object", "cube"], "torus, sphere, swatch or a mesh"),
        (vec!["--supersample", "0"], "--supersample"),
    ] {
        let out = fibrefit()
            .current_dir(d)
            .args(["render", "--params", "p.toml", "--out", "x.png"])
            .args(&args)
            .assert()
            .code(2);
        let err = String::from_utf8_lossy(&out.get_output().stderr).to_string();
        assert!(err.contains(says), "{args:?}: {err}");
        assert!(!d.join("x.png").exists());
    }
    let out = fibrefit()
        .current_dir(d)
        .args(["render", "--params", "p.toml", "--out", "x.jpg"])
        .assert()
        .code(2);
    assert!(String::from_utf8_lossy(&out.get_output().stderr).contains(".exr or .png"));
    assert!(!d.join("x.jpg").exists());
    // an output never replaces an input
    fibrefit()
        .current_dir(d)
        .args(["render", "--params", "p.toml", "--out", "p.toml"])
        .assert()
        .code(2);
    assert_eq!(
        std::fs::read_to_string(d.join("p.toml")).unwrap(),
        "model = \"lambert\"\nkd = 0.5\n"
    );
}

#[test]
fn a_mesh_takes_its_fibres_from_its_curvature() {
    // an open cylinder about z as OBJ: k1 runs round it, so the tangent AOV is horizontal
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::write(d.join("cyl.obj"), cylinder_obj(64, 16)).unwrap();
    std::fs::write(
        d.join("p.toml"),
        "model = \"poulin-fournier\"\nkd = 0.5\nks = 0.4\nexponent = 30\nspacing = 2.0\n",
    )
    .unwrap();
    fibrefit()
        .current_dir(d)
        .args([
            "render",
            "--params",
            "p.toml",
            "--object",
            "cyl.obj",
            "--tangents",
            "curvature",
        ])
        .args([
            "--camera",
            "80,270",
            "--size",
            "40",
            "40",
            "--supersample",
            "1",
        ])
        .args(["--out", "c.exr", "--aovs", "aov", "-q"])
        .assert()
        .success();
    let read = |n: &str| image_io::read(&d.join("aov").join(n), None, None).unwrap();
    let (normal, tangent, position) = (
        read("normal.exr"),
        read("tangent.exr"),
        read("position.exr"),
    );
    let mut checked = 0;
    for i in 0..40 * 40 {
        let (n, t, p) = (vec3(&normal, i), vec3(&tangent, i), vec3(&position, i));
        if dot(n, n) == 0.0 || p[2].abs() > 0.7 {
            continue;
        }
        assert!(t[2].abs() < 0.02, "pixel {i}: tangent {t:?} at {p:?}");
        assert!(dot(t, n).abs() < 1e-5 && (dot(t, t) - 1.0).abs() < 1e-5);
        checked += 1;
    }
    assert!(checked > 200, "{checked}");
    // a field the mesh cannot give is refused
    fibrefit()
        .current_dir(d)
        .args([
            "render",
            "--params",
            "p.toml",
            "--object",
            "cyl.obj",
            "--tangents",
            "uv",
        ])
        .args(["--out", "u.png"])
        .assert()
        .code(2);
    assert!(!d.join("u.png").exists());
}

#[test]
fn recovered_maps_set_each_texels_height_and_fibre_direction() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    // 8 x 4 texels: H = 0.2 x + 0.1, psi = 10 y - 20 degrees
    let (w, h) = (8, 4);
    let hmap: Vec<f32> = (0..w * h).map(|i| 0.2 * (i % w) as f32 + 0.1).collect();
    let pmap: Vec<f32> = (0..w * h).map(|i| 10.0 * (i / w) as f32 - 20.0).collect();
    std::fs::create_dir_all(d.join("maps")).unwrap();
    fibrefit::export::images::write_exr(&d.join("maps/height.exr"), w, h, 1, &hmap).unwrap();
    fibrefit::export::images::write_exr(&d.join("maps/fibre_azimuth.exr"), w, h, 1, &pmap).unwrap();
    std::fs::write(
        d.join("p.toml"),
        "model = \"varying-topology\"\nkd = 0.5\nks = 0.4\nexponent = 30\nspacing = 2.0\nfibre_azimuth_deg = 0\n",
    )
    .unwrap();
    fibrefit()
        .current_dir(d)
        .args([
            "render", "--params", "p.toml", "--object", "swatch", "--maps", "maps",
        ])
        .args([
            "--camera",
            "0,0",
            "--size",
            "64",
            "64",
            "--supersample",
            "1",
        ])
        .args(["--out", "s.exr", "--aovs", "aov", "-q"])
        .assert()
        .success();
    let read = |n: &str| image_io::read(&d.join("aov").join(n), None, None).unwrap();
    let (height, tangent, position) = (
        read("height.exr"),
        read("tangent.exr"),
        read("position.exr"),
    );
    let mut checked = 0;
    for i in 0..64 * 64 {
        let p = vec3(&position, i);
        if height.data[i].is_nan() {
            continue;
        }
        // the swatch's (u, v) = ((x + 1)/2, (y + 1)/2), v up the map
        let (u, v) = ((p[0] + 1.0) / 2.0, (p[1] + 1.0) / 2.0);
        let tx = ((u * w as f64) as usize).min(w - 1);
        let ty = (((1.0 - v) * h as f64) as usize).min(h - 1);
        if (u * w as f64).fract().min(1.0 - (u * w as f64).fract()) < 0.05
            || (v * h as f64).fract().min(1.0 - (v * h as f64).fract()) < 0.05
        {
            continue; // on a texel border, either texel is right
        }
        assert_eq!(height.data[i], hmap[ty * w + tx], "pixel {i} at {p:?}");
        let t = vec3(&tangent, i);
        let psi = t[1].atan2(t[0]).to_degrees();
        assert!(
            (psi - pmap[ty * w + tx] as f64).abs() < 1e-4,
            "{psi} at {p:?}"
        );
        checked += 1;
    }
    assert!(checked > 1000, "{checked}");
}

#[test]
fn a_scene_with_a_point_light_and_a_pinhole_camera() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::write(d.join("p.toml"), "model = \"lambert\"\nkd = 0.5\n").unwrap();
    std::fs::write(
        d.join("scene.toml"),
        r#"size = [48, 32]
supersample = 1
exposure = 2.0
[camera]
type = "pinhole"
position = [0, -6, 3]
look_at = [0, 0, 0]
fov_deg = 35
[[lights]]
type = "point"
position = [2, -2, 3]
intensity = 7
[[objects]]
type = "sphere"
offset = [0.5, 0, 0]
scale = 0.8
"#,
    )
    .unwrap();
    fibrefit()
        .current_dir(d)
        .args(["render", "--params", "p.toml", "--scene", "scene.toml"])
        .args(["--out", "s.exr", "--aovs", "aov", "-q"])
        .assert()
        .success();
    let img = image_io::read(&d.join("s.exr"), None, None).unwrap();
    let read = |n: &str| image_io::read(&d.join("aov").join(n), None, None).unwrap();
    let (normal, position) = (read("normal.exr"), read("position.exr"));
    assert_eq!((img.width, img.height), (48, 32));
    let a = alpha(&d.join("s.exr"));
    let mut checked = 0;
    for (i, &ai) in a.iter().enumerate() {
        if ai != 1.0 {
            continue;
        }
        let (n, p) = (vec3(&normal, i), vec3(&position, i));
        // on the moved and scaled sphere
        let r = [p[0] - 0.5, p[1], p[2]];
        assert!((dot(r, r).sqrt() - 0.8).abs() < 1e-5, "{p:?}");
        let l = [2.0 - p[0], -2.0 - p[1], 3.0 - p[2]];
        let r2 = dot(l, l);
        let cos = (dot(n, l) / r2.sqrt()).max(0.0);
        let want = 0.5 / std::f64::consts::PI * 7.0 / r2 * cos;
        let got = img.data[3 * i] as f64;
        assert!((got - want).abs() <= 1e-5 * (1.0 + want), "{got} vs {want}");
        checked += 1;
    }
    assert!(checked > 150, "{checked}");
    // a scene that is wrong names itself and the field
    std::fs::write(d.join("bad.toml"), "[camera]\ntype = \"pinhole\"\nposition = [0, 0, 1]\nfov_deg = 400\n[[lights]]\ntype = \"point\"\nposition = [0, 0, 1]\nintensity = 1\n[[objects]]\ntype = \"sphere\"\n").unwrap();
    let out = fibrefit()
        .current_dir(d)
        .args([
            "render", "--params", "p.toml", "--scene", "bad.toml", "--out", "b.png",
        ])
        .assert()
        .code(2);
    let err = String::from_utf8_lossy(&out.get_output().stderr).to_string();
    assert!(err.contains("bad.toml") && err.contains("fov_deg"), "{err}");
    assert!(!d.join("b.png").exists());
}

#[test]
fn ward_alphas_follow_the_curvature_of_a_mesh() {
    // a cylinder of radius 1: k1 = 1 round it, k2 = 0 along it; with F = 0.3 the pixels equal
    // Ward with alpha_x = 0.3 (across the axis, the tangent) and alpha_y = 0.01 (the floor)
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::write(d.join("cyl.obj"), cylinder_obj(96, 8)).unwrap();
    std::fs::write(
        d.join("w.toml"),
        "model = \"ward\"\nrho_d = 0.2\nrho_s = 0.3\nalpha_x = 0.05\nalpha_y = 0.05\n",
    )
    .unwrap();
    let render = |extra: &[&str], out: &str| {
        fibrefit()
            .current_dir(d)
            .args(["render", "--params", "w.toml", "--object", "cyl.obj"])
            .args([
                "--camera",
                "80,250",
                "--light",
                "60,300",
                "--size",
                "32",
                "32",
                "--supersample",
                "1",
            ])
            .args(extra)
            .args(["--out", out, "-q"])
            .assert()
    };
    render(&["--ward-curvature-alpha", "0.3"], "c.exr").success();
    std::fs::write(
        d.join("w2.toml"),
        "model = \"ward\"\nrho_d = 0.2\nrho_s = 0.3\nalpha_x = 0.3\nalpha_y = 0.01\n",
    )
    .unwrap();
    fibrefit()
        .current_dir(d)
        .args(["render", "--params", "w2.toml", "--object", "cyl.obj"])
        .args([
            "--camera",
            "80,250",
            "--light",
            "60,300",
            "--size",
            "32",
            "32",
            "--supersample",
            "1",
        ])
        .args(["--out", "f.exr", "-q"])
        .assert()
        .success();
    let (c, f) = (
        image_io::read(&d.join("c.exr"), None, None).unwrap(),
        image_io::read(&d.join("f.exr"), None, None).unwrap(),
    );
    let a = alpha(&d.join("c.exr"));
    let mut compared = 0;
    for (i, &ai) in a.iter().enumerate() {
        if ai == 1.0 {
            let (x, y) = (c.data[3 * i] as f64, f.data[3 * i] as f64);
            // |k1| interpolated over the faces of a 96-gon: within 0.1 % of 1
            assert!(
                (x - y).abs() <= 0.02 * y.abs() + 1e-6,
                "pixel {i}: {x} vs {y}"
            );
            compared += 1;
        }
    }
    assert!(compared > 100, "{compared}");
    render(&["--ward-curvature-alpha", "0"], "z.png").code(2);
    fibrefit()
        .current_dir(d)
        .args([
            "render",
            "--params",
            "w.toml",
            "--object",
            "torus",
            "--ward-curvature-alpha",
            "0.3",
            "--out",
            "t.png",
        ])
        .assert()
        .code(2);
}

/// Issue 40, item 5: `--preset studio|grazing|flat`; each renders, studio lights the rim on
/// the side away from the key light, a bad preset is refused naming the presets.
#[test]
fn presets_render_and_studio_lights_the_rim() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::write(
        d.join("p.toml"),
        "model = \"poulin-fournier\"\nkd = 0.5\nks = 0.4\nexponent = 30\nspacing = 2.0\n",
    )
    .unwrap();
    let render = |preset: &str| {
        let out = format!("{preset}.exr");
        fibrefit()
            .current_dir(d)
            .args(["render", "--params", "p.toml", "--object", "sphere"])
            .args([
                "--preset",
                preset,
                "--size",
                "64",
                "64",
                "--supersample",
                "1",
            ])
            .args(["--out", &out, "--aovs", preset, "-q"])
            .assert()
            .success();
        let img = image_io::read(&d.join(&out), None, None).unwrap();
        let normal = image_io::read(&d.join(preset).join("normal.exr"), None, None).unwrap();
        (img, normal)
    };
    let (flat, normal) = render("flat");
    let (studio, _) = render("studio");
    let (grazing, _) = render("grazing");
    let channels = flat.data.len() / (64 * 64);
    let lum = |img: &image_io::LinearImage, i: usize| {
        (0..3)
            .map(|c| img.data[channels * i + c] as f64)
            .sum::<f64>()
    };
    // every preset lights the sphere
    for img in [&flat, &studio, &grazing] {
        let lit = (0..64 * 64).filter(|&i| lum(img, i) > 0.0).count();
        assert!(lit > 64 * 64 / 3, "{lit}");
    }
    // the rim: near the silhouette (the normal nearly across the view), on the side away from
    // the flat key light (40,120; camera 50,270 by default)
    let (cam, key) = (dir_of(50.0, 270.0), dir_of(40.0, 120.0));
    let rim: Vec<usize> = (0..64 * 64)
        .filter(|&i| {
            let n = vec3(&normal, i);
            dot(n, n) > 0.5 && dot(n, cam) < 0.3 && dot(n, key) < -0.2
        })
        .collect();
    assert!(rim.len() > 20, "{}", rim.len());
    let mean = |img: &image_io::LinearImage| {
        rim.iter().map(|&i| lum(img, i)).sum::<f64>() / rim.len() as f64
    };
    let (s, f) = (mean(&studio), mean(&flat));
    assert!(s > 1.5 * f, "rim: studio {s}, flat {f}");
    // a bad preset: exit 2, the presets named, nothing written
    let bad = fibrefit()
        .current_dir(d)
        .args([
            "render", "--params", "p.toml", "--preset", "disco", "--out", "x.png",
        ])
        .assert()
        .code(2);
    let err = String::from_utf8_lossy(&bad.get_output().stderr).to_string();
    assert!(
        err.contains("studio") && err.contains("grazing") && err.contains("flat"),
        "{err}"
    );
    assert!(!d.join("x.png").exists());
}

/// Adaptive shading of the subsamples (the default) against every subsample shaded
/// (`--every-subsample`): the same coverage bit for bit, the same radiance wherever a pixel's
/// rays do not all hit the object (edges are always shaded at every ray), and elsewhere within
/// a small share of the picture's level (the bound the neighbours' second and third differences
/// give where the radiance is smooth; up to half a small jump across the torus's climbing seam).
#[test]
fn adaptive_subsamples_match_every_subsample_shaded() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    for (k, params) in [
        "model = \"lambert\"\nkd = [0.6, 0.4, 0.2]\n",
        "model = \"varying-topology\"\nkd = 0.3\nks = 0.6\nexponent = 100\nspacing = 2.6\nheight = 0.8\n",
        "model = \"poulin-fournier\"\nkd = 0.3\nks = 0.6\nexponent = 20\nspacing = 2.6\n\
         azimuth_spread_deg = 180\nfuzz = 3.0\nfuzz_depth = 0.3\nfuzz_asymmetry = 0.6\n",
    ]
    .iter()
    .enumerate()
    {
        let p = format!("p{k}.toml");
        std::fs::write(d.join(&p), params).unwrap();
        for (out, every) in [("a.exr", false), ("e.exr", true)] {
            let mut cmd = fibrefit();
            cmd.current_dir(d)
                .args(["render", "--params", &p, "--size", "160", "160"])
                .args(["--supersample", "2", "--out", out, "-q"]);
            if every {
                cmd.arg("--every-subsample");
            }
            cmd.assert().success();
        }
        let (a, e) = (
            image_io::read(&d.join("a.exr"), None, None).unwrap(),
            image_io::read(&d.join("e.exr"), None, None).unwrap(),
        );
        let (alpha_a, alpha_e) = (alpha(&d.join("a.exr")), alpha(&d.join("e.exr")));
        assert_eq!(alpha_a, alpha_e, "{params}");
        let mut lit: Vec<f32> = e.data.iter().copied().filter(|&v| v > 0.0).collect();
        lit.sort_by(f32::total_cmp);
        let level = lit[(lit.len() - 1) * 995 / 1000] as f64;
        let (mut worst, mut same) = (0.0f64, 0usize);
        for (i, &c) in alpha_e.iter().enumerate() {
            let (x, y) = (vec3(&a, i), vec3(&e, i));
            if c < 1.0 {
                assert_eq!(x, y, "{params}: edge pixel {i}");
                continue;
            }
            same += (x == y) as usize;
            for ch in 0..3 {
                worst = worst.max((x[ch] - y[ch]).abs() / level);
            }
        }
        eprintln!("{params}: largest difference {worst:.2e} of the level; {same} interior pixels equal");
        assert!(worst < 1e-2, "{params}: {worst}");
        assert!(worst > 0.0, "{params}: adaptive shading shaded every ray");
    }
}
