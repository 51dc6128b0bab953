// @section common
// ---------------------------------------------------------------------------------------------
// fibrefit shading library (WGSL master; GLSL, HLSL and MSL are translated from it by naga).
// Every name starts with fibrefit_ / Fibrefit / FIBREFIT_. f32 throughout. Local frame
// components of a direction are (t, b, n) = (along the fibre, along N x T, along N).
// ---------------------------------------------------------------------------------------------

const FIBREFIT_PI: f32 = 3.14159265358979;
const FIBREFIT_FRAC_1_PI: f32 = 0.318309886183791;

// The directions in the fibre frame (T, B = N x T, N) of a renderer's unit vectors; the tangent
// is made perpendicular to n and turned by `azimuth_offset` (radians, from T towards B).
struct FibrefitLocal {
    l: vec3<f32>,
    v: vec3<f32>,
}

fn fibrefit_local(l: vec3<f32>, v: vec3<f32>, n: vec3<f32>, t: vec3<f32>, azimuth_offset: f32) -> FibrefitLocal {
    var tp = t - n * dot(t, n);
    let len = length(tp);
    if (!(len > 1e-12)) {
        // no tangent in the plane: any perpendicular (the result is then that of an arbitrary
        // fibre direction)
        if (abs(n.x) < 0.9) {
            tp = cross(n, vec3<f32>(1.0, 0.0, 0.0));
        } else {
            tp = cross(n, vec3<f32>(0.0, 1.0, 0.0));
        }
    }
    tp = normalize(tp);
    var bt = cross(n, tp);
    if (azimuth_offset != 0.0) {
        let c = cos(azimuth_offset);
        let s = sin(azimuth_offset);
        let t2 = tp * c + bt * s;
        bt = bt * c - tp * s;
        tp = t2;
    }
    return FibrefitLocal(
        vec3<f32>(dot(l, tp), dot(l, bt), dot(l, n)),
        vec3<f32>(dot(v, tp), dot(v, bt), dot(v, n))
    );
}

// Elementary functions written out: drivers' asin, acos, atan2 and log2 vary (one CPU Vulkan
// driver measured 4e-4 absolute for asin and 6e-7 absolute for log2, which e = 1e4 turns into
// 4e-3 in the lobe); with these the whole model agrees with fibrefit's f64 model to ~1e-5.

// atan(x) for |x| <= 1 (Cephes atanf: reduction at tan(pi/8), minimax on [0, tan(pi/8)]).
fn fibrefit_atan_unit(x: f32) -> f32 {
    let a = abs(x);
    var y = 0.0;
    var z = a;
    if (a > 0.41421356) {
        y = 0.78539816;
        z = (a - 1.0) / (a + 1.0);
    }
    let z2 = z * z;
    let r = (((8.05374449538e-2 * z2 - 1.38776856032e-1) * z2 + 1.99777106478e-1) * z2
        - 3.33329491539e-1) * z2 * z + z;
    return sign(x) * (y + r);
}

// atan2(y, x) for x >= 0 (every call in the model: angles from N in the right half plane).
fn fibrefit_atan2_right(y: f32, x: f32) -> f32 {
    if (abs(y) <= x) {
        if (x == 0.0) {
            return 0.0;
        }
        return fibrefit_atan_unit(y / x);
    }
    return sign(y) * 1.57079633 - fibrefit_atan_unit(x / y);
}

// asin(s), s in [-1, 1]; 1 - s^2 as (1 - s)(1 + s), exact near +-1.
fn fibrefit_asin(s: f32) -> f32 {
    let c = clamp(s, -1.0, 1.0);
    return fibrefit_atan2_right(c, sqrt((1.0 - c) * (1.0 + c)));
}

// acos(c), c in [0, 1].
fn fibrefit_acos_positive(c: f32) -> f32 {
    let x = clamp(c, 0.0, 1.0);
    return fibrefit_atan2_right(sqrt((1.0 - x) * (1.0 + x)), x);
}

// ln(x) for x > 0 normal: x = 2^k m, m in [sqrt(1/2), sqrt(2)), ln m = 2 atanh(f / (2 + f)).
fn fibrefit_ln(x: f32) -> f32 {
    let bits = bitcast<u32>(x);
    var k = f32(i32((bits >> 23u) & 0xffu) - 127);
    var m = bitcast<f32>((bits & 0x007fffffu) | 0x3f800000u);
    if (m > 1.41421356) {
        m = 0.5 * m;
        k = k + 1.0;
    }
    let f = m - 1.0;
    let s = f / (2.0 + f);
    let z = s * s;
    let r = 2.0 * s * (1.0 + z * (1.0 / 3.0 + z * (1.0 / 5.0 + z * (1.0 / 7.0 + z * (1.0 / 9.0)))));
    return k * 0.693147181 + r;
}

// x^e for x >= 0, e >= 1 (0 at x = 0, where pow is undefined in some languages).
fn fibrefit_pow(x: f32, e: f32) -> f32 {
    if (x < 1e-30) {
        return 0.0;
    }
    return exp(e * fibrefit_ln(x));
}

// Schlick's factor at cos theta_d = l.h for index of refraction `ior` (0: off, factor 1).
fn fibrefit_schlick(l: vec3<f32>, v: vec3<f32>, ior: f32) -> f32 {
    if (ior <= 0.0) {
        return 1.0;
    }
    let h = l + v;
    let norm = length(h);
    var c = 0.0;
    if (norm > 0.0) {
        c = clamp(dot(l, h) / norm, 0.0, 1.0);
    }
    let f0 = ((ior - 1.0) / (ior + 1.0)) * ((ior - 1.0) / (ior + 1.0));
    let m = 1.0 - c;
    let m2 = m * m;
    return f0 + (1.0 - f0) * (m2 * m2 * m);
}

// The fuzz layer: (attenuation A of the rung, single-scattering column P); depth 0: (1, 0).
fn fibrefit_fuzz(l: vec3<f32>, v: vec3<f32>, depth: f32, g: f32) -> vec2<f32> {
    let mi = l.z;
    let mo = v.z;
    if (!(mi > 0.0 && mo > 0.0) || depth <= 0.0) {
        return vec2<f32>(1.0, 0.0);
    }
    let a = exp(-depth * (1.0 / mi + 1.0 / mo));
    let cos_a = clamp(-dot(l, v), -1.0, 1.0);
    let d = max(1.0 + g * g - 2.0 * g * cos_a, 1e-30);
    let p = (1.0 - g * g) / (4.0 * FIBREFIT_PI * d * sqrt(d));
    return vec2<f32>(a, p * (1.0 - a) / (4.0 * (mi + mo)));
}

// @section lambert
fn fibrefit_lambert(l: vec3<f32>, v: vec3<f32>) -> vec4<f32> {
    return vec4<f32>(FIBREFIT_FRAC_1_PI, 0.0, 0.0, 0.0);
}

// @section max_normal
// Banks / Heidrich-Seidel: the brightest normal (MODEL.md, max-normal).
fn fibrefit_max_normal(l: vec3<f32>, v: vec3<f32>, exponent: f32) -> vec4<f32> {
    let lp = sqrt(l.y * l.y + l.z * l.z);
    let vp = sqrt(v.y * v.y + v.z * v.z);
    let lobe = max(lp * vp - l.x * v.x, 0.0);
    return vec4<f32>(FIBREFIT_FRAC_1_PI * lp / l.z, fibrefit_pow(lobe, exponent) / l.z, 0.0, 0.0);
}

