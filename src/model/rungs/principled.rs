//! `principled`: Blender 5.0's Principled BSDF as Cycles evaluates it, opaque dielectric subset
//! (metallic, transmission, coat, subsurface, emission and thin film 0, alpha 1), with the
//! tangent across the fibres.
//!
//! # What it follows
//!
//! Cycles' kernel as Blender 5.0 ships it (the `bpy` 5.0.1 module carries the kernel source in
//! `5.0/scripts/addons_core/cycles/source/`); every line below names the function it follows.
//!
//! - `svm_node_closure_bsdf`, case `CLOSURE_BSDF_PRINCIPLED_ID` (`kernel/svm/closure.h`): the
//!   closures and their weights, top layer first, each lower layer's weight scaled by
//!   `closure_layering_weight(albedo, weight) = weight saturate(1 - max(albedo / weight))`:
//!   1. sheen, weight `sheen_weight x sheen_tint`; then the layers below by its albedo;
//!   2. the dielectric GGX specular, `alpha = roughness^2`, with `anisotropic > 0`:
//!      `aspect = sqrt(1 - 0.9 anisotropic)`, `alpha_x = alpha / aspect` along the tangent,
//!      `alpha_y = alpha aspect` (each saturated to [0, 1] by `bsdf_microfacet_ggx_setup`);
//!      the IOR level: `f0 = F0(ior) 2 level`, `eta = ior_from_F0(f0)` unless level = 0.5; the
//!      Fresnel `FresnelGeneralizedSchlick` with `f0 x specular_tint`, F90 1 and the real
//!      Fresnel curve remapped onto them (`microfacet_fresnel`, exponent < 0); the
//!      multiple-scattering energy of `microfacet_ggx_preserve_energy` (the Principled BSDF's
//!      default distribution, Multiscatter GGX); then the diffuse below by its albedo
//!      (`bsdf_microfacet_estimate_albedo`, the table `ggx_gen_schlick_ior_s`);
//!   3. the base colour's Lambertian diffuse (`bsdf_diffuse_eval`; Diffuse Roughness 0).
//! - `bsdf_sheen_setup` / `bsdf_sheen_eval` (`kernel/closure/bsdf_sheen.h`): Zeltner, Burley
//!   and Chiang's linearly transformed cosine, its (a, b) and albedo from `table_sheen_ltc` at
//!   (cos theta_v, sheen roughness clamped to [1e-3, 1]), in the frame of N and the view;
//!   skipped (no closure, no layering) where |a| < 1e-5 or the albedo < 1e-5.
//! - `bsdf_microfacet_eval` (`kernel/closure/bsdf_microfacet.h`): `D G2 F / (4 cos theta_v)`
//!   times the cosine of the light (what Cycles' closure `eval` returns; this rung returns the
//!   BRDF, that over cos theta_l), the anisotropic `bsdf_aniso_D` and `bsdf_aniso_lambda`.
//! - The tables (`scene/shader.tables`) are read as `lookup_table_read*` does: clamped to the
//!   grid, linear between nodes (`cycles_tables`, numbers only).
//!
//! Cycles' Principled BSDF is **not reciprocal**: the sheen's LTC and albedo, the layering
//! weights and the energy compensation all depend on the view. Here `v` is Cycles' `wi`
//! (towards the camera) and `l` its `wo` (towards the light), as fibrefit's pairs are
//! everywhere (light, view).
//!
//! # The fibres
//!
//! Blender's tangent (where the larger alpha lies) is the fibres' B = N x T, across them: a
//! fibre's normals spread across it (as for the `gltf` rung, whose anisotropy direction is the
//! same). So the exported material's Anisotropic Rotation is (fibre azimuth + 90 deg) / 360 of a
//! turn from the UV tangent.
//!
//! # Linear in the base colour
//!
//! With grey sheen and specular tints, the base colour enters only the diffuse closure:
//! `f = c W2 / pi + layers`, so the base colour is the rung's `kd` (solved exactly per channel)
//! and the sheen and specular are the specular column, whose weight `principled_layers` is 1
//! (held: Blender has no such weight).

use crate::model::parameter::{Ability::*, Param};
use crate::model::params::PrincipledShape;
use crate::model::rung::{Cost, LobeAlbedo, LobeSampling, Rung, Sampling, ShaderSection};
use crate::model::{Basis, DirectionPair, Lobe, Local, ShadingModel};
use std::f64::consts::FRAC_1_PI;

