"""The plan turned to one robot's fixed frame (agent/core/formation/view/own_frame.py)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from agent.core.formation.params import D_E, PlanParams
from agent.core.formation.plan import plan_from_positions
from agent.core.formation.view.own_frame import in_own_frame

IDS = [1, 2, 3, 4]
STARTS = np.array([[0.0, 0.0], [1.0, 0.1], [0.2, 1.1], [-0.9, 0.4]])


def _plan():  # type: ignore[no-untyped-def]
    return plan_from_positions(IDS, STARTS, PlanParams(d_e=D_E))


def test_zero_gives_the_same_plan() -> None:
    plan = _plan()
    assert in_own_frame(plan, 0.0) is plan


def test_a_quarter_turn_worked_by_hand() -> None:
    # robot 2's fixed frame is the common frame turned by +90°: a common-frame vector
    # (1, 0) is (0, -1) in it; headings drop by 90°
    plan = _plan()
    mine = in_own_frame(plan, math.pi / 2)
    r, m = plan.robot(2), mine.robot(2)
    d = np.asarray(r.target) - np.asarray(r.start)
    np.testing.assert_allclose(
        np.asarray(m.target) - np.asarray(m.start), [d[1], -d[0]], atol=1e-12
    )
    assert mine.axis == pytest.approx(math.remainder(plan.axis - math.pi / 2, 2 * math.pi))
    assert m.heading == pytest.approx(math.remainder(r.heading - math.pi / 2, 2 * math.pi))
    assert mine.digest == plan.digest and mine.ids == plan.ids and mine.leader == plan.leader


@settings(max_examples=30, deadline=None)
@given(st.floats(-math.pi, math.pi))
def test_turning_keeps_every_distance_and_the_round_trip(psi: float) -> None:
    plan = _plan()
    mine = in_own_frame(plan, psi)
    for a, b in zip(plan.robots, mine.robots, strict=True):
        assert np.hypot(*(b.target - b.start)) == pytest.approx(np.hypot(*(a.target - a.start)))
        assert b.parent == a.parent and b.wave == a.wave
    back = in_own_frame(mine, -psi)
    np.testing.assert_allclose(back.targets(), plan.targets(), atol=1e-9)
    assert math.cos(back.axis - plan.axis) == pytest.approx(1.0)


def test_non_finite_turn() -> None:
    with pytest.raises(ValueError, match="finite"):
        in_own_frame(_plan(), math.nan)
