"""Row lanes (agent/core/formation/paths/row_lanes.py): bundles, lanes and via points worked
by hand, kept and re-paired; properties on line slots (lanes nest: the farther the slot,
the farther its lane from the row; every lane clear of every slot; each bundle keeps its
slots; bit-identical results for permuted rows); None when no slot lies beyond the fleet;
the errors; and the whole plan of a line and of a column from uniform starts: within 2×
CAPT, safe under both rules, the same plan from shuffled input."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from agent.core.formation.params import PlanParams
from agent.core.formation.paths.row_lanes import ROW_LANE_GAP, row_lanes
from agent.core.formation.plan import Plan, plan_from_positions
from agent.core.formation.shape.layout import centred, placed, shape_frame
from agent.core.formation.shape.spec import BUILTIN
from agent.core.formation.waves.execution import (
    capt_makespan,
    check_dependencies,
    dependency_makespan,
    path_lengths,
)
from agent.core.formation.waves.safety import check_safety

C = 0.4
G = ROW_LANE_GAP * C  # 0.48 m

# shape frame: the row is the x axis; four robots in a cluster round x = 0, slots on y = 0
STARTS = np.array([[0.0, 1.0], [1.0, 2.0], [-1.0, -1.0], [0.5, -2.0]])
SLOTS = np.array([[0.0, 0.0], [10.0, 0.0], [12.0, 0.0], [-10.0, 0.0]])


def planned_within_twice_capt(pos: np.ndarray, params: PlanParams, seed: int) -> Plan:
    """The plan of robots 1..n at ``pos``: safe under both checkers (release points and
    whole paths), its dependency makespan within 2× CAPT on the centred slots, and the
    same digest for the robots shuffled."""
    n = pos.shape[0]
    ids = list(range(1, n + 1))
    plan = plan_from_positions(ids, pos, params)
    paths, waves = plan.paths(), plan.wave_of()
    row = {r.robot_id: k for k, r in enumerate(plan.robots)}
    after = [[row[j] for j in r.after] for r in plan.robots]
    at = [list(r.after_at) for r in plan.robots]
    assert not check_safety(paths, waves, C / 2)
    assert not check_dependencies(paths, after, waves, C / 2, after_at=at)
    assert not check_dependencies(paths, after, waves, C / 2)
    frame = shape_frame(pos, params.axis, params.shape)
    starts_p = frame.to_pyramid(pos)
    slots = frame.to_common(placed(params.shape, n, params.d_e, params.phi_e, starts_p, "centroid"))
    ms = dependency_makespan(path_lengths(paths), after, waves, at)
    assert ms <= 2.0 * capt_makespan(pos, slots)
    perm = np.random.default_rng(seed).permutation(n)
    again = plan_from_positions([ids[k] for k in perm], pos[perm], params)
    assert again.digest == plan.digest
    return plan


def test_row_lanes_worked_by_hand() -> None:
    # r0 -> slot 0 (inside the fleet: no lane), r1 -> (12, 0), r2 -> (-10, 0), r3 -> (10, 0)
    order = np.array([0, 2, 3, 1])
    got = row_lanes(STARTS, SLOTS, order, C)
    assert got is not None
    new_order, vias = got
    assert new_order.tolist() == order.tolist()
    assert vias[0] == ()
    # end +1 (edge x = 1.0, entry x = 1.48): r1 above its slot, r3 below: one robot each,
    # so each lane is one gap beyond the row
    np.testing.assert_allclose(np.array(vias[1]), [[1.0 + G, G], [12.0, G]])
    np.testing.assert_allclose(np.array(vias[3]), [[1.0 + G, -G], [10.0, -G]])
    # end -1 (edge x = -1.0): r2 starts below its slot
    np.testing.assert_allclose(np.array(vias[2]), [[-1.0 - G, -G], [-10.0, -G]])


def test_a_bundle_nests_its_lanes_and_re_pairs_by_height() -> None:
    starts = np.array([[0.0, 1.0], [0.5, 2.0], [1.0, 3.0]])
    slots = np.array([[10.0, 0.0], [14.0, 0.0], [12.0, 0.0]])
    # kept: r0 -> 14 (the farthest: the highest lane), r1 -> 10 (the lowest), r2 -> 12
    order = np.array([1, 0, 2])
    got = row_lanes(starts, slots, order, C)
    assert got is not None
    kept, vias = got
    assert kept.tolist() == [1, 0, 2]
    lane = {int(kept[i]): float(vias[i][0][1]) for i in range(3)}
    assert lane == pytest.approx({1: 3 * G, 2: 2 * G, 0: G})
    # re-paired: the robot farthest from the row (r2, y = 3) takes the farthest slot
    got = row_lanes(starts, slots, order, C, repair=True)
    assert got is not None
    assert got[0].tolist() == [0, 2, 1]
    for i in range(3):
        np.testing.assert_allclose(got[1][i][0], [1.0 + G, [G, 2 * G, 3 * G][i]])
        np.testing.assert_allclose(got[1][i][1], [slots[got[0][i], 0], [G, 2 * G, 3 * G][i]])


def test_no_slot_beyond_the_fleet_gives_none() -> None:
    starts = np.array([[0.0, 0.0], [4.0, 1.0], [8.0, 0.0]])
    slots = np.array([[1.0, 0.0], [4.0, 0.0], [7.0, 0.0]])
    assert row_lanes(starts, slots, np.arange(3), C) is None


@pytest.mark.parametrize(
    ("starts", "slots", "order", "clearance", "match"),
    [
        (np.zeros((3, 3)), np.zeros((3, 2)), np.arange(3), C, "arrays"),
        (np.zeros((3, 2)), np.zeros((2, 2)), np.arange(3), C, "arrays"),
        (np.zeros((3, 2)), np.zeros((3, 2)), np.array([0, 0, 1]), C, "permutation"),
        (np.zeros((3, 2)), np.zeros((3, 2)), np.arange(2), C, "permutation"),
        (np.zeros((3, 2)), np.zeros((3, 2)), np.arange(3), 0.0, "clearance"),
        (np.zeros((3, 2)), np.zeros((3, 2)), np.arange(3), math.nan, "clearance"),
    ],
)
def test_errors(
    starts: np.ndarray, slots: np.ndarray, order: np.ndarray, clearance: float, match: str
) -> None:
    with pytest.raises(ValueError, match=match):
        row_lanes(starts, slots, order, clearance)


def _line_case(seed: int, n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    side = math.sqrt(n) * 1.5
    starts = rng.uniform(-side / 2, side / 2, (n, 2)) * np.array([2.0, 0.5])
    slots = centred(BUILTIN["line"], n, 2.0, math.radians(30))
    return starts, slots, rng.permutation(n)


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 10_000), n=st.integers(4, 40), repair=st.booleans())
def test_property_lanes_nest_clear_the_slots_and_keep_the_bundles(
    seed: int, n: int, repair: bool
) -> None:
    starts, slots, order = _line_case(seed, n)
    got = row_lanes(starts, slots, order, C, repair)
    if got is None:
        return
    new_order, vias = got
    assert sorted(new_order.tolist()) == list(range(n))
    laned = [i for i in range(n) if vias[i]]
    assert all(vias[i] == () and new_order[i] == order[i] for i in range(n) if i not in laned)
    for i in laned:
        entry, turn = vias[i]
        slot = slots[new_order[i]]
        e = math.copysign(1.0, slot[0] - starts[i, 0])
        assert entry[1] == turn[1] and turn[0] == slot[0]  # a lane parallel to the row
        assert e * entry[0] == pytest.approx(float(np.max(e * starts[:, 0])) + G)
        # every lane >= one gap from every slot of the row
        assert float(np.min(np.abs(turn[1] - slots[:, 1]))) >= G - 1e-12
    # the same bundle (end, side of the row): the same slots, lanes nested by distance
    for e in (-1.0, 1.0):
        for side in (-1.0, 1.0):
            grp = [
                i
                for i in laned
                if e * (vias[i][1][0] - starts[i, 0]) > 0 and side * vias[i][1][1] > 0
            ]
            before = sorted(int(order[i]) for i in grp)
            assert sorted(int(new_order[i]) for i in grp) == before
            by_far = sorted(grp, key=lambda i: -e * vias[i][1][0])
            heights = [side * vias[i][1][1] for i in by_far]
            assert all(a - b == pytest.approx(G) for a, b in itertools.pairwise(heights))
    # permuted rows: the same slots and vias per robot
    perm = np.random.default_rng(seed + 1).permutation(n)
    again = row_lanes(starts[perm], slots, order[perm], C, repair)
    assert again is not None
    if not repair:  # (re-pairing breaks ties in height by row)
        assert again[0].tolist() == new_order[perm].tolist()
        for k, i in enumerate(perm.tolist()):
            assert len(again[1][k]) == len(vias[i])
            for a, b in zip(again[1][k], vias[i], strict=True):
                assert np.array_equal(a, b)


def _uniform(n: int, seed: int, d_e: float = 2.0) -> np.ndarray:
    """n starts >= 0.6·d_e apart in a rectangle of aspect 2 (tools.bench makespan's
    ``uniform`` family, here as a test seed of its own)."""
    rng = np.random.default_rng([seed, n, 41])
    w, h = math.sqrt(2 * n) * 0.9 * d_e, math.sqrt(n / 2) * 0.9 * d_e
    pts: list[np.ndarray] = []
    while len(pts) < n:
        p = rng.uniform((0.0, 0.0), (w, h))
        if all(math.hypot(*(p - q)) >= 0.6 * d_e for q in pts):
            pts.append(p)
    return np.array(pts)


@pytest.mark.parametrize(("seed", "shape"), [(0, "line"), (1, "line"), (0, "column")])
def test_a_line_or_column_of_40_from_uniform_starts_within_2x_capt_safe_and_alike(
    seed: int, shape: str
) -> None:
    """The line (its row along the fleet's x) and the column (one slot column along its
    y): the side-by-side plans in either frame."""
    n, d_e, phi = 40, 2.0, math.radians(30)
    pos = _uniform(n, seed)
    params = PlanParams(d_e=d_e, phi_e=phi, radius=C / 2, shape=BUILTIN[shape])
    plan = planned_within_twice_capt(pos, params, seed)
    assert any(len(r.via) == 2 for r in plan.robots)  # the row lanes won