// @section hast_diffuse
// Hast's diffuse in the stable form Phi = (|l_p| + N.l) / pi.
fn fibrefit_hast_diffuse(l: vec3<f32>, v: vec3<f32>) -> vec4<f32> {
    let phi = FIBREFIT_FRAC_1_PI * (sqrt(l.y * l.y + l.z * l.z) + l.z);
    return vec4<f32>(FIBREFIT_FRAC_1_PI * phi / l.z, 0.0, 0.0, 0.0);
}

// @section ward
// Ward 1992, normalised (alpha_x along the fibre, alpha_y across).
fn fibrefit_ward(l: vec3<f32>, v: vec3<f32>, ax: f32, ay: f32) -> vec4<f32> {
    let h = l + v;
    let e = ((h.x / ax) * (h.x / ax) + (h.y / ay) * (h.y / ay)) / (h.z * h.z);
    let lobe = exp(-e) / (4.0 * FIBREFIT_PI * ax * ay * sqrt(l.z * v.z));
    return vec4<f32>(FIBREFIT_FRAC_1_PI, lobe, 0.0, 0.0);
}

// @section gltf
// The glTF 2.0 metallic-roughness BRDF with KHR_materials_sheen, _anisotropy (along t),
// _specular and _ior (src/model/rungs/gltf.rs, which cites the specifications): x the base
// colour's column, y the layers' (specular lobes and sheen). p.material: [0] metallic, GGX alpha
// along t, alpha along b (the anisotropy direction), specular factor; [1] dielectric F0 from the
// ior, sheen, sheen alpha, variant (0 khronos, 1 threejs: three.js r187's BRDF, whose base colour
// squared's column is z); [2..] the sheen's directional albedo E at N.v = k / 31, k = 0..31,
// four a row.
fn fibrefit_gltf_lambda_l(x: f32, a: f32) -> f32 {
    let t = (1.0 - a) * (1.0 - a);
    let pa = mix(21.5473, 25.3245, t);
    let pb = mix(3.82987, 3.32435, t);
    let pc = mix(0.19823, 0.16801, t);
    let pd = mix(-1.97760, -1.27393, t);
    let pe = mix(-4.32054, -4.85967, t);
    var xp = 0.0;
    if (x > 0.0) {
        xp = exp(pc * log(x));
    }
    return pa / (1.0 + pb * xp) + pd * x + pe;
}

fn fibrefit_gltf_sheen_lambda(c: f32, a: f32) -> f32 {
    if (abs(c) < 0.5) {
        return exp(fibrefit_gltf_lambda_l(c, a));
    }
    return exp(2.0 * fibrefit_gltf_lambda_l(0.5, a) - fibrefit_gltf_lambda_l(1.0 - c, a));
}

// The sheen's directional albedo E at cos theta, linear between the table's nodes.
fn fibrefit_gltf_sheen_e(p: FibrefitParams, mu: f32) -> f32 {
    var g = p.material;
    let x = clamp(mu, 0.0, 1.0) * 31.0;
    let k = min(u32(floor(x)), 30u);
    let f = x - f32(k);
    let a = g[2u + k / 4u][k % 4u];
    let b = g[2u + (k + 1u) / 4u][(k + 1u) % 4u];
    return a * (1.0 - f) + b * f;
}

fn fibrefit_gltf(l: vec3<f32>, v: vec3<f32>, p: FibrefitParams) -> vec4<f32> {
    let g0 = p.material[0];
    let g1 = p.material[1];
    if (g1.w > 0.5) {
        // gltf_variant = threejs
        return fibrefit_gltf_threejs(l, v, p);
    }
    let m = g0.x;
    let at = g0.y;
    let ab = g0.z;
    let sp = g0.w;
    let h = normalize(l + v);
    let vh = abs(dot(v, h));
    let x1 = clamp(1.0 - vh, 0.0, 1.0);
    let x2 = x1 * x1;
    let x = x2 * x2 * x1;
    // anisotropic GGX D and height-correlated V
    let a2 = at * ab;
    let f = vec3<f32>(ab * h.x, at * h.y, a2 * h.z);
    let w2 = a2 / dot(f, f);
    var d = 0.0;
    if (h.z > 0.0) {
        d = a2 * w2 * w2 * FIBREFIT_FRAC_1_PI;
    }
    let vis_v = l.z * length(vec3<f32>(at * v.x, ab * v.y, v.z));
    let vis_l = v.z * length(vec3<f32>(at * l.x, ab * l.y, l.z));
    let s = d * 0.5 / (vis_v + vis_l);
    let fr = g1.x + (1.0 - g1.x) * x;
    let diffuse = (1.0 - m) * (1.0 - sp * fr) * FIBREFIT_FRAC_1_PI + m * s * (1.0 - x);
    let layers = (1.0 - m) * sp * fr * s + m * s * x;
    var k = 1.0;
    var sheen = 0.0;
    if (g1.y > 0.0) {
        let a = g1.z;
        let e = max(fibrefit_gltf_sheen_e(p, l.z), fibrefit_gltf_sheen_e(p, v.z));
        k = 1.0 - g1.y * e;
        let sin2 = max(1.0 - h.z * h.z, 0.0);
        var dc = 0.0;
        if (sin2 > 0.0) {
            dc = (2.0 + 1.0 / a) * exp(0.5 / a * log(sin2)) / (2.0 * FIBREFIT_PI);
        }
        let vs = 1.0 / ((1.0 + fibrefit_gltf_sheen_lambda(v.z, a) + fibrefit_gltf_sheen_lambda(l.z, a)) * (4.0 * v.z * l.z));
        sheen = g1.y * dc * clamp(vs, 0.0, 1.0);
    }
    return vec4<f32>(k * diffuse, k * layers + sheen, 0.0, 0.0);
}

