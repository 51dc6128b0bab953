//! The fitted model as shader code: one WGSL source (`fibrefit.wgsl`, written once for every
//! rung) with the fitted parameters baked in, translated by naga to GLSL, HLSL and MSL.
//!
//! The file a user gets is a library: functions, one struct and constants, every name prefixed
//! `fibrefit_` / `Fibrefit` / `FIBREFIT_`, no entry points and no bindings. Its documented entry
//! points are written in [`HEADER`]. [`gpu`] runs it as a compute shader to prove it equal to the
//! Rust model.

pub mod check;
pub mod gpu;

use crate::model::azimuth_spread::spread_nodes;
use crate::model::numerics::quadrature::GaussLegendre;
use crate::model::rungs::ShaderSection;
use crate::model::topology::max_height;
use crate::model::{Ability, ModelId, ModelParams};
use anyhow::{anyhow, bail, Result};
use std::fmt::Write as _;

/// The master source, in sections (`// @section NAME`).
const MASTER: &str = include_str!("fibrefit.wgsl");

/// Shader languages `export --shader` writes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Language {
    Wgsl,
    Glsl,
    /// GLSL ES 3.00 (WebGL2: three.js's `ShaderMaterial`), `#version` and precision lines first.
    GlslEs,
    Hlsl,
    Msl,
}

impl std::str::FromStr for Language {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        Ok(match s {
            "wgsl" => Language::Wgsl,
            "glsl" => Language::Glsl,
            "glsl-es" => Language::GlslEs,
            "hlsl" => Language::Hlsl,
            "msl" => Language::Msl,
            _ => {
                return Err(format!(
                    "unknown shader language '{s}'; expected one of: wgsl, glsl, glsl-es, hlsl, msl"
                ))
            }
        })
    }
}

impl Language {
    pub fn as_str(self) -> &'static str {
        match self {
            Language::Wgsl => "wgsl",
            Language::Glsl => "glsl",
            Language::GlslEs => "glsl-es",
            Language::Hlsl => "hlsl",
            Language::Msl => "msl",
        }
    }
}

/// The documentation at the top of every exported file (comment syntax is the same in all four
/// languages).
const HEADER: &str = "\
// Entry points (WGSL spelling; the translations keep the names and argument order):
//
//   fn fibrefit_brdf(l: vec3<f32>, v: vec3<f32>, n: vec3<f32>, t: vec3<f32>) -> vec3<f32>
//       The BRDF in 1/sr per channel (grey results repeat the value). l, v: unit directions
//       towards the light and the viewer; n: the macro normal; t: the fibre tangent; any
//       orthonormal frame (t is made perpendicular to n). 0 at and below either horizon.
//       Shaded radiance = fibrefit_brdf(l, v, n, t) * irradiance * dot(n, l).
//   fn fibrefit_brdf_at(l, v, n, t, height: f32, azimuth_offset: f32) -> vec3<f32>
//       The same at one texel: `height` H of the climbing fibres in fibre radii (clamped to
//       [0, FIBREFIT_MAX_HEIGHT]; rungs without a topology ignore it) and the fibre direction
//       turned by `azimuth_offset` radians about n, from t towards n x t (a texel's fitted
//       fibre azimuth minus FIBREFIT_FIBRE_AZIMUTH_DEG in radians). A topology map value m in
//       [0, 1] gives its height by fibrefit_height_from_map(m).
//   fn fibrefit_basis(l, v, n, t) -> vec4<f32>
//   fn fibrefit_basis_at(l, v, n, t, height, azimuth_offset) -> vec4<f32>
//       The BRDF per unit albedo of each linear component, (diffuse, specular, substrate, fuzz):
//       brdf = b.x kd + b.y ks + b.z substrate_albedo + b.w fuzz (Ward: b.x rho_d + b.y rho_s),
//       for renderers that feed albedo maps.
//   fn fibrefit_correction(l, v, n) -> vec3<f32>
//       The result's smooth correction of the rung per channel (1 without one): fibrefit_brdf
//       and fibrefit_brdf_at include it; a renderer combining the basis itself multiplies by it.
//
// Parameters: baked in as the constants returned by fibrefit_params(). Every entry point has a
// `_with` form taking them first, e.g. fibrefit_brdf_with(p: FibrefitParams, l, v, n, t), so a
// renderer can pass its own values, e.g. from a uniform buffer it declares itself:
//   @group(0) @binding(0) var<uniform> material: FibrefitParams;  ...  fibrefit_brdf_with(material, l, v, n, t)
// FibrefitParams is laid out for uniform buffers (vec4 members, arrays of vec4). The array
// lengths (height nodes, spread nodes) and the Gauss-Legendre rule are fixed by this export.
// This file declares no bindings and no entry points of its own.
";

