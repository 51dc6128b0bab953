"""The fitted model in Dr.Jit's vectorised operations, for the Mitsuba plugin's fast mode.

The numbers are the library's own: ``fibrefit.export(result, shader="wgsl")`` bakes a result's
parameters into the WGSL function ``fibrefit_params()`` (albedos, the fuzz layer, the GGX alphas,
the sheen's albedo table, the spread's nodes, ...); :func:`parse_wgsl` reads them back, and
:class:`DrJitModel` evaluates the same equations as that shader (``src/export/shader/
fibrefit.wgsl``, which ``fibrefit export --check`` proves equal to the Rust model) with Dr.Jit
arrays, so a Mitsuba render compiles them into its kernels instead of calling back into numpy.

Ported rungs: ``lambert``, ``hast-diffuse``, ``max-normal``, ``ward``, the renderers' materials
``principled`` and ``openpbr`` (Cycles' tables read from the shader), ``gltf`` (its
``khronos`` variant) and the cross-section rungs ``poulin-fournier`` and ``varying-topology``
(the shader's ``cross_section`` section: the pair, the occlusion gaps, the closed-form diffuse,
the Gauss-Legendre lobe, the substrate strip; the height histogram's nodes), each with the
shader's common parts (the fibre-direction spread's nodes, Fresnel, the fuzz layer). The
cross-section rungs' nested loops (spread nodes, height nodes and fibres, the merge of the seen
and lit arcs) are Dr.Jit symbolic loops, so the kernel holds each body once whatever the node
counts. The ``gltf`` rung's ``threejs`` variant is ported too (the ``gltf_threejs`` section,
three.js's DFG table read from the shader). The ``reference`` has no shader and is not ported:
:func:`unsupported_reason` says why, and the plugin keeps its exact path for it.
"""

from __future__ import annotations

import math
import re
from typing import Any, Dict, List, Optional, Tuple

import numpy as np

#: rung bodies of the WGSL's ``fibrefit_rung`` that are ported here, by the function they call
PORTED = {
    "    return fibrefit_lambert(l, v);": "lambert",
    "    return fibrefit_hast_diffuse(l, v);": "hast_diffuse",
    "    return fibrefit_max_normal(l, v, p.shape.x);": "max_normal",
    "    return fibrefit_ward(l, v, p.extra.x, p.extra.y);": "ward",
    "    return fibrefit_gltf(l, v, p);": "gltf",
    "    return fibrefit_principled(l, v, p);": "principled",
    "    return fibrefit_openpbr(l, v, p);": "openpbr",
    "    let sp = fibrefit_pair(l, v, p.shape.w);\n"
    "    let b = fibrefit_pattern(sp, p.shape.y, 0.0, 1.0, p.shape.x);\n"
    "    return vec4<f32>(b, 0.0);": "poulin_fournier",
    "    let sp = fibrefit_pair(l, v, p.shape.w);\n"
    "    if (at_height) {\n"
    "        return vec4<f32>(fibrefit_pattern(sp, p.shape.y, height, 1.0, p.shape.x), 0.0);\n"
    "    }\n"
    "    var heights = p.heights;\n"
    "    var b = vec3<f32>(0.0);\n"
    "    for (var k = 0u; k < FIBREFIT_HEIGHT_NODES; k++) {\n"
    "        b += fibrefit_pattern(sp, p.shape.y, heights[k].x, heights[k].y, p.shape.x);\n"
    "    }\n"
    "    return vec4<f32>(b, 0.0);": "varying_topology",
}

#: the rungs evaluated by the shader's ``cross_section`` section
CROSS_SECTION = ("poulin_fournier", "varying_topology")

_VEC4 = re.compile(r"vec4<f32>\(([^()]*)\)")
_VEC2 = re.compile(r"vec2<f32>\(([^()]*)\)")
_GAUSS = re.compile(r"const FIBREFIT_GAUSS_LEGENDRE = array<vec2<f32>, \d+>\((.*?)\);", re.S)
_CONST = re.compile(r"^const (FIBREFIT_\w+): (?:f32|u32) = ([-+0-9.eE]+)u?;", re.M)


def parse_wgsl(src: str) -> Dict[str, Any]:
    """The parameters a fibrefit WGSL export bakes in: ``rung`` (the ported rung's name, or None),
    ``rung_body``, ``consts`` (the FIBREFIT_ constants), and the ``FibrefitParams`` members as
    float64 arrays: ``kd``, ``ks``, ``substrate``, ``fuzz`` (rgb), ``shape``, ``extra``,
    ``topology`` (4), ``gltf`` (the ``material`` member, rows x 4), ``heights``, ``spread`` (nodes x 4); and the
    specular lobe's Gauss-Legendre rule ``gauss_legendre`` (order x 2: node, weight); for the gltf
    rung's threejs variant, three.js's DFG table ``gltf_dfg`` (256 x 2: scale, bias)."""
    consts = {k: float(v) for k, v in _CONST.findall(src)}
    m = re.search(r"fn fibrefit_params\(\) -> FibrefitParams \{(.*?)\n\}", src, re.S)
    if m is None:
        raise ValueError("no fibrefit_params() in the shader")
    rows = [np.array([float(x) for x in r.split(",")], dtype=np.float64) for r in _VEC4.findall(m.group(1))]
    # the renderer material's rows (FIBREFIT_GLTF_ROWS before the member was shared by the
    # renderer-material rungs)
    n_gltf = int(consts.get("FIBREFIT_MATERIAL_ROWS", consts.get("FIBREFIT_GLTF_ROWS", 0)))
    n_h = int(consts["FIBREFIT_HEIGHT_NODES"])
    n_s = int(consts["FIBREFIT_SPREAD_NODES"])
    if len(rows) != 7 + n_gltf + n_h + n_s:
        raise ValueError(f"fibrefit_params(): {len(rows)} rows, expected {7 + n_gltf + n_h + n_s}")
    body = re.search(r"fn fibrefit_rung\([^)]*\) -> vec4<f32> \{\n(.*?)\n\}", src, re.S)
    rung_body = body.group(1) if body else ""
    p: Dict[str, Any] = {
        "consts": consts,
        "rung_body": rung_body,
        "rung": PORTED.get(rung_body),
        "kd": rows[0][:3],
        "ks": rows[1][:3],
        "substrate": rows[2][:3],
        "fuzz": rows[3][:3],
        "shape": rows[4],
        "extra": rows[5],
        "topology": rows[6],
        "gltf": np.array(rows[7 : 7 + n_gltf]),
        "heights": np.array(rows[7 + n_gltf : 7 + n_gltf + n_h]),
        "spread": np.array(rows[7 + n_gltf + n_h :]),
    }
    dfg = re.search(r"const FIBREFIT_GLTF_DFG = array<vec2<f32>, 256>\((.*?)\);", src, re.S)
    if dfg:
        p["gltf_dfg"] = np.array([[float(x) for x in r.split(",")] for r in _VEC2.findall(dfg.group(1))], dtype=np.float64)
    g = _GAUSS.search(src)
    gl = [[float(x) for x in r.split(",")] for r in _VEC2.findall(g.group(1))] if g else []
    p["gauss_legendre"] = np.array(gl, dtype=np.float64).reshape(-1, 2)
    p["correction"] = _parse_correction(src, consts)
    return p


_VEC3 = re.compile(r"vec3<f32>\(([^()]*)\)")
_UVEC3 = re.compile(r"vec3<u32>\(([^()]*)\)")


