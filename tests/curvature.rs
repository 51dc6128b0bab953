//! Principal curvatures of meshes of analytic surfaces (torus, ellipsoid, cylinder, saddle)
//! against the closed form, at three resolutions: the direction error (degrees) and the
//! magnitude error fall as the mesh is refined; umbilics (a sphere) are flagged; and
//! `fibrefit tangents` writes the CSV and the GLB a glTF reader accepts.

use assert_cmd::Command;
use fibrefit::load::mesh::Mesh;
use fibrefit::model::frame::Vec3;
use fibrefit::render::curvature::principal_curvatures;
use nalgebra::Matrix3;

/// A surface given implicitly by F(p) = 0 (outward normal grad F): gradient and Hessian.
trait Implicit {
    fn grad(&self, p: &Vec3) -> Vec3;
    fn hessian(&self, p: &Vec3) -> Matrix3<f64>;
}

/// Exact (k1, k2, direction of k1) at `p`: the shape operator P H P / |grad F| on the tangent
/// plane (positive where the surface bends away from its normal, as a sphere).
fn exact(s: &dyn Implicit, p: &Vec3) -> (f64, f64, Vec3) {
    let g = s.grad(p);
    let n = g.normalize();
    let a = if n.x.abs() < 0.9 {
        Vec3::x()
    } else {
        Vec3::y()
    };
    let t1 = (a - n * n.dot(&a)).normalize();
    let t2 = n.cross(&t1);
    let h = s.hessian(p) / g.norm();
    let (m00, m01, m11) = (t1.dot(&(h * t1)), t1.dot(&(h * t2)), t2.dot(&(h * t2)));
    let mean = 0.5 * (m00 + m11);
    let r = (0.25 * (m00 - m11).powi(2) + m01 * m01).sqrt();
    let (k1, k2) = (mean + r, mean - r);
    // eigenvector of k1
    let (x, y) = if m01.abs() > 1e-14 {
        (m01, k1 - m00)
    } else if m00 >= m11 {
        (1.0, 0.0)
    } else {
        (0.0, 1.0)
    };
    ((k1), k2, (t1 * x + t2 * y).normalize())
}

struct Torus(f64, f64);
impl Implicit for Torus {
    fn grad(&self, p: &Vec3) -> Vec3 {
        let (rr, r) = (self.0, self.1);
        let s = p.norm_squared() + rr * rr - r * r;
        Vec3::new(
            4.0 * s * p.x - 8.0 * rr * rr * p.x,
            4.0 * s * p.y - 8.0 * rr * rr * p.y,
            4.0 * s * p.z,
        )
    }
    fn hessian(&self, p: &Vec3) -> Matrix3<f64> {
        let (rr, r) = (self.0, self.1);
        let s = p.norm_squared() + rr * rr - r * r;
        let mut h = p * p.transpose() * 8.0 + Matrix3::identity() * (4.0 * s);
        h[(0, 0)] -= 8.0 * rr * rr;
        h[(1, 1)] -= 8.0 * rr * rr;
        h
    }
}

struct Ellipsoid(f64, f64, f64);
impl Implicit for Ellipsoid {
    fn grad(&self, p: &Vec3) -> Vec3 {
        Vec3::new(
            2.0 * p.x / (self.0 * self.0),
            2.0 * p.y / (self.1 * self.1),
            2.0 * p.z / (self.2 * self.2),
        )
    }
    fn hessian(&self, _: &Vec3) -> Matrix3<f64> {
        Matrix3::from_diagonal(&Vec3::new(
            2.0 / (self.0 * self.0),
            2.0 / (self.1 * self.1),
            2.0 / (self.2 * self.2),
        ))
    }
}

/// x^2 + y^2 - 1 = 0.
struct Cylinder;
impl Implicit for Cylinder {
    fn grad(&self, p: &Vec3) -> Vec3 {
        Vec3::new(2.0 * p.x, 2.0 * p.y, 0.0)
    }
    fn hessian(&self, _: &Vec3) -> Matrix3<f64> {
        Matrix3::from_diagonal(&Vec3::new(2.0, 2.0, 0.0))
    }
}

/// z - (x^2 - y^2) / 2 = 0, normal up.
struct Saddle;
impl Implicit for Saddle {
    fn grad(&self, p: &Vec3) -> Vec3 {
        Vec3::new(-p.x, p.y, 1.0)
    }
    fn hessian(&self, _: &Vec3) -> Matrix3<f64> {
        Matrix3::from_diagonal(&Vec3::new(-1.0, 1.0, 0.0))
    }
}