// @section gltf_threejs
// The gltf rung's `threejs` variant (src/model/rungs/gltf/threejs.rs, which writes the equations
// and names the three.js r187 chunks they follow): Epic's Fresnel, the multiple-scattering factor
// from three.js's DFG table, V_Neubelt and D_Charlie with its floor, IBLSheenBRDF's albedo
// scaling; x the base colour's column, y the layers', z the base colour squared's (kd^2 is the
// substrate albedo of this variant).
// three.js's DFG table (DFGLUTData.js), (scale, bias) per texel, rows along N.v, 16 x 16.
const FIBREFIT_GLTF_DFG = array<vec2<f32>, 256>(
    vec2<f32>(0.1470947265625, 0.85205078125), vec2<f32>(0.16552734375, 0.78759765625), vec2<f32>(0.244384765625, 0.638671875), vec2<f32>(0.370849609375, 0.51953125),
    vec2<f32>(0.496826171875, 0.41552734375), vec2<f32>(0.60205078125, 0.326416015625), vec2<f32>(0.68408203125, 0.25390625), vec2<f32>(0.74609375, 0.197509765625),
    vec2<f32>(0.79052734375, 0.154296875), vec2<f32>(0.822265625, 0.12164306640625), vec2<f32>(0.84326171875, 0.09698486328125), vec2<f32>(0.8564453125, 0.07843017578125),
    vec2<f32>(0.86328125, 0.06439208984375), vec2<f32>(0.86572265625, 0.0537109375), vec2<f32>(0.8642578125, 0.045440673828125), vec2<f32>(0.85986328125, 0.039031982421875),
    vec2<f32>(0.388671875, 0.611328125), vec2<f32>(0.39306640625, 0.6005859375), vec2<f32>(0.412353515625, 0.5458984375), vec2<f32>(0.45654296875, 0.4482421875),
    vec2<f32>(0.52783203125, 0.3525390625), vec2<f32>(0.607421875, 0.27392578125), vec2<f32>(0.6787109375, 0.21142578125), vec2<f32>(0.7333984375, 0.16259765625),
    vec2<f32>(0.77099609375, 0.1253662109375), vec2<f32>(0.79345703125, 0.0972900390625), vec2<f32>(0.80322265625, 0.07623291015625), vec2<f32>(0.8037109375, 0.06036376953125),
    vec2<f32>(0.79638671875, 0.048431396484375), vec2<f32>(0.78564453125, 0.03936767578125), vec2<f32>(0.77197265625, 0.03240966796875), vec2<f32>(0.7548828125, 0.0269775390625),
    vec2<f32>(0.572265625, 0.427490234375), vec2<f32>(0.57373046875, 0.424072265625), vec2<f32>(0.57958984375, 0.403564453125), vec2<f32>(0.591796875, 0.3544921875),
    vec2<f32>(0.6162109375, 0.2880859375), vec2<f32>(0.6552734375, 0.224853515625), vec2<f32>(0.69873046875, 0.172607421875), vec2<f32>(0.7353515625, 0.1318359375),
    vec2<f32>(0.75927734375, 0.10089111328125), vec2<f32>(0.77001953125, 0.07745361328125), vec2<f32>(0.77197265625, 0.0599365234375), vec2<f32>(0.76611328125, 0.046844482421875),
    vec2<f32>(0.751953125, 0.0369873046875), vec2<f32>(0.732421875, 0.029541015625), vec2<f32>(0.70947265625, 0.023834228515625), vec2<f32>(0.68359375, 0.019439697265625),
    vec2<f32>(0.708984375, 0.291015625), vec2<f32>(0.708984375, 0.289794921875), vec2<f32>(0.7099609375, 0.28125), vec2<f32>(0.7099609375, 0.258544921875),
    vec2<f32>(0.71142578125, 0.220458984375), vec2<f32>(0.7197265625, 0.1768798828125), vec2<f32>(0.734375, 0.1370849609375), vec2<f32>(0.748046875, 0.10479736328125),
    vec2<f32>(0.755859375, 0.07989501953125), vec2<f32>(0.759765625, 0.061004638671875), vec2<f32>(0.75341796875, 0.046844482421875), vec2<f32>(0.73876953125, 0.036224365234375),
    vec2<f32>(0.7177734375, 0.02825927734375), vec2<f32>(0.69189453125, 0.0222625732421875), vec2<f32>(0.6611328125, 0.0177001953125), vec2<f32>(0.62841796875, 0.01419830322265625),
    vec2<f32>(0.80810546875, 0.1917724609375), vec2<f32>(0.8076171875, 0.1912841796875), vec2<f32>(0.80615234375, 0.18798828125), vec2<f32>(0.8017578125, 0.1781005859375),
    vec2<f32>(0.79296875, 0.15869140625), vec2<f32>(0.78369140625, 0.1322021484375), vec2<f32>(0.775390625, 0.1048583984375), vec2<f32>(0.7685546875, 0.08111572265625),
    vec2<f32>(0.7646484375, 0.061981201171875), vec2<f32>(0.75537109375, 0.047271728515625), vec2<f32>(0.740234375, 0.036163330078125), vec2<f32>(0.71875, 0.0277557373046875),
    vec2<f32>(0.69091796875, 0.021484375), vec2<f32>(0.658203125, 0.0167388916015625), vec2<f32>(0.6220703125, 0.01316070556640625), vec2<f32>(0.583984375, 0.01041412353515625),
    vec2<f32>(0.87841796875, 0.1217041015625), vec2<f32>(0.8779296875, 0.1217041015625), vec2<f32>(0.875, 0.12060546875), vec2<f32>(0.869140625, 0.116943359375),
    vec2<f32>(0.85693359375, 0.1080322265625), vec2<f32>(0.837890625, 0.09375), vec2<f32>(0.81494140625, 0.076904296875), vec2<f32>(0.7958984375, 0.060699462890625),
    vec2<f32>(0.7763671875, 0.046875), vec2<f32>(0.75634765625, 0.035919189453125), vec2<f32>(0.732421875, 0.0274505615234375), vec2<f32>(0.703125, 0.021026611328125),
    vec2<f32>(0.6689453125, 0.01617431640625), vec2<f32>(0.63037109375, 0.01251220703125), vec2<f32>(0.58935546875, 0.00974273681640625), vec2<f32>(0.54638671875, 0.007633209228515625),
    vec2<f32>(0.92626953125, 0.07379150390625), vec2<f32>(0.92578125, 0.07391357421875), vec2<f32>(0.9228515625, 0.07391357421875), vec2<f32>(0.9169921875, 0.0731201171875),
    vec2<f32>(0.90380859375, 0.06982421875), vec2<f32>(0.88134765625, 0.0631103515625), vec2<f32>(0.85107421875, 0.053802490234375), vec2<f32>(0.8212890625, 0.043701171875),
    vec2<f32>(0.791015625, 0.034393310546875), vec2<f32>(0.76123046875, 0.026611328125), vec2<f32>(0.72802734375, 0.02044677734375), vec2<f32>(0.69189453125, 0.015655517578125),
    vec2<f32>(0.65087890625, 0.0120086669921875), vec2<f32>(0.607421875, 0.00925445556640625), vec2<f32>(0.56103515625, 0.0071563720703125), vec2<f32>(0.51416015625, 0.005565643310546875),
    vec2<f32>(0.95751953125, 0.042327880859375), vec2<f32>(0.95703125, 0.042449951171875), vec2<f32>(0.95458984375, 0.042816162109375), vec2<f32>(0.94921875, 0.043182373046875),
    vec2<f32>(0.93701171875, 0.04266357421875), vec2<f32>(0.9130859375, 0.040252685546875), vec2<f32>(0.8818359375, 0.035797119140625), vec2<f32>(0.8447265625, 0.0301361083984375),
    vec2<f32>(0.80615234375, 0.0243377685546875), vec2<f32>(0.76708984375, 0.0191497802734375), vec2<f32>(0.7265625, 0.01485443115234375), vec2<f32>(0.6826171875, 0.01142120361328125),
    vec2<f32>(0.63623046875, 0.0087738037109375), vec2<f32>(0.5869140625, 0.006740570068359375), vec2<f32>(0.53662109375, 0.005199432373046875), vec2<f32>(0.486083984375, 0.00402069091796875),
    vec2<f32>(0.9775390625, 0.0226287841796875), vec2<f32>(0.97705078125, 0.0227508544921875), vec2<f32>(0.97509765625, 0.023193359375), vec2<f32>(0.9697265625, 0.0239105224609375),
    vec2<f32>(0.95947265625, 0.0244903564453125), vec2<f32>(0.93603515625, 0.0241241455078125), vec2<f32>(0.9052734375, 0.02252197265625), vec2<f32>(0.865234375, 0.0197601318359375),
    vec2<f32>(0.82177734375, 0.016510009765625), vec2<f32>(0.7744140625, 0.0132904052734375), vec2<f32>(0.7265625, 0.01045989990234375), vec2<f32>(0.67626953125, 0.0081329345703125),
    vec2<f32>(0.6240234375, 0.00627899169921875), vec2<f32>(0.56982421875, 0.004825592041015625), vec2<f32>(0.51513671875, 0.0037136077880859375), vec2<f32>(0.46142578125, 0.0028629302978515625),
    vec2<f32>(0.98876953125, 0.01107025146484375), vec2<f32>(0.98876953125, 0.01116180419921875), vec2<f32>(0.98681640625, 0.01151275634765625), vec2<f32>(0.98291015625, 0.01221466064453125),
    vec2<f32>(0.97314453125, 0.01299285888671875), vec2<f32>(0.953125, 0.013519287109375), vec2<f32>(0.9228515625, 0.01328277587890625), vec2<f32>(0.88232421875, 0.01226043701171875),
    vec2<f32>(0.8349609375, 0.01065826416015625), vec2<f32>(0.783203125, 0.00885009765625), vec2<f32>(0.728515625, 0.007114410400390625), vec2<f32>(0.671875, 0.00560760498046875),
    vec2<f32>(0.61376953125, 0.004360198974609375), vec2<f32>(0.5546875, 0.0033721923828125), vec2<f32>(0.496337890625, 0.0025997161865234375), vec2<f32>(0.439453125, 0.0020046234130859375),
    vec2<f32>(0.9951171875, 0.00479888916015625), vec2<f32>(0.9951171875, 0.004863739013671875), vec2<f32>(0.99365234375, 0.005096435546875), vec2<f32>(0.990234375, 0.005603790283203125),
    vec2<f32>(0.9814453125, 0.0063323974609375), vec2<f32>(0.96435546875, 0.006977081298828125), vec2<f32>(0.93603515625, 0.007297515869140625), vec2<f32>(0.896484375, 0.0071258544921875),
    vec2<f32>(0.8466796875, 0.00649261474609375), vec2<f32>(0.79150390625, 0.005596160888671875), vec2<f32>(0.7314453125, 0.004627227783203125), vec2<f32>(0.6689453125, 0.0037174224853515625),
    vec2<f32>(0.60546875, 0.0029296875), vec2<f32>(0.54150390625, 0.00228118896484375), vec2<f32>(0.479248046875, 0.001766204833984375), vec2<f32>(0.419677734375, 0.00136566162109375),
    vec2<f32>(0.998046875, 0.0017604827880859375), vec2<f32>(0.998046875, 0.0017938613891601562), vec2<f32>(0.99658203125, 0.0019292831420898438), vec2<f32>(0.994140625, 0.002239227294921875),
    vec2<f32>(0.986328125, 0.0027294158935546875), vec2<f32>(0.9716796875, 0.0032501220703125), vec2<f32>(0.94580078125, 0.00366973876953125), vec2<f32>(0.90771484375, 0.003818511962890625),
    vec2<f32>(0.8583984375, 0.003681182861328125), vec2<f32>(0.79931640625, 0.0033206939697265625), vec2<f32>(0.7353515625, 0.0028438568115234375), vec2<f32>(0.66748046875, 0.0023441314697265625),
    vec2<f32>(0.5986328125, 0.0018796920776367188), vec2<f32>(0.5302734375, 0.0014829635620117188), vec2<f32>(0.464111328125, 0.0011587142944335938), vec2<f32>(0.402099609375, 0.0008993148803710938),
    vec2<f32>(0.99951171875, 0.0005011558532714844), vec2<f32>(0.99951171875, 0.0005154609680175781), vec2<f32>(0.998046875, 0.000583648681640625), vec2<f32>(0.99658203125, 0.0007505416870117188),
    vec2<f32>(0.9892578125, 0.00101470947265625), vec2<f32>(0.97607421875, 0.001346588134765625), vec2<f32>(0.95263671875, 0.0016527175903320312), vec2<f32>(0.916015625, 0.0018558502197265625),
    vec2<f32>(0.8671875, 0.0019054412841796875), vec2<f32>(0.8076171875, 0.0018167495727539062), vec2<f32>(0.7392578125, 0.001621246337890625), vec2<f32>(0.6669921875, 0.0013799667358398438),
    vec2<f32>(0.59326171875, 0.0011358261108398438), vec2<f32>(0.52001953125, 0.0009121894836425781), vec2<f32>(0.450439453125, 0.0007219314575195312), vec2<f32>(0.385986328125, 0.0005650520324707031),
    vec2<f32>(1.0, 9.316205978393555e-05), vec2<f32>(1.0, 9.78708267211914e-05), vec2<f32>(0.9990234375, 0.00012540817260742188), vec2<f32>(0.9970703125, 0.00019216537475585938),
    vec2<f32>(0.99072265625, 0.0003104209899902344), vec2<f32>(0.97900390625, 0.0004699230194091797), vec2<f32>(0.95751953125, 0.0006470680236816406), vec2<f32>(0.92333984375, 0.0007915496826171875),
    vec2<f32>(0.87548828125, 0.0008769035339355469), vec2<f32>(0.81494140625, 0.0008869171142578125), vec2<f32>(0.744140625, 0.0008325576782226562), vec2<f32>(0.66748046875, 0.0007386207580566406),
    vec2<f32>(0.58837890625, 0.0006265640258789062), vec2<f32>(0.51123046875, 0.0005168914794921875), vec2<f32>(0.438232421875, 0.0004165172576904297), vec2<f32>(0.37109375, 0.0003311634063720703),
    vec2<f32>(1.0, 7.271766662597656e-06), vec2<f32>(1.0, 8.165836334228516e-06), vec2<f32>(0.9990234375, 1.6987323760986328e-05), vec2<f32>(0.99755859375, 3.790855407714844e-05),
    vec2<f32>(0.9921875, 7.593631744384766e-05), vec2<f32>(0.9814453125, 0.00013744831085205078), vec2<f32>(0.96142578125, 0.00020754337310791016), vec2<f32>(0.92919921875, 0.00028014183044433594),
    vec2<f32>(0.8828125, 0.0003345012664794922), vec2<f32>(0.82177734375, 0.00036263465881347656), vec2<f32>(0.7490234375, 0.00036215782165527344), vec2<f32>(0.66845703125, 0.0003380775451660156),
    vec2<f32>(0.58544921875, 0.00029969215393066406), vec2<f32>(0.50390625, 0.00025582313537597656), vec2<f32>(0.427001953125, 0.0002117156982421875), vec2<f32>(0.357666015625, 0.00017201900482177734),
    vec2<f32>(1.0, 0.0), vec2<f32>(1.0, 5.960464477539063e-08), vec2<f32>(0.99951171875, 1.2516975402832031e-06), vec2<f32>(0.99755859375, 5.304813385009766e-06),
    vec2<f32>(0.9931640625, 1.5079975128173828e-05), vec2<f32>(0.98291015625, 2.855062484741211e-05), vec2<f32>(0.96435546875, 4.744529724121094e-05), vec2<f32>(0.93408203125, 6.842613220214844e-05),
    vec2<f32>(0.88916015625, 8.893013000488281e-05), vec2<f32>(0.828125, 0.0001042485237121582), vec2<f32>(0.75390625, 0.00011217594146728516), vec2<f32>(0.67041015625, 0.00011241436004638672),
    vec2<f32>(0.5830078125, 0.00010627508163452148), vec2<f32>(0.4970703125, 9.584426879882812e-05), vec2<f32>(0.4169921875, 8.33272933959961e-05), vec2<f32>(0.34521484375, 7.051229476928711e-05),
);

