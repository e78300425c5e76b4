"""tools.router and tools.wait_for: real processes and zenoh sessions on loopback.

Insecure (plain TCP, ``--insecure``) for the router's own behaviour; secure (a fleet, a
TLS router with access control) for what the containers do: ``wait_for world/clock``
with a robot's or the observer's key.
"""

from __future__ import annotations

import json
import queue
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import pytest
import zenoh

from agent.wire import NetworkSpec
from tools import router, wait_for
from tools.harness.procs import free_port

REPO = Path(__file__).resolve().parents[2]


def _session(endpoint: str) -> zenoh.Session:
    cfg = zenoh.Config()
    cfg.insert_json5("connect/endpoints", json.dumps([endpoint]))
    cfg.insert_json5("scouting/multicast/enabled", "false")
    return zenoh.open(cfg)


@pytest.fixture
def running_router() -> Iterator[tuple[str, str, subprocess.Popen[str]]]:
    ep = f"tcp/127.0.0.1:{free_port()}"
    proc = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "tools.router",
            "--insecure",
            "--listen",
            ep,
            "--no-multicast-scouting",
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        cwd=str(REPO),
    )
    lines: queue.Queue[str] = queue.Queue()

    def pump() -> None:
        assert proc.stdout is not None
        for line in proc.stdout:
            lines.put(line.strip())

    threading.Thread(target=pump, daemon=True).start()
    try:
        ready = lines.get(timeout=30)
        assert ready.startswith("router ready zid="), ready
        zid = ready.split("zid=", 1)[1].split()[0]
        yield ep, zid, proc
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait(timeout=10)


@pytest.mark.system
def test_router_serves_and_stops_cleanly(
    running_router: tuple[str, str, subprocess.Popen[str]],
) -> None:
    ep, zid, proc = running_router
    with _session(ep) as s:
        end = time.monotonic() + 15
        while time.monotonic() < end and not list(s.info.routers_zid()):
            time.sleep(0.05)
        assert [str(z) for z in s.info.routers_zid()] == [zid]
    proc.send_signal(signal.SIGTERM)
    assert proc.wait(timeout=15) == 0


@pytest.mark.system
def test_wait_for_queryable_and_sample(
    running_router: tuple[str, str, subprocess.Popen[str]],
) -> None:
    ep, _zid, _proc = running_router
    # nothing serves yet: a clear timeout, exit 1
    argv = ["nao/test/q", "--queryable", "--timeout", "1", "--insecure", "--connect", ep]
    assert wait_for.main(argv) == 1
    spec = NetworkSpec(connect=(ep,), multicast_scouting=False)
    with _session(ep) as s:
        q = s.declare_queryable("nao/test/q")
        assert wait_for.wait_for("nao/test/q", spec, 15.0, queryable=True)
        pub = s.declare_publisher("nao/test/tick")
        stop = threading.Event()

        def tick() -> None:
            while not stop.wait(0.05):
                pub.put(b"x")

        t = threading.Thread(target=tick, daemon=True)
        t.start()
        try:
            assert wait_for.wait_for("nao/test/tick", spec, 15.0)
        finally:
            stop.set()
            t.join(timeout=5)
        q.undeclare()


