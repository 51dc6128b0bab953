//! The `gltf` rung's `threejs` variant (`gltf_variant = "threejs"`): the BRDF three.js r187's
//! `MeshPhysicalMaterial` renders for a direct light (a `DirectionalLight`, point or spot light),
//! term by term as its WebGL shader chunks write it, so that a fit with this variant is what
//! stock three.js draws from the exported GLB. docs/web.md measures each departure from the
//! Khronos form ([`super`]) in a browser.
//!
//! # What three.js computes (r187, `src/renderers/shaders/ShaderChunk/`)
//!
//! With the material as `lights_physical_fragment` sets it up from GLTFLoader's values (base
//! colour c, metalness m, specularIntensity s, specularColor 1, ior, sheenColor sigma, sheen
//! roughness rho, anisotropy strength a):
//!
//! ```text
//! r      = min(max(roughness, 0.045), 1)          (+ the mesh's normal variation: 0 when flat)
//! F0d    = min(((ior - 1)/(ior + 1))^2, 1) s      material.specularColor
//! F90    = mix(s, 1, m)                          material.specularF90
//! F0b    = mix(F0d, c, m)                        material.specularColorBlended
//! alpha  = r^2, alphaT = mix(alpha, 1, a^2)      (along the anisotropy direction: across the fibres)
//! ```
//!
//! and `RE_Direct_Physical` (`lights_physical_pars_fragment`) for a light of colour E from l:
//!
//! ```text
//! e(x)   = exp2((-5.55473 x - 6.98316) x)          F_Schlick (common): Epic's fit of (1 - x)^5
//! F(f0)  = f0 (1 - e(V.H)) + F90 e(V.H)
//! k      = 1 - sigma max(E_ibl(N.v), E_ibl(N.l))   the sheen's albedo scaling, IBLSheenBRDF
//! sheen  = sigma D_Charlie(rho, N.h) V_Neubelt(N.v, N.l)
//! spec   = F(F0b) V_GGX D_GGX (1 + F0b (1 / E_ss(r, N.v) - 1))   BRDF_GGX x multiScatteringCompensation
//! diff   = c (1 - m) / pi (1 - F(F0d))             BRDF_Lambert(diffuseContribution) (1 - F)
//! f      = sheen + k (spec + diff)
//! ```
//!
//! - `D_GGX_Anisotropic` and `V_GGX_SmithCorrelated_Anisotropic` are the Khronos forms
//!   ([`super::ggx_d`], [`super::ggx_v`]) at the floored roughness.
//! - E_ss = dfg.x + dfg.y, three.js's DFG table (`DFGLUTData.js`: 16 x 16 RG half floats, u the
//!   roughness r, v = N.v, linear filtering, clamped to the edge), looked up in
//!   `lights_fragment_begin` ("Multi-scattering energy compensation for direct lighting",
//!   Turquin's equation 16). The table's numbers are copied below ([`DFG`]), not computed.
//! - `D_Charlie(rho, N.h) = (2 + 1/alpha) max(1 - N.h^2, 2^-7)^(1/(2 alpha)) / (2 pi)`, alpha =
//!   rho^2, rho = clamp(sheenRoughness, 1e-4, 1); `V_Neubelt = saturate(1 / (4 (N.l + N.v - N.l N.v)))`.
//! - `IBLSheenBRDF(N.x, rho) = saturate(exp(A N.x + B))` with
//!   `A = -1.9362 + 1.0678 rho + 0.4573 rho^2 - 0.8469 / (rho + 0.1)`,
//!   `B = -0.6014 + 0.5538 rho - 0.4670 rho^2 - 0.1255 / (rho + 0.1)`.
//!
//! # Its columns
//!
//! With P = (1 - m) F0d (1 - e) + F90 e, R = 1 + (1 - m) F0d g, g = 1 / E_ss - 1 and S = V D,
//! F(F0b) = P + m (1 - e) c and the compensation is R + m g c, so
//!
//! ```text
//! f = c A + B + c^2 Q,   A = k [ (1 - m)(1 - F(F0d)) / pi + S m (P g + (1 - e) R) ]
//!                        B = k S P R + sheen,        Q = k S m^2 g (1 - e)
//! ```
//!
//! The c^2 column Q (three.js tints the compensation by F0b, which holds the base colour of a
//! metal) is the basis's `substrate` column, whose albedo is kd^2 for this variant
//! (`model::params`, `fit::problem::rung_model::albedos_of`); it is zero for a dielectric
//! (m = 0). A fit solves the base colour for it exactly, as the minimum of a quartic per channel
//! (`fit::problem`'s `solve_threejs_base_colour`).
//!
//! # Reciprocity
//!
//! Not reciprocal: the compensation factor 1 + F0b (1 / E_ss(r, N.v) - 1) is a function of N.v
//! alone, so f(l, v) != f(v, l) wherever it differs from 1 (F0b > 0 and E_ss < 1). Everything
//! else is symmetric: V.H = L.H, V and D, V_Neubelt, and the sheen scaling's max over both.

