import math

import numpy as np
import pytest

from agent.core.perception.camera import CameraModel


def test_intrinsics_match_common_conventions() -> None:
    cam = CameraModel()
    assert cam.fx == pytest.approx(320 / math.tan(math.radians(30.45)))
    assert (cam.cx, cam.cy) == (320.0, 240.0)


def test_pixel_bearing_known_answers() -> None:
    cam = CameraModel()
    assert cam.pixel_bearing(320.0) == 0.0
    assert cam.pixel_bearing(0.0) == pytest.approx(math.radians(30.45))  # left edge: +left
    assert cam.pixel_bearing(640.0) == pytest.approx(-math.radians(30.45))
    for b in (-0.4, -0.1, 0.0, 0.25, 0.5):
        assert cam.pixel_bearing(cam.bearing_column(b)) == pytest.approx(b)


def test_cylindrical_map_is_identity_at_centre_and_angle_linear() -> None:
    cam = CameraModel()
    mx, my = cam.cylindrical_maps()
    assert mx[240, 320] == pytest.approx(320.0)
    assert my[240, 320] == pytest.approx(240.0)
    # cylindrical column u' sees the ray at bearing (cx - u')/fx
    for u_cyl in (10, 100, 500, 630):
        src = float(mx[240, u_cyl])
        assert cam.pixel_bearing(src) == pytest.approx(cam.cyl_bearing(u_cyl), abs=1e-5)


def test_body_offset_rotates_with_head_yaw() -> None:
    cam = CameraModel(cam_forward=0.05, neck_forward=0.01)
    assert cam.body_offset(0.0) == pytest.approx((0.06, 0.0))
    assert cam.body_offset(math.pi / 2) == pytest.approx((0.01, 0.05))


def test_bad_inputs() -> None:
    cam = CameraModel()
    with pytest.raises(ValueError, match="finite"):
        cam.pixel_bearing(float("nan"))
    with pytest.raises(ValueError, match="finite"):
        cam.cyl_bearing(float("inf"))
    with pytest.raises(ValueError, match="behind"):
        cam.bearing_column(math.pi / 2)
    with pytest.raises(ValueError, match="too small"):
        CameraModel(width=8)
    with pytest.raises(ValueError, match="hfov"):
        CameraModel(hfov=0.0)
    assert np.isfinite(cam.cylindrical_maps()[0]).all()


def test_sweep_yaws_see_every_nao_whole() -> None:
    cam = CameraModel()
    yaws = cam.sweep_yaws()
    assert len(yaws) == 10
    assert yaws[0] == pytest.approx(-math.radians(119.5)) and yaws[-1] == pytest.approx(
        math.radians(119.5)
    )
    half = math.atan(0.15 / 0.5)
    for b in np.linspace(-math.radians(119.5), math.radians(119.5), 2001):
        assert any(abs(b - y) + half <= cam.hfov / 2 + 1e-9 for y in yaws)
    assert len(cam.sweep_yaws(min_distance=1.0)) < len(yaws)
    with pytest.raises(ValueError, match="min_distance"):
        cam.sweep_yaws(min_distance=0.1)
    with pytest.raises(ValueError, match="fit"):
        CameraModel(hfov=math.radians(20)).sweep_yaws(min_distance=0.2)
