"""fibrefit: fit fibre reflectance models to measurements, and use the fits in renderers.

The model, the fitter and the loaders are fibrefit's Rust library (the same code as the
``fibrefit`` command line); this package converts numpy arrays and Python values to and from it.
Each function is a command of the command line, its keyword arguments the command's flags:

- ``load(result_json, maps=None, capture=None) -> Material``: a fitted material.
  ``Material.eval(l, v, uv)`` gives the BRDF (1/sr) as an (N, C) array, ``Material.sample(v, u,
  uv)`` importance-samples light directions ``(l, weight, pdf)``, ``Material.pdf(v, l, uv)``
  their density (1/sr).
- ``fit(data, config=None, model=None, *, metric, fuzz, maps, progress, <loading flags>) ->
  Result``: a fit, as ``fibrefit fit``.
- ``score(result_json, data, *, <loading flags>) -> Score``: a result on other data, as
  ``fibrefit score``.
- ``eval(params, queries, model=None) -> (brdf, intensity)``: a parameter file's BRDF at a
  query CSV's directions, as ``fibrefit eval``.
- ``export(result_json, shader=None, gltf=False, object="swatch", check=False, model=None) ->
  Exported``: shader source and a GLB preview, in memory, as ``fibrefit export``.
- ``view(result_json, out=None, data=None) -> str``: the viewer page (one self-contained HTML
  file: the exact model beside the glTF route in WebGL2, measured against fitted, the parameter
  table), written as ``fibrefit view`` writes it; returns its path.
- ``load_data(path, *, <loading flags>) -> dict``: a measurement's samples as numpy arrays.
- ``fibrefit.blender``: a ``principled`` fit as a Principled BSDF material in the running Blender
  (``fibrefit.blender.material(result, name=None)``), as ``fibrefit export --blender``.
- ``fibrefit.materialx``: an ``openpbr`` fit as an OpenPBR Surface material
  (``fibrefit.materialx.document(result)``, ``.usda(result)``), as ``fibrefit export
  --materialx`` and ``--usd``.
- ``fibrefit.mitsuba``: a Mitsuba 3 BSDF plugin backed by ``Material`` and the Mitsuba scene of a
  capture image.

The loading flags (keyword-only, as the command line's flags of the same names; ``None`` the
command line's default): ``stride`` and ``fraction`` (captures: every stride-th pixel, a seeded
fraction of them; default a fit config's, else 1), ``subsample_seed`` (0), ``directions``
(measured-BRDF files: direction pairs drawn, 3000), ``direction_seed`` (0), ``max_theta``
(degrees, 78), ``skip_bad_rows``, ``small_angles_ok`` (goniometric tables), ``columns`` (a dict
of our column names to the file's, as ``--columns``; it extends a fit config's ``[columns]``) and
``angles`` (``"deg"`` or ``"rad"``: the unit of a goniometric table's angle columns, as
``--angles``; default a fit config's ``[data] angles``, else degrees).

Frames and units: directions are unit vectors in the swatch frame (z the macro normal, x the
swatch's x axis, as the command line's angles); ``l`` points towards the light and ``v``
towards the viewer, both away from the surface. Texture coordinates ``uv`` in [0, 1]^2 span a
result's per-texel maps, v up the image. Every error is a ``FibrefitError`` (a ``ValueError``)
with the message the command line prints (a keyword the function does not have is Python's
``TypeError``).
"""

from __future__ import annotations

import json as _json
import operator as _operator
import os as _os
import re as _re
from dataclasses import dataclass as _dataclass, field as _field
from typing import Any, Dict, List, Optional, Sequence, Tuple, Union

import numpy as np

from . import _native
from ._native import FibrefitError

__all__ = [
    "Exported",
    "FibrefitError",
    "Material",
    "Parameter",
    "Result",
    "Score",
    "board",
    "calibrate",
    "eval",
    "export",
    "fit",
    "load",
    "load_data",
    "score",
    "view",
    "__version__",
]

__version__ = _native.version()

PathLike = Union[str, "_os.PathLike[str]"]


def _image_index(image_index: Any) -> int:
    """An image index as the native layer takes it: an integer >= 0 (one beyond the capture's
    images is refused there, with the capture's count)."""
    if isinstance(image_index, (bool, np.bool_)):
        raise FibrefitError(f"image_index = {image_index!r}: expected an integer >= 0")
    try:
        i = _operator.index(image_index)
    except TypeError:
        raise FibrefitError(f"image_index = {image_index!r}: expected an integer >= 0") from None
    if i < 0:
        raise FibrefitError(f"image_index = {i}: expected an integer >= 0")
    # beyond any capture's images, and within what the native layer converts
    return min(i, 2**63 - 1)


