"""agent/body/zenoh_world.py: retrying queries that met no queryable (lossy links, fresh sessions)."""

from __future__ import annotations

import pytest

from agent.body.base import BodyError, MotionResult
from agent.body.zenoh_world import ZenohBody, retry_no_route, retry_timeout
from agent.net.bus import BusError, NoRoute, QueryTimeout
from agent.wire import CommandReply, TurnRequest


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


class LossyBus:
    """A bus whose first ``lost`` queries time out (a lost request or reply)."""

    def __init__(self, lost: int, error: BusError | None = None) -> None:
        self.lost = lost
        self.error = error
        self.asked: list[tuple[str, object, float]] = []

    def query(self, key: str, msg: object, expect: type, timeout: float) -> object:
        self.asked.append((key, msg, timeout))
        if self.error is not None:
            raise self.error
        if self.lost > 0:
            self.lost -= 1
            raise QueryTimeout(f"{key}: no reply within {timeout:g} s")
        return CommandReply(robot_id=3, status="done", t_sim=2.0)


def test_a_timed_out_motion_is_asked_again_with_the_same_request_id() -> None:
    bus = LossyBus(lost=2)
    body = ZenohBody(bus, 3)  # type: ignore[arg-type]
    assert body.walk(0.2) == MotionResult("done", 2.0, "")
    msgs = [m for _, m, _ in bus.asked]
    assert len(msgs) == 3 and len({m.request_id for m in msgs}) == 1  # type: ignore[attr-defined]
    assert body.retries == 2
    body.turn(0.1)  # the next motion has a new id
    ids = [m.request_id for _, m, _ in bus.asked]  # type: ignore[attr-defined]
    assert ids[-1] == ids[0] + 1 and isinstance(bus.asked[-1][1], TurnRequest)
    assert all(t <= 60.0 for _, _, t in bus.asked)  # one attempt waits MOTION_ATTEMPT_S


def test_a_motion_that_never_answers_fails_after_the_motion_timeout() -> None:
    bus = LossyBus(lost=10**6)
    body = ZenohBody(bus, 3, motion_timeout=0.3)  # type: ignore[arg-type]
    with pytest.raises(BodyError, match="no reply"):
        body.turn(0.1)
    assert len(bus.asked) >= 1


def test_an_error_reply_to_a_motion_is_not_retried() -> None:
    bus = LossyBus(lost=0, error=BusError("robot 3 is busy with a motion"))
    body = ZenohBody(bus, 3)  # type: ignore[arg-type]
    with pytest.raises(BodyError, match="busy"):
        body.walk(0.1)
    assert len(bus.asked) == 1


def test_retry_timeout_counts_attempts_and_raises_past_the_total() -> None:
    calls: list[float] = []

    def call(timeout: float) -> int:
        calls.append(timeout)
        if len(calls) < 3:
            raise QueryTimeout("lost")
        return 5

    assert retry_timeout(call, total_s=100.0, attempt_s=2.0, what="x") == (5, 3)
    assert calls == [2.0, 2.0, 2.0]

    def never(timeout: float) -> int:
        raise QueryTimeout("lost")

    with pytest.raises(QueryTimeout):
        retry_timeout(never, total_s=0.05, attempt_s=2.0, what="x")


def test_camera_waits_grow_with_the_fleet_behind_the_worlds_queue() -> None:
    from agent.body.zenoh_world import CAMERA_ATTEMPT_S, CAMERA_TIMEOUT_S, camera_waits

    assert camera_waits(None) == camera_waits(3) == (CAMERA_ATTEMPT_S, CAMERA_TIMEOUT_S)
    assert camera_waits(15) == (15.0, 30.0)  # unchanged up to 15 robots
    assert camera_waits(30) == (30.0, 60.0)
    assert camera_waits(100) == (100.0, 200.0)


def test_a_camera_attempt_waits_as_long_as_the_body_is_told() -> None:
    from agent.wire import CameraRequest

    bus = LossyBus(lost=10**6)
    body = ZenohBody(bus, 3, camera_timeout=0.3, camera_attempt=0.2)  # type: ignore[arg-type]
    with pytest.raises(BodyError, match="camera"):
        body.camera(0.0)
    assert bus.asked and all(isinstance(m, CameraRequest) for _, m, _ in bus.asked)
    assert max(t for _, _, t in bus.asked) <= 0.2
    long = ZenohBody(LossyBus(lost=0), 3, camera_attempt=100.0)  # type: ignore[arg-type]
    assert (long.camera_attempt, long.camera_timeout) == (100.0, 30.0)
