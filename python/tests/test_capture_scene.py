"""fibrefit.mitsuba.image_scene: a capture image's light and camera from the library
(`fibrefit::api::capture`), equal to the Python derivation `capture_scene` had before it (kept
here as the reference) for every image of the shipped captures, orthographic and pinhole,
directional and point lights; and the same refusals. Needs no Mitsuba."""

import math

import numpy as np
import pytest

import fibrefit
import fibrefit.mitsuba as fm
from conftest import DATA

CAPTURES = ["brushed", "loose", "silk"]


def _direction(theta_deg, phi_deg):
    t, p = math.radians(theta_deg), math.radians(phi_deg)
    return np.array([math.sin(t) * math.cos(p), math.sin(t) * math.sin(p), math.cos(t)])


def old_scene(capture, k):
    """The light and camera of image k as `capture_scene` derived them in Python (until the
    library gave them): Mitsuba's numbers."""
    geo = fm.capture_geometry(capture)
    img = geo["images"][k]
    w_mm, h_mm = geo["swatch"]["size_mm"]
    W, H = int(img["width"]), int(img["height"])
    light = img["light"]
    if light["type"] == "directional":
        ld = _direction(light["theta_deg"], light["phi_deg"])
        emitter = {"direction": (-ld).tolist(), "irradiance": light["irradiance"]}
    else:
        emitter = {"position": list(map(float, light["position_mm"])), "intensity": light["intensity"] * 1e6}
    cam = img["camera"]
    if cam["type"] == "orthographic":
        v = _direction(cam["theta_deg"], cam["phi_deg"])
        a = H / W
        far = 10.0 * (w_mm + h_mm)
        m = np.zeros((4, 4))
        m[:3, 0] = [-w_mm / 2.0, 0.0, 0.0]
        m[:3, 1] = [0.0, h_mm / (2.0 * a), 0.0]
        m[:3, 2] = -v
        m[:3, 3] = far * v
        m[3, 3] = 1.0
        sensor = {"to_world": m.tolist(), "near_clip": 1e-3, "far_clip": 4.0 * far}
    else:
        cx, cy, cz = map(float, cam["position_mm"])
        sensor = {
            "to_world": [[-1.0, 0.0, 0.0, cx], [0.0, 1.0, 0.0, cy], [0.0, 0.0, -1.0, cz], [0.0, 0.0, 0.0, 1.0]],
            "fov": math.degrees(2.0 * math.atan(w_mm / (2.0 * cz))),
            "principal_point_offset_x": -cx / w_mm,
            "principal_point_offset_y": cy / h_mm,
            "near_clip": 1e-3,
            "far_clip": 10.0 * (cz + w_mm + h_mm),
        }
    return (W, H, (w_mm, h_mm)), light["type"], emitter, cam["type"], sensor


def close(a, b):
    np.testing.assert_allclose(np.asarray(a, dtype=float), np.asarray(b, dtype=float), rtol=0, atol=1e-12)


def check(capture):
    n = len(fm.capture_geometry(capture)["images"])
    kinds = set()
    for k in range(n):
        (W, H, size), light_type, emitter, cam_type, sensor = old_scene(capture, k)
        g = fm.image_scene(capture, k)
        assert (g["width"], g["height"]) == (W, H)
        close(g["size_mm"], size)
        light = g["light"]
        assert light["type"] == light_type
        if light_type == "directional":
            close([-c for c in light["towards_light"]], emitter["direction"])
            close(light["irradiance"], emitter["irradiance"])
        else:
            close(light["position_mm"], emitter["position"])
            close(light["intensity_mm"], emitter["intensity"])
        cam = g["camera"]
        assert cam["type"] == cam_type
        close(cam["to_world"], sensor["to_world"])
        close(cam["near_clip_mm"], sensor["near_clip"])
        close(cam["far_clip_mm"], sensor["far_clip"])
        if cam_type == "pinhole":
            close(cam["fov_x_deg"], sensor["fov"])
            close(cam["principal_point_offset_x"], sensor["principal_point_offset_x"])
            close(cam["principal_point_offset_y"], sensor["principal_point_offset_y"])
        kinds.add((light_type, cam_type))
    return kinds


def test_the_shipped_captures_give_the_old_derivation():
    kinds = set()
    for name in CAPTURES:
        kinds |= check(DATA / name / "capture.toml")
    # every kind of light and camera was compared
    assert {l for l, _ in kinds} == {"directional", "point"}
    assert {c for _, c in kinds} == {"orthographic", "pinhole"}


def _capture(tmp_path, camera, size="30.0, 30.0", light='type = "point"\nposition_mm = [-60.0, 40.0, 250.0]\nintensity = 0.05'):
    png = (DATA / "brushed" / "img_000.png").resolve()
    cap = tmp_path / "capture.toml"
    cap.write_text(
        f"""[swatch]
size_mm = [{size}]

[[images]]
file = "{png}"
encoding = "srgb"
exposure = 1.0
[images.light]
{light}
[images.camera]
{camera}
"""
    )
    return cap


def test_an_off_axis_pinhole_and_point_light_give_the_old_derivation(tmp_path):
    cap = _capture(tmp_path, 'type = "pinhole"\nposition_mm = [35.0, -20.0, 300.0]')
    assert check(cap) == {("point", "pinhole")}


def test_the_refusals(tmp_path):
    low = _capture(tmp_path, 'type = "pinhole"\nposition_mm = [0.0, 0.0, -5.0]')
    with pytest.raises(fibrefit.FibrefitError, match="not above the swatch"):
        fm.image_scene(low, 0)
    oblong = _capture(tmp_path, 'type = "pinhole"\nposition_mm = [0.0, 0.0, 300.0]', size="30.0, 20.0")
    with pytest.raises(fibrefit.FibrefitError, match="not square"):
        fm.image_scene(oblong, 0)
    # an orthographic camera renders non-square pixels
    ortho = _capture(tmp_path, 'type = "orthographic"\ntheta_deg = 20.0\nphi_deg = 10.0', size="30.0, 20.0")
    assert check(ortho) == {("point", "orthographic")}
    views = _capture(tmp_path, 'type = "view-map"\nfile = "views.exr"')
    with pytest.raises(fibrefit.FibrefitError, match="view-map"):
        fm.image_scene(views, 0)
    with pytest.raises(fibrefit.FibrefitError, match="image 4 asked for, but the capture has 4 images"):
        fm.image_scene(DATA / "brushed" / "capture.toml", 4)
    with pytest.raises(fibrefit.FibrefitError):
        fm.image_scene(DATA / "brushed" / "capture.toml", -1)