// E_ss(r, N.v) = dfg.x + dfg.y, bilinear between texel centres, clamped to the edge.
fn fibrefit_gltf_threejs_ess(r: f32, nv: f32) -> f32 {
    var t = FIBREFIT_GLTF_DFG;
    let x = clamp(clamp(r, 0.0, 1.0) * 16.0 - 0.5, 0.0, 15.0);
    let y = clamp(clamp(nv, 0.0, 1.0) * 16.0 - 0.5, 0.0, 15.0);
    let i = min(u32(floor(x)), 14u);
    let j = min(u32(floor(y)), 14u);
    let fx = x - f32(i);
    let fy = y - f32(j);
    let lo = mix(t[16u * j + i], t[16u * j + i + 1u], fx);
    let hi = mix(t[16u * (j + 1u) + i], t[16u * (j + 1u) + i + 1u], fx);
    let d = mix(lo, hi, fy);
    return d.x + d.y;
}

// IBLSheenBRDF: three.js's fitted exponential for the Charlie sheen's directional albedo.
fn fibrefit_gltf_threejs_sheen_e(mu: f32, r: f32) -> f32 {
    let inv = 1.0 / (r + 0.1);
    let a = -1.9362 + 1.0678 * r + 0.4573 * r * r - 0.8469 * inv;
    let b = -0.6014 + 0.5538 * r - 0.4670 * r * r - 0.1255 * inv;
    return clamp(exp(a * clamp(mu, 0.0, 1.0) + b), 0.0, 1.0);
}