use super::{ggx_d, ggx_v, half_vector, Gltf};
use crate::model::{Basis, DirectionPair};
use std::f64::consts::{FRAC_1_PI, PI};

/// three.js's roughness floor for punctual lights (`lights_physical_fragment`: "Matches
/// Filament's desktop MIN_PERCEPTUAL_ROUGHNESS").
pub const ROUGHNESS_FLOOR: f64 = 0.045;

/// three.js's clamp of the sheen roughness (`lights_physical_fragment`).
pub const SHEEN_ROUGHNESS_FLOOR: f64 = 1e-4;

/// The floor `D_Charlie` keeps on sin^2(h): 2^-7.
pub const CHARLIE_SIN2_FLOOR: f64 = 0.0078125;

/// three.js r187's DFG table (`src/renderers/shaders/DFGLUTData.js`, `DATA`): 16 x 16 texels of
/// (scale, bias) as IEEE half floats, row-major, rows along v = N.v, columns along u = roughness.
#[rustfmt::skip]
pub const DFG: [u16; 512] = [
    0x30b5, 0x3ad1, 0x314c, 0x3a4d, 0x33d2, 0x391c, 0x35ef, 0x3828, 0x37f3, 0x36a6, 0x38d1, 0x3539, 0x3979, 0x3410, 0x39f8, 0x3252, 0x3a53, 0x30f0, 0x3a94, 0x2fc9, 0x3abf, 0x2e35, 0x3ada, 0x2d05, 0x3ae8, 0x2c1f, 0x3aed, 0x2ae0, 0x3aea, 0x29d1, 0x3ae1, 0x28ff,
    0x3638, 0x38e4, 0x364a, 0x38ce, 0x3699, 0x385e, 0x374e, 0x372c, 0x3839, 0x35a4, 0x38dc, 0x3462, 0x396e, 0x32c4, 0x39de, 0x3134, 0x3a2b, 0x3003, 0x3a59, 0x2e3a, 0x3a6d, 0x2ce1, 0x3a6e, 0x2bba, 0x3a5f, 0x2a33, 0x3a49, 0x290a, 0x3a2d, 0x2826, 0x3a0a, 0x26e8,
    0x3894, 0x36d7, 0x3897, 0x36c9, 0x38a3, 0x3675, 0x38bc, 0x35ac, 0x38ee, 0x349c, 0x393e, 0x3332, 0x3997, 0x3186, 0x39e2, 0x3038, 0x3a13, 0x2e75, 0x3a29, 0x2cf5, 0x3a2d, 0x2bac, 0x3a21, 0x29ff, 0x3a04, 0x28bc, 0x39dc, 0x2790, 0x39ad, 0x261a, 0x3978, 0x24fa,
    0x39ac, 0x34a8, 0x39ac, 0x34a3, 0x39ae, 0x3480, 0x39ae, 0x3423, 0x39b1, 0x330e, 0x39c2, 0x31a9, 0x39e0, 0x3063, 0x39fc, 0x2eb5, 0x3a0c, 0x2d1d, 0x3a14, 0x2bcf, 0x3a07, 0x29ff, 0x39e9, 0x28a3, 0x39be, 0x273c, 0x3989, 0x25b3, 0x394a, 0x2488, 0x3907, 0x2345,
    0x3a77, 0x3223, 0x3a76, 0x321f, 0x3a73, 0x3204, 0x3a6a, 0x31b3, 0x3a58, 0x3114, 0x3a45, 0x303b, 0x3a34, 0x2eb6, 0x3a26, 0x2d31, 0x3a1e, 0x2bef, 0x3a0b, 0x2a0d, 0x39ec, 0x28a1, 0x39c0, 0x271b, 0x3987, 0x2580, 0x3944, 0x2449, 0x38fa, 0x22bd, 0x38ac, 0x2155,
    0x3b07, 0x2fca, 0x3b06, 0x2fca, 0x3b00, 0x2fb8, 0x3af4, 0x2f7c, 0x3adb, 0x2eea, 0x3ab4, 0x2e00, 0x3a85, 0x2cec, 0x3a5e, 0x2bc5, 0x3a36, 0x2a00, 0x3a0d, 0x2899, 0x39dc, 0x2707, 0x39a0, 0x2562, 0x395a, 0x2424, 0x390b, 0x2268, 0x38b7, 0x20fd, 0x385f, 0x1fd1,
    0x3b69, 0x2cb9, 0x3b68, 0x2cbb, 0x3b62, 0x2cbb, 0x3b56, 0x2cae, 0x3b3b, 0x2c78, 0x3b0d, 0x2c0a, 0x3acf, 0x2ae3, 0x3a92, 0x2998, 0x3a54, 0x2867, 0x3a17, 0x26d0, 0x39d3, 0x253c, 0x3989, 0x2402, 0x3935, 0x2226, 0x38dc, 0x20bd, 0x387d, 0x1f54, 0x381d, 0x1db3,
    0x3ba9, 0x296b, 0x3ba8, 0x296f, 0x3ba3, 0x297b, 0x3b98, 0x2987, 0x3b7f, 0x2976, 0x3b4e, 0x2927, 0x3b0e, 0x2895, 0x3ac2, 0x27b7, 0x3a73, 0x263b, 0x3a23, 0x24e7, 0x39d0, 0x239b, 0x3976, 0x21d9, 0x3917, 0x207e, 0x38b2, 0x1ee7, 0x384b, 0x1d53, 0x37c7, 0x1c1e,
    0x3bd2, 0x25cb, 0x3bd1, 0x25d3, 0x3bcd, 0x25f0, 0x3bc2, 0x261f, 0x3bad, 0x2645, 0x3b7d, 0x262d, 0x3b3e, 0x25c4, 0x3aec, 0x250f, 0x3a93, 0x243a, 0x3a32, 0x22ce, 0x39d0, 0x215b, 0x3969, 0x202a, 0x38fe, 0x1e6e, 0x388f, 0x1cf1, 0x381f, 0x1b9b, 0x3762, 0x19dd,
    0x3be9, 0x21ab, 0x3be9, 0x21b7, 0x3be5, 0x21e5, 0x3bdd, 0x2241, 0x3bc9, 0x22a7, 0x3ba0, 0x22ec, 0x3b62, 0x22cd, 0x3b0f, 0x2247, 0x3aae, 0x2175, 0x3a44, 0x2088, 0x39d4, 0x1f49, 0x3960, 0x1dbe, 0x38e9, 0x1c77, 0x3870, 0x1ae8, 0x37f1, 0x1953, 0x3708, 0x181b,
    0x3bf6, 0x1cea, 0x3bf6, 0x1cfb, 0x3bf3, 0x1d38, 0x3bec, 0x1dbd, 0x3bda, 0x1e7c, 0x3bb7, 0x1f25, 0x3b7d, 0x1f79, 0x3b2c, 0x1f4c, 0x3ac6, 0x1ea6, 0x3a55, 0x1dbb, 0x39da, 0x1cbd, 0x395a, 0x1b9d, 0x38d8, 0x1a00, 0x3855, 0x18ac, 0x37ab, 0x173c, 0x36b7, 0x1598,
    0x3bfc, 0x1736, 0x3bfc, 0x1759, 0x3bf9, 0x17e7, 0x3bf4, 0x1896, 0x3be4, 0x1997, 0x3bc6, 0x1aa8, 0x3b91, 0x1b84, 0x3b43, 0x1bd2, 0x3ade, 0x1b8a, 0x3a65, 0x1acd, 0x39e2, 0x19d3, 0x3957, 0x18cd, 0x38ca, 0x17b3, 0x383e, 0x1613, 0x376d, 0x14bf, 0x366f, 0x135e,
    0x3bff, 0x101b, 0x3bff, 0x1039, 0x3bfc, 0x10c8, 0x3bf9, 0x1226, 0x3bea, 0x1428, 0x3bcf, 0x1584, 0x3b9f, 0x16c5, 0x3b54, 0x179a, 0x3af0, 0x17ce, 0x3a76, 0x1771, 0x39ea, 0x16a4, 0x3956, 0x15a7, 0x38bf, 0x14a7, 0x3829, 0x1379, 0x3735, 0x11ea, 0x362d, 0x10a1,
    0x3c00, 0x061b, 0x3c00, 0x066a, 0x3bfe, 0x081c, 0x3bfa, 0x0a4c, 0x3bed, 0x0d16, 0x3bd5, 0x0fb3, 0x3ba9, 0x114d, 0x3b63, 0x127c, 0x3b01, 0x132f, 0x3a85, 0x1344, 0x39f4, 0x12d2, 0x3957, 0x120d, 0x38b5, 0x1122, 0x3817, 0x103c, 0x3703, 0x0ed3, 0x35f0, 0x0d6d,
    0x3c00, 0x007a, 0x3c00, 0x0089, 0x3bfe, 0x011d, 0x3bfb, 0x027c, 0x3bf0, 0x04fa, 0x3bda, 0x0881, 0x3bb1, 0x0acd, 0x3b6f, 0x0c97, 0x3b10, 0x0d7b, 0x3a93, 0x0df1, 0x39fe, 0x0def, 0x3959, 0x0d8a, 0x38af, 0x0ce9, 0x3808, 0x0c31, 0x36d5, 0x0af0, 0x35b9, 0x09a3,
    0x3c00, 0x0000, 0x3c00, 0x0001, 0x3bff, 0x0015, 0x3bfb, 0x0059, 0x3bf2, 0x00fd, 0x3bdd, 0x01df, 0x3bb7, 0x031c, 0x3b79, 0x047c, 0x3b1d, 0x05d4, 0x3aa0, 0x06d5, 0x3a08, 0x075a, 0x395d, 0x075e, 0x38aa, 0x06f7, 0x37f4, 0x0648, 0x36ac, 0x0576, 0x3586, 0x049f,
];