pub mod cycles_tables;
use cycles_tables::{GGX_E, GGX_EAVG, GGX_GEN_SCHLICK_IOR_S, SHEEN_LTC};

/// The rung.
pub static RUNG: Rung = Rung {
    name: "principled",
    description: "Blender 5.0's Principled BSDF as Cycles renders it (sheen, anisotropic GGX, IOR)",
    abilities: &[FibreDiffuse, FibreDirection, PrincipledMaterial],
    build: |a| Box::new(Principled::new(&a.principled)),
    sampling: Sampling {
        lobe: LobeSampling::Ggx,
        diffuse_tube: 0.0,
        diffuse_cosine: 1.0,
        lobe_albedo: LobeAlbedo::Normalised,
        cone_from: None,
    },
    shader: ShaderSection::Sections {
        sections: &["principled"],
        body: "    return fibrefit_principled(l, v, p);\n",
        material_rows: Some(|p| Principled::new(&p.principled).shader_rows()),
    },
    cost: Cost::ClosedForm,
    auto_rank: Some(7),
    example: &[
        (Param::Kd, 0.4),
        (Param::Roughness, 0.45),
        (Param::Anisotropic, 0.6),
        (Param::Ior, 1.5),
        (Param::SheenWeight, 0.5),
        (Param::SheenRoughness, 0.5),
    ],
    symmetries: &[],
    renderer: Some("Blender (Cycles' Principled BSDF)"),
    auto_fuzz: false,
};

/// Cycles' `CLOSURE_WEIGHT_CUTOFF`: closures lighter than this are not made.
const WEIGHT_CUTOFF: f64 = 1e-5;

/// The material at one parameter set, with what does not depend on the directions.
#[derive(Clone, Debug)]
pub struct Principled {
    /// GGX alpha along Blender's tangent (across the fibres, B) and along the fibres (T).
    alpha_b: f64,
    alpha_t: f64,
    /// The energy tables' roughness sqrt(sqrt(alpha_b alpha_t)) and E_avg there (by view
    /// direction only E changes).
    rough: f64,
    e_avg: f64,
    /// The specular's relative IOR after the IOR level, its Fresnel F0 (tinted, saturated) and
    /// the untinted F0 of eta; `None`: no specular closure (eta = 1).
    specular: Option<Specular>,
    sheen_weight: f64,
    /// Sheen roughness clamped as `bsdf_sheen_setup` does.
    sheen_roughness: f64,
}

#[derive(Clone, Copy, Debug)]
struct Specular {
    eta: f64,
    /// `fresnel->f0` (F0 x specular tint, saturated).
    f0: f64,
    /// F0 of eta (the real Fresnel's value at normal incidence).
    f0_real: f64,
    /// The table coordinate z = sqrt(|eta - 1| / (eta + 1)) of `ggx_gen_schlick_ior_s`.
    z: f64,
    /// The single-scattering Fresnel average Fss (`bsdf_microfacet_setup_fresnel_generalized_schlick`).
    fss: f64,
}

impl Principled {
    /// The material of `p`.
    pub fn new(p: &PrincipledShape) -> Self {
        // "Apply IOR adjustment"
        let ior = p.ior.max(1e-5);
        let mut eta = ior;
        let mut f0 = f0_from_ior(eta);
        if p.specular_ior_level.max(0.0) != 0.5 {
            f0 *= 2.0 * p.specular_ior_level.max(0.0);
            eta = ior_from_f0(f0);
            if ior < 1.0 {
                eta = 1.0 / eta;
            }
        }
        let specular = (eta != 1.0).then(|| {
            let f0 = (f0 * p.specular_tint.max(0.0)).clamp(0.0, 1.0);
            let f0_real = f0_from_ior(eta);
            let s = inverse_lerp(f0_real, 1.0, fresnel_dielectric_fss(eta)).clamp(0.0, 1.0);
            Specular {
                eta,
                f0,
                f0_real,
                z: ((eta - 1.0) / (eta + 1.0)).abs().sqrt(),
                fss: f0 + (1.0 - f0) * s,
            }
        });
        let mut m = Self {
            alpha_b: 0.0,
            alpha_t: 0.0,
            rough: 0.0,
            e_avg: 0.0,
            specular,
            sheen_weight: p.sheen_weight.max(0.0),
            // saturated by the node, then clamped by `bsdf_sheen_setup`
            sheen_roughness: p.sheen_roughness.clamp(1e-3, 1.0),
        };
        m.set_lobe(p.roughness, p.anisotropic);
        m
    }

