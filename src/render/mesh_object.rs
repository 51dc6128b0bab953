//! A triangle mesh as a render object: a bounding-volume hierarchy (median splits of triangle
//! centroids, slab tests) for the nearest hit (Möller–Trumbore), smooth normals, and a fibre
//! tangent field from the mesh's principal curvature (seed 004), its texture coordinates, or a
//! constant direction.

use super::curvature::{self, consistent_on_face, VertexCurvature};
use super::ray::{Hit, Ray};
use crate::load::mesh::Mesh;
use crate::model::frame::Vec3;
use anyhow::{bail, Result};

/// Where the fibre tangent of a mesh comes from.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum TangentSource {
    /// k1's direction of the principal curvatures, corners made to agree per face; a face
    /// whose corners are all umbilic falls back to `Constant`.
    Curvature,
    /// dp/du of the texture coordinates.
    Uv,
    /// The world direction (cos psi, sin psi, 0) projected on the tangent plane.
    Constant { psi_deg: f64 },
}

#[derive(Clone, Copy, Debug)]
struct Node {
    lo: Vec3,
    hi: Vec3,
    /// Leaf: first triangle and count in `order`; inner: children at `first` and `first + 1`.
    first: usize,
    count: usize,
}

#[derive(Debug)]
pub struct MeshObject {
    mesh: Mesh,
    normals: Vec<Vec3>,
    curvature: Option<Vec<VertexCurvature>>,
    tangents: TangentSource,
    fallback_psi_deg: f64,
    nodes: Vec<Node>,
    order: Vec<usize>,
    pub centre: Vec3,
    pub radius: f64,
}

const LEAF: usize = 4;

impl MeshObject {
    pub fn new(mesh: Mesh, tangents: TangentSource, fallback_psi_deg: f64) -> Result<Self> {
        if tangents == TangentSource::Uv && mesh.uvs.is_none() {
            bail!(
                "{}: --tangents uv needs texture coordinates (vt) on every vertex",
                mesh.source.display()
            );
        }
        let normals = curvature::vertex_normals(&mesh);
        let curvature = (tangents == TangentSource::Curvature)
            .then(|| curvature::principal_curvatures(&mesh, 2));
        let (mut lo, mut hi) = (Vec3::repeat(f64::INFINITY), Vec3::repeat(f64::NEG_INFINITY));
        for p in &mesh.positions {
            lo = lo.inf(p);
            hi = hi.sup(p);
        }
        let centre = (lo + hi) * 0.5;
        let radius = mesh
            .positions
            .iter()
            .map(|p| (p - centre).norm())
            .fold(0.0, f64::max)
            .max(1e-12);
        let mut o = Self {
            order: (0..mesh.triangles.len()).collect(),
            mesh,
            normals,
            curvature,
            tangents,
            fallback_psi_deg,
            nodes: Vec::new(),
            centre,
            radius,
        };
        o.build();
        Ok(o)
    }

    fn corners(&self, t: usize) -> [Vec3; 3] {
        self.mesh.triangles[t].map(|i| self.mesh.positions[i])
    }

    fn build(&mut self) {
        let cent: Vec<Vec3> = (0..self.mesh.triangles.len())
            .map(|t| {
                let c = self.corners(t);
                (c[0] + c[1] + c[2]) / 3.0
            })
            .collect();
        self.nodes.push(Node {
            lo: Vec3::zeros(),
            hi: Vec3::zeros(),
            first: 0,
            count: self.order.len(),
        });
        let mut stack = vec![0usize];
        while let Some(n) = stack.pop() {
            let (first, count) = (self.nodes[n].first, self.nodes[n].count);
            let (mut lo, mut hi) = (Vec3::repeat(f64::INFINITY), Vec3::repeat(f64::NEG_INFINITY));
            for &t in &self.order[first..first + count] {
                for p in self.corners(t) {
                    lo = lo.inf(&p);
                    hi = hi.sup(&p);
                }
            }
            self.nodes[n].lo = lo;
            self.nodes[n].hi = hi;
            if count <= LEAF {
                continue;
            }
            let ext = hi - lo;
            let axis = if ext.x >= ext.y && ext.x >= ext.z {
                0
            } else if ext.y >= ext.z {
                1
            } else {
                2
            };
            let slice = &mut self.order[first..first + count];
            slice.sort_unstable_by(|a, b| cent[*a][axis].total_cmp(&cent[*b][axis]));
            let half = count / 2;
            let left = self.nodes.len();
            self.nodes.push(Node {
                lo,
                hi,
                first,
                count: half,
            });
            self.nodes.push(Node {
                lo,
                hi,
                first: first + half,
                count: count - half,
            });
            // inner node: children at `left`, `left + 1`
            self.nodes[n].first = left;
            self.nodes[n].count = 0;
            stack.push(left);
            stack.push(left + 1);
        }
    }

    fn slab(node: &Node, ray: &Ray, inv: &Vec3, t_max: f64) -> bool {
        let (mut t0, mut t1) = (0.0f64, t_max);
        for a in 0..3 {
            let (mut n, mut f) = (
                (node.lo[a] - ray.origin[a]) * inv[a],
                (node.hi[a] - ray.origin[a]) * inv[a],
            );
            if n > f {
                std::mem::swap(&mut n, &mut f);
            }
            t0 = t0.max(n);
            t1 = t1.min(f);
            if t0 > t1 {
                return false;
            }
        }
        true
    }

