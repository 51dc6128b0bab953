"""A Mitsuba 3 BSDF backed by fibrefit, and the Mitsuba scene of a capture image.

``register()`` registers the BSDF type ``fibrefit``::

    import mitsuba as mi
    mi.set_variant("llvm_ad_rgb")          # or "scalar_rgb"
    import fibrefit.mitsuba
    fibrefit.mitsuba.register()
    bsdf = {"type": "fibrefit", "filename": "fit.json"}   # optional "maps": a maps directory

Two paths, chosen by the BSDF's ``mode`` property:

* ``"fast"``: the fitted BRDF in Dr.Jit's vectorised operations (``fibrefit._drjit_model``: the
  equations of fibrefit's WGSL export, with the numbers that export bakes in for the result), so
  Mitsuba compiles it into its kernels like its own BSDFs, and a tabulated importance sampler
  (Mitsuba's ``MarginalContinuous2D2`` over the light directions, conditioned on the view as
  its ``measured`` BSDF does; its pdf is exact for what it draws, and the sample's weight is
  eval x cos / pdf). On load the Dr.Jit model is checked against :class:`fibrefit.Material` at
  random and grazing direction pairs: each value within 1e-3 of the exact one, relative to
  max(|value|, 1e-4 of the largest) (the comparison of ``fibrefit export --check``). Ported:
  lambert, hast-diffuse, max-normal, ward, gltf (khronos and threejs), principled, openpbr,
  poulin-fournier and varying-topology, with the spread, Fresnel and the fuzz layer; and the
  result's per-texel maps (albedos, fibre direction, height) and topology map, each texel's
  values read at uv as ``Material.eval`` reads them (``Material.texel_fields()``; the check then
  at texel centres), lobe maps (roughness, anisotropy) aside.
* ``"exact"`` (or ``"exact": True``): :class:`fibrefit.Material` (the Rust model) through numpy
  at every call, the result's per-texel maps at the surface's uv, fibrefit's own importance
  sampler. Any rung, maps included. Converting Dr.Jit arrays to numpy needs evaluated (not
  symbolic) loops and virtual calls in the JIT variants, so an exact instance switches
  ``dr.JitFlag.SymbolicLoops`` and ``dr.JitFlag.SymbolicCalls`` off when it loads (renders are
  then slower than with symbolic recording, fast instances included).
* ``"auto"`` (the default): fast where the rung is ported, the result has no lobe maps and the
  load check holds; exact otherwise (with a warning saying why).

The fibre frame is the surface's shading frame (dp/du is the swatch's x axis; the fibres lie at
the result's ``fibre_azimuth_deg`` from it). One-sided: zero from below. The LLVM variants need
libLLVM 16 or newer: when ``DRJIT_LIBLLVM_PATH`` is unset, importing this module points it at
Debian's ``libllvm19`` if that is installed (``apt-get install libllvm19``).

``capture_scene(capture_toml, result_json, image_index)`` is the scene of one image of an
image capture: rendered and divided by nothing more (the capture's exposure is applied to the
captured image by ``captured_image``), pixel (row, column) of the render is pixel (row, column)
of the captured file.
"""

from __future__ import annotations

import json as _json
import os as _os
import warnings as _warnings
from typing import Any, Dict, Optional, Tuple

import numpy as np

from . import FibrefitError, Material, PathLike, _native
from . import _image_index, _native_call
from . import load as _load
from . import _drjit_model as _dm

__all__ = [
    "FAST_TOLERANCE",
    "FibrefitBSDF",
    "LLVM_CANDIDATES",
    "bsdf_class",
    "capture_geometry",
    "capture_scene",
    "check_fast",
    "check_pairs",
    "exact_flags",
    "captured_image",
    "image_scene",
    "register",
]

