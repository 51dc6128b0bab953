"""A Mitsuba 3 BSDF backed by fibrefit, and the Mitsuba scene of a capture image.

``register()`` registers the BSDF type ``fibrefit``::

    import mitsuba as mi
    mi.set_variant("llvm_ad_rgb")          # or "scalar_rgb"
    import fibrefit.mitsuba
    fibrefit.mitsuba.register()
    bsdf = {"type": "fibrefit", "filename": "fit.json"}   # optional "maps": a maps directory

Its ``eval``, ``sample``, ``pdf`` and ``eval_pdf`` call :class:`fibrefit.Material` (the Rust
model, not a Python copy): the fitted BRDF with the result's per-texel maps looked up at the
surface's uv, and fibrefit's importance sampler. The fibre frame is the surface's shading frame
(dp/du is the swatch's x axis; the fibres lie at the result's ``fibre_azimuth_deg`` from it).
One-sided: zero from below.

Dr.Jit flags: a BSDF written in Python that converts Dr.Jit arrays to numpy needs evaluated
(not symbolic) loops and virtual calls in the JIT variants, so ``register()`` switches
``dr.JitFlag.SymbolicLoops`` and ``dr.JitFlag.SymbolicCalls`` off (a plain ``mi.render`` then
works; renders are slower than with symbolic recording). The LLVM variants need libLLVM 16 or
newer: when ``DRJIT_LIBLLVM_PATH`` is unset, importing this module points it at Debian's
``libllvm19`` if that is installed (``apt-get install libllvm19``).

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

__all__ = [
    "FibrefitBSDF",
    "LLVM_CANDIDATES",
    "bsdf_class",
    "capture_geometry",
    "capture_scene",
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

    def _inputs(self, si, *xs):
        n = _width(si.wi, si.uv, *xs)
        v = _rows(si.wi, n, 3)
        uv = _rows(si.uv, n, 2)
        return n, v, uv

    def eval(self, ctx, si, wo, active=True):
        import drjit as dr

        n, v, uv = self._inputs(si, wo)
        l = _rows(wo, n, 3)
        f = self.material.eval(_unit(l), _unit(v), uv)
        cos = np.clip(l[:, 2], 0.0, None)[:, None]
        return dr.select(active, _spectrum(f * cos, self._scalar), 0.0)

    def pdf(self, ctx, si, wo, active=True):
        import drjit as dr

        n, v, uv = self._inputs(si, wo)
        l = _rows(wo, n, 3)
        p = self.material.pdf(_unit(v), _unit(l), uv)
        return dr.select(active, _floats(p, self._scalar), 0.0)

    def eval_pdf(self, ctx, si, wo, active=True):
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

    def sample(self, ctx, si, sample1, sample2, active=True):
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
        return f"FibrefitBSDF[filename={self.filename!r}, model={self.material.model!r}, maps={self.material.has_maps}]"


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


def register(variant: Optional[str] = None) -> None:
    """Register the BSDF type ``fibrefit`` (:class:`FibrefitBSDF`) with Mitsuba 3 (for the
    current variant, or ``variant`` after setting it).

    Switches ``dr.JitFlag.SymbolicLoops`` and ``dr.JitFlag.SymbolicCalls`` off in the JIT
    variants (the plugin converts arrays to numpy, which needs evaluated loops and calls).
    Properties of the BSDF: ``filename`` (a result JSON, required), ``maps`` (a maps
    directory; default: the one the result names) and ``capture`` (a capture TOML whose
    tangent/azimuth and height maps fill in where the result has none).
    """
    import drjit as dr
    import mitsuba as mi

    if variant is not None:
        mi.set_variant(variant)
    v = mi.variant()
    if v is None:
        raise FibrefitError("fibrefit.mitsuba.register(): set a Mitsuba variant first (mi.set_variant('llvm_ad_rgb'))")
    if "rgb" not in v:
        raise FibrefitError(f"fibrefit.mitsuba: variant {v!r} is not an RGB variant; use e.g. llvm_ad_rgb or scalar_rgb")
    if not v.startswith("scalar"):
        dr.set_flag(dr.JitFlag.SymbolicLoops, False)
        dr.set_flag(dr.JitFlag.SymbolicCalls, False)
    cls = bsdf_class()
    mi.register_bsdf("fibrefit", lambda props: cls(props))
    _REGISTERED[v] = True


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
