//! The objects `fibrefit render` shows a material on: a sphere, a flat swatch and seed 001's
//! torus wound with fibres (MODEL.md §7), each intersected by a ray in closed form (the torus by
//! sphere tracing its distance function, then Newton on its quartic), and each giving at a hit
//! the normal, the fibre tangent, the surface coordinates (u, v) in [0, 1] and, for the torus,
//! the mathematical topology of its climbing fibres.

use crate::model::frame::Vec3;

pub use super::ray::{Hit, Ray};

#[derive(Clone, Debug)]
pub enum Object {
    /// Unit sphere at the origin; fibres along the circles of latitude about z, turned by
    /// `psi_deg` towards the meridians (0: wound round the z axis, 90: pole to pole).
    Sphere { psi_deg: f64 },
    /// The square [-1, 1]^2 in the plane z = 0, normal +z; fibres at azimuth `psi_deg` from x.
    Swatch { psi_deg: f64 },
    /// Seed 001's torus about the z axis: tube radius r = 0.375, major radius R = 5r/3 (outer side
    /// four times the inner side), fibres wound round the tube (spacing `spacing`), so they
    /// climb twice from the outer to the inner side.
    Torus { spacing: f64 },
    /// A triangle mesh ([`super::mesh_object`]).
    Mesh(std::sync::Arc<super::mesh_object::MeshObject>),
    /// An object scaled by `scale` and moved by `offset` (world = offset + scale object).
    Placed {
        inner: Box<Object>,
        offset: Vec3,
        scale: f64,
    },
}

/// Seed 001's torus: tube radius and major radius R = 5 r / 3.
pub const TORUS_TUBE: f64 = 0.375;
pub const TORUS_MAJOR: f64 = TORUS_TUBE * 5.0 / 3.0;

impl Object {
    /// Radius of a sphere about [`Object::centre`] that holds the object.
    pub fn bound(&self) -> f64 {
        match self {
            Object::Sphere { .. } => 1.0,
            Object::Swatch { .. } => std::f64::consts::SQRT_2,
            Object::Torus { .. } => TORUS_MAJOR + TORUS_TUBE,
            Object::Mesh(m) => m.radius,
            Object::Placed { inner, scale, .. } => inner.bound() * scale,
        }
    }

    /// Centre of the object's bounding sphere (the origin but for meshes).
    pub fn centre(&self) -> Vec3 {
        match self {
            Object::Mesh(m) => m.centre,
            Object::Placed {
                inner,
                offset,
                scale,
            } => offset + inner.centre() * *scale,
            _ => Vec3::zeros(),
        }
    }

    /// The ray parameter t > 0 of the nearest hit of `ray`, without the hit's frame (what
    /// coverage needs: `intersect(ray).map(|h| h.t)`, cheaper).
    pub fn nearest_t(&self, ray: &Ray) -> Option<f64> {
        match *self {
            Object::Torus { .. } => torus_t(ray),
            Object::Mesh(ref m) => m.nearest(ray).map(|n| n.0),
            Object::Placed {
                ref inner,
                offset,
                scale,
            } => inner.nearest_t(&placed(ray, offset, scale)).map(|t| t * scale),
            Object::Sphere { .. } | Object::Swatch { .. } => self.intersect(ray).map(|h| h.t),
        }
    }

    /// The nearest hit of `ray` with t > 0.
    pub fn intersect(&self, ray: &Ray) -> Option<Hit> {
        match *self {
            Object::Sphere { psi_deg } => sphere(ray, psi_deg),
            Object::Swatch { psi_deg } => swatch(ray, psi_deg),
            Object::Torus { spacing } => torus(ray, spacing),
            Object::Mesh(ref m) => m.intersect(ray),
            Object::Placed {
                ref inner,
                offset,
                scale,
            } => {
                let local = placed(ray, offset, scale);
                inner.intersect(&local).map(|h| Hit {
                    t: h.t * scale,
                    position: offset + h.position * scale,
                    ..h
                })
            }
        }
    }
}

