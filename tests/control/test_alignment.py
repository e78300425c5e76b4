"""Where the child looks for its parent and which NAO it takes (agent/core/control/alignment.py)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from agent.core.control.alignment import look_yaws, match_parent


def test_look_yaws_fan_out_around_the_expected_bearing() -> None:
    yaws = look_yaws(math.pi / 2, math.pi / 2, 0.3, 2.0)
    assert yaws == pytest.approx([0.0, 0.3, -0.3, 0.6, -0.6])
    # relative bearing 0.5 rad: the fan is centred there
    assert look_yaws(1.0, 0.5, 0.2, 2.0) == pytest.approx([0.5, 0.7, 0.3, 0.9, 0.1])


def test_look_yaws_clip_to_the_head_and_drop_repeats() -> None:
    # centre 1.9 rad, limit 2.0: +0.3 and +0.6 both clip to 2.0 (kept once)
    assert look_yaws(1.9, 0.0, 0.3, 2.0) == pytest.approx([1.9, 2.0, 1.6, 1.3])
    assert look_yaws(0.0, 0.0, 0.0, 2.0) == [0.0]  # no spread: one look


def test_look_yaws_wrap_the_relative_bearing() -> None:
    (first, *_) = look_yaws(-3.0, 3.0, 0.1, 2.0)
    assert first == pytest.approx(2 * math.pi - 6.0)


@pytest.mark.parametrize(
    ("args", "msg"),
    [
        ((0.0, 0.0, -0.1, 2.0), "spread"),
        ((0.0, 0.0, 0.1, math.inf), "limit"),
        ((math.nan, 0.0, 0.1, 2.0), "finite"),
    ],
)
def test_look_yaws_errors(args: tuple[float, float, float, float], msg: str) -> None:
    with pytest.raises(ValueError, match=msg):
        look_yaws(*args)


def test_match_parent_takes_the_nearest_within_the_gate() -> None:
    pts = np.array([[1.0, 0.0], [-0.1, 1.0], [0.1, 1.0], [0.0, 1.25]])
    assert match_parent(pts, np.array([0.0, 1.0]), 0.3) == 1  # tie (0.1, 0.1): first
    assert match_parent(pts[[0, 3]], np.array([0.0, 1.0]), 0.3) == 1
    # the nearest NAO is 0.25 m off: with a 0.2 m gate it is another robot
    assert match_parent(pts[[0, 3]], np.array([0.0, 1.0]), 0.2) is None
    assert match_parent(np.zeros((0, 2)), np.array([0.0, 1.0]), 0.3) is None
    assert match_parent(np.array([]), np.array([0.0, 1.0]), 0.3) is None


@pytest.mark.parametrize(
    ("pts", "exp", "gate", "msg"),
    [
        (np.zeros((2, 3)), np.zeros(2), 0.3, "shape|\\(K, 2\\)"),
        (np.zeros((2, 2)), np.zeros(3), 0.3, "\\(2,\\)"),
        (np.array([[np.nan, 0.0]]), np.zeros(2), 0.3, "finite"),
        (np.zeros((1, 2)), np.zeros(2), 0.0, "gate"),
    ],
)
def test_match_parent_errors(pts: np.ndarray, exp: np.ndarray, gate: float, msg: str) -> None:
    with pytest.raises(ValueError, match=msg):
        match_parent(pts, exp, gate)
