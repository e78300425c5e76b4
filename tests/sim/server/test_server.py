"""The world over a real zenoh session on loopback (sim/server/server.py, python -m sim)."""

from __future__ import annotations

import json
import math
import queue
import subprocess
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import cv2
import msgpack
import numpy as np
import pytest
import zenoh

from agent.wire import (
    KEY_WORLD_REGISTER,
    CameraReply,
    CameraRequest,
    ClockMsg,
    CommandReply,
    ContactMsg,
    ErrorReply,
    RegisterReply,
    RegisterRequest,
    TruthPosesMsg,
    TurnRequest,
    WalkRequest,
    decode,
    encode,
    key_camera,
    key_turn,
    key_walk,
)
from agent.wire.picture import picture_of
from sim import scenarios
from sim.physics.locomotion import DT
from sim.server.glances import LookTiming
from tools.harness.procs import free_port, start_world, stop, wait_ready

pytestmark = pytest.mark.system
NORTH = math.pi / 2


def png(data: bytes) -> np.ndarray:
    """The picture of a PNG file's bytes (what ``sim.server.client camera`` writes)."""
    img = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_COLOR)
    assert img is not None, "not a PNG"
    return img


class Client:
    def __init__(self, endpoint: str) -> None:
        cfg = zenoh.Config()
        cfg.insert_json5("connect/endpoints", json.dumps([endpoint]))
        cfg.insert_json5("scouting/multicast/enabled", "false")
        self.session = zenoh.open(cfg)
        self.samples: queue.Queue[Any] = queue.Queue()
        self.truth: list[TruthPosesMsg] = []
        self.contacts: list[ContactMsg] = []
        self.clock: list[ClockMsg] = []
        self._lock = threading.Lock()

        def on_sample(s: zenoh.Sample) -> None:
            self.samples.put(s.payload.to_bytes())

        self._sub = self.session.declare_subscriber("world/**", on_sample)

    def pump(self) -> None:
        while True:
            try:
                m = decode(self.samples.get_nowait())
            except queue.Empty:
                return
            if isinstance(m, TruthPosesMsg):
                self.truth.append(m)
            elif isinstance(m, ContactMsg):
                self.contacts.append(m)
            elif isinstance(m, ClockMsg):
                self.clock.append(m)

    def raw(self, key: str, payload: bytes | None, timeout: float = 20.0) -> Any:
        replies = self.session.get(key, payload=payload, timeout=timeout)
        for r in replies:
            assert r.ok is not None, "the world must answer with an ok reply"
            return decode(r.ok.payload.to_bytes())
        raise AssertionError(f"no reply on {key}")

    def ask(self, key: str, msg: Any, timeout: float = 20.0) -> Any:
        return self.raw(key, encode(msg), timeout)

    def close(self) -> None:
        self._sub.undeclare()
        self.session.close()


@pytest.fixture(
    scope="module",
    params=[(0, "bgr8"), (2, "png")],
    ids=["render-in-process-bgr8", "render-workers-2-png"],
)
def world(
    request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory
) -> Iterator[tuple[subprocess.Popen[bytes], str, str]]:
    # The whole module runs twice: camera images rendered by the world process itself and
    # carried as raw pixels (the defaults), and rendered by a pool of two render workers
    # and carried as PNG (python -m sim --render-workers 2 --camera-encoding png).
    # Robots 1 and 2 face each other 0.7 m apart (contact test); robot 3 stands apart.
    sc = scenarios.Scenario(
        robots=(
            scenarios.RobotSpec(1, 0.0, 0.0, NORTH),
            scenarios.RobotSpec(2, 0.0, 0.7, -NORTH),
            scenarios.RobotSpec(3, 1.5, -1.5, NORTH),
        ),
        seed=4,
        room=3.0,
    )
    path = tmp_path_factory.mktemp("sim") / "scenario.json"
    scenarios.dump(sc, path)
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    workers, encoding = request.param
    extra = ["--scenario", str(path), "--speed", "4", "--render-workers", str(workers)]
    extra += ["--camera-encoding", encoding]
    world = start_world(3, sc.seed, endpoint, path.parent, extra)  # the file sets the robots
    try:
        ready = wait_ready(world, 60.0)
        assert "robots=1,2,3" in ready, f"world did not start: {ready!r}"
        yield world.popen, endpoint, encoding
    finally:
        stop(world, 20.0)