def _parse_correction(src: str, consts: Dict[str, float]) -> Optional[Dict[str, Any]]:
    """The result's smooth correction the shader bakes in (``fibrefit_correction``): ``degree``,
    ``terms`` ((a, b, c) per term), ``coefficients`` (terms x 3), ``cos_range``, ``log_lo``,
    ``log_hi``; None without one."""
    if "FIBREFIT_CORRECTION_TERMS" not in consts:
        return None

    def block(name: str) -> str:
        m = re.search(rf"const {name}(?:: [^=]+)? = (.*?);", src, re.S)
        if m is None:
            raise ValueError(f"the shader's correction has no {name}")
        return m.group(1)

    terms = [tuple(int(x.strip().rstrip("u")) for x in r.split(",")) for r in _UVEC3.findall(block("FIBREFIT_CORRECTION_TERM"))]
    coeff = [[float(x) for x in r.split(",")] for r in _VEC3.findall(block("FIBREFIT_CORRECTION_COEFF"))]
    vec = lambda name, rx: [float(x) for x in rx.findall(block(name))[0].split(",")]  # noqa: E731
    n = int(consts["FIBREFIT_CORRECTION_TERMS"])
    if len(terms) != n or len(coeff) != n:
        raise ValueError(f"the shader's correction: {len(terms)} terms and {len(coeff)} coefficients, expected {n}")
    return {
        "degree": int(consts["FIBREFIT_CORRECTION_DEGREE"]),
        "terms": terms,
        "coefficients": coeff,
        "cos_range": vec("FIBREFIT_CORRECTION_COS", _VEC2),
        "log_lo": vec("FIBREFIT_CORRECTION_LOG_LO", _VEC3),
        "log_hi": vec("FIBREFIT_CORRECTION_LOG_HI", _VEC3),
    }


def unsupported_reason(p: Dict[str, Any]) -> Optional[str]:
    """Why the fast path cannot evaluate these parameters (None: it can)."""
    if p["rung"] is None:
        name = re.search(r"fibrefit_(\w+)\(", p["rung_body"])
        return (
            f"its rung ({name.group(1) if name else 'unknown'}) is not ported to Dr.Jit "
            "(ported: lambert, hast-diffuse, max-normal, ward, gltf, principled, openpbr, poulin-fournier, "
            "varying-topology)"
        )
    if p["rung"] == "gltf" and p["gltf"][1][3] > 0.5 and p.get("gltf_dfg") is None:
        return "the gltf rung's threejs variant: the shader has no DFG table"
    return None