def _f64(name: str, a: Any, width: int) -> np.ndarray:
    """`a` as a C-contiguous float64 (N, width) array; one row is accepted as (width,)."""
    if np.iscomplexobj(a):
        raise FibrefitError(
            f"{name}: complex values; expected real numbers (their imaginary parts would be lost)"
        )
    try:
        arr = np.ascontiguousarray(a, dtype=np.float64)
    except (TypeError, ValueError) as e:
        raise FibrefitError(f"{name}: not an array of numbers ({e})") from None
    if arr.ndim == 1 and arr.shape[0] == width:
        arr = arr.reshape(1, width)
    if arr.ndim != 2 or arr.shape[1] != width:
        raise FibrefitError(f"{name}: expected an (N, {width}) array, got shape {arr.shape}")
    return arr


def _instance(a: Any) -> Optional[np.ndarray]:
    """The instance uniforms as a C-contiguous float64 (N,) array (None stays None)."""
    if a is None:
        return None
    if np.iscomplexobj(a):
        raise FibrefitError("instance: complex values; expected real numbers in [0, 1)")
    try:
        arr = np.ascontiguousarray(a, dtype=np.float64)
    except (TypeError, ValueError) as e:
        raise FibrefitError(f"instance: not an array of numbers ({e})") from None
    if arr.ndim == 0:
        arr = arr.reshape(1)
    if arr.ndim != 1:
        raise FibrefitError(f"instance: expected an (N,) array, got shape {arr.shape}")
    return arr


class Material:
    """A fitted material: BRDF, importance sampler and pdf (see the module docs for frames).

    Load one with :func:`load` or :meth:`Result.material`. Every method takes arrays of N rows,
    runs without the GIL and in parallel.
    """

    def __init__(self, native: "_native.Material"):
        self._m = native

    def eval(self, l: Any, v: Any, uv: Any = None, instance: Any = None) -> np.ndarray:
        """The BRDF f(l, v) in 1/sr: an (N, C) array (C = 3 for RGB results, 1 for grey).

        ``l``, ``v``: (N, 3) unit vectors (light, view); ``uv``: (N, 2) texture coordinates
        into the maps (None: the global parameters). Zero where either direction is at or
        below the horizon. ``instance``: (N,) uniforms in [0, 1), each picking one instance of
        the material (see :attr:`instances`): that instance's value.
        """
        return self._m.eval(
            _f64("l", l, 3), _f64("v", v, 3), None if uv is None else _f64("uv", uv, 2), _instance(instance)
        )

    def sample(
        self, v: Any, u: Any, uv: Any = None, instance: Any = None
    ) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Importance-sample light directions for views ``v`` from uniforms ``u`` ((N, 2) in [0, 1)).

        Returns ``(l, weight, pdf)``: ``l`` (N, 3) unit vectors, ``weight`` (N, C) =
        f(l, v) cos(theta_l) / pdf, ``pdf`` (N,) in 1/sr (solid angle). A failed sample (the view
        or the sampled direction below the horizon) has l = 0, weight 0, pdf 0.

        ``instance``: (N,) uniforms in [0, 1). A material with a fibre-direction spread or a
        height histogram mixes :attr:`instances` instances (fibres turned by one spread node, at
        one height); each row then draws from, and is weighed by, the instance its uniform
        picks (f and pdf of that instance: :meth:`eval` and :meth:`pdf` with the same
        uniform). The mean is the material's, the cost that of one instance (16-256 times
        less), the variance larger (``reports/sampling.md``). Use one uniform per shading point
        for its light samples and its BSDF sample alike.
        """
        return self._m.sample(
            _f64("v", v, 3), _f64("u", u, 2), None if uv is None else _f64("uv", uv, 2), _instance(instance)
        )

    def pdf(self, v: Any, l: Any, uv: Any = None, instance: Any = None) -> np.ndarray:
        """The density (1/sr) with which :meth:`sample` picks ``l`` given ``v``: an (N,) array
        (with ``instance``: the density of each row's instance's sampler)."""
        return self._m.pdf(
            _f64("v", v, 3), _f64("l", l, 3), None if uv is None else _f64("uv", uv, 2), _instance(instance)
        )

    @property
    def instances(self) -> int:
        """How many instances the material mixes: a fibre-direction spread's nodes times a
        height histogram's heights (1: none)."""
        return self._m.instances

    def render_capture(self, capture_toml: PathLike, image_index: int) -> np.ndarray:
        """Image ``image_index`` of a capture as this material renders it, noise-free: an
        (H, W, C) float32 array of radiance per unit irradiance (exposure applied, as
        ``fibrefit.mitsuba.captured_image``), the maps looked up at each pixel's texel."""
        return self._m.render_capture(_os.fspath(capture_toml), _image_index(image_index))

    @property
    def model(self) -> str:
        """The rung's id, e.g. ``"varying-topology"``."""
        return self._m.model

    @property
    def channels(self) -> int:
        """3 for RGB results, 1 for grey."""
        return self._m.channels

    @property
    def has_maps(self) -> bool:
        """Whether per-texel maps are looked up at ``uv``."""
        return self._m.has_maps

    def texel_fields(self) -> Optional[Dict[str, Any]]:
        """What :meth:`eval` reads at each texel of the result's per-texel maps or topology map
        (texel x = floor(u W), y = floor((1 - v) H), clamped; row 0 the top row), for renderers
        that look it up themselves: ``width``, ``rows`` and, per texel row by row, ``height``
        (fibre radii; NaN: the spot's height distribution), ``kd``, ``ks``, ``substrate``
        ((W H, 3)) and ``azimuth_offset`` (radians from ``fibre_azimuth_deg``, turning the
        fibres towards N x T). None without maps, with lobe maps (roughness, anisotropy), or
        with a topology map on another grid than the maps'."""
        return self._m.texel_fields()

    @property
    def maps_size(self) -> Optional[Tuple[int, int]]:
        """(width, height) of the maps in texels, or None."""
        return self._m.maps_size

    @property
    def fibre_azimuth_deg(self) -> float:
        """The global fibre direction, degrees from x towards y."""
        return self._m.fibre_azimuth_deg

    @property
    def source(self) -> str:
        return self._m.source

    @property
    def warnings(self) -> List[str]:
        """Notes made while loading (parameters the rung does not use, maps not found, values
        the data did not determine)."""
        return list(self._m.warnings)

    @property
    def undetermined(self) -> Dict[str, str]:
        """The result's values its data did not determine, label -> why (at a bound, held by a
        degeneracy, a flat cost): the material uses them as given, but they are not
        measurements."""
        return dict(self._m.undetermined)

    def __repr__(self) -> str:
        return repr(self._m)


