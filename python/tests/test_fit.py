"""fibrefit.fit / load_data: the library's fit (the CLI's), lmfit's vocabulary, outputs that
never replace inputs, and errors as exceptions."""

import json

import numpy as np
import pytest

import fibrefit
from conftest import CONFIGS, DATA, write_params


def test_load_data_gonio():
    d = fibrefit.load_data(DATA / "brushed" / "gonio.csv")
    n = d["l"].shape[0]
    assert d["kind"] == "goniometric" and n > 1000
    assert d["l"].shape == (n, 3) and d["v"].shape == (n, 3)
    np.testing.assert_allclose(np.linalg.norm(d["l"], axis=1), 1, rtol=1e-12)
    assert d["value"].shape == (n, d["channels"])
    np.testing.assert_allclose(np.cos(np.radians(d["theta_i"])), d["l"][:, 2], atol=1e-12)
    assert d["origin"][0] == 2  # CSV line of the first sample (after the header)


def test_load_data_capture_and_options():
    d = fibrefit.load_data(DATA / "brushed" / "capture.toml", stride=2)
    assert d["kind"] == "image capture" and d["image_size"] == (64, 64)
    assert d["origin"].shape[1] == 3
    assert d["l"].shape[0] <= 4 * 32 * 32
    with pytest.raises(fibrefit.FibrefitError, match="--stride must be at least 1"):
        fibrefit.load_data(DATA / "brushed" / "capture.toml", stride=0)
    # the options are keyword arguments: an unknown one is Python's TypeError
    with pytest.raises(TypeError, match="strde"):
        fibrefit.load_data(DATA / "brushed" / "capture.toml", strde=2)


def test_fit_recovers_the_truth_and_reports(tmp_path):
    truth = json.loads((DATA / "brushed" / "truth.json").read_text())
    r = fibrefit.fit(DATA / "brushed" / "gonio.csv", config=CONFIGS / "fit_brushed.toml")
    assert r.model == truth["model"]
    assert "[[Fit Statistics]]" in r.report()
    for name in ["exponent", "fibre_azimuth_deg"]:
        p = r.params[name]
        assert p.vary and p.stderr is not None and p.stderr > 0
        assert abs(p.value - truth[name]) < 5 * p.stderr + 1e-6 * abs(truth[name]), (name, p, truth[name])
    kd = r.params["kd"]
    assert np.allclose(kd.value, truth["kd"], atol=0.02)
    assert all(isinstance(x, float) for x in kd.correl.values())
    out = tmp_path / "fit.json"
    r.to_json(out)
    written = json.loads(out.read_text())
    assert written["schema"] == "fibrefit-result/1" and written["model"] == r.model
    m = r.material()
    assert m.model == r.model and m.channels == written["data"]["channels"]


def test_fit_without_model_or_config_is_refused():
    with pytest.raises(fibrefit.FibrefitError, match="--model"):
        fibrefit.fit(DATA / "brushed" / "gonio.csv")


def test_missing_data_names_the_file(tmp_path):
    with pytest.raises(fibrefit.FibrefitError, match="nothing.csv"):
        fibrefit.fit(tmp_path / "nothing.csv", model="lambert")


def test_output_never_replaces_an_input(tmp_path):
    data = tmp_path / "gonio.csv"
    data.write_bytes((DATA / "brushed" / "gonio.csv").read_bytes())
    before = data.read_bytes()
    r = fibrefit.fit(data, model="lambert")
    with pytest.raises(fibrefit.FibrefitError, match="is an input of this run"):
        r.to_json(data)
    assert data.read_bytes() == before