fn fibrefit_gltf_threejs(l: vec3<f32>, v: vec3<f32>, p: FibrefitParams) -> vec4<f32> {
    let g0 = p.material[0];
    let g1 = p.material[1];
    let m = g0.x;
    let at = g0.y;
    let ab = g0.z;
    let sp = g0.w;
    let h = normalize(l + v);
    let vh = clamp(dot(v, h), 0.0, 1.0);
    let e = exp2((-5.55473 * vh - 6.98316) * vh);
    let f0d = min(g1.x, 1.0) * sp;
    let f90 = sp + (1.0 - sp) * m;
    let fd = f0d * (1.0 - e) + f90 * e;
    let pr = (1.0 - m) * f0d * (1.0 - e) + f90 * e;
    // at = r^2 along t, the floored roughness r
    let gm = 1.0 / fibrefit_gltf_threejs_ess(sqrt(at), clamp(v.z, 0.0, 1.0)) - 1.0;
    let rr = 1.0 + (1.0 - m) * f0d * gm;
    let a2 = at * ab;
    let f = vec3<f32>(ab * h.x, at * h.y, a2 * h.z);
    let w2 = a2 / dot(f, f);
    var d = 0.0;
    if (h.z > 0.0) {
        d = a2 * w2 * w2 * FIBREFIT_FRAC_1_PI;
    }
    let vis_v = l.z * length(vec3<f32>(at * v.x, ab * v.y, v.z));
    let vis_l = v.z * length(vec3<f32>(at * l.x, ab * l.y, l.z));
    let s = d * 0.5 / (vis_v + vis_l);
    var k = 1.0;
    var sheen = 0.0;
    if (g1.y > 0.0) {
        let a = g1.z;
        let rho = sqrt(a);
        k = 1.0 - g1.y * max(fibrefit_gltf_threejs_sheen_e(v.z, rho), fibrefit_gltf_threejs_sheen_e(l.z, rho));
        let nh = clamp(h.z, 0.0, 1.0);
        let sin2 = max(1.0 - nh * nh, 0.0078125);
        let dc = (2.0 + 1.0 / a) * exp(0.5 / a * log(sin2)) / (2.0 * FIBREFIT_PI);
        let vn = clamp(1.0 / (4.0 * (l.z + v.z - l.z * v.z)), 0.0, 1.0);
        sheen = g1.y * dc * vn;
    }
    let diffuse = (1.0 - m) * (1.0 - fd) * FIBREFIT_FRAC_1_PI + s * m * (pr * gm + (1.0 - e) * rr);
    return vec4<f32>(k * diffuse, k * s * pr * rr + sheen, k * s * m * m * gm * (1.0 - e), 0.0);
}

// @section cross_section
// The periodic fibre cross-section (MODEL.md section 2; src/model/cross_section.rs): exact
// visible-and-lit arcs of the two fibres of a period, closed-form diffuse, Gauss-Legendre lobe.

// A direction projected into the cross-section plane.
struct FibrefitProj {
    alpha: f32,
    s: f32,
    c: f32,
    len: f32,
    tn: f32,
    sec: f32,
}

fn fibrefit_project(w: vec3<f32>) -> FibrefitProj {
    let len = sqrt(w.y * w.y + w.z * w.z);
    return FibrefitProj(fibrefit_atan2_right(w.y, w.z), w.y / len, w.z / len, len, w.y / w.z, len / w.z);
}

// Three intervals sorted by their start.
fn fibrefit_sort3(v: array<vec2<f32>, 3>) -> array<vec2<f32>, 3> {
    var x = v;
    for (var i = 0u; i < 2u; i++) {
        for (var j = 0u; j < 2u - i; j++) {
            if (x[j + 1u].x < x[j].x) {
                let y = x[j];
                x[j] = x[j + 1u];
                x[j + 1u] = y;
            }
        }
    }
    return x;
}

// The gaps, in s = sin(th - alpha), that every occluder of the infinite pattern leaves on one
// fibre's front arc seen along a direction (sin sa, cos ca of its angle); `other_row` is the
// other row's axis height above this fibre's (+H even, -H odd). Up to four gaps.
struct FibrefitGaps {
    e: array<vec2<f32>, 4>,
    n: u32,
}

fn fibrefit_gaps(sa: f32, ca: f32, step: f32, other_row: f32) -> FibrefitGaps {
    let none = vec2<f32>(3.0, 3.0);
    var sh = array<vec2<f32>, 3>(none, none, none);
    let ds = 2.0 * step * ca;
    let da = 2.0 * step * sa;
    // own row: the nearest member ahead shadows (ds - 1, ds + 1) or its mirror; farther ones
    // continue the run past +-1 while ds < 2
    if (ds < 2.0 && da != 0.0) {
        if (da > 0.0) {
            sh[0] = vec2<f32>(ds - 1.0, 1.0);
        } else {
            sh[0] = vec2<f32>(-1.0, 1.0 - ds);
        }
    }
    // other row: members m at s0 + m ds, a0 + m da
    let s0 = step * ca - other_row * sa;
    let a0 = step * sa + other_row * ca;
    var lo = ceil((-2.0 - s0) / ds);
    var hi = floor((2.0 - s0) / ds);
    if (da > 0.0) {
        lo = max(lo, floor(-a0 / da) + 1.0);
    }
    if (da < 0.0) {
        hi = min(hi, ceil(-a0 / da) - 1.0);
    }
    if ((da != 0.0 || a0 > 0.0) && lo <= hi) {
        let s = s0 + lo * ds;
        if (ds <= 2.0) {
            sh[1] = vec2<f32>(s - 1.0, s0 + hi * ds + 1.0);
        } else {
            sh[1] = vec2<f32>(s - 1.0, s + 1.0);
            if (hi > lo) {
                sh[2] = vec2<f32>(s + ds - 1.0, s + ds + 1.0);
            }
        }
    }
    // sort by start, then the complement of the union in (-1, 1)
    sh = fibrefit_sort3(sh);
    var out: FibrefitGaps;
    out.n = 0u;
    var cursor = -1.0;
    for (var k = 0u; k < 3u; k++) {
        let a = min(sh[k].x, 1.0);
        if (a > cursor) {
            out.e[out.n] = vec2<f32>(cursor, a);
            out.n++;
        }
        cursor = max(cursor, sh[k].y);
    }
    if (1.0 > cursor) {
        out.e[out.n] = vec2<f32>(cursor, 1.0);
        out.n++;
    }
    return out;
}