    /// The GGX lobe of `roughness` and `anisotropic`, with what the energy tables take of it.
    fn set_lobe(&mut self, roughness: f64, anisotropic: f64) {
        (self.alpha_b, self.alpha_t) = alphas(roughness, anisotropic);
        self.rough = (self.alpha_b * self.alpha_t).sqrt().sqrt();
        self.e_avg = lookup_1d(&GGX_EAVG, self.rough);
    }

    /// The rows the shader export bakes (`FibrefitParams::material`, read by the `principled`
    /// section of `fibrefit.wgsl`): [0] alpha across the fibres (Blender's tangent), alpha along
    /// them, E_avg, 1 with a specular closure; [1] eta, F0 (tinted), F0 of eta, Fss; [2] the
    /// sheen weight; then this material's slices of Cycles' tables by cos theta_v: [3 + k] at
    /// cos theta_v = k / 31 (k = 0..31) GGX E at its roughness and the sheen LTC's a, b and
    /// albedo at its sheen roughness; [35..39) `ggx_gen_schlick_ior_s` at its roughness and eta
    /// at k / 15, four a row. Each slice is the table's bilinear interpolation along its other
    /// axes, so linear interpolation along cos theta_v gives what `parts` reads (the same
    /// bilinear form, summed in another order).
    pub fn shader_rows(&self) -> Vec<[f64; 4]> {
        let blend = |d0: f64, d1: f64, t: f64| if t == 0.0 { d0 } else { (1.0 - t) * d0 + t * d1 };
        // the node below `x` in [0, 1] over `n` nodes, the one above and the fraction
        let at = |x: f64, n: usize| {
            let y = x.clamp(0.0, 1.0) * (n - 1) as f64;
            let i = (y as usize).min(n - 1);
            (i, (i + 1).min(n - 1), y - i as f64)
        };
        let ggx_e: Vec<f64> = (0..32)
            .map(|j| lookup_1d(&GGX_E[j * 32..(j + 1) * 32], self.rough))
            .collect();
        let albedo_s: Vec<f64> = match &self.specular {
            Some(s) => {
                let (i, next, t) = at(s.z, 16);
                let row = |plane: usize, j: usize| {
                    let start = plane * 256 + j * 16;
                    lookup_1d(&GGX_GEN_SCHLICK_IOR_S[start..start + 16], self.rough)
                };
                (0..16).map(|j| blend(row(i, j), row(next, j), t)).collect()
            }
            None => vec![0.0; 16],
        };
        let (i, next, t) = at(self.sheen_roughness, 32);
        let sheen = |k: usize| -> Vec<f64> {
            let plane = &SHEEN_LTC[k * 1024..(k + 1) * 1024];
            (0..32)
                .map(|x| blend(plane[i * 32 + x] as f64, plane[next * 32 + x] as f64, t))
                .collect()
        };
        let s = self.specular.unwrap_or(Specular {
            eta: 1.0,
            f0: 0.0,
            f0_real: 0.0,
            z: 0.0,
            fss: 0.0,
        });
        let flag = if self.specular.is_some() { 1.0 } else { 0.0 };
        let mut rows = vec![
            [self.alpha_b, self.alpha_t, self.e_avg, flag],
            [s.eta, s.f0, s.f0_real, s.fss],
            [self.sheen_weight, 0.0, 0.0, 0.0],
        ];
        let (a, b, albedo) = (sheen(0), sheen(1), sheen(2));
        rows.extend((0..32).map(|k| [ggx_e[k], a[k], b[k], albedo[k]]));
        rows.extend(albedo_s.chunks(4).map(|c| [c[0], c[1], c[2], c[3]]));
        rows
    }