#: Where libLLVM 16+ is looked for when ``DRJIT_LIBLLVM_PATH`` is unset (Debian's libllvm19..16).
LLVM_CANDIDATES = [
    "/usr/lib/x86_64-linux-gnu/libLLVM-19.so",
    "/usr/lib/x86_64-linux-gnu/libLLVM.so.19.1",
    "/usr/lib/llvm-19/lib/libLLVM-19.so",
    "/usr/lib/aarch64-linux-gnu/libLLVM-19.so",
    "/usr/lib/x86_64-linux-gnu/libLLVM-18.so",
    "/usr/lib/x86_64-linux-gnu/libLLVM-17.so",
    "/usr/lib/x86_64-linux-gnu/libLLVM-16.so",
]


def _point_drjit_at_llvm() -> None:
    if _os.environ.get("DRJIT_LIBLLVM_PATH"):
        return
    for c in LLVM_CANDIDATES:
        if _os.path.exists(c):
            _os.environ["DRJIT_LIBLLVM_PATH"] = c
            return


_point_drjit_at_llvm()

_REGISTERED: Dict[str, bool] = {}

#: the BSDF's ``mode`` values
MODES = ("auto", "fast", "exact")
#: the fast path's bound: each value of its Dr.Jit model within this of the exact model's,
#: relative to max(|value|, 1e-4 of the largest value over the checked pairs)
FAST_TOLERANCE = 1e-3
#: the BSDF's properties setting the sampler's table resolution (defaults ``_drjit_model.SAMPLER_RES``)
TABLE_KEYS = ("table_theta_v", "table_phi_v", "table_theta_l", "table_phi_l")


def exact_flags() -> None:
    """Switch Dr.Jit's symbolic loops and calls off (``dr.JitFlag.SymbolicLoops``,
    ``dr.JitFlag.SymbolicCalls``) on the calling thread: what a scene with an exact-mode
    ``fibrefit`` BSDF needs before ``mi.render`` (the exact path converts Dr.Jit arrays to numpy,
    which symbolic recording cannot do). The fast mode needs nothing. An exact instance calls
    this itself when it loads, which reaches the rendering thread only when the scene is loaded
    on it (``mi.load_dict(scene, parallel=False)``); ``register(exact_flags=True)`` calls it too.
    """
    import drjit as dr

    dr.set_flag(dr.JitFlag.SymbolicLoops, False)
    dr.set_flag(dr.JitFlag.SymbolicCalls, False)


