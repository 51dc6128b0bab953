//! Previews of a material on an object (`fibrefit render`): an orthographic camera's rays, the
//! nearest hit with the objects of [`objects`], and at the hit the model of the parameters in
//! the hit's frame (x along the fibre tangent, z along the normal) at the hit's fibre height,
//! under directional lights of given irradiance. Sits beside export: it reads a model and writes
//! pictures, nothing fits through it.
//!
//! Radiance L = sum over lights of f(l, v) E max(0, n.l) per channel (1/sr x the irradiance's
//! unit); no cast shadows between or within objects (each point sees every light above its
//! horizon), no interreflection: the BRDF as a renderer's direct lighting shows it.

pub mod curvature;
pub mod lighting;
pub mod mesh_object;
pub mod objects;
pub mod preview_mesh;
pub mod ray;
pub mod scene;

use crate::load::texel_maps::TexelMapsIn;
use crate::model::frame::{FibreFrame, Vec3};
use crate::model::topology::{max_height, TopologyMap};
use crate::model::{Albedos, Basis, DirectionPair, Lobe, ShadingModel};
use objects::{Object, Ray};
use rayon::prelude::*;

/// Most pixels of one picture: 32 M. A render holds about 124 bytes per pixel (radiance, alpha,
/// the AOVs and the encoded file; measured peak 130 MB at 1 Mpx), so this is about 4 GB.
pub const MAX_PIXELS: usize = 1 << 25;
/// Most camera rays of one render (pixels x supersample^2): 2^28, about 3.5 minutes at the 1.3 M
/// rays per second measured on 2 cores (torus, 1024^2 x 16 rays in 12.7 s).
pub const MAX_RAYS: usize = 1 << 28;

/// Refuse a picture size and supersampling beyond [`MAX_PIXELS`] and [`MAX_RAYS`] (computed
/// without overflow), with the estimate; `what` names the setting in the message.
pub fn check_budget(
    width: usize,
    height: usize,
    supersample: usize,
    what: &str,
) -> anyhow::Result<()> {
    if !(1..=16).contains(&supersample) {
        anyhow::bail!("{what}: supersample {supersample}: expected 1 to 16");
    }
    let pixels = width
        .checked_mul(height)
        .filter(|&p| p > 0 && p <= MAX_PIXELS);
    let Some(pixels) = pixels else {
        anyhow::bail!(
            "{what}: size {width} x {height}: expected 1 to {} M pixels (about {} bytes each in memory)",
            MAX_PIXELS >> 20,
            124
        );
    };
    let rays = pixels * supersample * supersample;
    if rays > MAX_RAYS {
        anyhow::bail!(
            "{what}: {width} x {height} pixels at supersample {supersample} is {rays} rays, more than the \
             {MAX_RAYS} a render may take (about {:.0} minutes at 1.3 M rays/s); lower the size or the supersampling",
            rays as f64 / 1.3e6 / 60.0
        );
    }
    Ok(())
}

/// Irradiance of `render`'s default fill light (the key lights have 1): a directional light from
/// the camera's direction, so every surface the camera sees is lit by it (n.v > 0 there) and no
/// side of an object is black; a quarter of a key light keeps the key's shading readable.
pub const DEFAULT_FILL: f64 = 0.25;

/// The fill light of irradiance `fill` from `camera` (the direction towards the camera), none
/// for 0; `what` names the setting in the error for a negative or non-finite value.
pub fn fill_light(camera: Vec3, fill: f64, what: &str) -> anyhow::Result<Option<Light>> {
    if !(fill.is_finite() && fill >= 0.0) {
        anyhow::bail!("{what} {fill}: expected a finite irradiance >= 0 (0: no fill light)");
    }
    Ok((fill > 0.0).then_some(Light::Directional {
        direction: camera.normalize(),
        irradiance: fill,
    }))
}

#[derive(Clone, Copy, Debug)]
pub enum Light {
    /// A distant light: unit direction towards it and irradiance E perpendicular to it.
    Directional { direction: Vec3, irradiance: f64 },
    /// A point light: position and radiant intensity I; E = I / r^2 (r in scene units).
    Point { position: Vec3, intensity: f64 },
}

impl Light {
    /// Unit direction towards the light and its perpendicular irradiance at `p`.
    pub fn at(&self, p: &Vec3) -> (Vec3, f64) {
        match *self {
            Light::Directional {
                direction,
                irradiance,
            } => (direction, irradiance),
            Light::Point {
                position,
                intensity,
            } => {
                let d = position - p;
                let r2 = d.norm_squared().max(1e-300);
                (d / r2.sqrt(), intensity / r2)
            }
        }
    }
}

