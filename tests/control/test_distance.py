"""Distance control (NAO paper 5.2.2): steps of <= 20 cm, re-aiming, dead reckoning."""

from __future__ import annotations

import math

import numpy as np
import pytest

from agent.core.control.distance import STEP_LENGTH, advance, next_leg, split_distance


def test_split_known_answers() -> None:
    assert split_distance(0.0) == []
    assert split_distance(0.2) == pytest.approx([0.2])
    assert split_distance(0.5) == pytest.approx([0.5 / 3] * 3)
    assert split_distance(0.8) == pytest.approx([0.2] * 4)
    assert split_distance(0.05) == pytest.approx([0.05])


@pytest.mark.parametrize("d", [0.01, 0.19, 0.21, 0.6, 1.37, 3.0])
def test_split_invariants(d: float) -> None:
    steps = split_distance(d)
    assert sum(steps) == pytest.approx(d)
    assert all(0 < s <= STEP_LENGTH + 1e-12 for s in steps)
    assert len(steps) == math.ceil(d / STEP_LENGTH - 1e-9)


@pytest.mark.parametrize("args", [(-0.1,), (math.nan,), (1.0, 0.0), (1.0, math.inf)])
def test_split_bad_input(args: tuple[float, ...]) -> None:
    with pytest.raises(ValueError):
        split_distance(*args)


def test_next_leg_known_answer() -> None:
    # facing north (pi/2) at the origin, goal 0.5 m east: turn -90°, first of 3 steps
    leg = next_leg((0.0, 0.0), math.pi / 2, (0.5, 0.0))
    assert leg is not None
    assert leg.turn == pytest.approx(-math.pi / 2)
    assert leg.walk == pytest.approx(0.5 / 3)
    assert leg.heading == pytest.approx(0.0)
    assert leg.remaining == pytest.approx(0.5)


def test_next_leg_arrived() -> None:
    assert next_leg((1.0, 1.0), 0.0, (1.01, 1.0)) is None


def test_next_leg_turn_is_wrapped() -> None:
    leg = next_leg((0.0, 0.0), math.radians(170), (-1.0, -0.1))
    assert leg is not None
    assert abs(leg.turn) < math.radians(20)


def test_advance_straight_and_drifting() -> None:
    p = advance((0.0, 0.0), math.pi / 2, math.pi / 2, 0.2)
    assert p == pytest.approx([0.0, 0.2])
    # drift from 0 to 0.2 rad: moves along 0.1 rad
    p2 = advance((1.0, 0.0), 0.0, 0.2, 0.2)
    assert p2 == pytest.approx([1.0 + 0.2 * math.cos(0.1), 0.2 * math.sin(0.1)])
    # mean across the wrap: pi-0.1 and -pi+0.1 -> pi
    p3 = advance((0.0, 0.0), math.pi - 0.1, -math.pi + 0.1, 1.0)
    assert p3 == pytest.approx([-1.0, 0.0], abs=1e-9)


def test_closed_loop_reaches_goal_with_drift() -> None:
    """Walk legs on a plant that drifts 0.05 rad per step; the compass sees the drift."""
    rng = np.random.default_rng(0)
    true_p = np.zeros(2)
    heading = math.pi / 2
    belief = np.zeros(2)
    goal = np.array([0.7, 0.9])
    for _ in range(30):
        leg = next_leg(belief, heading, goal)
        if leg is None:
            break
        heading += leg.turn
        drift = 0.05 + rng.normal(0, 0.01)
        before = heading
        true_p = true_p + leg.walk * np.array(
            [math.cos(heading + drift / 2), math.sin(heading + drift / 2)]
        )
        heading += drift
        belief = advance(belief, before, heading, leg.walk)
    assert np.linalg.norm(true_p - goal) < 0.03


@pytest.mark.parametrize(
    "args",
    [
        ((math.nan, 0.0), 0.0, (1.0, 1.0)),
        ((0.0, 0.0), math.inf, (1.0, 1.0)),
        ((0.0, 0.0), 0.0, (1.0, 1.0, 1.0)),
    ],
)
def test_next_leg_bad_input(args: tuple[object, ...]) -> None:
    with pytest.raises(ValueError):
        next_leg(*args)  # type: ignore[arg-type]


def test_next_leg_bad_tolerance() -> None:
    with pytest.raises(ValueError):
        next_leg((0.0, 0.0), 0.0, (1.0, 0.0), tolerance=0.0)


def test_advance_bad_input() -> None:
    with pytest.raises(ValueError):
        advance((0.0, 0.0), math.nan, 0.0, 0.1)
    with pytest.raises(ValueError):
        advance((0.0, 0.0), 0.0, 0.0, math.inf)


def test_next_leg_steps_back_for_a_small_correction_behind() -> None:
    # facing north, goal 10 cm south: step back instead of a half turn
    leg = next_leg((0.0, 0.0), math.pi / 2, (0.0, -0.1), backward_within=0.3)
    assert leg is not None
    assert leg.walk == pytest.approx(-0.1)
    assert leg.turn == pytest.approx(0.0)
    # but a far goal behind is walked to forwards
    far = next_leg((0.0, 0.0), math.pi / 2, (0.0, -1.0), backward_within=0.3)
    assert far is not None and far.walk > 0 and abs(far.turn) == pytest.approx(math.pi)
    # dead reckoning of a backward step
    assert advance((0.0, 0.0), math.pi / 2, math.pi / 2, -0.1) == pytest.approx([0.0, -0.1])
