"""The circle pattern (AUV paper III.B.2.a): its circle as a shape
(agent/core/formation/shape/circle_pattern.py), the circle planned round the frame robot,
which stands still (agent/core/formation/plan.py), and the formation planned from the
circle with the robot at 90° as its leader where it stands (reshape.py ``from_circle``)."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from agent.core.formation.params import PlanParams
from agent.core.formation.plan import first_shape, plan_from_positions, plan_from_records
from agent.core.formation.reshape import circle_leader, from_circle
from agent.core.formation.shape.circle_pattern import CIRCLE_NAME, circle, ring_radius
from agent.core.formation.shape.spec import BUILTIN, PYRAMID
from tests.formation.conftest import random_fleet, records_from_positions
from tests.formation.test_plan_shapes import assert_shape_plan

CP = PlanParams(orientation="cp")
D = CP.d_e


def test_radius_known_answers() -> None:
    assert ring_radius(2, D) == D  # one robot on the circle: d_e ahead
    assert ring_radius(4, D) == D  # a triangle's side d_e·√3 > d_e: R = d_e
    assert ring_radius(7, D) == pytest.approx(D)  # a hexagon: side = R
    # seven on the circle: R = d_e / (2 sin(π/7)) = 1.1524 d_e
    assert ring_radius(8, D) == pytest.approx(D / (2 * math.sin(math.pi / 7)))
    assert ring_radius(8, D) == pytest.approx(1.15238 * D, rel=1e-5)


@pytest.mark.parametrize(
    ("n", "d_e", "match"),
    [(1, D, "at least 2"), (True, D, "at least 2"), (2.0, D, "at least 2"),
     (4, 0.0, "d_e"), (4, math.inf, "d_e"), (4, -1.0, "d_e")],
)  # fmt: skip
def test_radius_errors(n: object, d_e: float, match: str) -> None:
    with pytest.raises(ValueError, match=match):
        ring_radius(n, d_e)  # type: ignore[arg-type]


@pytest.mark.parametrize("n", [2, 3, 4, 6, 8, 13])
def test_the_circle_round_its_centre(n: int) -> None:
    """Slot 0 is the centre; every other slot is its child at R; slot 1 straight ahead;
    neighbours on the circle >= d_e apart, each d_e or more from the centre."""
    shape = circle(n, D)
    assert shape.name == CIRCLE_NAME and shape.capacity == n
    s = shape.slots(n, D, CP.phi_e)
    assert s.parent[0] == -1 and list(s.parent[1:]) == [0] * (n - 1)
    r = ring_radius(n, D)
    np.testing.assert_allclose(np.hypot(*s.positions[1:].T), r, rtol=1e-12)
    np.testing.assert_allclose(s.positions[1], [0.0, r], atol=1e-12)
    d = np.hypot(*(s.positions[:, None] - s.positions[None]).transpose(2, 0, 1))
    assert d[~np.eye(n, dtype=bool)].min() >= D - 1e-9


def fleet(n: int, seed: int) -> tuple[list[int], np.ndarray]:
    rng = np.random.default_rng([n, seed, 34])
    return list(range(1, n + 1)), random_fleet(rng, n, 0.6)


@pytest.mark.parametrize(("n", "seed"), [(4, 1), (6, 2), (6, 3), (10, 4)])
def test_the_circle_is_planned_round_the_frame_robot(n: int, seed: int) -> None:
    """From ideal records: the frame robot keeps slot 0 where it stands, the others take
    the circle round it, slot 1 at 90° of the common frame; the plan is safe."""
    ids, pos = fleet(n, seed)
    plan = plan_from_records(records_from_positions(ids, pos, seen=99.0), CP)
    centre = plan.robot(plan.frame_robot)
    assert centre.order == 0 and centre.distance == 0.0 and centre.via == ()
    np.testing.assert_array_equal(centre.target, centre.start)
    assert plan.axis == math.pi / 2
    assert_shape_plan(plan, circle(n, D), D, CP.phi_e)
    ahead = circle_leader(plan)
    np.testing.assert_allclose(
        plan.robot(ahead).target - centre.target, [0.0, ring_radius(n, D)], atol=1e-9
    )
    assert first_shape(CP, n) == circle(n, D) and first_shape(PlanParams(), n) == PYRAMID


@pytest.mark.parametrize(("n", "seed"), [(4, 1), (6, 2), (6, 3), (10, 4)])
def test_the_formation_is_planned_from_the_circle(n: int, seed: int) -> None:
    """The robot at 90° leads where it stands; the pyramid faces north; every robot starts
    on its circle slot; the digest chains the circle's."""
    ids, pos = fleet(n, seed)
    ring = plan_from_records(records_from_positions(ids, pos, seen=99.0), CP)
    final = from_circle(ring, CP)
    lead = circle_leader(ring)
    assert final.leader == lead
    r = final.robot(lead)
    assert r.distance == 0.0 and r.via == ()
    np.testing.assert_array_equal(r.target, ring.robot(lead).target)
    np.testing.assert_array_equal(final.starts(), ring.targets())
    assert final.axis == math.pi / 2
    assert_shape_plan(final, PYRAMID, D, CP.phi_e)
    assert final.digest != ring.digest
    # every slot behind the leader, the formation's front
    assert float(np.max(final.targets()[:, 1])) == pytest.approx(r.target[1])


