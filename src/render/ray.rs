//! A ray and where it meets a surface: the types every object (`objects.rs`, `mesh_object.rs`)
//! and the renderer share.

use crate::model::frame::Vec3;

/// Where a ray meets an object.
#[derive(Clone, Copy, Debug)]
pub struct Hit {
    /// Distance along the (unit) ray.
    pub t: f64,
    pub position: Vec3,
    /// Unit outward normal.
    pub normal: Vec3,
    /// Unit fibre tangent, perpendicular to the normal.
    pub tangent: Vec3,
    /// Surface coordinates in [0, 1] (texture lookups: u across, v up the image).
    pub uv: [f64; 2],
    /// The object's own fibre height H (fibre radii) where it has one (the torus's climbing).
    pub height: Option<f64>,
    /// Principal curvature magnitudes (|k1|, |k2|) where the object's tangents follow its
    /// curvature (meshes), for Ward alphas that follow them (seed 004).
    pub curvature: Option<[f64; 2]>,
}

/// A ray: origin and unit direction.
#[derive(Clone, Copy, Debug)]
pub struct Ray {
    pub origin: Vec3,
    pub direction: Vec3,
}

impl Ray {
    pub fn at(&self, t: f64) -> Vec3 {
        self.origin + self.direction * t
    }
}
