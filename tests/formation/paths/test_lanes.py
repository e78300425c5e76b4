"""Bundle lanes (agent/core/formation/paths/lanes.py): which robots get a lane, which
lane, the re-pairing and the via points, worked by hand; properties on pyramid slots
(every lane clear of every slot, each bundle keeps its slots and its robots walk its way,
every lane entered before its slot's row, bit-identical results for permuted rows) and
the lines where a robot started among the slot rows; the errors; a lane plan of a line
scheduled and checked (both rules)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from agent.core.formation.params import PlanParams
from agent.core.formation.paths.assignment import assign
from agent.core.formation.paths.lanes import LANE_SLOPE, bundle_lanes, lane_rows
from agent.core.formation.shape.layout import centred, placed
from agent.core.formation.shape.pyramid import pyramid_frame
from agent.core.formation.shape.spec import PYRAMID
from agent.core.formation.waves.execution import check_dependencies
from agent.core.formation.waves.safety import check_safety
from agent.core.formation.waves.scheduled import scheduled_plan

C = 0.4
D_E = 2.0
PHI = math.radians(30)  # h = d_e sin(phi) / 2 = 0.5 m >= 1.2 c

# pyramid frame: the axis is +y, the bundle walks down (e = -1)
STARTS = np.array([[0.0, 18.5], [0.0, 20.0], [0.0, 21.5], [0.0, 23.0], [10.0, 0.0]])
SLOTS = np.array([[-1.0, 0.0], [1.5, 4.0], [1.5, 0.0], [0.5, 2.0], [10.0, -1.0]])


def test_lanes_worked_by_hand() -> None:
    order = np.array([0, 1, 3, 2, 4])  # r1 -> (1.5, 4), r2 -> (0.5, 2), r3 -> (1.5, 0)
    # r0 is the front robot (no start ahead of it), r4 walks 1 m: neither gets a lane;
    # r1, r2, r3 each pass the start ahead of them (0.14, 0.04, 0.10 m off)
    assert lane_rows(STARTS, SLOTS[order], C).tolist() == [1, 2, 3]
    got = bundle_lanes(STARTS, SLOTS, order, D_E, PHI, C)
    assert got is not None
    new_order, vias = got
    # lanes: outermost slots first, (1.5, 0) before (1.5, 4) (deeper): outer lane 2.0;
    # (1.5, 4): its outer lane 2.0 holds one robot, its inner lane 1.0 none: 1.0;
    # (0.5, 2): lane 0.0 is 0 m from the bundle's starts (< 1.5 c): 1.0 (shared).
    # Pairing: nearest robot (r1, y 20) to the innermost lane's deepest slot (0.5, 2),
    # r2 to (1.5, 4) in the same lane, r3 (the farthest) to the outer lane 2.0.
    assert new_order.tolist() == [0, 3, 1, 2, 4]
    assert vias[0] == () and vias[4] == ()
    step1 = 1.0 / LANE_SLOPE  # 2.2222 m along the axis to reach lane 1.0
    step2 = 2.0 / LANE_SLOPE  # 4.4444 m to reach lane 2.0
    np.testing.assert_allclose(np.array(vias[1]), [[1.0, 20.0 - step1], [1.0, 2.0]])
    np.testing.assert_allclose(np.array(vias[2]), [[1.0, 21.5 - step1], [1.0, 4.0]])
    np.testing.assert_allclose(np.array(vias[3]), [[2.0, 23.0 - step2], [2.0, 0.0]])
    np.testing.assert_allclose(np.array(vias[3])[0], [2.0, 18.5556], atol=1e-4)
    # the same slot set, so the joint pairing (one side here) gives the same plan
    joint = bundle_lanes(STARTS, SLOTS, order, D_E, PHI, C, joint=True)
    assert joint is not None
    assert joint[0].tolist() == new_order.tolist()


def test_joint_pairs_both_sides_by_lane_depth() -> None:
    starts = np.array([[0.0, 18.5], [0.0, 20.0], [0.0, 21.5]])
    slots = np.array([[0.0, 10.0], [-2.5, 0.0], [1.5, 0.0]])
    order = np.array([0, 1, 2])  # r1 -> left slot (lane -3.0), r2 -> right (lane 2.0)
    side = bundle_lanes(starts, slots, order, D_E, PHI, C)
    joint = bundle_lanes(starts, slots, order, D_E, PHI, C, joint=True)
    assert side is not None and joint is not None
    # per side: each side keeps its robot
    assert side[0].tolist() == [0, 1, 2]
    # jointly: the nearer robot r1 takes the inner lane (2.0), r2 the outer one (-3.0)
    assert joint[0].tolist() == [0, 2, 1]
    assert joint[1][1][0][0] == 2.0 and joint[1][2][0][0] == -3.0


def test_no_lanes_when_columns_are_too_close_or_nobody_walks_past() -> None:
    order = np.array([0, 1, 3, 2, 4])
    # NAO spacing: d_e = 0.8 m gives h = 0.2 m < 1.2 clearances
    assert bundle_lanes(STARTS, SLOTS, order, 0.8, PHI, C) is None
    short = np.array([[0.0, 0.0], [3.0, 0.0]])
    assert bundle_lanes(short, short + np.array([0.0, 2.0]), np.array([0, 1]), D_E, PHI, C) is None


@pytest.mark.parametrize(
    ("starts", "slots", "order", "d_e", "clearance", "match"),
    [
        (STARTS[:, :1], SLOTS[:, :1], np.arange(5), D_E, C, "must be"),
        (STARTS, SLOTS[:4], np.arange(5), D_E, C, "must be"),
        (STARTS, SLOTS, np.array([0, 0, 1, 2, 3]), D_E, C, "permutation"),
        (STARTS, SLOTS, np.arange(4), D_E, C, "permutation"),
        (STARTS, SLOTS, np.arange(5), D_E, 0.0, "clearance"),
        (STARTS, SLOTS, np.arange(5), D_E, math.nan, "clearance"),
        (STARTS, SLOTS, np.arange(5), -1.0, C, "d_e"),
    ],
)
def test_errors(
    starts: np.ndarray,
    slots: np.ndarray,
    order: np.ndarray,
    d_e: float,
    clearance: float,
    match: str,
) -> None:
    with pytest.raises(ValueError, match=match):
        bundle_lanes(starts, slots, order, d_e, PHI, clearance)


def _line(n: int, seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A line of n robots along the axis, centred like the pyramid, and its slots with a
    seeded random assignment."""
    rng = np.random.default_rng(seed)
    y = (np.arange(n) - (n - 1) / 2) * 1.5 + rng.uniform(-0.05, 0.05, n)
    starts = np.c_[rng.uniform(-0.2, 0.2, n), y]
    slots = centred(PYRAMID, n, D_E, PHI)
    return starts, slots, rng.permutation(n)


