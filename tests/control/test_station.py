"""Station keeping on the parent (agent/core/control/station.py): known answers, invariants,
one test per error branch."""

from __future__ import annotations

import math

import numpy as np
import pytest

from agent.core.control.station import (
    StationCommand,
    StationGains,
    StationKeeper,
    safe_walk,
    unicycle_step,
)

P_ONLY = StationGains(kp=1.0, ki=0.0)


def test_range_error_is_removed_in_one_step_by_p_only() -> None:
    # parent due north (β* = 90°) at 1.0 m instead of 0.8: walk 0.2 m north
    sk = StationKeeper(0.8, math.pi / 2, P_ONLY)
    cmd = sk.update(1.0, math.pi / 2)
    assert (cmd.dx, cmd.dy) == pytest.approx((0.0, 0.2))
    assert cmd.e_range == pytest.approx(0.2) and cmd.e_bearing == pytest.approx(0.0)
    assert not cmd.saturated


def test_bearing_error_gives_a_tangential_step() -> None:
    # parent wanted straight east (β* = 0) at 0.8 m; seen at 0.8 m, 0.1 rad to the left:
    # Δ = ρ·e_β·t̂(β) = 0.08·(−sin 0.1, cos 0.1)
    sk = StationKeeper(0.8, 0.0, P_ONLY)
    cmd = sk.update(0.8, 0.1)
    assert cmd.dx == pytest.approx(-0.08 * math.sin(0.1))
    assert cmd.dy == pytest.approx(0.08 * math.cos(0.1))
    assert cmd.e_bearing == pytest.approx(0.1)


def test_pi_known_answer_with_integral() -> None:
    # kP 0.8, kI 0.2: e = 0.1 → I = 0.1, u = 0.08 + 0.02 = 0.1; then e = 0.05 → I = 0.15,
    # u = 0.04 + 0.03 = 0.07 (parent due east, β* = 0)
    sk = StationKeeper(0.8, 0.0)
    assert sk.update(0.9, 0.0).dx == pytest.approx(0.10)
    assert sk.update(0.85, 0.0).dx == pytest.approx(0.07)
    assert sk.i_range == pytest.approx(0.15)


def test_speed_limit_and_no_windup() -> None:
    sk = StationKeeper(0.8, 0.0, max_step=0.2)
    cmd = sk.update(1.4, 0.0)
    assert cmd.saturated and cmd.size == pytest.approx(0.2)
    assert sk.i_range == 0.0  # frozen while saturated


def test_deadband() -> None:
    sk = StationKeeper(0.8, 0.0, P_ONLY, deadband=0.03)
    cmd = sk.update(0.82, 0.0)
    assert (cmd.dx, cmd.dy) == (0.0, 0.0) and cmd.e_range == pytest.approx(0.02)


def test_integral_is_clamped_and_reset() -> None:
    g = StationGains(kp=0.1, ki=0.1, i_range_max=0.05)
    sk = StationKeeper(0.8, 0.0, g, max_step=1.0)
    for _ in range(10):
        sk.update(0.9, 0.0)
    assert sk.i_range == pytest.approx(0.05)
    sk.reset()
    assert sk.i_range == 0.0 and sk.i_bearing == 0.0


def _march(gains: StationGains, v: float, cycles: int) -> list[float]:
    """Parent walks v per cycle along +x, child behind at d_ref; the range errors the
    child measures (after the parent's step, before its own)."""
    sk = StationKeeper(0.8, 0.0, gains, deadband=0.0)
    parent, child, errs = 0.8, 0.0, []
    for _ in range(cycles):
        parent += v
        cmd = sk.update(parent - child, 0.0, (child, 0.0))
        child += cmd.dx
        errs.append(cmd.e_range)
    return errs


