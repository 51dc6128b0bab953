//! Principal curvatures and directions per vertex of a triangle mesh (seed 004's tangent field,
//! MODEL.md §7): at each vertex, in the tangent frame of its normal, a quadric
//! z = a x^2 + b x y + c y^2 + d x + e y is fitted by least squares to the vertex's k-ring
//! neighbours (libigl's method), and its shape operator at the vertex gives the principal
//! curvatures k1 >= k2 and their directions.
//!
//! Sign: curvatures are positive where the surface bends away from its normal (a sphere with
//! outward normals has k1 = k2 = 1/r), negative where it bends towards it; a saddle has one of
//! each. Directions have no sign (d and -d are the same principal direction): a renderer
//! interpolating them across a triangle first flips each corner's to agree with the first
//! corner's ([`consistent_on_face`]). Where k1 ~ k2 (umbilics: every direction is principal,
//! spheres, planes) the directions are undefined and the vertex is flagged, never given an
//! arbitrary direction silently.

use crate::load::mesh::Mesh;
use crate::model::frame::Vec3;
use nalgebra::{Matrix2, Matrix5, Vector5};
use rayon::prelude::*;

/// k1 and k2 closer than this fraction of the larger magnitude (or both below
/// [`FLAT_CURVATURE`] times the inverse mean edge length) make a vertex umbilic.
pub const UMBILIC_TOLERANCE: f64 = 0.05;
pub const FLAT_CURVATURE: f64 = 1e-3;

#[derive(Clone, Copy, Debug)]
pub struct VertexCurvature {
    /// Unit normal (angle-weighted mean of the face normals).
    pub normal: Vec3,
    /// Unit direction of k1 and of k2 (perpendicular to each other and to the normal).
    pub k1_direction: Vec3,
    pub k2_direction: Vec3,
    /// Principal curvatures, 1 / (the mesh's length unit), k1 >= k2.
    pub k1: f64,
    pub k2: f64,
    /// k1 ~ k2: the directions are undefined.
    pub umbilic: bool,
}

/// Angle-weighted vertex normals (oriented as the triangles wind: counter-clockwise seen from
/// the outside gives outward normals).
pub fn vertex_normals(mesh: &Mesh) -> Vec<Vec3> {
    let mut n = vec![Vec3::zeros(); mesh.positions.len()];
    for t in &mesh.triangles {
        let p = t.map(|i| mesh.positions[i]);
        let face = (p[1] - p[0]).cross(&(p[2] - p[0]));
        if face.norm() == 0.0 {
            continue;
        }
        let face = face.normalize();
        for c in 0..3 {
            let (a, b) = (p[(c + 1) % 3] - p[c], p[(c + 2) % 3] - p[c]);
            let angle = a.angle(&b);
            if angle.is_finite() {
                n[t[c]] += face * angle;
            }
        }
    }
    n.into_iter()
        .map(|v| {
            if v.norm() > 0.0 {
                v.normalize()
            } else {
                Vec3::z()
            }
        })
        .collect()
}

/// Vertex neighbours (one ring), sorted.
fn adjacency(mesh: &Mesh) -> Vec<Vec<usize>> {
    let mut adj = vec![Vec::new(); mesh.positions.len()];
    for t in &mesh.triangles {
        for c in 0..3 {
            let (a, b) = (t[c], t[(c + 1) % 3]);
            adj[a].push(b);
            adj[b].push(a);
        }
    }
    for a in &mut adj {
        a.sort_unstable();
        a.dedup();
    }
    adj
}

/// The most neighbours a vertex's quadric is fitted to. A vertex of an ordinary mesh has far
/// fewer within four rings (a regular grid: 60); one in the fan of a polygon of n corners has n
/// within two, which without a bound makes the rings of all vertices O(n^2) work.
pub const MAX_RING_VERTICES: usize = 256;

/// A hasher for vertex indices (a multiplicative hash: no need for SipHash's resistance here).
#[derive(Default)]
struct IndexHasher(u64);

