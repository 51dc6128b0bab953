"""fibrefit.load / Material: values against the CLI's own check values, physical properties,
the sampler's consistency, and errors as exceptions carrying the CLI's messages."""

import json

import numpy as np
import pytest

import fibrefit
from conftest import DATA, direction, hemisphere, write_params

PF = """{"model": "poulin-fournier", "kd": [0.5, 0.3, 0.2], "ks": 0.3, "exponent": 200,
"spacing": 2.0, "fibre_azimuth_deg": 30, "azimuth_spread_deg": 10, "fresnel_ior": 1.5,
"fuzz": 0.1, "fuzz_depth": 0.5}"""


def test_truth_materials_load_with_channels(tmp_path):
    silk = fibrefit.load(DATA / "silk" / "truth.json")
    assert silk.model == "varying-topology" and silk.channels == 3
    assert abs(silk.fibre_azimuth_deg - 20.0) < 1e-9
    brushed = fibrefit.load(DATA / "brushed" / "truth.json")
    l = hemisphere(50, np.random.default_rng(1))
    v = hemisphere(50, np.random.default_rng(2))
    f = brushed.eval(l, v)
    assert f.shape == (50, brushed.channels)
    assert np.all(np.isfinite(f)) and np.all(f >= 0)


def test_eval_matches_the_results_check_values(tmp_path):
    # a fit written by the library: its check values were computed by the Rust model at fit time
    r = fibrefit.fit(DATA / "brushed" / "gonio.csv", model="lambert")
    out = tmp_path / "fit.json"
    r.to_json(out)
    res = json.loads(out.read_text())
    m = fibrefit.load(out)
    for cv in res["check_values"]:
        l = direction(cv["theta_i"], cv["phi_i"])
        v = direction(cv["theta_o"], cv["phi_o"])
        got = m.eval(l[None], v[None])[0]
        want = np.array(cv["brdf"], dtype=float)
        np.testing.assert_allclose(got[: len(want)], want, rtol=1e-12, atol=1e-15)


def test_reciprocity_and_flip_invariance(tmp_path, rng):
    m = fibrefit.load(write_params(tmp_path, "pf.json", PF))
    l, v = hemisphere(400, rng), hemisphere(400, rng)
    a, b = m.eval(l, v), m.eval(v, l)
    np.testing.assert_allclose(a, b, rtol=1e-9, atol=1e-12)
    # T -> -T: the same fibres; rotating both directions by 180 degrees about the normal
    rot = np.array([[-1, 0, 0], [0, -1, 0], [0, 0, 1.0]])
    np.testing.assert_allclose(m.eval(l @ rot.T, v @ rot.T), a, rtol=1e-9, atol=1e-12)
    assert np.all(a >= 0) and np.all(np.isfinite(a))


def test_below_horizon_is_zero(tmp_path):
    m = fibrefit.load(write_params(tmp_path, "pf.json", PF))
    l = np.array([[0.0, 0.6, -0.8], [0.6, 0.0, 0.8]])
    v = np.array([[0.0, 0.0, 1.0], [0.0, 0.6, -0.8]])
    assert np.all(m.eval(l, v) == 0)
    assert np.all(m.pdf(v, l) == 0)


def test_sample_weight_is_eval_cos_over_pdf(tmp_path, rng):
    m = fibrefit.load(write_params(tmp_path, "pf.json", PF))
    n = 2000
    v = hemisphere(n, rng, 85)
    u = rng.random((n, 2))
    l, w, pdf = m.sample(v, u)
    ok = pdf > 0
    assert ok.mean() > 0.5
    np.testing.assert_allclose(np.linalg.norm(l[ok], axis=1), 1.0, rtol=1e-12)
    assert np.all(l[ok][:, 2] > 0)
    f = m.eval(l[ok], v[ok])
    np.testing.assert_allclose(w[ok], f * l[ok][:, 2:3] / pdf[ok][:, None], rtol=1e-9, atol=1e-14)
    np.testing.assert_allclose(m.pdf(v[ok], l[ok]), pdf[ok], rtol=1e-9)
    assert np.all(w[~ok] == 0) and np.all(l[~ok] == 0)
    # determinism
    l2, w2, p2 = m.sample(v, u)
    assert np.array_equal(l, l2) and np.array_equal(w, w2) and np.array_equal(pdf, p2)


def test_sampled_albedo_agrees_with_quadrature(tmp_path, rng):
    # the directional albedo: E[weight] under the sampler equals the integral of f cos over the
    # hemisphere (dense uniform quadrature), within the estimate's standard error
    m = fibrefit.load(write_params(tmp_path, "pf.json", PF))
    v0 = direction(40, 75)
    n = 200_000
    v = np.repeat(v0[None], n, axis=0)
    _, w, _ = m.sample(v, rng.random((n, 2)))
    est, se = w.mean(axis=0), w.std(axis=0) / np.sqrt(n)
    lq = hemisphere(n, np.random.default_rng(3), 90)
    ref = (m.eval(lq, v) * lq[:, 2:3]).mean(axis=0) * 2 * np.pi
    ref_se = (m.eval(lq, v) * lq[:, 2:3]).std(axis=0) * 2 * np.pi / np.sqrt(n)
    assert np.all(np.abs(est - ref) < 4 * np.hypot(se, ref_se)), (est, ref, se, ref_se)