// Integral over [t0, t1] of cos(th - a) cos(th - b), long or short form (no cancellation next
// to the terminator).
fn fibrefit_diffuse_kernel(t0: f32, t1: f32, a: f32, b: f32, cos_ab: f32) -> f32 {
    let d = t1 - t0;
    let u = t0 + t1 - a - b;
    if (d > 0.5) {
        return 0.5 * (d * cos_ab + cos(u) * sin(d));
    }
    let m = 0.5 * (t0 + t1);
    let d2 = d * d;
    let d_minus_sin = d * d2 * (1.0 / 6.0 - d2 * (1.0 / 120.0 - d2 * (1.0 / 5040.0 - d2 / 362880.0)));
    return max(d * cos(m - a) * cos(m - b) - 0.5 * cos(u) * d_minus_sin, 0.0);
}

fn fibrefit_wrap(x: f32, p: f32, inv_p: f32) -> f32 {
    let r = x - p * floor(x * inv_p);
    if (r >= p || r < 0.0) {
        return 0.0;
    }
    return r;
}

// Fraction of the substrate strip of one period seen along v and lit along l.
fn fibrefit_substrate(l: FibrefitProj, v: FibrefitProj, step: f32, rise: f32) -> f32 {
    let p = 2.0 * step;
    let inv_p = 1.0 / p;
    let wl = 2.0 * l.sec;
    let wv = 2.0 * v.sec;
    if (max(wl, wv) >= p) {
        return 0.0;
    }
    let a0 = vec2<f32>(-l.tn - l.sec, wl);
    let a1 = vec2<f32>(step - (1.0 + rise) * l.tn - l.sec, wl);
    let a2 = vec2<f32>(-v.tn - v.sec, wv);
    let a3 = vec2<f32>(step - (1.0 + rise) * v.tn - v.sec, wv);
    var origin = a2.x;
    var width = wv;
    var first = a0;
    var second = a1;
    if (wl >= wv) {
        origin = a0.x;
        width = wl;
        first = a1;
        second = a2;
    }
    var x = array<vec2<f32>, 3>(first, second, a3);
    for (var k = 0u; k < 3u; k++) {
        let r = fibrefit_wrap(x[k].x - origin, p, inv_p);
        x[k] = vec2<f32>(r, min(r + x[k].y, p));
    }
    x = fibrefit_sort3(x);
    var cursor = width;
    var open = 0.0;
    for (var k = 0u; k < 3u; k++) {
        open += max(x[k].x - cursor, 0.0);
        cursor = max(cursor, x[k].y);
    }
    open += max(p - cursor, 0.0);
    return open * inv_p;
}

// Everything of a light/view pair that does not depend on the pattern.
struct FibrefitPair {
    l: FibrefitProj,
    v: FibrefitProj,
    cos_lv: f32,
    cos_delta: f32,
    // 1 + cos_delta without cancellation (l and v opposite in the cross-section plane)
    opc: f32,
    sigma: f32,
    k2: f32,
    // the lobe window [x, y] in th; z > 0 when there is one
    window: vec3<f32>,
}

fn fibrefit_pair(l: vec3<f32>, v: vec3<f32>, lobe_floor: f32) -> FibrefitPair {
    let lp = fibrefit_project(l);
    let vp = fibrefit_project(v);
    let cos_lv = dot(l, v);
    let cos_delta = lp.c * vp.c + lp.s * vp.s;
    // 1 + cos(al - av) = ((lc + vc)^2 + (ls + vs)^2) / 2 for unit projections
    let opc = 0.5 * ((lp.c + vp.c) * (lp.c + vp.c) + (lp.s + vp.s) * (lp.s + vp.s));
    let k = lp.len * vp.len;
    let peak = k * opc - cos_lv;
    let c = (lobe_floor * peak + cos_lv) / k - cos_delta;
    let cc = clamp(c, -1.0, 1.0);
    let half = fibrefit_atan2_right(sqrt(1.0 - cc), sqrt(1.0 + cc));
    let sigma = lp.alpha + vp.alpha;
    var has = 0.0;
    if (peak > 0.0 && k > 0.0 && c < 1.0) {
        has = 1.0;
    }
    return FibrefitPair(lp, vp, cos_lv, cos_delta, opc, sigma, 2.0 * k,
        vec3<f32>(0.5 * sigma - half, 0.5 * sigma + half, has));
}

// The lobe integral over [a, b]: (b - a)/2 sum w max(0, r.v)^e cc at the Gauss-Legendre nodes.
fn fibrefit_lobe(a: f32, b: f32, sp: FibrefitPair, exponent: f32) -> f32 {
    let half = 0.5 * (b - a);
    let tms = (a + b) - sp.sigma;
    var nodes = FIBREFIT_GAUSS_LEGENDRE;
    var acc = 0.0;
    for (var i = 0u; i < FIBREFIT_QUADRATURE_ORDER; i++) {
        let u = 2.0 * half * nodes[i].x + tms;
        // (cos_delta + cos u) / 2 as ((1 + cos_delta) - 2 sin^2(u/2)) / 2: no cancellation
        // when l and v are opposite in the cross-section plane (grazing from both sides)
        let h = sin(0.5 * u);
        let cc = 0.5 * (sp.opc - 2.0 * h * h);
        let rv = sp.k2 * cc - sp.cos_lv;
        if (rv > 0.0) {
            acc += nodes[i].y * fibrefit_pow(rv, exponent) * cc;
        }
    }
    return half * acc;
}

// (diffuse, specular, substrate) of one pattern of spacing d and odd-fibre height H, weight w.
fn fibrefit_pattern(sp: FibrefitPair, spacing: f32, height: f32, weight: f32, exponent: f32) -> vec3<f32> {
    let phi = min(fibrefit_asin(clamp(height / spacing, 0.0, 1.0)), fibrefit_acos_positive(1.0 / spacing));
    let step = spacing * cos(phi);
    let rise = spacing * sin(phi);
    let denom = 2.0 * step * sp.l.c * sp.v.c;
    if (!(denom > 0.0)) {
        return vec3<f32>(0.0);
    }
    let norm = (exponent + 2.0) / (2.0 * FIBREFIT_PI);
    var diffuse = 0.0;
    var specular = 0.0;
    var fibres = 2u;
    var count = 1.0;
    if (rise == 0.0) {
        // the odd row is the even row moved by one step: one fibre, counted twice
        fibres = 1u;
        count = 2.0;
    }
    for (var f = 0u; f < fibres; f++) {
        var other = rise;
        if (f == 1u) {
            other = -rise;
        }
        let seen = fibrefit_gaps(sp.v.s, sp.v.c, step, other);
        let lit = fibrefit_gaps(sp.l.s, sp.l.c, step, other);
        let factor = weight * count * norm / denom;
        var i = 0u;
        var j = 0u;
        loop {
            if (i >= seen.n || j >= lit.n) {
                break;
            }
            let xa = sp.v.alpha + fibrefit_asin(seen.e[i].x);
            let xb = sp.v.alpha + fibrefit_asin(seen.e[i].y);
            let ya = sp.l.alpha + fibrefit_asin(lit.e[j].x);
            let yb = sp.l.alpha + fibrefit_asin(lit.e[j].y);
            let lo = max(xa, ya);
            let hi = min(xb, yb);
            if (hi > lo) {
                diffuse += count * fibrefit_diffuse_kernel(lo, hi, sp.l.alpha, sp.v.alpha, sp.cos_delta);
                if (sp.window.z > 0.0) {
                    let wa = max(lo, sp.window.x);
                    let wb = min(hi, sp.window.y);
                    if (wb > wa) {
                        specular += factor * fibrefit_lobe(wa, wb, sp, exponent);
                    }
                }
            }
            if (xb < yb) {
                i++;
            } else {
                j++;
            }
        }
    }
    let substrate = fibrefit_substrate(sp.l, sp.v, step, rise);
    return vec3<f32>(weight * FIBREFIT_FRAC_1_PI * diffuse / denom, specular,
        weight * FIBREFIT_FRAC_1_PI * substrate);
}