/// The baked parameters' field documentation (WGSL struct).
const PARAMS_STRUCT: &str = "\
struct FibrefitParams {
    // albedos per channel (rgb; w unused): fibre diffuse kd (Ward rho_d), specular ks (Ward
    // rho_s), substrate, fuzz layer weight
    kd: vec4<f32>,
    ks: vec4<f32>,
    substrate: vec4<f32>,
    fuzz: vec4<f32>,
    // x: Phong exponent e, y: spacing d (fibre radii), z: Fresnel index of refraction (0: off),
    // w: fraction of the lobe peak where the specular window ends, exp(ln(1e-15) / e)
    shape: vec4<f32>,
    // x: Ward alpha_x (along t), y: Ward alpha_y, z: fuzz optical depth (0: no layer),
    // w: fuzz phase asymmetry g
    extra: vec4<f32>,
    // x: base height H0, y: map scale s, z: H_max = sqrt(d^2 - 1) (fibre radii); w unused
    topology: vec4<f32>,
    // a renderer material's values and its tables at them (one row of zeros for the fibre
    // rungs); the rung's section below says what each row holds
    material: array<vec4<f32>, FIBREFIT_MATERIAL_ROWS>,
    // the spot's height distribution: x height H (fibre radii), y weight (summing to 1)
    heights: array<vec4<f32>, FIBREFIT_HEIGHT_NODES>,
    // the fibre-direction spread's nodes: x cos, y sin of the turn from t, z weight
    spread: array<vec4<f32>, FIBREFIT_SPREAD_NODES>,
}
";

/// The sections of the master each rung needs, after `common`, the body of its
/// `fibrefit_rung` and its material rows (the rung's [`ShaderSection`]).
type RungShader = (
    &'static [&'static str],
    &'static str,
    Option<fn(&ModelParams) -> Vec<[f64; 4]>>,
);

fn sections(id: ModelId) -> Result<RungShader> {
    match id.rung().shader {
        ShaderSection::Sections {
            sections,
            body,
            material_rows,
        } => Ok((sections, body, material_rows)),
        ShaderSection::None(why) => bail!("{why}"),
    }
}

/// The text of one master section.
fn section(name: &str) -> &'static str {
    let marker = format!("// @section {name}\n");
    let start = MASTER
        .find(&marker)
        .unwrap_or_else(|| panic!("fibrefit.wgsl has no section {name}"))
        + marker.len();
    let end = MASTER[start..]
        .find("// @section ")
        .map_or(MASTER.len(), |e| start + e);
    &MASTER[start..end]
}

/// An f32 constant as a WGSL literal (round-trips the f32).
fn lit(x: f64) -> String {
    let v = x as f32;
    let s = format!("{v:?}");
    if s.contains('.') || s.contains('e') || s.contains("inf") || s.contains("NaN") {
        s
    } else {
        format!("{s}.0")
    }
}

fn vec4(v: [f64; 4]) -> String {
    format!(
        "vec4<f32>({}, {}, {}, {})",
        lit(v[0]),
        lit(v[1]),
        lit(v[2]),
        lit(v[3])
    )
}

/// What an export bakes in.
pub struct Baked {
    pub id: ModelId,
    /// (H, weight) of the spot's height distribution (one node for rungs without a topology).
    pub heights: Vec<(f64, f64)>,
    /// (cos, sin, weight) of the spread's nodes (one identity node without a spread).
    pub spread: Vec<(f64, f64, f64)>,
    pub quadrature_order: usize,
    /// The rows of `FibrefitParams::material` (at least one).
    pub material: Vec<[f64; 4]>,
}

