import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from agent.core.perception import compass as cp
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


# ------------------------------------------------------------ the same answers, cheaper
def _table(votes: np.ndarray, level: np.ndarray, tol: float) -> np.ndarray:
    """The m×m table the counts stand for."""
    return ((np.abs(votes[:, None] - votes[None, :]) <= tol) & level[None, :]).sum(axis=1)


@given(
    st.lists(st.integers(-40, 40), max_size=120),
    st.lists(st.booleans(), min_size=120, max_size=120),
    st.sampled_from([0.0, 1e-18, 1e-12]),
)
@settings(max_examples=300, deadline=None)
def test_inlier_counts_are_the_tables(ticks: list[int], level: list[bool], jitter: float) -> None:
    """Votes on a grid of tol/7 (many at exactly tol apart, where rounding decides),
    nudged by ``jitter``: the sorted count is the table's, vote for vote."""
    tol = math.radians(0.4)
    votes = np.array(ticks, dtype=np.float64) * (tol / 7.0)
    votes = votes + jitter * np.where(np.arange(len(votes)) % 2 == 0, 1.0, -1.0)
    lv = np.array(level[: len(votes)], dtype=bool)
    assert (cp._within(votes, lv, tol) == _table(votes, lv, tol)).all()


def test_a_pictures_features_are_kept_and_give_the_same_answer(pano: np.ndarray) -> None:
    a = view_of_panorama(pano, 0.3, CAM.fx, CAM.fy)
    b = view_of_panorama(pano, 0.35, CAM.fx, CAM.fy)
    c = view_of_panorama(pano, 0.4, CAM.fx, CAM.fy)
    kept = VisualCompass(CAM)
    first = [kept.measure(a, b), kept.measure(b, c), kept.measure(a, c)]
    again = [kept.measure(a, b), kept.measure(b, c), kept.measure(a, c)]
    fresh = [VisualCompass(CAM).measure(x, y) for x, y in ((a, b), (b, c), (a, c))]
    assert first == again == fresh and all(r.ok for r in first)
    assert len(kept._cache) <= cp.FEATURE_CACHE
    # a picture changed in place is a new picture, never its old features
    d = a.copy()
    kept.measure(d, b)
    d[200:280, 300:340] = 255 - d[200:280, 300:340]
    assert kept.measure(d, b) == VisualCompass(CAM).measure(d, b)
