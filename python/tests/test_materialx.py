"""The `openpbr` rung's exports checked by MaterialX and USD themselves: fits of the shipped felt,
silk and brushed data, written as a MaterialX document (``fibrefit.materialx.document``, what
``fibrefit export --materialx`` writes) and a USD stage (``--usd``).

- MaterialX (the ``materialx`` package, 1.39): the document validates against MaterialX's own
  data library, its OpenPBR Surface's values are the result's, and the GLSL MaterialX generates
  from it (pixel and vertex stages) compiles with glslangValidator.
- USD (``usd-core``): the stage opens, every validator usd-core registers passes, the material's
  MaterialX render context and universal surface resolve to the OpenPBR and UsdPreviewSurface
  shaders. usd-core's wheel is built without MaterialX, so its shader registry cannot know
  MaterialX's node definitions (``ND_...``); those shaders are checked against MaterialX's own
  library instead (every id a node definition, every input one of its inputs, of its type).

A ``--maps`` fit's document and stage read its maps as image nodes (closest filtering) driving
base_color, specular_roughness, specular_roughness_anisotropy and the tangent's rotation: they
validate, their GLSL compiles, the files lie beside them (their pixels are the maps' texels:
tests/renderer_lobe_maps.rs).

The renders themselves (the generated shader in WebGL equals the rung) are in
tests/browser/materialx.mjs.

scripts/test.sh installs ``materialx`` and ``usd-core`` into the test environment; without
them (FIBREFIT_REQUIRE_MATERIALX unset) these tests are skipped.
"""

import json
import os
import re
import shutil
import subprocess
from xml.etree import ElementTree

import numpy as np
import pytest

import fibrefit
import fibrefit.materialx
from conftest import DATA, ROOT

try:
    import MaterialX as mx
    import MaterialX.PyMaterialXGenGlsl as mx_glsl
    import MaterialX.PyMaterialXGenShader as mx_gen
    from pxr import Sdf, Usd, UsdShade, UsdValidation
except ImportError:  # pragma: no cover - depends on the environment
    if os.environ.get("FIBREFIT_REQUIRE_MATERIALX"):
        raise
    pytest.skip("the materialx and usd-core packages are not installed", allow_module_level=True)

FELT = ROOT / "tests" / "data" / "rgl" / "acrylic_felt_green_rgb.bsdf"


@pytest.fixture(scope="module")
def fits(tmp_path_factory):
    """openpbr fits of the shipped felt (RGL), silk and brushed (goniometric tables)."""
    out = {}
    d = tmp_path_factory.mktemp("fits")
    for name, data in [
        ("felt", FELT),
        ("silk", DATA / "silk" / "gonio.csv"),
        ("brushed", DATA / "brushed" / "gonio.csv"),
    ]:
        r = fibrefit.fit(str(data), model="openpbr", directions=1500 if name == "felt" else None)
        path = d / f"{name}.json"
        r.to_json(str(path))
        out[name] = path
    return out


@pytest.fixture(scope="module")
def library():
    lib = mx.createDocument()
    mx.loadLibraries(mx.getDefaultDataLibraryFolders(), mx.getDefaultDataSearchPath(), lib)
    return lib


def load(text, library):
    doc = mx.createDocument()
    mx.readFromXmlString(doc, text)
    doc.setDataLibrary(library)
    return doc


@pytest.mark.parametrize("name", ["felt", "silk", "brushed"])
def test_the_document_validates_and_carries_the_fit(fits, library, name):
    m = fibrefit.materialx.material(str(fits[name]), name=f"fibrefit {name}")
    ElementTree.fromstring(m["document"])  # well-formed XML (a strict parser: no `--` in comments)
    doc = load(m["document"], library)
    ok, message = doc.validate()
    assert ok, message
    assert m["name"] == f"fibrefit_{name}"
    material = doc.getChild(m["name"])
    assert material.getCategory() == "surfacematerial"
    shaders = mx.getShaderNodes(material)
    assert len(shaders) == 1 and shaders[0].getCategory() == "open_pbr_surface"
    surface = shaders[0]
    assert surface.getNodeDef().getName() == "ND_open_pbr_surface_surfaceshader"
    # the values are the result's, by OpenPBR's names: as written (float64 text) and as
    # MaterialX reads them (float32)
    def value(key):
        text = surface.getInput(key).getValueString()
        exact = [float(x) for x in text.split(",")]
        read = surface.getInputValue(key)
        read = list(read) if hasattr(read, "__len__") else [read]
        assert np.allclose(read, exact, rtol=1e-7, atol=1e-30), key
        return exact if len(exact) > 1 else exact[0]

    params = {k: v["value"] for k, v in json.loads(fits[name].read_text())["parameters"].items()}
    kd = params["kd"]
    kd = kd if isinstance(kd, list) else [kd] * 3
    assert np.allclose(value("base_color"), kd, rtol=1e-14, atol=1e-300)
    for key in [
        "specular_roughness",
        "specular_roughness_anisotropy",
        "specular_ior",
        "specular_weight",
        "fuzz_weight",
        "fuzz_roughness",
    ]:
        assert value(key) == pytest.approx(params[key], rel=1e-14, abs=1e-300), key
    for key, want in m["inputs"].items():
        assert np.allclose(value(key), want, rtol=1e-14, atol=1e-300), key
    # the tangent: the UV tangent turned about the normal so the anisotropy lies across the fibres
    rotate = doc.getNode(f"{m['name']}_tangent_across_fibres")
    amount = float(rotate.getInput("amount").getValueString())
    assert amount == m["tangent_rotation_deg"]
    assert (amount + params["fibre_azimuth_deg"] + 90.0) % 360.0 == pytest.approx(0.0, abs=1e-9) or (
        amount + params["fibre_azimuth_deg"] + 90.0
    ) % 360.0 == pytest.approx(360.0, abs=1e-9)
    print(f"{name}: valid; {len(m['inputs'])} inputs equal the result's")


