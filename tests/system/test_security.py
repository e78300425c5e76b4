"""Trust on real zenoh sessions (docs/design.md §8): TLS, access control, signatures.

- A TLS router with the fleet's access control: a stranger cannot open a link; an
  observer's key and robot 1's key cannot publish as robot 2 (records, camera frames);
  robot 2 can.
- The world with credentials over plain links (only the signatures stand): a robot's
  key drives its own robot and no other, a key claims only its own id, unsigned
  requests get no answer, a second session of a claimed key is refused, and replies
  reach only their own request.
- ``tools.demo --rogue``: the rogue's attacks against a 3-robot demo, with TLS (the
  default) and over plain links; the formation is built from exactly the records the
  robots signed, and the rogue moves no robot.
"""

from __future__ import annotations

import json
import queue
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
import zenoh

from agent import wire as P
from agent.net.bus import Bus, BusConfig, BusError, NoRoute
from agent.wire import trust as T
from sim import scenarios
from sim.physics.world import World
from sim.server.server import WorldServer
from tools.harness.procs import free_port

pytestmark = pytest.mark.system
ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def fleet(tmp_path_factory: pytest.TempPathFactory) -> T.Credentials:
    root = tmp_path_factory.mktemp("sec") / "fleet"
    T.create_fleet(root, [1, 2, 3])
    return T.Credentials(root)


def session(spec: P.NetworkSpec) -> zenoh.Session:
    cfg = zenoh.Config()
    for k, v in spec.json5_items():
        cfg.insert_json5(k, v)
    cfg.insert_json5("connect/timeout_ms", "3000")
    return zenoh.open(cfg)


def client(fleet: T.Credentials, ep: str, cn: str) -> P.NetworkSpec:
    return P.NetworkSpec(
        connect=(ep,), multicast_scouting=False, mode="client",
        credentials=str(fleet.root), identity=cn,
    )  # fmt: skip


def test_tls_router_refuses_strangers_and_enforces_roles(fleet: T.Credentials) -> None:
    ep = f"tls/127.0.0.1:{free_port()}"
    router = session(
        P.NetworkSpec(
            listen=(ep,),
            multicast_scouting=False,
            mode="router",
            credentials=str(fleet.root),
            identity="router",
        )
    )
    got: queue.Queue[tuple[str, bytes]] = queue.Queue()
    try:
        # a stranger: no fleet certificate, so no link
        stranger = zenoh.Config()
        stranger.insert_json5("mode", '"client"')
        stranger.insert_json5("connect/endpoints", json.dumps([ep]))
        stranger.insert_json5("scouting/multicast/enabled", "false")
        stranger.insert_json5("connect/timeout_ms", "2000")
        with pytest.raises(Exception, match="Unable to connect"):
            zenoh.open(stranger)
        obs = session(client(fleet, ep, "observer"))  # listens (zenoh delivers a
        rogue = session(client(fleet, ep, "observer"))  # session's own puts locally)
        sub = obs.declare_subscriber("nao/**", lambda s: got.put((str(s.key_expr), b"")))
        r1 = session(client(fleet, ep, "robot-1"))
        r2 = session(client(fleet, ep, "robot-2"))
        forgers = [(r1, "robot-1"), (rogue, "observer")]
        # poll: robot 2's own publication arrives once routes exist; forgeries never do
        deadline = time.monotonic() + 20.0
        seen: set[str] = set()
        while "nao/2/record" not in seen and time.monotonic() < deadline:
            for s, _ in forgers:
                s.put("nao/2/record", b"forged")
            r2.put("nao/2/record", b"genuine")
            r1.put("nao/1/record", b"genuine")
            time.sleep(0.1)  # pacing the puts while polling for delivery, bounded above
            while not got.empty():
                seen.add(got.get()[0])
        assert {"nao/2/record", "nao/1/record"} <= seen
        sub.undeclare()
        got2: queue.Queue[bytes] = queue.Queue()
        sub2 = obs.declare_subscriber("nao/2/record", lambda s: got2.put(s.payload.to_bytes()))
        end = time.monotonic() + 2.0
        while time.monotonic() < end:
            r1.put("nao/2/record", b"forged")
            rogue.put("nao/2/record", b"forged")
            time.sleep(0.05)  # a stream of forgeries for 2 s
        payloads = []
        while not got2.empty():
            payloads.append(got2.get())
        assert b"forged" not in payloads
        sub2.undeclare()
        # camera frames for viewers: robot 2's own reach the observer, robot 1's
        # and the observer's on robot 2's camera key never do
        got3: queue.Queue[bytes] = queue.Queue()
        sub3 = obs.declare_subscriber("nao/2/camera", lambda s: got3.put(s.payload.to_bytes()))
        frames: list[bytes] = []
        end = time.monotonic() + 20.0
        while b"genuine" not in frames and time.monotonic() < end:
            r1.put("nao/2/camera", b"forged")
            rogue.put("nao/2/camera", b"forged")
            r2.put("nao/2/camera", b"genuine")
            time.sleep(0.05)  # pacing the puts while polling for delivery, bounded above
            while not got3.empty():
                frames.append(got3.get())
        assert b"genuine" in frames and b"forged" not in frames
        sub3.undeclare()
        for s in (obs, rogue, r1, r2):
            s.close()
    finally:
        router.close()


# --------------------------------------------------------------------------- the world