/// A camera looking from `direction` (unit, towards the camera) at `target`: orthographic, its
/// image `half_width` world units either side of the centre horizontally; or, with `pinhole`,
/// a pinhole at that position with that horizontal field of view (degrees).
#[derive(Clone, Copy, Debug)]
pub struct Camera {
    pub direction: Vec3,
    pub target: Vec3,
    pub width: usize,
    pub height: usize,
    pub half_width: f64,
    pub pinhole: Option<(Vec3, f64)>,
}

impl Camera {
    /// Right and up unit vectors of the image plane (up towards +z where it can be).
    fn basis(&self) -> (Vec3, Vec3) {
        let forward = -self.direction;
        let world_up = if self.direction.z.abs() > 0.999 {
            Vec3::y()
        } else {
            Vec3::z()
        };
        let right = forward.cross(&world_up).normalize();
        let up = right.cross(&forward);
        (right, up)
    }

    /// The ray through image point (x, y) in pixels (0, 0 the top left corner).
    pub fn ray(&self, x: f64, y: f64, distance: f64) -> Ray {
        let (right, up) = self.basis();
        let (cx, cy) = (x - 0.5 * self.width as f64, 0.5 * self.height as f64 - y);
        match self.pinhole {
            Some((position, fov_deg)) => {
                let scale = 2.0 * (0.5 * fov_deg.to_radians()).tan() / self.width as f64;
                Ray {
                    origin: position,
                    direction: (-self.direction + (right * cx + up * cy) * scale).normalize(),
                }
            }
            None => {
                let scale = 2.0 * self.half_width / self.width as f64;
                Ray {
                    origin: self.target
                        + (right * cx + up * cy) * scale
                        + self.direction * distance,
                    direction: -self.direction,
                }
            }
        }
    }
}

/// What shades a hit: the model, its albedos, and where the fibre height comes from.
pub struct Material<'a> {
    pub model: &'a dyn ShadingModel,
    pub albedos: Albedos,
    pub channels: usize,
    pub spacing: f64,
    /// H0 and the map scale s of the parameters.
    pub height: f64,
    pub map_scale: f64,
    /// A topology map over the object's (u, v): H = H0 + s (2 m - 1), or added to the object's
    /// own height (the torus) as s (2 m - 1); clamped to [0, H_max].
    pub topology_map: Option<&'a TopologyMap>,
    /// Per-texel maps recovered by `fit --maps`, over the object's (u, v): a texel's height
    /// replaces the topology, its fibre azimuth turns the object's tangent by the difference
    /// from `fibre_azimuth_deg`, its kd and ks replace the albedos.
    pub texel_maps: Option<&'a TexelMapsIn>,
    /// The parameters' fibre azimuth psi, degrees.
    pub fibre_azimuth_deg: f64,
    /// The parameters' lobe (roughness, anisotropy strength), which the texel maps' roughness
    /// and anisotropy strength replace texel by texel ([`ShadingModel::with_lobe`]).
    pub lobe: Lobe,
    /// Ward only: alpha_x = f |k1|, alpha_y = f |k2| (clamped to [0.01, 1]) where the hit has
    /// curvatures (seed 004); the plain Ward lobe there.
    pub ward_curvature: Option<f64>,
    /// The result's smooth correction of the rung, if any: the BRDF per channel times its
    /// factor.
    pub correction: Option<&'a crate::model::correction::Correction>,
}