impl Baked {
    pub fn new(id: ModelId, p: &ModelParams) -> Result<Self> {
        let (_, _, material_rows) = sections(id)?;
        let material = match material_rows {
            Some(rows) => rows(p),
            None => vec![[0.0; 4]],
        };
        let heights = if id.has(Ability::HeightHistogram) {
            p.topology.discretise(p.spacing, p.histogram_bins)
        } else {
            vec![(0.0, 1.0)]
        };
        let spread = if id.has(Ability::DirectionSpread) && p.azimuth_spread_deg > 0.0 {
            spread_nodes(p.azimuth_spread_deg, p.azimuth_nodes, p.fibre_azimuth)
        } else {
            vec![(1.0, 0.0, 1.0)]
        };
        Ok(Self {
            id,
            heights,
            spread,
            quadrature_order: if id.is_cross_section() {
                p.quadrature_order
            } else {
                1
            },
            material,
        })
    }
}

/// The members of `FibrefitParams` in order, each a vec4 (the struct is nothing but vec4s and
/// arrays of vec4, so this is also its uniform-buffer layout, 16 bytes per row).
fn params_rows(p: &ModelParams, baked: &Baked) -> Vec<[f64; 4]> {
    let a = &p.albedos;
    let rgb = |c: [f64; 3]| [c[0], c[1], c[2], 0.0];
    let lobe_floor = (1e-15f64.ln() / p.exponent).exp();
    let mut rows = vec![
        rgb(a.diffuse),
        rgb(a.specular),
        rgb(a.substrate),
        rgb(a.fuzz),
        [p.exponent, p.spacing, p.fresnel_ior, lobe_floor],
        [p.alpha_x, p.alpha_y, p.fuzz_depth, p.fuzz_asymmetry],
        [
            p.topology.height,
            p.topology.map_scale,
            max_height(p.spacing),
            0.0,
        ],
    ];
    rows.extend(&baked.material);
    rows.extend(baked.heights.iter().map(|&(h, w)| [h, w, 0.0, 0.0]));
    rows.extend(baked.spread.iter().map(|&(c, s, w)| [c, s, w, 0.0]));
    rows
}

/// The bytes of a `FibrefitParams` uniform buffer holding the parameters `wgsl` bakes in
/// (little-endian f32), for renderers (and tests) that pass them with the `_with` entry points.
pub fn params_uniform(id: ModelId, p: &ModelParams) -> Result<Vec<u8>> {
    let baked = Baked::new(id, p)?;
    Ok(params_rows(p, &baked)
        .iter()
        .flat_map(|r| r.iter().flat_map(|&x| (x as f32).to_le_bytes()))
        .collect())
}

