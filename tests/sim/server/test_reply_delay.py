"""A slow world (``python -m sim --reply-delay MAX_S``, sim/server/delays.py): camera and motion
replies held for a seeded random delay by the world's one loop, which keeps serving."""

from __future__ import annotations

import threading
import time
from collections.abc import Iterator
from typing import Any

import pytest

from agent.wire import (
    KEY_WORLD_REGISTER,
    CameraReply,
    CameraRequest,
    CommandReply,
    RegisterReply,
    RegisterRequest,
    TurnRequest,
    decode,
    encode,
    key_camera,
    key_turn,
)
from sim import scenarios
from sim.__main__ import main
from sim.server.delays import MAX_REPLY_DELAY_S, DelayedReplies


class TimedQuery:
    """A query that notes when each reply came (monotonic seconds)."""

    def __init__(self, key: str, msg: Any) -> None:
        self.key_expr = key
        self.parameters: dict[str, str] = {}
        self.payload = _Bytes(encode(msg))
        self.replies: list[tuple[float, Any]] = []
        self.got = threading.Event()

    def reply(self, key: str, data: bytes) -> None:
        self.replies.append((time.monotonic(), decode(data)))
        self.got.set()

    def drop(self) -> None:
        pass


class _Bytes:
    def __init__(self, data: bytes) -> None:
        self.data = data

    def __len__(self) -> int:
        return len(self.data)

    def to_bytes(self) -> bytes:
        return self.data


def test_delays_are_seeded_bounded_and_sent_in_due_order() -> None:
    a: DelayedReplies[str, int] = DelayedReplies(2.0, seed=5)
    b: DelayedReplies[str, int] = DelayedReplies(2.0, seed=5)
    da = [a.hold(f"q{i}", i, now=10.0) for i in range(20)]
    db = [b.hold(f"q{i}", i, now=10.0) for i in range(20)]
    assert da == db and all(0.0 <= d <= 2.0 for d in da) and len(set(da)) == 20
    other: DelayedReplies[str, int] = DelayedReplies(2.0, seed=6)
    assert [other.hold("q", 0, 0.0) for _ in range(20)] != da
    assert a.next_due() == pytest.approx(10.0 + min(da))
    early = a.due(10.0 + 1.0)
    assert [m for _, m in early] == sorted(
        (i for i in range(20) if da[i] <= 1.0), key=da.__getitem__
    )
    rest = a.take_all()
    assert len(early) + len(rest) == 20 and len(a) == 0 and a.next_due() is None
    assert a.held == 20
    for bad in (-0.1, float("nan"), float("inf"), MAX_REPLY_DELAY_S + 1):
        with pytest.raises(ValueError, match="reply delay"):
            DelayedReplies(bad, 0)


@pytest.mark.parametrize("bad", ["-1", "nan", "11"])
def test_bad_reply_delay_is_a_usage_error(bad: str, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["--robots", "2", "--reply-delay", bad, "--insecure"]) == 2
    assert "reply delay" in capsys.readouterr().err


@pytest.fixture()
def slow_world() -> Iterator[Any]:
    """A real world (2 robots) served by its loop in a thread, replies held up to 0.6 s;
    queries are handed to it as the zenoh callbacks would (no session)."""
    from sim.physics.world import World
    from sim.server.server import WorldServer

    log = type("Log", (), {"write": lambda self, t: None, "flush": lambda self: None})()
    with World(scenarios.generate(2, 3)) as world:
        server = WorldServer(world, reply_delay=0.6, reply_delay_seed=3, log=log)
        server._publish_truth = lambda: None  # type: ignore[method-assign]  # no session
        loop = threading.Thread(target=server.serve, daemon=True)
        loop.start()
        try:
            yield server
        finally:
            server.stop()
            loop.join(timeout=10.0)
            server.close()


def test_a_slow_world_holds_camera_and_motion_replies_and_keeps_serving(slow_world: Any) -> None:
    # the delays the world will draw, in the order its replies are made (camera, then turn)
    expect: DelayedReplies[int, int] = DelayedReplies(0.6, seed=3)
    want = [expect.hold(0, 0, 0.0) for _ in range(2)]
    assert min(want) > 0.5  # seed 3: long enough to see the world serve meanwhile
    t0 = time.monotonic()
    cam = TimedQuery(key_camera(1), CameraRequest(yaw=0.0))
    slow_world.admit("camera", cam)
    held_by(slow_world, 1)
    reg = TimedQuery(KEY_WORLD_REGISTER, RegisterRequest(want=1))
    t_ask = time.monotonic()
    slow_world.admit("register", reg)  # not a camera or motion reply: answered at once
    assert reg.got.wait(5.0)
    t_turn_ask = time.monotonic()
    turn = TimedQuery(key_turn(2), TurnRequest(angle=0.05))
    slow_world.admit("turn", turn)
    assert cam.got.wait(10.0) and turn.got.wait(10.0)
    (t_reg, r_reg), (t_cam, r_cam) = reg.replies[0], cam.replies[0]
    t_turn, r_turn = turn.replies[0]
    assert isinstance(r_reg, RegisterReply) and r_reg.robot_id == 1
    assert isinstance(r_cam, CameraReply) and r_cam.robot_id == 1
    assert isinstance(r_turn, CommandReply) and r_turn.status == "done"
    assert t_reg - t_ask < 0.3 and t_reg < t_cam  # served while the picture was held
    assert want[0] - 0.02 <= t_cam - t0 <= want[0] + 2.0
    assert want[1] - 0.02 <= t_turn - t_turn_ask <= want[1] + 2.0
    assert slow_world.delays.held == 2 and len(slow_world.delays) == 0


def held_by(server: Any, n: int) -> None:
    """Wait (at most 5 s) until ``server`` holds ``n`` replies."""
    end = time.monotonic() + 5.0
    while len(server.delays) < n and time.monotonic() < end:
        time.sleep(0.01)  # polling the world loop's state, bounded
    assert len(server.delays) == n


def test_held_replies_go_out_when_the_world_closes(slow_world: Any) -> None:
    slow_world.delays.max_s = 9.0  # far later than the test waits
    cam = TimedQuery(key_camera(2), CameraRequest(yaw=0.0))
    slow_world.admit("camera", cam)
    held_by(slow_world, 1)
    assert not cam.replies
    slow_world.stop()
    time.sleep(0.2)
    slow_world.close()
    assert isinstance(cam.replies[0][1], CameraReply)