impl Material<'_> {
    /// The hit with the texel maps' fibre azimuth applied to its tangent.
    pub fn mapped(&self, hit: &objects::Hit) -> objects::Hit {
        let mut h = *hit;
        if let Some(m) = self.texel_maps {
            let (x, y) = m.texel(hit.uv);
            if let Some(psi) = TexelMapsIn::at(&m.psi, x, y, 0) {
                let a = (psi - self.fibre_azimuth_deg).to_radians();
                h.tangent = hit.tangent * a.cos() + hit.normal.cross(&hit.tangent) * a.sin();
            }
        }
        h
    }

    /// The albedos at a hit: the texel maps' kd and ks where they have them (the substrate
    /// follows kd when it is tied to it).
    fn albedos_at(&self, hit: &objects::Hit) -> Albedos {
        let mut a = self.albedos;
        if let Some(m) = self.texel_maps {
            let (x, y) = m.texel(hit.uv);
            let tied = a.substrate == a.diffuse;
            for c in 0..3 {
                if let Some(k) = TexelMapsIn::at(&m.kd, x, y, c) {
                    a.diffuse[c] = k;
                    if tied {
                        a.substrate[c] = k;
                    }
                }
                if let Some(k) = TexelMapsIn::at(&m.ks, x, y, c) {
                    a.specular[c] = k;
                }
            }
        }
        a
    }

    /// The fibre height at a hit, where the model has a topology and the hit fixes one;
    /// `None`: the model's own height distribution (a constant swatch).
    pub fn height_at(&self, hit: &objects::Hit) -> Option<f64> {
        if !self.model.rung().has(crate::model::Ability::Topology) {
            return None;
        }
        let h_max = max_height(self.spacing);
        if let Some(m) = self.texel_maps {
            let (x, y) = m.texel(hit.uv);
            if let Some(h) = TexelMapsIn::at(&m.height, x, y, 0) {
                return Some(h.clamp(0.0, h_max));
            }
        }
        let m = self.topology_map.map(|t| {
            let (w, h) = (t.width, t.height);
            let x = ((hit.uv[0] * w as f64) as usize).min(w - 1);
            let y = (((1.0 - hit.uv[1]) * h as f64) as usize).min(h - 1);
            t.texel(x, y)
        });
        match (hit.height, m) {
            (Some(h), Some(m)) => Some((h + self.map_scale * (2.0 * m - 1.0)).clamp(0.0, h_max)),
            (Some(h), None) => Some(h.clamp(0.0, h_max)),
            (None, Some(m)) => {
                Some((self.height + self.map_scale * (2.0 * m - 1.0)).clamp(0.0, h_max))
            }
            (None, None) => None,
        }
    }

    /// The texel maps' lobe at a hit, where they give a roughness or anisotropy strength there
    /// and the model has such a lobe.
    fn lobe_at(&self, hit: &objects::Hit) -> Option<Lobe> {
        let m = self.texel_maps?;
        let (x, y) = m.texel(hit.uv);
        m.lobe_at(x, y, self.lobe)
    }

    /// What shades a hit: its fibre frame (the texel maps' azimuth applied), albedos and height.
    pub fn point(&self, hit: &objects::Hit) -> ShadingPoint {
        let hit = &self.mapped(hit);
        let n = hit.normal;
        let t = hit.tangent;
        ShadingPoint {
            t,
            b: n.cross(&t),
            n,
            albedos: self.albedos_at(hit),
            height: self.height_at(hit),
            lobe: self.lobe_at(hit),
            ward_alphas: self.ward_curvature.zip(hit.curvature).map(|(f, [k1, k2])| {
                let alpha = |k: f64| (f * k).clamp(0.01, 1.0);
                (alpha(k1), alpha(k2))
            }),
        }
    }

    /// The basis at a shading point for a pair in its fibre frame.
    pub fn basis(&self, sp: &ShadingPoint, pair: &DirectionPair) -> Basis {
        if let Some(m) = sp.lobe.and_then(|l| self.model.with_lobe(l)) {
            return m.basis(pair);
        }
        match (sp.height, sp.ward_alphas) {
            (_, Some((ax, ay))) => crate::model::ward::Ward::new(ax, ay).basis(pair),
            (Some(h), None) => self.model.basis_at_height(pair, h).unwrap_or_default(),
            (None, None) => self.model.basis(pair),
        }
    }

    /// The BRDF per channel (1/sr) at a shading point for world directions `l`, `v` (zero
    /// below the horizon).
    pub fn brdf(&self, sp: &ShadingPoint, l: &Vec3, v: &Vec3) -> [f64; 3] {
        let pair = DirectionPair::new(&FibreFrame::from_azimuth(0.0), &sp.local(l), &sp.local(v));
        self.brdf_of(sp, &pair, &self.basis(sp, &pair))
    }

    /// The BRDF per channel (1/sr) of `basis` at a shading point's `pair`: its albedos, the
    /// correction's factor, a grey result's channel repeated.
    pub fn brdf_of(&self, sp: &ShadingPoint, pair: &DirectionPair, basis: &Basis) -> [f64; 3] {
        let factor = self.factor(pair);
        std::array::from_fn(|c| basis.brdf(&sp.albedos, c.min(self.channels - 1)) * factor[c])
    }

    /// The correction's factor per channel at a pair (1 without one).
    pub fn factor(&self, pair: &DirectionPair) -> [f64; 3] {
        match self.correction {
            Some(c) => {
                let f = c.factor(pair);
                std::array::from_fn(|k| f[k.min(self.channels - 1)])
            }
            None => [1.0; 3],
        }
    }

    /// [`Material::basis`] of every pair at one shading point, into `out`: as one batch
    /// (`basis_many`, `basis_many_at_height`), equal to pair by pair.
    fn bases(&self, sp: &ShadingPoint, pairs: &[DirectionPair], out: &mut [Basis]) {
        if let Some(m) = sp.lobe.and_then(|l| self.model.with_lobe(l)) {
            return m.basis_many(pairs, out);
        }
        match (sp.height, sp.ward_alphas) {
            (_, Some(_)) => {
                for (p, o) in pairs.iter().zip(out.iter_mut()) {
                    *o = self.basis(sp, p);
                }
            }
            (Some(h), None) => {
                if !self.model.basis_many_at_height(pairs, h, out) {
                    out.iter_mut().for_each(|o| *o = Basis::default());
                }
            }
            (None, None) => self.model.basis_many(pairs, out),
        }
    }

    /// Radiance per channel towards `v` at a hit under `lights` (the lights above the
    /// horizon evaluated as one batch).
    pub fn radiance(&self, hit: &objects::Hit, v: &Vec3, lights: &[Light]) -> [f64; 3] {
        let sp = self.point(hit);
        let frame = FibreFrame::from_azimuth(0.0);
        let local_v = sp.local(v);
        let mut pairs = Vec::with_capacity(lights.len());
        let mut weights = Vec::with_capacity(lights.len());
        for light in lights {
            let (l, irradiance) = light.at(&hit.position);
            let cos_i = sp.n.dot(&l);
            if cos_i <= 0.0 {
                continue;
            }
            pairs.push(DirectionPair::new(&frame, &sp.local(&l), &local_v));
            weights.push((irradiance, cos_i));
        }
        let mut bases = vec![Basis::default(); pairs.len()];
        self.bases(&sp, &pairs, &mut bases);
        let mut out = [0.0; 3];
        for ((basis, pair), &(irradiance, cos_i)) in bases.iter().zip(&pairs).zip(&weights) {
            let factor = self.factor(pair);
            for (c, o) in out.iter_mut().enumerate() {
                *o += basis.brdf(&sp.albedos, c.min(self.channels - 1))
                    * factor[c]
                    * irradiance
                    * cos_i;
            }
        }
        out
    }
}

