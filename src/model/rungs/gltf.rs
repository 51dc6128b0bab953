//! `gltf`: the glTF 2.0 metallic-roughness BRDF with KHR_materials_sheen,
//! KHR_materials_anisotropy, KHR_materials_specular and KHR_materials_ior, as web and real-time
//! engines render it, its anisotropy along the fibres.
//!
//! # What it follows
//!
//! - The glTF 2.0 specification, Appendix B "BRDF Implementation" (KhronosGroup/glTF,
//!   `specification/2.0/Specification.adoc`): `material = mix(dielectric_brdf, metal_brdf,
//!   metallic)`, `metal_brdf = specular_brdf(alpha) * (baseColor + (1 - baseColor) (1 -
//!   |V.H|)^5)` (`conductor_fresnel`), `dielectric_brdf = fresnel_mix(...)`, `diffuse_brdf =
//!   baseColor / pi`, `specular_brdf = V * D` with the Smith height-correlated visibility,
//!   alpha = roughness^2.
//! - KHR_materials_ior (`extensions/2.0/Khronos/KHR_materials_ior/README.md`): the dielectric's
//!   F0 = ((ior - 1) / (ior + 1))^2 (1.5 gives 0.04).
//! - KHR_materials_specular (`extensions/2.0/Khronos/KHR_materials_specular/README.md`,
//!   "Implementation", commit 05e0f7b, and its "Interaction with other extensions": F0 =
//!   ((ior - 1)/(ior + 1))^2 specularFactor specularColor, F90 = specularFactor). With the grey
//!   specular colour 1 used here every published form of it (that one; the 2023 `fresnel_mix`
//!   with `(1 - specular max(fr)) base + specular fr layer`; the Sample Viewer's
//!   `mix(f_diffuse, f_specular, F_Schlick(f0 specularWeight, specularWeight, VdotH))`) is one
//!   formula:
//!
//!   ```text
//!   fr = F0 + (1 - F0) (1 - |V.H|)^5,   dielectric = (1 - s fr) baseColor / pi + s fr V D
//!   ```
//! - KHR_materials_anisotropy (`extensions/2.0/Khronos/KHR_materials_anisotropy/README.md`):
//!   alpha_t = mix(alpha, 1, strength^2) along the anisotropy direction, alpha_b = alpha, the
//!   anisotropic GGX D and the height-correlated anisotropic visibility, as the Sample Viewer's
//!   `D_GGX_anisotropic` and `V_GGX_anisotropic` (`source/Renderer/shaders/brdf.glsl`, commit
//!   00536c7, the functions of those names) write them:
//!   `D = a2 w2^2 / pi` with `a2 = at ab`, `f = (ab T.H, at B.H, a2 N.H)`, `w2 = a2 / f.f`;
//!   `V = 0.5 / (N.L |(at T.V, ab B.V, N.V)| + N.V |(at T.L, ab B.L, N.L)|)`. The
//!   anisotropy direction (glTF's tangent, where alpha_t, the larger alpha, lies) is the
//!   fibres' B = N x T, across them: a fibre's normals spread across it, so its highlight's
//!   half vectors do (MODEL.md §2), and `fibre_azimuth_deg` keeps meaning the fibre direction
//!   (held where the data give it). Measured: with the direction along T instead, the fit of
//!   `data_synthetic/silk` (fibres at 20 deg) put the fibres at -69.5 deg. In glTF terms the
//!   anisotropy rotation is the fibre azimuth + 90 deg. With strength 0 it is the isotropic
//!   GGX of Appendix B exactly. The Sample Viewer's clamps (`ab >= 0.001`, V in [0, 1]) are not
//!   taken: the roughness's lower bound 0.03 keeps alpha >= 9e-4 and V finite.
//! - KHR_materials_sheen (`extensions/2.0/Khronos/KHR_materials_sheen/README.md`,
//!   "Implementation Notes"): `f = f_sheen + (f_diffuse + f_specular) sheenAlbedoScaling` with
//!   `sheenAlbedoScaling = min(1 - max3(sheenColor) E(V.N), 1 - max3(sheenColor) E(L.N))`, the
//!   Charlie distribution `(2 + 1/a) sin(h)^(1/a) / (2 pi)` and visibility
//!   `1 / ((1 + lambdaSheen(N.V) + lambdaSheen(N.L)) 4 N.V N.L)` with its fitted `l(x, a)`.
//!   As the Sample Viewer (`brdf.glsl`: `D_Charlie`, `V_Sheen`, `lambdaSheen`,
//!   `lambdaSheenNumericHelper`) and three.js do, a = sheenRoughness^2 (the spec's note writes
//!   `alphaG = sheenRoughness`: the one place the reference implementation departs from it, and
//!   the one taken here), and V is clamped to [0, 1]. The sheen colour is grey here (`sheen`).
//!   E(x), the sheen's directional albedo (the spec's look-up table, the Sample Viewer's
//!   `u_SheenELUT`), is computed when the rung is built, by quadrature of this same sheen BRDF
//!   at [`SHEEN_E_NODES`] equally spaced cosines, and interpolated linearly between them; the
//!   shader export bakes the same table, so the two agree.
//!
//! # Linear in the base colour
//!
//! With the grey specular colour and sheen, the material is affine in the base colour c:
//! `f = c A + B` with, for x = (1 - |V.H|)^5 and S = V D,
//!
//! ```text
//! A = k [ (1 - m) (1 - s fr) / pi + m S (1 - x) ]
//! B = k [ (1 - m) s fr S + m S x ] + sheen D_charlie V_sheen,    k = sheenAlbedoScaling
//! ```
//!
//! so the base colour is the rung's `kd` (the diffuse column, solved exactly per channel like
//! every rung's albedos) and B is the specular column, whose weight `gltf_layers` is 1 (held:
//! glTF has no such weight). Reciprocal (|V.H| = |L.H|, V and D symmetric, the scaling takes
//! the min over both directions) and invariant under T -> -T (D and V are even in T).
//!
//! # Variants
//!
//! `gltf_variant` (a knob: `fibrefit fit --gltf-variant`, `knobs.gltf_variant` of a config and
//! of a result, `gltf_variant` of a parameter file) chooses whose BRDF the rung is:
//! [`GltfVariant::Khronos`] (the default), the above, what the specification and its Sample
//! Viewer define; [`GltfVariant::Threejs`], what stock three.js r187 renders for a direct
//! light ([`threejs`], its own module: five departures and a roughness floor, each measured in
//! docs/web.md), so that a fit with it is exact in three.js.