def load(result_json: PathLike, maps: Optional[PathLike] = None, capture: Optional[PathLike] = None) -> Material:
    """The material of a ``fibrefit fit`` result (or a parameter file).

    ``maps``: the directory of per-texel maps (``fit --maps``); default: the one the result
    names, looked for beside it. ``capture``: a capture TOML whose per-texel fields (its
    tangent or fibre-azimuth map, its height map) fill in where the result has no maps, so the
    capture renders as it was fitted.
    """
    return Material(
        _native.load(
            _os.fspath(result_json),
            None if maps is None else _os.fspath(maps),
            None if capture is None else _os.fspath(capture),
        )
    )


def _native_call(f: Any, *args: Any, **kwargs: Any) -> Any:
    """A call of the native layer; an argument of the wrong type or range (the TypeError or
    OverflowError of the conversion, naming the argument) is a FibrefitError, as every other
    bad input."""
    try:
        return f(*args, **kwargs)
    except (TypeError, OverflowError) as e:
        # the conversion names the argument in a note: "while processing 'stride'"
        names = [m.group(1) for n in getattr(e, "__notes__", []) for m in [_re.search(r"processing '(\w+)'", n)] if m]
        if names and names[0] in kwargs:
            raise FibrefitError(f"{names[0]} = {kwargs[names[0]]!r}: {e}") from None
        raise FibrefitError(f"{', '.join(names) + ': ' if names else ''}{e}") from None


def _path(p: Optional[PathLike]) -> Optional[str]:
    return None if p is None else _os.fspath(p)