    /// The BRDF's parts at (l, v), v towards the camera: (diffuse per unit base colour, the
    /// specular closure's, the sheen closure's), each over cos theta_l (a BRDF, 1/sr).
    pub fn parts(&self, l: &Local, v: &Local) -> (f64, f64, f64) {
        let mu_v = v.n;
        // 1. sheen (`bsdf_sheen_setup`, `bsdf_sheen_eval`)
        let mut weight = 1.0;
        let mut sheen = 0.0;
        if self.sheen_weight > WEIGHT_CUTOFF {
            let (a, b, albedo) = sheen_ltc(mu_v, self.sheen_roughness);
            if a.abs() >= 1e-5 && albedo >= 1e-5 {
                let w = self.sheen_weight * albedo;
                // at normal view Cycles' frame is the world's, which the swatch frame does not
                // know (Cycles' own value there turns with the object): the table's skew b
                // there (|b| <= 0.004, largest at sheen roughness 0.13) is dropped, keeping the
                // rung invariant under T -> -T
                let (lo, b) = match sheen_local(l, v) {
                    Some(lo) => (lo, b),
                    None => (*l, 0.0),
                };
                let len2 = (a * lo.t + b * lo.n).powi(2) + (a * lo.b).powi(2) + lo.n * lo.n;
                // val = cos theta_l (a / len2)^2 / pi; the BRDF is that over cos theta_l
                let val = FRAC_1_PI * (a / len2).powi(2);
                sheen = if lo.n > 0.0 { w * val } else { 0.0 };
                weight = layering(w, weight);
            }
        }
        // 2. the specular
        let mut specular = 0.0;
        if let Some(s) = &self.specular {
            let (rough, e_avg) = (self.rough, self.e_avg);
            let e = lookup_2d(&GGX_E, 32, 32, rough, mu_v);
            let missing = (1.0 - e) / e;
            let energy_scale = 1.0 + missing;
            let darkening = if s.fss != 1.0 {
                let fms = s.fss * e_avg / (1.0 - s.fss * (1.0 - e_avg));
                (1.0 + fms * missing) / energy_scale
            } else {
                1.0
            };
            let w = weight * darkening;
            if self.alpha_b * self.alpha_t > 2e-10 {
                specular = w * energy_scale * self.ggx(s, l, v);
            }
            // the layers below by the specular's albedo
            let ts = lookup_3d(&GGX_GEN_SCHLICK_IOR_S, rough, mu_v, s.z);
            let albedo = w * (s.f0 + (1.0 - s.f0) * ts);
            weight = layering(albedo, weight);
        }
        // 3. the base colour's Lambertian diffuse
        (weight * FRAC_1_PI, specular, sheen)
    }

    /// The single-scattering GGX BRDF with the remapped Fresnel (`bsdf_microfacet_eval` over
    /// cos theta_l): F D G2 / (4 cos theta_v cos theta_l).
    fn ggx(&self, s: &Specular, l: &Local, v: &Local) -> f64 {
        let (t, b, n) = (l.t + v.t, l.b + v.b, l.n + v.n);
        let len = (t * t + b * b + n * n).sqrt();
        if len == 0.0 {
            return 0.0;
        }
        let h = Local {
            t: t / len,
            b: b / len,
            n: n / len,
        };
        let cos_hi = h.dot(v);
        let f_real = fresnel_dielectric(cos_hi, s.eta);
        let f = s.f0 + (1.0 - s.f0) * inverse_lerp(s.f0_real, 1.0, f_real).clamp(0.0, 1.0);
        // `bsdf_aniso_D`: x along Blender's tangent (B), y along the fibres (up to sign)
        let (ax, ay) = (self.alpha_b, self.alpha_t);
        let (hx, hy, hz) = (h.b / ax, h.t / ay, h.n);
        let d = FRAC_1_PI / (ax * ay * (hx * hx + hy * hy + hz * hz).powi(2));
        let lambda = |w: &Local| {
            let s2 = ((ax * w.b).powi(2) + (ay * w.t).powi(2)) / (w.n * w.n);
            0.5 * ((1.0 + s2).sqrt() - 1.0)
        };
        let g2 = 1.0 / (1.0 + lambda(l) + lambda(v));
        f * d * g2 / (4.0 * v.n * l.n)
    }
}