/// The WGSL library for rung `id` with parameters `p`; `provenance` (one line per entry) says
/// where they came from. Validated by naga before it is returned.
pub fn wgsl(id: ModelId, p: &ModelParams, provenance: &[String]) -> Result<String> {
    let baked = Baked::new(id, p)?;
    let mut s = String::new();
    writeln!(
        s,
        "// fibrefit {} shader export: model `{id}`",
        env!("CARGO_PKG_VERSION")
    )?;
    for line in provenance {
        writeln!(s, "// {line}")?;
    }
    s.push_str("//\n");
    s.push_str(HEADER);
    s.push('\n');
    writeln!(
        s,
        "// The rung and its discretisation (fixed by this export).\nconst FIBREFIT_MODEL: u32 = {}u; // {id}",
        ModelId::ALL.iter().position(|&m| m == id).unwrap_or(0)
    )?;
    writeln!(
        s,
        "const FIBREFIT_FIBRE_AZIMUTH_DEG: f32 = {}; // the fit's fibre azimuth psi from the swatch's x axis",
        lit(p.fibre_azimuth.to_degrees())
    )?;
    writeln!(
        s,
        "const FIBREFIT_MAX_HEIGHT: f32 = {}; // sqrt(d^2 - 1), fibre radii",
        lit(max_height(p.spacing))
    )?;
    writeln!(
        s,
        "const FIBREFIT_HEIGHT_NODES: u32 = {}u;",
        baked.heights.len()
    )?;
    writeln!(
        s,
        "const FIBREFIT_MATERIAL_ROWS: u32 = {}u;\nconst FIBREFIT_SPREAD_NODES: u32 = {}u;",
        baked.material.len(),
        baked.spread.len()
    )?;
    writeln!(
        s,
        "const FIBREFIT_QUADRATURE_ORDER: u32 = {}u;",
        baked.quadrature_order
    )?;
    let gl = GaussLegendre::new(baked.quadrature_order);
    let (x, w) = gl.nodes_and_weights();
    let nodes: Vec<String> = x
        .iter()
        .zip(w)
        .map(|(x, w)| format!("vec2<f32>({}, {})", lit(*x), lit(*w)))
        .collect();
    writeln!(
        s,
        "// Gauss-Legendre nodes and weights on [-1, 1] of the specular lobe\nconst FIBREFIT_GAUSS_LEGENDRE = array<vec2<f32>, {}>(\n    {}\n);\n",
        nodes.len(),
        nodes.join(",\n    ")
    )?;
    s.push_str(PARAMS_STRUCT);
    s.push('\n');
    let rows = params_rows(p, &baked);
    let fmt = |r: &[[f64; 4]]| -> Vec<String> { r.iter().map(|v| vec4(*v)).collect() };
    let (fixed, arrays) = rows.split_at(7);
    let (material_rows, arrays) = arrays.split_at(baked.material.len());
    let (heights, spread) = arrays.split_at(baked.heights.len());
    let f = fmt(fixed);
    writeln!(
        s,
        "// The fitted parameters.
fn fibrefit_params() -> FibrefitParams {{
    return FibrefitParams(
        {}, // kd
        {}, // ks
        {}, // substrate
        {}, // fuzz
        {}, // exponent, spacing, Fresnel ior, lobe floor
        {}, // alpha_x, alpha_y, fuzz depth, fuzz asymmetry
        {}, // H0, map scale, H_max
        array<vec4<f32>, {}>(\n            {}\n        ),
        array<vec4<f32>, {}>(\n            {}\n        ),
        array<vec4<f32>, {}>(\n            {}\n        )
    );
}}
",
        f[0],
        f[1],
        f[2],
        f[3],
        f[4],
        f[5],
        f[6],
        material_rows.len(),
        fmt(material_rows).join(",\n            "),
        heights.len(),
        fmt(heights).join(",\n            "),
        spread.len(),
        fmt(spread).join(",\n            "),
    )?;
    s.push_str(&correction_wgsl(p.correction.as_ref()));
    s.push_str(section("common"));
    let (names, body, _) = sections(id)?;
    for name in names {
        s.push_str(section(name));
    }
    writeln!(
        s,
        "
// ---------------------------------------------------------------------------------------------
// The rung `{id}` and the public entry points.
// ---------------------------------------------------------------------------------------------

fn fibrefit_rung(p: FibrefitParams, l: vec3<f32>, v: vec3<f32>, height: f32, at_height: bool) -> vec4<f32> {{
{}}}",
        body
    )?;
    s.push_str(PUBLIC);
    validate(&s)?;
    Ok(s)
}

