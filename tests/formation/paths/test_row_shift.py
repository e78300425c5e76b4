"""Row shift (agent/core/formation/paths/row_shift.py): the distance across the row worked by
hand, the cases without a shift, the errors, the same result for permuted rows; and the
whole plan of a line shape on a fleet standing in a line (a stretch along the row): within
2× CAPT, safe under both rules, the same plan from shuffled input."""

from __future__ import annotations

import math

import numpy as np
import pytest

from agent.core.formation.params import PlanParams
from agent.core.formation.paths.row_shift import row_shift
from agent.core.formation.shape.spec import BUILTIN
from tests.formation.paths.test_row_lanes import C, planned_within_twice_capt


def test_row_shift_worked_by_hand() -> None:
    starts = np.array([[0.0, 0.0], [1.0, 0.0], [2.0, 0.0]])  # delta = 1
    slots = np.array([[-2.0, 0.0], [0.0, 0.0], [2.0, 0.0]])
    # identity: the longest walk along the row is 2 m; sin(theta) = 0.4
    d = row_shift(starts, slots, np.arange(3), C)
    assert d == pytest.approx(2.0 * 0.4 / math.sqrt(1.0 - 0.16))
    # the paths' angle: tan(theta) = d / dx, neighbours 1 m apart -> sin(theta) m apart
    assert math.sin(math.atan2(d or 0.0, 2.0)) * 1.0 == pytest.approx(C)
    # the order decides dx: r0 -> (2, 0), r2 -> (-2, 0): dx = 4
    d2 = row_shift(starts, slots, np.array([2, 1, 0]), C)
    assert d2 == pytest.approx(2.0 * (d or 0.0))
    # permuted rows: the same distance
    perm = np.array([2, 0, 1])
    assert row_shift(starts[perm], slots, np.arange(3)[perm], C) == d


def test_no_shift() -> None:
    one = np.zeros((1, 2))
    assert row_shift(one, one, np.arange(1), C) is None
    close = np.array([[0.0, 0.0], [0.3, 0.0]])  # closer than the clearance
    assert row_shift(close, close + np.array([5.0, 0.0]), np.arange(2), C) is None
    still = np.array([[0.0, 0.0], [1.0, 0.0]])  # nobody moves along the row
    assert row_shift(still, still + np.array([0.0, 3.0]), np.arange(2), C) is None


@pytest.mark.parametrize(
    ("starts", "slots", "order", "clearance", "match"),
    [
        (np.zeros((3, 3)), np.zeros((3, 2)), np.arange(3), C, "arrays"),
        (np.zeros((3, 2)), np.zeros((2, 2)), np.arange(3), C, "arrays"),
        (np.zeros((3, 2)), np.zeros((3, 2)), np.array([0, 0, 1]), C, "permutation"),
        (np.zeros((3, 2)), np.zeros((3, 2)), np.arange(3), -1.0, "clearance"),
        (np.zeros((3, 2)), np.zeros((3, 2)), np.arange(3), math.inf, "clearance"),
    ],
)
def test_errors(
    starts: np.ndarray, slots: np.ndarray, order: np.ndarray, clearance: float, match: str
) -> None:
    with pytest.raises(ValueError, match=match):
        row_shift(starts, slots, order, clearance)


@pytest.mark.parametrize("seed", [0, 1])
def test_a_line_shape_on_a_line_of_40_within_2x_capt_safe_and_alike(seed: int) -> None:
    n, d_e, phi = 40, 2.0, math.radians(30)
    rng = np.random.default_rng([seed, 43])
    step = rng.uniform(0.6, 0.7) * d_e  # a line denser than the shape's: it stretches
    t = (np.arange(n) + rng.uniform(-0.05, 0.05, n)) * step
    pos = np.c_[t, 0.02 * (t - t.mean()) ** 2 / t[-1] + rng.uniform(-0.1, 0.1, n)]
    params = PlanParams(d_e=d_e, phi_e=phi, radius=C / 2, shape=BUILTIN["line"])
    planned_within_twice_capt(pos, params, seed)
