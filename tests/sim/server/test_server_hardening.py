"""The world server's callbacks hardened, without zenoh (sim/server/server.py): fake queries
through the checks and the bounded inbox; motion request ids executed once."""

from __future__ import annotations

from typing import Any

import msgpack
import pytest
import zenoh

from agent.wire import (
    KEY_WORLD_REGISTER,
    CameraRequest,
    CommandReply,
    ErrorReply,
    TurnRequest,
    WalkRequest,
    decode,
    encode,
    key_camera,
    key_turn,
    key_walk,
)
from tests.fakes import FakeZBytes


def _bad(version: int = 1, **fields: Any) -> bytes:
    return bytes(msgpack.packb({"v": version, **fields}))


class FakeQuery:
    def __init__(self, key: str, payload: bytes | FakeZBytes | None, params: str = "") -> None:
        self.key_expr = key
        self.payload = FakeZBytes(len(payload), payload) if isinstance(payload, bytes) else payload
        self.parameters = dict(kv.split("=", 1) for kv in params.split("&") if kv)
        self.replies: list[Any] = []

    def reply(self, key: str, data: bytes) -> None:
        self.replies.append(decode(data))

    def drop(self) -> None:
        pass


class Exploding:
    """A query whose every attribute raises: the callback must still survive."""

    def __getattr__(self, name: str) -> Any:
        raise RuntimeError(f"no {name}")


@pytest.fixture()
def server() -> Any:
    from types import SimpleNamespace

    from sim.server.server import WorldServer

    world = SimpleNamespace(robot_ids=(1, 2, 3), t_sim=0.0)
    log = SimpleNamespace(lines=[], write=lambda t: log.lines.append(t), flush=lambda: None)
    # free looks: a camera request is drawn at once (looks on the clock: test_glances.py)
    srv = WorldServer(world, free_looks=True, log=log)  # type: ignore[arg-type]
    srv.log_lines = log.lines
    return srv


@pytest.mark.parametrize(
    ("kind", "key", "payload", "reason"),
    [
        ("camera", key_camera(3), FakeZBytes(2 * 2**20), "exceeds 1024"),  # never copied
        ("camera", key_camera(3), b"\xc1", "not msgpack"),
        ("camera", key_camera(9), encode(CameraRequest(yaw=0.0)), "unknown robot 9"),
        ("camera", "world/robot/03/camera", encode(CameraRequest(yaw=0.0)), "robot id"),
        ("camera", key_camera(3), encode(CameraRequest(yaw=3.0)), "outside"),
        ("camera", key_camera(3), _bad(version=True, t="camera", yaw=0.0), "schema version"),
        ("walk", key_walk(3), None, "missing"),
        ("walk", key_walk(3), encode(TurnRequest(angle=0.1)), "expected a 'walk'"),
        ("turn", key_turn(3), b"\x91" * 20 + b"\x90", "nested deeper"),
        ("register", KEY_WORLD_REGISTER, _bad(t="register", want=True), "expected int"),
    ],
)
def test_malformed_requests_are_sorted_out_in_the_callback(
    server: Any, kind: str, key: str, payload: Any, reason: str
) -> None:
    q = FakeQuery(key, payload)
    server.admit(kind, q)
    assert server.inbox.lengths()["malformed"] == 1 and server.rejected == 1
    server._drain(block=False)
    (rep,) = q.replies
    assert isinstance(rep, ErrorReply) and reason in rep.reason
    assert server.errors == 1


def test_huge_malformed_requests_cannot_pile_up(server: Any) -> None:
    from sim.server.server import MALFORMED_MAX_BYTES

    alone = FakeQuery(key_camera(3), FakeZBytes(MALFORMED_MAX_BYTES + 1))
    server.admit("camera", alone)  # heavier than the whole lane: dropped unanswered
    assert server.inbox.lengths()["malformed"] == 0 and server.dropped == 1
    big = [FakeQuery(key_camera(3), FakeZBytes(4 * 2**20)) for _ in range(10)]
    for q in big:
        server.admit("camera", q)
    assert server.inbox.lengths()["malformed"] == 4 and server.dropped == 7
    server._drain(block=False)
    assert [len(q.replies) for q in big] == [0] * 6 + [1] * 4  # the newest are answered
    assert server.rejected == 11