def test_a_robot_among_the_slot_rows_keeps_walking_its_bundles_way() -> None:
    # a line of 39 centred on the pyramid (seed 789): row 22 starts at y 4.51, among the
    # slot rows, and is the robot of the downward bundle nearest the pyramid. Zipped with
    # the slot order it would take (0.46, 5.06), behind it; the upward pass would then take
    # it into the upward bundle, with a slot of that bundle and a lane entered above the
    # slot it had left. Each robot takes the first free slot ahead of it, and each bundle
    # is re-paired once, from the given pairing.
    starts, slots, order = _line(39, 789)
    assert starts[22, 1] == pytest.approx(4.5089, abs=1e-4) and order[22] == 33
    got = bundle_lanes(starts, slots, order, D_E, PHI, C)
    assert got is not None
    new_order, vias = got
    assert new_order[22] == 32 and slots[32].tolist() == pytest.approx([1.4615, -3.5973], abs=1e-4)
    lane = slots[32, 0] + 0.5  # its outer lane, h = 0.5 m
    entry = starts[22, 1] - (lane - starts[22, 0]) / LANE_SLOPE  # 2.01 m right, 4.47 m down
    assert entry == pytest.approx(0.0387, abs=1e-4)
    np.testing.assert_allclose(np.array(vias[22]), [[lane, entry], [lane, slots[32, 1]]])
    # the next one up (row 24, y 7.5) takes the first slot below it, too near for a lane
    assert new_order[24] == 4 and slots[4, 1] < starts[24, 1] and vias[24] == ()


@pytest.mark.parametrize(("n", "seed", "joint"), [(39, 789, False), (40, 2872, True)])
def test_the_lines_whose_robot_crossed_into_the_other_bundle(
    n: int, seed: int, joint: bool
) -> None:
    # 39/789: a lane entered beyond its slot's row (above); 40/2872: zipped, row 21 would
    # take a slot behind it and the upward pass a slot ahead of it again, so no lane is
    # wrong but the two bundles would exchange slots
    inner = test_property_lanes_clear_every_slot_and_the_bundle_keeps_its_slots
    inner.hypothesis.inner_test(n=n, seed=seed, joint=joint)  # type: ignore[attr-defined]


