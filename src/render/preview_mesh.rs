//! Triangle meshes of the preview objects, with per-vertex normals, fibre tangents and texture
//! coordinates, for files other renderers open (the glTF export): the same surfaces and fibre
//! directions `render` intersects in closed form ([`super::objects`]), tessellated, or an OBJ
//! mesh with seed 004's curvature-aligned tangents.

use super::curvature::{self, consistent_on_face};
use super::objects::{TORUS_MAJOR, TORUS_TUBE};
use crate::load::mesh::Mesh;
use crate::model::frame::Vec3;
use anyhow::Result;
use std::f64::consts::TAU;

/// A mesh with its per-vertex frames: normal, fibre tangent (unit, perpendicular to the
/// normal), bitangent N x T, and whether the tangent is undefined (umbilic vertices).
pub struct FramedMesh {
    pub mesh: Mesh,
    pub normals: Vec<Vec3>,
    pub tangents: Vec<Vec3>,
    pub bitangents: Vec<Vec3>,
    pub undefined: Vec<bool>,
}

impl FramedMesh {
    /// The frames with bitangents N x T.
    fn new(mesh: Mesh, normals: Vec<Vec3>, tangents: Vec<Vec3>, undefined: Vec<bool>) -> Self {
        let bitangents = normals
            .iter()
            .zip(&tangents)
            .map(|(n, t)| n.cross(t))
            .collect();
        Self {
            mesh,
            normals,
            tangents,
            bitangents,
            undefined,
        }
    }
}

/// A (u, v) grid of `nu` x `nv` quads over a parametric surface `at(u, v)` -> (position, normal,
/// tangent), u, v in [0, 1]; seams keep separate vertices (texture coordinates are continuous).
fn grid(nu: usize, nv: usize, at: impl Fn(f64, f64) -> (Vec3, Vec3, Vec3)) -> Result<FramedMesh> {
    let (mut positions, mut normals, mut tangents, mut uvs) = (vec![], vec![], vec![], vec![]);
    for j in 0..=nv {
        for i in 0..=nu {
            let (u, v) = (i as f64 / nu as f64, j as f64 / nv as f64);
            let (p, n, t) = at(u, v);
            positions.push(p);
            normals.push(n);
            tangents.push(t);
            uvs.push([u, v]);
        }
    }
    let idx = |i: usize, j: usize| j * (nu + 1) + i;
    let mut triangles = vec![];
    for j in 0..nv {
        for i in 0..nu {
            // counter-clockwise seen from the side the normal points to
            triangles.push([idx(i, j), idx(i + 1, j), idx(i + 1, j + 1)]);
            triangles.push([idx(i, j), idx(i + 1, j + 1), idx(i, j + 1)]);
        }
    }
    let mut mesh = Mesh::new(positions, triangles)?;
    mesh.uvs = Some(uvs);
    let undefined = vec![false; normals.len()];
    Ok(FramedMesh::new(mesh, normals, tangents, undefined))
}

/// The swatch [-1, 1]^2 at z = 0, normal +z, fibres at azimuth `psi_deg` from x.
pub fn swatch(psi_deg: f64) -> Result<FramedMesh> {
    let t = Vec3::new(psi_deg.to_radians().cos(), psi_deg.to_radians().sin(), 0.0);
    grid(16, 16, |u, v| {
        (Vec3::new(2.0 * u - 1.0, 2.0 * v - 1.0, 0.0), Vec3::z(), t)
    })
}

/// The unit sphere, fibres along the circles of latitude turned by `psi_deg` towards the
/// meridians (as `render`'s sphere).
pub fn sphere(psi_deg: f64) -> Result<FramedMesh> {
    sphere_grid(psi_deg, 96, 48)
}

/// [`sphere`] tessellated by `nu` x `nv` quads.
pub fn sphere_grid(psi_deg: f64, nu: usize, nv: usize) -> Result<FramedMesh> {
    let psi = psi_deg.to_radians();
    grid(nu, nv, |u, v| {
        let lon = (u - 0.5) * TAU;
        let lat = (v - 0.5) * std::f64::consts::PI;
        let n = Vec3::new(lat.cos() * lon.cos(), lat.cos() * lon.sin(), lat.sin());
        let east = Vec3::new(-lon.sin(), lon.cos(), 0.0);
        let north = n.cross(&east);
        (n, n, east * psi.cos() + north * psi.sin())
    })
}

/// Seed 001's torus (tube r = 0.375, R = 5r/3 about z), fibres wound round the tube.
pub fn torus() -> Result<FramedMesh> {
    torus_grid(128, 64)
}