use crate::model::parameter::{Ability::*, Param};
use crate::model::params::GltfShape;
use crate::model::rung::{Cost, LobeAlbedo, LobeSampling, Rung, Sampling, ShaderSection};
use crate::model::{Basis, DirectionPair, Lobe, Local, ShadingModel};
use std::f64::consts::{FRAC_1_PI, PI};

pub mod threejs;

/// Whose BRDF the rung evaluates (the knob `gltf_variant`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum GltfVariant {
    /// The Khronos specification and Sample Viewer (exact in engines that follow them).
    #[default]
    Khronos,
    /// Stock three.js r187's `MeshPhysicalMaterial` under direct light ([`threejs`]).
    Threejs,
}

impl GltfVariant {
    /// Every variant, in the order help texts list them.
    pub const ALL: [GltfVariant; 2] = [GltfVariant::Khronos, GltfVariant::Threejs];

    /// The name configs, results and the command line use.
    pub fn as_str(self) -> &'static str {
        match self {
            GltfVariant::Khronos => "khronos",
            GltfVariant::Threejs => "threejs",
        }
    }

    /// The engine a GLB of this variant's fit is exact in, in words.
    pub fn exact_in(self) -> &'static str {
        match self {
            GltfVariant::Khronos => {
                "engines that follow the Khronos specification (the glTF Sample Viewer)"
            }
            GltfVariant::Threejs => {
                "three.js r187 (MeshPhysicalMaterial via GLTFLoader), direct lights"
            }
        }
    }

    /// Whether this is the default.
    pub fn is_khronos(&self) -> bool {
        *self == GltfVariant::Khronos
    }
}

impl std::fmt::Display for GltfVariant {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.as_str())
    }
}

impl std::str::FromStr for GltfVariant {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        GltfVariant::ALL
            .into_iter()
            .find(|v| v.as_str() == s)
            .ok_or_else(|| format!("unknown gltf variant `{s}`: expected khronos or threejs"))
    }
}