/// An IEEE 754 half float's value.
pub fn half(bits: u16) -> f64 {
    let sign = if bits & 0x8000 != 0 { -1.0 } else { 1.0 };
    let exp = ((bits >> 10) & 0x1f) as i32;
    let frac = (bits & 0x3ff) as f64;
    sign * match exp {
        0 => frac * 2f64.powi(-24),
        31 => f64::INFINITY,
        _ => (1.0 + frac / 1024.0) * 2f64.powi(exp - 15),
    }
}

/// The DFG table's (scale, bias) at texture coordinates (u, v) = (roughness, N.v) as WebGL's
/// linear filter reads a 16 x 16 texture clamped to its edge: texel centres at (i + 0.5) / 16.
pub fn dfg(roughness: f64, nv: f64) -> (f64, f64) {
    let axis = |t: f64| {
        let x = (t.clamp(0.0, 1.0) * 16.0 - 0.5).clamp(0.0, 15.0);
        let i = (x.floor() as usize).min(14);
        (i, x - i as f64)
    };
    let ((i, fx), (j, fy)) = (axis(roughness), axis(nv));
    let texel = |x: usize, y: usize| {
        let k = 2 * (16 * y + x);
        (half(DFG[k]), half(DFG[k + 1]))
    };
    let lerp = |a: (f64, f64), b: (f64, f64), f: f64| (a.0 + (b.0 - a.0) * f, a.1 + (b.1 - a.1) * f);
    let lo = lerp(texel(i, j), texel(i + 1, j), fx);
    let hi = lerp(texel(i, j + 1), texel(i + 1, j + 1), fx);
    lerp(lo, hi, fy)
}