@pytest.fixture(scope="module")
def client(world: tuple[subprocess.Popen[bytes], str, str]) -> Iterator[Client]:
    c = Client(world[1])
    # Poll until the link is up: a register query answered.
    deadline = time.monotonic() + 20.0
    while time.monotonic() < deadline:
        try:
            c.ask(key_camera(3), CameraRequest(yaw=0.0), timeout=2.0)
            break
        except AssertionError:
            time.sleep(0.1)
    yield c
    c.close()


def test_camera_round_trip(world: tuple[subprocess.Popen[bytes], str, str], client: Client) -> None:
    for yaw in (0.0, math.radians(45.0), -math.radians(119.5)):
        rep = client.ask(key_camera(3), CameraRequest(yaw=yaw))
        assert isinstance(rep, CameraReply)
        assert rep.robot_id == 3 and rep.yaw == pytest.approx(yaw)
        assert (rep.width, rep.height, rep.encoding) == (640, 480, world[2])
        img = picture_of(rep.encoding, rep.width, rep.height, rep.data)
        assert img.shape == (480, 640, 3)
        assert img.std() > 10  # a textured room, not a blank picture


def test_a_look_costs_its_robot_the_head_turn_settling_and_capture(client: Client) -> None:
    """The world's clock charges a camera request the time a NAO takes for it
    (sim/server/glances.py): the picture comes at the first clock step past that time."""
    t0 = client.ask(key_camera(3), CameraRequest(yaw=0.0)).t_sim
    rep = client.ask(key_camera(3), CameraRequest(yaw=0.6))
    assert isinstance(rep, CameraReply)
    cost = LookTiming().cost(0.0, 0.6)
    assert cost - 1e-6 <= rep.t_sim - t0 < cost + DT + 1e-6


def test_camera_yaw_as_selector_parameter(client: Client) -> None:
    rep = client.raw(key_camera(3) + "?yaw=0.5", None)
    assert isinstance(rep, CameraReply) and rep.yaw == pytest.approx(0.5)
    rep = client.raw(key_camera(3) + "?yaw=abc", None)
    assert isinstance(rep, ErrorReply) and "not a number" in rep.reason


def test_robot_1_sees_robot_2(client: Client) -> None:
    rep = client.ask(key_camera(1), CameraRequest(yaw=0.0))
    img = picture_of(rep.encoding, rep.width, rep.height, rep.data)
    mask = cv2.inRange(cv2.cvtColor(img, cv2.COLOR_BGR2HSV), (2, 170, 50), (10, 255, 255))
    n, _, stats, _ = cv2.connectedComponentsWithStats(mask)
    assert sum(1 for i in range(1, n) if stats[i][4] > 30) == 3


def _bad(version: int = 1, **fields: Any) -> bytes:
    return bytes(msgpack.packb({"v": version, **fields}))