def test_one_instance_per_sample_is_consistent_and_unbiased(tmp_path, rng):
    # PF's spread of 10 degrees mixes 16 turned fibre directions: with `instance` uniforms each
    # row is one of them, its weight that instance's eval cos / pdf, the same uniform picking
    # the same instance in eval, pdf and sample; the mean over instances is the material
    m = fibrefit.load(write_params(tmp_path, "pf.json", PF))
    assert m.instances == 16
    n = 2000
    v = hemisphere(n, rng, 85)
    u, r = rng.random((n, 2)), rng.random(n)
    l, w, pdf = m.sample(v, u, instance=r)
    ok = pdf > 0
    assert ok.mean() > 0.5
    f = m.eval(l[ok], v[ok], instance=r[ok])
    np.testing.assert_allclose(w[ok], f * l[ok][:, 2:3] / pdf[ok][:, None], rtol=1e-9, atol=1e-14)
    np.testing.assert_allclose(m.pdf(v[ok], l[ok], instance=r[ok]), pdf[ok], rtol=1e-9)
    # the instances' values differ, and their mean over many uniforms is eval's (all 16 drawn)
    l1 = hemisphere(1, rng, 80)
    k = 200_000
    vals = m.eval(np.repeat(l1, k, axis=0), np.repeat(v[:1], k, axis=0), instance=rng.random(k))
    assert np.unique(vals[:, 0]).size == 16
    exact = m.eval(l1, v[:1])[0]
    assert np.all(np.abs(vals.mean(axis=0) - exact) < 5 * vals.std(axis=0) / np.sqrt(k) + 1e-15)
    # the albedo estimate: one instance per row against the exact sampler
    v0 = np.repeat(direction(40, 75)[None], 100_000, axis=0)
    _, w_exact, _ = m.sample(v0, rng.random((100_000, 2)))
    _, w_inst, _ = m.sample(v0, rng.random((100_000, 2)), instance=rng.random(100_000))
    se = np.hypot(w_exact.std(axis=0), w_inst.std(axis=0)) / np.sqrt(100_000)
    assert np.all(np.abs(w_exact.mean(axis=0) - w_inst.mean(axis=0)) < 4.5 * se)
    with pytest.raises(fibrefit.FibrefitError, match="instance row 1"):
        m.sample(v[:2], u[:2], instance=[0.2, 1.5])
    with pytest.raises(fibrefit.FibrefitError, match="instance"):
        m.eval(v[:2], v[:2], instance=[0.2])


def test_pdf_integrates_to_at_most_one(tmp_path, rng):
    m = fibrefit.load(write_params(tmp_path, "pf.json", PF))
    n = 400_000
    v = np.repeat(direction(60, 10)[None], n, axis=0)
    l = hemisphere(n, rng, 90)
    total = m.pdf(v, l).mean() * 2 * np.pi
    assert total <= 1.02 and total > 0.8, total


@pytest.mark.parametrize(
    "args, message",
    [
        ((np.zeros((3, 2)), np.zeros((3, 3))), "l: expected an (N, 3) array, got shape (3, 2)"),
        ((np.array([[0, 0, 1.0]]), np.array([[np.nan, 0, 1.0]])), "v row 0: (NaN, 0, 1) is not finite"),
        ((np.array([[0, 0, 2.0]]), np.array([[0, 0, 1.0]])), "l row 0: (0, 0, 2) has length 2"),
        ((np.zeros((2, 3)) + [0, 0, 1], np.zeros((3, 3)) + [0, 0, 1]), "l has 2 rows but v has 3"),
    ],
)
def test_bad_arrays_raise_with_the_message(tmp_path, args, message):
    m = fibrefit.load(write_params(tmp_path, "pf.json", PF))
    with pytest.raises(fibrefit.FibrefitError) as e:
        m.eval(*args)
    assert message in str(e.value)
    assert isinstance(e.value, ValueError)


def test_bad_uniforms_and_uv(tmp_path):
    m = fibrefit.load(write_params(tmp_path, "pf.json", PF))
    v = np.array([[0, 0, 1.0]])
    with pytest.raises(fibrefit.FibrefitError, match=r"u row 0: \(1, 0.5\) is not in \[0, 1\)\^2"):
        m.sample(v, np.array([[1.0, 0.5]]))
    with pytest.raises(fibrefit.FibrefitError, match="uv row 0"):
        m.eval(v, v, np.array([[np.inf, 0.5]]))


def test_files_of_the_wrong_kind_raise(tmp_path):
    other = tmp_path / "other.json"
    other.write_text('{"schema": "fibrefit-result/9", "model": "lambert", "parameters": {}}')
    with pytest.raises(fibrefit.FibrefitError, match="result schema `fibrefit-result/9`"):
        fibrefit.load(other)
    with pytest.raises(fibrefit.FibrefitError, match="missing.json"):
        fibrefit.load(tmp_path / "missing.json")
    bad = write_params(tmp_path, "bad.json", '{"model": "lambert", "kd": 7}')
    with pytest.raises(fibrefit.FibrefitError, match=r"kd.*out of range"):
        fibrefit.load(bad)


def test_grey_results_have_one_channel(tmp_path, rng):
    m = fibrefit.load(write_params(tmp_path, "w.json", '{"model": "ward", "rho_d": 0.2, "rho_s": 0.1, "alpha_x": 0.2, "alpha_y": 0.4}'))
    l, v = hemisphere(10, rng), hemisphere(10, rng)
    assert m.channels == 1 and m.eval(l, v).shape == (10, 1)
    _, w, p = m.sample(v, rng.random((10, 2)))
    assert w.shape == (10, 1) and p.shape == (10,)
    # lists and float32 arrays are accepted
    assert m.eval(l.astype(np.float32).tolist(), v.astype(np.float32)).shape == (10, 1)
