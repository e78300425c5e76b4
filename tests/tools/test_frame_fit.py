"""The common frame placed in the world by a rigid fit (tools/lib/frame_fit.py)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from tools.harness.view.scene import to_world
from tools.lib.frame_fit import common_frame_pose


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