@pytest.mark.parametrize(
    ("key", "payload", "reason"),
    [
        (key_camera(3), encode(CameraRequest(yaw=math.radians(120.0))), "outside"),
        (key_camera(3), _bad(t="camera", yaw=float("nan")), "not finite"),
        (key_camera(3), _bad(version=9, t="camera", yaw=0.0), "schema version"),
        (key_camera(3), b"\xc1garbage", "not msgpack"),
        (key_camera(3), encode(WalkRequest(distance=0.1)), "expected a 'camera'"),
        (key_camera(9), encode(CameraRequest(yaw=0.0)), "unknown robot 9"),
        ("world/robot/abc/camera", encode(CameraRequest(yaw=0.0)), "not a non-negative"),
        (key_walk(3), _bad(t="walk", distance=float("nan")), "not finite"),
        (key_walk(3), encode(WalkRequest(distance=80.0)), "exceeds"),
        (key_walk(3), None, "missing"),
        (key_walk(3), _bad(t="walk", distance="far"), "expected a number"),
        (key_turn(3), _bad(t="turn", angle=float("inf")), "not finite"),
        (key_turn(3), encode(TurnRequest(angle=100.0)), "exceeds"),
        (key_turn(7), encode(TurnRequest(angle=0.1)), "unknown robot 7"),
        (KEY_WORLD_REGISTER, encode(RegisterRequest(want=42)), "not in this world"),
        (KEY_WORLD_REGISTER, _bad(t="register", want="x"), "expected int"),
    ],
)
def test_bad_requests_get_a_reason_and_the_world_keeps_serving(
    client: Client, key: str, payload: bytes | None, reason: str
) -> None:
    rep = client.raw(key, payload)
    assert isinstance(rep, ErrorReply)
    assert reason in rep.reason
    ok = client.ask(key_camera(3), CameraRequest(yaw=0.0))
    assert isinstance(ok, CameraReply)


def test_register_hands_out_free_ids(client: Client) -> None:
    assert client.ask(KEY_WORLD_REGISTER, RegisterRequest(want=2)) == RegisterReply(robot_id=2)
    rep = client.ask(KEY_WORLD_REGISTER, RegisterRequest(want=2))
    assert isinstance(rep, ErrorReply) and "already claimed" in rep.reason
    assert client.ask(KEY_WORLD_REGISTER, RegisterRequest()) == RegisterReply(robot_id=1)
    assert client.ask(KEY_WORLD_REGISTER, RegisterRequest()) == RegisterReply(robot_id=3)
    rep = client.ask(KEY_WORLD_REGISTER, RegisterRequest())
    assert isinstance(rep, ErrorReply) and "every robot is claimed" in rep.reason


def _register_until(client: Client, want: int, done: Any) -> Any:
    deadline = time.monotonic() + 10.0
    rep = None
    while time.monotonic() < deadline:
        rep = client.ask(KEY_WORLD_REGISTER, RegisterRequest(want=want))
        if done(rep):
            break
        time.sleep(0.05)
    return rep


def test_claim_is_released_when_the_agent_token_goes(client: Client) -> None:
    # After test_register_hands_out_free_ids every robot is claimed.
    rep = client.ask(KEY_WORLD_REGISTER, RegisterRequest(want=1))
    assert isinstance(rep, ErrorReply) and "already claimed" in rep.reason
    token = client.session.liveliness().declare_token("nao/alive/1")
    token.undeclare()
    rep = _register_until(client, 1, lambda r: isinstance(r, RegisterReply))
    assert rep == RegisterReply(robot_id=1)


def test_a_live_agent_token_takes_its_id(client: Client) -> None:
    # Robot 3 is claimed; its agent leaves, and one started with a fixed --id 3 comes.
    gone = client.session.liveliness().declare_token("nao/alive/3")
    gone.undeclare()
    fixed = client.session.liveliness().declare_token("nao/alive/3")
    rep = _register_until(client, 3, lambda r: isinstance(r, ErrorReply) and "live" in r.reason)
    assert isinstance(rep, ErrorReply) and "driven by a live agent" in rep.reason
    fixed.undeclare()
    rep = _register_until(client, 3, lambda r: isinstance(r, RegisterReply))
    assert rep == RegisterReply(robot_id=3)