/// `fibrefit_correction(l, v, n)`: the factor of the result's smooth correction `k` per
/// channel (`model::correction`, in f32), or 1 without one.
fn correction_wgsl(k: Option<&crate::model::correction::Correction>) -> String {
    let Some(k) = k else {
        return "
// No correction: the rung as fitted (a result's `correction` would multiply it here).
fn fibrefit_correction(l: vec3<f32>, v: vec3<f32>, n: vec3<f32>) -> vec3<f32> {
    return vec3<f32>(1.0);
}
"
        .into();
    };
    let v3 = |x: [f64; 3]| format!("vec3<f32>({}, {}, {})", lit(x[0]), lit(x[1]), lit(x[2]));
    let terms = crate::model::correction::terms(k.degree);
    let term_list: Vec<String> = terms
        .iter()
        .map(|(a, b, c)| format!("vec3<u32>({a}u, {b}u, {c}u)"))
        .collect();
    let coeffs: Vec<String> = k.coefficients.iter().map(|c| v3(*c)).collect();
    format!(
        "
// The result's smooth correction of the rung (`correction.series`; not a physical parameter):
// the BRDF per channel times exp(s), s = sum over the terms (a, b, c) of c_k (P_a(x_i) P_b(x_o)
// + P_b(x_i) P_a(x_o)) P_c(y) (one product when a = b), P_n Legendre polynomials,
// x = 2 cos theta - 1 with the cosine clamped to the range the data covered, y = cos(phi_i -
// phi_o); s clamped per channel to the range it took on the data. Reciprocal in l and v.
const FIBREFIT_CORRECTION_DEGREE: u32 = {degree}u;
const FIBREFIT_CORRECTION_TERMS: u32 = {n}u;
const FIBREFIT_CORRECTION_COS: vec2<f32> = vec2<f32>({lo}, {hi});
const FIBREFIT_CORRECTION_LOG_LO: vec3<f32> = {log_lo};
const FIBREFIT_CORRECTION_LOG_HI: vec3<f32> = {log_hi};
const FIBREFIT_CORRECTION_TERM = array<vec3<u32>, {n}>(
    {term_list}
);
const FIBREFIT_CORRECTION_COEFF = array<vec3<f32>, {n}>(
    {coeffs}
);

// P_0(x) .. P_8(x) (those above the correction's degree unused).
fn fibrefit_legendre(x: f32) -> array<f32, 9> {{
    var p: array<f32, 9>;
    p[0] = 1.0;
    p[1] = x;
    for (var k = 2u; k <= FIBREFIT_CORRECTION_DEGREE; k++) {{
        let kf = f32(k);
        p[k] = ((2.0 * kf - 1.0) * x * p[k - 1u] - (kf - 1.0) * p[k - 2u]) / kf;
    }}
    return p;
}}

// The factor per channel at unit l, v (towards the light and the viewer) and the macro normal
// n; 1 at and below either horizon (where the BRDF is 0).
fn fibrefit_correction(l: vec3<f32>, v: vec3<f32>, n: vec3<f32>) -> vec3<f32> {{
    let ci = dot(l, n);
    let co = dot(v, n);
    if (!(ci > 0.0 && co > 0.0)) {{
        return vec3<f32>(1.0);
    }}
    let lp = l - ci * n;
    let vp = v - co * n;
    let q = sqrt(dot(lp, lp) * dot(vp, vp));
    var y = 1.0;
    if (q > 1e-12) {{
        y = clamp(dot(lp, vp) / q, -1.0, 1.0);
    }}
    let range = FIBREFIT_CORRECTION_COS;
    let pl = fibrefit_legendre(2.0 * clamp(ci, range.x, range.y) - 1.0);
    let pv = fibrefit_legendre(2.0 * clamp(co, range.x, range.y) - 1.0);
    let py = fibrefit_legendre(y);
    var term = FIBREFIT_CORRECTION_TERM;
    var coeff = FIBREFIT_CORRECTION_COEFF;
    var s = vec3<f32>(0.0);
    for (var k = 0u; k < FIBREFIT_CORRECTION_TERMS; k++) {{
        let t = term[k];
        var b = pl[t.x] * pv[t.y];
        if (t.x != t.y) {{
            b += pl[t.y] * pv[t.x];
        }}
        s += (b * py[t.z]) * coeff[k];
    }}
    return exp(clamp(s, FIBREFIT_CORRECTION_LOG_LO, FIBREFIT_CORRECTION_LOG_HI));
}}
",
        degree = k.degree,
        n = terms.len(),
        lo = lit(k.cos_range[0]),
        hi = lit(k.cos_range[1]),
        log_lo = v3(k.log_range.map(|r| r[0])),
        log_hi = v3(k.log_range.map(|r| r[1])),
        term_list = term_list.join(",\n    "),
        coeffs = coeffs.join(",\n    "),
    )
}

/// The entry points, the same for every rung.
const PUBLIC: &str = "
// The basis at fibre-frame directions: the spread's nodes, the Fresnel factor, the fuzz layer.
fn fibrefit_basis_local(p: FibrefitParams, l: vec3<f32>, v: vec3<f32>, height: f32, at_height: bool) -> vec4<f32> {
    if (!(l.z > 0.0 && v.z > 0.0)) {
        return vec4<f32>(0.0);
    }
    var spread = p.spread;
    var b = vec4<f32>(0.0);
    for (var j = 0u; j < FIBREFIT_SPREAD_NODES; j++) {
        let c = spread[j].x;
        let s = spread[j].y;
        let lr = normalize(vec3<f32>(l.x * c + l.y * s, -l.x * s + l.y * c, l.z));
        let vr = normalize(vec3<f32>(v.x * c + v.y * s, -v.x * s + v.y * c, v.z));
        b += spread[j].z * fibrefit_rung(p, lr, vr, height, at_height);
    }
    b.y *= fibrefit_schlick(l, v, p.shape.z);
    let fz = fibrefit_fuzz(l, v, p.extra.z, p.extra.w);
    return vec4<f32>(b.xyz * fz.x, b.w * fz.x + fz.y);
}