def test_another_shape_from_the_circle() -> None:
    ids, pos = fleet(6, 5)
    params = replace(CP, shape=BUILTIN["wedge"])
    ring = plan_from_records(records_from_positions(ids, pos, seen=99.0), params)
    final = from_circle(ring, params)
    assert final.leader == circle_leader(ring)
    assert_shape_plan(final, BUILTIN["wedge"], D, CP.phi_e)


def test_from_circle_needs_the_circle_pattern() -> None:
    ids, pos = fleet(4, 1)
    ring = plan_from_records(records_from_positions(ids, pos, seen=99.0), CP)
    with pytest.raises(ValueError, match="'cp'"):
        from_circle(ring, PlanParams())


def test_a_fleet_of_one_has_no_circle() -> None:
    plan = plan_from_records(records_from_positions([5], np.zeros((1, 2))), CP)
    assert plan.leader == 5 and circle_leader(plan) == 5
    assert first_shape(CP, 1) == PYRAMID


def test_the_anchor_must_be_a_robot() -> None:
    ids, pos = fleet(4, 1)
    with pytest.raises(ValueError, match="anchor 9"):
        plan_from_positions(ids, pos, CP, anchor=9)


def test_no_safe_plan_with_the_anchor_in_place() -> None:
    """An obstacle on a circle slot: the circle cannot be scheduled round the anchor."""
    ids, pos = fleet(4, 1)
    params = replace(CP, shape=circle(4, D))
    on_slot = pos[0] + np.array([0.0, ring_radius(4, D)])
    with pytest.raises(ValueError, match="robot 1 holding slot 0"):
        plan_from_positions(ids, pos, params, obstacles=on_slot[None], anchor=1)


@settings(max_examples=25, deadline=None)
@given(n=st.integers(2, 9), seed=st.integers(0, 10_000), data=st.data())
def test_property_shuffled_records_plan_the_same_circle_and_formation(
    n: int, seed: int, data: st.DataObject
) -> None:
    ids, pos = fleet(n, seed)
    recs = records_from_positions(ids, pos, seen=99.0)
    ring = plan_from_records(recs, CP)
    perm = data.draw(st.permutations(range(n)))
    again = plan_from_records([recs[k] for k in perm], CP)
    assert again.digest == ring.digest
    assert from_circle(again, CP).digest == from_circle(ring, CP).digest
    centre = ring.robot(ring.frame_robot)
    assert centre.order == 0 and centre.distance == 0.0