/// The rung.
pub static RUNG: Rung = Rung {
    name: "gltf",
    description: "glTF 2.0 metallic-roughness + sheen, anisotropy, specular, ior: web engines",
    abilities: &[FibreDiffuse, FibreDirection, GltfMaterial],
    build: |a| Box::new(Gltf::new(&a.gltf)),
    sampling: Sampling {
        lobe: LobeSampling::Ggx,
        diffuse_tube: 0.0,
        diffuse_cosine: 1.0,
        lobe_albedo: LobeAlbedo::Normalised,
        cone_from: None,
    },
    shader: ShaderSection::Sections {
        sections: &["gltf", "gltf_threejs"],
        body: "    return fibrefit_gltf(l, v, p);\n",
        material_rows: Some(|p| Gltf::new(&p.gltf).shader_rows()),
    },
    cost: Cost::ClosedForm,
    auto_rank: Some(6),
    example: &[
        (Param::Kd, 0.4),
        (Param::Metallic, 0.1),
        (Param::Roughness, 0.45),
        (Param::AnisotropyStrength, 0.6),
        (Param::SpecularFactor, 0.8),
        (Param::Ior, 1.5),
        (Param::Sheen, 0.3),
        (Param::SheenRoughness, 0.5),
    ],
    symmetries: &[],
    renderer: Some("web and real-time engines (glTF 2.0: three.js, <model-viewer>, Babylon.js)"),
    auto_fuzz: true,
};

/// Nodes of the sheen's directional albedo table E(cos theta), at cos theta = k / (n - 1).
pub const SHEEN_E_NODES: usize = 32;

/// The material at one parameter set, with what it derives once (the GGX alphas, F0, the
/// sheen's albedo table).
#[derive(Clone, Debug)]
pub struct Gltf {
    variant: GltfVariant,
    metallic: f64,
    /// The roughness the variant evaluates with (three.js: floored at 0.045).
    roughness: f64,
    /// GGX alpha along the fibres (T) and across them (B, the anisotropy direction).
    alpha_t: f64,
    alpha_b: f64,
    specular: f64,
    /// The dielectric's F0 from the IOR.
    f0: f64,
    sheen: f64,
    /// The sheen roughness the variant evaluates with (three.js: at least 1e-4).
    sheen_roughness: f64,
    /// The Charlie alpha = sheen_roughness^2.
    sheen_alpha: f64,
    /// E at cos theta = k / (SHEEN_E_NODES - 1).
    sheen_e: [f64; SHEEN_E_NODES],
}

impl Gltf {
    /// The material of `g`.
    pub fn new(g: &GltfShape) -> Self {
        let (roughness, sheen_roughness) = g.evaluated_roughnesses();
        let (alpha_t, alpha_b) = ggx_alphas(roughness, g.anisotropy);
        let sheen_alpha = sheen_roughness * sheen_roughness;
        Self {
            variant: g.variant,
            metallic: g.metallic,
            roughness,
            alpha_t,
            alpha_b,
            specular: g.specular,
            f0: ior_f0(g.ior),
            sheen: g.sheen,
            sheen_roughness,
            sheen_alpha,
            sheen_e: sheen_albedo_table(sheen_alpha),
        }
    }

    /// The rows the shader export bakes for this material (`FibrefitParams::material`): metallic,
    /// alpha along T, alpha along B, specular; F0, sheen, sheen alpha, the variant (0 khronos,
    /// 1 threejs); then the E table, four a row.
    pub fn shader_rows(&self) -> Vec<[f64; 4]> {
        let variant = match self.variant {
            GltfVariant::Khronos => 0.0,
            GltfVariant::Threejs => 1.0,
        };
        let mut rows = vec![
            [self.metallic, self.alpha_t, self.alpha_b, self.specular],
            [self.f0, self.sheen, self.sheen_alpha, variant],
        ];
        rows.extend(
            self.sheen_e
                .chunks(4)
                .map(|c| [c[0], c[1], c[2], c[3]]),
        );
        rows
    }

    /// The sheen's directional albedo E at cos theta = `mu`, from the table.
    pub fn sheen_albedo(&self, mu: f64) -> f64 {
        let x = mu.clamp(0.0, 1.0) * (SHEEN_E_NODES - 1) as f64;
        let k = (x.floor() as usize).min(SHEEN_E_NODES - 2);
        let f = x - k as f64;
        self.sheen_e[k] * (1.0 - f) + self.sheen_e[k + 1] * f
    }
}