/// A grid surface p(u, v) over nu x nv cells, wrapped in u and/or v, triangles wound so that
/// p_u x p_v is the outward normal.
fn grid(nu: usize, nv: usize, wrap_u: bool, wrap_v: bool, p: impl Fn(f64, f64) -> Vec3) -> Mesh {
    let (cu, cv) = (
        if wrap_u { nu } else { nu + 1 },
        if wrap_v { nv } else { nv + 1 },
    );
    let mut pos = Vec::new();
    for j in 0..cv {
        for i in 0..cu {
            pos.push(p(i as f64 / nu as f64, j as f64 / nv as f64));
        }
    }
    let id = |i: usize, j: usize| (j % cv) * cu + (i % cu);
    let mut tri = Vec::new();
    for j in 0..nv {
        for i in 0..nu {
            let (a, b, c, d) = (id(i, j), id(i + 1, j), id(i + 1, j + 1), id(i, j + 1));
            tri.push([a, b, c]);
            tri.push([a, c, d]);
        }
    }
    Mesh::new(pos, tri).unwrap()
}

/// Mean direction error of k1 (degrees) and mean magnitude error relative to the larger exact
/// curvature, over the vertices `keep` accepts where the exact k1 and k2 are distinct.
fn errors(mesh: &Mesh, s: &dyn Implicit, keep: impl Fn(&Vec3) -> bool) -> (f64, f64, usize) {
    let est = principal_curvatures(mesh, 2);
    let (mut dir, mut mag, mut n) = (0.0, 0.0, 0usize);
    for (p, c) in mesh.positions.iter().zip(&est) {
        if !keep(p) {
            continue;
        }
        let (k1, k2, d1) = exact(s, p);
        let scale = k1.abs().max(k2.abs());
        if k1 - k2 < 0.2 * scale {
            continue; // near an umbilic the direction is ill-conditioned
        }
        assert!(!c.umbilic, "flagged umbilic at {p:?}: {c:?} vs {k1} {k2}");
        dir += c.k1_direction.dot(&d1).abs().min(1.0).acos().to_degrees();
        mag += ((c.k1 - k1).abs() + (c.k2 - k2).abs()) / (2.0 * scale);
        n += 1;
    }
    (dir / n as f64, mag / n as f64, n)
}

/// Errors at three resolutions fall at second order (each halving of the edge length divides
/// them by about 4; asserted: by more than 2.5), and the finest are within `bounds` (degrees,
/// relative).
fn converges(name: &str, at: impl Fn(usize) -> (f64, f64, usize), bounds: (f64, f64)) {
    let e: Vec<(f64, f64, usize)> = [1, 2, 4].iter().map(|&k| at(k)).collect();
    eprintln!("{name}: {e:?}");
    for w in e.windows(2) {
        assert!(
            w[1].0 < w[0].0 / 2.5,
            "{name}: direction error does not fall: {e:?}"
        );
        assert!(
            w[1].1 < w[0].1 / 2.5,
            "{name}: magnitude error does not fall: {e:?}"
        );
    }
    assert!(e[2].0 < bounds.0 && e[2].1 < bounds.1, "{name}: {e:?}");
    assert!(
        e.iter().all(|x| x.2 > 20),
        "{name}: too few vertices checked: {e:?}"
    );
}

#[test]
fn curvature_of_a_torus_converges() {
    let (rr, r) = (2.0, 0.7);
    converges(
        "torus",
        |k| {
            let m = grid(24 * k, 12 * k, true, true, |u, v| {
                let (u, v) = (u * std::f64::consts::TAU, v * std::f64::consts::TAU);
                Vec3::new(
                    (rr + r * v.cos()) * u.cos(),
                    (rr + r * v.cos()) * u.sin(),
                    r * v.sin(),
                )
            });
            errors(&m, &Torus(rr, r), |_| true)
        },
        (0.5, 0.015),
    );
}

#[test]
fn curvature_of_an_ellipsoid_converges() {
    let (a, b, c) = (1.0, 1.5, 2.0);
    converges(
        "ellipsoid",
        |k| {
            // latitude-longitude grid without the poles' rows
            let m = grid(32 * k, 16 * k, true, false, |u, v| {
                let th = std::f64::consts::PI * (0.1 + 0.8 * v);
                let ph = std::f64::consts::TAU * u;
                Vec3::new(
                    a * th.sin() * ph.cos(),
                    b * th.sin() * ph.sin(),
                    -c * th.cos(),
                )
            });
            errors(&m, &Ellipsoid(a, b, c), |p| p.z.abs() < 0.6 * c)
        },
        (0.3, 0.005),
    );
}

