"""fibrefit.view: the viewer page as `fibrefit view` writes it (the page's drawing is tested in
headless Chromium, tests/browser/view.mjs)."""

import json
import shutil

import pytest

import fibrefit
from conftest import DATA

PARAMS = 'model = "poulin-fournier"\nkd = [0.55, 0.35, 0.30]\nks = 0.25\nexponent = 60\nspacing = 2.0\nfibre_azimuth_deg = 20\n'


def page_data(path):
    html = open(path, encoding="utf-8").read()
    start = html.index('id="fibrefit-data">') + len('id="fibrefit-data">')
    end = html.index("</script>", start)
    return json.loads(html[start:end].replace("<\\/", "</"))


def test_view_writes_the_page_beside_or_where_asked(tmp_path):
    params = tmp_path / "pf.toml"
    params.write_text(PARAMS)
    written = fibrefit.view(params)
    assert written == str(tmp_path / "pf.html")
    d = page_data(written)
    assert d["model"] == "poulin-fournier"
    assert d["gltf_route"]["kind"] == "converted"
    assert not d["comparison"]["available"]
    other = fibrefit.view(str(params), out=tmp_path / "other.html")
    assert other == str(tmp_path / "other.html")


def test_view_compares_a_fit_with_its_data(tmp_path):
    shutil.copy(DATA / "silk" / "gonio.csv", tmp_path / "gonio.csv")
    result = fibrefit.fit(tmp_path / "gonio.csv", model="lambert")
    result.to_json(tmp_path / "fit.json")
    d = page_data(fibrefit.view(tmp_path / "fit.json", out=tmp_path / "v.html"))
    assert d["comparison"]["available"], d["comparison"]["note"]
    assert d["result"]["fitted"]
    # the glTF route is the gltf material the fit recorded, fitted to the same data
    route = d["gltf_route"]
    assert route["kind"] == "recorded" and "fitted to the same data" in route["text"], route
    recorded = next(m for m in json.loads((tmp_path / "fit.json").read_text())["renderer_materials"] if m["model"] == "gltf")
    assert route["values"]["roughnessFactor"] == recorded["parameters"]["roughness"]["value"]


def test_view_refusals_write_nothing(tmp_path):
    params = tmp_path / "pf.toml"
    params.write_text(PARAMS)
    with pytest.raises(fibrefit.FibrefitError, match="missing.json"):
        fibrefit.view(tmp_path / "missing.json", out=tmp_path / "x.html")
    with pytest.raises(fibrefit.FibrefitError, match="nowhere.csv"):
        fibrefit.view(params, out=tmp_path / "x.html", data=tmp_path / "nowhere.csv")
    with pytest.raises(fibrefit.FibrefitError):
        fibrefit.view(params, out=params)
    assert params.read_text() == PARAMS
    assert sorted(p.name for p in tmp_path.iterdir()) == ["pf.toml"]
