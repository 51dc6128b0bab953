#!/usr/bin/env python3
"""The GLSL ES 3.00 (WebGL2) shaders MaterialX generates for a material of a MaterialX document,
with one directional light bound (the environment is set to black by the caller), and the values of the uniforms MaterialX
sets from the document: what a WebGL renderer of the document runs (MaterialX's own viewer
does the same). Used by tests/browser/materialx.mjs to render `fibrefit export --materialx`
documents.

Usage: materialx_essl.py DOC.mtlx MATERIAL > shaders.json
Writes {"vertex": ..., "pixel": ..., "uniforms": [[name, type, value], ...]}; needs the
`materialx` package (1.39).
"""

import json
import sys

import MaterialX as mx
import MaterialX.PyMaterialXGenGlsl as mx_glsl
import MaterialX.PyMaterialXGenShader as mx_gen


def main(path, name):
    lib = mx.createDocument()
    mx.loadLibraries(mx.getDefaultDataLibraryFolders(), mx.getDefaultDataSearchPath(), lib)
    doc = mx.createDocument()
    mx.readFromXmlFile(doc, path)
    doc.setDataLibrary(lib)
    ok, message = doc.validate()
    if not ok:
        sys.exit(f"{path}: not a valid MaterialX document: {message}")
    material = doc.getChild(name)
    if material is None:
        sys.exit(f"{path}: no material named {name}")
    gen = mx_glsl.EsslShaderGenerator.create()
    ctx = mx_gen.GenContext(gen)
    ctx.registerSourceCodeSearchPath(mx.getDefaultDataSearchPath())
    opts = ctx.getOptions()
    opts.hwMaxActiveLightSources = 1
    opts.hwSpecularEnvironmentMethod = mx_gen.HwSpecularEnvironmentMethod.SPECULAR_ENVIRONMENT_FIS
    opts.hwShadowMap = False
    opts.hwSrgbEncodeOutput = False
    # light type 1: a directional light, as MaterialX's viewer binds it
    mx_gen.HwShaderGenerator.bindLightShader(lib.getNodeDef("ND_directional_light"), 1, ctx)
    shader = gen.generate("fibrefit", material, ctx)
    uniforms = []
    for stage in [mx_gen.PIXEL_STAGE, mx_gen.VERTEX_STAGE]:
        for block in shader.getStage(stage).getUniformBlocks().values():
            for i in range(block.size()):
                v = block[i]
                value = v.getValue()
                if value is None:
                    continue
                value = value.getData()
                if isinstance(value, mx.Matrix44):
                    value = [value[i, j] for i in range(4) for j in range(4)]
                elif hasattr(value, "__len__"):
                    value = list(value)
                uniforms.append([v.getVariable(), v.getType().getName(), value])
    json.dump(
        {
            "vertex": shader.getSourceCode(mx_gen.VERTEX_STAGE),
            "pixel": shader.getSourceCode(mx_gen.PIXEL_STAGE),
            "uniforms": uniforms,
        },
        sys.stdout,
    )


if __name__ == "__main__":
    if len(sys.argv) != 3:
        sys.exit(__doc__)
    main(sys.argv[1], sys.argv[2])