/// A surface point as the material shades it: the fibre frame (T, B = N x T, N) in world
/// coordinates, the albedos and the fibre height there, Ward's alphas where they follow the
/// curvature.
#[derive(Clone, Copy, Debug)]
pub struct ShadingPoint {
    pub t: Vec3,
    pub b: Vec3,
    pub n: Vec3,
    pub albedos: Albedos,
    pub height: Option<f64>,
    pub ward_alphas: Option<(f64, f64)>,
    /// The texel's own lobe (roughness and anisotropy maps), where it has one.
    pub lobe: Option<Lobe>,
}

impl ShadingPoint {
    /// A world direction in the point's (T, B, N) components.
    pub fn local(&self, d: &Vec3) -> Vec3 {
        Vec3::new(d.dot(&self.t), d.dot(&self.b), d.dot(&self.n))
    }

    /// A direction given in the point's (T, B, N) components, in world coordinates.
    pub fn world(&self, d: &Vec3) -> Vec3 {
        self.t * d.x + self.b * d.y + self.n * d.z
    }
}

/// A rendered picture and its per-pixel AOVs (from each pixel's centre ray; zero, and NaN for
/// the height, where it misses).
pub struct Picture {
    pub width: usize,
    pub height: usize,
    /// Linear radiance, RGB, the mean over the pixel's subsamples (misses count as 0).
    pub radiance: Vec<[f32; 3]>,
    /// Fraction of the pixel's subsamples that hit an object.
    pub alpha: Vec<f32>,
    pub normal: Vec<[f32; 3]>,
    pub tangent: Vec<[f32; 3]>,
    pub position: Vec<[f32; 3]>,
    /// Fibre height H used (fibre radii); NaN where none.
    pub fibre_height: Vec<f32>,
    /// Pixels whose every subsample ray was shaded (all those any ray hits with supersample > 1
    /// and [`Subsamples::Every`]; with [`Subsamples::Adaptive`], the edges and the pixels whose
    /// radiance is not smooth).
    pub shaded_every: usize,
}