def test_integral_removes_the_lag_behind_a_marching_parent() -> None:
    pi = _march(StationGains(), 0.1, 40)
    p = _march(P_ONLY, 0.1, 40)
    assert abs(pi[-1]) < 1e-3  # PI: no steady-state lag (u = kI·I = v)
    assert p[-1] == pytest.approx(0.1)  # P (kP = 1): trails by one cycle's advance v
    lagging = _march(StationGains(kp=0.5, ki=0.0), 0.1, 40)
    assert lagging[-1] == pytest.approx(0.2, abs=1e-3)  # P: lag v/kP
    # the first cycle sees the whole advance; no oscillation beyond a small undershoot
    assert max(pi) == pytest.approx(0.1) and min(pi) > -0.02


@pytest.mark.parametrize("heading", [0.0, 1.0, -2.5, math.pi / 2])
def test_unicycle_forward_known_answers(heading: float) -> None:
    # displacement straight ahead: no turn, walk its length
    turn, walk = unicycle_step(0.1 * math.cos(heading), 0.1 * math.sin(heading), heading)
    assert turn == pytest.approx(0.0) and walk == pytest.approx(0.1)
    # straight behind: no turn, walk backwards
    turn, walk = unicycle_step(-0.1 * math.cos(heading), -0.1 * math.sin(heading), heading)
    assert turn == pytest.approx(0.0) and walk == pytest.approx(-0.1)


def test_unicycle_turn_is_limited_and_walk_projected() -> None:
    # facing east, displacement 0.1 m at 40° left: turn 15°, walk 0.1·cos 25°
    d = math.radians(40)
    turn, walk = unicycle_step(0.1 * math.cos(d), 0.1 * math.sin(d), 0.0)
    assert turn == pytest.approx(math.radians(15))
    assert walk == pytest.approx(0.1 * math.cos(math.radians(25)))
    # sideways: 90° → treated as forward (|α| ≤ 90°), turn 15°, walk 0.1·cos 75°
    turn, walk = unicycle_step(0.0, 0.1, 0.0)
    assert turn == pytest.approx(math.radians(15))
    assert walk == pytest.approx(0.1 * math.cos(math.radians(75)))
    # small angles are not turned (below 8°): 5° → walk the projection
    d = math.radians(5)
    turn, walk = unicycle_step(0.1 * math.cos(d), 0.1 * math.sin(d), 0.0)
    assert turn == 0.0 and walk == pytest.approx(0.1 * math.cos(d))
    assert unicycle_step(0.0, 0.0, 0.3) == (0.0, 0.0)


def test_command_size() -> None:
    assert StationCommand(0.3, 0.4, 0.0, 0.0, False).size == pytest.approx(0.5)


@pytest.mark.parametrize(
    "kwargs",
    [{"kp": 0.0}, {"kp": math.nan}, {"ki": -0.1}, {"kp": 3.0}, {"i_range_max": -1.0},
     {"i_bearing_max": math.inf}, {"kf": 1.5}],
)  # fmt: skip
def test_bad_gains(kwargs: dict[str, float]) -> None:
    with pytest.raises(ValueError):
        StationGains(**kwargs)


@pytest.mark.parametrize(
    "kwargs",
    [{"d_ref": 0.0}, {"d_ref": math.nan}, {"bearing_ref": math.inf}, {"max_step": 0.0},
     {"max_step": 2.0}, {"deadband": -0.01}, {"deadband": 0.5}, {"smoothing": 1.5}],
)  # fmt: skip
def test_bad_keeper(kwargs: dict[str, float]) -> None:
    args: dict[str, float] = {"d_ref": 0.8, "bearing_ref": 0.0, **kwargs}
    with pytest.raises(ValueError):
        StationKeeper(**args)  # type: ignore[arg-type]


@pytest.mark.parametrize("args", [(math.nan, 0.0), (-0.1, 0.0), (1.0, math.inf), (200.0, 0.0)])
def test_bad_measurement(args: tuple[float, float]) -> None:
    with pytest.raises(ValueError):
        StationKeeper(0.8, 0.0).update(*args)


