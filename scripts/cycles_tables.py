#!/usr/bin/env python3
"""Write src/model/rungs/principled/cycles_tables.rs: the four tables of Blender 5.0's Cycles
that its Principled BSDF reads (intern/cycles/scene/shader.tables: table_ggx_E, table_ggx_Eavg,
table_ggx_gen_schlick_ior_s, table_sheen_ltc), taken from the `bpy` 5.0.1 module's binary, where
the compiler keeps shader.tables' arrays in reverse order of declaration, back to back:

    ... gen_schlick_s[4096] gen_schlick_ior_s[4096] sheen_ltc[3072] glass_inv_Eavg[256]
        glass_inv_E[4096] glass_Eavg[256] glass_E[4096] ggx_Eavg[32] ggx_E[1024]

ggx_E is found by its first values (1, 0.980405, 0.994967, 0.997749), the rest by the layout;
each is checked by a property of what it is (see `check`). Usage:
    python3 scripts/cycles_tables.py PATH/TO/bpy/__init__.so
"""
import struct
import sys

import numpy as np

so = sys.argv[1]
b = open(so, "rb").read()
e = b.find(struct.pack("<4f", 1.0, 0.980405, 0.994967, 0.997749))
assert e > 0, "table_ggx_E not found"


def at(offset_floats, n):
    s = e + 4 * offset_floats
    return np.frombuffer(b[s : s + 4 * n], dtype="<f4")


ggx_e = at(0, 1024)
ggx_eavg = at(-32, 32)
sheen = at(-32 - 4096 - 256 - 4096 - 256 - 3072, 3072)
ior_s = at(-32 - 4096 - 256 - 4096 - 256 - 3072 - 4096, 4096)


def check():
    # the last row of table_ggx_E and the first of table_ggx_Eavg, as shader.tables prints them
    assert abs(ggx_e[-1] - 0.306853) < 1e-7 and abs(ggx_eavg[1] - 0.999992) < 1e-7
    # gen_schlick_ior_s at roughness 1e-4 (a mirror) is the remapped real Fresnel
    z = 8 / 15
    f0 = z**4
    ior = (1 + z * z) / (1 - z * z)
    mu = np.clip(np.arange(16) / 15, 1e-4, 1)
    g = np.sqrt(ior * ior - 1 + mu * mu)
    a, c = (g - mu) / (g + mu), (mu * (g + mu) - 1) / (mu * (g - mu) + 1)
    f = 0.5 * a * a * (1 + c * c)
    assert np.abs(ior_s.reshape(16, 16, 16)[8, :, 0] - (f - f0) / (1 - f0)).max() < 2e-5
    # every sheen LTC (plane 0: a, plane 1: b) integrates to 1 over the hemisphere
    s = sheen.reshape(3, 32, 32)
    n = 200
    th = (np.arange(n) + 0.5) / n * np.pi / 2
    ph = (np.arange(2 * n) + 0.5) / (2 * n) * 2 * np.pi
    T, P = np.meshgrid(th, ph, indexing="ij")
    x, y, zz = np.sin(T) * np.cos(P), np.sin(T) * np.sin(P), np.cos(T)
    da = (np.pi / 2 / n) * (np.pi / n) * np.sin(T)
    for iy, ix in [(16, 16), (31, 5), (8, 30)]:
        a, bb = float(s[0, iy, ix]), float(s[1, iy, ix])
        l2 = (a * x + bb * zz) ** 2 + (a * y) ** 2 + zz**2
        total = (zz / np.pi * (a / l2) ** 2 * da).sum()
        assert abs(total - 1) < 1e-3, total


check()


def rust(name, doc, a):
    vals = [np.format_float_positional(np.float32(v), unique=True, trim="0") for v in a]
    vals = [v if "." in v else v + ".0" for v in vals]
    lines = []
    for i in range(0, len(vals), 8):
        lines.append("    " + ", ".join(vals[i : i + 8]) + ",")
    return f"/// {doc}\npub static {name}: [f32; {len(a)}] = [\n" + "\n".join(lines) + "\n];\n"


out = [
    "//! Blender 5.0 Cycles' tables that its Principled BSDF reads, as published in\n"
    "//! `intern/cycles/scene/shader.tables` (numbers only; the code that reads them is\n"
    "//! `super`). Written by `scripts/cycles_tables.py` from the `bpy` 5.0.1 module, where the\n"
    "//! compiled arrays are these exactly (the script checks each by what it is). Do not edit.\n\n"
    "#![cfg_attr(rustfmt, rustfmt_skip)]\n"
    "// numbers, not constants (one of them is 0.69314)\n"
    "#![allow(clippy::approx_constant)]\n",
    rust("GGX_E", "`table_ggx_E`: GGX directional albedo E, 32 x 32, x = roughness (sqrt of alpha), y = cos theta.", ggx_e),
    rust("GGX_EAVG", "`table_ggx_Eavg`: its cosine-weighted average over the hemisphere, by roughness.", ggx_eavg),
    rust(
        "GGX_GEN_SCHLICK_IOR_S",
        "`table_ggx_gen_schlick_ior_s`: 16 x 16 x 16, x = roughness, y = cos theta, z = sqrt((ior - 1)/(ior + 1)): the interpolant s of the albedo mix(F0, F90, s).",
        ior_s,
    ),
    rust(
        "SHEEN_LTC",
        "`table_sheen_ltc`: three 32 x 32 planes (LTC a, LTC b, albedo), x = cos theta, y = sheen roughness (Zeltner et al. 2022).",
        sheen,
    ),
]
open("src/model/rungs/principled/cycles_tables.rs", "w").write("\n".join(out))
print("wrote src/model/rungs/principled/cycles_tables.rs")
