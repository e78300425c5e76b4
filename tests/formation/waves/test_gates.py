"""agent/core/formation/waves/gates.py: known answers by hand, a test per error branch, and
the rule's promise as a property: plans of the real planner, walked at random speeds
with every step held until its gate opens, keep every pair its room."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from agent.core.control import STEP_LENGTH
from agent.core.formation.params import PlanParams
from agent.core.formation.plan import Plan, plan_from_positions
from agent.core.formation.waves.execution import dependency_makespan, path_lengths
from agent.core.formation.waves.gates import (
    MILESTONE,
    STEP_SLACK,
    Gates,
    gated_makespan,
    milestone,
    milestones,
    need,
    path_length,
    predecessors,
    room,
    stretch,
)
from agent.core.formation.waves.release import tail

# a walks east along y = 0 from x = 0 to 4; b walks north across its way at x = 2
A = np.array([[0.0, 0.0], [4.0, 0.0]])
B = np.array([[2.0, -2.0], [2.0, 2.0]])


def test_stretch_and_length_by_hand() -> None:
    bent = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0]])
    assert path_length(bent) == 2.0
    assert stretch(bent, 0.5, 1.5).tolist() == [[0.5, 0.0], [1.0, 0.0], [1.0, 0.5]]
    assert stretch(bent, -1.0, 0.25).tolist() == [[0.0, 0.0], [0.25, 0.0]]
    assert stretch(bent, 1.0, 5.0).tolist() == [[1.0, 0.0], [1.0, 1.0]]
    assert stretch(np.array([[3.0, 4.0]]), 0.0, 1.0).tolist() == [[3.0, 4.0], [3.0, 4.0]]


def test_need_is_the_last_point_of_a_near_the_stretch() -> None:
    # b's whole path: a is within 0.4 m of it until x = 2.4 (the release point)
    assert need(A, B, 0.4) == pytest.approx(2.4)
    # b's first metre stays 1 m from a's way: nothing to wait for
    assert need(A, stretch(B, 0.0, 1.0), 0.4) == -math.inf
    # b's stretch from y = -0.5 to -0.3: a is near it up to x = 2 + sqrt(0.4² − 0.3²)
    assert need(A, stretch(B, 1.5, 1.7), 0.4) == pytest.approx(2.0 + math.sqrt(0.16 - 0.09))


def test_room_is_the_clearance_or_the_nearer_ends() -> None:
    assert room(A, B, 0.4) == 0.4
    near = np.array([[0.1, 0.0], [0.1, 3.0]])  # starts 0.1 m apart: held to that
    assert room(A, near, 0.4) == pytest.approx(0.1)
    with pytest.raises(ValueError, match="clearance"):
        room(A, B, 0.0)


def test_milestones_round_up_and_stop_at_the_cap() -> None:
    assert milestone(0.1, 9.0) == MILESTONE
    assert milestone(1.0, 9.0) == 1.0  # on a milestone: that one
    assert milestone(2.26, 2.4) == 2.4  # never beyond the release point
    assert milestone(-math.inf, 2.4) == -math.inf
    assert milestones(1.6, (1.2, 7.0, 0.0)) == [0.5, 1.0, 1.2, 1.5]
    assert milestones(0.0) == []
    with pytest.raises(ValueError, match="finite"):
        milestone(math.nan, 1.0)
    with pytest.raises(ValueError, match="length"):
        milestones(-1.0)


def test_predecessors_follow_the_after_lists() -> None:
    after = [[], [0], [1], [2, 0], []]
    assert predecessors(after, 3) == [0, 1, 2]
    assert predecessors(after, 4) == [] and predecessors(after, 0) == []


def test_the_gates_of_the_crossing_by_hand() -> None:
    g = Gates([A, B], [[], [0]], 1, 0.4, [[], [2.4]])
    assert [a for a, *_ in g.on] == [0] and g.at_start == []
    assert g.needs(0.0, STEP_LENGTH + STEP_SLACK) == []  # b starts at once
    assert g.needs(1.5, 1.75) == [(0, 2.4)]  # near a's way: a must be past 2.4 m
    assert g.needs(3.5, 9.0) == []  # beyond a's way
    # a robot the plan names whose path never comes near: its release point stands
    far = np.array([[0.0, 5.0], [1.0, 5.0]])
    g = Gates([far, B], [[], [0]], 1, 0.4, [[], [0.5]])
    assert g.on == [] and g.needs(0.0, 0.25) == [(0, 0.5)]
    with pytest.raises(ValueError, match="row"):
        Gates([A, B], [[]], 1, 0.4)
    with pytest.raises(ValueError, match="finite"):
        stretch(A, 1.0, 0.5)


def test_the_crossing_walked_at_unit_speed() -> None:
    # b walks 1.6 m to the edge of a's way, holds until a is past 2.4 m, walks on
    gated = gated_makespan([A, B], [[], [0]], [0, 1], 0.4, STEP_LENGTH, [[], [2.4]])
    start_only = dependency_makespan(path_lengths([A, B]), [[], [0]], [0, 1], [[], [2.4]])
    assert start_only == pytest.approx(6.4)
    assert 4.0 < gated <= 2.4 + 2.6 + 1e-9
    with pytest.raises(ValueError, match="step"):
        gated_makespan([A, B], [[], [0]], [0, 1], 0.4, 0.0)
    with pytest.raises(ValueError, match="same or a later wave"):
        gated_makespan([A, B], [[], [0]], [1, 0], 0.4, STEP_LENGTH)


def _walk(plan: Plan, clearance: float, rng: np.random.Generator) -> float:
    """The plan walked with every robot at its own random speed, changing every tick,
    each step asked of its gate first (granted: walked at once or later); the smallest
    distance between two robots less their room (negative: a breach)."""
    ids = plan.ids
    row = {r: k for k, r in enumerate(ids)}
    paths = plan.paths()
    after = [[row[j] for j in r.after] for r in plan.robots]
    at = [list(r.after_at) or [plan.robot(j).length() for j in r.after] for r in plan.robots]
    gates = [Gates(paths, after, b, clearance, at) for b in range(len(ids))]
    lens = [g.length for g in gates]
    n = len(ids)
    s = np.zeros(n)
    granted = np.zeros(n)
    rooms = np.array([[room(paths[i], paths[k], clearance) for k in range(n)] for i in range(n)])
    worst = math.inf
    for _ in range(20000):
        if np.all(s >= np.array(lens) - 1e-12):
            break
        for b in rng.permutation(n).tolist():
            if s[b] >= granted[b] - 1e-12 and s[b] < lens[b] - 1e-12:
                y1 = min(lens[b], s[b] + STEP_LENGTH)
                if all(
                    s[a] >= need_a - 1e-12 for a, need_a in gates[b].needs(s[b], y1 + STEP_SLACK)
                ):
                    granted[b] = y1
            s[b] = min(granted[b], s[b] + float(rng.uniform(0.0, 0.05)))
        pos = np.array([tail(paths[k], s[k])[0] for k in range(n)])
        d = np.hypot(pos[:, None, 0] - pos[None, :, 0], pos[:, None, 1] - pos[None, :, 1])
        np.fill_diagonal(d, math.inf)
        worst = min(worst, float(np.min(d - rooms * (1 - 1e-9))))
    assert np.all(s >= np.array(lens) - 1e-9), "a robot never got through its gates"
    return worst


@settings(max_examples=12, deadline=None)
@given(st.integers(0, 10_000), st.integers(7, 12))
def test_a_plan_walked_at_random_speeds_through_its_gates_keeps_every_room(
    seed: int, n: int
) -> None:
    rng = np.random.default_rng(seed)
    side = math.ceil(math.sqrt(n))
    grid = np.array([(x, y) for x in range(side) for y in range(side)][:n], dtype=float)
    starts = grid * 0.7 + rng.uniform(-0.15, 0.15, size=(n, 2))
    plan = plan_from_positions(tuple(range(1, n + 1)), starts, PlanParams(d_e=0.6))
    assert _walk(plan, 2.0 * PlanParams().radius, rng) >= -1e-9