def test_walk_1m_in_20cm_steps_and_read_the_truth(client: Client) -> None:
    client.pump()
    x0, y0, _ = next(p[1:] for p in client.truth[-1].poses if p[0] == 3)
    t_prev = 0.0
    for _ in range(5):
        rep = client.ask(key_walk(3), WalkRequest(distance=0.2), timeout=30.0)
        assert isinstance(rep, CommandReply) and rep.status == "done" and rep.robot_id == 3
        assert rep.t_sim > t_prev
        t_prev = rep.t_sim
    deadline = time.monotonic() + 10.0
    pose = None
    while time.monotonic() < deadline:
        client.pump()
        if client.truth and client.truth[-1].t_sim >= t_prev:
            pose = next(p[1:] for p in client.truth[-1].poses if p[0] == 3)
            break
        time.sleep(0.05)
    assert pose is not None, "no truth pose after the last step"
    travelled = math.hypot(pose[0] - x0, pose[1] - y0)
    assert 0.85 < travelled < 1.15  # 1 m with the seeded distance/heading noise
    assert client.clock and client.clock[-1].t_sim >= t_prev


def _heading(client: Client, rid: int, since: float) -> float | None:
    """Robot ``rid``'s heading in the latest ground truth, if that is of sim time ``since``
    or later (None: no such truth yet)."""
    client.pump()
    if not client.truth or client.truth[-1].t_sim < since:
        return None
    return next((p[3] for p in client.truth[-1].poses if p[0] == rid), None)


def test_busy_robot_refuses_a_second_motion(client: Client) -> None:
    # A 6 rad turn lasts 10 s of sim time, 2.5 s of wall time at --speed 4. The second
    # request is sent only once the ground truth shows the first one running (robot 3's
    # heading moving), so the order in which the two reach the world is never in doubt.
    # An earlier test of this module may leave robot 3 still moving: wait until a zero
    # turn is accepted (the robot is free) before starting the long one.
    deadline = time.monotonic() + 30.0
    while not isinstance(free := client.ask(key_turn(3), TurnRequest(angle=0.0)), CommandReply):
        assert time.monotonic() < deadline, "robot 3 never became free"
        time.sleep(0.05)
    deadline = time.monotonic() + 10.0
    while (before := _heading(client, 3, free.t_sim)) is None:  # the truth after that turn
        assert time.monotonic() < deadline, "no ground truth of robot 3"
        time.sleep(0.05)
    first = client.session.get(key_turn(3), payload=encode(TurnRequest(angle=6.0)), timeout=60.0)
    deadline = time.monotonic() + 30.0
    while True:  # the truth is published at 10 Hz of wall time, also while robot 3 turns
        now = _heading(client, 3, free.t_sim)
        if now is not None and abs(math.remainder(now - before, math.tau)) > 0.05:
            break
        assert time.monotonic() < deadline, "the first motion never started"
        time.sleep(0.02)
    rep = client.ask(key_walk(3), WalkRequest(distance=0.1))
    assert isinstance(rep, ErrorReply) and "busy" in rep.reason
    done = [decode(r.ok.payload.to_bytes()) for r in first if r.ok is not None]
    assert len(done) == 1 and isinstance(done[0], CommandReply) and done[0].status == "done"


def test_two_robots_walking_into_each_other_get_contact(client: Client) -> None:
    a = client.session.get(key_walk(1), payload=encode(WalkRequest(distance=1.0)), timeout=30.0)
    b = client.session.get(key_walk(2), payload=encode(WalkRequest(distance=1.0)), timeout=30.0)
    ra = [decode(r.ok.payload.to_bytes()) for r in a if r.ok is not None]
    rb = [decode(r.ok.payload.to_bytes()) for r in b if r.ok is not None]
    assert ra[0].status == "contact" and "robot 2" in ra[0].detail
    assert rb[0].status == "contact" and "robot 1" in rb[0].detail
    # One contact if both walks ran together; two if robot 2's request came after robot 1
    # had already bumped into it standing (then robot 2's first step is a contact too).
    deadline = time.monotonic() + 10.0
    while time.monotonic() < deadline:
        client.pump()
        if client.contacts and client.truth and client.truth[-1].contacts == len(client.contacts):
            break
        time.sleep(0.05)
    assert 1 <= len(client.contacts) <= 2
    assert all((c.a, c.b) == (1, 2) for c in client.contacts)
    assert client.truth[-1].contacts == len(client.contacts)


