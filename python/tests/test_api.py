"""fibrefit.score / eval / export: the commands of the command line as functions, giving what
`fibrefit score`, `fibrefit eval` and `fibrefit export` give on the same files; and the fit's
loading flags as typed keyword arguments."""

import json
import subprocess

import numpy as np
import pytest

import fibrefit
from conftest import CONFIGS, DATA, ROOT, cli_binary

CLI = cli_binary()
needs_cli = pytest.mark.skipif(CLI is None, reason="no fibrefit command line built (cargo build)")


def run_cli(*args):
    p = subprocess.run([CLI, *map(str, args)], capture_output=True, text=True)
    assert p.returncode == 0, p.stderr
    return p.stdout


@pytest.fixture(scope="module")
def silk_result(tmp_path_factory):
    """The silk gonio set fitted with its config, written as a result JSON."""
    d = tmp_path_factory.mktemp("silk")
    r = fibrefit.fit(DATA / "silk" / "gonio.csv", config=CONFIGS / "fit_silk.toml")
    r.to_json(d / "fit.json")
    return d / "fit.json"


@needs_cli
def test_score_is_the_clis(silk_result):
    for data, flags in [
        (DATA / "silk" / "gonio.csv", {}),
        (DATA / "silk" / "capture.toml", {"stride": 4, "fraction": 0.5, "subsample_seed": 3}),
    ]:
        s = fibrefit.score(silk_result, data, **flags)
        args = [a for k, v in flags.items() for a in (f"--{k.replace('_', '-')}", v)]
        assert s.result == json.loads(run_cli("score", silk_result, data, "--json", *args))
        assert s.report() == run_cli("score", silk_result, data, *args)
        assert s.verdict in s.report() and s.result["samples"] > 0


def test_score_of_its_own_data_reproduces_the_fit(silk_result):
    s = fibrefit.score(silk_result, DATA / "silk" / "gonio.csv")
    fitted = json.loads(silk_result.read_text())["statistics"]
    assert s.statistics["rmse"] == pytest.approx(fitted["rmse"], rel=1e-9)


@needs_cli
@pytest.mark.parametrize("params", ["silk_params", "result"])
def test_eval_is_the_clis(silk_result, params):
    p = CONFIGS / "silk_params.toml" if params == "silk_params" else silk_result
    q = DATA / "queries_slices.csv"
    brdf, intensity = fibrefit.eval(p, q)
    rows = run_cli("eval", "--params", p, "--queries", q).splitlines()
    header = rows[0].split(",")
    table = np.array([[float(x) for x in r.split(",")] for r in rows[1:]])
    c = brdf.shape[1]
    assert brdf.shape == intensity.shape == (len(rows) - 1, c)
    assert header[-2 * c :] == (["brdf", "intensity"] if c == 1 else [f"{k}_{x}" for k in ("brdf", "intensity") for x in "rgb"])
    # the CLI writes each f64 in its shortest exact form: the very values
    np.testing.assert_array_equal(brdf, table[:, -2 * c : -c])
    np.testing.assert_array_equal(intensity, table[:, -c:])


def test_eval_with_another_rung_and_errors(tmp_path):
    q = DATA / "queries_slices.csv"
    brdf, _ = fibrefit.eval(CONFIGS / "silk_params.toml", q, model="poulin-fournier")
    silk, _ = fibrefit.eval(CONFIGS / "silk_params.toml", q)
    assert brdf.shape == silk.shape and not np.array_equal(brdf, silk)
    with pytest.raises(fibrefit.FibrefitError, match="nothing.csv"):
        fibrefit.eval(CONFIGS / "silk_params.toml", tmp_path / "nothing.csv")
    with pytest.raises(fibrefit.FibrefitError, match="no-such-rung"):
        fibrefit.eval(CONFIGS / "silk_params.toml", q, model="no-such-rung")