def test_camera_yaw_parameter_checked_in_the_callback(server: Any) -> None:
    for params, reason in (("yaw=abc", "not a number"), ("yaw=" + "1" * 100, "100 characters")):
        q = FakeQuery(key_camera(3), None, params)
        server.admit("camera", q)
        server._drain(block=False)
        assert reason in q.replies[0].reason


def test_a_callback_survives_a_query_that_explodes(server: Any) -> None:
    server.admit("camera", Exploding())
    server.admit_alive(Exploding())
    assert server.rejected == 2
    assert server.inbox.lengths()["malformed"] == 1  # answered "internal: ..." if possible
    server._drain(block=False)  # the reply fails too: counted, logged, the loop goes on
    assert any("reply failed: RuntimeError: no reply" in line for line in server.log_lines)
    assert server.rejected == 2


def test_a_flood_of_malformed_requests_is_bounded_and_cannot_delay_a_valid_one(
    server: Any,
) -> None:
    from sim.server.server import INBOX_CAPS

    first = [FakeQuery(key_camera(3), b"garbage") for _ in range(10)]
    for q in first:
        server.admit("camera", q)
    valid = FakeQuery(key_walk(3), encode(WalkRequest(distance=0.1)))
    server.admit("walk", valid)
    for _ in range(3000):
        server.admit("camera", FakeQuery(key_camera(3), b"garbage"))
    cap = INBOX_CAPS["malformed"]
    assert server.inbox.lengths() == {"rendered": 0, "alive": 0, "valid": 1, "malformed": cap}
    assert server.dropped == 3010 - cap
    assert all(q.replies == [] for q in first)  # the oldest garbage went first
    lane, req = server.inbox.get_nowait()  # the valid request is served first
    assert lane == "valid" and req.msg == WalkRequest(distance=0.1)
    # the log is rate limited: far fewer lines than rejected inputs
    assert server.rejected == 3010 and len(server.log_lines) < 50


def test_liveliness_of_non_robots_keeps_no_state(server: Any) -> None:
    from types import SimpleNamespace

    for key in ("nao/alive/2", "nao/alive/500", "nao/alive/02"):
        server.admit_alive(SimpleNamespace(key_expr=key, kind=zenoh.SampleKind.PUT))
    assert server.rejected == 1  # the alias 02
    server._drain(block=False)
    assert server.bindings.alive == {2}
    server.admit_alive(SimpleNamespace(key_expr="nao/alive/2", kind=zenoh.SampleKind.DELETE))
    server._drain(block=False)
    assert server.bindings.alive == set()


class FakeLegs:
    """Locomotion that records what it was told and finishes only when told to."""

    def __init__(self) -> None:
        self.started: list[tuple[str, int, float]] = []
        self.moving: set[int] = set()

    def walk(self, rid: int, d: float) -> None:
        self.started.append(("walk", rid, d))
        self.moving.add(rid)

    def turn(self, rid: int, a: float) -> None:
        self.started.append(("turn", rid, a))
        self.moving.add(rid)

    def busy(self, rid: int) -> bool:
        return rid in self.moving


@pytest.fixture()
def legs(server: Any) -> FakeLegs:
    legs = FakeLegs()
    server.world.locomotion = legs
    server._publish_truth = lambda: None
    return legs


def _ask(server: Any, kind: str, msg: Any, rid: int = 3) -> FakeQuery:
    q = FakeQuery(f"world/robot/{rid}/{kind}", encode(msg))
    server.admit(kind, q)
    server._drain(block=False)
    return q


def _finish(server: Any, legs: FakeLegs, rid: int, kind: str, t: float) -> None:
    from sim.physics.locomotion import Done

    legs.moving.discard(rid)
    server._finish([Done(rid, kind, "done", t)], [])


def test_a_motion_request_id_is_executed_once_and_a_repeat_gets_the_first_result(
    server: Any, legs: FakeLegs
) -> None:
    first = _ask(server, "walk", WalkRequest(distance=0.2, request_id=7))
    again = _ask(server, "walk", WalkRequest(distance=0.2, request_id=7))  # while it runs
    assert legs.started == [("walk", 3, 0.2)] and first.replies == again.replies == []
    _finish(server, legs, 3, "walk", 1.5)
    want = CommandReply(robot_id=3, status="done", t_sim=1.5)
    assert first.replies == again.replies == [want]
    late = _ask(server, "walk", WalkRequest(distance=0.2, request_id=7))  # after it ended
    assert late.replies == [want] and legs.started == [("walk", 3, 0.2)]
    assert server.motions.repeats == 2
    other = _ask(server, "walk", WalkRequest(distance=0.2, request_id=7), rid=2)  # per robot
    assert legs.started[-1] == ("walk", 2, 0.2) and other.replies == []