// @section principled
// Blender 5.0's Principled BSDF as Cycles evaluates it, opaque dielectric subset
// (src/model/rungs/principled.rs names the Cycles kernel function each line follows): the sheen
// (Zeltner's LTC from Cycles' table), the dielectric GGX with the remapped real Fresnel and the
// multiple-scattering energy scale, the base colour's Lambertian diffuse, each lower layer
// weighted by closure_layering_weight. Not reciprocal: v is Cycles' wi (towards the camera).
// x the base colour's column, y the layers' (specular and sheen). p.material: [0] GGX alpha
// across the fibres (Blender's tangent, the fibres' b), alpha along them (t), E_avg, 1 with a
// specular closure; [1] eta, F0 (tinted), F0 of eta, Fss; [2] x the sheen weight; then Cycles'
// tables at this material by cos theta_v, read as lookup_table_read reads (clamped, linear
// between nodes): [3 + k] at k / 31, k = 0..31: GGX E, the sheen LTC's a, b and albedo;
// [35..39) ggx_gen_schlick_ior_s at k / 15, k = 0..15, four a row.

// closure_layering_weight for grey weights.
fn fibrefit_principled_layering(albedo: f32, weight: f32) -> f32 {
    var ratio = 0.0;
    if (weight != 0.0) {
        ratio = albedo / weight;
    }
    return weight * clamp(1.0 - ratio, 0.0, 1.0);
}

// fresnel_dielectric: unpolarised Fresnel reflectance for relative IOR eta.
fn fibrefit_principled_fresnel(cos_i: f32, eta: f32) -> f32 {
    let ect = eta * eta - (1.0 - cos_i * cos_i);
    if (ect <= 0.0) {
        return 1.0;
    }
    let ci = abs(cos_i);
    let ct = -sqrt(ect) / eta;
    let rs = (ci + eta * ct) / (ci - eta * ct);
    let rp = (ct + eta * ci) / (eta * ci - ct);
    return 0.5 * (rs * rs + rp * rp);
}

// The single-scattering GGX BRDF with the remapped Fresnel: F D G2 / (4 cos theta_v cos theta_l).
fn fibrefit_principled_ggx(l: vec3<f32>, v: vec3<f32>, m0: vec4<f32>, m1: vec4<f32>) -> f32 {
    let hs = l + v;
    let len = length(hs);
    if (len == 0.0) {
        return 0.0;
    }
    let h = hs / len;
    let f_real = fibrefit_principled_fresnel(dot(h, v), m1.x);
    let f = m1.y + (1.0 - m1.y) * clamp((f_real - m1.z) / (1.0 - m1.z), 0.0, 1.0);
    // bsdf_aniso_D: x along Blender's tangent (b), y along the fibres
    let ax = m0.x;
    let ay = m0.y;
    let hx = h.y / ax;
    let hy = h.x / ay;
    let q = hx * hx + hy * hy + h.z * h.z;
    let d = FIBREFIT_FRAC_1_PI / (ax * ay * q * q);
    let sl = ((ax * l.y) * (ax * l.y) + (ay * l.x) * (ay * l.x)) / (l.z * l.z);
    let sv = ((ax * v.y) * (ax * v.y) + (ay * v.x) * (ay * v.x)) / (v.z * v.z);
    let g2 = 1.0 / (1.0 + 0.5 * (sqrt(1.0 + sl) - 1.0) + 0.5 * (sqrt(1.0 + sv) - 1.0));
    return f * d * g2 / (4.0 * v.z * l.z);
}

fn fibrefit_principled(l: vec3<f32>, v: vec3<f32>, p: FibrefitParams) -> vec4<f32> {
    var m = p.material;
    let m0 = m[0];
    let m1 = m[1];
    // the tables at cos theta_v: (GGX E, sheen a, b, albedo) and the specular's albedo table
    let y = clamp(v.z, 0.0, 1.0) * 31.0;
    let i = min(u32(y), 31u);
    let t = y - f32(i);
    var tab = m[3u + i];
    if (t != 0.0) {
        tab = (1.0 - t) * tab + t * m[3u + min(i + 1u, 31u)];
    }
    let ys = clamp(v.z, 0.0, 1.0) * 15.0;
    let k = min(u32(ys), 15u);
    let ts = ys - f32(k);
    var albedo_s = m[35u + k / 4u][k % 4u];
    if (ts != 0.0) {
        let k1 = min(k + 1u, 15u);
        albedo_s = (1.0 - ts) * albedo_s + ts * m[35u + k1 / 4u][k1 % 4u];
    }
    // 1. the sheen (bsdf_sheen_setup, bsdf_sheen_eval)
    var weight = 1.0;
    var sheen = 0.0;
    let a = tab.y;
    if (m[2].x > 1e-5 && abs(a) >= 1e-5 && tab.w >= 1e-5) {
        let w = m[2].x * tab.w;
        // the frame of N and the view: B = N x v, T = B x N; at normal view the skew b is
        // dropped (Cycles' frame there is the world's)
        var b = tab.z;
        var lo = l;
        let bl = sqrt(v.y * v.y + v.x * v.x);
        if (bl > 0.0) {
            let bx = -v.y / bl;
            let by = v.x / bl;
            lo = vec3<f32>(l.x * by - l.y * bx, l.x * bx + l.y * by, l.z);
        } else {
            b = 0.0;
        }
        let x = a * lo.x + b * lo.z;
        let yy = a * lo.y;
        let len2 = x * x + yy * yy + lo.z * lo.z;
        if (lo.z > 0.0) {
            sheen = w * FIBREFIT_FRAC_1_PI * (a / len2) * (a / len2);
        }
        weight = fibrefit_principled_layering(w, weight);
    }
    // 2. the dielectric specular, with microfacet_ggx_preserve_energy
    var specular = 0.0;
    if (m0.w > 0.5) {
        let e = tab.x;
        let missing = (1.0 - e) / e;
        let energy_scale = 1.0 + missing;
        var darkening = 1.0;
        if (m1.w != 1.0) {
            let fms = m1.w * m0.z / (1.0 - m1.w * (1.0 - m0.z));
            darkening = (1.0 + fms * missing) / energy_scale;
        }
        let w = weight * darkening;
        if (m0.x * m0.y > 2e-10) {
            specular = w * energy_scale * fibrefit_principled_ggx(l, v, m0, m1);
        }
        weight = fibrefit_principled_layering(w * (m1.y + (1.0 - m1.y) * albedo_s), weight);
    }
    // 3. the base colour's Lambertian diffuse
    return vec4<f32>(weight * FIBREFIT_FRAC_1_PI, specular + sheen, 0.0, 0.0);
}