/// GGX alphas (across the fibres = along Blender's tangent, along the fibres) of roughness r
/// and Anisotropic a: `alpha = r^2`, and for a > 0 `alpha / aspect`, `alpha aspect` with
/// `aspect = sqrt(1 - 0.9 a)`, each saturated.
pub fn alphas(roughness: f64, anisotropic: f64) -> (f64, f64) {
    let r = roughness.clamp(0.0, 1.0);
    let a = anisotropic.clamp(0.0, 1.0);
    let alpha = r * r;
    if a > 0.0 {
        let aspect = (1.0 - 0.9 * a).sqrt();
        ((alpha / aspect).clamp(0.0, 1.0), (alpha * aspect).clamp(0.0, 1.0))
    } else {
        (alpha, alpha)
    }
}

/// `closure_layering_weight` for grey weights: the weight left below a layer of albedo
/// `albedo` over a weight `weight`.
fn layering(albedo: f64, weight: f64) -> f64 {
    let ratio = if weight != 0.0 { albedo / weight } else { 0.0 };
    weight * (1.0 - ratio).clamp(0.0, 1.0)
}

/// The light direction in the sheen's frame (`make_orthonormals_safe_tangent(N, wi)`):
/// B = N x v normalised, T = B x N; `None` at normal view (N x v = 0), where Cycles falls back to
/// `make_orthonormals(N)`, a frame fixed to the world's axes, not the swatch's.
fn sheen_local(l: &Local, v: &Local) -> Option<Local> {
    // N x v with N = (0, 0, 1) in (t, b, n): (-v.b, v.t, 0)
    let (bx, by) = (-v.b, v.t);
    let len = (bx * bx + by * by).sqrt();
    if len == 0.0 {
        return None;
    }
    let (bx, by) = (bx / len, by / len);
    // T = B x N = (by, -bx, 0)
    let (tx, ty) = (by, -bx);
    Some(Local {
        t: l.t * tx + l.b * ty,
        b: l.t * bx + l.b * by,
        n: l.n,
    })
}

/// The sheen's LTC (a, b) and albedo at cos theta_v and the sheen roughness.
fn sheen_ltc(mu: f64, roughness: f64) -> (f64, f64, f64) {
    let plane = |k: usize| lookup_2d(&SHEEN_LTC[k * 1024..(k + 1) * 1024], 32, 32, mu, roughness);
    (plane(0), plane(1), plane(2))
}

/// `lookup_table_read`: x clamped to [0, 1] over `data`'s nodes, linear between them.
fn lookup_1d(data: &[f32], x: f64) -> f64 {
    let size = data.len();
    let x = x.clamp(0.0, 1.0) * (size - 1) as f64;
    let index = (x as usize).min(size - 1);
    let next = (index + 1).min(size - 1);
    let t = x - index as f64;
    let d0 = data[index] as f64;
    if t == 0.0 {
        return d0;
    }
    (1.0 - t) * d0 + t * data[next] as f64
}

/// `lookup_table_read_2D`: x the fast axis (`xsize` a row), y the rows.
fn lookup_2d(data: &[f32], xsize: usize, ysize: usize, x: f64, y: f64) -> f64 {
    let y = y.clamp(0.0, 1.0) * (ysize - 1) as f64;
    let index = (y as usize).min(ysize - 1);
    let next = (index + 1).min(ysize - 1);
    let t = y - index as f64;
    let row = |i: usize| lookup_1d(&data[i * xsize..(i + 1) * xsize], x);
    let d0 = row(index);
    if t == 0.0 {
        return d0;
    }
    (1.0 - t) * d0 + t * row(next)
}

/// `lookup_table_read_3D` of a 16 x 16 x 16 table (x fast, then y, then z).
fn lookup_3d(data: &[f32], x: f64, y: f64, z: f64) -> f64 {
    let z = z.clamp(0.0, 1.0) * 15.0;
    let index = (z as usize).min(15);
    let next = (index + 1).min(15);
    let t = z - index as f64;
    let plane = |i: usize| lookup_2d(&data[i * 256..(i + 1) * 256], 16, 16, x, y);
    let d0 = plane(index);
    if t == 0.0 {
        return d0;
    }
    (1.0 - t) * d0 + t * plane(next)
}

/// `F0_from_ior`.
pub fn f0_from_ior(ior: f64) -> f64 {
    ((ior - 1.0) / (ior + 1.0)).powi(2)
}