def load_data(
    path: PathLike,
    *,
    stride: Optional[int] = None,
    fraction: Optional[float] = None,
    subsample_seed: Optional[int] = None,
    directions: Optional[int] = None,
    direction_seed: Optional[int] = None,
    max_theta: Optional[float] = None,
    skip_bad_rows: bool = False,
    small_angles_ok: bool = False,
    columns: Optional[Dict[str, str]] = None,
    angles: Optional[str] = None,
) -> Dict[str, Any]:
    """The samples of a goniometric table (``.csv``, ``.tsv``, ``.txt``, ``.dat``), capture TOML
    or measured-BRDF file as numpy arrays.

    Keys: ``l``, ``v`` ((N, 3) unit vectors), ``theta_i``, ``phi_i``, ``theta_o``, ``phi_o``
    (degrees), ``value`` ((N, C) BRDF, 1/sr), ``sigma`` ((N, C) or None), ``weight``,
    ``fibre_azimuth_deg`` (NaN where the file gives none), ``origin`` (CSV line, or
    (image, x, y) per pixel), ``channels``, ``kind``, ``source``, ``image_size``.
    The loading flags as the command line's (see the module docs): ``stride``, ``fraction``,
    ``subsample_seed`` (captures), ``directions``, ``direction_seed``, ``max_theta`` (measured
    files), ``skip_bad_rows``, ``small_angles_ok``, ``columns``, ``angles`` (``"deg"`` or
    ``"rad"``; goniometric tables).
    """
    return _native_call(
        _native.load_data,
        _os.fspath(path),
        stride=stride,
        fraction=fraction,
        subsample_seed=subsample_seed,
        directions=directions,
        direction_seed=direction_seed,
        max_theta=max_theta,
        skip_bad_rows=skip_bad_rows,
        small_angles_ok=small_angles_ok,
        columns=columns,
        angles=angles,
    )


@_dataclass
class Parameter:
    """One fitted parameter, in lmfit's vocabulary.

    ``value`` and ``stderr`` are floats, or (3,) arrays for RGB albedos; ``stderr`` is None
    for fixed parameters. ``correl`` maps other parameters' names to the correlation
    coefficient with this one.
    """

    name: str
    value: Union[float, np.ndarray]
    stderr: Optional[Union[float, np.ndarray]]
    min: float
    max: float
    vary: bool
    at_bound: bool
    correl: Dict[str, float] = _field(default_factory=dict)
    #: False when the data do not determine the value (for an RGB albedo, when any channel's is
    #: not): at a bound, held by a degeneracy, or the cost is flat along it. ``value`` is then
    #: the value used, not a measurement; ``undetermined_reason`` says why.
    determined: bool = True
    #: Why not (per channel for an RGB albedo: a list of str or None), else None.
    undetermined_reason: Optional[Union[str, List[Optional[str]]]] = None


def _any_false(x: Any) -> bool:
    return any(v is False for v in x) if isinstance(x, list) else x is False


def _number(x: Any) -> Any:
    if isinstance(x, list):
        return np.array(x, dtype=float)
    return x if x is None else float(x)