def test_maps_fit_material_looks_up_the_maps(tmp_path):
    maps = tmp_path / "maps"
    cfg = tmp_path / "maps.toml"
    cfg.write_text(
        (CONFIGS / "fit_brushed.toml").read_text()
        + "\n[maps]\nheight = false\nfibre_azimuth = true\nkd = true\n"
    )
    r = fibrefit.fit(DATA / "brushed" / "capture.toml", config=cfg, maps=maps)
    assert r.has_maps
    m0 = r.material()
    assert not m0.has_maps and any("not written" in w for w in m0.warnings)
    r.to_json(tmp_path / "fit.json")
    m = r.material()
    assert m.has_maps and m.maps_size == (64, 64)
    again = fibrefit.load(tmp_path / "fit.json")
    assert again.has_maps
    # the maps matter: two texels with their own kd give their own values
    l = np.array([[0.0, 0.0, 1.0]] * 2)
    uv = np.array([[0.1, 0.1], [0.9, 0.8]])
    f = m.eval(l, l, uv)
    assert f.shape == (2, m.channels) and not np.allclose(f[0], f[1], rtol=1e-9)


def test_auto_fuzz_true_false_and_default_set_the_candidates(tmp_path):
    cfg = write_params(
        tmp_path, "auto.toml", 'model = "auto"\n[selection]\nrungs = ["lambert", "ward"]\n'
    )
    data = tmp_path / "gonio.csv"
    rows = (DATA / "brushed" / "gonio.csv").read_text().splitlines(keepends=True)
    data.write_text("".join(rows[:301]))

    def names(**kw):
        r = fibrefit.fit(data, config=cfg, **kw)
        return [c["name"] for c in r.result["model_selection"]]

    assert names() == ["lambert", "lambert + fuzz", "ward", "ward + fuzz"]
    assert names(fuzz=False) == ["lambert", "ward"]
    assert names(fuzz=True) == ["lambert + fuzz", "ward + fuzz"]
    listed = write_params(
        tmp_path, "listed.toml", 'model = "auto"\n[parameters]\nfuzz_depth = {}\n'
    )
    with pytest.raises(fibrefit.FibrefitError, match="lists the fuzz layer's parameter `fuzz_depth`"):
        fibrefit.fit(data, config=listed, fuzz=False)


def _silk_head(tmp_path, rows=300):
    text = (DATA / "silk" / "gonio.csv").read_text().splitlines()
    path = tmp_path / "silk.csv"
    path.write_text("\n".join(text[: rows + 1]) + "\n")
    return path


def _values(r):
    return {k: p.value for k, p in r.params.items()}


def test_fit_from_arrays_and_a_dataframe_is_the_file_fit(tmp_path):
    import pandas as pd

    path = _silk_head(tmp_path)
    ref = fibrefit.fit(path, model="ward")
    d = fibrefit.load_data(path)
    # numpy arrays a user already holds: directions, values and sigmas
    a = fibrefit.fit(l=d["l"], v=d["v"], values=d["value"], sigma=d["sigma"], model="ward", threads=1)
    # a DataFrame with the table's columns
    df = pd.read_csv(path)
    b = fibrefit.fit(df, model="ward")
    # a lab's own column names and radians, mapped and converted as for a file
    names = {"theta_i": "ti", "phi_i": "pi", "theta_o": "to", "phi_o": "po"}
    lab = df.rename(columns=names)
    for c in names.values():
        lab[c] = np.radians(lab[c])
    c = fibrefit.fit(lab, model="ward", columns=names, angles="rad")
    for r in (a, b, c):
        assert r.model == ref.model and r.statistics["n"] == ref.statistics["n"] == 900  # 300 rows x RGB
        for k, x in _values(ref).items():
            np.testing.assert_allclose(_values(r)[k], x, rtol=1e-6, atol=1e-9, err_msg=k)
    # the result names its data and records their hash, as a file's
    out = tmp_path / "arrays.json"
    a.to_json(out)
    written = json.loads(out.read_text())
    assert written["data"]["file"] == "arrays" and len(written["data"]["sha256"]) == 64
    # grey values as (N,), one sigma per row
    g = fibrefit.fit(l=d["l"], v=d["v"], values=d["value"][:, 1], sigma=d["sigma"][:, 1], model="lambert")
    assert g.material().channels == 1


