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

    def query(
        self, key: str, msg: object, expect: type, timeout: float, best: bool = False
    ) -> object:
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


# --------------------------------------------------------------------------- pose time
# a render worker follows the world's poses a little behind; a frame drawn
# from poses older than the end of the robot's last motion is never used.


def _png() -> bytes:
    import cv2
    import numpy as np

    ok, data = cv2.imencode(".png", np.zeros((4, 6, 3), np.uint8))
    assert ok
    return bytes(data.tobytes())


class RenderedBus:
    """Motions end at ``motion_t``; camera replies carry the pose times of ``frames``
    in turn (the last one repeated); every camera query must ask for the best match."""

    def __init__(
        self, frames: list[float], motion_t: float = 5.0, encoding: str = "png", data: bytes = b""
    ) -> None:
        self.frames = frames
        self.motion_t = motion_t
        self.encoding = encoding
        self.data = data or _png()
        self.status = "done"
        self.camera_asks = 0

    def query(
        self, key: str, msg: object, expect: type, timeout: float, best: bool = False
    ) -> object:
        from agent.wire import CameraReply

        if key.endswith("/camera"):
            assert best, "a camera query goes to one complete queryable"
            self.camera_asks += 1
            t = self.frames.pop(0) if len(self.frames) > 1 else self.frames[0]
            return CameraReply(
                robot_id=3,
                yaw=0.0,
                t_sim=t,
                width=6,
                height=4,
                encoding=self.encoding,
                data=self.data,
            )
        return CommandReply(robot_id=3, status=self.status, t_sim=self.motion_t)


def test_a_frame_older_than_the_last_motion_is_asked_for_again() -> None:
    bus = RenderedBus([4.9, 4.95, 5.0])
    body = ZenohBody(bus, 3)  # type: ignore[arg-type]
    assert body.camera(0.0).t_sim == 4.9  # no motion yet: any frame will do
    bus.frames = [4.9, 4.95, 5.0]
    body.walk(0.2)
    assert body.motion_end == 5.0
    frame = body.camera(0.3)
    assert frame.t_sim == 5.0 and bus.camera_asks == 4 and body.stale_frames == 2


@pytest.mark.parametrize(
    ("encoding", "data"),
    [("bgr8", bytes(range(72))), ("png", b"")],  # png: RenderedBus's 6 x 4 picture
)
def test_a_picture_is_decoded_from_either_encoding(encoding: str, data: bytes) -> None:
    import numpy as np

    body = ZenohBody(RenderedBus([1.0], encoding=encoding, data=data), 3)  # type: ignore[arg-type]
    img = body.camera(0.0).image
    assert img.shape == (4, 6, 3) and img.dtype == np.uint8 and img.flags.writeable
    if encoding == "bgr8":  # row after row, B G R a pixel
        assert img[1, 0].tolist() == [18, 19, 20]


@pytest.mark.parametrize(
    ("encoding", "data"),
    [("bgr8", bytes(71)), ("png", b"\x89PNG not really")],
)
def test_a_picture_that_does_not_decode_is_a_body_error(encoding: str, data: bytes) -> None:
    body = ZenohBody(RenderedBus([1.0], encoding=encoding, data=data), 3)  # type: ignore[arg-type]
    with pytest.raises(BodyError, match="undecodable image"):
        body.camera(0.0)


def test_a_contact_ends_a_motion_too() -> None:
    bus = RenderedBus([7.0])
    bus.motion_t, bus.status = 7.5, "contact"
    body = ZenohBody(bus, 3, camera_timeout=0.3)  # type: ignore[arg-type]
    assert body.turn(0.1).status == "contact"
    assert body.motion_end == 7.5
    with pytest.raises(BodyError, match=r"predates the last motion.*t=7\.00.*t=7\.50"):
        body.camera(0.0)
    assert body.stale_frames >= 1


def test_a_renderer_that_never_catches_up_fails_within_the_camera_timeout() -> None:
    import time

    bus = RenderedBus([1.0], motion_t=2.0)
    body = ZenohBody(bus, 3, camera_timeout=0.5)  # type: ignore[arg-type]
    body.walk(0.1)
    t0 = time.monotonic()
    with pytest.raises(BodyError, match="predates the last motion"):
        body.camera(0.0)
    assert time.monotonic() - t0 < 1.5
    assert 1 < bus.camera_asks < 20  # asked again with a growing pause, not in a hot loop


def test_an_error_reply_to_a_camera_query_is_not_retried() -> None:
    bus = LossyBus(lost=0, error=BusError("render failed: boom"))

    def query(key: str, msg: object, expect: type, timeout: float, best: bool = False) -> object:
        return LossyBus.query(bus, key, msg, expect, timeout)

    bus.query = query  # type: ignore[method-assign]
    body = ZenohBody(bus, 3)  # type: ignore[arg-type]
    with pytest.raises(BodyError, match="render failed"):
        body.camera(0.0)
    assert len(bus.asked) == 1


def test_a_busy_world_is_asked_again_after_a_pause() -> None:
    from agent.net.bus import Busy

    bus = RenderedBus([1.0])
    real = bus.query
    busy = [2]

    def query(key: str, msg: object, expect: type, timeout: float, best: bool = False) -> object:
        if busy[0] > 0:
            busy[0] -= 1
            raise Busy(f"{key}: world busy: 64 pictures being drawn")
        return real(key, msg, expect, timeout, best)

    bus.query = query  # type: ignore[method-assign]
    body = ZenohBody(bus, 3)  # type: ignore[arg-type]
    frame = body.camera(0.0)  # two refusals, 0.5 s then 1 s apart
    assert frame.t_sim == 1.0 and body.busy_replies == 2
    body.close()
    assert body.busy_replies == 0


def test_a_world_busy_until_the_camera_timeout_fails() -> None:
    from agent.net.bus import Busy

    bus = LossyBus(lost=0, error=Busy("world/robot/3/camera: world busy: 64 pictures"))
    body = ZenohBody(bus, 3, camera_timeout=1.0)  # type: ignore[arg-type]
    with pytest.raises(BodyError, match=r"world busy.*until the camera timeout"):
        body.camera(0.0)
    assert len(bus.asked) == 2  # at 0 and after 0.5 s; the next pause (1 s) is past the end


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