fn fibrefit_combine(p: FibrefitParams, b: vec4<f32>) -> vec3<f32> {
    return b.x * p.kd.xyz + b.y * p.ks.xyz + b.z * p.substrate.xyz + b.w * p.fuzz.xyz;
}

fn fibrefit_height_from_map_with(p: FibrefitParams, m: f32) -> f32 {
    return clamp(p.topology.x + p.topology.y * (2.0 * m - 1.0), 0.0, p.topology.z);
}

fn fibrefit_basis_with(p: FibrefitParams, l: vec3<f32>, v: vec3<f32>, n: vec3<f32>, t: vec3<f32>) -> vec4<f32> {
    let d = fibrefit_local(l, v, n, t, 0.0);
    return fibrefit_basis_local(p, d.l, d.v, 0.0, false);
}

fn fibrefit_basis_at_with(p: FibrefitParams, l: vec3<f32>, v: vec3<f32>, n: vec3<f32>, t: vec3<f32>, height: f32, azimuth_offset: f32) -> vec4<f32> {
    let d = fibrefit_local(l, v, n, t, azimuth_offset);
    return fibrefit_basis_local(p, d.l, d.v, clamp(height, 0.0, p.topology.z), true);
}

fn fibrefit_brdf_with(p: FibrefitParams, l: vec3<f32>, v: vec3<f32>, n: vec3<f32>, t: vec3<f32>) -> vec3<f32> {
    return fibrefit_combine(p, fibrefit_basis_with(p, l, v, n, t)) * fibrefit_correction(l, v, n);
}

fn fibrefit_brdf_at_with(p: FibrefitParams, l: vec3<f32>, v: vec3<f32>, n: vec3<f32>, t: vec3<f32>, height: f32, azimuth_offset: f32) -> vec3<f32> {
    return fibrefit_combine(p, fibrefit_basis_at_with(p, l, v, n, t, height, azimuth_offset))
        * fibrefit_correction(l, v, n);
}

fn fibrefit_height_from_map(m: f32) -> f32 {
    return fibrefit_height_from_map_with(fibrefit_params(), m);
}

fn fibrefit_basis(l: vec3<f32>, v: vec3<f32>, n: vec3<f32>, t: vec3<f32>) -> vec4<f32> {
    return fibrefit_basis_with(fibrefit_params(), l, v, n, t);
}

fn fibrefit_basis_at(l: vec3<f32>, v: vec3<f32>, n: vec3<f32>, t: vec3<f32>, height: f32, azimuth_offset: f32) -> vec4<f32> {
    return fibrefit_basis_at_with(fibrefit_params(), l, v, n, t, height, azimuth_offset);
}

fn fibrefit_brdf(l: vec3<f32>, v: vec3<f32>, n: vec3<f32>, t: vec3<f32>) -> vec3<f32> {
    return fibrefit_brdf_with(fibrefit_params(), l, v, n, t);
}

fn fibrefit_brdf_at(l: vec3<f32>, v: vec3<f32>, n: vec3<f32>, t: vec3<f32>, height: f32, azimuth_offset: f32) -> vec3<f32> {
    return fibrefit_brdf_at_with(fibrefit_params(), l, v, n, t, height, azimuth_offset);
}
";

/// Parse and validate WGSL with naga.
pub fn validate(src: &str) -> Result<(naga::Module, naga::valid::ModuleInfo)> {
    let module = naga::front::wgsl::parse_str(src).map_err(|e| {
        anyhow!(
            "internal: the shader does not parse: {}",
            e.emit_to_string(src)
        )
    })?;
    let info = naga::valid::Validator::new(
        naga::valid::ValidationFlags::all(),
        naga::valid::Capabilities::empty(),
    )
    .validate(&module)
    .map_err(|e| {
        anyhow!(
            "internal: the shader does not validate: {}",
            e.emit_to_string(src)
        )
    })?;
    Ok((module, info))
}