class DrJitModel:
    """The BRDF of :func:`parse_wgsl`'s parameters on Dr.Jit arrays of the current Mitsuba variant.

    :meth:`eval` takes the light and view directions in the fibre frame (x along the fibre, z
    the normal) as ``mi.Vector3f`` and returns f (1/sr) as ``mi.Color3f``; zero at and below
    either horizon. Every parameter is a Python float baked into the traced kernel; the sheen's
    albedo table (32 values) is the one array gathered from.
    """

    def __init__(self, p: Dict[str, Any], texels: Optional[Dict[str, Any]] = None):
        """``texels``: what the result's per-texel maps or topology map give each texel
        (``Material.texel_fields()``): :meth:`eval` then reads at ``uv`` the texel's albedos, its
        fibre azimuth and, for varying-topology, its height (one pattern per spread node instead
        of the spot's height histogram; every texel must have one)."""
        import mitsuba as mi

        why = unsupported_reason(p)
        if why is not None:
            raise ValueError(why)
        self.p = p
        self.rung = p["rung"]
        self.kd = [float(x) for x in p["kd"]]
        self.ks = [float(x) for x in p["ks"]]
        self.substrate = [float(x) for x in p["substrate"]]
        self.fuzz = [float(x) for x in p["fuzz"]]
        self.fresnel_ior = float(p["shape"][2])
        self.exponent = float(p["shape"][0])
        self.alpha_x, self.alpha_y = float(p["extra"][0]), float(p["extra"][1])
        self.fuzz_depth, self.fuzz_g = float(p["extra"][2]), float(p["extra"][3])
        self.spread = [(float(c), float(s), float(w)) for c, s, w, _ in p["spread"]]
        # the material rows (one row of zeros for the fibre rungs)
        g = p["gltf"]
        self.g0 = [float(x) for x in g[0]]
        self.g1 = [float(x) for x in g[1]] if len(g) > 1 else [0.0] * 4
        self.sheen_table = np.asarray(g[2:], dtype=np.float64).reshape(-1)
        self._sheen_e: Any = None
        self._scalar = mi.variant().startswith("scalar")
        self._texels: Optional[Tuple[int, int]] = None
        self._texel_heights = False
        if self.rung in CROSS_SECTION:
            self._setup_cross_section(p)
        if texels is not None:
            self._setup_texels(texels)
        if self.rung == "gltf" and self.g1[3] > 0.5:
            self.rung = "gltf_threejs"
            self._setup_threejs(p)
        if self.rung in ("principled", "openpbr"):
            self._setup_material(g)
        if self.rung == "gltf":
            scalar = mi.variant().startswith("scalar")
            # scalar variants: a list indexed by Python ints; JIT variants: an array gathered from
            self._sheen_e = self.sheen_table.tolist() if scalar else mi.Float(self.sheen_table.astype(np.float32))

    # -- the shader's common parts ------------------------------------------------------------

    @staticmethod
    def _pow(x, e: float):
        import drjit as dr

        return dr.select(x < 1e-30, 0.0, dr.exp(e * dr.log(dr.maximum(x, 1e-30))))

    def _schlick(self, l, v):
        import drjit as dr

        ior = self.fresnel_ior
        if ior <= 0.0:
            return 1.0
        h = l + v
        norm = dr.norm(h)
        c = dr.select(norm > 0.0, dr.clip(dr.dot(l, h) / dr.maximum(norm, 1e-30), 0.0, 1.0), 0.0)
        f0 = ((ior - 1.0) / (ior + 1.0)) ** 2
        m = 1.0 - c
        m2 = m * m
        return f0 + (1.0 - f0) * (m2 * m2 * m)

    def _fuzz(self, l, v):
        """(attenuation A, single-scattering column P) of the fuzz layer; no layer: (1, 0)."""
        import drjit as dr

        depth, g = self.fuzz_depth, self.fuzz_g
        if depth <= 0.0:
            return 1.0, 0.0
        mi_, mo = dr.maximum(l.z, 1e-30), dr.maximum(v.z, 1e-30)
        a = dr.exp(-depth * (1.0 / mi_ + 1.0 / mo))
        cos_a = dr.clip(-dr.dot(l, v), -1.0, 1.0)
        d = dr.maximum(1.0 + g * g - 2.0 * g * cos_a, 1e-30)
        p = (1.0 - g * g) / (4.0 * math.pi * d * dr.sqrt(d))
        return a, p * (1.0 - a) / (4.0 * (mi_ + mo))

    # -- the rungs: (diffuse, specular, substrate) columns ---------------------------------------

    def _lambert(self, l, v):
        return 1.0 / math.pi, 0.0, 0.0

    def _hast_diffuse(self, l, v):
        import drjit as dr

        phi = (dr.sqrt(l.y * l.y + l.z * l.z) + l.z) / math.pi
        return phi / (math.pi * l.z), 0.0, 0.0

    def _max_normal(self, l, v):
        import drjit as dr

        lp = dr.sqrt(l.y * l.y + l.z * l.z)
        vp = dr.sqrt(v.y * v.y + v.z * v.z)
        lobe = dr.maximum(lp * vp - l.x * v.x, 0.0)
        return lp / (math.pi * l.z), self._pow(lobe, self.exponent) / l.z, 0.0

    def _ward(self, l, v):
        import drjit as dr

        ax, ay = self.alpha_x, self.alpha_y
        h = l + v
        e = ((h.x / ax) ** 2 + (h.y / ay) ** 2) / (h.z * h.z)
        lobe = dr.exp(-e) / (4.0 * math.pi * ax * ay * dr.sqrt(l.z * v.z))
        return 1.0 / math.pi, lobe, 0.0

    def _sheen_lambda_l(self, x, a: float):
        import drjit as dr

        t = (1.0 - a) ** 2
        mix = lambda u, w: u * (1.0 - t) + w * t  # noqa: E731
        pa, pb, pc = mix(21.5473, 25.3245), mix(3.82987, 3.32435), mix(0.19823, 0.16801)
        pd, pe = mix(-1.97760, -1.27393), mix(-4.32054, -4.85967)
        xp = dr.select(x > 0.0, dr.exp(pc * dr.log(dr.maximum(x, 1e-30))), 0.0)
        return pa / (1.0 + pb * xp) + pd * x + pe

    def _sheen_lambda(self, c, a: float):
        import drjit as dr

        near = dr.exp(self._sheen_lambda_l(c, a))
        far = dr.exp(2.0 * self._sheen_lambda_l(0.5, a) - self._sheen_lambda_l(1.0 - c, a))
        return dr.select(dr.abs(c) < 0.5, near, far)

    def _sheen_albedo(self, mu):
        import drjit as dr
        import mitsuba as mi

        x = dr.clip(mu, 0.0, 1.0) * 31.0
        if isinstance(self._sheen_e, list):
            k = min(int(math.floor(x)), 30)
            f = x - k
            return self._sheen_e[k] * (1.0 - f) + self._sheen_e[k + 1] * f
        k = dr.minimum(mi.UInt32(dr.floor(x)), 30)
        f = x - mi.Float(k)
        a = dr.gather(mi.Float, self._sheen_e, k)
        b = dr.gather(mi.Float, self._sheen_e, k + 1)
        return a * (1.0 - f) + b * f

    @staticmethod
    def _ggx_specular(l, v, h, at, ab):
        """The anisotropic GGX D x V (alphas ``at``, ``ab``; half vector ``h``), as glTF's
        KHR_materials_anisotropy and three.js evaluate it."""
        import drjit as dr
        import mitsuba as mi

        a2 = at * ab
        fv = mi.Vector3f(ab * h.x, at * h.y, a2 * h.z)
        w2 = a2 / dr.dot(fv, fv)
        d = dr.select(h.z > 0.0, a2 * w2 * w2 / math.pi, 0.0)
        vis_v = l.z * dr.norm(mi.Vector3f(at * v.x, ab * v.y, v.z))
        vis_l = v.z * dr.norm(mi.Vector3f(at * l.x, ab * l.y, l.z))
        return d * 0.5 / (vis_v + vis_l)

    def _gltf(self, l, v):
        import drjit as dr
        import mitsuba as mi

        m, at, ab, sp = self.g0
        f0, sheen, sheen_alpha = self.g1[0], self.g1[1], self.g1[2]
        h = dr.normalize(l + v)
        vh = dr.abs(dr.dot(v, h))
        x1 = dr.clip(1.0 - vh, 0.0, 1.0)
        x2 = x1 * x1
        x = x2 * x2 * x1
        s = self._ggx_specular(l, v, h, at, ab)
        fr = f0 + (1.0 - f0) * x
        diffuse = (1.0 - m) * (1.0 - sp * fr) / math.pi + m * s * (1.0 - x)
        layers = (1.0 - m) * sp * fr * s + m * s * x
        if sheen > 0.0:
            a = sheen_alpha
            e = dr.maximum(self._sheen_albedo(l.z), self._sheen_albedo(v.z))
            k = 1.0 - sheen * e
            sin2 = dr.maximum(1.0 - h.z * h.z, 0.0)
            dc = dr.select(
                sin2 > 0.0,
                (2.0 + 1.0 / a) * dr.exp(0.5 / a * dr.log(dr.maximum(sin2, 1e-30))) / (2.0 * math.pi),
                0.0,
            )
            vs = 1.0 / ((1.0 + self._sheen_lambda(v.z, a) + self._sheen_lambda(l.z, a)) * (4.0 * v.z * l.z))
            return k * diffuse, k * layers + sheen * dc * dr.clip(vs, 0.0, 1.0), 0.0
        return diffuse, layers, 0.0

    # -- the renderers' materials (the shader's principled and openpbr sections) ---------------

    def _setup_material(self, rows) -> None:
        import mitsuba as mi

        rows = np.asarray(rows, dtype=np.float64)
        self.m0 = [float(x) for x in rows[0]]
        self.m1 = [float(x) for x in rows[1]]
        self.m2 = [float(x) for x in rows[2]] if len(rows) > 2 else [0.0] * 4
        if self.rung != "principled":
            return
        # Cycles' tables at the material by cos theta_v: GGX E, the sheen LTC's a, b, albedo (32
        # nodes, rows 3..35), the specular's albedo table (16 nodes, rows 35..39)
        cols = [rows[3:35, k] for k in range(4)] + [rows[35:39].reshape(-1)]
        if self._scalar:
            self._tables = [c.tolist() for c in cols]
        else:
            self._tables = [mi.Float(c.astype(np.float32)) for c in cols]

    def _table(self, k: int, nodes: int, mu):
        """Table ``k`` at ``mu`` as the shader reads it (clamped, linear between nodes)."""
        import drjit as dr
        import mitsuba as mi

        x = dr.clip(mu, 0.0, 1.0) * float(nodes - 1)
        data = self._tables[k]
        if isinstance(data, list):
            i = min(int(x), nodes - 1)
            t = x - i
            return data[i] if t == 0.0 else (1.0 - t) * data[i] + t * data[min(i + 1, nodes - 1)]
        i = dr.minimum(mi.UInt32(x), nodes - 1)
        t = x - mi.Float(i)
        a = dr.gather(mi.Float, data, i)
        b = dr.gather(mi.Float, data, dr.minimum(i + 1, nodes - 1))
        return (1.0 - t) * a + t * b

    @staticmethod
    def _layering(albedo, weight):
        """closure_layering_weight for grey weights."""
        import drjit as dr

        if isinstance(weight, float):
            ratio = albedo / weight if weight != 0.0 else 0.0 * albedo
        else:
            ratio = dr.select(weight != 0.0, albedo / dr.select(weight != 0.0, weight, 1.0), 0.0)
        return weight * dr.clip(1.0 - ratio, 0.0, 1.0)

    def _principled_ggx(self, l, v):
        import drjit as dr

        m0, m1 = self.m0, self.m1
        h = dr.normalize(l + v)
        c = dr.dot(h, v)
        eta = m1[0]
        ect = eta * eta - (1.0 - c * c)
        ci = dr.abs(c)
        ct = -dr.sqrt(dr.maximum(ect, 0.0)) / eta
        rs = (ci + eta * ct) / (ci - eta * ct)
        rp = (ct + eta * ci) / (eta * ci - ct)
        f_real = dr.select(ect <= 0.0, 1.0, 0.5 * (rs * rs + rp * rp))
        f = m1[1] + (1.0 - m1[1]) * dr.clip((f_real - m1[2]) / (1.0 - m1[2]), 0.0, 1.0)
        ax, ay = m0[0], m0[1]
        hx, hy = h.y / ax, h.x / ay
        q = hx * hx + hy * hy + h.z * h.z
        d = 1.0 / (math.pi * ax * ay * q * q)
        sl = ((ax * l.y) ** 2 + (ay * l.x) ** 2) / (l.z * l.z)
        sv = ((ax * v.y) ** 2 + (ay * v.x) ** 2) / (v.z * v.z)
        g2 = 1.0 / (1.0 + 0.5 * (dr.sqrt(1.0 + sl) - 1.0) + 0.5 * (dr.sqrt(1.0 + sv) - 1.0))
        return f * d * g2 / (4.0 * v.z * l.z)

    def _principled(self, l, v):
        """fibrefit_principled: Blender's Principled BSDF as Cycles evaluates it."""
        import drjit as dr

        m0, m1, m2 = self.m0, self.m1, self.m2
        mu = v.z
        weight = 1.0
        sheen = 0.0
        if m2[0] > 1e-5:
            a = self._table(1, 32, mu)
            albedo = self._table(3, 32, mu)
            on = (dr.abs(a) >= 1e-5) & (albedo >= 1e-5)
            w = m2[0] * albedo
            # the frame of N and the view; at normal view the skew b is dropped
            bl = dr.sqrt(v.y * v.y + v.x * v.x)
            has = bl > 0.0
            bls = dr.select(has, bl, 1.0)
            bx, by = -v.y / bls, v.x / bls
            lox = dr.select(has, l.x * by - l.y * bx, l.x)
            loy = dr.select(has, l.x * bx + l.y * by, l.y)
            b = dr.select(has, self._table(2, 32, mu), 0.0)
            x = a * lox + b * l.z
            y = a * loy
            len2 = x * x + y * y + l.z * l.z
            val = dr.select(l.z > 0.0, w / math.pi * (a / len2) ** 2, 0.0)
            sheen = dr.select(on, val, 0.0)
            weight = dr.select(on, self._layering(w, 1.0), 1.0)
        specular = 0.0
        if m0[3] > 0.5:
            e = self._table(0, 32, mu)
            missing = (1.0 - e) / e
            energy_scale = 1.0 + missing
            darkening = 1.0
            if m1[3] != 1.0:
                fms = m1[3] * m0[2] / (1.0 - m1[3] * (1.0 - m0[2]))
                darkening = (1.0 + fms * missing) / energy_scale
            w = weight * darkening
            if m0[0] * m0[1] > 2e-10:
                specular = w * energy_scale * self._principled_ggx(l, v)
            ts = self._table(4, 16, mu)
            weight = self._layering(w * (m1[1] + (1.0 - m1[1]) * ts), weight)
        return weight / math.pi, specular + sheen, 0.0

    def _openpbr(self, l, v):
        """fibrefit_openpbr: OpenPBR Surface as MaterialX 1.39 implements it."""
        import drjit as dr
        import mitsuba as mi

        eps = 1e-8
        m0, m1 = self.m0, self.m1
        n_v = dr.clip(v.z, eps, 1.0)
        n_l = dr.clip(l.z, eps, 1.0)
        fuzz = 0.0
        t_fuzz = 1.0
        if not (m1[1] < eps):
            r = m1[2]
            # mx_zeltner_sheen_dir_albedo
            sg = r * (0.0206607 + 1.58491 * r) / (0.0379424 + r * (1.32227 + r))
            mg = r * (-0.193854 + r * (-1.14885 + r * (1.7932 - 0.95943 * r * r))) / (0.046391 + r)
            og = r * (0.000654023 + (-0.0207818 + 0.119681 * r) * r) / (1.26264 + r * (-1.92021 + r))
            z = (n_v - mg) / sg
            albedo = dr.exp(-0.5 * z * z) / (sg * math.sqrt(2.0 * math.pi)) + og
            # mx_zeltner_sheen_brdf in the frame of N and v
            a_inv = (2.58126 * n_v + 0.813703 * r) * r / (1.0 + 0.310327 * n_v * n_v + 2.60994 * n_v * r)
            b_inv = dr.sqrt(1.0 - n_v) * (r - 1.0) * r * r * r / (
                0.0000254053 + 1.71228 * n_v - 1.71506 * n_v * r + 1.34174 * r * r
            )
            xs = mi.Vector3f(v.x, v.y, v.z - n_v)
            len2 = dr.dot(xs, xs)
            has = len2 > 0.0
            xn = xs / dr.sqrt(dr.select(has, len2, 1.0))
            w0 = dr.select(has, dr.dot(l, xn), l.x)
            w1 = dr.select(has, l.y * xn.x - l.x * xn.y, l.y)
            wo = mi.Vector3f(a_inv * w0 + b_inv * l.z, a_inv * w1, l.z)
            q = a_inv / dr.dot(wo, wo)
            d = dr.maximum(l.z, 0.0) / math.pi * q * q
            fuzz = albedo * d * m1[1]
            t_fuzz = 1.0 - albedo * m1[1]
        h = dr.normalize(l + v)
        c = dr.clip(dr.dot(h, v), eps, 1.0)
        ior = m0[3]
        g2 = ior * ior + c * c - 1.0
        g = dr.sqrt(dr.maximum(g2, 0.0))
        fa = (g - c) / (g + c)
        fb = ((g + c) * c - 1.0) / ((g - c) * c + 1.0)
        f = dr.select(g2 < 0.0, 1.0, 0.5 * fa * fa * (1.0 + fb * fb))
        hx, hy = h.y / m0[0], -h.x / m0[1]
        qd = hx * hx + hy * hy + h.z * h.z
        dd = 1.0 / (math.pi * m0[0] * m0[1] * qd * qd)
        a2 = m0[2] * m0[2]
        lambda_l = dr.sqrt(a2 + (1.0 - a2) * n_l * n_l)
        lambda_v = dr.sqrt(a2 + (1.0 - a2) * n_v * n_v)
        gg = 2.0 * n_l * n_v / (lambda_l * n_v + lambda_v * n_l)
        # mx_ggx_dir_albedo_analytic
        x, y = n_v, m0[2]
        x2, y2 = x * x, y * y
        coef = [
            (0.1003, 0.9345, 1.0, 1.0),
            (-0.6303, -2.323, -1.765, 0.2281),
            (9.748, 2.229, 8.263, 15.94),
            (-2.038, -3.748, 11.53, -55.83),
            (29.34, 1.424, 28.96, 13.08),
            (-8.245, -0.7684, -7.507, 41.26),
            (-26.44, 1.436, -36.11, 54.9),
            (19.99, 0.2913, 15.86, 300.2),
            (-5.448, 0.6286, 33.37, -285.1),
        ]
        mono = [1.0, x, y, x * y, x2, y2, x2 * y, x * y2, x2 * y2]
        rr = [sum(cf[k] * mn for cf, mn in zip(coef, mono)) for k in range(4)]
        aa = dr.clip(rr[0] / rr[2], 0.0, 1.0)
        bb = dr.clip(rr[1] / rr[3], 0.0, 1.0)
        ess = aa + bb
        comp = 1.0 + f * (1.0 - ess) / ess
        spec = dd * f * gg * comp / (4.0 * n_v)
        t_spec = 1.0 - (m1[0] * aa + bb) * comp
        return t_fuzz * t_spec / math.pi, (t_fuzz * spec + fuzz) / n_l, 0.0

    # -- the gltf rung's threejs variant (the shader's gltf_threejs section) ---------------------

    def _setup_threejs(self, p: Dict[str, Any]) -> None:
        """E_ss of three.js's DFG table at this result's roughness: the table's bilinear lookup
        at r = sqrt(alpha_t) (a constant) is a linear one along N.v between 16 values, computed
        here once (f64)."""
        import mitsuba as mi

        t = p["gltf_dfg"].sum(axis=1).reshape(16, 16)  # dfg.x + dfg.y, rows along N.v
        r = math.sqrt(self.g0[1])
        x = min(max(min(max(r, 0.0), 1.0) * 16.0 - 0.5, 0.0), 15.0)
        i = min(int(math.floor(x)), 14)
        fx = x - i
        col = t[:, i] * (1.0 - fx) + t[:, i + 1] * fx
        self._dfg_col = col.tolist() if self._scalar else mi.Float(col.astype(np.float32))

    def _threejs_ess(self, nv):
        import drjit as dr
        import mitsuba as mi

        y = dr.clip(dr.clip(nv, 0.0, 1.0) * 16.0 - 0.5, 0.0, 15.0)
        if isinstance(self._dfg_col, list):
            j = min(int(math.floor(y)), 14)
            fy = y - j
            return self._dfg_col[j] * (1.0 - fy) + self._dfg_col[j + 1] * fy
        j = dr.minimum(mi.UInt32(dr.floor(y)), 14)
        fy = y - mi.Float(j)
        return dr.gather(mi.Float, self._dfg_col, j) * (1.0 - fy) + dr.gather(mi.Float, self._dfg_col, j + 1) * fy

    @staticmethod
    def _threejs_sheen_e(mu, r: float):
        import drjit as dr

        inv = 1.0 / (r + 0.1)
        a = -1.9362 + 1.0678 * r + 0.4573 * r * r - 0.8469 * inv
        b = -0.6014 + 0.5538 * r - 0.4670 * r * r - 0.1255 * inv
        return dr.clip(dr.exp(a * dr.clip(mu, 0.0, 1.0) + b), 0.0, 1.0)

    def _gltf_threejs(self, l, v):
        """fibrefit_gltf_threejs: three.js r187's BRDF; (base colour, layers, base colour
        squared) columns."""
        import drjit as dr
        import mitsuba as mi

        m, at, ab, sp = self.g0
        f0, sheen, sheen_alpha = self.g1[0], self.g1[1], self.g1[2]
        h = dr.normalize(l + v)
        vh = dr.clip(dr.dot(v, h), 0.0, 1.0)
        e = dr.exp2((-5.55473 * vh - 6.98316) * vh)
        f0d = min(f0, 1.0) * sp
        f90 = sp + (1.0 - sp) * m
        fd = f0d * (1.0 - e) + f90 * e
        pr = (1.0 - m) * f0d * (1.0 - e) + f90 * e
        gm = 1.0 / self._threejs_ess(dr.clip(v.z, 0.0, 1.0)) - 1.0
        rr = 1.0 + (1.0 - m) * f0d * gm
        s = self._ggx_specular(l, v, h, at, ab)
        k, sheen_term = 1.0, 0.0
        if sheen > 0.0:
            a = sheen_alpha
            rho = math.sqrt(a)
            k = 1.0 - sheen * dr.maximum(self._threejs_sheen_e(v.z, rho), self._threejs_sheen_e(l.z, rho))
            nh = dr.clip(h.z, 0.0, 1.0)
            sin2 = dr.maximum(1.0 - nh * nh, 0.0078125)
            dc = (2.0 + 1.0 / a) * dr.exp(0.5 / a * dr.log(sin2)) / (2.0 * math.pi)
            vn = dr.clip(1.0 / (4.0 * (l.z + v.z - l.z * v.z)), 0.0, 1.0)
            sheen_term = sheen * dc * vn
        diffuse = (1.0 - m) * (1.0 - fd) / math.pi + s * m * (pr * gm + (1.0 - e) * rr)
        return k * diffuse, k * s * pr * rr + sheen_term, k * s * m * m * gm * (1.0 - e)

    # -- the cross-section rungs (the shader's cross_section section) ---------------------------

    def _setup_cross_section(self, p: Dict[str, Any]) -> None:
        """The constants of the cross-section rungs: the lobe's, the Gauss-Legendre rule, and a
        list of jobs, one per (height node, fibre of the period) pattern evaluation, each with
        the numbers of ``fibrefit_pattern`` that depend only on the height (computed in f64, as
        the Rust model computes them)."""
        import mitsuba as mi

        self.spacing = float(p["shape"][1])
        self.lobe_floor = float(p["shape"][3])
        self.norm = (self.exponent + 2.0) / (2.0 * math.pi)
        gl = p["gauss_legendre"]
        if len(gl) == 0:
            raise ValueError("the shader has no Gauss-Legendre rule")
        self.gauss = [(float(x), float(w)) for x, w in gl]
        d = self.spacing
        heights = [(0.0, 1.0)] if self.rung == "poulin_fournier" else [(float(h), float(w)) for h, w, _, _ in p["heights"]]
        # job: step, other row's height, count x weight, substrate weight, rise (for the substrate)
        jobs: List[List[float]] = []
        for h, w in heights:
            phi = min(math.asin(min(max(h / d, 0.0), 1.0)), math.acos(min(max(1.0 / d, 0.0), 1.0)))
            step, rise = d * math.cos(phi), d * math.sin(phi)
            if rise == 0.0:
                # the odd row is the even row moved by one step: one fibre, counted twice
                jobs.append([step, 0.0, 2.0 * w, w, rise])
            else:
                jobs.append([step, rise, w, w, rise])
                jobs.append([step, -rise, w, 0.0, rise])
        self.jobs = jobs
        cols = list(zip(*jobs))
        if self._scalar:
            self._job_cols = [list(c) for c in cols]
            self._spread_cols = [list(c) for c in zip(*self.spread)]
        else:
            self._job_cols = [mi.Float(np.array(c, dtype=np.float32)) for c in cols]
            self._spread_cols = [mi.Float(np.array(c, dtype=np.float32)) for c in zip(*self.spread)]

    def _setup_texels(self, f: Dict[str, Any]) -> None:
        """The texels' albedos and fibre-azimuth offsets as arrays gathered at uv, and for
        varying-topology their heights as jobs."""
        import mitsuba as mi

        w, h = int(f["width"]), int(f["rows"])
        self._texels = (w, h)
        cols = {k: np.asarray(f[k], dtype=np.float64).reshape(w * h, 3) for k in ("kd", "ks", "substrate")}
        offset = np.asarray(f["azimuth_offset"], dtype=np.float64).reshape(-1)
        conv = (lambda a: a.tolist()) if self._scalar else (lambda a: mi.Float(np.ascontiguousarray(a, dtype=np.float32)))
        self._texel_albedos = {k: [conv(v[:, c]) for c in range(3)] for k, v in cols.items()}
        self._texel_offset = None if not np.any(offset) else (conv(np.cos(offset)), conv(np.sin(offset)))
        heights = np.asarray(f["height"], dtype=np.float64).reshape(-1)
        if self.rung == "varying_topology":
            if np.isnan(heights).any():
                raise ValueError("some texels have no height (the spot's height distribution there)")
            self._setup_texel_jobs(w, h, heights)

    def _setup_texel_jobs(self, width: int, height: int, heights: Any) -> None:
        """Two jobs per texel (its two fibres; one fibre counted twice and a weightless one
        where the rows are level), as ``_setup_cross_section`` makes them per height node: job
        2 t + k of texel t = y W + x."""
        import mitsuba as mi

        hs = np.asarray(heights, dtype=np.float64).reshape(-1)
        if hs.size != width * height:
            raise ValueError(f"texel heights: {hs.size} values for {width} x {height} texels")
        d = self.spacing
        phi = np.minimum(np.arcsin(np.clip(hs / d, 0.0, 1.0)), math.acos(min(max(1.0 / d, 0.0), 1.0)))
        step, rise = d * np.cos(phi), d * np.sin(phi)
        level = rise == 0.0
        one = np.ones_like(hs)
        first = [step, rise, np.where(level, 2.0, 1.0), one, rise]
        second = [step, -rise, np.where(level, 0.0, 1.0), 0.0 * one, rise]
        cols = [np.stack([a, b], axis=1).reshape(-1) for a, b in zip(first, second)]
        self._texel_heights = True
        if self._scalar:
            self._texel_cols = [c.tolist() for c in cols]
        else:
            self._texel_cols = [mi.Float(c.astype(np.float32)) for c in cols]

    def _texel(self, uv):
        """The texel index at ``uv`` as ``Material.eval`` finds it (x = floor(u W), y =
        floor((1 - v) H), clamped to the map)."""
        import drjit as dr
        import mitsuba as mi

        w, h = self._texels
        if self._scalar:
            x = min(max(math.floor(float(uv[0]) * w), 0), w - 1)
            y = min(max(math.floor((1.0 - float(uv[1])) * h), 0), h - 1)
            return int(y) * w + int(x)
        x = mi.UInt32(dr.clip(dr.floor(uv.x * w), 0.0, float(w - 1)))
        y = mi.UInt32(dr.clip(dr.floor((1.0 - uv.y) * h), 0.0, float(h - 1)))
        return y * w + x

    def _loop(self, state, cond, body, label):
        """``dr.while_loop``, symbolic in the JIT variants whatever the flags (an evaluated loop
        of loops would launch a kernel per iteration), a Python loop in the scalar ones."""
        import drjit as dr

        return dr.while_loop(state, cond, body, label=label, mode=None if self._scalar else "symbolic")

    def _at(self, col, k):
        import drjit as dr
        import mitsuba as mi

        if isinstance(col, list):
            return col[int(k)]
        return dr.gather(mi.Float, col, k)

    @staticmethod
    def _project(w):
        """fibrefit_project: (alpha, s, c, len, tan, sec) of a direction in the cross-section
        plane (w.z > 0)."""
        import drjit as dr

        ln = dr.sqrt(w.y * w.y + w.z * w.z)
        return dr.atan2(w.y, w.z), w.y / ln, w.z / ln, ln, w.y / w.z, ln / w.z

    @staticmethod
    def _sort3(x):
        """fibrefit_sort3: three (start, end) intervals sorted by their start."""
        import drjit as dr

        x = list(x)
        for j in (0, 1, 0):
            a, b = x[j], x[j + 1]
            sw = b[0] < a[0]
            x[j] = (dr.select(sw, b[0], a[0]), dr.select(sw, b[1], a[1]))
            x[j + 1] = (dr.select(sw, a[0], b[0]), dr.select(sw, a[1], b[1]))
        return x

    def _gaps(self, sa, ca, step, other_row):
        """fibrefit_gaps: the gaps (in s = sin(th - alpha)) that the pattern's occluders leave on
        one fibre's front arc seen along a direction of sin ``sa``, cos ``ca``: four slots of
        (start, end), the first ``n`` of them used, and n."""
        import drjit as dr

        none = 3.0
        ds = 2.0 * step * ca
        da = 2.0 * step * sa
        own = (ds < 2.0) & (da != 0.0)
        sh0 = (dr.select(own, dr.select(da > 0.0, ds - 1.0, -1.0), none), dr.select(own, dr.select(da > 0.0, 1.0, 1.0 - ds), none))
        s0 = step * ca - other_row * sa
        a0 = step * sa + other_row * ca
        lo = dr.ceil((-2.0 - s0) / ds)
        hi = dr.floor((2.0 - s0) / ds)
        das = dr.select(da == 0.0, 1.0, da)
        lo = dr.select(da > 0.0, dr.maximum(lo, dr.floor(-a0 / das) + 1.0), lo)
        hi = dr.select(da < 0.0, dr.minimum(hi, dr.ceil(-a0 / das) - 1.0), hi)
        ok = ((da != 0.0) | (a0 > 0.0)) & (lo <= hi)
        s = s0 + lo * ds
        narrow = ds <= 2.0
        sh1 = (dr.select(ok, s - 1.0, none), dr.select(ok, dr.select(narrow, s0 + hi * ds + 1.0, s + 1.0), none))
        two = ok & (ds > 2.0) & (hi > lo)
        sh2 = (dr.select(two, s + ds - 1.0, none), dr.select(two, s + ds + 1.0, none))
        sh = self._sort3([sh0, sh1, sh2])
        # the complement of the union in (-1, 1), compacted into the first n slots
        starts, ends = [1.0] * 4, [1.0] * 4
        n = 0.0 * ds
        cursor = -1.0 + 0.0 * ds
        for k in range(4):
            a = dr.minimum(sh[k][0], 1.0) if k < 3 else 1.0 + 0.0 * ds
            emit = a > cursor
            for m in range(k + 1):
                put = emit & (n == float(m))
                starts[m] = dr.select(put, cursor, starts[m])
                ends[m] = dr.select(put, a, ends[m])
            n = n + dr.select(emit, 1.0, 0.0)
            if k < 3:
                cursor = dr.maximum(cursor, sh[k][1])
        return starts, ends, n

    @staticmethod
    def _diffuse_kernel(t0, t1, a, b, cos_ab):
        """fibrefit_diffuse_kernel: the integral over [t0, t1] of cos(th - a) cos(th - b)."""
        import drjit as dr

        d = t1 - t0
        u = t0 + t1 - a - b
        long = 0.5 * (d * cos_ab + dr.cos(u) * dr.sin(d))
        m = 0.5 * (t0 + t1)
        d2 = d * d
        d_minus_sin = d * d2 * (1.0 / 6.0 - d2 * (1.0 / 120.0 - d2 * (1.0 / 5040.0 - d2 / 362880.0)))
        short = dr.maximum(d * dr.cos(m - a) * dr.cos(m - b) - 0.5 * dr.cos(u) * d_minus_sin, 0.0)
        return dr.select(d > 0.5, long, short)

    def _substrate(self, lp, vp, step, rise):
        """fibrefit_substrate: the fraction of one period's substrate strip seen and lit."""
        import drjit as dr

        p = 2.0 * step
        inv_p = 1.0 / p
        wl, wv = 2.0 * lp[5], 2.0 * vp[5]
        a0 = (-lp[4] - lp[5], wl)
        a1 = (step - (1.0 + rise) * lp[4] - lp[5], wl)
        a2 = (-vp[4] - vp[5], wv)
        a3 = (step - (1.0 + rise) * vp[4] - vp[5], wv)
        big = wl >= wv
        origin = dr.select(big, a0[0], a2[0])
        width = dr.select(big, wl, wv)
        first = (dr.select(big, a1[0], a0[0]), dr.select(big, a1[1], a0[1]))
        second = (dr.select(big, a2[0], a1[0]), dr.select(big, a2[1], a1[1]))
        x = []
        for start, w in (first, second, a3):
            r = start - origin
            r = r - p * dr.floor(r * inv_p)
            r = dr.select((r >= p) | (r < 0.0), 0.0, r)
            x.append((r, dr.minimum(r + w, p)))
        x = self._sort3(x)
        cursor = width
        open_ = 0.0
        for k in range(3):
            open_ = open_ + dr.maximum(x[k][0] - cursor, 0.0)
            cursor = dr.maximum(cursor, x[k][1])
        open_ = open_ + dr.maximum(p - cursor, 0.0)
        return dr.select(dr.maximum(wl, wv) >= p, 0.0, open_ * inv_p)

    def _pair(self, l, v):
        """fibrefit_pair: what the patterns share of a light/view pair."""
        import drjit as dr

        lp, vp = self._project(l), self._project(v)
        cos_lv = dr.dot(l, v)
        cos_delta = lp[2] * vp[2] + lp[1] * vp[1]
        opc = 0.5 * ((lp[2] + vp[2]) ** 2 + (lp[1] + vp[1]) ** 2)
        k = lp[3] * vp[3]
        peak = k * opc - cos_lv
        c = (self.lobe_floor * peak + cos_lv) / dr.select(k > 0.0, k, 1.0) - cos_delta
        cc = dr.clip(c, -1.0, 1.0)
        half = dr.atan2(dr.sqrt(1.0 - cc), dr.sqrt(1.0 + cc))
        sigma = lp[0] + vp[0]
        has = (peak > 0.0) & (k > 0.0) & (c < 1.0)
        return {
            "l": lp, "v": vp, "cos_lv": cos_lv, "cos_delta": cos_delta, "opc": opc, "sigma": sigma,
            "k2": 2.0 * k, "win": (0.5 * sigma - half, 0.5 * sigma + half), "has": has,
        }

    def _lobe(self, a, b, sp):
        """fibrefit_lobe: the lobe integral over [a, b] by the Gauss-Legendre rule."""
        import drjit as dr

        half = 0.5 * (b - a)
        tms = (a + b) - sp["sigma"]
        acc = 0.0
        for x, w in self.gauss:
            u = 2.0 * half * x + tms
            h = dr.sin(0.5 * u)
            cc = 0.5 * (sp["opc"] - 2.0 * h * h)
            rv = sp["k2"] * cc - sp["cos_lv"]
            acc = acc + dr.select(rv > 0.0, w * self._pow(rv, self.exponent) * cc, 0.0)
        return half * acc

    def _lobe_where(self, need, a, b, sp):
        """The lobe integral where ``need``, else 0. In the JIT variants it is the body of a
        symbolic loop run at most once: the LLVM backend skips a loop's body for a packet of
        lanes none of which enters it (a symbolic ``if`` evaluates both sides), and most arcs
        miss the lobe's window."""
        import drjit as dr
        import mitsuba as mi

        if self._scalar:
            return self._lobe(a, b, sp) if need else 0.0

        def body(go, acc):
            return dr.zeros(mi.Bool, dr.width(go)), self._lobe(a, b, sp)

        zero = dr.zeros(mi.Float, dr.width(need))
        _, acc = self._loop((mi.Bool(need), zero), lambda go, acc: go, body, "fibrefit_lobe")
        return acc

    @staticmethod
    def _pick(slots, i):
        import drjit as dr

        r = slots[3]
        for m in (2, 1, 0):
            r = dr.select(i == float(m), slots[m], r)
        return r

    def _fibre(self, sp, step, other_row, active):
        """One fibre of ``fibrefit_pattern``: the sums over its seen-and-lit arcs of the diffuse
        kernel and of the lobe integral (inside the lobe window), by the merge of the gaps seen
        along v and lit along l (a symbolic loop: at most seen + lit - 1 arcs)."""
        import drjit as dr

        lp, vp = sp["l"], sp["v"]
        ss, se, sn = self._gaps(vp[1], vp[2], step, other_row)
        ls, le, ln = self._gaps(lp[1], lp[2], step, other_row)
        # the arcs' ends as angles th (alpha + asin s), once per gap
        ss = [vp[0] + dr.asin(dr.clip(x, -1.0, 1.0)) for x in ss]
        se = [vp[0] + dr.asin(dr.clip(x, -1.0, 1.0)) for x in se]
        ls = [lp[0] + dr.asin(dr.clip(x, -1.0, 1.0)) for x in ls]
        le = [lp[0] + dr.asin(dr.clip(x, -1.0, 1.0)) for x in le]
        zero = 0.0 * sn

        def cond(i, j, dif, spec):
            return (i < sn) & (j < ln) & active

        def body(i, j, dif, spec):
            xa, xb = self._pick(ss, i), self._pick(se, i)
            ya, yb = self._pick(ls, j), self._pick(le, j)
            lo, hi = dr.maximum(xa, ya), dr.minimum(xb, yb)
            arc = hi > lo
            dif = dif + dr.select(arc, self._diffuse_kernel(lo, hi, lp[0], vp[0], sp["cos_delta"]), 0.0)
            wa, wb = dr.maximum(lo, sp["win"][0]), dr.minimum(hi, sp["win"][1])
            lobe = arc & sp["has"] & (wb > wa)
            if "whole" in sp:
                # an arc over the whole window: the pair's integral over it, made once
                whole = (wa == sp["win"][0]) & (wb == sp["win"][1])
                if self._scalar:
                    spec = spec + (sp["whole"] if lobe and whole else self._lobe_where(lobe, wa, wb, sp))
                else:
                    spec = spec + dr.select(lobe & whole, sp["whole"], 0.0)
                    spec = spec + self._lobe_where(lobe & ~whole, wa, wb, sp)
            else:
                spec = spec + self._lobe_where(lobe, wa, wb, sp)
            adv = xb < yb
            return dr.select(adv, i + 1.0, i), dr.select(adv, j, j + 1.0), dif, spec

        _, _, dif, spec = self._loop((zero, zero, zero, zero), cond, body, "fibrefit_arcs")
        return dif, spec

    def _cross_section(self, l, v, texel=None):
        """The rung's (diffuse, specular, substrate) columns at one spread node: the jobs
        (height nodes x fibres, or a texel's two fibres) summed, in a symbolic loop where there
        are several."""
        import drjit as dr
        import mitsuba as mi

        sp = self._pair(l, v)
        if texel is None and len(self.jobs) > 1:
            # the lobe is the same for every height, and a narrow lobe's window lies inside
            # most heights' arcs: its integral over the whole window once per pair (as the
            # Rust model integrates each distinct arc of a pair once)
            w0, w1 = sp["win"]
            sp = dict(sp, whole=self._lobe_where(sp["has"] & (w1 > w0), w0, w1, sp))
        lp, vp = sp["l"], sp["v"]
        zero = 0.0 * l.z
        cols = self._job_cols if texel is None else self._texel_cols

        def job(k, d, s, b):
            idx = k if texel is None else 2 * texel + k
            step, other, cw, sw, rise = [self._at(c, idx) for c in cols]
            denom = 2.0 * step * lp[2] * vp[2]
            ok = denom > 0.0
            dif, spec = self._fibre(sp, step, other, ok)
            scale = cw / dr.select(ok, denom, 1.0)
            d = d + dr.select(ok, scale * (1.0 / math.pi) * dif, 0.0)
            s = s + dr.select(ok, scale * self.norm * spec, 0.0)
            b = b + dr.select(ok & (sw > 0.0), sw * (1.0 / math.pi) * self._substrate(lp, vp, step, rise), 0.0)
            return k + 1, d, s, b

        if texel is None and len(self.jobs) == 1:
            _, d, s, b = job(0 if self._scalar else mi.UInt32(0), zero, zero, zero)
            return d, s, b
        k0 = 0 if self._scalar else dr.zeros(mi.UInt32, dr.width(l.z))
        n = len(self.jobs) if texel is None else 2
        _, d, s, b = self._loop((k0, zero, zero, zero), lambda k, d, s, b: k < n, job, "fibrefit_patterns")
        return d, s, b

    def _cross_section_spread(self, l, v, texel=None):
        """The spread's nodes of a cross-section rung, summed (a symbolic loop over the nodes
        where there are several)."""
        import drjit as dr
        import mitsuba as mi

        zero = 0.0 * l.z
        if len(self.spread) == 1:
            c, s, w = self.spread[0]
            if c == 1.0 and s == 0.0:
                d, sp, b = self._cross_section(l, v, texel)
                return w * d, w * sp, w * b

        def node(j, bx, by, bz):
            c, s, w = [self._at(col, j) for col in self._spread_cols]
            lr = dr.normalize(mi.Vector3f(l.x * c + l.y * s, -l.x * s + l.y * c, l.z))
            vr = dr.normalize(mi.Vector3f(v.x * c + v.y * s, -v.x * s + v.y * c, v.z))
            x, y, z = self._cross_section(lr, vr, texel)
            return j + 1, bx + w * x, by + w * y, bz + w * z

        j0 = 0 if self._scalar else dr.zeros(mi.UInt32, dr.width(l.z))
        n = len(self.spread)
        _, bx, by, bz = self._loop((j0, zero, zero, zero), lambda j, bx, by, bz: j < n, node, "fibrefit_spread")
        return bx, by, bz

    # -- the public entry ----------------------------------------------------------------------

    def eval(self, l, v, active=True, uv=None):
        """f(l, v) in 1/sr (``mi.Color3f``) at fibre-frame unit directions; 0 at and below either
        horizon. ``uv``: the texture coordinates, read where the model has texel heights."""
        import drjit as dr
        import mitsuba as mi

        up = (l.z > 0.0) & (v.z > 0.0) & active
        # keep the arithmetic finite where the result is masked to zero
        lz = dr.select(up, l.z, 1.0)
        vz = dr.select(up, v.z, 1.0)
        l = mi.Vector3f(l.x, l.y, lz)
        v = mi.Vector3f(v.x, v.y, vz)
        texel = None
        kd, ks, substrate = self.kd, self.ks, self.substrate
        if self._texels is not None:
            if uv is None:
                raise ValueError("this model reads texel fields: eval needs uv")
            texel = self._texel(uv)
            kd, ks, substrate = ([self._at(col, texel) for col in self._texel_albedos[k]] for k in ("kd", "ks", "substrate"))
            if self._texel_offset is not None:
                # the texel's fibres turned by its azimuth offset, from T towards B
                c, s = (self._at(col, texel) for col in self._texel_offset)
                l = mi.Vector3f(l.x * c + l.y * s, l.y * c - l.x * s, l.z)
                v = mi.Vector3f(v.x * c + v.y * s, v.y * c - v.x * s, v.z)
        if self.rung in CROSS_SECTION:
            bx, by, bz = self._cross_section_spread(l, v, texel if self._texel_heights else None)
        else:
            rung = getattr(self, "_" + self.rung)
            bx, by, bz = 0.0, 0.0, 0.0
            for c, s, w in self.spread:
                if c == 1.0 and s == 0.0:
                    lr, vr = l, v
                else:
                    lr = dr.normalize(mi.Vector3f(l.x * c + l.y * s, -l.x * s + l.y * c, l.z))
                    vr = dr.normalize(mi.Vector3f(v.x * c + v.y * s, -v.x * s + v.y * c, v.z))
                x, y, z = rung(lr, vr)
                bx, by, bz = bx + w * x, by + w * y, bz + w * z
        by = by * self._schlick(l, v)
        a, pz = self._fuzz(l, v)
        bx, by, bz, bw = bx * a, by * a, bz * a, pz
        factor = self._correction(l, v) if self.p.get("correction") else None
        out = []
        for ch in range(3):
            val = bx * kd[ch] + by * ks[ch] + bz * substrate[ch] + bw * self.fuzz[ch]
            if factor is not None:
                val = val * factor[ch]
            out.append(dr.select(up, val, 0.0) if not isinstance(val, float) else dr.select(up, mi.Float(val), 0.0))
        return mi.Color3f(out[0], out[1], out[2])

    def _correction(self, l, v):
        """The shader's ``fibrefit_correction`` per channel at fibre-frame directions above both
        horizons (turning about the normal changes neither cosine nor the azimuth difference)."""
        import drjit as dr

        k = self.p["correction"]
        lo, hi = k["cos_range"]
        q = dr.sqrt((l.x * l.x + l.y * l.y) * (v.x * v.x + v.y * v.y))
        y = dr.select(q > 1e-12, dr.clip((l.x * v.x + l.y * v.y) / dr.maximum(q, 1e-30), -1.0, 1.0), 1.0)

        def legendre(x):
            p = [1.0 + 0.0 * x, x]
            for n in range(2, k["degree"] + 1):
                p.append(((2 * n - 1) * x * p[n - 1] - (n - 1) * p[n - 2]) / n)
            return p

        pl = legendre(2.0 * dr.clip(l.z, lo, hi) - 1.0)
        pv = legendre(2.0 * dr.clip(v.z, lo, hi) - 1.0)
        py = legendre(y)
        s = [0.0, 0.0, 0.0]
        for (a, b, c), coeff in zip(k["terms"], k["coefficients"]):
            t = pl[a] * pv[b]
            if a != b:
                t = t + pl[b] * pv[a]
            t = t * py[c]
            s = [s[ch] + t * coeff[ch] for ch in range(3)]
        return [dr.exp(dr.clip(s[ch], k["log_lo"][ch], k["log_hi"][ch])) for ch in range(3)]