class Result:
    """A finished fit (:func:`fit`): ``params``, ``report()``, ``to_json(path)``, ``material()``."""

    def __init__(self, native: "_native.FitResult"):
        self._r = native
        self.result: Dict[str, Any] = _json.loads(native.json())
        corr: Dict[str, Dict[str, float]] = {}
        for c in self.result.get("correlations", []):
            corr.setdefault(c["a"], {})[c["b"]] = c["r"]
            corr.setdefault(c["b"], {})[c["a"]] = c["r"]
        self.params: Dict[str, Parameter] = {}
        for name, p in self.result["parameters"].items():
            fixed = bool(p.get("fixed", False))
            self.params[name] = Parameter(
                name=name,
                value=_number(p["value"]),
                stderr=None if fixed else _number(p.get("std_error")),
                min=float(p["min"]),
                max=float(p["max"]),
                vary=not fixed,
                at_bound=bool(p.get("at_bound", False)),
                correl=corr.get(name, {}),
                # absent for fixed parameters and in results written before it existed
                determined=not _any_false(p.get("determined", True)),
                undetermined_reason=p.get("undetermined_reason"),
            )

    @property
    def model(self) -> str:
        """The fitted rung's id (auto's choice for ``model="auto"``)."""
        return self._r.model

    @property
    def statistics(self) -> Dict[str, Any]:
        """RMSE, relative RMSE, reduced chi-square, ... as in the result JSON."""
        return self.result["statistics"]

    @property
    def warnings(self) -> List[str]:
        """What the fit's quality checks and stages found (printed by the CLI)."""
        return list(self._r.warnings)

    @property
    def verdict(self) -> str:
        """With sigmas "fits within the noise" or "does not fit within the noise"; without,
        judged by the floor: "within 1.2x of what the data allow" or "misses structure the data
        hold: ..." (where, in words)."""
        return self._r.verdict

    @property
    def floor(self) -> Optional[float]:
        """What the data themselves allow: a nonparametric predictor's held-out error on the
        model's own held-out samples, in the fit's metric (``None`` for per-texel maps). The
        details, and where the model's excess lies: ``result["quality"]["floor"]``."""
        return self._r.floor

    @property
    def floor_ratio(self) -> Optional[float]:
        """The model's held-out error over the floor (within 1.2: as good as the data allow)."""
        return self._r.floor_ratio

    @property
    def reciprocal_floor(self) -> Optional[float]:
        """Where the floor's predictor is not reciprocal and the model is beyond 1.2x the floor,
        the same predictor made reciprocal (each training sample also standing for its pair with
        light and view swapped): what any material, a reciprocal BRDF, can reach. Above 1.2x the
        floor the data are not reciprocal (a measurement's light and view responses differ), and
        a model within 1.2x of this is "within 1.2x of what a material can reach". ``None`` where
        the floor is reciprocal already, the model within 1.2x of it, or no floor was measured;
        details in ``result["quality"]["floor"]["reciprocal"]``."""
        return self._r.reciprocal_floor

    @property
    def correction(self) -> Optional[Dict[str, float]]:
        """The smooth reciprocal correction kept on the rung where the rung missed what the data
        hold and the correction paid held out: ``{"degree", "heldout_error", "rung_heldout_error",
        "material_heldout_error", "instrument_terms"}`` (log metric); ``None`` when none was kept.
        Not a physical parameter: the rung's BRDF per channel times exp(a Legendre series in cos
        theta_i, cos theta_o, cos dphi), symmetric in light and view. Beside it the fit models
        the instrument's light/view imbalance (``instrument_terms`` per channel; what of the data
        is not reciprocal): ``heldout_error`` is the model of the measurement's,
        ``material_heldout_error`` the material's alone. ``Material`` of the result applies the
        series, never the instrument's terms (eval, sample); the coefficients are
        ``result["correction"]["series"]``."""
        c = self._r.correction
        if c is None:
            return None
        return {
            "degree": c[0],
            "heldout_error": c[1],
            "rung_heldout_error": c[2],
            "material_heldout_error": c[3],
            "instrument_terms": c[4],
        }

    @property
    def undetermined(self) -> Dict[str, str]:
        """The values the data do not determine, label (``"spacing"``, ``"kd[b]"``) -> why (at a
        bound, held by a degeneracy, or a flat cost): the fit used them, but they are not
        measurements. Empty when the data determine every free value."""
        return {u["label"]: u["reason"] for u in self.result.get("quality", {}).get("undetermined", [])}

    @property
    def has_maps(self) -> bool:
        return self._r.has_maps

    def report(self) -> str:
        """The fit report, as ``fibrefit fit`` prints it (lmfit's layout)."""
        return self._r.report()

    def to_json(self, path: PathLike, report: Optional[PathLike] = None) -> None:
        """Write the result JSON (atomically; never over an input), the maps into the directory
        given to ``fit(maps=...)``, and a report directory when ``report`` is given."""
        self._r.to_json(_os.fspath(path), None if report is None else _os.fspath(report))

    def material(self) -> Material:
        """The fitted material (with its maps once :meth:`to_json` has written them)."""
        return Material(self._r.material())

    def __repr__(self) -> str:
        s = self.statistics
        # without sigmas chi-square is not defined: the residual variance, by its own name
        spread = "reduced_chi_square" if s.get("sigmas_given") else "residual_variance"
        return (
            f"Result(model={self.model!r}, samples={self.result['data']['samples']}, "
            f"{spread}={s.get(spread)}, undetermined={len(self.undetermined)}, "
            f"warnings={len(self.warnings)})"
        )


