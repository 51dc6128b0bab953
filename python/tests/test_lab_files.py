"""A lab's own goniometric tables from Python: any of .csv/.tsv/.txt/.dat (delimiter sniffed),
angles in radians with ``angles="rad"`` or the config's ``[data] angles``."""

import math

import numpy as np
import pytest

import fibrefit
from conftest import DATA


def _rows(n=301):
    return (DATA / "brushed" / "gonio.csv").read_text().splitlines()[:n]


def _radians(rows):
    out = [rows[0]]
    for r in rows[1:]:
        f = r.split(",")
        out.append(",".join([repr(math.radians(float(x))) for x in f[:4]] + f[4:]))
    return out


def test_tables_load_whatever_their_extension(tmp_path):
    rows = _rows()
    ref = fibrefit.load_data(DATA / "brushed" / "gonio.csv")
    for name, sep in [("g.tsv", "\t"), ("g.txt", "  "), ("g.dat", ";"), ("g.TSV", "\t")]:
        p = tmp_path / name
        p.write_text("\n".join(sep.join(r.split(",")) for r in rows) + "\n")
        d = fibrefit.load_data(p)
        np.testing.assert_array_equal(d["l"], ref["l"][:300])
        np.testing.assert_array_equal(d["value"], ref["value"][:300])
    with pytest.raises(fibrefit.FibrefitError, match=r"\.tsv, \.txt or \.dat"):
        bad = tmp_path / "g.xlsx"
        bad.write_text("\n".join(rows))
        fibrefit.load_data(bad)


def test_radians_with_the_keyword_or_the_config(tmp_path):
    rad = tmp_path / "rad.csv"
    rad.write_text("\n".join(_radians(_rows())) + "\n")
    deg = tmp_path / "deg.csv"
    deg.write_text("\n".join(_rows()) + "\n")
    with pytest.raises(fibrefit.FibrefitError, match="--angles rad"):
        fibrefit.load_data(rad)
    a = fibrefit.load_data(rad, angles="rad")
    b = fibrefit.load_data(deg)
    np.testing.assert_allclose(a["l"], b["l"], atol=1e-12)
    np.testing.assert_allclose(a["theta_i"], b["theta_i"], atol=1e-9)
    with pytest.raises(fibrefit.FibrefitError, match="not an angle unit"):
        fibrefit.load_data(rad, angles="grad")

    cfg = tmp_path / "cfg.toml"
    cfg.write_text('model = "lambert"\n[data]\nangles = "rad"\n')
    plain = tmp_path / "plain.toml"
    plain.write_text('model = "lambert"\n')
    kd = fibrefit.fit(deg, config=plain).params["kd"].value
    np.testing.assert_allclose(fibrefit.fit(rad, config=cfg).params["kd"].value, kd, rtol=1e-9)
    np.testing.assert_allclose(fibrefit.fit(rad, config=plain, angles="rad").params["kd"].value, kd, rtol=1e-9)
    # the keyword overrides the config
    np.testing.assert_allclose(fibrefit.fit(deg, config=cfg, angles="deg").params["kd"].value, kd, rtol=1e-9)