#[test]
fn curvature_of_a_cylinder_and_a_saddle_converge() {
    converges(
        "cylinder",
        |k| {
            let m = grid(24 * k, 8 * k, true, false, |u, v| {
                let ph = std::f64::consts::TAU * u;
                Vec3::new(ph.cos(), ph.sin(), 2.0 * v - 1.0)
            });
            errors(&m, &Cylinder, |p| p.z.abs() < 0.5)
        },
        (0.1, 0.005),
    );
    converges(
        "saddle",
        |k| {
            let m = grid(12 * k, 12 * k, false, false, |u, v| {
                let (x, y) = (2.0 * u - 1.0, 2.0 * v - 1.0);
                Vec3::new(x, y, 0.5 * (x * x - y * y))
            });
            errors(&m, &Saddle, |p| p.x.abs() < 0.6 && p.y.abs() < 0.6)
        },
        (0.05, 0.001),
    );
}

#[test]
fn a_sphere_is_umbilic_everywhere_and_flagged() {
    let m = grid(32, 16, true, false, |u, v| {
        let th = std::f64::consts::PI * (0.1 + 0.8 * v);
        let ph = std::f64::consts::TAU * u;
        Vec3::new(th.sin() * ph.cos(), th.sin() * ph.sin(), -th.cos()) * 2.0
    });
    let c = principal_curvatures(&m, 2);
    let interior: Vec<_> = m
        .positions
        .iter()
        .zip(&c)
        .filter(|(p, _)| p.z.abs() < 1.2)
        .collect();
    assert!(interior.len() > 200);
    for (p, c) in interior {
        assert!(c.umbilic, "{p:?}: {c:?}");
        // the coarse 32 x 16 mesh: a few per cent
        assert!(
            (c.k1 - 0.5).abs() < 0.03 && (c.k2 - 0.5).abs() < 0.03,
            "{c:?}"
        );
    }
}

#[test]
fn fibrefit_tangents_writes_csv_and_a_valid_glb() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    // a torus as OBJ with texture coordinates
    let (nu, nv, rr, r) = (48, 24, 2.0, 0.7);
    let mut obj = String::new();
    for j in 0..nv {
        for i in 0..nu {
            let (u, v) = (
                i as f64 / nu as f64 * std::f64::consts::TAU,
                j as f64 / nv as f64 * std::f64::consts::TAU,
            );
            obj += &format!(
                "v {} {} {}\nvt {} {}\n",
                (rr + r * v.cos()) * u.cos(),
                (rr + r * v.cos()) * u.sin(),
                r * v.sin(),
                i as f64 / nu as f64,
                j as f64 / nv as f64
            );
        }
    }
    for j in 0..nv {
        for i in 0..nu {
            let id = |i: usize, j: usize| (j % nv) * nu + (i % nu) + 1;
            let (a, b, c, e) = (id(i, j), id(i + 1, j), id(i + 1, j + 1), id(i, j + 1));
            obj += &format!("f {a}/{a} {b}/{b} {c}/{c} {e}/{e}\n");
        }
    }
    std::fs::write(d.join("torus.obj"), obj).unwrap();
    let run = |out: &str| {
        Command::cargo_bin("fibrefit")
            .unwrap()
            .current_dir(d)
            .args(["tangents", "torus.obj", "--out", out, "-q"])
            .assert()
    };
    run("t.csv").success();
    let mut rd = csv::Reader::from_path(d.join("t.csv")).unwrap();
    assert_eq!(
        rd.headers().unwrap().iter().collect::<Vec<_>>(),
        ["x", "y", "z", "nx", "ny", "nz", "k1x", "k1y", "k1z", "k2x", "k2y", "k2z", "k1", "k2"]
    );
    let rows: Vec<Vec<f64>> = rd
        .records()
        .map(|r| r.unwrap().iter().map(|x| x.parse().unwrap()).collect())
        .collect();
    assert_eq!(rows.len(), nu * nv);
    for row in &rows {
        // k1 = 1/r round the tube on this torus (48 x 24: within 10 %), k1 >= k2
        assert!((row[12] - 1.0 / r).abs() < 0.1 / r, "{row:?}");
        assert!(row[12] >= row[13]);
    }
    run("t.glb").success();
    let bytes = std::fs::read(d.join("t.glb")).unwrap();
    let g = gltf::Gltf::from_slice(&bytes).expect("a valid glTF");
    let blob = g.blob.as_ref().expect("a BIN chunk");
    let prim = g.meshes().next().unwrap().primitives().next().unwrap();
    let reader = prim.reader(|_| Some(blob));
    let normals: Vec<[f32; 3]> = reader.read_normals().unwrap().collect();
    let tangents: Vec<[f32; 4]> = reader.read_tangents().unwrap().collect();
    assert_eq!(normals.len(), nu * nv);
    assert_eq!(tangents.len(), nu * nv);
    assert!(reader.read_tex_coords(0).is_some());
    for (n, t) in normals.iter().zip(&tangents) {
        let (n, t3) = (
            Vec3::new(n[0] as f64, n[1] as f64, n[2] as f64),
            Vec3::new(t[0] as f64, t[1] as f64, t[2] as f64),
        );
        assert!((n.norm() - 1.0).abs() < 1e-5 && (t3.norm() - 1.0).abs() < 1e-5);
        assert!(n.dot(&t3).abs() < 1e-5);
        assert!(t[3] == 1.0 || t[3] == -1.0);
    }
    assert_eq!(g.accessors().count(), 6);
    // bad input: exit 2, nothing written
    std::fs::write(d.join("bad.obj"), "v 0 0 0\nv 1 0 0\nf 1 2 3\n").unwrap();
    Command::cargo_bin("fibrefit")
        .unwrap()
        .current_dir(d)
        .args(["tangents", "bad.obj", "--out", "b.csv"])
        .assert()
        .code(2);
    assert!(!d.join("b.csv").exists());
    run("t.txt").code(2);
}

