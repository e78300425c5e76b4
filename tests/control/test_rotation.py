"""Rotation control (NAO paper 5.2.2): known answers, invariants, error branches."""

from __future__ import annotations

import math

import numpy as np
import pytest

from agent.core.control.rotation import (
    MAX_STEP,
    PAPER_GAINS,
    STEP_GAINS,
    PidGains,
    RotationControl,
    wrap_pi,
)

DEG = math.pi / 180.0


def test_first_step_is_clipped_to_15_degrees() -> None:
    rc = RotationControl(math.pi)
    assert rc.next_step() == pytest.approx(MAX_STEP)
    rc2 = RotationControl(-math.pi)
    assert rc2.next_step() == pytest.approx(-MAX_STEP)


def test_small_target_is_one_proportional_step() -> None:
    rc = RotationControl(10 * DEG)
    # e = 10°, no derivative kick on the first step: u = kP * e = 10°
    assert rc.next_step() == pytest.approx(10 * DEG)
    rc.record(10 * DEG)
    assert rc.done
    assert rc.next_step() == 0.0


def test_derivative_term_known_answer() -> None:
    rc = RotationControl(20 * DEG, tolerance=0.5 * DEG)
    assert rc.next_step() == pytest.approx(15 * DEG)
    rc.record(12 * DEG)  # the body under-turned: e_0 = 20°, e_1 = 8°
    # u = 1.0 * 8° + 0.2 * (8° - 20°) = 5.6°
    assert rc.next_step() == pytest.approx(5.6 * DEG)


def test_perfect_plant_reaches_180_in_14_steps() -> None:
    rc = RotationControl(math.pi)
    us = []
    while not rc.done:
        u = rc.next_step()
        us.append(math.degrees(u))
        rc.record(u)
    # 11 saturated steps, then the derivative brakes: e = 15° -> u = 15 + 0.2 * (15 - 30) = 12°,
    # e = 3° -> u = 3 + 0.2 * (3 - 15) = 0.6°, e = 2.4° -> u = 2.4 + 0.2 * (2.4 - 3) = 2.28°
    assert us == pytest.approx([15.0] * 11 + [12.0, 0.6, 2.28])
    assert abs(rc.error) <= math.radians(2.0)


@pytest.mark.parametrize("gain", [0.7, 0.9, 1.1, 1.3])
def test_converges_on_a_biased_noisy_plant(gain: float) -> None:
    rng = np.random.default_rng(3)
    for target in (-170 * DEG, -40 * DEG, 3 * DEG, 95 * DEG, 180 * DEG):
        rc = RotationControl(target, tolerance=1.5 * DEG)
        while not (rc.done or rc.exhausted):
            u = rc.next_step()
            rc.record(gain * u + rng.normal(0.0, 0.3 * DEG))
        assert rc.done, (gain, target, rc)
        assert abs(rc.error) <= 1.5 * DEG


def test_never_turns_away_from_target() -> None:
    rc = RotationControl(30 * DEG, gains=PidGains(1.0, 0.0, 5.0), tolerance=1 * DEG)
    rc.next_step()
    rc.record(25 * DEG)  # e: 30° -> 5°, kD (5 - 30) * 5 would turn back
    u = rc.next_step()
    assert u > 0.0


def test_exhausted_after_max_steps() -> None:
    rc = RotationControl(90 * DEG, max_steps=3)
    for _ in range(3):
        rc.next_step()
        rc.record(0.0)  # the body does not move
    assert rc.exhausted and not rc.done
    assert rc.next_step() == 0.0


def test_step_gains_have_no_derivative() -> None:
    assert STEP_GAINS.kd == 0.0
    assert PidGains(1.0, 0.0, 0.2) == PAPER_GAINS


def test_wrap_pi() -> None:
    assert wrap_pi(3 * math.pi / 2) == pytest.approx(-math.pi / 2)
    assert wrap_pi(-3 * math.pi / 2) == pytest.approx(math.pi / 2)
    assert wrap_pi(0.25) == pytest.approx(0.25)
    assert wrap_pi(math.pi) == pytest.approx(-math.pi)


@pytest.mark.parametrize(
    "kwargs",
    [
        {"target": math.nan},
        {"target": 7.0},
        {"target": 1.0, "max_step": 0.0},
        {"target": 1.0, "max_step": math.radians(45)},
        {"target": 1.0, "tolerance": 0.0},
        {"target": 1.0, "tolerance": MAX_STEP},
        {"target": 1.0, "max_steps": 0},
    ],
)
def test_bad_construction_raises(kwargs: dict[str, float]) -> None:
    with pytest.raises(ValueError):
        RotationControl(**kwargs)  # type: ignore[arg-type]


@pytest.mark.parametrize("gains", [(0.0, 0.0, 0.2), (1.0, -1.0, 0.0), (1.0, 0.0, math.inf)])
def test_bad_gains_raise(gains: tuple[float, float, float]) -> None:
    with pytest.raises(ValueError):
        PidGains(*gains)


def test_bad_measurement_raises_and_keeps_state() -> None:
    rc = RotationControl(1.0)
    with pytest.raises(ValueError, match="not finite"):
        rc.record(math.inf)
    with pytest.raises(ValueError, match="implausible"):
        rc.record(math.radians(120))
    assert rc.steps == 0 and rc.completed == 0.0


def test_wrap_pi_rejects_nan() -> None:
    with pytest.raises(ValueError):
        wrap_pi(math.nan)