@needs_cli
def test_export_is_the_clis(silk_result, tmp_path):
    for lang in ["wgsl", "glsl", "hlsl", "msl"]:
        e = fibrefit.export(silk_result, shader=lang)
        out = tmp_path / f"s.{lang}"
        run_cli("export", silk_result, "--shader", lang, "--out", out, "-q")
        assert e.shader == out.read_text() and e.glb is None and e.gltf_material is None
        assert e.model == "varying-topology"
    for obj in ["swatch", "sphere"]:
        e = fibrefit.export(silk_result, gltf=True, object=obj)
        glb = tmp_path / f"{obj}.glb"
        run_cli("export", silk_result, "--gltf", glb, "--object", obj, "-q")
        assert e.glb == glb.read_bytes() and e.shader is None
        m = e.gltf_material
        assert len(m["base_color"]) == 3 and 0 <= m["roughness"] <= 1
        # the glTF material the varying-topology fit recorded, fitted to the same data
        assert m["route"] == "recorded" and m["recorded_by"] == "varying-topology"
        assert m["relative_rms_error_against_data"] > 0 and "relative RMS error" in m["error_text"]
    both = fibrefit.export(silk_result, shader="wgsl", gltf=True)
    assert both.shader and both.glb[:4] == b"glTF"


@needs_cli
def test_renderer_materials_export_shaders_as_the_cli_does(tmp_path):
    # principled and openpbr fits of the brushed table: the shader library of Blender's and
    # MaterialX's own material, as `fibrefit export --shader` writes it
    for model in ["principled", "openpbr"]:
        r = fibrefit.fit(DATA / "brushed" / "gonio.csv", model=model)
        r.to_json(tmp_path / f"{model}.json")
        e = fibrefit.export(tmp_path / f"{model}.json", shader="glsl")
        out = tmp_path / f"{model}.glsl"
        run_cli("export", tmp_path / f"{model}.json", "--shader", "glsl", "--out", out, "-q")
        assert e.shader == out.read_text() and e.model == model
        assert f"fibrefit_{model}(" in e.shader


def test_export_refusals(silk_result):
    with pytest.raises(fibrefit.FibrefitError, match="nothing to export"):
        fibrefit.export(silk_result)
    with pytest.raises(fibrefit.FibrefitError, match="unknown shader language 'cuda'"):
        fibrefit.export(silk_result, shader="cuda")
    with pytest.raises(fibrefit.FibrefitError, match="--object cube"):
        fibrefit.export(silk_result, gltf=True, object="cube")
    # the package has no GPU driver to check the shader on
    with pytest.raises(fibrefit.FibrefitError, match="gpu"):
        fibrefit.export(silk_result, shader="wgsl", check=True)


def test_loading_flags_are_typed_keywords():
    capture = DATA / "brushed" / "capture.toml"
    # unknown keywords are Python's TypeError, naming the keyword
    with pytest.raises(TypeError, match="strde"):
        fibrefit.load_data(capture, strde=2)
    with pytest.raises(TypeError, match="strde"):
        fibrefit.fit(capture, model="lambert", strde=2)
    with pytest.raises(TypeError, match="strde"):
        fibrefit.score(DATA / "brushed" / "truth.json", capture, strde=2)
    # values of the wrong type or range are FibrefitErrors naming the argument
    with pytest.raises(fibrefit.FibrefitError, match="stride"):
        fibrefit.load_data(capture, stride="2")
    with pytest.raises(fibrefit.FibrefitError):
        fibrefit.load_data(capture, stride=-1)
    with pytest.raises(fibrefit.FibrefitError, match="columns"):
        fibrefit.load_data(capture, columns=["brdf"])
    with pytest.raises(fibrefit.FibrefitError, match=r"--fraction must lie in \(0, 1\]"):
        fibrefit.load_data(capture, fraction=1.5)
    a = fibrefit.load_data(capture, stride=2, fraction=0.5, subsample_seed=1)
    b = fibrefit.load_data(capture, stride=2, fraction=0.5, subsample_seed=2)
    assert a["l"].shape[0] != b["l"].shape[0] or not np.array_equal(a["origin"], b["origin"])