    /// Möller–Trumbore: (t, b1, b2) of the hit with triangle `t`.
    fn triangle(&self, t: usize, ray: &Ray) -> Option<(f64, f64, f64)> {
        let [p0, p1, p2] = self.corners(t);
        let (e1, e2) = (p1 - p0, p2 - p0);
        let pv = ray.direction.cross(&e2);
        let det = e1.dot(&pv);
        if det.abs() < 1e-300 {
            return None;
        }
        let inv = 1.0 / det;
        let tv = ray.origin - p0;
        let u = tv.dot(&pv) * inv;
        if !(0.0..=1.0).contains(&u) {
            return None;
        }
        let qv = tv.cross(&e1);
        let v = ray.direction.dot(&qv) * inv;
        if v < 0.0 || u + v > 1.0 {
            return None;
        }
        let d = e2.dot(&qv) * inv;
        (d > 1e-12).then_some((d, u, v))
    }

    /// The nearest triangle `ray` hits: (t, triangle, barycentric u, v).
    pub fn nearest(&self, ray: &Ray) -> Option<(f64, usize, f64, f64)> {
        let inv = ray.direction.map(|d| 1.0 / d);
        let mut best: Option<(f64, usize, f64, f64)> = None;
        let mut stack = vec![0usize];
        while let Some(n) = stack.pop() {
            let node = self.nodes[n];
            let t_max = best.map_or(f64::INFINITY, |b| b.0);
            if !Self::slab(&node, ray, &inv, t_max) {
                continue;
            }
            if node.count > 0 {
                for &t in &self.order[node.first..node.first + node.count] {
                    if let Some((d, u, v)) = self.triangle(t, ray) {
                        if best.is_none_or(|b| d < b.0) {
                            best = Some((d, t, u, v));
                        }
                    }
                }
            } else {
                stack.push(node.first);
                stack.push(node.first + 1);
            }
        }
        best
    }

    /// The nearest hit of `ray`, its frame interpolated over the triangle.
    pub fn intersect(&self, ray: &Ray) -> Option<Hit> {
        let (d, t, u, v) = self.nearest(ray)?;
        Some(self.hit(ray, d, t, [1.0 - u - v, u, v]))
    }

    fn hit(&self, ray: &Ray, d: f64, t: usize, w: [f64; 3]) -> Hit {
        let ids = self.mesh.triangles[t];
        let [p0, p1, p2] = self.corners(t);
        let face = (p1 - p0).cross(&(p2 - p0)).normalize();
        let mut n = (0..3)
            .map(|c| self.normals[ids[c]] * w[c])
            .fold(Vec3::zeros(), |a, b| a + b);
        n = if n.norm() > 0.0 { n.normalize() } else { face };
        // seen from behind: shade the side facing the camera
        if n.dot(&ray.direction) > 0.0 {
            n = -n;
        }
        let uv = self.mesh.uvs.as_ref().map(|uvs| {
            let c = ids.map(|i| uvs[i]);
            [
                w[0] * c[0][0] + w[1] * c[1][0] + w[2] * c[2][0],
                w[0] * c[0][1] + w[1] * c[1][1] + w[2] * c[2][1],
            ]
        });
        let constant = |psi: f64| Vec3::new(psi.to_radians().cos(), psi.to_radians().sin(), 0.0);
        let mut curvature = None;
        let raw = match self.tangents {
            TangentSource::Constant { psi_deg } => constant(psi_deg),
            TangentSource::Uv => {
                let uvs = self.mesh.uvs.as_ref().expect("checked in new");
                let c = ids.map(|i| uvs[i]);
                let (du1, dv1) = (c[1][0] - c[0][0], c[1][1] - c[0][1]);
                let (du2, dv2) = (c[2][0] - c[0][0], c[2][1] - c[0][1]);
                let det = du1 * dv2 - du2 * dv1;
                if det.abs() > 1e-300 {
                    ((p1 - p0) * dv2 - (p2 - p0) * dv1) / det
                } else {
                    constant(self.fallback_psi_deg)
                }
            }
            TangentSource::Curvature => {
                let curv = self.curvature.as_ref().expect("computed in new");
                let defined: Vec<usize> = (0..3).filter(|&c| !curv[ids[c]].umbilic).collect();
                if defined.is_empty() {
                    constant(self.fallback_psi_deg)
                } else {
                    curvature = Some([0, 1].map(|k| {
                        (0..3)
                            .map(|c| {
                                let v = &curv[ids[c]];
                                w[c] * if k == 0 { v.k1.abs() } else { v.k2.abs() }
                            })
                            .sum::<f64>()
                    }));
                    let dirs = consistent_on_face(
                        [0, 1, 2]
                            .map(|k| curv[ids[defined[k.min(defined.len() - 1)]]].k1_direction),
                    );
                    defined
                        .iter()
                        .enumerate()
                        .map(|(k, &c)| dirs[k] * w[c])
                        .fold(Vec3::zeros(), |a, b| a + b)
                }
            }
        };
        let mut tangent = raw - n * n.dot(&raw);
        if tangent.norm() < 1e-9 {
            let a = if n.x.abs() < 0.9 {
                Vec3::x()
            } else {
                Vec3::y()
            };
            tangent = a - n * n.dot(&a);
        }
        Hit {
            t: d,
            position: ray.at(d),
            normal: n,
            tangent: tangent.normalize(),
            uv: uv.unwrap_or([0.5, 0.5]),
            height: None,
            curvature,
        }
    }
}
