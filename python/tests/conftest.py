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