@pytest.mark.parametrize(
    "args",
    [(math.nan, 0.0, 0.0), (0.0, math.inf, 0.0), (0.1, 0.0, math.nan), (0.1, 0.0, 0.0, -0.1),
     (0.1, 0.0, 0.0, 0.2, 4.0)],
)  # fmt: skip
def test_bad_unicycle(args: tuple[float, ...]) -> None:
    with pytest.raises(ValueError):
        unicycle_step(*args)


def test_safe_walk_known_answers() -> None:
    # facing east; a robot 0.61 m ahead, clearance 0.4: 0.2 m ends 0.41 away (allowed)
    ahead = np.array([[0.61, 0.0]])
    assert safe_walk(0.2, 0.0, ahead, 0.4) == pytest.approx(0.2)
    # 0.5 m ahead: 0.2 → 0.3 away (no), 0.1 → 0.4 (yes)
    assert safe_walk(0.2, 0.0, np.array([[0.5, 0.0]]), 0.4) == pytest.approx(0.1)
    # 0.3 m ahead (already inside 2·radius): no step towards it, but away from it yes
    close = np.array([[0.3, 0.0]])
    assert safe_walk(0.2, 0.0, close, 0.4) == 0.0
    assert safe_walk(-0.1, 0.0, close, 0.4) == pytest.approx(-0.1)
    assert safe_walk(0.2, math.pi, close, 0.4) == pytest.approx(0.2)
    # passing by: a robot 0.3 m to the side of the path's middle blocks the long step
    side = np.array([[0.1, 0.3]])
    assert safe_walk(0.2, 0.0, side, 0.4) == 0.0
    # nobody in view
    assert safe_walk(0.15, 1.0, np.zeros((0, 2)), 0.4) == pytest.approx(0.15)
    assert safe_walk(0.0, 0.0, ahead, 0.4) == 0.0


@pytest.mark.parametrize(
    "args",
    [(2.0, 0.0, np.zeros((0, 2)), 0.4), (0.1, math.nan, np.zeros((0, 2)), 0.4),
     (0.1, 0.0, np.zeros((0, 2)), -0.4), (0.1, 0.0, np.array([[math.nan, 0.0]]), 0.4)],
)  # fmt: skip
def test_bad_safe_walk(args: tuple[float, float, np.ndarray, float]) -> None:
    with pytest.raises(ValueError):
        safe_walk(*args)


def test_parent_advance_is_estimated_and_fed_forward() -> None:
    # parent due east at d_ref; it advances 0.1 m east per cycle, the child stays put:
    # a_1 = 0.5·0.1 = 0.05, a_2 = 0.5·0.05 + 0.5·0.1 = 0.075 (λ = 0.5)
    g = StationGains(kp=1.0, ki=0.0, kf=1.0)
    sk = StationKeeper(0.8, 0.0, g, deadband=0.0)
    assert sk.update(0.8, 0.0, (0.0, 0.0)).dx == pytest.approx(0.0)
    cmd = sk.update(0.9, 0.0, (0.0, 0.0))
    assert sk.advance == pytest.approx((0.05, 0.0))
    assert cmd.dx == pytest.approx(0.1 + 0.05)
    sk.update(1.0, 0.0, (0.0, 0.0))
    assert sk.advance == pytest.approx((0.075, 0.0))
    # the child's own motion is not the parent's: child moved 0.1, parent too → a stays
    sk2 = StationKeeper(0.8, 0.0, g, deadband=0.0)
    sk2.update(0.8, 0.0, (0.0, 0.0))
    sk2.update(0.8, 0.0, (0.1, 0.0))
    assert sk2.advance == pytest.approx((0.05, 0.0))
    sk2.reset()
    assert sk2.advance == (0.0, 0.0)


def test_feed_forward_keeps_up_sooner() -> None:
    with_ff = _march(StationGains(kf=0.8), 0.1, 8)
    without = _march(StationGains(), 0.1, 8)
    assert sum(abs(e) for e in with_ff) < sum(abs(e) for e in without)


def test_bad_position() -> None:
    with pytest.raises(ValueError):
        StationKeeper(0.8, 0.0).update(0.8, 0.0, (math.nan, 0.0))
