"""How far along its planned path a walking robot says it is (finer waits:
``agent.core.formation.waves.release.walked_along``, published as ``StatusMsg.walked``)."""

from __future__ import annotations

import numpy as np
import pytest

from agent.core.formation.waves.release import walked_along


def test_walked_along_counts_the_legs_and_the_way_left() -> None:
    goals = [np.array([3.0, 4.0]), np.array([3.0, 10.0])]  # legs of 5 m and 6 m
    assert walked_along(goals, 0, np.zeros(2)) == 0.0
    assert walked_along(goals, 0, np.array([0.6, 0.8])) == pytest.approx(1.0)
    assert walked_along(goals, 1, np.array([3.0, 7.0])) == pytest.approx(8.0)
    # 1 m beside the leg at its middle: counted as sqrt(3^2 + 1) from its goal
    assert walked_along(goals, 1, np.array([4.0, 7.0])) == pytest.approx(11 - 10**0.5)
    assert walked_along(goals, 1, np.array([3.0, 11.0])) == pytest.approx(10.0)  # overshoot
    assert walked_along(goals, 5, np.zeros(2)) == pytest.approx(11.0)  # past the last leg