/// `ior_from_F0` (F0 clamped to [0, 0.99]).
pub fn ior_from_f0(f0: f64) -> f64 {
    let s = f0.clamp(0.0, 0.99).sqrt();
    (1.0 + s) / (1.0 - s)
}

/// `inverse_lerp(a, b, x) = (x - a) / (b - a)`.
fn inverse_lerp(a: f64, b: f64, x: f64) -> f64 {
    (x - a) / (b - a)
}

/// `fresnel_dielectric_Fss`: Kulla and Conty's fit of the average single-scattering Fresnel.
fn fresnel_dielectric_fss(eta: f64) -> f64 {
    if eta < 1.0 {
        0.997118 + eta * (0.1014 - eta * (0.965241 + eta * 0.130607))
    } else {
        (eta - 1.0) / (4.08567 + 1.00071 * eta)
    }
}

/// `fresnel_dielectric`: the unpolarised Fresnel reflectance at cos theta_i for relative IOR
/// eta (1 under total internal reflection).
pub fn fresnel_dielectric(cos_i: f64, eta: f64) -> f64 {
    let eta_cos_t_sq = eta * eta - (1.0 - cos_i * cos_i);
    if eta_cos_t_sq <= 0.0 {
        return 1.0;
    }
    let ci = cos_i.abs();
    let ct = -eta_cos_t_sq.max(0.0).sqrt() / eta;
    let rs = (ci + eta * ct) / (ci - eta * ct);
    let rp = (ct + eta * ci) / (eta * ci - ct);
    0.5 * (rs * rs + rp * rp)
}