/// The GGX alphas along the fibres (T) and across them (B, the anisotropy direction):
/// KHR_materials_anisotropy's alpha_b = alpha = roughness^2 along T and
/// alpha_t = mix(alpha, 1, strength^2) along B.
pub fn ggx_alphas(roughness: f64, strength: f64) -> (f64, f64) {
    let alpha = roughness * roughness;
    let s2 = strength * strength;
    (alpha, alpha + (1.0 - alpha) * s2)
}

/// KHR_materials_ior: F0 = ((ior - 1) / (ior + 1))^2.
pub fn ior_f0(ior: f64) -> f64 {
    ((ior - 1.0) / (ior + 1.0)).powi(2)
}

/// The anisotropic GGX distribution D(h) (1/sr, h a unit half vector in the fibre frame),
/// `at` along T and `ab` along B: `D_GGX_anisotropic` of the Sample Viewer (whose tangent is
/// here B, so its (ab T.H, at B.H) is this (ab h.t, at h.b) up to the names). 0 for h.n <= 0.
pub fn ggx_d(at: f64, ab: f64, h: &Local) -> f64 {
    if !(h.n > 0.0) {
        return 0.0;
    }
    let a2 = at * ab;
    let f = [ab * h.t, at * h.b, a2 * h.n];
    let w2 = a2 / (f[0] * f[0] + f[1] * f[1] + f[2] * f[2]);
    a2 * w2 * w2 * FRAC_1_PI
}

/// The height-correlated anisotropic visibility V = G2 / (4 N.L N.V): `V_GGX_anisotropic`
/// (`at` along T, `ab` along B).
pub fn ggx_v(at: f64, ab: f64, l: &Local, v: &Local) -> f64 {
    let len = |w: &Local| ((at * w.t).powi(2) + (ab * w.b).powi(2) + w.n * w.n).sqrt();
    0.5 / (l.n * len(v) + v.n * len(l))
}

/// Smith's Lambda of the anisotropic GGX at a direction w (w.n > 0): G1 = 1 / (1 + Lambda).
pub fn ggx_lambda(at: f64, ab: f64, w: &Local) -> f64 {
    let t2 = ((at * w.t).powi(2) + (ab * w.b).powi(2)) / (w.n * w.n);
    0.5 * ((1.0 + t2).sqrt() - 1.0)
}

/// The Charlie sheen distribution (2 + 1/a) sin(h)^(1/a) / (2 pi) at cos h = `nh`, a the
/// Charlie alpha (`D_Charlie`).
pub fn charlie_d(a: f64, nh: f64) -> f64 {
    let inv = 1.0 / a;
    let sin2 = (1.0 - nh * nh).max(0.0);
    (2.0 + inv) * sin2.powf(0.5 * inv) / (2.0 * PI)
}

/// The sheen spec's fitted l(x, a) (`lambdaSheenNumericHelper`).
fn sheen_l(x: f64, a: f64) -> f64 {
    let t = (1.0 - a) * (1.0 - a);
    let mix = |p: f64, q: f64| p + (q - p) * t;
    let (pa, pb, pc) = (
        mix(21.5473, 25.3245),
        mix(3.82987, 3.32435),
        mix(0.19823, 0.16801),
    );
    let (pd, pe) = (mix(-1.97760, -1.27393), mix(-4.32054, -4.85967));
    pa / (1.0 + pb * x.powf(pc)) + pd * x + pe
}

/// The sheen's Lambda at cos theta (`lambdaSheen`).
fn sheen_lambda(cos: f64, a: f64) -> f64 {
    if cos.abs() < 0.5 {
        sheen_l(cos, a).exp()
    } else {
        (2.0 * sheen_l(0.5, a) - sheen_l(1.0 - cos, a)).exp()
    }
}

/// The sheen visibility of the Sample Viewer (`V_Sheen`), clamped to [0, 1].
pub fn sheen_v(nl: f64, nv: f64, a: f64) -> f64 {
    let v = 1.0 / ((1.0 + sheen_lambda(nv, a) + sheen_lambda(nl, a)) * (4.0 * nv * nl));
    if v.is_nan() {
        return 0.0;
    }
    v.clamp(0.0, 1.0)
}

/// The sheen BRDF per unit sheen colour, D V, at l, v above the horizon.
pub fn sheen_brdf(a: f64, l: &Local, v: &Local) -> f64 {
    let h = half_vector(l, v);
    charlie_d(a, h.n) * sheen_v(l.n, v.n, a)
}