@pytest.mark.skipif(shutil.which("glslangValidator") is None, reason="glslangValidator not installed")
@pytest.mark.parametrize("name", ["felt", "silk"])
def test_the_glsl_materialx_generates_compiles(fits, library, name, tmp_path):
    m = fibrefit.materialx.material(str(fits[name]))
    glsl_compiles(load(m["document"], library), m, name, tmp_path)


def glsl_compiles(doc, m, name, tmp_path):
    """The GLSL MaterialX generates from ``doc`` (pixel and vertex stages) compiles."""
    material = doc.getChild(m["name"])
    gen = mx_glsl.GlslShaderGenerator.create()
    ctx = mx_gen.GenContext(gen)
    ctx.registerSourceCodeSearchPath(mx.getDefaultDataSearchPath())
    shader = gen.generate("fibrefit", material, ctx)
    for stage, ext in [(mx_gen.PIXEL_STAGE, "frag"), (mx_gen.VERTEX_STAGE, "vert")]:
        src = shader.getSourceCode(stage)
        assert "mx_sheen_bsdf" in src or ext == "vert"
        path = tmp_path / f"{name}.{ext}"
        path.write_text(src)
        run = subprocess.run(["glslangValidator", str(path)], capture_output=True, text=True)
        assert run.returncode == 0, run.stdout + run.stderr
    print(f"{name}: MaterialX's GLSL ({len(shader.getSourceCode(mx_gen.PIXEL_STAGE))} chars) compiles")


@pytest.mark.parametrize("name", ["felt", "brushed"])
def test_the_usd_stage_opens_and_validates(fits, library, name, tmp_path):
    m = fibrefit.materialx.material(str(fits[name]))
    path = tmp_path / f"{name}.usda"
    path.write_text(m["usda"])
    usd_stage_is_valid(path, m, library)
    print(f"{name}: USD stage valid (MaterialX ids checked against MaterialX)")


def usd_stage_is_valid(path, m, library):
    """The stage at ``path`` (of material ``m``) opens, passes every usd-core validator but the
    registry's ignorance of MaterialX's ids, which are MaterialX's own node definitions; its
    material's surfaces resolve, its values are ``m``'s, the swatch is bound to it."""
    stage = Usd.Stage.Open(str(path))
    assert stage.GetDefaultPrim().GetPath() == Sdf.Path("/fibrefit")
    validators = UsdValidation.ValidationRegistry().GetOrLoadAllValidators()
    assert len(validators) >= 20
    errors = UsdValidation.ValidationContext(validators).Validate(stage)
    material_ids = set()
    for e in errors:
        # usd-core has no MaterialX: only its registry's ignorance of MaterialX's ids may remain
        found = re.match(r"shaderId '(ND_\w+)' specified on shader prim", e.GetMessage())
        assert e.GetName() == "MissingShaderIdInRegistry" and found, (e.GetName(), e.GetMessage())
        material_ids.add(found.group(1))
    # ... and those are MaterialX's own node definitions, with their inputs and types
    shaders = [UsdShade.Shader(p) for p in stage.Traverse() if p.IsA(UsdShade.Shader)]
    ids = {s.GetIdAttr().Get(): s for s in shaders}
    assert material_ids <= set(ids)
    for node_id, s in ids.items():
        if node_id in ("UsdPreviewSurface", "UsdUVTexture", "UsdPrimvarReader_float2"):
            continue
        nodedef = library.getNodeDef(node_id)
        assert nodedef is not None, node_id
        usd_types = {
            "float": "float",
            "color3": "color3f",
            "vector3": "vector3f",
            "string": "string",
            "filename": "asset",
        }
        for i in s.GetInputs():
            d = nodedef.getActiveInput(i.GetBaseName())
            assert d is not None, f"{node_id} has no input {i.GetBaseName()}"
            assert str(i.GetTypeName()) == usd_types[d.getType()], (node_id, i.GetBaseName())
    mat = UsdShade.Material(stage.GetPrimAtPath(f"/fibrefit/Materials/{m['name']}"))
    mtlx = mat.ComputeSurfaceSource("mtlx")[0]
    assert mtlx.GetIdAttr().Get() == "ND_open_pbr_surface_surfaceshader"
    assert mat.ComputeSurfaceSource()[0].GetIdAttr().Get() == "UsdPreviewSurface"
    for key, value in m["inputs"].items():
        if key in m["textures"]:
            # read from its image node, the file beside the stage
            src = mtlx.GetInput(key).GetConnectedSource()[0]
            image = UsdShade.Shader(src.GetPrim())
            assert image.GetIdAttr().Get() in ("ND_image_color3", "ND_image_float"), key
            file = image.GetInput("file").Get()
            assert (path.parent / file.path).is_file(), file
            continue
        got = mtlx.GetInput(key).Get()
        got = list(got) if hasattr(got, "__len__") else [got]
        want = value if isinstance(value, list) else [value]
        assert np.allclose(got, want, rtol=1e-6), key
    swatch = stage.GetPrimAtPath("/fibrefit/Swatch")
    bound, _ = UsdShade.MaterialBindingAPI(swatch).ComputeBoundMaterial()
    assert bound.GetPath() == mat.GetPath()


