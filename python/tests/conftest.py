"""Shared paths and helpers of the Python tests (run from anywhere: `pytest python/tests`)."""

import os
import pathlib

import numpy as np
import pytest

ROOT = pathlib.Path(__file__).resolve().parents[2]
DATA = ROOT / "data_synthetic"
CONFIGS = ROOT / "configs"


def hemisphere(n, rng, max_theta_deg=89.0):
    """n directions uniform in solid angle above the horizon, up to max_theta_deg."""
    cmin = np.cos(np.radians(max_theta_deg))
    z = cmin + (1 - cmin) * rng.random(n)
    phi = 2 * np.pi * rng.random(n)
    s = np.sqrt(1 - z * z)
    return np.stack([s * np.cos(phi), s * np.sin(phi), z], axis=1)


def direction(theta_deg, phi_deg):
    t, p = np.radians(theta_deg), np.radians(phi_deg)
    return np.array([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)])


@pytest.fixture
def rng():
    return np.random.default_rng(7)


def write_params(tmp_path, name, text):
    p = tmp_path / name
    p.write_text(text)
    return p


def cli_binary():
    """The `fibrefit` command line to compare the bindings with: $FIBREFIT_CLI, else the newest
    of the workspace's target/{release,debug}/fibrefit ($CARGO_TARGET_DIR's first), else one
    on PATH; None when there is none (`cargo build` makes one; CI's `cargo test` does)."""
    import shutil

    env = os.environ.get("FIBREFIT_CLI")
    if env:
        return env
    dirs = [pathlib.Path(os.environ["CARGO_TARGET_DIR"])] if os.environ.get("CARGO_TARGET_DIR") else []
    dirs.append(ROOT / "target")
    for d in dirs:
        found = [d / p / "fibrefit" for p in ("release", "debug") if (d / p / "fibrefit").is_file()]
        if found:
            return str(max(found, key=lambda p: p.stat().st_mtime))
    return shutil.which("fibrefit")