/// A world ray in the coordinates of an object placed at `offset`, scaled by `scale` (its t
/// in those coordinates is the world t / `scale`).
fn placed(ray: &Ray, offset: Vec3, scale: f64) -> Ray {
    Ray {
        origin: (ray.origin - offset) / scale,
        direction: ray.direction,
    }
}

/// Entry and exit of a ray through the sphere of radius `r` at the origin.
fn sphere_span(ray: &Ray, r: f64) -> Option<(f64, f64)> {
    let b = ray.origin.dot(&ray.direction);
    let c = ray.origin.norm_squared() - r * r;
    let disc = b * b - c;
    if disc < 0.0 {
        return None;
    }
    let s = disc.sqrt();
    // the nearer root without cancellation
    let q = -b - s;
    let (t0, t1) = (q, c / q);
    let (t0, t1) = if t0 <= t1 { (t0, t1) } else { (t1, t0) };
    (t1 > 0.0).then_some((t0, t1))
}

fn sphere(ray: &Ray, psi_deg: f64) -> Option<Hit> {
    let (t0, t1) = sphere_span(ray, 1.0)?;
    let t = if t0 > 0.0 { t0 } else { t1 };
    let p = ray.at(t);
    let n = p.normalize();
    // latitude circle about z (east) and meridian (north); at the poles any direction
    let east = Vec3::z().cross(&n);
    let east = if east.norm() > 1e-12 {
        east.normalize()
    } else {
        Vec3::x()
    };
    let north = n.cross(&east);
    let psi = psi_deg.to_radians();
    let u = 0.5 + p.y.atan2(p.x) / std::f64::consts::TAU;
    let v = 0.5 + n.z.clamp(-1.0, 1.0).asin() / std::f64::consts::PI;
    Some(Hit {
        t,
        position: p,
        normal: n,
        tangent: east * psi.cos() + north * psi.sin(),
        uv: [u, v],
        height: None,
        curvature: None,
    })
}

fn swatch(ray: &Ray, psi_deg: f64) -> Option<Hit> {
    if ray.direction.z.abs() < 1e-15 {
        return None;
    }
    let t = -ray.origin.z / ray.direction.z;
    if t <= 0.0 {
        return None;
    }
    let p = ray.at(t);
    if p.x.abs() > 1.0 || p.y.abs() > 1.0 {
        return None;
    }
    let psi = psi_deg.to_radians();
    Some(Hit {
        t,
        position: Vec3::new(p.x, p.y, 0.0),
        normal: Vec3::z(),
        tangent: Vec3::new(psi.cos(), psi.sin(), 0.0),
        uv: [0.5 * (p.x + 1.0), 0.5 * (p.y + 1.0)],
        height: None,
        curvature: None,
    })
}

/// Signed distance to the torus.
fn torus_distance(p: &Vec3) -> f64 {
    let q = (p.x * p.x + p.y * p.y).sqrt() - TORUS_MAJOR;
    (q * q + p.z * p.z).sqrt() - TORUS_TUBE
}

/// The torus's quartic f(p) = (|p|^2 + R^2 - r^2)^2 - 4 R^2 (x^2 + y^2) and its derivative
/// along the ray at t.
fn torus_quartic(ray: &Ray, t: f64) -> (f64, f64) {
    let p = ray.at(t);
    let (rr, r2) = (TORUS_MAJOR * TORUS_MAJOR, TORUS_TUBE * TORUS_TUBE);
    let s = p.norm_squared() + rr - r2;
    let f = s * s - 4.0 * rr * (p.x * p.x + p.y * p.y);
    let d = ray.direction;
    let ds = 2.0 * p.dot(&d);
    let df = 2.0 * s * ds - 8.0 * rr * (p.x * d.x + p.y * d.y);
    (f, df)
}

/// Distance to the torus below which its quartic is solved by Newton's method.
const TORUS_NEAR: f64 = 1e-4;