/// Instructions in the SPIR-V naga makes of the library (all its functions, called from one
/// entry point whose few instructions are included): the static size of the shader.
pub fn spirv_instructions(wgsl: &str) -> Result<usize> {
    let (module, info) = validate(&format!("{wgsl}{ANCHOR}"))?;
    let words = naga::back::spv::write_vec(
        &module,
        &info,
        &naga::back::spv::Options::default(),
        Some(&naga::back::spv::PipelineOptions {
            shader_stage: naga::ShaderStage::Compute,
            entry_point: "fibrefit_anchor_main".into(),
        }),
    )
    .map_err(|e| anyhow!("internal: SPIR-V translation: {e}"))?;
    // header of 5 words, then instructions whose first word holds their length in its high half
    let mut at = 5;
    let mut count = 0;
    while at < words.len() {
        let len = (words[at] >> 16) as usize;
        if len == 0 {
            bail!("internal: malformed SPIR-V");
        }
        at += len;
        count += 1;
    }
    Ok(count)
}

/// A compute entry point that calls every public function, so backends that write only what an
/// entry point reaches (GLSL) write them all; removed from the translation afterwards.
const ANCHOR: &str = "
@group(0) @binding(0) var<storage, read_write> fibrefit_anchor_io: array<vec4<f32>>;
@compute @workgroup_size(1)
fn fibrefit_anchor_main() {
    let a = fibrefit_anchor_io[0].xyz;
    let h = fibrefit_anchor_io[0].w;
    fibrefit_anchor_io[1] = vec4<f32>(fibrefit_brdf(a, a, a, a), h);
    fibrefit_anchor_io[2] = vec4<f32>(fibrefit_brdf_at(a, a, a, a, h, h), h);
    fibrefit_anchor_io[3] = fibrefit_basis(a, a, a, a);
    fibrefit_anchor_io[4] = fibrefit_basis_at(a, a, a, a, h, h);
    fibrefit_anchor_io[5] = vec4<f32>(fibrefit_height_from_map(h));
}
";

/// `wgsl` (a validated library) in `lang`, validated by naga, without entry points or bindings.
/// GLSL has no `#version` line (the host shader's comes first; written for GLSL 4.50 core).
pub fn translate(wgsl: &str, lang: Language) -> Result<String> {
    if lang == Language::Wgsl {
        return Ok(wgsl.to_string());
    }
    let header: String = wgsl
        .lines()
        .take_while(|l| l.starts_with("//"))
        .map(|l| format!("{l}\n"))
        .collect();
    let body = match lang {
        Language::Glsl => {
            // the GLSL writer writes what one entry point reaches: an anchor reaching everything,
            // removed again below
            let out = glsl_of(
                &format!("{wgsl}{ANCHOR}"),
                naga::back::glsl::Version::Desktop(450),
                naga::ShaderStage::Compute,
                "GLSL",
            )?;
            format!(
                "// GLSL 4.50 core. No #version line: include this after your shader's own.\n{}",
                strip_glsl_anchor(&out)?
            )
        }
        Language::GlslEs => return glsl_es(wgsl, &header),
        Language::Hlsl => {
            let (module, info) = validate(wgsl)?;
            let options = naga::back::hlsl::Options::default();
            let mut out = String::new();
            let mut w = naga::back::hlsl::Writer::new(&mut out, &options);
            w.write(&module, &info, None)
                .map_err(|e| anyhow!("internal: HLSL translation: {e}"))?;
            format!("// HLSL shader model 5.1 or later.\n{out}")
        }
        Language::Msl => {
            let (module, info) = validate(wgsl)?;
            let options = naga::back::msl::Options::default();
            let pipeline = naga::back::msl::PipelineOptions::default();
            let (out, _) = naga::back::msl::write_string(&module, &info, &options, &pipeline)
                .map_err(|e| anyhow!("internal: MSL translation: {e}"))?;
            out
        }
        Language::Wgsl => unreachable!(),
    };
    Ok(format!("{header}{body}"))
}