/// `fibrefit tangents` writes one row per vertex in the OBJ's own order, and the GLB's vertices
/// likewise, even when the faces use the vertices in another order (issue 24 item 5): a torus
/// whose `v` lines are shuffled, with faces referring to them by their shuffled numbers, one of
/// them never used by a face and a first face that starts at the file's last vertex.
#[test]
fn tangents_rows_follow_the_files_vertex_order() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let (nu, nv, rr, r) = (48, 24, 2.0, 0.7);
    let n = nu * nv;
    // file position of grid vertex g: a fixed shuffle (a stride coprime with n, reversed)
    let pos = |g: usize| n - 1 - (g * 7) % n;
    let mut lines = vec![String::new(); n];
    let mut xyz = vec![[0.0; 3]; n];
    for j in 0..nv {
        for i in 0..nu {
            let (u, v) = (
                i as f64 / nu as f64 * std::f64::consts::TAU,
                j as f64 / nv as f64 * std::f64::consts::TAU,
            );
            let p = [
                (rr + r * v.cos()) * u.cos(),
                (rr + r * v.cos()) * u.sin(),
                r * v.sin(),
            ];
            let g = j * nu + i;
            xyz[pos(g)] = p;
            lines[pos(g)] = format!("v {} {} {}\n", p[0], p[1], p[2]);
        }
    }
    let mut obj: String = lines.concat();
    obj += "v 9 9 9\n"; // used by no face
    let mut faces = Vec::new();
    for j in 0..nv {
        for i in 0..nu {
            let id = |i: usize, j: usize| pos((j % nv) * nu + (i % nu)) + 1;
            faces.push(format!(
                "f {} {} {} {}\n",
                id(i, j),
                id(i + 1, j),
                id(i + 1, j + 1),
                id(i, j + 1)
            ));
        }
    }
    // the faces in reverse, so the first one the parser meets is not the file's first vertex's
    faces.reverse();
    obj += &faces.concat();
    std::fs::write(d.join("shuffled.obj"), obj).unwrap();
    Command::cargo_bin("fibrefit")
        .unwrap()
        .current_dir(d)
        .args(["tangents", "shuffled.obj", "--out", "t.csv", "-q"])
        .assert()
        .success();
    let mut rd = csv::Reader::from_path(d.join("t.csv")).unwrap();
    let rows: Vec<Vec<f64>> = rd
        .records()
        .map(|r| r.unwrap().iter().map(|x| x.parse().unwrap()).collect())
        .collect();
    assert_eq!(
        rows.len(),
        n + 1,
        "one row per `v` line, the unused one included"
    );
    for (k, row) in rows.iter().take(n).enumerate() {
        for c in 0..3 {
            // (positions pass through f32)
            assert!(
                (row[c] - xyz[k][c]).abs() < 1e-5,
                "row {k}: {row:?} vs {:?}",
                xyz[k]
            );
        }
        // and each row's curvature is that vertex's: k1 = 1/r round the tube
        assert!((row[12] - 1.0 / r).abs() < 0.15 / r, "row {k}: {row:?}");
    }
    assert_eq!(&rows[n][..3], &[9.0, 9.0, 9.0]);
    Command::cargo_bin("fibrefit")
        .unwrap()
        .current_dir(d)
        .args(["tangents", "shuffled.obj", "--out", "t.glb", "-q"])
        .assert()
        .success();
    let bytes = std::fs::read(d.join("t.glb")).unwrap();
    let g = gltf::Gltf::from_slice(&bytes).unwrap();
    let blob = g.blob.as_ref().unwrap();
    let prim = g.meshes().next().unwrap().primitives().next().unwrap();
    let positions: Vec<[f32; 3]> = prim
        .reader(|_| Some(blob))
        .read_positions()
        .unwrap()
        .collect();
    assert!(positions.len() >= n);
    for (k, p) in positions.iter().take(n).enumerate() {
        for c in 0..3 {
            assert!(
                (p[c] as f64 - xyz[k][c]).abs() < 1e-5,
                "GLB vertex {k}: {p:?} vs {:?}",
                xyz[k]
            );
        }
    }
}
