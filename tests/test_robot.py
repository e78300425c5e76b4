"""agent/robot.py: retrying queries that met no queryable (lossy links, fresh sessions)."""

from __future__ import annotations

import pytest

from agent.bus import BusError, NoRoute
from agent.robot import retry_no_route


def flaky(failures: list[Exception], value: int = 7) -> tuple[list[int], object]:
    calls: list[int] = []

    def call() -> int:
        calls.append(1)
        if failures:
            raise failures.pop(0)
        return value

    return calls, call


def test_no_route_is_retried_until_it_succeeds() -> None:
    calls, call = flaky([NoRoute("a"), NoRoute("b")])
    assert retry_no_route(call, deadline_s=5.0, first_wait=0.001) == 7  # type: ignore[arg-type]
    assert len(calls) == 3


def test_other_bus_errors_are_not_retried() -> None:
    calls, call = flaky([BusError("robot 3 is busy")])
    with pytest.raises(BusError, match="busy"):
        retry_no_route(call, deadline_s=5.0, first_wait=0.001)  # type: ignore[arg-type]
    assert len(calls) == 1


def test_no_route_past_the_deadline_is_raised() -> None:
    calls, call = flaky([NoRoute("x")] * 100)
    with pytest.raises(NoRoute):
        retry_no_route(call, deadline_s=0.05, first_wait=0.02)  # type: ignore[arg-type]
    assert 1 < len(calls) < 100