impl std::hash::Hasher for IndexHasher {
    fn finish(&self) -> u64 {
        self.0
    }
    fn write(&mut self, bytes: &[u8]) {
        for &b in bytes {
            self.0 = (self.0.rotate_left(8) ^ b as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15);
        }
    }
    fn write_usize(&mut self, i: usize) {
        self.0 = (i as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15);
    }
}

/// The vertices within `rings` edges of `v`, without `v`, ring by ring in the order found, at
/// most [`MAX_RING_VERTICES`] of them.
fn k_ring(adj: &[Vec<usize>], v: usize, rings: usize) -> Vec<usize> {
    // membership: a scan while the set is small (ordinary meshes), a hash set beyond
    const SCAN: usize = 48;
    let mut seen = vec![v];
    let mut set: std::collections::HashSet<usize, std::hash::BuildHasherDefault<IndexHasher>> =
        Default::default();
    let mut frontier = vec![v];
    'rings: for _ in 0..rings {
        let mut next = Vec::new();
        for &f in &frontier {
            for &n in &adj[f] {
                let known = if seen.len() <= SCAN {
                    seen.contains(&n)
                } else {
                    set.contains(&n)
                };
                if !known {
                    seen.push(n);
                    if seen.len() == SCAN + 1 {
                        set.reserve(MAX_RING_VERTICES + 1);
                        set.extend(seen.iter().copied());
                    } else if seen.len() > SCAN + 1 {
                        set.insert(n);
                    }
                    next.push(n);
                    if seen.len() > MAX_RING_VERTICES {
                        break 'rings;
                    }
                }
            }
        }
        frontier = next;
    }
    seen.remove(0);
    seen
}

/// A unit vector perpendicular to `n`.
fn perpendicular(n: &Vec3) -> Vec3 {
    let a = if n.x.abs() < 0.9 {
        Vec3::x()
    } else {
        Vec3::y()
    };
    (a - n * n.dot(&a)).normalize()
}

/// Principal curvatures of every vertex from quadrics fitted to their `rings`-rings (at least
/// 2; a vertex with fewer than 5 neighbours there uses one ring more, up to 4).
pub fn principal_curvatures(mesh: &Mesh, rings: usize) -> Vec<VertexCurvature> {
    let normals = vertex_normals(mesh);
    let adj = adjacency(mesh);
    let edges: f64 = mesh
        .triangles
        .iter()
        .map(|t| (mesh.positions[t[1]] - mesh.positions[t[0]]).norm())
        .sum::<f64>()
        / mesh.triangles.len() as f64;
    let flat = FLAT_CURVATURE / edges.max(1e-300);
    (0..mesh.positions.len())
        .into_par_iter()
        .map(|v| {
            let n = normals[v];
            let mut k = rings.max(1);
            let mut nb = k_ring(&adj, v, k);
            while nb.len() < 5 && k < 4 {
                k += 1;
                nb = k_ring(&adj, v, k);
            }
            fit(
                mesh.positions[v],
                n,
                nb.iter().map(|&i| mesh.positions[i]),
                flat,
            )
        })
        .collect()
}