/// The unit half vector of l and v.
pub fn half_vector(l: &Local, v: &Local) -> Local {
    let (t, b, n) = (l.t + v.t, l.b + v.b, l.n + v.n);
    let len = (t * t + b * b + n * n).sqrt();
    Local {
        t: t / len,
        b: b / len,
        n: n / len,
    }
}

/// E(cos theta) at the table's nodes: int sheen_brdf (N.l) d omega over the hemisphere, by a
/// 48 x 48 Gauss-Legendre rule in (N.l, phi) (phi over half the circle, by symmetry).
///
/// A fit builds the material once per evaluation of its residuals (every Jacobian column), and
/// the table is 32 x 48 x 48 powers: it is kept per thread for the last [`SHEEN_E_CACHE`] sheen
/// alphas (keyed by their bits, so a hit returns exactly what the sum would), and the rule's
/// light directions are made once. Before the cache the table was half of `--model auto`'s
/// time on the felt.
fn sheen_albedo_table(a: f64) -> [f64; SHEEN_E_NODES] {
    thread_local! {
        static CACHE: std::cell::RefCell<Vec<(u64, [f64; SHEEN_E_NODES])>> =
            const { std::cell::RefCell::new(Vec::new()) };
    }
    let key = a.to_bits();
    if let Some(t) = CACHE.with(|c| c.borrow().iter().find(|e| e.0 == key).map(|e| e.1)) {
        return t;
    }
    let table = sheen_albedo_sum(a);
    CACHE.with(|c| {
        let mut c = c.borrow_mut();
        if c.len() >= SHEEN_E_CACHE {
            c.remove(0);
        }
        c.push((key, table));
    });
    table
}

/// Sheen alphas whose albedo tables each thread keeps.
const SHEEN_E_CACHE: usize = 8;

/// The sheen albedo sum itself (see [`sheen_albedo_table`]): the same sum of `sheen_brdf (N.l)`
/// over the rule, arranged so that what does not depend on the alpha is made once: the rule's
/// directions, ln(sin^2) of every (node, direction) pair's half vector, and the sheen's Lambda
/// at each of the 48 + 32 distinct cosines per alpha. `charlie_d`'s power is exp(ln(sin^2) /
/// (2a)) here (within a few ulps of `powf`; `sheen_brdf_matches_the_sum` checks 1e-13).
fn sheen_albedo_sum(a: f64) -> [f64; SHEEN_E_NODES] {
    /// The rule: per light direction (w_i w_j, N.l, index of N.l among the cosines), and
    /// per (node, direction) pair ln(sin^2) of the half vector's angle.
    struct Rule {
        points: Vec<(f64, f64, usize)>,
        cosines: Vec<f64>,
        ln_sin2: Vec<f64>,
    }
    static RULE: std::sync::OnceLock<Rule> = std::sync::OnceLock::new();
    let rule = RULE.get_or_init(|| {
        use crate::model::numerics::quadrature::GaussLegendre;
        let gl = GaussLegendre::new(48);
        let (x, w) = gl.nodes_and_weights();
        let mut points = Vec::with_capacity(x.len() * x.len());
        let mut dirs = Vec::with_capacity(x.len() * x.len());
        let mut cosines = Vec::with_capacity(x.len());
        for (xi, wi) in x.iter().zip(w) {
            let nl = 0.5 * (xi + 1.0);
            let sl = (1.0 - nl * nl).sqrt();
            cosines.push(nl);
            for (xj, wj) in x.iter().zip(w) {
                let phi = 0.5 * PI * (xj + 1.0);
                dirs.push(Local {
                    t: sl * phi.cos(),
                    b: sl * phi.sin(),
                    n: nl,
                });
                points.push((wi * wj, nl, cosines.len() - 1));
            }
        }
        let mut ln_sin2 = Vec::with_capacity(SHEEN_E_NODES * dirs.len());
        for k in 0..SHEEN_E_NODES {
            let v = sheen_table_view(k);
            for l in &dirs {
                let nh = half_vector(l, &v).n;
                ln_sin2.push((1.0 - nh * nh).max(0.0).ln());
            }
        }
        Rule {
            points,
            cosines,
            ln_sin2,
        }
    });
    let inv = 1.0 / a;
    let (norm, half_inv) = ((2.0 + inv) / (2.0 * PI), 0.5 * inv);
    let lambda_l: Vec<f64> = rule.cosines.iter().map(|&c| sheen_lambda(c, a)).collect();
    let mut table = [0.0; SHEEN_E_NODES];
    for (k, e) in table.iter_mut().enumerate() {
        let nv = sheen_table_view(k).n;
        let lambda_v = sheen_lambda(nv, a);
        let ln_sin2 = &rule.ln_sin2[k * rule.points.len()..(k + 1) * rule.points.len()];
        let mut sum = 0.0;
        for (&(w, nl, c), &ln) in rule.points.iter().zip(ln_sin2) {
            // charlie_d and sheen_v as `sheen_brdf` evaluates them
            let d = norm * (half_inv * ln).exp();
            let vis = 1.0 / ((1.0 + lambda_v + lambda_l[c]) * (4.0 * nv * nl));
            let vis = if vis.is_nan() { 0.0 } else { vis.clamp(0.0, 1.0) };
            sum += w * (d * vis) * nl;
        }
        // d(N.l) = dx / 2, d phi = pi dx / 2, twice for the other half of the circle
        *e = sum * 0.5 * 0.5 * PI * 2.0;
    }
    table
}

