"""sim/server/render_worker.py without zenoh: shards, the camera queries it takes, answers and
refuses, the poses it follows; and the world's scenario queryable (sim/server/server.py)."""

from __future__ import annotations

import json
from collections.abc import Iterator
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import numpy as np
import pytest

from agent.wire import (
    KEY_WORLD_SCENARIO,
    KEY_WORLD_TRUTH_POSES,
    CameraReply,
    CameraRequest,
    ErrorReply,
    NetworkSpec,
    ScenarioReply,
    ScenarioRequest,
    TruthPosesMsg,
    encode,
    key_camera,
    trust,
)
from agent.wire.picture import picture_of
from sim import scenarios
from sim.physics.world import World
from sim.server.render_worker import RenderWorker, parse_shard, shard_robots
from tests.fakes import zb
from tests.sim.server.test_server_hardening import Exploding, FakeQuery

SCENARIO = scenarios.generate(3, 7)


class FakeSession:
    """Records what a worker declares; hands its callbacks to the test."""

    def __init__(self) -> None:
        self.queryables: dict[str, tuple[Any, bool]] = {}
        self.subscribers: dict[str, Any] = {}

    def declare_queryable(self, key: str, cb: Any, complete: bool = False) -> Any:
        self.queryables[key] = (cb, complete)
        return SimpleNamespace(undeclare=lambda: None)

    def declare_subscriber(self, key: str, cb: Any) -> Any:
        self.subscribers[key] = cb
        return SimpleNamespace(undeclare=lambda: None)


@pytest.fixture(scope="module")
def room() -> Iterator[World]:
    with World(SCENARIO, noise=False) as w:
        yield w


def worker(room: World, robots: tuple[int, ...] = (1, 2, 3), spec: Any = None) -> RenderWorker:
    w = RenderWorker(room, robots, spec or NetworkSpec(), FakeSession())
    w.follow()
    return w


def poses_msg(t: float, moved: float = 0.0) -> TruthPosesMsg:
    return TruthPosesMsg(
        t_sim=t, poses=tuple((r.id, r.x + moved, r.y, r.heading) for r in SCENARIO.robots)
    )


def publish(w: RenderWorker, data: bytes) -> None:
    w.session.subscribers[KEY_WORLD_TRUTH_POSES](SimpleNamespace(payload=zb(data)))


def ask(w: RenderWorker, rid: int, payload: bytes | None) -> FakeQuery:
    q = FakeQuery(key_camera(rid), payload)
    w.admit(q)
    w.drain()
    return q


# --------------------------------------------------------------------------- shards


def test_shards_split_the_sorted_robots() -> None:
    assert parse_shard("1/1") == (1, 1) and parse_shard("2/3") == (2, 3)
    for bad in ("0/2", "3/2", "1", "a/b", "1/65", "-1/2"):
        with pytest.raises(ValueError, match="I/K"):
            parse_shard(bad)
    ids = [5, 1, 3, 2, 4]
    assert shard_robots(ids, (1, 2)) == (1, 3, 5)
    assert shard_robots(ids, (2, 2)) == (2, 4)
    assert shard_robots(ids, (1, 1)) == (1, 2, 3, 4, 5)
    assert shard_robots([1, 2], (3, 3)) == ()


def test_a_worker_declares_complete_queryables_for_its_robots_only(room: World) -> None:
    w = worker(room, (1, 3))
    w.declare()
    assert w.session.queryables.keys() == {key_camera(1), key_camera(3)}
    assert all(complete for _, complete in w.session.queryables.values())


# --------------------------------------------------------------------------- pictures


def test_a_picture_is_the_worlds_at_the_poses_it_follows(room: World) -> None:
    w = worker(room)
    publish(w, encode(poses_msg(4.5, moved=0.1)))
    (rep,) = ask(w, 2, encode(CameraRequest(yaw=0.4))).replies
    assert isinstance(rep, CameraReply)
    assert rep.t_sim == 4.5 and rep.robot_id == 2 and rep.yaw == pytest.approx(0.4)
    with World(SCENARIO, noise=False) as ref:  # the world's own picture at those poses
        for rid, x, y, th in poses_msg(4.5, moved=0.1).poses:
            ref.set_pose(rid, x, y, th)
        want = ref.render(2, 0.4)
    got = picture_of(rep.encoding, rep.width, rep.height, rep.data)
    assert np.array_equal(got, want)
    assert w.served == 1 and w.t_poses == 4.5


def test_newer_poses_are_applied_before_the_next_picture(room: World) -> None:
    w = worker(room)
    publish(w, encode(poses_msg(1.0)))
    ask(w, 1, encode(CameraRequest()))
    publish(w, encode(poses_msg(2.0, moved=0.2)))
    (rep,) = ask(w, 1, encode(CameraRequest())).replies
    assert rep.t_sim == 2.0
    assert room.pose(3)[0] == pytest.approx(SCENARIO.robots[2].x + 0.2)


@pytest.mark.parametrize(
    ("rid", "payload", "reason"),
    [
        (2, encode(CameraRequest(yaw=0.0)), "unknown robot 2"),  # not of this shard
        (1, encode(CameraRequest(yaw=3.0)), "outside"),
        (1, b"\xc1", "not msgpack"),
        (1, encode(ScenarioRequest()), "expected a 'camera'"),
    ],
)
def test_bad_requests_get_a_reason_and_the_worker_serves_on(
    room: World, rid: int, payload: bytes, reason: str
) -> None:
    w = worker(room, (1, 3))
    publish(w, encode(poses_msg(0.0)))
    (rep,) = ask(w, rid, payload).replies
    assert isinstance(rep, ErrorReply) and reason in rep.reason
    assert w.errors == 1 and w.guard.rejected == 1
    (ok,) = ask(w, 1, encode(CameraRequest())).replies
    assert isinstance(ok, CameraReply)


