"""Long computations while the bus is pumped (agent/phases/waves.py ``while_pumping``:
agreement that scales)."""

from __future__ import annotations

import threading

import pytest

from agent.phases.waves import while_pumping


def test_the_bus_is_pumped_until_the_plan_is_done() -> None:
    """The computation waits until the pump has run three times: it can only finish if
    the pump runs while it computes."""
    pumped = threading.Event()
    calls: list[int] = []

    def compute() -> str:
        assert pumped.wait(10.0), "never pumped while computing"
        return "plan"

    def pump() -> None:
        calls.append(1)
        if len(calls) >= 3:
            pumped.set()

    assert while_pumping(compute, pump, 0.01) == "plan"
    assert len(calls) >= 3


def test_a_quick_plan_pumps_nothing() -> None:
    calls: list[int] = []
    assert while_pumping(lambda: 7, lambda: calls.append(1), 5.0) == 7
    assert calls == []


def test_the_plans_error_is_raised_here() -> None:
    def refuse() -> None:
        raise ValueError("sightings do not fit")

    with pytest.raises(ValueError, match="sightings do not fit"):
        while_pumping(refuse, lambda: None, 0.01)


def test_a_timeout_raised_by_the_plan_is_not_taken_for_pending() -> None:
    def slow_then_timeout() -> None:
        threading.Event().wait(0.05)
        raise TimeoutError("inner")

    with pytest.raises(TimeoutError, match="inner"):
        while_pumping(slow_then_timeout, lambda: None, 0.01)


def test_a_pump_that_fails_waits_for_the_plan_and_raises() -> None:
    done = threading.Event()

    def compute() -> None:
        threading.Event().wait(0.05)
        done.set()

    def pump() -> None:
        raise RuntimeError("bus closed")

    with pytest.raises(RuntimeError, match="bus closed"):
        while_pumping(compute, pump, 0.01)
    assert done.is_set()  # the worker was not left running


@pytest.mark.parametrize("every", [0.0, -1.0, float("nan")])
def test_bad_intervals_are_refused(every: float) -> None:
    with pytest.raises(ValueError, match="every must be > 0"):
        while_pumping(lambda: 1, lambda: None, every)