/// The single-scattering GGX albedo E_ss(r, N.v) = dfg.x + dfg.y (`lights_fragment_begin`'s
/// `EssMs`).
pub fn e_ss(roughness: f64, nv: f64) -> f64 {
    let (a, b) = dfg(roughness, nv);
    a + b
}

/// Epic's fit of Schlick's (1 - x)^5 in three.js's `F_Schlick` (`common`):
/// exp2((-5.55473 x - 6.98316) x).
pub fn epic_fresnel(x: f64) -> f64 {
    ((-5.55473 * x - 6.98316) * x).exp2()
}

/// three.js's `D_Charlie(roughness, N.h)`: alpha = roughness^2 and sin^2(h) at least 2^-7.
pub fn d_charlie(roughness: f64, nh: f64) -> f64 {
    let inv = 1.0 / (roughness * roughness);
    let sin2 = (1.0 - nh * nh).max(CHARLIE_SIN2_FLOOR);
    (2.0 + inv) * sin2.powf(0.5 * inv) / (2.0 * PI)
}

/// three.js's `V_Neubelt`: saturate(1 / (4 (N.l + N.v - N.l N.v))) (Neubelt and Pettineo 2013,
/// via Filament).
pub fn v_neubelt(nv: f64, nl: f64) -> f64 {
    (1.0 / (4.0 * (nl + nv - nl * nv))).clamp(0.0, 1.0)
}