/// The quadric fit at `p` with normal `n` over the points `nb`.
fn fit(p: Vec3, n: Vec3, nb: impl Iterator<Item = Vec3>, flat: f64) -> VertexCurvature {
    let e1 = perpendicular(&n);
    let e2 = n.cross(&e1);
    let mut ata = Matrix5::<f64>::zeros();
    let mut atz = Vector5::<f64>::zeros();
    let mut count = 0;
    for q in nb {
        let d = q - p;
        let (x, y, z) = (d.dot(&e1), d.dot(&e2), d.dot(&n));
        let row = Vector5::new(x * x, x * y, y * y, x, y);
        ata += row * row.transpose();
        atz += row * z;
        count += 1;
    }
    let undefined = VertexCurvature {
        normal: n,
        k1_direction: e1,
        k2_direction: e2,
        k1: f64::NAN,
        k2: f64::NAN,
        umbilic: true,
    };
    if count < 5 {
        return undefined;
    }
    let Some(c) = ata.cholesky().map(|ch| ch.solve(&atz)) else {
        return undefined;
    };
    let (a, b, cc, d, e) = (c[0], c[1], c[2], c[3], c[4]);
    // first and second fundamental forms of (x, y, z(x, y)) at the origin
    let w = (1.0 + d * d + e * e).sqrt();
    let first = Matrix2::new(1.0 + d * d, d * e, d * e, 1.0 + e * e);
    let second = Matrix2::new(2.0 * a, b, b, 2.0 * cc) / w;
    let Some(inv) = first.try_inverse() else {
        return undefined;
    };
    // shape operator in the (x, y) parameter basis; its eigenvalues are real (similar to a
    // symmetric matrix); the sign turns "bends away from the normal" positive
    let s = -(inv * second);
    let tr = s.trace();
    let det = s.determinant();
    let disc = (0.25 * tr * tr - det).max(0.0).sqrt();
    let (k1, k2) = (0.5 * tr + disc, 0.5 * tr - disc);
    // eigenvector of k1 in parameters, then in space along x_u = e1 + d n, x_v = e2 + e n
    let eig = |k: f64| -> (f64, f64) {
        let (m00, m01, m10, m11) = (s[(0, 0)] - k, s[(0, 1)], s[(1, 0)], s[(1, 1)] - k);
        if m01.abs() + m00.abs() >= m10.abs() + m11.abs() {
            (-m01, m00)
        } else {
            (m11, -m10)
        }
    };
    let to_space = |(al, be): (f64, f64)| {
        let t = (e1 + n * d) * al + (e2 + n * e) * be;
        let t = t - n * n.dot(&t);
        if t.norm() > 0.0 {
            t.normalize()
        } else {
            e1
        }
    };
    let umbilic = (k1 - k2).abs() <= UMBILIC_TOLERANCE * k1.abs().max(k2.abs())
        || (k1.abs() < flat && k2.abs() < flat);
    let d1 = to_space(eig(k1));
    // k2's direction perpendicular to k1's in the tangent plane (exact for the metric at a
    // point where the fit's slope is small, as at a vertex)
    let d2 = n.cross(&d1).normalize();
    VertexCurvature {
        normal: n,
        k1_direction: d1,
        k2_direction: d2,
        k1,
        k2,
        umbilic,
    }
}

/// The three corners' `directions` made to agree in sign with the first corner's.
pub fn consistent_on_face(directions: [Vec3; 3]) -> [Vec3; 3] {
    let first = directions[0];
    directions.map(|d| if d.dot(&first) < 0.0 { -d } else { d })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_fitted_paraboloid_gives_its_curvatures_and_directions() {
        // z = -(x^2 / 2 + 2 y^2 / 2): curvatures 1 along x and 2 along y at the origin
        let pts: Vec<Vec3> = (-3..=3)
            .flat_map(|i| (-3..=3).map(move |j| (i as f64 * 0.01, j as f64 * 0.01)))
            .filter(|&(x, y)| x != 0.0 || y != 0.0)
            .map(|(x, y)| Vec3::new(x, y, -(0.5 * x * x + y * y)))
            .collect();
        let c = fit(Vec3::zeros(), Vec3::z(), pts.into_iter(), 0.0);
        assert!(
            (c.k1 - 2.0).abs() < 1e-9 && (c.k2 - 1.0).abs() < 1e-9,
            "{c:?}"
        );
        assert!(c.k1_direction.y.abs() > 1.0 - 1e-9);
        assert!(c.k2_direction.x.abs() > 1.0 - 1e-9);
        assert!(!c.umbilic);
    }

    #[test]
    fn corners_agree_in_sign_after_the_flip() {
        let d = consistent_on_face([Vec3::x(), -Vec3::x(), Vec3::new(-0.9, 0.1, 0.0)]);
        assert!(d.iter().all(|v| v.x > 0.0));
    }
}