/// One pixel's radiance, coverage, (normal, tangent, position) and fibre height.
type PixelOut = ([f32; 3], f32, [[f32; 3]; 3], f32);

/// The nearest hit of `ray` among `objects`.
pub fn nearest(objects: &[Object], ray: &Ray) -> Option<objects::Hit> {
    nearest_indexed(objects, ray).map(|(_, hit)| hit)
}

/// How a pixel's subsamples are shaded.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Subsamples {
    /// Every subsample ray is shaded (the exact box-filtered picture; slow for costly rungs).
    Every,
    /// Adaptive: every subsample ray is traced (coverage, edges), but an interior pixel whose
    /// radiance is smooth is shaded once, at its centre, from which (and its neighbouring
    /// pixels' centres) its subsamples' mean is estimated. Over a pixel the mean of the
    /// symmetric s x s subsample grid is the centre's value plus c (L_xx + L_yy), c = (s^2 - 1)
    /// / (24 s^2), to second order (the odd terms cancel); L_xx, L_yy are the second
    /// differences of the neighbouring centres. Where the pixel and the 12 around it (two either
    /// way along each axis, the four diagonal ones) are all interior pixels of one object, the
    /// estimate is the centre's value plus that term, and its error is bounded by c times how
    /// much the second differences change from one pixel to the next (the larger third
    /// difference along each axis: a crease or kink inside the pixel, which the second
    /// differences would take for curvature, shows there) plus (s^2 - 1)^2 / (576 s^4) |L_xxyy|
    /// (the fourth-order term the axes do not see). Nearer an edge the estimate is the centre's
    /// value itself, bounded by c (|L_xx| + |L_yy|) (which does not see a kink, so its bound
    /// must stay within `tolerance` / [`NARROW_SAFETY`]). Where the bound exceeds `tolerance`
    /// times the picture's level (the 99.5th percentile of the lit centres' radiance, what
    /// `--exposure auto` maps to 0.8), or the pixel, or one of its four neighbours, is not
    /// covered by the same object, every subsample is shaded as with [`Subsamples::Every`].
    Adaptive { tolerance: f64 },
}

/// The default adaptive tolerance: 5e-4 of the picture's level, an eighth of an 8-bit step at
/// `--exposure auto` before the sRGB curve (`fibrefit bench render` measures the result
/// against [`Subsamples::Every`]).
pub const ADAPTIVE_TOLERANCE: f64 = 5e-4;

/// Near an edge the centre's value stands for the subsamples only where the second-order term
/// stays within the tolerance divided by this: that bound does not see a crease or a jump
/// inside the pixel (measured: at the torus's climbing seam and next to its silhouette the
/// difference reaches ~15x the bound), the fuller bound does.
pub const NARROW_SAFETY: f64 = 2.5;

/// The subsamples' mean of the pixel at `(x, y)` of a `w` x `h` picture from the centres (`s`
/// subsamples along each axis), where [`Subsamples::Adaptive`]'s bound keeps it within `tol`
/// (radiance units); `None` where every subsample must be shaded.
fn centre_estimate(
    centres: &[Centre],
    (w, h): (usize, usize),
    (x, y): (usize, usize),
    s: usize,
    tol: f64,
) -> Option<[f64; 3]> {
    let me = &centres[y * w + x];
    if !me.interior || x == 0 || y == 0 || x + 1 >= w || y + 1 >= h {
        return None;
    }
    let at = |dx: isize, dy: isize| {
        &centres[(y as isize + dy) as usize * w + (x as isize + dx) as usize]
    };
    const CROSS: [(isize, isize); 4] = [(-1, 0), (1, 0), (0, -1), (0, 1)];
    const OUTER: [(isize, isize); 8] = [
        (-2, 0),
        (2, 0),
        (0, -2),
        (0, 2),
        (-1, -1),
        (1, -1),
        (-1, 1),
        (1, 1),
    ];
    if CROSS.iter().any(|&(dx, dy)| at(dx, dy).object != me.object) {
        return None;
    }
    let wide = x >= 2
        && y >= 2
        && x + 2 < w
        && y + 2 < h
        && CROSS
            .iter()
            .chain(&OUTER)
            .all(|&(dx, dy)| at(dx, dy).interior && at(dx, dy).object == me.object);
    // the s x s midpoint grid's offsets u (pixels): mean u^2 = (s^2 - 1) / (12 s^2)
    let n2 = (s * s) as f64;
    let m2 = (n2 - 1.0) / (12.0 * n2);
    let (c2, c22) = (m2 / 2.0, m2 * m2 / 4.0);
    let mut out = me.radiance;
    for (c, o) in out.iter_mut().enumerate() {
        let l = |dx: isize, dy: isize| at(dx, dy).radiance[c];
        let l0 = l(0, 0);
        let lxx = l(-1, 0) + l(1, 0) - 2.0 * l0;
        let lyy = l(0, -1) + l(0, 1) - 2.0 * l0;
        if wide {
            // the larger change of the second difference to either neighbour
            let third = |m2: f64, m1: f64, p1: f64, p2: f64| {
                let up = p2 - 3.0 * p1 + 3.0 * l0 - m1;
                let down = p1 - 3.0 * l0 + 3.0 * m1 - m2;
                up.abs().max(down.abs())
            };
            let tx = third(l(-2, 0), l(-1, 0), l(1, 0), l(2, 0));
            let ty = third(l(0, -2), l(0, -1), l(0, 1), l(0, 2));
            let row = |dy: isize| l(-1, dy) + l(1, dy) - 2.0 * l(0, dy);
            let lxxyy = row(-1) + row(1) - 2.0 * row(0);
            if !(c2 * (tx + ty) + c22 * lxxyy.abs() <= tol) {
                return None;
            }
            *o = l0 + c2 * (lxx + lyy);
        } else if !(c2 * (lxx.abs() + lyy.abs()) <= tol / NARROW_SAFETY) {
            return None;
        }
    }
    Some(out)
}

