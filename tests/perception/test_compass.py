import math

import numpy as np
import pytest

from agent.core.perception.camera import CameraModel
from agent.core.perception.compass import VisualCompass
from tests.perception.synth import canvas, textured_panorama, view_of_panorama

CAM = CameraModel()


@pytest.fixture(scope="module")
def pano() -> np.ndarray:
    return textured_panorama(7, CAM.fx)


@pytest.mark.parametrize("step_deg", [-15.0, -5.0, 0.0, 7.5, 15.0])
def test_turn_measured_within_half_degree(pano: np.ndarray, step_deg: float) -> None:
    vc = VisualCompass(CAM)
    a = view_of_panorama(pano, 0.3, CAM.fx, CAM.fy)
    b = view_of_panorama(pano, 0.3 + math.radians(step_deg), CAM.fx, CAM.fy)
    r = vc.measure(a, b)
    assert r.ok, r.reason
    assert math.degrees(r.dtheta) == pytest.approx(step_deg, abs=0.5)
    assert r.inliers <= r.matches and 0.4 <= r.inlier_ratio <= 1.0


def test_featureless_view_fails_instead_of_guessing() -> None:
    r = VisualCompass(CAM).measure(canvas(), canvas())
    assert not r.ok and r.dtheta == 0.0 and "featureless" in r.reason


def test_step_beyond_the_field_of_view_fails(pano: np.ndarray) -> None:
    a = view_of_panorama(pano, 0.0, CAM.fx, CAM.fy)
    b = view_of_panorama(pano, math.radians(75), CAM.fx, CAM.fy)
    r = VisualCompass(CAM).measure(a, b)
    assert not r.ok and r.dtheta == 0.0 and r.reason


def test_bad_inputs(pano: np.ndarray) -> None:
    a = view_of_panorama(pano, 0.0, CAM.fx, CAM.fy)
    vc = VisualCompass(CAM)
    with pytest.raises(ValueError, match="expects 640x480"):
        vc.measure(a, a[:240, :320])
    with pytest.raises(ValueError, match=r"\(h, w, 3\)"):
        vc.measure(a[:, :, 0], a)
    with pytest.raises(ValueError, match="min_matches"):
        VisualCompass(CAM, min_matches=1)
    with pytest.raises(ValueError, match="ratio"):
        VisualCompass(CAM, min_inlier_ratio=0.0)
    with pytest.raises(ValueError, match="> 0"):
        VisualCompass(CAM, tol=0.0)