def test_other_results_are_refused_with_the_route_to_an_openpbr_fit(tmp_path):
    p = tmp_path / "ward.toml"
    p.write_text('model = "ward"\nrho_d = 0.3\nrho_s = 0.1\nalpha_x = 0.2\nalpha_y = 0.3\n')
    with pytest.raises(fibrefit.FibrefitError, match="--model openpbr"):
        fibrefit.materialx.document(str(p))


def test_any_fit_carries_the_openpbr_material_fitted_to_its_data(library, tmp_path):
    # a fibre rung's fit records OpenPBR fitted to the same data; the export writes that
    r = fibrefit.fit(str(DATA / "silk" / "gonio.csv"), model="hast-diffuse")
    path = tmp_path / "silk.json"
    r.to_json(str(path))
    recorded = {m["model"]: m for m in json.loads(path.read_text())["renderer_materials"]}
    assert set(recorded) == {"gltf", "principled", "openpbr"}
    m = fibrefit.materialx.material(str(path))
    doc = load(m["document"], library)
    assert doc.validate()[0]
    want = recorded["openpbr"]["parameters"]["specular_roughness"]["value"]
    assert m["inputs"]["specular_roughness"] == want
    rel = recorded["openpbr"]["statistics"]["relative_rmse"]
    assert f"relative RMS error {100 * rel:.1f} %" in m["error_text"]


@pytest.fixture(scope="module")
def maps_fit(tmp_path_factory):
    """An openpbr ``--maps`` fit of the shipped silk capture (6 images): base colour, fibre
    direction, specular roughness and its anisotropy per texel."""
    d = tmp_path_factory.mktemp("maps_fit")
    cfg = d / "maps.toml"
    cfg.write_text(
        'model = "openpbr"\n[maps]\nkd = true\nfibre_azimuth = true\nspecular_roughness = true\n'
        "specular_roughness_anisotropy = true\nrounds = 2\n"
    )
    r = fibrefit.fit(str(DATA / "silk" / "capture.toml"), config=str(cfg), maps=str(d / "maps"))
    path = d / "silk_maps.json"
    r.to_json(str(path))
    return path


def test_a_maps_fit_reads_its_maps_as_image_nodes(maps_fit, library, tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    m = fibrefit.materialx.material(str(maps_fit), materialx=out / "silk.mtlx", usd=out / "silk.usda")
    inputs = {"base_color", "specular_roughness", "specular_roughness_anisotropy", "amount"}
    assert set(m["textures"]) == inputs
    for t in m["textures"].values():
        assert t["pixels"].ndim == 3 and t["pixels"].shape[2] == 3 and np.isfinite(t["pixels"]).all()
        # the document and the stage share one stem, so one set of textures beside both
        assert t["file"].startswith("silk_") and (out / t["file"]).is_file()
        assert os.path.samefile(t["path"], out / t["file"])
    # the document as written: valid, each input read from an image node beside it
    doc = mx.createDocument()
    mx.readFromXmlFile(doc, str(out / "silk.mtlx"))
    doc.setDataLibrary(library)
    ok, message = doc.validate()
    assert ok, message
    surface = mx.getShaderNodes(doc.getChild(m["name"]))[0]
    rotate = doc.getNode(f"{m['name']}_tangent_across_fibres")
    for node, key in [(surface, k) for k in sorted(inputs - {"amount"})] + [(rotate, "amount")]:
        image = node.getInput(key).getConnectedNode()
        assert image is not None and image.getCategory() == "image", key
        assert image.getInputValue("filtertype") == "closest", key
        file = image.getInputValue("file")
        assert (out / file).is_file(), file
        assert file == m["textures"][key]["file"], key
    if shutil.which("glslangValidator"):
        glsl_compiles(doc, m, "silk_maps", tmp_path)
    # the stage: valid, the same images (its own files beside it)
    usd_stage_is_valid(out / "silk.usda", m, library)
    print(f"maps fit: document and stage valid; {len(inputs)} inputs read from image nodes")