/// One pixel's centre: the object hit (its index), its shaded radiance, its AOVs and
/// fibre height, and the subsamples' coverage (hits, and whether all hit the centre's object).
struct Centre {
    object: Option<usize>,
    radiance: [f64; 3],
    aov: [[f32; 3]; 3],
    height: f32,
    hits: usize,
    interior: bool,
}

/// The picture's level: the 99.5th percentile of the lit centres' radiance (largest channel);
/// 1 where nothing is lit.
fn level(centres: &[Centre]) -> f64 {
    let mut lit: Vec<f64> = centres
        .iter()
        .filter(|c| c.object.is_some())
        .map(|c| c.radiance.iter().fold(0.0f64, |a, &b| a.max(b)))
        .filter(|&v| v > 0.0 && v.is_finite())
        .collect();
    if lit.is_empty() {
        return 1.0;
    }
    let k = ((lit.len() - 1) as f64 * 0.995).round() as usize;
    *lit.select_nth_unstable_by(k, |a, b| a.total_cmp(b)).1
}

/// The nearest hit of `ray` among `objects`, with the object's index.
fn nearest_indexed(objects: &[Object], ray: &Ray) -> Option<(usize, objects::Hit)> {
    objects
        .iter()
        .enumerate()
        .filter_map(|(k, o)| o.intersect(ray).map(|h| (k, h)))
        .min_by(|a, b| a.1.t.total_cmp(&b.1.t))
}

/// The index of the object `ray` hits first (no hit's frame computed: coverage only).
fn nearest_object(objects: &[Object], ray: &Ray) -> Option<usize> {
    objects
        .iter()
        .enumerate()
        .filter_map(|(k, o)| o.nearest_t(ray).map(|t| (k, t)))
        .min_by(|a, b| a.1.total_cmp(&b.1))
        .map(|(k, _)| k)
}

/// Render `objects` with `material` under `lights` through `camera`, `supersample` x
/// `supersample` rays per pixel, shaded adaptively ([`Subsamples::Adaptive`] at
/// [`ADAPTIVE_TOLERANCE`]).
pub fn render(
    objects: &[Object],
    material: &Material,
    lights: &[Light],
    camera: &Camera,
    supersample: usize,
    bar: &indicatif::ProgressBar,
) -> Picture {
    render_with(
        objects,
        material,
        lights,
        camera,
        supersample,
        Subsamples::Adaptive {
            tolerance: ADAPTIVE_TOLERANCE,
        },
        bar,
    )
}