def test_a_callback_survives_a_query_that_explodes(room: World) -> None:
    w = worker(room)
    w.admit(Exploding())  # type: ignore[arg-type]
    assert w.drain() == 0 and w.guard.rejected == 1


def test_undecodable_poses_are_refused_and_the_last_good_ones_kept(room: World) -> None:
    w = worker(room)
    publish(w, encode(poses_msg(3.0)))
    publish(w, b"\xc1")
    publish(w, encode(ScenarioRequest()))
    assert w.poses.received == 1 and w.guard.rejected == 2
    latest = w.poses.latest()
    assert latest is not None and latest.t_sim == 3.0


# --------------------------------------------------------------------------- secure


@pytest.fixture(scope="module")
def fleet(tmp_path_factory: pytest.TempPathFactory) -> trust.Credentials:
    root = tmp_path_factory.mktemp("fleet") / "f"
    trust.create_fleet(root, [1, 2, 3])
    return trust.Credentials(root)


def secure(fleet: trust.Credentials) -> NetworkSpec:
    return NetworkSpec(
        connect=("tls/127.0.0.1:1",),
        mode="client",
        credentials=str(fleet.root),
        identity="render",
    )


def sealed_ask(w: RenderWorker, fleet: trust.Credentials, who: str, rid: int) -> FakeQuery:
    signer = fleet.signer(trust.Identity.parse(who))
    data, nonce = signer.seal_request(key_camera(rid), encode(CameraRequest()))
    q = FakeQuery(key_camera(rid), data)
    q.nonce = nonce  # type: ignore[attr-defined]
    q.reply = lambda key, data: q.replies.append(data)  # type: ignore[method-assign]
    w.admit(q)
    w.drain()
    return q


def test_secure_a_robot_sees_its_own_camera_only_and_replies_are_signed(
    room: World, fleet: trust.Credentials
) -> None:
    w = worker(room, spec=secure(fleet))
    world = fleet.signer(trust.Identity("world"))
    publish(w, world.seal(KEY_WORLD_TRUTH_POSES, encode(poses_msg(1.5))))
    q = sealed_ask(w, fleet, "robot-2", 2)
    (sealed,) = q.replies
    opened = fleet.verifier().open(key_camera(2), sealed, bind=q.nonce, replay=False)  # type: ignore[attr-defined]
    assert opened.who == trust.Identity("render")
    (refused,) = sealed_ask(w, fleet, "robot-1", 2).replies
    assert b"may not see robot 2" in refused
    assert w.untrusted == 1 and w.served == 1
    unsigned = ask(w, 2, encode(CameraRequest()))
    assert unsigned.replies == [] and w.untrusted == 2  # no answer to a stranger


def test_secure_poses_are_taken_from_the_world_only(room: World, fleet: trust.Credentials) -> None:
    w = worker(room, spec=secure(fleet))
    robot = fleet.signer(trust.Identity.robot(1))
    publish(w, robot.seal(KEY_WORLD_TRUTH_POSES, encode(poses_msg(9.0))))
    publish(w, encode(poses_msg(9.0)))  # unsigned
    assert w.poses.received == 0 and w.guard.rejected == 2


# --------------------------------------------------------------------------- the world


def test_the_world_hands_out_its_scenario(tmp_path: Path) -> None:
    from sim.server.server import WorldServer

    world = SimpleNamespace(robot_ids=(1, 2, 3), t_sim=0.0, scenario=SCENARIO)
    log = SimpleNamespace(write=lambda t: None, flush=lambda: None)
    srv = WorldServer(world, log=log)  # type: ignore[arg-type]
    for payload in (None, encode(ScenarioRequest())):
        q = FakeQuery(KEY_WORLD_SCENARIO, payload)
        srv.admit("scenario", q)
        srv._drain(block=False)
        (rep,) = q.replies
        assert isinstance(rep, ScenarioReply)
        assert scenarios.from_dict(json.loads(rep.scenario)) == SCENARIO
    q = FakeQuery(KEY_WORLD_SCENARIO, encode(CameraRequest()))
    srv.admit("scenario", q)
    srv._drain(block=False)
    assert isinstance(q.replies[0], ErrorReply)


def test_a_world_or_worker_with_an_unknown_camera_encoding_refuses_to_start(room: World) -> None:
    from sim.server.server import WorldServer

    world = SimpleNamespace(robot_ids=(1, 2, 3), t_sim=0.0, scenario=SCENARIO)
    with pytest.raises(ValueError, match="camera encoding 'jpeg' not one of"):
        WorldServer(world, camera_encoding="jpeg")  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="camera encoding 'jpeg' not one of"):
        RenderWorker(room, (1,), NetworkSpec(), FakeSession(), encoding="jpeg")


def test_a_worker_draws_png_when_asked(room: World) -> None:
    w = RenderWorker(room, (1, 2, 3), NetworkSpec(), FakeSession(), encoding="png")
    w.follow()
    publish(w, encode(poses_msg(2.0)))
    (rep,) = ask(w, 1, encode(CameraRequest(yaw=0.0))).replies
    assert isinstance(rep, CameraReply) and rep.encoding == "png"
    assert rep.data[:4] == b"\x89PNG"
    assert picture_of("png", rep.width, rep.height, rep.data).shape == (480, 640, 3)
