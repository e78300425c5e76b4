"""Segment geometry: distances and the crossing rule (NAO paper Lemma 1)."""

from __future__ import annotations

import numpy as np
import pytest

from agent.core.formation.paths.geometry import point_seg_dist, seg_seg_dist


def P(*pts: tuple[float, float]) -> np.ndarray:
    return np.array(pts, dtype=np.float64)


def test_geometry_known_answers() -> None:
    assert point_seg_dist(P((0, 1)), P((-1, 0)), P((1, 0)))[0] == pytest.approx(1.0)
    assert point_seg_dist(P((3, 4)), P((0, 0)), P((0, 0)))[0] == pytest.approx(5.0)
    assert seg_seg_dist(P((0, 0)), P((2, 2)), P((0, 2)), P((2, 0)))[0] == 0.0  # crossing
    assert seg_seg_dist(P((0, 0)), P((1, 0)), P((0, 0.3)), P((1, 0.3)))[0] == pytest.approx(0.3)


def test_collinear_disjoint_segments_are_not_a_crossing() -> None:
    # two legs on one slanted line (rounding makes the orientations tiny, of any sign)
    u = np.array([np.cos(0.7), np.sin(0.7)])
    for k in range(50):
        a0, a1 = 0.1 * k * u, (0.1 * k + 1.0) * u
        b0, b1 = (0.1 * k + 3.0) * u, (0.1 * k + 5.0) * u
        assert seg_seg_dist(a0, a1, b0, b1) == pytest.approx(2.0)