def test_columns_extend_the_configs_as_the_cli_does(tmp_path):
    # the file's own names for every column, given partly by the config and partly by `columns`
    rows = (DATA / "brushed" / "gonio.csv").read_text().splitlines(keepends=True)
    header = [h.strip() for h in rows[0].split(",")]
    renamed = {"theta_i": "ti", "phi_i": "pi", "theta_o": "to", "phi_o": "po"}
    data = tmp_path / "renamed.csv"
    data.write_text(",".join(renamed.get(h, h) for h in header) + "\n" + "".join(rows[1:301]))
    cfg = tmp_path / "cfg.toml"
    cfg.write_text('model = "lambert"\n[columns]\ntheta_i = "ti"\nphi_i = "pi"\n')
    with pytest.raises(fibrefit.FibrefitError):
        fibrefit.fit(data, config=cfg)
    r = fibrefit.fit(data, config=cfg, columns={"theta_o": "to", "phi_o": "po"})
    plain = tmp_path / "plain.csv"
    plain.write_text("".join(rows[:301]))
    lambert = tmp_path / "lambert.toml"
    lambert.write_text('model = "lambert"\n')
    np.testing.assert_array_equal(r.params["kd"].value, fibrefit.fit(plain, config=lambert).params["kd"].value)


def test_fit_and_score_carry_the_verdict_and_the_floor(tmp_path):
    """Without sigmas the verdict is judged against the floor (what the data themselves allow);
    the fit's Result and a Score both give the floor and the ratio."""
    rows = (DATA / "silk" / "gonio.csv").read_text().splitlines()
    header = rows[0].split(",")
    keep = [k for k, name in enumerate(header) if not name.startswith("sigma")]
    no_sigmas = tmp_path / "no_sigmas.csv"
    no_sigmas.write_text(
        "\n".join(",".join(r.split(",")[k] for k in keep) for r in rows if not r.startswith("#")) + "\n"
    )
    r = fibrefit.fit(no_sigmas, model="lambert", fuzz=False, metric="log")
    assert r.floor is not None and r.floor > 0
    assert r.floor_ratio == pytest.approx(r.result["quality"]["floor"]["ratio"])
    assert r.verdict == r.result["quality"]["verdict"]
    assert r.verdict.startswith("misses structure the data hold") or r.verdict.startswith("within 1.2x")
    r.to_json(tmp_path / "fit.json")
    s = fibrefit.score(tmp_path / "fit.json", no_sigmas)
    assert s.floor is not None and s.floor_ratio is not None
    assert s.verdict == s.result["verdict"]


def test_the_felt_is_not_reciprocal_and_the_floor_says_so():
    """The shipped felt file is not reciprocal (f(l, v) and f(v, l) differ by 0.1 in log RMS):
    the floor's predictor made reciprocal, what any material can reach, lies well above the
    data's own floor, and the result carries both; it judges the material (without the
    instrument's terms of a correction, where one was kept)."""
    felt = ROOT / "tests" / "data" / "rgl" / "acrylic_felt_green_rgb.bsdf"
    r = fibrefit.fit(felt, model="lambert", fuzz=True, metric="log")
    rec = r.result["quality"]["floor"]["reciprocal"]
    assert r.reciprocal_floor == pytest.approx(rec["floor"])
    assert r.reciprocal_floor > 1.2 * r.floor
    judged = r.result["quality"]["floor"]["heldout_error"]
    if r.correction is not None and r.correction["instrument_terms"] > 0:
        judged = r.correction["material_heldout_error"]
        assert rec["material_error"] == pytest.approx(judged)
    assert rec["ratio"] == pytest.approx(judged / rec["floor"])