/// Newton on the quartic from `t`, outside the torus and within [`TORUS_NEAR`] of it: the root
/// (the first surface: from outside, with steps below 4 [`TORUS_NEAR`], Newton approaches the
/// nearer root), or `None` where it finds none close by (a ray passing near the surface).
fn torus_newton(ray: &Ray, mut t: f64) -> Option<f64> {
    for _ in 0..12 {
        let (f, df) = torus_quartic(ray, t);
        if !(df.abs() > 1e-300) {
            return None;
        }
        let step = f / df;
        if !(step.abs() < 4.0 * TORUS_NEAR) {
            return None;
        }
        t -= step;
        if step.abs() < 1e-13 * (1.0 + t.abs()) {
            break;
        }
    }
    (torus_distance(&ray.at(t)).abs() < 1e-10).then_some(t)
}

/// The mathematical topology of seed 001's torus at tube angle v (0 on the outer side): a fibre
/// of the outer side's width keeps its count per turn, so its width relative to the outer side
/// is w = (R + r cos v) / (R + r) in [1/4, 1]; each completed layer of climbing halves it, so
/// phi = acos(w 2^k) with k = 0 for w > 1/2 and 1 below (two climbs from the outer to the inner
/// side), and H = d sin(phi) clamped to [0, H_max(d)] (MODEL.md §4, §7).
pub fn torus_height(v: f64, spacing: f64) -> f64 {
    let w = (TORUS_MAJOR + TORUS_TUBE * v.cos()) / (TORUS_MAJOR + TORUS_TUBE);
    let k = if w > 0.5 { 0 } else { 1 };
    let phi = (w * f64::from(1 << k)).min(1.0).acos();
    (spacing * phi.sin()).clamp(0.0, crate::model::topology::max_height(spacing))
}

fn torus(ray: &Ray, spacing: f64) -> Option<Hit> {
    torus_t(ray).map(|t| torus_hit(ray, t, spacing))
}

/// The t of the ray's first hit on the torus.
fn torus_t(ray: &Ray) -> Option<f64> {
    let (t0, t1) = sphere_span(ray, TORUS_MAJOR + TORUS_TUBE + 1e-9)?;
    let mut t = t0.max(0.0);
    // sphere tracing never passes the first surface; within TORUS_NEAR of it Newton on the
    // quartic finishes (quadratically, where sphere tracing creeps linearly at grazing
    // incidence); a near miss, where Newton finds no root, marches on
    let mut found = None;
    for _ in 0..2000 {
        let d = torus_distance(&ray.at(t));
        if d < 1e-10 {
            found = Some(t);
            break;
        }
        if d < TORUS_NEAR {
            if let Some(root) = torus_newton(ray, t) {
                found = Some(root);
                break;
            }
        }
        t += d;
        if t > t1 {
            return None;
        }
    }
    let mut t = found?;
    for _ in 0..3 {
        let (f, df) = torus_quartic(ray, t);
        if df.abs() > 1e-300 {
            let step = f / df;
            if step.abs() < 1e-6 {
                t -= step;
            }
        }
    }
    Some(t)
}

