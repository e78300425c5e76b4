"""The heading re-measured after a crash, weighed by the errors (agent/core/control/heading_fix.py)."""

from __future__ import annotations

import math

import pytest
from hypothesis import given
from hypothesis import strategies as st

from agent.core.control import wrap_pi
from agent.core.control.heading_fix import (
    BELIEF_SIGMA,
    COMPASS_IN_PLACE,
    GATE_CHI2,
    compass_sigma,
    estimate_sigma,
    fuse,
)

DEG = math.radians(1.0)


def test_the_compass_sigma_by_hand() -> None:
    assert compass_sigma(0.0) == pytest.approx(COMPASS_IN_PLACE)
    assert compass_sigma(1.0) == pytest.approx(math.hypot(0.2, 14.0) * DEG)
    assert compass_sigma(0.5) == pytest.approx(math.hypot(0.2, 7.0) * DEG)


def test_the_estimate_sigma_by_command() -> None:
    assert estimate_sigma() == BELIEF_SIGMA
    assert estimate_sigma("turn", 1.0) == pytest.approx(math.hypot(BELIEF_SIGMA, 0.07))
    assert estimate_sigma("turn", -1.0) == estimate_sigma("turn", 1.0)
    assert estimate_sigma("walk", 0.2) == pytest.approx(math.hypot(BELIEF_SIGMA, 0.1))
    assert estimate_sigma("side", -0.2) == estimate_sigma("walk", 0.2)
    # a turn whose execution is unknown may not have happened: its whole value too
    unknown = estimate_sigma("turn", 0.5, known=False)
    assert unknown == pytest.approx(math.hypot(BELIEF_SIGMA, math.hypot(0.045, 0.5)))


def test_in_place_the_compass_wins() -> None:
    fix = fuse(0.0, BELIEF_SIGMA, 3 * DEG, compass_sigma(0.0))
    assert fix.accepted and fix.gain > 0.98
    assert fix.heading == pytest.approx(3 * DEG, abs=0.05 * DEG)
    assert fix.sigma < COMPASS_IN_PLACE


def test_a_metre_away_parallax_barely_moves_a_sound_estimate() -> None:
    """The hold resumption's case: 13.6° of parallax 0.9 m from the reference view."""
    fix = fuse(math.pi / 2, BELIEF_SIGMA, math.pi / 2 + 13.6 * DEG, compass_sigma(0.74))
    assert fix.accepted
    assert 0.0 < fix.heading - math.pi / 2 < 0.5 * DEG
    assert fix.gain == pytest.approx(BELIEF_SIGMA**2 / (BELIEF_SIGMA**2 + compass_sigma(0.74) ** 2))


def test_an_innovation_beyond_the_gate_keeps_the_estimate() -> None:
    s = math.hypot(BELIEF_SIGMA, COMPASS_IN_PLACE)
    inside = fuse(1.0, BELIEF_SIGMA, 1.0 + 3.2 * s, COMPASS_IN_PLACE)
    outside = fuse(1.0, BELIEF_SIGMA, 1.0 + 3.4 * s, COMPASS_IN_PLACE)
    assert inside.accepted and not outside.accepted
    assert outside.heading == pytest.approx(1.0) and outside.gain == 0.0
    assert outside.sigma == BELIEF_SIGMA
    assert math.sqrt(GATE_CHI2) == pytest.approx(3.29, abs=0.005)


def test_the_innovation_wraps_across_pi() -> None:
    fix = fuse(math.pi - DEG, BELIEF_SIGMA, -math.pi + DEG, COMPASS_IN_PLACE)
    assert fix.innovation == pytest.approx(2 * DEG)
    assert fix.heading == pytest.approx(wrap_pi(math.pi + DEG), abs=0.1 * DEG)


@given(
    est=st.floats(-3.0, 3.0),
    nu=st.floats(-0.3, 0.3),
    away=st.floats(0.0, 3.0),
    sigma_e=st.floats(0.005, 0.5),
)
def test_the_fused_heading_lies_between_the_two(
    est: float, nu: float, away: float, sigma_e: float
) -> None:
    fix = fuse(est, sigma_e, est + nu, compass_sigma(away))
    moved = wrap_pi(fix.heading - est)
    assert min(0.0, nu) - 1e-9 <= moved <= max(0.0, nu) + 1e-9
    assert fix.sigma <= sigma_e + 1e-12
    # farther from the reference view the compass weighs less (its gate widens, though)
    farther = fuse(est, sigma_e, est + nu, compass_sigma(away + 0.5))
    assert farther.accepted or not fix.accepted
    if fix.accepted:
        assert farther.gain <= fix.gain + 1e-12


@pytest.mark.parametrize(
    ("args", "match"),
    [
        ((math.nan, 0.1, 0.0, 0.1), "estimate must be finite"),
        ((0.0, math.inf, 0.0, 0.1), "sigma_e must be finite"),
        ((0.0, 0.1, 0.0, 0.0), "sigmas must be > 0"),
        ((0.0, -0.1, 0.0, 0.1), "sigmas must be > 0"),
    ],
)
def test_fuse_errors(args: tuple[float, float, float, float], match: str) -> None:
    with pytest.raises(ValueError, match=match):
        fuse(*args)


def test_sigma_errors() -> None:
    with pytest.raises(ValueError, match="away must be >= 0"):
        compass_sigma(-0.1)
    with pytest.raises(ValueError, match="away must be finite"):
        compass_sigma(math.nan)
    with pytest.raises(ValueError, match="command must be"):
        estimate_sigma("jump", 1.0)
    with pytest.raises(ValueError, match="value must be finite"):
        estimate_sigma("turn", math.inf)