def check_pairs(n: int = 20000, seed: int = 12345) -> Tuple[np.ndarray, np.ndarray]:
    """The direction pairs (swatch frame) at which the fast path is checked on load: n pairs
    uniform over the two hemispheres, n / 4 with both directions within 5 degrees of the
    horizon, and the normal with directions at 0, 30, 60, 80, 89 and 89.9 degrees."""
    rng = np.random.default_rng(seed)

    def hemi(k, cmin=0.0, cmax=1.0):
        z = cmin + (cmax - cmin) * rng.random(k)
        phi = 2 * np.pi * rng.random(k)
        r = np.sqrt(1 - z * z)
        return np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=1)

    g = float(np.sin(np.radians(5.0)))
    t = np.radians([0.0, 30.0, 60.0, 80.0, 89.0, 89.9])
    fixed = np.stack([np.sin(t), np.zeros_like(t), np.cos(t)], axis=1)
    normal = np.broadcast_to([0.0, 0.0, 1.0], fixed.shape)
    l = np.concatenate([hemi(n), hemi(n // 4, 1e-4, g), fixed, normal])
    v = np.concatenate([hemi(n), hemi(n // 4, 1e-4, g), normal, fixed])
    return l, v


def check_fast(
    model: Any, material: Material, cs: Tuple[float, float], pairs=None, texels: Optional[Tuple[int, int]] = None
) -> Dict[str, Any]:
    """How far the fast path's Dr.Jit model is from ``material.eval`` (the exact model): over
    the pairs (default :func:`check_pairs`), the largest and 99th-percentile error of each value
    relative to max(|exact value|, 1e-4 of the largest exact value), the largest absolute error
    (1/sr) and the largest exact value. ``texels`` (W, H): a model with texel heights, each pair
    at a seeded texel's centre."""
    import mitsuba as mi

    l, v = check_pairs() if pairs is None else pairs
    uv = None
    if texels is not None:
        w, h = texels
        rng = np.random.default_rng(777)
        x, y = rng.integers(0, w, len(l)), rng.integers(0, h, len(l))
        uv = np.stack([(x + 0.5) / w, 1.0 - (y + 0.5) / h], axis=1)
    ref = material.eval(l, v, uv)
    if mi.variant().startswith("scalar"):
        idx = np.linspace(0, len(l) - 1, 400).astype(int)
        l, v, ref = l[idx], v[idx], ref[idx]
        uvs = [None] * len(idx) if uv is None else [tuple(uv[i]) for i in idx]
        got = np.array(
            [
                np.array(model.eval(_dm.fibre_frame(mi.Vector3f(*a), *cs), _dm.fibre_frame(mi.Vector3f(*b), *cs), True, c))
                for a, b, c in zip(l, v, uvs)
            ],
            dtype=np.float64,
        )
    else:
        L = mi.Vector3f(*[mi.Float(np.ascontiguousarray(l[:, k], dtype=np.float32)) for k in range(3)])
        V = mi.Vector3f(*[mi.Float(np.ascontiguousarray(v[:, k], dtype=np.float32)) for k in range(3)])
        UV = None if uv is None else mi.Point2f(*[mi.Float(np.ascontiguousarray(uv[:, k], dtype=np.float32)) for k in range(2)])
        got = np.array(model.eval(_dm.fibre_frame(L, *cs), _dm.fibre_frame(V, *cs), True, UV), dtype=np.float64).T
    got = got[:, : ref.shape[1]]
    err = np.abs(got - ref)
    largest = float(np.abs(ref).max())
    rel = err / np.maximum(np.abs(ref), 1e-4 * max(largest, 1e-300))
    return {
        "cases": int(len(l)),
        "max_relative": float(rel.max()),
        "p99_relative": float(np.quantile(rel, 0.99)),
        "max_absolute": float(err.max()),
        "largest": largest,
    }


def _rows(a: Any, n: int, width: int) -> np.ndarray:
    """A Dr.Jit vector (or scalar variant value) as an (n, width) float64 array."""
    arr = np.array(a, dtype=np.float64)
    if arr.ndim == 1:
        arr = arr.reshape(width, 1) if arr.shape[0] == width else arr.reshape(1, -1)
    arr = arr.reshape(width, -1).T
    if arr.shape[0] != n:
        arr = np.broadcast_to(arr, (n, width))
    return np.ascontiguousarray(arr)


def _width(*xs: Any) -> int:
    import drjit as dr

    return max(dr.width(x) for x in xs)


def _spectrum(rgb: np.ndarray, scalar: bool):
    import mitsuba as mi

    if rgb.shape[1] == 1:
        rgb = np.repeat(rgb, 3, axis=1)
    if scalar:
        return mi.Color3f(*[float(x) for x in rgb[0]])
    return mi.Color3f(*[mi.Float(np.ascontiguousarray(rgb[:, c], dtype=np.float32)) for c in range(3)])


def _floats(x: np.ndarray, scalar: bool):
    import mitsuba as mi

    return mi.Float(float(x[0])) if scalar else mi.Float(np.ascontiguousarray(x, dtype=np.float32))


def _vectors(x: np.ndarray, scalar: bool):
    import mitsuba as mi

    if scalar:
        return mi.Vector3f(*[float(c) for c in x[0]])
    return mi.Vector3f(*[mi.Float(np.ascontiguousarray(x[:, c], dtype=np.float32)) for c in range(3)])


class FibrefitBSDF:
    """fibrefit's fitted fibre BSDF as a Mitsuba 3 plugin (see the module docs).

    Mitsuba's ``mi.BSDF`` exists only once a variant is set, and is another class in each
    variant; so this class holds the plugin (its methods), and :func:`bsdf_class` makes the
    current variant's subclass of ``mi.BSDF`` with them, which :func:`register` registers as
    the BSDF type ``fibrefit``. Instances are made by Mitsuba (``mi.load_dict``), not directly.
    """

    #: set in the variant's class by :func:`bsdf_class`: that variant's ``mi.BSDF`` and whether
    #: it is a scalar variant
    _base: Any = None
    _scalar: bool = False

    def __init__(self, props):
        import mitsuba as mi

        self._base.__init__(self, props)
        if "filename" not in props:
            raise FibrefitError("the fibrefit BSDF needs a `filename` property (a fibrefit result JSON)")
        self.filename = str(props["filename"])
        maps = str(props["maps"]) if "maps" in props else None
        capture = str(props["capture"]) if "capture" in props else None
        self.material: Material = _load(self.filename, maps, capture)
        for label, why in self.material.undetermined.items():
            # the renderer uses the value, but the data did not determine it: say so
            _warnings.warn(
                f"{self.filename}: `{label}` is undetermined ({why}); the BSDF uses its value as given",
                stacklevel=2,
            )
        flags = mi.BSDFFlags.GlossyReflection | mi.BSDFFlags.DiffuseReflection | mi.BSDFFlags.FrontSide
        if self.material.has_maps:
            flags = flags | mi.BSDFFlags.SpatiallyVarying
        self.m_flags = flags
        self.m_components = [flags]
        mode = str(props["mode"]) if "mode" in props else "auto"
        if "exact" in props and bool(props["exact"]):
            mode = "exact"
        if mode not in MODES:
            raise FibrefitError(f"the fibrefit BSDF's mode {mode!r}: expected one of {', '.join(MODES)}")
        res = tuple(int(props[k]) if k in props else d for k, d in zip(TABLE_KEYS, _dm.SAMPLER_RES))
        self.fast_check: Optional[Dict[str, Any]] = None
        self.fast_reason: Optional[str] = None
        self.table_bytes = 0
        if mode != "exact":
            self.fast_reason = self._setup_fast(maps, capture, res)
            if self.fast_reason is not None:
                if mode == "fast":
                    raise FibrefitError(f"{self.filename}: the fibrefit BSDF's fast mode: {self.fast_reason}")
                hint = "" if self._scalar else (
                    "; render it after fibrefit.mitsuba.exact_flags() (or register(exact_flags=True)): "
                    "the exact path needs Dr.Jit's symbolic loops and calls off"
                )
                _warnings.warn(
                    f"{self.filename}: the fibrefit BSDF uses its exact path: {self.fast_reason}{hint}", stacklevel=2
                )
        self.mode = "fast" if mode != "exact" and self.fast_reason is None else "exact"
        if self.mode == "exact" and not self._scalar:
            exact_flags()

    def _setup_fast(self, maps, capture, res) -> Optional[str]:
        """Build the fast path (the Dr.Jit model and the sampler's tables); the reason it cannot
        be used, or None."""
        import mitsuba as mi

        texels = None
        if self.material.has_maps or _topology_map(self.filename):
            # per-texel maps, or a topology map's heights (has_maps does not count them): the
            # fast path reads what Material.eval reads at each texel (without them it would
            # evaluate the spot: the global values, the map's height histogram)
            texels = self.material.texel_fields()
            if texels is None:
                return (
                    "the result's per-texel maps include lobe maps (roughness, anisotropy) or a topology map "
                    "on another grid (looked up at uv by the exact path only)"
                )
        try:
            shader = _native_call(_native.export, self.filename, "wgsl", False, "swatch", False, None, progress=False)["shader"]
        except FibrefitError as e:
            return f"no shader export of the result ({e})"
        p = _dm.parse_wgsl(shader)
        why = _dm.unsupported_reason(p)
        if why is not None:
            return why
        try:
            self.model = _dm.DrJitModel(p, texels)
        except ValueError as e:
            return f"the fast path cannot read the result's texels: {e}"
        psi = float(np.radians(self.material.fibre_azimuth_deg))
        self._cs = (float(np.cos(psi)), float(np.sin(psi)))
        self.fast_check = check_fast(
            self.model, self.material, self._cs, texels=None if texels is None else (texels["width"], texels["rows"])
        )
        if self.fast_check["max_relative"] > FAST_TOLERANCE:
            return (
                f"the Dr.Jit model is {self.fast_check['max_relative']:.2g} from the exact one "
                f"(relative, over {self.fast_check['cases']} direction pairs; bound {FAST_TOLERANCE:g})"
            )
        t = _dm.sampler_table(self.material, psi, res)
        self.table_res = res
        self.table_bytes = int(t["data"].nbytes)
        self._warp = mi.MarginalContinuous2D2(t["data"], [t["phi_v"].tolist(), t["y_v"].tolist()], normalize=True)
        return None

    def _inputs(self, si, *xs):
        if not self._scalar:
            import drjit as dr

            if dr.flag(dr.JitFlag.SymbolicScope):
                raise FibrefitError(
                    f"{self.filename}: the fibrefit BSDF's exact path converts Dr.Jit arrays to numpy, which "
                    "symbolic loops and calls cannot do: call fibrefit.mitsuba.exact_flags() (or "
                    "register(exact_flags=True)) before mi.render, or load the scene with "
                    "mi.load_dict(scene, parallel=False)"
                )
        n = _width(si.wi, si.uv, *xs)
        v = _rows(si.wi, n, 3)
        uv = _rows(si.uv, n, 2)
        return n, v, uv

    def eval(self, ctx, si, wo, active=True):
        if self.mode == "exact":
            return self._exact_eval(ctx, si, wo, active)
        import drjit as dr

        l, v = self._fibre(wo), self._fibre(si.wi)
        return self.model.eval(l, v, active, si.uv) * dr.maximum(l.z, 0.0)

    def pdf(self, ctx, si, wo, active=True):
        if self.mode == "exact":
            return self._exact_pdf(ctx, si, wo, active)
        return self._fast_pdf(self._fibre(wo), self._fibre(si.wi), active)

    def eval_pdf(self, ctx, si, wo, active=True):
        if self.mode == "exact":
            return self._exact_eval_pdf(ctx, si, wo, active)
        import drjit as dr

        l, v = self._fibre(wo), self._fibre(si.wi)
        return self.model.eval(l, v, active, si.uv) * dr.maximum(l.z, 0.0), self._fast_pdf(l, v, active)

    def sample(self, ctx, si, sample1, sample2, active=True):
        if self.mode == "exact":
            return self._exact_sample(ctx, si, sample1, sample2, active)
        import drjit as dr
        import mitsuba as mi

        v = self._fibre(si.wi)
        phi_v, param = self._view_param(v)
        pos, pdf_xy = self._warp.sample(mi.Point2f(sample2), param, active)
        cos_l = 1.0 - pos.y
        sin_l = dr.safe_sqrt(1.0 - cos_l * cos_l)
        phi_l = phi_v + (2.0 * dr.pi) * pos.x
        l = mi.Vector3f(sin_l * dr.cos(phi_l), sin_l * dr.sin(phi_l), cos_l)
        ok = active & (v.z > 0.0) & (cos_l > 0.0) & (pdf_xy > 0.0)
        pdf = dr.select(ok, pdf_xy / (2.0 * dr.pi), 0.0)
        bs = dr.zeros(mi.BSDFSample3f)
        bs.wo = self._shading(l)
        bs.pdf = pdf
        bs.eta = 1.0
        bs.sampled_type = mi.UInt32(+mi.BSDFFlags.GlossyReflection)
        bs.sampled_component = mi.UInt32(0)
        # the value at the direction returned (turned back to the fibre frame, as eval turns it),
        # so weight x pdf is eval(bs.wo) to rounding, even in a sharp lobe
        l = self._fibre(bs.wo)
        value = self.model.eval(l, v, ok, si.uv) * dr.maximum(l.z, 0.0)
        return bs, dr.select(ok, value / dr.select(ok, pdf, 1.0), 0.0)

    # -- the fast path's frames and the sampler's coordinates -----------------------------------

    def _fibre(self, w):
        return _dm.fibre_frame(w, *self._cs)

    def _shading(self, w):
        return _dm.shading_frame(w, *self._cs)

    def _view_param(self, v):
        """The view's azimuth in the fibre frame in [0, 2 pi) and the sampler's parameter
        (that azimuth, 1 - cos theta_v)."""
        import drjit as dr
        import mitsuba as mi

        phi_v = dr.atan2(v.y, v.x)
        phi_v = dr.select(phi_v < 0.0, phi_v + 2.0 * dr.pi, phi_v)
        return phi_v, mi.Point2f(phi_v, 1.0 - v.z)

    def _fast_pdf(self, l, v, active):
        import drjit as dr
        import mitsuba as mi

        phi_v, param = self._view_param(v)
        x = (dr.atan2(l.y, l.x) - phi_v) * (0.5 / dr.pi)
        x = x - dr.floor(x)
        ok = active & (l.z > 0.0) & (v.z > 0.0)
        p = self._warp.eval(mi.Point2f(x, 1.0 - l.z), param, ok) / (2.0 * dr.pi)
        return dr.select(ok, p, 0.0)

    def _exact_eval(self, ctx, si, wo, active=True):
        import drjit as dr

        n, v, uv = self._inputs(si, wo)
        l = _rows(wo, n, 3)
        f = self.material.eval(_unit(l), _unit(v), uv)
        cos = np.clip(l[:, 2], 0.0, None)[:, None]
        return dr.select(active, _spectrum(f * cos, self._scalar), 0.0)

    def _exact_pdf(self, ctx, si, wo, active=True):
        import drjit as dr

        n, v, uv = self._inputs(si, wo)
        l = _rows(wo, n, 3)
        p = self.material.pdf(_unit(v), _unit(l), uv)
        return dr.select(active, _floats(p, self._scalar), 0.0)

    def _exact_eval_pdf(self, ctx, si, wo, active=True):
        import drjit as dr

        n, v, uv = self._inputs(si, wo)
        l = _rows(wo, n, 3)
        lu, vu = _unit(l), _unit(v)
        f = self.material.eval(lu, vu, uv)
        cos = np.clip(l[:, 2], 0.0, None)[:, None]
        p = self.material.pdf(vu, lu, uv)
        return (
            dr.select(active, _spectrum(f * cos, self._scalar), 0.0),
            dr.select(active, _floats(p, self._scalar), 0.0),
        )

    def _exact_sample(self, ctx, si, sample1, sample2, active=True):
        import drjit as dr
        import mitsuba as mi

        n, v, uv = self._inputs(si, sample1, sample2)
        u = np.clip(_rows(sample2, n, 2), 0.0, np.nextafter(1.0, 0.0))
        l, w, p = self.material.sample(_unit(v), u, uv)
        bs = dr.zeros(mi.BSDFSample3f, n) if not self._scalar else mi.BSDFSample3f()
        bs.wo = _vectors(l, self._scalar)
        bs.pdf = dr.select(active, _floats(p, self._scalar), 0.0)
        bs.eta = 1.0
        bs.sampled_type = mi.UInt32(+mi.BSDFFlags.GlossyReflection)
        bs.sampled_component = mi.UInt32(0)
        return bs, dr.select(active & (bs.pdf > 0), _spectrum(w, self._scalar), 0.0)

    def traverse(self, callback):
        pass

    def parameters_changed(self, keys):
        pass

    def to_string(self):
        return (
            f"FibrefitBSDF[filename={self.filename!r}, model={self.material.model!r}, "
            f"maps={self.material.has_maps}, mode={self.mode!r}]"
        )


_CLASSES: Dict[str, type] = {}


def bsdf_class() -> type:
    """The plugin's class in the current Mitsuba variant: that variant's subclass of ``mi.BSDF``
    with :class:`FibrefitBSDF`'s methods (made once per variant)."""
    import mitsuba as mi

    v = mi.variant()
    if v is None:
        raise FibrefitError("fibrefit.mitsuba: set a Mitsuba variant first (mi.set_variant('llvm_ad_rgb'))")
    cls = _CLASSES.get(v)
    if cls is None:
        body = {k: x for k, x in vars(FibrefitBSDF).items() if k not in ("__dict__", "__weakref__")}
        body.update(_base=mi.BSDF, _scalar=v.startswith("scalar"))
        cls = type(mi.BSDF)("FibrefitBSDF", (mi.BSDF,), body)
        _CLASSES[v] = cls
    return cls


def register(variant: Optional[str] = None, exact_flags: bool = False) -> None:
    """Register the BSDF type ``fibrefit`` (:class:`FibrefitBSDF`) with Mitsuba 3 (for the
    current variant, or ``variant`` after setting it).

    Properties of the BSDF: ``filename`` (a result JSON, required), ``mode`` (``"auto"``, the
    default, ``"fast"`` or ``"exact"``; ``"exact": True`` is ``"mode": "exact"``; see the module
    docs), ``maps`` (a maps directory; default: the one the result names), ``capture`` (a
    capture TOML whose tangent/azimuth and height maps fill in where the result has none) and
    the fast sampler's table resolution ``table_theta_v``, ``table_phi_v``, ``table_theta_l``,
    ``table_phi_l`` (default ``_drjit_model.SAMPLER_RES``). ``exact_flags``: also switch
    Dr.Jit's symbolic loops and calls off (:func:`exact_flags`), which exact instances need in
    the JIT variants; the fast mode renders with them on.
    """
    import mitsuba as mi

    if variant is not None:
        mi.set_variant(variant)
    v = mi.variant()
    if v is None:
        raise FibrefitError("fibrefit.mitsuba.register(): set a Mitsuba variant first (mi.set_variant('llvm_ad_rgb'))")
    if "rgb" not in v:
        raise FibrefitError(f"fibrefit.mitsuba: variant {v!r} is not an RGB variant; use e.g. llvm_ad_rgb or scalar_rgb")
    if exact_flags and not v.startswith("scalar"):
        globals()["exact_flags"]()
    cls = bsdf_class()
    mi.register_bsdf("fibrefit", lambda props: cls(props))
    _REGISTERED[v] = True


def _topology_map(filename: str) -> Optional[str]:
    """The topology map a result (``knobs.topology_map``) or parameter file (``topology_map``)
    names, if any."""
    try:
        j = _json.loads(open(filename, encoding="utf-8").read())
    except (OSError, ValueError):
        return None
    if not isinstance(j, dict):
        return None
    knobs = j.get("knobs") if isinstance(j.get("knobs"), dict) else {}
    return knobs.get("topology_map") or j.get("topology_map")


def _unit(a: np.ndarray) -> np.ndarray:
    """Rows normalised (Mitsuba's float32 directions are unit to ~1e-7; zero rows stay zero and
    are refused by fibrefit only if they are not directions at all)."""
    n = np.linalg.norm(a, axis=1, keepdims=True)
    out = np.where(n > 0, a / np.where(n > 0, n, 1.0), np.array([0.0, 0.0, 1.0]))
    return out


def capture_geometry(capture_toml: str) -> Dict[str, Any]:
    """The capture's swatch and images (files, sizes, exposures, lights, cameras) as a dict."""
    return _json.loads(_native.capture_geometry(_os.fspath(capture_toml)))


def captured_image(capture_toml: str, image_index: int) -> Tuple[np.ndarray, np.ndarray]:
    """Image ``image_index`` of a capture as the fit reads it, times its exposure: an
    (H, W, C) float32 array of radiance per unit irradiance (row 0 at the top) and an (H, W)
    bool array of saturated pixels."""
    return _native.capture_image(_os.fspath(capture_toml), _image_index(image_index))


def image_scene(capture_toml: PathLike, image_index: int) -> Dict[str, Any]:
    """Image ``image_index`` of a capture as a renderer's scene, from fibrefit's library
    (``fibrefit::api::capture``), millimetres and the swatch frame: ``size_mm``, ``width``,
    ``height`` (pixels), ``light`` (``type`` ``"directional"``: ``towards_light`` (unit),
    ``irradiance``; ``"point"``: ``position_mm``, ``intensity_mm`` (irradiance = intensity_mm /
    r^2, r in mm)) and ``camera`` (``type`` ``"orthographic"``: ``towards_camera`` (unit),
    ``to_world`` (4x4, rows), ``near_clip_mm``, ``far_clip_mm``; ``"pinhole"``: ``position_mm``,
    ``to_world``, ``fov_x_deg``, ``principal_point_offset_x``, ``principal_point_offset_y``,
    ``near_clip_mm``, ``far_clip_mm``). A view-map camera, a pinhole at or below the swatch and
    non-square pixels under a pinhole are refused."""
    return _json.loads(_native_call(_native.image_scene, _os.fspath(capture_toml), _image_index(image_index)))


def capture_scene(
    capture_toml: str,
    result_json: str,
    image_index: int,
    spp: Optional[int] = None,
    maps: Optional[str] = None,
    mode: Optional[str] = None,
) -> Dict[str, Any]:
    """The Mitsuba scene dict of image ``image_index`` of a capture, with the fitted material.

    The swatch is a ``rectangle`` of the capture's size (millimetres; the scene's unit), its
    BSDF the registered ``fibrefit`` type with ``result_json`` (and its maps); the image's light
    (``directional`` with its irradiance, or ``point`` with its intensity, converted from the
    capture's r-in-metres to millimetres) and camera (``orthographic`` or ``perspective`` at the
    capture's pose) at the image's resolution, rectified to the swatch as the capture's images
    are: pixel (row, column) of ``mi.render(mi.load_dict(scene))`` is pixel (row, column) of the
    captured file, in the units of ``captured_image`` (radiance per unit irradiance, exposure
    applied). ``register()`` must have been called. ``spp``: None (default) traces one ray
    through each pixel's centre, as a capture's pixel is defined (exact under its point or
    directional light); a number traces that many random rays over each pixel's area (a box
    filter: a sharp highlight then differs from the centre value by the pixel's footprint).
    ``mode``: the BSDF's (``"auto"``, ``"fast"``, ``"exact"``; None: the plugin's default,
    auto). A capture whose tangent or height maps fill in makes the material one with maps,
    which only the exact path renders.
    """
    import mitsuba as mi

    g = image_scene(capture_toml, image_index)
    w_mm, h_mm = g["size_mm"]
    T = mi.ScalarTransform4f
    light = g["light"]
    if light["type"] == "directional":
        # Mitsuba's direction is the one the light travels in
        emitter = {
            "type": "directional",
            "direction": [-c for c in light["towards_light"]],
            "irradiance": {"type": "rgb", "value": [light["irradiance"]] * 3},
        }
    else:
        emitter = {
            "type": "point",
            "position": light["position_mm"],
            "intensity": {"type": "rgb", "value": [light["intensity_mm"]] * 3},
        }
    cam = g["camera"]
    film = {"type": "hdrfilm", "width": g["width"], "height": g["height"], "rfilter": {"type": "box"}, "pixel_format": "rgb"}
    sensor: Dict[str, Any] = {
        "type": "orthographic" if cam["type"] == "orthographic" else "perspective",
        "to_world": T(cam["to_world"]),
        "near_clip": cam["near_clip_mm"],
        "far_clip": cam["far_clip_mm"],
        "film": film,
    }
    if cam["type"] == "pinhole":
        sensor.update(
            fov=cam["fov_x_deg"],
            fov_axis="x",
            principal_point_offset_x=cam["principal_point_offset_x"],
            principal_point_offset_y=cam["principal_point_offset_y"],
        )
    if spp is None:
        sensor["sampler"] = {"type": "stratified", "sample_count": 1, "jitter": False}
    else:
        sensor["sampler"] = {"type": "independent", "sample_count": int(spp)}
    # the capture's own per-texel fields (tangent map, height map) where the result has no maps
    bsdf: Dict[str, Any] = {"type": "fibrefit", "filename": _os.fspath(result_json), "capture": _os.fspath(capture_toml)}
    if maps is not None:
        bsdf["maps"] = _os.fspath(maps)
    if mode is not None:
        bsdf["mode"] = mode
    return {
        "type": "scene",
        "integrator": {"type": "direct"},
        "sensor": sensor,
        "swatch": {
            "type": "rectangle",
            "to_world": T().scale([w_mm / 2.0, h_mm / 2.0, 1.0]),
            "bsdf": bsdf,
        },
        "light": emitter,
    }
