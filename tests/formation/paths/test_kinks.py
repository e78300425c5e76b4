"""Start sidesteps (agent/core/formation/paths/kinks.py): which robots step aside at
the start, where to, worked by hand, and as properties (row order, clearance)."""

from __future__ import annotations

import math

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from agent.core.formation.paths.kinks import KINK_ALONG, KINK_OFFSET, start_kinks

C = 0.4
UP = np.array([0.0, 1.0])


def test_a_robot_walking_past_a_start_ahead_steps_to_its_slot_side() -> None:
    starts = np.array([[0.0, 0.0], [0.0, -2.0], [10.0, 0.0]])
    targets = np.array([[3.0, -20.0], [-3.0, -10.0], [10.0, -3.0]])
    vias = start_kinks(starts, targets, UP, C)
    # robot 0: 20.2 m, passes robot 1's start 0.3 m off (< 2c, ahead): a sidestep 2 m
    # along and 0.6 m to the right (its slot is right of the axis through its start)
    length = math.hypot(3.0, 20.0)
    u = np.array([3.0, -20.0]) / length
    right = np.array([-u[1], u[0]])  # left of a path going down = +x
    assert right[0] > 0
    assert len(vias[0]) == 1
    np.testing.assert_allclose(vias[0][0], KINK_ALONG * C * u + KINK_OFFSET * C * right)
    np.testing.assert_allclose(vias[0][0], [0.8900, -1.8889], atol=1e-4)
    # robot 1 walks away from robot 0's start (behind it): none; robot 2: too short
    assert vias[1] == ()
    assert vias[2] == ()


def test_the_side_follows_the_slot_across_the_axis() -> None:
    starts = np.array([[0.0, 0.0], [0.0, -2.0]])
    left = start_kinks(starts, np.array([[-3.0, -20.0], [0.0, -30.0]]), UP, C)
    assert left[0][0][0] < 0  # slot left of the axis: the step goes left
    # robot 1 walks straight down the axis (nothing across it): the left of its path
    assert left[1] == ()  # ... but no start lies ahead of it


def test_nobody_near_no_sidestep() -> None:
    starts = np.array([[0.0, 0.0], [5.0, 0.0]])
    targets = np.array([[0.0, -20.0], [5.0, -20.0]])
    assert start_kinks(starts, targets, UP, C) == [(), ()]


@settings(max_examples=30, deadline=None)
@given(
    n=st.integers(2, 12),
    seed=st.integers(0, 10_000),
)
def test_property_rows_permute_with_the_input_and_the_step_is_fixed(n: int, seed: int) -> None:
    rng = np.random.default_rng(seed)
    starts = np.c_[rng.uniform(-0.2, 0.2, n), np.arange(n) * 1.5]
    targets = np.c_[rng.uniform(-8, 8, n), rng.uniform(-30, -20, n)]
    vias = start_kinks(starts, targets, UP, C)
    perm = rng.permutation(n)
    again = start_kinks(starts[perm], targets[perm], UP, C)
    for k, i in enumerate(perm.tolist()):
        assert len(again[k]) == len(vias[i])
        for a, b in zip(again[k], vias[i], strict=True):
            assert a.tobytes() == b.tobytes()  # bit-identical
    for i, v in enumerate(vias):
        if v:  # a sidestep KINK_ALONG·c along and KINK_OFFSET·c beside the straight path
            d = targets[i] - starts[i]
            w = v[0] - starts[i]
            along = float(w @ d) / float(np.hypot(*d))
            assert math.isclose(along, KINK_ALONG * C, rel_tol=1e-9)
            assert math.isclose(float(np.hypot(*w)), math.hypot(KINK_ALONG, KINK_OFFSET) * C)