/// [`render`] with the subsamples shaded as `shading` says.
pub fn render_with(
    objects: &[Object],
    material: &Material,
    lights: &[Light],
    camera: &Camera,
    supersample: usize,
    shading: Subsamples,
    bar: &indicatif::ProgressBar,
) -> Picture {
    let (w, h) = (camera.width, camera.height);
    let distance = 10.0
        + objects
            .iter()
            .map(|o| o.bound() + (o.centre() - camera.target).norm())
            .fold(0.0, f64::max);
    let s = supersample.max(1);
    let sub = |x: usize, sx: usize| x as f64 + (sx as f64 + 0.5) / s as f64;
    // the centres are shaded where they may stand for the subsamples (or are the only one)
    let adaptive = matches!(shading, Subsamples::Adaptive { .. }) && s > 1;
    let shade_centres = adaptive || s == 1;
    // pass 1: every pixel's centre shaded, its subsamples traced
    let centres: Vec<Centre> = (0..h)
        .into_par_iter()
        .flat_map_iter(|y| {
            (0..w).map(move |x| {
                let centre_ray = camera.ray(x as f64 + 0.5, y as f64 + 0.5, distance);
                let centre = nearest_indexed(objects, &centre_ray);
                let (mut hits, mut interior) = (0usize, centre.is_some());
                if s == 1 {
                    // the one subsample ray is the centre's
                    hits = centre.is_some() as usize;
                } else {
                    for sy in 0..s {
                        for sx in 0..s {
                            let ray = camera.ray(sub(x, sx), sub(y, sy), distance);
                            let hit = nearest_object(objects, &ray);
                            hits += hit.is_some() as usize;
                            interior &= hit == centre.as_ref().map(|c| c.0);
                        }
                    }
                }
                let f = |v: Vec3| [v.x as f32, v.y as f32, v.z as f32];
                match centre {
                    Some((k, hit)) => {
                        let mapped = material.mapped(&hit);
                        Centre {
                            object: Some(k),
                            radiance: match shade_centres {
                                true => material.radiance(&hit, &-centre_ray.direction, lights),
                                false => [0.0; 3],
                            },
                            aov: [f(mapped.normal), f(mapped.tangent), f(mapped.position)],
                            height: material.height_at(&mapped).map_or(f32::NAN, |h| h as f32),
                            hits,
                            interior,
                        }
                    }
                    None => Centre {
                        object: None,
                        radiance: [0.0; 3],
                        aov: [[0.0; 3]; 3],
                        height: f32::NAN,
                        hits,
                        interior: false,
                    },
                }
            })
        })
        .collect();
    bar.inc((h / 2) as u64);
    let tolerance = match shading {
        Subsamples::Adaptive { tolerance } if adaptive => Some(tolerance * level(&centres)),
        _ => None,
    };
    let estimate =
        |x: usize, y: usize| tolerance.and_then(|tol| centre_estimate(&centres, (w, h), (x, y), s, tol));
    // pass 2: the pixels' values, every subsample shaded where the centre does not stand for them
    let rows: Vec<Vec<(PixelOut, bool)>> = (0..h)
        .into_par_iter()
        .map(|y| {
            let row = (0..w)
                .map(|x| {
                    let me = &centres[y * w + x];
                    let n = (s * s) as f64;
                    let (radiance, every) = if s == 1 || me.hits == 0 {
                        (me.radiance, false)
                    } else if let Some(v) = estimate(x, y) {
                        (v.map(|v| v * me.hits as f64 / n), false)
                    } else {
                        let mut sum = [0.0f64; 3];
                        for sy in 0..s {
                            for sx in 0..s {
                                let ray = camera.ray(sub(x, sx), sub(y, sy), distance);
                                if let Some(hit) = nearest(objects, &ray) {
                                    let l = material.radiance(&hit, &-ray.direction, lights);
                                    for c in 0..3 {
                                        sum[c] += l[c];
                                    }
                                }
                            }
                        }
                        (sum.map(|v| v / n), true)
                    };
                    (
                        (
                            radiance.map(|v| v as f32),
                            (me.hits as f64 / n) as f32,
                            me.aov,
                            me.height,
                        ),
                        every,
                    )
                })
                .collect();
            if y % 2 == 1 {
                bar.inc(1);
            }
            row
        })
        .collect();
    let all: Vec<_> = rows.into_iter().flatten().collect();
    let shaded_every = all.iter().filter(|p| p.1).count();
    let all: Vec<PixelOut> = all.into_iter().map(|p| p.0).collect();
    Picture {
        width: w,
        height: h,
        shaded_every,
        radiance: all.iter().map(|p| p.0).collect(),
        alpha: all.iter().map(|p| p.1).collect(),
        normal: all.iter().map(|p| p.2[0]).collect(),
        tangent: all.iter().map(|p| p.2[1]).collect(),
        position: all.iter().map(|p| p.2[2]).collect(),
        fibre_height: all.iter().map(|p| p.3).collect(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A field's centres on a `n` x `n` picture, every pixel an interior pixel of one object,
    /// and the exact mean of each pixel's s x s subsamples.
    fn field(n: usize, s: usize, f: &dyn Fn(f64, f64) -> f64) -> (Vec<Centre>, Vec<f64>) {
        let mut centres = vec![];
        let mut means = vec![];
        for y in 0..n {
            for x in 0..n {
                let (cx, cy) = (x as f64 + 0.5, y as f64 + 0.5);
                let v = f(cx, cy);
                centres.push(Centre {
                    object: Some(0),
                    radiance: [v, 0.5 * v, 0.0],
                    aov: [[0.0; 3]; 3],
                    height: f32::NAN,
                    hits: s * s,
                    interior: true,
                });
                let mut sum = 0.0;
                for sy in 0..s {
                    for sx in 0..s {
                        let u = |k: usize| (k as f64 + 0.5) / s as f64;
                        sum += f(x as f64 + u(sx), y as f64 + u(sy));
                    }
                }
                means.push(sum / (s * s) as f64);
            }
        }
        (centres, means)
    }

    /// Wherever the adaptive rule lets the centres stand for a pixel, its estimate is within
    /// the tolerance of the exact subsample mean: on smooth fields (where it should accept
    /// most pixels), and on creases, kinks and sub-pixel bumps at many angles and offsets
    /// (where a second-order rule alone takes the feature for curvature).
    #[test]
    fn the_adaptive_estimate_stays_within_its_tolerance() {
        let n = 24;
        let tol = 1e-3;
        type Field = Box<dyn Fn(f64, f64) -> f64>;
        let mut smooth: Vec<Field> = vec![];
        let mut rough: Vec<Field> = vec![];
        let mut jumps: Vec<Field> = vec![];
        for k in 0..12 {
            let th = 0.37 + k as f64 * 0.53;
            let (c, s) = (th.cos(), th.sin());
            let off = 12.0 + 0.137 * k as f64;
            // smooth: a broad Gaussian highlight, a slow wave, a quadratic ramp
            let sigma = 4.0 + k as f64;
            smooth.push(Box::new(move |x, y| {
                (-((x - off).powi(2) + (y - 11.3).powi(2)) / (2.0 * sigma * sigma)).exp()
            }));
            smooth.push(Box::new(move |x, y| 0.5 + 0.3 * ((c * x + s * y) / 5.0).sin()));
            smooth.push(Box::new(move |x, y| 1e-3 * (c * x + s * y - off).powi(2)));
            // rough: a kink (a terminator), a crease, a jump, a narrow bump
            rough.push(Box::new(move |x, y| 0.1 * (c * x + s * y - off).max(0.0)));
            rough.push(Box::new(move |x, y| 0.5 - 0.05 * (c * x + s * y - off).abs()));
            jumps.push(Box::new(move |x, y| {
                if c * x + s * y > off {
                    0.5
                } else {
                    0.49
                }
            }));
            let narrow = 0.4 + 0.1 * k as f64;
            rough.push(Box::new(move |x, y| {
                (-((x - off).powi(2) + (y - 11.7).powi(2)) / (2.0 * narrow * narrow)).exp()
            }));
        }
        for s in [2, 3] {
            let mut accepted_smooth = 0usize;
            for (fields, smooth, allowed) in [
                (&smooth, true, tol),
                (&rough, false, tol),
                (&jumps, false, 8.0 * tol),
            ] {
                for (i, f) in fields.iter().enumerate() {
                    let (centres, means) = field(n, s, f.as_ref());
                    for y in 0..n {
                        for x in 0..n {
                            let Some(v) = centre_estimate(&centres, (n, n), (x, y), s, tol)
                            else {
                                continue;
                            };
                            accepted_smooth += smooth as usize;
                            let want = means[y * n + x];
                            assert!(
                                (v[0] - want).abs() <= allowed
                                    && (v[1] - 0.5 * want).abs() <= allowed,
                                "s {s}, field {i} (smooth {smooth}), pixel ({x}, {y}): {} against {want}",
                                v[0]
                            );
                        }
                    }
                }
            }
            // the interior of the smooth fields is mostly shaded once
            let interior = smooth.len() * (n - 4) * (n - 4);
            assert!(accepted_smooth > interior * 9 / 10, "s {s}: {accepted_smooth} of {interior}");
        }
    }
}
