"""Reshaping on command with real processes (docs/formation.md "Reshaping").

- The TLS router's access control: the operator's command on ``fleet/reshape`` reaches a
  robot; the same put by robot 1's key or the observer's never does.
- ``python -m tools.fleet reshape`` as a process against two robots' sessions.
- ``python -m tools.demo --robots 4 --reshape line``: the fleet builds the pyramid, the
  demo (the operator, with the run's operator key) commands the line once every robot
  holds; every robot plans the same transition (the evaluator recomputes its digest from
  the signed records), walks it without a contact or a second search, and the ground
  truth holds a line in tolerance; the recording's scene, which heard the command, draws
  the line's plan.
"""

from __future__ import annotations

import json
import queue
import subprocess
import sys
import time
from pathlib import Path

import pytest

from agent import wire as P
from agent.wire import trust as T
from tests.system.test_security import client, session
from tests.system.world import run_demo
from tools.harness.procs import free_port

pytestmark = pytest.mark.system
ROOT = Path(__file__).resolve().parents[2]


def test_the_router_delivers_the_operators_command_and_no_robots(tmp_path: Path) -> None:
    root = tmp_path / "fleet"
    T.create_fleet(root, [1, 2])
    fleet = T.Credentials(root)
    ep = f"tls/127.0.0.1:{free_port()}"
    router = session(
        P.NetworkSpec(
            listen=(ep,), multicast_scouting=False, mode="router",
            credentials=str(fleet.root), identity="router",
        )
    )  # fmt: skip
    got: queue.Queue[bytes] = queue.Queue()
    try:
        r2 = session(client(fleet, ep, "robot-2"))
        sub = r2.declare_subscriber(P.KEY_RESHAPE, lambda s: got.put(s.payload.to_bytes()))
        r1 = session(client(fleet, ep, "robot-1"))
        obs = session(client(fleet, ep, "observer"))
        op = session(client(fleet, ep, "operator"))
        heard: list[bytes] = []
        deadline = time.monotonic() + 20.0
        while b"operator" not in heard and time.monotonic() < deadline:
            r1.put(P.KEY_RESHAPE, b"robot-1")
            obs.put(P.KEY_RESHAPE, b"observer")
            op.put(P.KEY_RESHAPE, b"operator")
            time.sleep(0.1)  # pacing the puts while polling for delivery, bounded above
            while not got.empty():
                heard.append(got.get())
        end = time.monotonic() + 1.0
        while time.monotonic() < end:  # a stream of forgeries once routes exist
            r1.put(P.KEY_RESHAPE, b"robot-1")
            obs.put(P.KEY_RESHAPE, b"observer")
            time.sleep(0.05)
        while not got.empty():
            heard.append(got.get())
        assert b"operator" in heard
        assert b"robot-1" not in heard and b"observer" not in heard
        sub.undeclare()
        for s in (r1, r2, obs, op):
            s.close()
    finally:
        router.close()


@pytest.mark.slow
def test_four_robots_reshape_a_pyramid_into_a_line(tmp_path: Path) -> None:
    res, r = run_demo(
        tmp_path, "--robots", "4", "--seed", "1", "--reshape", "line", "--reshape-wait", "10",
        "--no-publish-camera",
    )  # fmt: skip
    assert "identical plan digests" in res.stdout, res.stderr[-2000:]
    assert r["shape_spec"] == "pyramid" and r["reshape_specs"] == ["line"]
    (t,) = r["reshapes"]
    assert t["outcome"] == "held", t
    assert t["sim_s"] > 0 and t["wall_s"] > 0
    assert r["reshape_ok"] is True
    assert r["exit_codes"] == {"1": 0, "2": 0, "3": 0, "4": 0}, r.get("errors")
    # every robot on the transition's plan, the one the evaluator recomputes
    assert set(r["plan_digests"].values()) == {t["plan"]}
    assert r["evaluator_plan_digest"] == t["plan"] and t["base"] != t["plan"]
    assert set(r["record_rounds"].values()) == {0}  # no second search
    # the line from ground truth: three pairs, each beside its parent, in tolerance
    assert len(r["pairs"]) == 3
    for p in r["pairs"]:
        assert abs(p["r_d"]) <= 0.125 and abs(p["r_phi"]) <= 0.30, p
        assert abs(p["angle_deg"] - 90.0) <= 9.0, p
    assert r["contacts"] == 0
    assert r["success"] is True and res.returncode == 0
    assert "reshape 1 to line: held" in res.stdout
    # the recording heard the operator's command, and its scene drew the line's plan
    from mcap.reader import make_reader

    topics, notes = set(), []
    with (tmp_path / "demo" / "run.mcap").open("rb") as f:
        for _, channel, message in make_reader(f).iter_messages():
            topics.add(channel.topic)
            if channel.topic == "/log":
                notes.append(json.loads(message.data)["message"])
    assert P.KEY_RESHAPE in topics
    assert any(n.startswith(f"plan {t['plan'][:12]} drawn") for n in notes), notes[-20:]


def test_the_operator_cli_commands_a_holding_fleet_over_real_sessions(tmp_path: Path) -> None:
    """``tools.fleet reshape`` as a process: two robots' sessions (robot keys, signatures
    over plain links) say ``done`` on plan A; the operator's command reaches them signed
    by the operator, naming A and the line; they say ``done`` on plan B; the CLI reports
    the transition held and exits 0."""
    from agent.config import load_shape
    from agent.net.bus import Bus, BusConfig

    root = tmp_path / "fleet"
    T.create_fleet(root, [1, 2])
    ep = f"tcp/127.0.0.1:{free_port()}"
    a, b = "aa" * 32, "bb" * 32

    def robot(i: int) -> Bus:
        spec = BusConfig(
            listen=(ep,) if i == 1 else (), connect=() if i == 1 else (ep,),
            multicast_scouting=False, credentials=str(root), identity=f"robot-{i}", tls=False,
        )  # fmt: skip
        return Bus(spec)

    with robot(1) as r1, robot(2) as r2:
        r1.subscribe(P.KEY_RESHAPE)
        cli = subprocess.Popen(
            [sys.executable, "-m", "tools.fleet", "reshape", "--shape", "line",
             "--fleet-size", "2", "--credentials", str(root), "--plain-links",
             "--connect", ep, "--no-multicast-scouting", "--timeout", "60"],
            cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
        )  # fmt: skip
        got: list[tuple[P.ReshapeMsg, str]] = []
        plan, end = a, time.monotonic() + 40.0
        try:
            while cli.poll() is None and time.monotonic() < end:
                for i, bus in ((1, r1), (2, r2)):
                    bus.publish(
                        P.key_status(i), P.StatusMsg(sender=i, phase="done", plan_digest=plan)
                    )
                for ev in r1.drain(0.3):
                    if isinstance(ev.msg, P.ReshapeMsg):
                        got.append((ev.msg, ev.signer))
                        plan = b  # the fleet takes it
            out, err = cli.communicate(timeout=10)
        finally:
            if cli.poll() is None:
                cli.kill()
    assert cli.returncode == 0, err[-2000:]
    msg, signer = got[0]
    assert signer == "operator" and msg.base == a and msg.command == 1
    assert msg.shape_digest == load_shape("line").digest
    assert "reshape 1 to line: held (every robot done on plan bbbbbbbbbbbb)" in out