def fit(
    data: Any = None,
    config: Optional[PathLike] = None,
    model: Optional[str] = None,
    *,
    l: Any = None,
    v: Any = None,
    values: Any = None,
    sigma: Any = None,
    metric: Optional[str] = None,
    fuzz: Optional[bool] = None,
    maps: Optional[PathLike] = None,
    progress: bool = False,
    threads: Optional[int] = None,
    gltf_variant: Optional[str] = None,
    correction: Optional[bool] = None,
    stride: Optional[int] = None,
    fraction: Optional[float] = None,
    subsample_seed: Optional[int] = None,
    directions: Optional[int] = None,
    direction_seed: Optional[int] = None,
    max_theta: Optional[float] = None,
    skip_bad_rows: bool = False,
    small_angles_ok: bool = False,
    columns: Optional[Dict[str, str]] = None,
    angles: Optional[str] = None,
) -> Result:
    """Fit measurements, as ``fibrefit fit`` does.

    The measurements: ``data``, a file (goniometric table ``.csv``/``.tsv``/``.txt``/``.dat``,
    capture TOML, RGL ``.bsdf`` or MERL ``.binary``) or a pandas DataFrame with a table's
    columns (``theta_i, phi_i, theta_o, phi_o`` in degrees, ``brdf`` or ``brdf_r, brdf_g,
    brdf_b``, optional ``sigma``...; ``columns`` and ``angles`` map and convert them as for a
    file; errors name the table's line: line 1 is the header, line k + 2 the row at position
    k); or numpy arrays ``l``, ``v`` ((N, 3) unit directions towards the light and the viewer,
    swatch frame, normal +z), ``values`` ((N,) or (N, 3) BRDF values in 1/sr) and optionally
    ``sigma`` ((N,) or as ``values``, 1/sr).

    ``config``: a fit config TOML (``configs/fit_*.toml``); ``model``: a rung id or ``"auto"``
    (overrides the config's; needed without a config); ``metric``: ``"linear"``, ``"log"`` or
    ``"cosine"``; ``fuzz``: ``True`` adds the fuzz layer (to the rung, or to every candidate of
    ``"auto"``), ``False`` leaves it out (``--no-fuzz``), ``None`` the config's or the default
    (``"auto"`` tries each rung without and with it); ``maps``: a directory for per-texel maps
    (captures; written by :meth:`Result.to_json`); ``progress``: progress bars on stderr;
    ``threads``: worker threads (``None``: one per core, or ``RAYON_NUM_THREADS``);
    ``gltf_variant``: the ``gltf`` rung's, ``"khronos"`` (the Khronos specification) or
    ``"threejs"`` (what stock three.js r187 renders; ``--gltf-variant``), ``None`` the config's
    ``knobs.gltf_variant`` or ``"khronos"``; ``correction``: ``False`` never fits a smooth
    correction on the rung (``--no-correction``), ``None`` the config's (by default one is kept
    where the rung misses what data without sigmas hold and it pays held out:
    :attr:`Result.correction`). The loading
    flags as :func:`load_data`'s; ``stride``, ``fraction``, ``columns`` and ``angles`` merged
    with the config's as the command line merges them (the library does it, once for both).
    """
    table = None
    if hasattr(data, "to_csv") and hasattr(data, "columns"):
        # a DataFrame is read as the table it holds, by the same reader as a file
        table, data = data.to_csv(index=False), None
    elif data is not None and not isinstance(data, (str, bytes, _os.PathLike)):
        raise FibrefitError(
            f"data: expected a file path or a pandas DataFrame, got {type(data).__name__} "
            "(arrays go in l, v, values and sigma)"
        )
    arrays: Dict[str, Any] = {}
    if l is not None:
        arrays["l"] = _f64("l", l, 3)
    if v is not None:
        arrays["v"] = _f64("v", v, 3)
    for name, a in (("values", values), ("sigma", sigma)):
        if a is not None:
            arrays[name] = _values(name, a)
    return Result(
        _native_call(
            _native.fit,
            None if data is None else _os.fspath(data),
            _path(config),
            model,
            table=table,
            metric=metric,
            fuzz=fuzz,
            maps=_path(maps),
            progress=progress,
            threads=threads,
            gltf_variant=gltf_variant,
            correction=correction,
            stride=stride,
            fraction=fraction,
            subsample_seed=subsample_seed,
            directions=directions,
            direction_seed=direction_seed,
            max_theta=max_theta,
            skip_bad_rows=skip_bad_rows,
            small_angles_ok=small_angles_ok,
            columns=columns,
            angles=angles,
            **arrays,
        )
    )


def _values(name: str, a: Any) -> np.ndarray:
    """`a` as a C-contiguous float64 (N,) or (N, C) array."""
    if np.iscomplexobj(a):
        raise FibrefitError(f"{name}: complex values; expected real numbers")
    try:
        arr = np.ascontiguousarray(a, dtype=np.float64)
    except (TypeError, ValueError) as e:
        raise FibrefitError(f"{name}: not an array of numbers ({e})") from None
    if arr.ndim not in (1, 2):
        raise FibrefitError(f"{name}: expected an (N,) or (N, C) array, got shape {arr.shape}")
    return arr