/// [`torus`] tessellated by `nu` x `nv` quads; the tube angle of grid row j is (j / nv - 1/2) 2 pi
/// (0 on the outer side, as [`super::objects::torus_height`] takes it).
pub fn torus_grid(nu: usize, nv: usize) -> Result<FramedMesh> {
    grid(nu, nv, |u, v| {
        let (a, b) = ((u - 0.5) * TAU, (v - 0.5) * TAU);
        let dir = Vec3::new(a.cos(), a.sin(), 0.0);
        let n = dir * b.cos() + Vec3::z() * b.sin();
        let p = dir * TORUS_MAJOR + n * TORUS_TUBE;
        let t = Vec3::new(-b.sin() * a.cos(), -b.sin() * a.sin(), b.cos());
        (p, n, t)
    })
}

/// A cloth draped over a sphere: the square [-1.2, 1.2]^2 (u, v in [0, 1]) whose height falls
/// off smoothly from a rounded top, with three folds running down its sides, fibres along the
/// warp (the u direction, turned by `psi_deg` towards v, projected on the surface). `nu` x `nv`
/// quads.
pub fn cloth(psi_deg: f64, nu: usize, nv: usize) -> Result<FramedMesh> {
    let psi = psi_deg.to_radians();
    // height z(x, y) and its gradient
    let surface = |x: f64, y: f64| -> (f64, f64, f64) {
        let r2 = x * x + y * y;
        let r = r2.sqrt();
        let a = y.atan2(x);
        // a rounded dome, then the folds growing with the distance from the top
        let dome = 0.9 * (-1.3 * r2).exp();
        let fold = 0.06 * r2 * (3.0 * a).cos();
        let z = dome + fold;
        // d/dx, d/dy by the chain rule (r, a)
        let ddome_dr = -2.6 * r * dome;
        let dfold_dr = 0.12 * r * (3.0 * a).cos();
        let dfold_da = -0.18 * r2 * (3.0 * a).sin();
        let dz_dr = ddome_dr + dfold_dr;
        let (c, s) = if r > 1e-12 { (x / r, y / r) } else { (1.0, 0.0) };
        let inv_r = if r > 1e-12 { 1.0 / r } else { 0.0 };
        let dzdx = dz_dr * c - dfold_da * s * inv_r;
        let dzdy = dz_dr * s + dfold_da * c * inv_r;
        (z, dzdx, dzdy)
    };
    grid(nu, nv, |u, v| {
        let (x, y) = (2.4 * u - 1.2, 2.4 * v - 1.2);
        let (z, zx, zy) = surface(x, y);
        let n = Vec3::new(-zx, -zy, 1.0).normalize();
        let warp = Vec3::new(psi.cos(), psi.sin(), zx * psi.cos() + zy * psi.sin());
        let t = (warp - n * warp.dot(&n)).normalize();
        (Vec3::new(x, y, z - 0.45), n, t)
    })
}

/// An OBJ mesh with seed 004's tangents: each vertex's k1 direction (flipped to agree with its
/// neighbours along the faces where it can), the direction (cos psi, sin psi, 0) projected on
/// the tangent plane at umbilic vertices (flagged undefined).
pub fn curvature_aligned(mesh: Mesh, psi_deg: f64) -> Result<FramedMesh> {
    let curv = curvature::principal_curvatures(&mesh, 2);
    let fallback = Vec3::new(psi_deg.to_radians().cos(), psi_deg.to_radians().sin(), 0.0);
    let normals: Vec<Vec3> = curv.iter().map(|c| c.normal).collect();
    let mut tangents: Vec<Vec3> = curv
        .iter()
        .map(|c| {
            if c.umbilic {
                let t = fallback - c.normal * fallback.dot(&c.normal);
                if t.norm() > 1e-9 {
                    t.normalize()
                } else {
                    c.k1_direction
                }
            } else {
                c.k1_direction
            }
        })
        .collect();
    // directions have no sign: make each face's corners agree with its first, face by face
    let mut fixed = vec![false; tangents.len()];
    for tri in &mesh.triangles {
        let dirs = consistent_on_face(tri.map(|i| tangents[i]));
        for (k, &i) in tri.iter().enumerate() {
            if !fixed[i] {
                tangents[i] = dirs[k];
                fixed[i] = true;
            }
        }
    }
    let undefined = curv.iter().map(|c| c.umbilic).collect();
    Ok(FramedMesh::new(mesh, normals, tangents, undefined))
}
