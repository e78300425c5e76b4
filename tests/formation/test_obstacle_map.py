"""Merging perceived obstacles into the common frame (agent/core/formation/obstacle_map.py)
and planning around them from records (plan_from_records ``sightings``)."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from agent.core.formation.frame.records import NeighborRecord
from agent.core.formation.obstacle_map import (
    MERGE_RADIUS,
    common_frame_obstacles,
    merge_sightings,
)
from agent.core.formation.params import D_E, PlanParams
from agent.core.formation.plan import plan_from_records


def test_two_robots_see_one_obstacle() -> None:
    # robot 1 at (0, 0) sees it at (1.0, 0.0); robot 2 at (2, 0) sees it at (-0.9, 0.1)
    out = common_frame_obstacles(
        [1, 2],
        np.array([[0.0, 0.0], [2.0, 0.0]]),
        {1: np.array([[1.0, 0.0]]), 2: np.array([[-0.9, 0.1]])},
    )
    assert out.shape == (1, 2)
    # weights 1/max(d, 0.5): 1/1.0 and 1/0.906 -> the nearer sighting weighs more
    w1, w2 = 1.0, 1.0 / np.hypot(0.9, 0.1)
    expect = (w1 * np.array([1.0, 0.0]) + w2 * np.array([1.1, 0.1])) / (w1 + w2)
    assert np.allclose(out[0], expect)


def test_distinct_obstacles_stay_apart_and_are_sorted() -> None:
    pts = np.array([[2.0, 1.0], [0.0, 0.0], [2.05, 1.0], [0.0, 0.8]])
    out = merge_sightings(pts, np.ones(4))
    assert out.shape == (3, 2)
    assert np.array_equal(out[:, 0], np.sort(out[:, 0]))
    assert np.allclose(out[2], [2.025, 1.0])


def test_sightings_of_unplaced_robots_are_left_out() -> None:
    out = common_frame_obstacles([1], np.zeros((1, 2)), {1: np.zeros((0, 2)), 9: np.ones((1, 2))})
    assert out.shape == (0, 2)


@settings(max_examples=60, deadline=None)
@given(
    st.lists(
        st.tuples(st.floats(-3, 3), st.floats(-3, 3), st.floats(0.3, 4.0)), min_size=1, max_size=25
    ),
    st.randoms(use_true_random=False),
)
def test_any_order_gives_bit_identical_obstacles(
    rows: list[tuple[float, float, float]], rnd: object
) -> None:
    arr = np.array(rows)
    ref = merge_sightings(arr[:, :2], arr[:, 2])
    perm = list(range(len(rows)))
    rnd.shuffle(perm)  # type: ignore[attr-defined]
    again = merge_sightings(arr[perm, :2], arr[perm, 2])
    assert ref.tobytes() == again.tobytes()
    # invariants: at most one obstacle per sighting, each within the sightings' hull
    assert 1 <= ref.shape[0] <= len(rows)
    assert np.all(ref.min(axis=0) >= arr[:, :2].min(axis=0) - 1e-9)
    assert np.all(ref.max(axis=0) <= arr[:, :2].max(axis=0) + 1e-9)
    # merged obstacles are farther apart than the merge radius
    if ref.shape[0] > 1:
        d = np.hypot(*(ref[:, None, :] - ref[None, :, :]).transpose(2, 0, 1))
        assert d[np.triu_indices(len(ref), 1)].min() > 0.0


def test_shuffled_records_plan_identically_around_a_seen_obstacle() -> None:
    # three robots in a row facing the same way; an obstacle between 1 and 3's targets
    starts = {1: np.array([0.0, 0.0]), 2: np.array([1.0, 0.0]), 3: np.array([2.0, 0.0])}
    obstacle = np.array([1.0, 0.9])
    records = []
    sightings = {}
    for i, p in starts.items():
        nb = np.array([starts[j] - p for j in sorted(starts) if j != i])
        records.append(NeighborRecord(i, nb))
        sightings[i] = (obstacle - p + 0.01 * i).reshape(1, 2)  # a cm of error each
    params = PlanParams(d_e=D_E)
    plan = plan_from_records(records, params, sightings=sightings)
    again = plan_from_records(records[::-1], params, sightings=dict(reversed(sightings.items())))
    assert plan.digest == again.digest
    assert plan.obstacles.shape == (1, 2)
    assert np.linalg.norm(plan.obstacles[0] - (obstacle - starts[1] + 0.02)) < 0.02
    # clearance: every path stays 2·radius from the obstacle
    ob = plan.obstacles[0]
    for path in plan.paths():
        for a, b in itertools.pairwise(path):
            t = np.clip(np.dot(ob - a, b - a) / max(np.dot(b - a, b - a), 1e-12), 0.0, 1.0)
            assert np.linalg.norm(a + t * (b - a) - ob) >= 2 * params.radius - 1e-6


@pytest.mark.parametrize(
    ("pts", "dist", "radius", "msg"),
    [
        (np.zeros((2, 3)), np.zeros(2), MERGE_RADIUS, "need points"),
        (np.zeros((2, 2)), np.zeros(3), MERGE_RADIUS, "need points"),
        (np.array([[np.nan, 0.0]]), np.zeros(1), MERGE_RADIUS, "non-finite"),
        (np.zeros((1, 2)), np.zeros(1), 0.0, "merge radius"),
    ],
)
def test_bad_sightings_raise(pts: np.ndarray, dist: np.ndarray, radius: float, msg: str) -> None:
    with pytest.raises(ValueError, match=msg):
        merge_sightings(pts, dist, radius)