/// The torus's hit at `t` on `ray`: its frame, (u, v) and the climbing fibres' height.
fn torus_hit(ray: &Ray, t: f64, spacing: f64) -> Hit {
    let p = ray.at(t);
    let rho = (p.x * p.x + p.y * p.y).sqrt();
    let u_angle = p.y.atan2(p.x);
    let v_angle = p.z.atan2(rho - TORUS_MAJOR);
    let centre = Vec3::new(u_angle.cos(), u_angle.sin(), 0.0) * TORUS_MAJOR;
    let n = (p - centre).normalize();
    // fibres wound round the tube: along d/dv
    let tangent = Vec3::new(
        -v_angle.sin() * u_angle.cos(),
        -v_angle.sin() * u_angle.sin(),
        v_angle.cos(),
    );
    Hit {
        t,
        position: p,
        normal: n,
        tangent,
        uv: [
            0.5 + u_angle / std::f64::consts::TAU,
            0.5 + v_angle / std::f64::consts::TAU,
        ],
        height: Some(torus_height(v_angle, spacing)),
        curvature: None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Parallel rays along a fixed oblique direction through an n x n grid of points filling
    /// [-half, half]^2 in the plane z = 0, started 5 units before it.
    fn oblique_rays(n: usize, half: f64) -> impl Iterator<Item = Ray> {
        let dir = Vec3::new(0.3, -0.5, -1.0).normalize();
        (0..n * n).map(move |k| {
            let at = |i: usize| -half + 2.0 * half * (i as f64 + 0.5) / n as f64;
            Ray {
                origin: Vec3::new(at(k / n), at(k % n), 0.0) - dir * 5.0,
                direction: dir,
            }
        })
    }

    #[test]
    fn torus_hits_lie_on_the_torus_with_unit_perpendicular_frames() {
        let o = Object::Torus { spacing: 2.0 };
        let mut hits = 0;
        for ray in oblique_rays(40, 1.0) {
            if let Some(h) = o.intersect(&ray) {
                hits += 1;
                assert!(torus_distance(&h.position).abs() < 1e-9);
                assert!((h.normal.norm() - 1.0).abs() < 1e-12);
                assert!((h.tangent.norm() - 1.0).abs() < 1e-12);
                assert!(h.normal.dot(&h.tangent).abs() < 1e-12);
                // visible from the ray's side
                assert!(h.normal.dot(&ray.direction) < 1e-9);
            }
        }
        assert!(hits > 300, "{hits}");
    }

    #[test]
    fn coverage_finds_the_hits_t_for_every_object_kind() {
        let placed = |inner: Object| Object::Placed {
            inner: Box::new(inner),
            offset: Vec3::new(0.1, -0.2, 0.3),
            scale: 1.5,
        };
        let objects = [
            Object::Torus { spacing: 2.0 },
            Object::Sphere { psi_deg: 10.0 },
            Object::Swatch { psi_deg: 0.0 },
            placed(Object::Torus { spacing: 2.0 }),
            placed(Object::Sphere { psi_deg: 0.0 }),
        ];
        for o in &objects {
            let mut hits = 0;
            for ray in oblique_rays(60, 1.6) {
                let t = o.nearest_t(&ray);
                assert_eq!(t, o.intersect(&ray).map(|h| h.t), "{o:?} {ray:?}");
                hits += t.is_some() as usize;
            }
            assert!(hits > 300, "{o:?}: {hits}");
        }
    }

    #[test]
    fn the_torus_climbs_twice_from_the_outer_to_the_inner_side() {
        // flat on the outer side (w = 1), fully climbed at w = 1/2, flat again just inside,
        // fully climbed on the inner side (w = 1/4)
        assert!(torus_height(0.0, 2.0).abs() < 1e-12);
        let h_max = 3f64.sqrt();
        assert!((torus_height(std::f64::consts::PI, 2.0) - h_max).abs() < 1e-9);
        // w = 1/2 where cos v = (R + r)/(2 r) - R/r
        let v_half =
            ((TORUS_MAJOR + TORUS_TUBE) / (2.0 * TORUS_TUBE) - TORUS_MAJOR / TORUS_TUBE).acos();
        assert!((torus_height(v_half - 1e-9, 2.0) - h_max).abs() < 1e-6);
        assert!(torus_height(v_half + 1e-6, 2.0) < 0.01);
    }

    #[test]
    fn sphere_and_swatch_frames() {
        let down = Vec3::new(0.0, 0.0, -1.0);
        let h = Object::Sphere { psi_deg: 0.0 }
            .intersect(&Ray {
                origin: Vec3::new(0.6, 0.0, 5.0),
                direction: down,
            })
            .unwrap();
        assert!((h.position - Vec3::new(0.6, 0.0, 0.8)).norm() < 1e-12);
        assert!((h.tangent - Vec3::y()).norm() < 1e-12);
        let s = Object::Swatch { psi_deg: 90.0 }
            .intersect(&Ray {
                origin: Vec3::new(0.2, 0.3, 2.0),
                direction: down,
            })
            .unwrap();
        assert!((s.t - 2.0).abs() < 1e-12 && (s.tangent - Vec3::y()).norm() < 1e-12);
        assert!(Object::Swatch { psi_deg: 0.0 }
            .intersect(&Ray {
                origin: Vec3::new(1.2, 0.0, 2.0),
                direction: down
            })
            .is_none());
    }
}
