"""The common frame placed in the world by a rigid fit (tools/lib/frame_fit.py)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from tools.harness.view.scene import to_world
from tools.lib.frame_fit import common_frame_pose, frame_error, truth_in_frame


def test_a_turned_and_moved_frame_is_recovered() -> None:
    plan = {1: np.array([0.0, 0.0]), 2: np.array([1.0, 0.0]), 3: np.array([0.0, 2.0])}
    turn, at = math.radians(40), np.array([3.0, -1.0])
    c, s = math.cos(turn), math.sin(turn)
    true = {i: (*(at + np.array([[c, -s], [s, c]]) @ p), 0.0) for i, p in plan.items()}
    x, y, h = common_frame_pose(plan, true)
    assert (x, y) == pytest.approx(tuple(at)) and h == pytest.approx(turn + math.pi / 2)
    for i, p in plan.items():
        assert to_world(p, (x, y, h)) == pytest.approx(true[i][:2])


def test_one_robot_uses_its_heading_and_none_is_an_error() -> None:
    x, y, h = common_frame_pose({1: np.zeros(2)}, {1: (0.5, 0.5, 1.0), 2: (0.0, 0.0, 0.0)})
    assert (x, y, h) == pytest.approx((0.5, 0.5, 1.0))
    with pytest.raises(ValueError, match="no planned robot"):
        common_frame_pose({1: np.zeros(2)}, {2: (0.0, 0.0, 0.0)})


def test_truth_in_frame_is_what_frame_error_reads_back() -> None:
    """Poses written in robot 2's frame from the truth are judged 0 m and 0° off, and the
    frame robot stands at the origin facing ψ 0; a robot without a truth is an error."""
    truth = {1: (1.0, 2.0, 0.3), 2: (3.0, -1.0, 2.0), 3: (-2.0, 0.5, -1.0)}
    pos, psi = truth_in_frame(truth, [1, 2, 3], 2)
    assert np.allclose(pos[1], 0.0) and psi[1] == 0.0
    # robot 1 at its true distance from robot 2
    assert np.hypot(*pos[0]) == pytest.approx(math.hypot(2.0, 3.0))
    err = frame_error({i: (pos[k], float(psi[k])) for k, i in enumerate([1, 2, 3])}, truth)
    assert err == pytest.approx((0.0, 0.0), abs=1e-12)
    with pytest.raises(ValueError, match=r"\[4\]"):
        truth_in_frame(truth, [1, 4], 2)
