"""Issue 42 in Python: every error a FibrefitError with the CLI's message, complex input refused,
and a wait on a FIFO stopped by Ctrl-C (KeyboardInterrupt), never a hang."""

import json
import os
import shutil
import signal
import threading
import time

import numpy as np
import pytest

import fibrefit
from conftest import DATA, direction


def _material():
    return fibrefit.load(DATA / "brushed" / "truth.json")


@pytest.mark.parametrize("index", [-1, 2**64, 10**40, True, 1.5, "0"])
def test_image_indices_out_of_range_raise_fibrefit_errors(index):
    m = _material()
    with pytest.raises(fibrefit.FibrefitError):
        m.render_capture(DATA / "brushed" / "capture.toml", index)


def test_an_index_beyond_the_images_names_the_capture():
    m = _material()
    with pytest.raises(fibrefit.FibrefitError, match="capture"):
        m.render_capture(DATA / "brushed" / "capture.toml", 2**63)


def test_complex_arrays_are_refused():
    m = _material()
    l = direction(30, 0)[None, :]
    v = direction(40, 180)[None, :]
    with pytest.raises(fibrefit.FibrefitError, match="complex"):
        m.eval(l.astype(complex) + 1e-3j, v)
    with pytest.raises(fibrefit.FibrefitError, match="complex"):
        m.eval(l, v.astype(np.complex64))
    # real arrays of complex dtype are refused too: the type says what the caller meant
    with pytest.raises(fibrefit.FibrefitError, match="complex"):
        m.pdf(v.astype(complex), l)


def test_a_directory_given_as_a_result_is_named_as_one(tmp_path):
    for name in ["fit.json", "data.csv", "plain"]:
        d = tmp_path / name
        d.mkdir()
        with pytest.raises(fibrefit.FibrefitError, match="is a directory"):
            fibrefit.load(d)


def _interrupt_after(seconds):
    # Python's own Ctrl-C handler, whatever the process inherited: a shell that starts the
    # tests in the background (nohup, `&` without job control) hands them SIGINT ignored,
    # and Python then leaves it ignored
    signal.signal(signal.SIGINT, signal.default_int_handler)

    def fire():
        time.sleep(seconds)
        os.kill(os.getpid(), signal.SIGINT)

    t = threading.Thread(target=fire, daemon=True)
    t.start()
    return t


def test_ctrl_c_stops_a_fit_waiting_on_a_fifo_nobody_writes(tmp_path):
    fifo = tmp_path / "in.csv"
    os.mkfifo(fifo)
    t = _interrupt_after(0.5)
    start = time.monotonic()
    with pytest.raises(KeyboardInterrupt):
        fibrefit.fit(fifo, model="lambert")
    t.join()
    assert time.monotonic() - start < 10
    assert sorted(os.listdir(tmp_path)) == ["in.csv"]


def test_ctrl_c_stops_loading_maps_from_a_fifo(tmp_path):
    # a fitted result naming its maps, one of which is a FIFO
    res = {
        "schema": "fibrefit-result/1",
        "model": "lambert",
        "parameters": {"kd": {"value": 0.5}},
        "maps": {"directory": "maps"},
    }
    (tmp_path / "r.json").write_text(json.dumps(res))
    (tmp_path / "maps").mkdir()
    os.mkfifo(tmp_path / "maps" / "kd.exr")
    t = _interrupt_after(0.5)
    start = time.monotonic()
    with pytest.raises(KeyboardInterrupt):
        fibrefit.load(tmp_path / "r.json")
    t.join()
    assert time.monotonic() - start < 10
    # after the interrupt, the module works as before
    assert fibrefit.load(DATA / "brushed" / "truth.json").channels >= 1
    shutil.rmtree(tmp_path / "maps")