impl ShadingModel for Principled {
    fn rung(&self) -> &'static Rung {
        &RUNG
    }

    fn with_lobe(&self, lobe: Lobe) -> Option<Box<dyn ShadingModel>> {
        let mut p = self.clone();
        p.set_lobe(lobe.roughness, lobe.anisotropy);
        Some(Box::new(p))
    }

    fn basis_above_horizon(&self, pair: &DirectionPair) -> Basis {
        let (diffuse, specular, sheen) = self.parts(&pair.l, &pair.v);
        Basis {
            diffuse,
            specular: specular + sheen,
            substrate: 0.0,
            fuzz: 0.0,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn dir(theta_deg: f64, phi_deg: f64) -> Local {
        let (t, p) = (theta_deg.to_radians(), phi_deg.to_radians());
        Local {
            t: t.sin() * p.cos(),
            b: t.sin() * p.sin(),
            n: t.cos(),
        }
    }

    fn shape() -> PrincipledShape {
        PrincipledShape {
            roughness: 0.45,
            anisotropic: 0.6,
            ior: 1.5,
            specular_ior_level: 0.5,
            specular_tint: 1.0,
            sheen_weight: 0.5,
            sheen_roughness: 0.5,
        }
    }

    #[test]
    fn the_lookups_hit_the_nodes_and_interpolate_between_them() {
        // a node: the table's value; halfway: the mean of the two
        assert_eq!(lookup_1d(&GGX_EAVG, 0.0), 1.0);
        assert_eq!(lookup_1d(&GGX_EAVG, 1.0), GGX_EAVG[31] as f64);
        let half = lookup_1d(&GGX_EAVG, 0.5 / 31.0);
        assert!((half - 0.5 * (GGX_EAVG[0] as f64 + GGX_EAVG[1] as f64)).abs() < 1e-12);
        // 2D: y selects the row
        let v = lookup_2d(&GGX_E, 32, 32, 3.0 / 31.0, 1.0);
        assert_eq!(v, GGX_E[31 * 32 + 3] as f64);
        // 3D: z the plane
        let v = lookup_3d(&GGX_GEN_SCHLICK_IOR_S, 2.0 / 15.0, 5.0 / 15.0, 8.0 / 15.0);
        assert_eq!(v, GGX_GEN_SCHLICK_IOR_S[8 * 256 + 5 * 16 + 2] as f64);
    }

    #[test]
    fn the_sheen_ltc_is_normalised_and_symmetric_at_normal_view() {
        // each LTC integrates to 1 over the hemisphere (its pdf), at a few table points
        for (mu, r) in [(0.2, 0.3), (0.6, 0.5), (0.95, 0.9)] {
            let (a, b, _) = sheen_ltc(mu, r);
            let n = 400;
            let mut sum = 0.0;
            for i in 0..n {
                let th = (i as f64 + 0.5) / n as f64 * std::f64::consts::FRAC_PI_2;
                for j in 0..2 * n {
                    let ph = (j as f64 + 0.5) / (2 * n) as f64 * std::f64::consts::TAU;
                    let (x, y, z) = (th.sin() * ph.cos(), th.sin() * ph.sin(), th.cos());
                    let len2 = (a * x + b * z).powi(2) + (a * y).powi(2) + z * z;
                    let da = (std::f64::consts::FRAC_PI_2 / n as f64)
                        * (std::f64::consts::PI / n as f64)
                        * th.sin();
                    sum += z * FRAC_1_PI * (a / len2).powi(2) * da;
                }
            }
            assert!((sum - 1.0).abs() < 2e-3, "mu {mu} r {r}: {sum}");
        }
        // at normal view the LTC's skew b is small at every roughness (the rung drops it there)
        for k in 0..=40 {
            let (_, b, _) = sheen_ltc(1.0, k as f64 / 40.0);
            assert!(b.abs() <= 0.004, "{k}: {b}");
        }
    }

    #[test]
    fn finite_and_non_negative_everywhere_including_the_extremes() {
        for r in [0.03, 0.2, 0.5, 1.0] {
            for an in [0.0, 0.5, 1.0] {
                for sw in [0.0, 0.3, 1.0] {
                    let m = Principled::new(&PrincipledShape {
                        roughness: r,
                        anisotropic: an,
                        sheen_weight: sw,
                        ..shape()
                    });
                    for (tl, pl, tv, pv) in [
                        (0.0, 0.0, 0.0, 0.0),
                        (89.9, 0.0, 89.9, 180.0),
                        (89.9, 0.0, 89.9, 0.0),
                        (45.0, 30.0, 60.0, 250.0),
                        (10.0, 90.0, 80.0, 90.0),
                    ] {
                        let (d, s, sh) = m.parts(&dir(tl, pl), &dir(tv, pv));
                        for x in [d, s, sh] {
                            assert!(x.is_finite() && x >= 0.0, "{r} {an} {sw}: {d} {s} {sh}");
                        }
                    }
                }
            }
        }
    }

    #[test]
    fn no_more_energy_out_than_in() {
        // the directional albedo for a white base colour: at most 1 (Cycles' Principled BSDF
        // conserves energy by construction), and near 1 for a rough white material
        let m = Principled::new(&shape());
        for tv in [0.0, 30.0, 60.0, 85.0] {
            let v = dir(tv, 40.0);
            let n = 200;
            let mut albedo = 0.0;
            for i in 0..n {
                let ct = (i as f64 + 0.5) / n as f64;
                for j in 0..2 * n {
                    let ph = (j as f64 + 0.5) / (2 * n) as f64 * 360.0;
                    let l = dir(ct.acos().to_degrees(), ph);
                    let (d, s, sh) = m.parts(&l, &v);
                    albedo += (d + s + sh) * ct * (1.0 / n as f64) * (std::f64::consts::TAU / (2 * n) as f64);
                }
            }
            assert!(albedo < 1.0 + 2e-2 && albedo > 0.8, "view {tv}: {albedo}");
        }
    }

    #[test]
    fn the_specular_lobe_is_broad_across_the_fibres() {
        // anisotropic > 0: the highlight of a view along the fibres spreads across them
        let m = Principled::new(&PrincipledShape {
            sheen_weight: 0.0,
            ..shape()
        });
        let v = dir(40.0, 0.0);
        let mirror_off_across = m.parts(&dir(40.0, 180.0 + 25.0), &v).1;
        let mirror_off_along = m.parts(&dir(40.0 - 15.0, 180.0), &v).1;
        let (ab, at) = alphas(0.45, 0.6);
        assert!(ab > at);
        assert!(mirror_off_across > 0.0 && mirror_off_along > 0.0);
    }

    #[test]
    fn the_fresnel_is_the_real_one_remapped() {
        // at normal incidence F = f0, at grazing it tends to 1
        assert!((fresnel_dielectric(1.0, 1.5) - 0.04).abs() < 1e-12);
        assert!(fresnel_dielectric(1e-6, 1.5) > 0.999);
        assert!((ior_from_f0(f0_from_ior(1.45)) - 1.45).abs() < 1e-12);
    }
}