def test_fit_from_memory_names_what_is_wrong():
    import pandas as pd

    l = np.tile([0.0, 0.0, 1.0], (4, 1))
    v = np.tile([0.6, 0.0, 0.8], (4, 1))
    vals = np.full(4, 0.3)
    with pytest.raises(fibrefit.FibrefitError, match="l, v and values are needed together"):
        fibrefit.fit(l=l, values=vals, model="lambert")
    with pytest.raises(fibrefit.FibrefitError, match="not both"):
        fibrefit.fit(DATA / "silk" / "gonio.csv", l=l, v=v, values=vals, model="lambert")
    with pytest.raises(fibrefit.FibrefitError, match="nothing to fit"):
        fibrefit.fit(model="lambert")
    below = v.copy()
    below[2] = [1.0, 0.0, 0.0]
    with pytest.raises(fibrefit.FibrefitError, match=r"arrays: v\[2\] = \(1, 0, 0\) is at or below the horizon"):
        fibrefit.fit(l=l, v=below, values=vals, model="lambert")
    with pytest.raises(fibrefit.FibrefitError, match=r"values: expected an \(N,\) or \(N, C\) array"):
        fibrefit.fit(l=l, v=v, values=np.zeros((4, 3, 1)), model="lambert")
    with pytest.raises(fibrefit.FibrefitError, match="data: expected a file path or a pandas DataFrame"):
        fibrefit.fit([1, 2, 3], model="lambert")
    df = pd.DataFrame({"theta_i": [10.0, 20.0], "phi_i": [0.0, 0.0], "theta_o": [30.0, 95.0],
                       "phi_o": [180.0, 180.0], "brdf": [0.3, 0.3]})
    # the table's line: line 1 is the header, row k is line k + 2
    with pytest.raises(fibrefit.FibrefitError, match=r"DataFrame:3: column `theta_o` = 95 is at or below the horizon"):
        fibrefit.fit(df, model="lambert")
    with pytest.raises(fibrefit.FibrefitError, match="--threads 0"):
        fibrefit.fit(df.iloc[:1], model="lambert", threads=0)


def test_fit_gltf_variant_threejs_reaches_the_result(tmp_path):
    # the gltf rung's threejs variant (three.js r187's BRDF): the keyword as --gltf-variant
    data = DATA / "silk" / "gonio.csv"
    r = fibrefit.fit(data, model="gltf", gltf_variant="threejs")
    out = tmp_path / "fit.json"
    r.to_json(out)
    j = json.loads(out.read_text())
    assert j["knobs"]["gltf_variant"] == "threejs"
    assert "metallic" in j["parameters"]
    # the default is the Khronos specification's
    k = fibrefit.fit(data, model="gltf")
    k.to_json(tmp_path / "k.json")
    assert json.loads((tmp_path / "k.json").read_text())["knobs"]["gltf_variant"] == "khronos"
    with pytest.raises(fibrefit.FibrefitError, match="--gltf-variant: unknown gltf variant"):
        fibrefit.fit(data, model="gltf", gltf_variant="three")
    with pytest.raises(fibrefit.FibrefitError, match="knob of the gltf rung"):
        fibrefit.fit(data, model="ward", gltf_variant="threejs")


def test_a_material_that_gains_energy_is_said_to(tmp_path):
    # a Lambertian of 0.5 / sr (a directional albedo of pi / 2: data in the wrong units): the
    # rung's albedo stops at 1, the correction makes up the rest, and the fit says the material
    # reflects more than it receives, as the CLI does
    rows = ["theta_i,phi_i,theta_o,phi_o,brdf"]
    k = 0
    for ti in (0, 15, 30, 45, 60, 75):
        for to in (0, 20, 40, 60, 80):
            for po in (0, 60, 120, 180):
                k += 1
                rows.append(f"{ti},0,{to},{po},{0.5 * (1 + 0.01 * ((k * 7919 % 101) / 50 - 1))}")
    data = tmp_path / "bright.csv"
    data.write_text("\n".join(rows) + "\n")
    r = fibrefit.fit(data, model="lambert", metric="log")
    GAIN = "the material reflects more light than it receives"
    energy = [w for w in r.warnings if w.startswith(GAIN)]
    assert len(energy) == 1 and "normal incidence" in energy[0], r.warnings
    # the shipped brushed fit keeps its energy
    ok = fibrefit.fit(DATA / "brushed" / "gonio.csv", config=CONFIGS / "fit_brushed.toml")
    assert not any(w.startswith(GAIN) for w in ok.warnings)