/// three.js's `IBLSheenBRDF`: the fitted exponential it takes for the Charlie sheen's
/// directional albedo at cos theta = `mu`.
pub fn ibl_sheen(mu: f64, roughness: f64) -> f64 {
    let r = roughness;
    let (r2, inv) = (r * r, 1.0 / (r + 0.1));
    let a = -1.9362 + 1.0678 * r + 0.4573 * r2 - 0.8469 * inv;
    let b = -0.6014 + 0.5538 * r - 0.4670 * r2 - 0.1255 * inv;
    (a * mu.clamp(0.0, 1.0) + b).exp().clamp(0.0, 1.0)
}

/// The variant's basis (diffuse: A, specular: B, substrate: Q, the c^2 column) of material `g`
/// at a pair above the horizon, the module's equations. `g`'s alphas, roughness and sheen
/// roughness are three.js's (floored) ones.
pub fn basis(g: &Gltf, pair: &DirectionPair) -> Basis {
    let (l, v) = (&pair.l, &pair.v);
    let h = half_vector(l, v);
    let vh = (v.t * h.t + v.b * h.b + v.n * h.n).clamp(0.0, 1.0);
    let e = epic_fresnel(vh);
    let (m, s) = (g.metallic, g.specular);
    let f0d = g.f0.min(1.0) * s;
    let f90 = s + (1.0 - s) * m;
    let fd = f0d * (1.0 - e) + f90 * e;
    let p = (1.0 - m) * f0d * (1.0 - e) + f90 * e;
    let gm = 1.0 / e_ss(g.roughness, v.n.clamp(0.0, 1.0)) - 1.0;
    let r = 1.0 + (1.0 - m) * f0d * gm;
    let sv = ggx_d(g.alpha_t, g.alpha_b, &h) * ggx_v(g.alpha_t, g.alpha_b, l, v);
    let (k, sheen) = if g.sheen > 0.0 {
        let rho = g.sheen_roughness;
        let e_max = ibl_sheen(v.n, rho).max(ibl_sheen(l.n, rho));
        let d = d_charlie(rho, h.n.clamp(0.0, 1.0)) * v_neubelt(v.n, l.n);
        (1.0 - g.sheen * e_max, g.sheen * d)
    } else {
        (1.0, 0.0)
    };
    Basis {
        diffuse: k * ((1.0 - m) * (1.0 - fd) * FRAC_1_PI + sv * m * (p * gm + (1.0 - e) * r)),
        specular: k * sv * p * r + sheen,
        substrate: k * sv * m * m * gm * (1.0 - e),
        fuzz: 0.0,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_dfg_table_reads_as_three_js_stores_it() {
        // first texel (roughness ~0, N.v ~0): scale 0x30b5, bias 0x3ad1; the last (1, 1)
        assert!((half(0x30b5) - 0.1470947265625).abs() < 1e-12);
        assert!((half(0x3c00) - 1.0).abs() < 1e-15);
        assert_eq!(dfg(0.0, 0.0), (half(0x30b5), half(0x3ad1)));
        assert_eq!(dfg(1.0, 1.0), (half(DFG[510]), half(DFG[511])));
        // smooth at normal incidence: no energy lost
        assert!((e_ss(0.0, 1.0) - 1.0).abs() < 1e-3);
        for r in [0.05, 0.3, 0.7, 1.0] {
            for mu in [0.05, 0.5, 1.0] {
                let e = e_ss(r, mu);
                assert!(e > 0.2 && e <= 1.001, "E_ss({r}, {mu}) = {e}");
            }
        }
    }
}