def test_the_felt_fit_keeps_a_smooth_correction_that_material_applies(tmp_path):
    """gltf + fuzz misses structure the felt holds: a smooth reciprocal correction is kept on it
    (held out, it roughly halves the error); Material of the result evaluates the corrected BRDF
    (its check values), and correction=False judges the rung alone."""
    felt = ROOT / "tests" / "data" / "rgl" / "acrylic_felt_green_rgb.bsdf"
    r = fibrefit.fit(felt, model="gltf", fuzz=True, metric="log", directions=1500)
    c = r.correction
    assert c is not None and c["degree"] >= 1
    assert c["heldout_error"] < 0.8 * c["rung_heldout_error"]
    assert r.result["correction"]["heldout"]["error"] == pytest.approx(c["heldout_error"])
    # the felt is not reciprocal: the instrument's imbalance is fitted beside the series, and
    # the material alone (what Material evaluates) is judged without it
    assert c["instrument_terms"] == c["degree"]
    assert c["heldout_error"] <= c["material_heldout_error"] < c["rung_heldout_error"]
    assert r.result["correction"]["heldout"]["material_error"] == pytest.approx(c["material_heldout_error"])
    assert r.result["quality"]["floor"]["heldout_error"] == pytest.approx(c["heldout_error"])
    r.to_json(tmp_path / "fit.json")
    m = fibrefit.load(tmp_path / "fit.json")
    checks = r.result["correction"]["check_values"]
    rad = np.radians
    d = lambda t, p: np.array([np.sin(rad(t)) * np.cos(rad(p)), np.sin(rad(t)) * np.sin(rad(p)), np.cos(rad(t))])  # noqa: E731
    l = np.array([d(x["theta_i"], x["phi_i"]) for x in checks])
    v = np.array([d(x["theta_o"], x["phi_o"]) for x in checks])
    want = np.array([x["brdf"] for x in checks])
    np.testing.assert_allclose(m.eval(l, v), want, rtol=1e-9, atol=1e-12)
    # reciprocal: light and view swapped give the same values
    np.testing.assert_allclose(m.eval(v, l), want, rtol=1e-9, atol=1e-12)
    alone = fibrefit.fit(felt, model="gltf", fuzz=True, metric="log", directions=1500, correction=False)
    assert alone.correction is None and "correction" not in alone.result
    assert alone.result["quality"]["floor"]["heldout_error"] == pytest.approx(c["rung_heldout_error"])


def test_undetermined_values_are_said(tmp_path):
    """Ward fitted to data without a lobe (a matte surface): the lobe's widths are undetermined,
    with why; the result, the material a renderer loads and the exports say so."""
    rng = np.random.default_rng(1)

    def hemisphere(n):
        d = rng.standard_normal((n, 3))
        d[:, 2] = np.abs(d[:, 2]) + 0.2
        return d / np.linalg.norm(d, axis=1, keepdims=True)

    n = 400
    l, v = hemisphere(n), hemisphere(n)
    values = 0.3 / np.pi * (1 + 0.01 * rng.standard_normal(n))
    r = fibrefit.fit(l=l, v=v, values=values, model="ward", fuzz=False)
    # a lobe that is not there: its widths end at their bounds, not measurements
    assert {"alpha_x", "alpha_y"} <= set(r.undetermined), r.undetermined
    p = r.params["alpha_x"]
    assert p.determined is False and p.undetermined_reason == r.undetermined["alpha_x"]
    assert r.params["rho_d"].determined is True and "rho_d" not in r.undetermined
    r.to_json(tmp_path / "fit.json")
    m = fibrefit.load(tmp_path / "fit.json")
    assert m.undetermined["alpha_x"] == r.undetermined["alpha_x"]
    assert any("`alpha_x` is undetermined" in w for w in m.warnings)
    e = fibrefit.export(tmp_path / "fit.json", shader="wgsl", gltf=True)
    assert "alpha_x" in e.undetermined and "UNDETERMINED: `alpha_x` is undetermined" in e.shader