class Score:
    """A result scored on data (:func:`score`): ``result`` is the score as ``fibrefit score
    --json`` prints it (a dict: ``model``, ``samples``, ``statistics``, ``channels``,
    ``residual_bins``, ``verdict``, ``noise``, ``floor``), ``report()`` the text ``fibrefit score``
    prints."""

    def __init__(self, json_text: str, text: str):
        self.result: Dict[str, Any] = _json.loads(json_text)
        self._text = text

    @property
    def statistics(self) -> Dict[str, Any]:
        """RMSE, relative RMSE, chi-square, ... of the result on these data."""
        return self.result["statistics"]

    @property
    def verdict(self) -> str:
        """"fits within the noise" or "does not fit within the noise" (sigmas, neighbouring
        pixels); without sigmas, judged by the floor: "within 1.2x of what the data allow" or
        "misses structure the data hold: ..."."""
        return self.result["verdict"]

    @property
    def floor(self) -> Optional[float]:
        """What these data themselves allow (a nonparametric predictor, cross-validated on
        them, in the result's metric); ``None`` for captures."""
        f = self.result.get("floor")
        return None if f is None else f["floor"]

    @property
    def floor_ratio(self) -> Optional[float]:
        """The result's error on these data over their floor."""
        f = self.result.get("floor")
        return None if f is None else f["ratio"]

    def report(self) -> str:
        """The score as ``fibrefit score`` prints it."""
        return self._text

    def __repr__(self) -> str:
        return f"Score(model={self.result['model']!r}, samples={self.result['samples']}, verdict={self.verdict!r})"


def score(
    result_json: PathLike,
    data: PathLike,
    *,
    stride: Optional[int] = None,
    fraction: Optional[float] = None,
    subsample_seed: Optional[int] = None,
    directions: Optional[int] = None,
    direction_seed: Optional[int] = None,
    max_theta: Optional[float] = None,
    skip_bad_rows: bool = False,
    small_angles_ok: bool = False,
    columns: Optional[Dict[str, str]] = None,
    angles: Optional[str] = None,
) -> Score:
    """A fitted result evaluated exactly as the fit did (rung, knobs, topology map, residual
    metric) on ``data`` (goniometric CSV or capture TOML), as ``fibrefit score``. The loading
    flags as :func:`load_data`'s."""
    return Score(
        *_native_call(
            _native.score,
            _os.fspath(result_json),
            _os.fspath(data),
            stride=stride,
            fraction=fraction,
            subsample_seed=subsample_seed,
            directions=directions,
            direction_seed=direction_seed,
            max_theta=max_theta,
            skip_bad_rows=skip_bad_rows,
            small_angles_ok=small_angles_ok,
            columns=columns,
            angles=angles,
        )
    )


def eval(
    params: PathLike, queries: PathLike, model: Optional[str] = None, *, progress: bool = False
) -> Tuple[np.ndarray, np.ndarray]:
    """A model's BRDF and intensity at the directions of a query CSV, as ``fibrefit eval``.

    ``params``: a parameter file (TOML or JSON) or a result JSON; ``queries``: a CSV of
    ``theta_i,phi_i,theta_o,phi_o`` (degrees) with optional per-texel columns (``height``,
    ``fibre_azimuth_deg``, ``kd``, ``ks``; see ``fibrefit eval --help``); ``model``: a rung id
    overriding the file's; ``progress``: the bar and the parameter file's warnings on stderr.
    Returns ``(brdf, intensity)``: (N, C) arrays in 1/sr, intensity = f cos(theta_i) (C = 3 for
    RGB parameters or albedo columns, else 1), the values of ``fibrefit eval``'s table.
    """
    return _native_call(_native.eval, _os.fspath(params), _os.fspath(queries), model, progress=progress)


@_dataclass
class Exported:
    """What :func:`export` built: ``model`` (the rung's id), ``shader`` (the source, or None),
    ``glb`` (the GLB file's bytes, or None), ``gltf_material`` (the glTF material: ``route``
    ``"fitted"`` for a ``gltf`` fit written exactly, with ``metallic``, ``specular_factor`` and its
    errors against the data; ``"converted"`` for a material fitted to another model, with its
    errors against the model; both with ``base_color``, ``roughness``, ``anisotropy_strength``,
    ``anisotropy_rotation_rad``, ``ior``, ``sheen``; or None), ``textures`` (the maps the GLB's
    textures were made from: ``directory``, ``width``, ``height``, ``names``; or None) and
    ``undetermined`` (the result's values its data did not determine, label -> reason: the
    exports use them as given, and the shader's header and the GLB's ``extras`` say so)."""

    model: str
    shader: Optional[str]
    glb: Optional[bytes]
    gltf_material: Optional[Dict[str, Any]]
    textures: Optional[Dict[str, Any]]
    undetermined: Dict[str, str] = _field(default_factory=dict)


