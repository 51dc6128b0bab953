"""MaterialX and USD: an ``openpbr`` fit as an OpenPBR Surface material.

``document(result, name=None)`` is the MaterialX 1.39 document ``fibrefit export RESULT
--materialx FILE.mtlx --name NAME`` writes: an ``open_pbr_surface`` carrying the fit's values
exactly (the ``openpbr`` rung is that node as MaterialX implements it), its tangent the UV
tangent turned about the normal so the fibres lie at the fit's ``fibre_azimuth_deg`` from u.
``usda(result, name=None)`` is the USD stage ``--usd FILE.usda`` writes (the same network as the
material's MaterialX surface, a UsdPreviewSurface fallback, a swatch bound to it).
``material(result, name=None)`` returns both with what they set, as a dict.
"""

from __future__ import annotations

from typing import Any, Dict, Optional

from . import _native


def material(result: str, name: Optional[str] = None) -> Dict[str, Any]:
    """The OpenPBR material of ``result`` (an ``openpbr`` fit without the fuzz layer, or any
    other fit's result, whose ``renderer_materials`` hold the ``openpbr`` material fitted to
    the same data): a dict
    with ``document`` (MaterialX), ``usda`` (USD), ``name``, ``inputs`` (the OpenPBR Surface
    inputs set, by OpenPBR's names), ``tangent_rotation_deg``, ``fibre_azimuth_deg``,
    ``preview_roughness`` and ``error_text`` (the fit's error against its data). Raises
    ``FibrefitError`` with the command line's message otherwise."""
    return _native.openpbr_material(str(result), name)


def document(result: str, name: Optional[str] = None) -> str:
    """The MaterialX document (text) of ``result``."""
    return material(result, name)["document"]


def usda(result: str, name: Optional[str] = None) -> str:
    """The USD stage (usda text) of ``result``."""
    return material(result, name)["usda"]