def fibre_frame(w, cos_psi: float, sin_psi: float):
    """A shading-frame direction (x = dp/du, z = the normal) in the fibre frame: x along the
    fibres at azimuth psi from dp/du, y = z x t."""
    import mitsuba as mi

    return mi.Vector3f(w.x * cos_psi + w.y * sin_psi, -w.x * sin_psi + w.y * cos_psi, w.z)


def shading_frame(w, cos_psi: float, sin_psi: float):
    """The inverse of :func:`fibre_frame`."""
    import mitsuba as mi

    return mi.Vector3f(w.x * cos_psi - w.y * sin_psi, w.x * sin_psi + w.y * cos_psi, w.z)


# -- the tabulated importance sampler ---------------------------------------------------------------

#: default resolution of the sampling tables: view elevation nodes (uniform in cos), view
#: azimuth nodes over [0, 2 pi] (relative to the fibre), light elevation nodes (uniform in
#: cos) and light azimuth nodes over [0, 2 pi] (relative to the view's azimuth)
SAMPLER_RES = (12, 12, 32, 64)


def sampler_table(material: Any, psi: float, res=SAMPLER_RES, floor: float = 0.02) -> Dict[str, Any]:
    """The proposal of the fast sampler, tabulated from ``material.eval`` (the exact model).

    For each view direction on a grid (elevation nodes uniform in cos theta_v, azimuth nodes
    phi_v over [0, 2 pi] in the fibre frame), the light directions' density is the luminance of
    f cos theta_l on a grid in (x, y) = ((phi_l - phi_v) / 2 pi, 1 - cos theta_l), plus
    ``floor`` x its mean x cos theta_l (a cosine-weighted part, so no direction the BRDF reaches
    has zero density). (x, y) is area-preserving up to 2 pi (d omega = 2 pi dx dy), so the
    solid-angle pdf is the table's normalised bilinear density / (2 pi); Mitsuba's
    ``MarginalContinuous2D2`` samples that bilinear density exactly and interpolates it
    linearly between the view nodes, so the pdf is exact for what is drawn.
    Returns ``data`` (float32, (n_phi_v + 1, n_theta_v, n_theta_l, n_phi_l + 1)) and the
    parameter node values ``phi_v`` and ``cos_v``.
    """
    n_tv, n_pv, n_tl, n_pl = res
    eps = 1e-4
    cos_v = np.linspace(1.0, 0.0, n_tv)  # parameter nodes must increase: 1 - cos
    y_v = 1.0 - cos_v
    phi_v = np.linspace(0.0, 2 * np.pi, n_pv + 1)
    y_l = np.linspace(0.0, 1.0, n_tl)
    x_l = np.linspace(0.0, 1.0, n_pl + 1)
    cl = np.clip(1.0 - y_l, eps, 1.0)
    CL, XL = np.meshgrid(cl, x_l, indexing="ij")
    SL = np.sqrt(1.0 - CL * CL)
    data = np.zeros((n_pv + 1, n_tv, n_tl, n_pl + 1), dtype=np.float64)
    cv = np.clip(1.0 - y_v, eps, 1.0)[:, None, None]
    sv = np.sqrt(1.0 - cv * cv)
    for i, pv in enumerate(phi_v[:-1]):
        # one view azimuth's grid of (view elevation, light direction) pairs a batch, in the
        # swatch frame (the fibre frame turned by psi)
        av = pv + psi
        al = av + 2 * np.pi * XL
        shape = (n_tv, n_tl, n_pl + 1)
        v = np.stack(np.broadcast_arrays(sv * math.cos(av), sv * math.sin(av), cv + 0 * XL), axis=-1).reshape(-1, 3)
        l = np.stack(np.broadcast_arrays(SL * np.cos(al), SL * np.sin(al), CL + 0 * al), axis=-1)
        l = np.broadcast_to(l, shape + (3,)).reshape(-1, 3)
        f = material.eval(l, v)
        lum = f.mean(axis=1) if f.shape[1] > 1 else f[:, 0]
        data[i] = np.clip(lum, 0.0, None).reshape(shape) * CL
    data[-1] = data[0]  # phi_v = 2 pi is phi_v = 0
    mean = data.mean(axis=(2, 3), keepdims=True)
    mean = np.where(mean > 0, mean, 1.0)
    data = data + floor * mean * (1.0 - y_l)[None, None, :, None]
    return {"data": data.astype(np.float32), "phi_v": phi_v, "y_v": y_v}