@settings(max_examples=60, deadline=None)
@given(n=st.integers(10, 60), seed=st.integers(0, 10_000), joint=st.booleans())
def test_property_lanes_clear_every_slot_and_the_bundle_keeps_its_slots(
    n: int, seed: int, joint: bool
) -> None:
    starts, slots, order = _line(n, seed)
    got = bundle_lanes(starts, slots, order, D_E, PHI, C, joint=joint)
    if got is None:
        return
    new_order, vias = got
    assert sorted(new_order.tolist()) == list(range(n))
    moved = np.flatnonzero(new_order != order)
    rows = set(lane_rows(starts, slots[order], C).tolist())
    assert set(moved.tolist()) <= rows  # only bundle robots are re-paired
    way = np.sign(slots[order, 1] - starts[:, 1])  # each robot's bundle: the way it walks
    for e in (-1.0, 1.0):  # each bundle keeps its slots
        bundle = [r for r in sorted(rows) if way[r] == e]
        assert sorted(new_order[bundle].tolist()) == sorted(order[bundle].tolist())
    # every re-paired robot still walks its bundle's way
    assert all((slots[new_order[i], 1] - starts[i, 1]) * way[i] > 0 for i in moved.tolist())
    h = 0.5 * D_E * math.sin(PHI)
    for i, v in enumerate(vias):
        if not v:
            continue
        assert len(v) == 2 and v[0][0] == v[1][0]  # the lane: parallel to the axis
        lane = float(v[0][0])
        assert math.isclose(abs(lane - slots[new_order[i], 0]), h, abs_tol=1e-6)
        # the lane passes every slot >= h off (the slots' x lie on a grid of step 2h)
        assert float(np.min(np.abs(slots[:, 0] - lane))) >= h - 1e-6
        # ... and the x of every start of its bundle (the rows walking its way) by 1.5 c
        e = way[i]
        bundle = [r for r in rows if way[r] == e]
        assert i in bundle
        assert float(np.min(np.abs(starts[bundle, 0] - lane))) >= 1.5 * C - 1e-9
        # the lane is entered ahead of the start and before the slot's row, the bundle's way
        assert (v[0][1] - starts[i, 1]) * e >= 0 and (slots[new_order[i], 1] - v[0][1]) * e > 0
    # rows permuted: the same lanes and slots per robot, bit for bit
    perm = np.random.default_rng(seed + 1).permutation(n)
    again = bundle_lanes(starts[perm], slots, order[perm], D_E, PHI, C, joint=joint)
    assert again is not None
    assert again[0].tolist() == new_order[perm].tolist()
    for k, i in enumerate(perm.tolist()):
        assert len(again[1][k]) == len(vias[i])
        for a, b in zip(again[1][k], vias[i], strict=True):
            assert a.tobytes() == b.tobytes()


def test_a_lane_plan_of_a_line_schedules_safely() -> None:
    # a line of 30 robots along the axis, its min-sum pyramid, lanes, then the scheduler
    n = 30
    rng = np.random.default_rng(7)
    y = (np.arange(n) - (n - 1) / 2) * 1.5 + rng.uniform(-0.05, 0.05, n)
    pos = np.c_[y, rng.uniform(-0.2, 0.2, n)]  # common frame: the line along x
    frame = pyramid_frame(pos)
    starts_p = frame.to_pyramid(pos)
    slots_p = placed(PYRAMID, n, D_E, PHI, starts_p, "centroid")
    perm = assign(starts_p, slots_p, "optimal", D_E, PHI)
    got = bundle_lanes(starts_p, slots_p, perm, D_E, PHI, C)
    assert got is not None
    order, vias = got
    assert sum(1 for v in vias if v) >= 4
    params = PlanParams(d_e=D_E)
    sc = scheduled_plan(
        pos,
        frame.to_common(slots_p[order]),
        order,
        [tuple(frame.to_common(v) for v in vs) for vs in vias],
        np.zeros((0, 2)),
        params,
        "optimal",
    )
    paths = [np.vstack([pos[k], *sc.vias[k], sc.targets[k]]) for k in range(n)]
    assert not check_safety(paths, sc.waves, params.radius)
    assert not check_dependencies(paths, sc.after, sc.waves, params.radius, after_at=sc.after_at)
