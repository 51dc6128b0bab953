"""Blender: a ``principled`` fit as a Principled BSDF material, made in the running Blender.

``material(result, name=None)`` runs, in this Python's ``bpy`` (inside Blender, or the ``bpy``
module from PyPI), the script ``fibrefit export RESULT --blender FILE.py --name NAME`` writes:
it makes the material ``name`` (default: the result's file stem), or rebuilds it in place when
it exists (its users keep it), with a Principled BSDF carrying the fit's values exactly (the
``principled`` rung is that node as Cycles evaluates it) and a Tangent node (UV map) so the
fibres lie at the fit's ``fibre_azimuth_deg`` from the UV u axis. Returns the
``bpy.types.Material``. ``script(result, name=None, out=None)`` returns the script's text and
what it sets, without Blender (and writes it to ``out`` with its textures, as the CLI does).

A ``fit --maps`` result's maps become Image Texture nodes (Closest, Non-Color) driving Base
Color, Roughness, Anisotropic and Anisotropic Rotation texel by texel, read from RGB float EXRs
beside the script: ``material`` writes the script and its textures into ``textures_dir``
(default: the result's folder) as ``<name>.py`` and ``<name>_<input>.exr``.
"""

from __future__ import annotations

import os
import re
from typing import Any, Dict, Optional

from . import _native


def script(result: str, name: Optional[str] = None, out: Optional[str] = None) -> Dict[str, Any]:
    """The Blender script for ``result`` (a ``principled`` fit without the fuzz layer, or any
    other fit's result, whose ``renderer_materials`` hold the ``principled`` material fitted to
    the same data): a dict
    with ``script`` (Python source), ``name``, ``inputs`` (the Principled BSDF's inputs it
    sets, by Blender's names), ``textures`` (a maps fit's: input -> ``file``, ``path`` and
    ``pixels``, an (H, W, 3) float32 array; empty otherwise), ``fibre_azimuth_deg`` and
    ``error_text`` (the fit's error against its data). ``out`` (a ``.py`` path): also write the
    script there and the textures beside it, as ``fibrefit export --blender`` does. Raises
    ``FibrefitError`` with the command line's message otherwise."""
    return _native.blender_script(str(result), name, None if out is None else os.fspath(out))


def material(result: str, name: Optional[str] = None, textures_dir: Optional[str] = None):
    """Make (or rebuild in place) the Blender material of ``result`` in the running ``bpy``;
    returns the ``bpy.types.Material``. A maps fit's script and textures are written into
    ``textures_dir`` (default: the result's folder) first, named after the material."""
    try:
        import bpy  # noqa: F401  (the script imports it; fail here with a clear message)
    except ImportError as e:  # pragma: no cover - depends on the environment
        raise ImportError(
            "fibrefit.blender.material needs Blender's Python module `bpy` (run it inside "
            "Blender, or `pip install bpy` on Python 3.11)"
        ) from e
    s = script(result, name)
    if s["textures"]:
        folder = textures_dir if textures_dir is not None else os.path.dirname(os.path.abspath(result))
        stem = re.sub(r"[^A-Za-z0-9_.-]", "_", s["name"]) or "material"
        s = script(result, name, out=os.path.join(folder, stem + ".py"))
    namespace: Dict[str, Any] = {"__name__": "fibrefit_blender_material"}
    exec(compile(s["script"], f"<fibrefit blender material {s['name']}>", "exec"), namespace)
    return namespace["MATERIAL"]