def test_snapshot_joins_a_running_world(
    world: tuple[subprocess.Popen[bytes], str, str], client: Client, tmp_path: Path
) -> None:
    from tools import snapshot

    common = ["--connect", world[1], "--no-multicast-scouting", "--insecure", "--robot", "3"]
    out = tmp_path / "remote.png"
    assert snapshot.main([*common, "--yaw", "10", "--out", str(out)]) == 0
    assert png(out.read_bytes()).shape == (480, 640, 3)
    top = tmp_path / "top.png"
    assert snapshot.main([*common, "--top-down", "--out", str(top)]) == 0
    assert top.stat().st_size > 1000
    assert snapshot.main([*common, "--yaw", "130", "--out", str(tmp_path / "bad.png")]) == 1


def test_client_cli(
    world: tuple[subprocess.Popen[bytes], str, str],
    client: Client,
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
) -> None:
    from sim.server import client as cli

    common = ["--connect", world[1], "--no-multicast-scouting", "--insecure", "--timeout", "30"]
    out = tmp_path / "c.png"
    assert cli.main([*common, "camera", "3", "--yaw", "-30", "--out", str(out)]) == 0
    assert png(out.read_bytes()).shape == (480, 640, 3)
    assert cli.main([*common, "turn", "3", "10", "--times", "2"]) == 0
    text = capsys.readouterr().out
    assert text.count("turn robot 3: done") == 2 and "robot   3:" in text
    assert cli.main([*common, "poses"]) == 0
    assert cli.main([*common, "camera", "3", "--yaw", "150"]) == 1
    assert "outside" in capsys.readouterr().err
    assert cli.main([*common, "walk", "8", "0.2"]) == 1


def test_concurrent_clients_are_all_served(client: Client) -> None:
    # Three robots' worth of traffic at once: camera sweeps and a turn each.
    results: queue.Queue[Any] = queue.Queue()

    def agent(rid: int) -> None:
        try:
            for k in range(3):
                yaw = math.radians(-60.0 + 60.0 * k)
                rep = client.ask(key_camera(rid), CameraRequest(yaw=yaw), timeout=60.0)
                results.put((rid, "camera", isinstance(rep, CameraReply) and rep.robot_id == rid))
            rep = client.ask(key_turn(rid), TurnRequest(angle=0.2), timeout=60.0)
            results.put((rid, "turn", isinstance(rep, CommandReply) and rep.status == "done"))
        except Exception as exc:  # report, do not hang the test
            results.put((rid, "exception", repr(exc)))

    threads = [threading.Thread(target=agent, args=(rid,)) for rid in (1, 2, 3)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(timeout=120.0)
    got = []
    while not results.empty():
        got.append(results.get())
    assert len(got) == 12, got
    assert all(ok is True for _, _, ok in got), got


def test_a_flood_of_malformed_requests_against_the_running_world(client: Client) -> None:
    # 2000 bad requests sent without waiting, then a valid one: it is answered, and the
    # world keeps serving (the timing target is measured by python -m tools.fuzz --flood)
    for i in range(2000):
        key = key_camera(3) if i % 2 else key_walk(9)
        client.session.get(key, handler=lambda r: None, payload=b"\xc1" * (i % 50), timeout=5.0)
    rep = client.ask(key_camera(3), CameraRequest(yaw=0.0), timeout=60.0)
    assert isinstance(rep, CameraReply)
    rep = client.raw(key_camera(3), b"\xc1")
    assert isinstance(rep, ErrorReply) and "not msgpack" in rep.reason