/// `source` (the library with an anchor entry point `fibrefit_anchor_main` of `stage`, which
/// reaches every public function) validated and written by naga's GLSL writer at `version`;
/// `what` names the dialect in errors.
fn glsl_of(
    source: &str,
    version: naga::back::glsl::Version,
    stage: naga::ShaderStage,
    what: &str,
) -> Result<String> {
    let (module, info) = validate(source)?;
    let options = naga::back::glsl::Options {
        version,
        ..Default::default()
    };
    let pipeline = naga::back::glsl::PipelineOptions {
        shader_stage: stage,
        entry_point: "fibrefit_anchor_main".into(),
        multiview: None,
    };
    let mut out = String::new();
    let mut w = naga::back::glsl::Writer::new(
        &mut out,
        &module,
        &info,
        &options,
        &pipeline,
        naga::proc::BoundsCheckPolicies::default(),
    )
    .map_err(|e| anyhow!("internal: {what} translation: {e}"))?;
    w.write()
        .map_err(|e| anyhow!("internal: {what} translation: {e}"))?;
    Ok(out)
}

/// A fragment entry point calling every public function, for GLSL ES 3.00 (which has no compute
/// shaders); removed from the translation afterwards.
const FRAGMENT_ANCHOR: &str = "
@fragment
fn fibrefit_anchor_main(@location(0) a: vec4<f32>) -> @location(0) vec4<f32> {
    let x = a.xyz;
    let h = a.w;
    return vec4<f32>(fibrefit_brdf(x, x, x, x) + fibrefit_brdf_at(x, x, x, x, h, h), h)
        + fibrefit_basis(x, x, x, x) + fibrefit_basis_at(x, x, x, x, h, h)
        + vec4<f32>(fibrefit_height_from_map(h));
}
";

/// The first lines of a GLSL ES export: a WebGL2 fragment shader's `#version` and precisions
/// (three.js's `ShaderMaterial` with `glslVersion: THREE.GLSL3` writes its own: leave these out
/// there, [`GLSL_ES_PRELUDE`]'s line count says how many).
pub const GLSL_ES_PRELUDE: &str = "#version 300 es\nprecision highp float;\nprecision highp int;\n";

/// `wgsl` as GLSL ES 3.00 (WebGL2), validated by naga: [`GLSL_ES_PRELUDE`], then `header`
/// (comments), then the library, without the anchor.
fn glsl_es(wgsl: &str, header: &str) -> Result<String> {
    let out = glsl_of(
        &format!("{wgsl}{FRAGMENT_ANCHOR}"),
        naga::back::glsl::Version::Embedded {
            version: 300,
            is_webgl: true,
        },
        naga::ShaderStage::Fragment,
        "GLSL ES",
    )?;
    // the anchor's varyings and output, and the writer's own version and precision lines
    let kept: String = out
        .lines()
        .filter(|l| {
            !(l.starts_with("precision ") || l.starts_with("smooth in ") || l.starts_with("in "))
        })
        .map(|l| format!("{l}\n"))
        .collect();
    let body = strip_glsl_anchor(&kept)?;
    if body.contains("_vs2fs") || body.contains("_fs2p") {
        bail!("internal: the GLSL ES translation still refers to the anchor's varyings");
    }
    Ok(format!(
        "{GLSL_ES_PRELUDE}{header}// GLSL ES 3.00 (WebGL2). The first three lines are a fragment shader's \
         #version and precisions: leave them out where the host writes its own (three.js's \
         ShaderMaterial with glslVersion THREE.GLSL3).\n{body}"
    ))
}

/// The GLSL writer's output without the anchor: no `#version`/`#extension` lines, no `layout`
/// declarations (the compute size, the anchor's buffer) and no `void main()`.
fn strip_glsl_anchor(body: &str) -> Result<String> {
    let mut out = String::new();
    let mut lines = body.lines();
    let mut main = false;
    while let Some(line) = lines.next() {
        if line.starts_with("#version")
            || line.starts_with("#extension")
            || line.starts_with("layout(")
        {
            continue;
        }
        if line.starts_with("void main(") {
            main = true;
            if !line.trim_end().ends_with('}') {
                for l in lines.by_ref() {
                    if l.starts_with('}') {
                        break;
                    }
                }
            }
            continue;
        }
        out.push_str(line);
        out.push('\n');
    }
    if !main {
        bail!("internal: the GLSL translation has no anchor entry point to remove");
    }
    if out.contains("_group_0_binding") || out.contains("fibrefit_anchor") {
        bail!("internal: the GLSL translation still refers to the anchor");
    }
    Ok(out)
}