// @section openpbr
// OpenPBR Surface as MaterialX 1.39 implements it, opaque dielectric subset
// (src/model/rungs/openpbr.rs names the MaterialX node or GLSL function each part follows): the
// fuzz (mx_sheen_bsdf, Zeltner's LTC from its rational fits) over the dielectric GGX with Turquin's
// energy compensation from the analytic albedo fit, over the Lambertian base colour, each layer
// below scaled by the throughput 1 - albedo x weight above it. Not reciprocal: v is MaterialX's
// V (towards the camera). x the base colour's column, y the layers' (specular and fuzz).
// p.material: [0] GGX alpha across the fibres (OpenPBR's tangent, the fibres' b), alpha along
// them (t), their geometric mean, the modulated eta; [1] x its F0, y the fuzz weight, z the fuzz
// roughness (clamped to [0.01, 1]).
const FIBREFIT_OPENPBR_EPS: f32 = 1e-8;

// mx_fresnel_dielectric.
fn fibrefit_openpbr_fresnel(c: f32, ior: f32) -> f32 {
    let g2 = ior * ior + c * c - 1.0;
    if (g2 < 0.0) {
        return 1.0;
    }
    let g = sqrt(g2);
    let a = (g - c) / (g + c);
    let b = ((g + c) * c - 1.0) / ((g - c) * c + 1.0);
    return 0.5 * a * a * (1.0 + b * b);
}

// mx_ggx_dir_albedo_analytic's (A, B): the GGX directional albedo is F0 A + F90 B.
fn fibrefit_openpbr_albedo_ab(x: f32, y: f32) -> vec2<f32> {
    let x2 = x * x;
    let y2 = y * y;
    let r = vec4<f32>(0.1003, 0.9345, 1.0, 1.0)
        + vec4<f32>(-0.6303, -2.323, -1.765, 0.2281) * x
        + vec4<f32>(9.748, 2.229, 8.263, 15.94) * y
        + vec4<f32>(-2.038, -3.748, 11.53, -55.83) * (x * y)
        + vec4<f32>(29.34, 1.424, 28.96, 13.08) * x2
        + vec4<f32>(-8.245, -0.7684, -7.507, 41.26) * y2
        + vec4<f32>(-26.44, 1.436, -36.11, 54.9) * (x2 * y)
        + vec4<f32>(19.99, 0.2913, 15.86, 300.2) * (x * y2)
        + vec4<f32>(-5.448, 0.6286, 33.37, -285.1) * (x2 * y2);
    return clamp(vec2<f32>(r.x / r.z, r.y / r.w), vec2<f32>(0.0), vec2<f32>(1.0));
}

// mx_zeltner_sheen_dir_albedo.
fn fibrefit_openpbr_sheen_albedo(x: f32, y: f32) -> f32 {
    let s = y * (0.0206607 + 1.58491 * y) / (0.0379424 + y * (1.32227 + y));
    let m = y * (-0.193854 + y * (-1.14885 + y * (1.7932 - 0.95943 * y * y))) / (0.046391 + y);
    let o = y * (0.000654023 + (-0.0207818 + 0.119681 * y) * y) / (1.26264 + y * (-1.92021 + y));
    let z = (x - m) / s;
    return exp(-0.5 * z * z) / (s * 2.50662827463) + o;
}

// mx_zeltner_sheen_brdf: the LTC's density of l (the cosine included) in the frame of N and v.
fn fibrefit_openpbr_sheen(l: vec3<f32>, v: vec3<f32>, n_v: f32, r: f32) -> f32 {
    let a_inv = (2.58126 * n_v + 0.813703 * r) * r / (1.0 + 0.310327 * n_v * n_v + 2.60994 * n_v * r);
    let b_inv = sqrt(1.0 - n_v) * (r - 1.0) * r * r * r
        / (0.0000254053 + 1.71228 * n_v - 1.71506 * n_v * r + 1.34174 * r * r);
    // mx_orthonormal_basis_ltc: X = V - N (N.V) normalised, Y = N x X
    let xs = vec3<f32>(v.x, v.y, v.z - n_v);
    let len2 = dot(xs, xs);
    var w = l;
    if (len2 > 0.0) {
        let x = xs / sqrt(len2);
        w = vec3<f32>(dot(l, x), l.y * x.x - l.x * x.y, l.z);
    }
    let wo = vec3<f32>(a_inv * w.x + b_inv * w.z, a_inv * w.y, w.z);
    let q = a_inv / dot(wo, wo);
    return max(wo.z, 0.0) * FIBREFIT_FRAC_1_PI * q * q;
}

fn fibrefit_openpbr(l: vec3<f32>, v: vec3<f32>, p: FibrefitParams) -> vec4<f32> {
    let m0 = p.material[0];
    let m1 = p.material[1];
    let n_v = clamp(v.z, FIBREFIT_OPENPBR_EPS, 1.0);
    let n_l = clamp(l.z, FIBREFIT_OPENPBR_EPS, 1.0);
    // fuzz_bsdf: response and throughput
    var fuzz = 0.0;
    var t_fuzz = 1.0;
    if (!(m1.y < FIBREFIT_OPENPBR_EPS)) {
        let albedo = fibrefit_openpbr_sheen_albedo(n_v, m1.z);
        fuzz = albedo * fibrefit_openpbr_sheen(l, v, n_v, m1.z) * m1.y;
        t_fuzz = 1.0 - albedo * m1.y;
    }
    // dielectric_reflection (mx_dielectric_bsdf, reflection): response and throughput
    let hs = l + v;
    let len = length(hs);
    var h = vec3<f32>(0.0, 0.0, 1.0);
    if (len > 0.0) {
        h = hs / len;
    }
    let f = fibrefit_openpbr_fresnel(clamp(dot(h, v), FIBREFIT_OPENPBR_EPS, 1.0), m0.w);
    // mx_ggx_NDF with X the tangent (b, across the fibres), Y = N x X (-t)
    let hx = h.y / m0.x;
    let hy = -h.x / m0.y;
    let q = hx * hx + hy * hy + h.z * h.z;
    let d = 1.0 / (FIBREFIT_PI * m0.x * m0.y * q * q);
    // mx_ggx_smith_G2 at the average alpha
    let a2 = m0.z * m0.z;
    let lambda_l = sqrt(a2 + (1.0 - a2) * n_l * n_l);
    let lambda_v = sqrt(a2 + (1.0 - a2) * n_v * n_v);
    let g = 2.0 * n_l * n_v / (lambda_l * n_v + lambda_v * n_l);
    let ab = fibrefit_openpbr_albedo_ab(n_v, m0.z);
    let ess = ab.x + ab.y;
    let comp = 1.0 + f * (1.0 - ess) / ess;
    let spec = d * f * g * comp / (4.0 * n_v);
    let t_spec = 1.0 - (m1.x * ab.x + ab.y) * comp;
    return vec4<f32>(t_fuzz * t_spec * FIBREFIT_FRAC_1_PI, (t_fuzz * spec + fuzz) / n_l, 0.0, 0.0);
}