def test_router_cli_bad_endpoint(
    capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    assert router.main(["--insecure", "--listen", "nonsense"]) == 2
    assert "proto/address" in capsys.readouterr().err
    monkeypatch.delenv("NAO_CREDENTIALS", raising=False)
    assert router.main([]) == 2
    assert "no fleet credentials" in capsys.readouterr().err


def test_wait_for_cli_errors(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    from agent.wire.trust import create_fleet

    monkeypatch.delenv("NAO_CREDENTIALS", raising=False)
    assert wait_for.main(["world/clock", "--timeout", "0", "--insecure"]) == 2
    argv = ["bad//key", "--timeout", "1", "--no-multicast-scouting", "--insecure"]
    assert wait_for.main(argv) == 2
    # secure by default: no credentials, no start
    assert wait_for.main(["world/clock", "--connect", "tls/127.0.0.1:7447"]) == 2
    assert "no fleet credentials" in capsys.readouterr().err
    # an identity whose key the folder does not hold
    fleet = tmp_path / "fleet"
    create_fleet(fleet, [1])
    (fleet / "keys" / "robot-1.key").unlink()
    argv = ["world/clock", "--credentials", str(fleet), "--connect", "tls/127.0.0.1:7447"]
    assert wait_for.main([*argv, "--identity", "robot-1"]) == 2
    assert "no private key for robot-1" in capsys.readouterr().err


def test_wait_for_default_identity(tmp_path: Path) -> None:
    from agent.wire.trust import create_fleet

    fleet = tmp_path / "fleet"
    create_fleet(fleet, [2, 3])
    assert wait_for.default_identity(str(fleet)) == "observer"
    (fleet / "keys" / "observer.key").unlink()
    assert wait_for.default_identity(str(fleet)) == "robot-2"
    for k in ("robot-2", "robot-3"):
        (fleet / "keys" / f"{k}.key").unlink()
    assert wait_for.default_identity(str(fleet)) == "world"
    (fleet / "keys" / "world.key").unlink()
    with pytest.raises(ValueError, match="no observer, robot or world key"):
        wait_for.default_identity(str(fleet))


@pytest.mark.system
def test_wait_for_secure_world_clock(tmp_path: Path) -> None:
    """As in the agent containers: a TLS router with the fleet's access control, the world
    publishing world/clock; wait_for with a robot's key (the agents hold only robot keys)
    and with the observer's sees it; a robot key also sees the world/register queryable."""
    from agent.wire.trust import create_fleet

    fleet = tmp_path / "fleet"
    create_fleet(fleet, [1, 2])
    ep = f"tls/127.0.0.1:{free_port()}"
    proc = subprocess.Popen(
        [
            sys.executable, "-m", "tools.router", "--credentials", str(fleet), "--listen", ep,
            "--no-multicast-scouting",
        ],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=str(REPO),
    )  # fmt: skip
    try:
        assert proc.stdout is not None and "router ready" in proc.stdout.readline()
        base = ["--credentials", str(fleet), "--connect", ep, "--no-multicast-scouting"]
        # nothing published yet: a clear timeout
        assert wait_for.main(["world/clock", "--timeout", "1", *base]) == 1
        world = NetworkSpec(
            connect=(ep,), multicast_scouting=False, mode="client",
            credentials=str(fleet), identity="world",
        )  # fmt: skip
        from agent.net.bus import zenoh_config

        with zenoh.open(zenoh_config(world)) as s:
            q = s.declare_queryable("world/register")
            pub = s.declare_publisher("world/clock")
            stop = threading.Event()

            def tick() -> None:
                while not stop.wait(0.05):
                    pub.put(b"x")

            t = threading.Thread(target=tick, daemon=True)
            t.start()
            try:
                for who in ("robot-2", "observer"):
                    argv = ["world/clock", "--timeout", "15", "--identity", who, *base]
                    assert wait_for.main(argv) == 0
                argv = ["world/register", "--queryable", "--timeout", "15", *base]
                assert wait_for.main([*argv, "--identity", "robot-1"]) == 0
            finally:
                stop.set()
                t.join(timeout=5)
            q.undeclare()
    finally:
        if proc.poll() is None:
            proc.send_signal(signal.SIGTERM)
            proc.wait(timeout=15)


@pytest.mark.system
def test_wait_for_retries_an_unreachable_router(capsys: pytest.CaptureFixture[str]) -> None:
    """No router (yet, or a lossy link lost the handshake): not served within the
    timeout (exit 1, the last connection error on stderr), not a usage error (2)."""
    ep = f"tcp/127.0.0.1:{free_port()}"
    argv = ["world/clock", "--timeout", "3", "--insecure", "--mode", "client", "--connect", ep]
    t0 = time.monotonic()
    assert wait_for.main([*argv, "--no-multicast-scouting"]) == 1
    assert time.monotonic() - t0 < 30
    err = capsys.readouterr().err
    assert "wait_for: no session:" in err and "nothing on world/clock within 3 s" in err
