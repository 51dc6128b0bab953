"""MaterialX and USD: an ``openpbr`` fit as an OpenPBR Surface material.

``document(result, name=None)`` is the MaterialX 1.39 document ``fibrefit export RESULT
--materialx FILE.mtlx --name NAME`` writes: an ``open_pbr_surface`` carrying the fit's values
exactly (the ``openpbr`` rung is that node as MaterialX implements it), its tangent the UV
tangent turned about the normal so the fibres lie at the fit's ``fibre_azimuth_deg`` from u.
``usda(result, name=None)`` is the USD stage ``--usd FILE.usda`` writes (the same network as the
material's MaterialX surface, a UsdPreviewSurface fallback, a swatch bound to it).
``material(result, name=None, materialx=None, usd=None)`` returns both with what they set, as a
dict, and writes them to the paths given.

A ``fit --maps`` result's maps become image nodes (closest filtering, the UV set) driving
base_color, specular_roughness, specular_roughness_anisotropy and the tangent's rotation texel by
texel, reading RGB float EXRs named ``<stem>_<input>.exr`` beside the document or stage: give
``materialx=`` / ``usd=`` to write them (``document`` and ``usda`` alone name them after the
material and write nothing).
"""

from __future__ import annotations

import os
from typing import Any, Dict, Optional

from . import _native


def material(
    result: str,
    name: Optional[str] = None,
    materialx: Optional[str] = None,
    usd: Optional[str] = None,
) -> Dict[str, Any]:
    """The OpenPBR material of ``result`` (an ``openpbr`` fit without the fuzz layer, or any
    other fit's result, whose ``renderer_materials`` hold the ``openpbr`` material fitted to
    the same data): a dict
    with ``document`` (MaterialX), ``usda`` (USD), ``name``, ``inputs`` (the OpenPBR Surface
    inputs set, by OpenPBR's names), ``tangent_rotation_deg``, ``fibre_azimuth_deg``,
    ``preview_roughness``, ``textures`` (a maps fit's: input -> ``file``, ``path`` and
    ``pixels``, an (H, W, 3) float32 array; empty otherwise) and ``error_text`` (the fit's error
    against its data). ``materialx`` (a ``.mtlx`` path) and ``usd`` (a ``.usda`` path): also
    write the document and the stage there, each with its textures beside it, as ``fibrefit
    export --materialx/--usd`` does. Raises ``FibrefitError`` with the command line's message
    otherwise."""
    fs = lambda p: None if p is None else os.fspath(p)  # noqa: E731
    return _native.openpbr_material(str(result), name, fs(materialx), fs(usd))


def document(result: str, name: Optional[str] = None) -> str:
    """The MaterialX document (text) of ``result``."""
    return material(result, name)["document"]


def usda(result: str, name: Optional[str] = None) -> str:
    """The USD stage (usda text) of ``result``."""
    return material(result, name)["usda"]
