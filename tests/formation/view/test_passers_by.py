"""Who may still pass a robot's final alignment (agent/core/formation/view/passers_by.py)."""

from __future__ import annotations

import random

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from agent.core.formation.plan import Plan, RobotPlan
from agent.core.formation.view.passers_by import passers_by


def robot(
    rid: int,
    start: tuple[float, float],
    target: tuple[float, float],
    parent: int,
    *via: tuple[float, float],
) -> RobotPlan:
    return RobotPlan(
        robot_id=rid,
        start=np.array(start, dtype=float),
        target=np.array(target, dtype=float),
        order=rid,
        parent=parent,
        heading=0.0,
        distance=0.0,
        via=tuple(np.array(v, dtype=float) for v in via),
    )


def plan_of(*robots: RobotPlan) -> Plan:
    rs = tuple(sorted(robots, key=lambda r: r.robot_id))
    return Plan(
        frame_robot=rs[0].robot_id,
        leader=rs[0].robot_id,
        axis=0.0,
        origin=np.zeros(2),
        robots=rs,
        waves=(tuple(r.robot_id for r in rs),),
        digest="test",
    )


# Worked by hand: leader 1 at (0, 0); its child 2 at (-0.7, -0.4); the sight line of 2
# is the segment (-0.7, -0.4)-(0, 0).
PLAN = plan_of(
    robot(1, (0.0, 3.0), (0.0, 0.0), -1),
    robot(2, (-3.0, -0.4), (-0.7, -0.4), 1),
    # 3 walks along y = -1.0 from x = -2 to x = 2: 0.6 m below the child's slot
    robot(3, (-2.0, -1.0), (2.0, -1.0), 1),
    # 4 walks from (1, 1) down x = 1 to (1, -0.1), then to (3, 1): its first leg passes
    # 1.0 m right of the leader's slot, the (0, 0) end of the sight line
    robot(4, (1.0, 1.0), (3.0, 1.0), 1, (1.0, -0.1)),
    # 5 stays where it stands, on the sight line itself: it passes nobody
    robot(5, (-0.35, -0.2), (-0.35, -0.2), 1),
)


def test_known_answer_for_the_child() -> None:
    # 1's path ends on the sight line (distance 0); 3's comes 0.6 m from (-0.7, -0.4);
    # 4's legs x = 1 stay 1.0 m from the segment's end (0, 0); 5 does not move
    assert passers_by(PLAN, 2, 0.7) == (1, 3)
    assert passers_by(PLAN, 2, 0.59) == (1,)
    assert passers_by(PLAN, 2, 1.0) == (1, 3, 4)


def test_the_leader_has_only_its_slot() -> None:
    # around (0, 0): 2's path ends 0.81 m away, 3's passes 1.0 m below, 4's 1.0 m right
    assert passers_by(PLAN, 1, 0.8) == ()
    assert passers_by(PLAN, 1, 0.9) == (2,)
    assert passers_by(PLAN, 1, 1.0) == (2, 3, 4)


def test_errors() -> None:
    with pytest.raises(ValueError, match="margin"):
        passers_by(PLAN, 2, -0.1)
    with pytest.raises(ValueError, match="margin"):
        passers_by(PLAN, 2, float("nan"))
    with pytest.raises(ValueError, match="not in the plan"):
        passers_by(PLAN, 9, 0.7)


@settings(deadline=None)  # a deadline fails under load, never on the answer
@given(seed=st.integers(0, 2**32 - 1), margin=st.floats(0.0, 3.0))
def test_the_answer_does_not_depend_on_the_order_of_the_robots(seed: int, margin: float) -> None:
    """Every agent computes the same set: shuffled inputs give the same sorted ids, and
    a larger margin never takes a robot out."""
    rs = list(PLAN.robots)
    random.Random(seed).shuffle(rs)
    shuffled = Plan(
        frame_robot=1,
        leader=1,
        axis=0.0,
        origin=np.zeros(2),
        robots=tuple(rs),
        waves=PLAN.waves,
        digest="test",
    )
    for rid in (1, 2):
        got = passers_by(shuffled, rid, margin)
        assert got == passers_by(PLAN, rid, margin) == tuple(sorted(got))
        assert set(got) <= set(passers_by(PLAN, rid, margin + 0.5))