def export(
    result_json: PathLike,
    shader: Optional[str] = None,
    gltf: bool = False,
    object: str = "swatch",
    check: bool = False,
    model: Optional[str] = None,
    *,
    progress: bool = False,
) -> Exported:
    """The fitted model as shader source and as a glTF material on a preview mesh, built in
    memory as ``fibrefit export`` builds them (write ``Exported.shader`` and ``Exported.glb``
    where you like).

    ``shader``: ``"wgsl"``, ``"glsl"``, ``"hlsl"`` or ``"msl"`` (None: no shader); ``gltf``: a
    GLB preview; ``object``: its mesh (``"swatch"``, ``"sphere"``, ``"torus"`` or an ``.obj``
    path); ``check``: run the shader on the GPU driver against the Rust model first (refused:
    this package is built without a GPU driver; the command line has it); ``model``: a rung id
    overriding the file's; ``progress``: notes and warnings on stderr.
    """
    d = _native_call(
        _native.export,
        _os.fspath(result_json),
        shader,
        gltf,
        _os.fspath(object),
        check,
        model,
        progress=progress,
    )
    return Exported(**d)


def view(
    result_json: PathLike,
    out: Optional[PathLike] = None,
    data: Optional[PathLike] = None,
    *,
    progress: bool = False,
) -> str:
    """The viewer page of a fitted result (or parameter file), as ``fibrefit view RESULT --out
    OUT [--data DATA]`` writes it: one self-contained HTML file with a WebGL2 viewer (the exact
    model through its exported shader beside the glTF route's material), the measured against
    the fitted BRDF at the light (for data with enough directions), the parameter table, the
    verdict and the warnings (docs/guide/view.md).

    ``out``: the page (default: ``result_json`` with the extension ``.html``; never an input);
    ``data``: the measurements to compare with (default: the data file the result names, beside
    it); ``progress``: notes and warnings on stderr. Returns the path written.
    """
    path = _native_call(
        _native.view,
        _os.fspath(result_json),
        None if out is None else _os.fspath(out),
        None if data is None else _os.fspath(data),
        progress=progress,
    )
    return _os.fspath(path)


def board(
    out: PathLike,
    *,
    paper: str = "a4",
    window_mm: float = 60.0,
    dpi: int = 300,
    patch_reflectance: float = 0.5,
) -> List[str]:
    """The printable calibration board, as ``fibrefit board --out OUT`` writes it:
    ``board.png`` (print at 100 %, check the 100 mm scale bar) and ``board.toml`` (the
    markers, window, reference patch and scale bar in mm in the board frame;
    docs/guide/photograph.md). Returns the paths written."""
    paths = _native_call(
        _native.board,
        _os.fspath(out),
        paper=paper,
        window_mm=window_mm,
        dpi=dpi,
        patch_reflectance=patch_reflectance,
    )
    return [_os.fspath(p) for p in paths]


def calibrate(
    board: PathLike,
    photos: Sequence[PathLike],
    out: PathLike,
    *,
    flash_offset_mm: Tuple[float, float, float] = (10.0, 0.0, 0.0),
    texels: Optional[Tuple[int, int]] = None,
    px_per_mm: Optional[float] = None,
    intrinsics: Optional[PathLike] = None,
    lights: Optional[PathLike] = None,
    encoding: str = "srgb",
    progress: bool = False,
) -> Tuple[str, str]:
    """Photos of a swatch on the printed board made into a capture, as ``fibrefit calibrate
    --board BOARD --out OUT PHOTO...``: the markers found, the camera's intrinsics and every
    photo's pose calibrated, the photos rectified onto the window's texels with absolute values
    from the reference patch, and ``OUT/capture.toml`` written (``fit(OUT/capture.toml, ...)``
    runs on it), with ``cam.toml`` (reuse as ``intrinsics``) and ``report/``. ``texels`` (default
    128 x 128) or ``px_per_mm`` (texels per millimetre of the window) set the grid; ``lights``
    is the ``--lights`` TOML (lamps at measured positions, ambient frames to subtract);
    ``encoding`` is "srgb" or "linear" for PNG and TIFF photos; camera RAW photos (DNG, CR2,
    NEF, ARW, ...) are decoded to linear values. The camera's noise is estimated from the
    board (each image's ``noise``: the fit's sigmas), and with EXIF exposures the patch is
    pooled over the photos of one light (``scale_rel_se``). A bad photo raises
    FibrefitError naming it, and nothing is written. Returns (the capture file, the report)."""
    capture, report = _native_call(
        _native.calibrate,
        _os.fspath(board),
        [_os.fspath(p) for p in photos],
        _os.fspath(out),
        flash_offset_mm=tuple(float(v) for v in flash_offset_mm),
        texels=None if texels is None else tuple(int(v) for v in texels),
        px_per_mm=None if px_per_mm is None else float(px_per_mm),
        intrinsics=_path(intrinsics),
        lights=_path(lights),
        encoding=encoding,
        progress=progress,
    )
    return _os.fspath(capture), report