@pytest.fixture(scope="module")
def secure_world(fleet: T.Credentials) -> Iterator[tuple[WorldServer, str]]:
    sc = scenarios.generate(3, 5)
    ep = f"tcp/127.0.0.1:{free_port()}"
    net = P.NetworkSpec(
        listen=(ep,), multicast_scouting=False, credentials=str(fleet.root),
        identity="world", tls=False,
    )  # fmt: skip
    with World(sc, noise=False) as world:
        server = WorldServer(world, net)
        server.open()
        import threading

        t = threading.Thread(target=server.serve, daemon=True)
        t.start()
        try:
            yield server, ep
        finally:
            server.stop()
            t.join(10)
            server.close()


def robot_bus(fleet: T.Credentials, ep: str, cn: str) -> Bus:
    return Bus(
        BusConfig(
            connect=(ep,),
            multicast_scouting=False,
            credentials=str(fleet.root),
            identity=cn,
            tls=False,
        )
    )


def ask(bus: Bus, key: str, msg: P.Message, expect: type[Any], timeout: float = 20.0) -> Any:
    """``bus.query``, repeated while no route to the world exists yet (bounded)."""
    end = time.monotonic() + timeout
    while True:
        try:
            return bus.query(key, msg, expect, timeout=timeout)
        except NoRoute:
            if time.monotonic() > end:
                raise
            time.sleep(0.1)  # the fresh session has not learnt the world's route yet


def test_the_world_obeys_each_key_for_its_own_robot_only(
    fleet: T.Credentials, secure_world: tuple[WorldServer, str]
) -> None:
    server, ep = secure_world
    with robot_bus(fleet, ep, "robot-2") as bus:
        img = ask(bus, P.key_camera(2), P.CameraRequest(yaw=0.0), P.CameraReply)
        assert img.robot_id == 2  # a signed reply, verified, bound to this request
        before = server.untrusted
        with pytest.raises(BusError, match="may not command robot 1"):
            ask(bus, P.key_turn(1), P.TurnRequest(angle=0.1), P.CommandReply)
        with pytest.raises(BusError, match="may not claim robot 3"):
            ask(bus, P.KEY_WORLD_REGISTER, P.RegisterRequest(want=3), P.RegisterReply)
        assert ask(bus, P.KEY_WORLD_REGISTER, P.RegisterRequest(), P.RegisterReply).robot_id == 2
        assert server.untrusted > before
        # another session of robot 2's key (a replica, a thief) cannot drive it now
        with robot_bus(fleet, ep, "robot-2") as other, pytest.raises(BusError, match="bound"):
            ask(other, P.key_turn(2), P.TurnRequest(angle=0.1), P.CommandReply)
        done = ask(bus, P.key_turn(2), P.TurnRequest(angle=0.1), P.CommandReply)
        assert done.status == "done"


def test_the_world_answers_no_unsigned_request(
    fleet: T.Credentials, secure_world: tuple[WorldServer, str]
) -> None:
    server, ep = secure_world
    with Bus(BusConfig(connect=(ep,), multicast_scouting=False)) as stranger:
        before = server.untrusted
        end = time.monotonic() + 20.0
        while server.untrusted == before and time.monotonic() < end:
            with pytest.raises(BusError):  # NoRoute at first, then no reply at all
                stranger.query(P.key_walk(3), P.WalkRequest(distance=2.0), P.CommandReply, 1.0)
        assert server.untrusted > before  # refused as unsigned, nothing executed


def test_sim_client_acts_with_the_robots_key(
    fleet: T.Credentials,
    secure_world: tuple[WorldServer, str],
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
) -> None:
    from sim.server import client as cli

    _, ep = secure_world
    common = ["--credentials", str(fleet.root), "--plain-links", "--connect", ep,
              "--no-multicast-scouting", "--timeout", "20"]  # fmt: skip
    out = tmp_path / "c.png"
    assert cli.main([*common, "camera", "3", "--out", str(out)]) == 0
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert cli.main([*common, "--as", "robot-1", "turn", "3", "10"]) == 1
    assert "may not command robot 3" in capsys.readouterr().err
    assert cli.main([*common, "poses"]) == 0  # the observer's key reads ground truth
    assert "robot   3:" in capsys.readouterr().out


# --------------------------------------------------------------------------- the demo


@pytest.mark.slow
@pytest.mark.parametrize("links", ["tls", "plain"])
def test_rogue_against_a_three_robot_demo(tmp_path: Path, links: str) -> None:
    out = tmp_path / "demo"
    cmd = [sys.executable, "-m", "tools.demo", "--robots", "3", "--seed", "2", "--out", str(out),
           "--json", str(tmp_path / "r.json"), "--timeout", "240", "--rogue", "25"]  # fmt: skip
    if links == "plain":
        cmd.append("--plain-links")
    res = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, timeout=320)
    r = json.loads((tmp_path / "r.json").read_text())
    rogues = r["rogues"]
    why = {k: r.get(k) for k in ("outcome", "untrusted", "errors", "timeout", "record_rounds")}
    assert r["success"] is True, (why, res.stdout[-3000:])
    assert r["plan_matches_records"] and r["rogue_defeated"]
    assert set(rogues) == ({"stranger", "observer"} if links == "tls" else {"stranger", "robot-4"})
    for rep in rogues.values():
        assert rep.get("commands_executed", 0) == 0 and rep.get("claims_granted", 0) == 0
    if links == "tls":
        assert rogues["stranger"]["connected"] is False  # mutual TLS: no fleet certificate
    else:  # every attack reached the fleet and was refused by the signatures
        assert rogues["stranger"]["sent"]["forge"] > 0 and rogues["robot-4"]["sent"]["replay"] > 0