/// The view of the sheen table's node k: cos theta = k / (SHEEN_E_NODES - 1) (1e-6 at 0).
fn sheen_table_view(k: usize) -> Local {
    let mu = (k as f64 / (SHEEN_E_NODES - 1) as f64).max(1e-6);
    Local {
        t: (1.0 - mu * mu).sqrt(),
        b: 0.0,
        n: mu,
    }
}

impl ShadingModel for Gltf {
    fn rung(&self) -> &'static Rung {
        &RUNG
    }

    fn with_lobe(&self, lobe: Lobe) -> Option<Box<dyn ShadingModel>> {
        let mut g = self.clone();
        g.roughness = match self.variant {
            GltfVariant::Khronos => lobe.roughness,
            GltfVariant::Threejs => lobe.roughness.clamp(threejs::ROUGHNESS_FLOOR, 1.0),
        };
        (g.alpha_t, g.alpha_b) = ggx_alphas(g.roughness, lobe.anisotropy);
        Some(Box::new(g))
    }

    fn basis_above_horizon(&self, pair: &DirectionPair) -> Basis {
        match self.variant {
            GltfVariant::Khronos => self.khronos_basis(pair),
            GltfVariant::Threejs => threejs::basis(self, pair),
        }
    }
}

impl Gltf {
    /// The Khronos form's basis (the module's equations).
    fn khronos_basis(&self, pair: &DirectionPair) -> Basis {
        let (l, v) = (&pair.l, &pair.v);
        let h = half_vector(l, v);
        let vh = (v.t * h.t + v.b * h.b + v.n * h.n).abs();
        let x = (1.0 - vh).clamp(0.0, 1.0).powi(5);
        let s = ggx_d(self.alpha_t, self.alpha_b, &h) * ggx_v(self.alpha_t, self.alpha_b, l, v);
        let fr = self.f0 + (1.0 - self.f0) * x;
        let (m, sp) = (self.metallic, self.specular);
        let diffuse = (1.0 - m) * (1.0 - sp * fr) * FRAC_1_PI + m * s * (1.0 - x);
        let layers = (1.0 - m) * sp * fr * s + m * s * x;
        let (k, sheen) = if self.sheen > 0.0 {
            let e = self.sheen_albedo(l.n).max(self.sheen_albedo(v.n));
            let d = charlie_d(self.sheen_alpha, h.n) * sheen_v(l.n, v.n, self.sheen_alpha);
            (1.0 - self.sheen * e, self.sheen * d)
        } else {
            (1.0, 0.0)
        };
        Basis {
            diffuse: k * diffuse,
            specular: k * layers + sheen,
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

    #[test]
    fn isotropic_strength_zero_is_appendix_b() {
        // roughness 0.5, no anisotropy, no sheen, dielectric: Appendix B's formula by hand
        let g = Gltf::new(&GltfShape {
            metallic: 0.0,
            roughness: 0.5,
            anisotropy: 0.0,
            specular: 1.0,
            ior: 1.5,
            sheen: 0.0,
            sheen_roughness: 0.5,
            variant: GltfVariant::Khronos,
        });
        let (l, v) = (dir(30.0, 10.0), dir(50.0, 200.0));
        let b = g.basis_above_horizon(&DirectionPair { l, v });
        let h = half_vector(&l, &v);
        let a2: f64 = 0.25 * 0.25;
        let d = a2 / (PI * (h.n * h.n * (a2 - 1.0) + 1.0).powi(2));
        let vis = 0.5
            / (l.n * (v.n * v.n * (1.0 - a2) + a2).sqrt()
                + v.n * (l.n * l.n * (1.0 - a2) + a2).sqrt());
        let vh = v.t * h.t + v.b * h.b + v.n * h.n;
        let fr = 0.04 + 0.96 * (1.0 - vh).powi(5);
        let c = 0.7;
        let want = (1.0 - fr) * c / PI + fr * vis * d;
        let got = c * b.diffuse + b.specular;
        assert!((got - want).abs() < 1e-12 * want, "{got} vs {want}");
    }

    #[test]
    fn with_lobe_is_the_material_built_with_that_lobe() {
        for variant in GltfVariant::ALL {
            let shape = |roughness, anisotropy| GltfShape {
                roughness,
                anisotropy,
                sheen: 0.4,
                variant,
                ..GltfShape::default()
            };
            let swapped = Gltf::new(&shape(0.5, 0.2))
                .with_lobe(Lobe {
                    roughness: 0.02,
                    anisotropy: 0.7,
                })
                .expect("the gltf rung has a lobe");
            let built = Gltf::new(&shape(0.02, 0.7));
            for (a, b) in [(20.0, 0.0), (45.0, 70.0), (80.0, 170.0)] {
                let pair = DirectionPair {
                    l: dir(a, b),
                    v: dir(30.0, 200.0),
                };
                let (x, y) = (swapped.basis(&pair), built.basis(&pair));
                assert_eq!((x.diffuse, x.specular), (y.diffuse, y.specular), "{variant}");
            }
        }
    }

    #[test]
    fn the_sheen_table_is_a_directional_albedo() {
        let g = Gltf::new(&GltfShape {
            sheen: 1.0,
            sheen_roughness: 0.5,
            ..GltfShape::default()
        });
        for k in 0..SHEEN_E_NODES {
            let e = g.sheen_e[k];
            assert!(e.is_finite() && (0.0..1.0).contains(&e), "E[{k}] = {e}");
        }
        assert!(g.sheen_albedo(1.0) > 0.0);
    }

    #[test]
    fn sheen_brdf_matches_the_sum() {
        // the arranged sum against sheen_brdf summed over the same rule directly
        use crate::model::numerics::quadrature::GaussLegendre;
        let gl = GaussLegendre::new(48);
        let (x, w) = gl.nodes_and_weights();
        for a in [0.0001, 0.01, 0.09, 0.25, 0.5, 1.0] {
            let fast = sheen_albedo_sum(a);
            for (k, f) in fast.iter().enumerate() {
                let v = sheen_table_view(k);
                let mut sum = 0.0;
                for (xi, wi) in x.iter().zip(w) {
                    let nl = 0.5 * (xi + 1.0);
                    let sl = (1.0 - nl * nl).sqrt();
                    for (xj, wj) in x.iter().zip(w) {
                        let phi = 0.5 * PI * (xj + 1.0);
                        let l = Local {
                            t: sl * phi.cos(),
                            b: sl * phi.sin(),
                            n: nl,
                        };
                        sum += wi * wj * sheen_brdf(a, &l, &v) * nl;
                    }
                }
                let direct = sum * 0.5 * 0.5 * PI * 2.0;
                assert!(
                    (f - direct).abs() <= 1e-13 * direct.abs().max(1e-300),
                    "a {a} node {k}: {f} vs {direct}"
                );
            }
        }
    }

    #[test]
    fn the_cached_sheen_table_is_the_sum_bit_for_bit() {
        // more alphas than the cache holds, each asked for twice, interleaved
        let alphas: Vec<f64> = (1..=2 * SHEEN_E_CACHE).map(|k| 0.05 * k as f64).collect();
        for round in 0..2 {
            for &a in &alphas {
                let (cached, sum) = (sheen_albedo_table(a), sheen_albedo_sum(a));
                assert_eq!(cached.map(f64::to_bits), sum.map(f64::to_bits), "a {a} round {round}");
            }
        }
    }
}