def test_without_a_request_id_every_motion_is_executed(server: Any, legs: FakeLegs) -> None:
    for t in (1.0, 2.0):
        q = _ask(server, "turn", TurnRequest(angle=0.1))
        _finish(server, legs, 3, "turn", t)
        assert q.replies == [CommandReply(robot_id=3, status="done", t_sim=t)]
    assert len(legs.started) == 2 and server.motions.repeats == 0


def test_a_request_id_reused_for_another_motion_is_refused(server: Any, legs: FakeLegs) -> None:
    _ask(server, "turn", TurnRequest(angle=0.1, request_id=9))
    running = _ask(server, "walk", WalkRequest(distance=0.1, request_id=9))
    assert "was a turn, not a walk" in running.replies[0].reason
    _finish(server, legs, 3, "turn", 1.0)
    done = _ask(server, "walk", WalkRequest(distance=0.1, request_id=9))
    assert "was a turn, not a walk" in done.replies[0].reason
    assert len(legs.started) == 1


def test_the_motion_cache_is_bounded_per_robot(server: Any, legs: FakeLegs) -> None:
    from sim.server.server import MOTION_CACHE

    for i in range(1, MOTION_CACHE + 2):
        _ask(server, "turn", TurnRequest(angle=0.1, request_id=i))
        _finish(server, legs, 3, "turn", float(i))
    assert len(server.motions.results[3]) == MOTION_CACHE
    _ask(server, "turn", TurnRequest(angle=0.1, request_id=1))  # forgotten: executed again
    assert len(legs.started) == MOTION_CACHE + 2


def test_a_full_render_queue_answers_busy(server: Any) -> None:
    """With every render slot taken the world draws nothing and says so with
    agent.wire.BUSY first, so that the robot asks again later (agent.net.bus.Busy)."""
    from types import SimpleNamespace

    from agent.wire import BUSY

    server.cameras.pool = SimpleNamespace(alive=1)
    cap = server.cameras.pending.capacity
    for job in range(cap):  # every slot taken (by ids outside the world: a flood)
        server.cameras.pending.add(job, None, 100 + job, 0.0, 0.0)
    q = FakeQuery(key_camera(3), encode(CameraRequest(yaw=0.0)))
    server.admit("camera", q)
    server._drain(block=False)
    (rep,) = q.replies
    assert isinstance(rep, ErrorReply)
    assert rep.reason == f"{BUSY}: {cap} pictures being drawn"
    assert server.errors == 1


def test_a_repeated_camera_query_is_answered_by_the_picture_in_the_works(server: Any) -> None:
    """At 100 NAOs: a robot that asks again while its picture is drawn gets that
    picture, once; no second job is queued; at another yaw it is told the world is busy."""
    from types import SimpleNamespace

    from agent.wire import BUSY, CameraReply
    from sim.server.render_pool import Result

    jobs: list[Any] = []
    server.cameras.pool = SimpleNamespace(alive=1, submit=jobs.append, worker_done=lambda r: None)
    server.world.set_head_yaw = lambda rid, yaw: None
    server.world.next_shot = lambda rid, yaw: None
    server.world.poses = dict
    server.world.head_yaw = lambda rid: 0.0
    first, again, other = (
        FakeQuery(key_camera(3), encode(CameraRequest(yaw=y))) for y in (0.5, 0.5, -0.5)
    )
    for q in (first, again, other):
        server.admit("camera", q)
        server._drain(block=False)
    assert len(jobs) == 1 and len(server.cameras.pending) == 1
    (gone,) = first.replies
    assert isinstance(gone, ErrorReply) and "superseded" in gone.reason
    (busy,) = other.replies
    assert isinstance(busy, ErrorReply) and busy.reason.startswith(BUSY)
    server.cameras.rendered(Result(jobs[0].job_id, 0, data=b"picture"))
    (pic,) = again.replies
    assert isinstance(pic, CameraReply) and pic.robot_id == 3 and pic.yaw == 0.5
    assert len(server.cameras.pending) == 0 and len(first.replies) == 1
