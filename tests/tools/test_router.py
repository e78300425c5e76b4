"""tools.router and tools.wait_for: real processes and zenoh sessions on loopback."""

from __future__ import annotations

import json
import queue
import signal
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import pytest
import zenoh

from tools import router, wait_for

REPO = Path(__file__).resolve().parents[2]


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _session(endpoint: str) -> zenoh.Session:
    cfg = zenoh.Config()
    cfg.insert_json5("connect/endpoints", json.dumps([endpoint]))
    cfg.insert_json5("scouting/multicast/enabled", "false")
    return zenoh.open(cfg)


@pytest.fixture
def running_router() -> Iterator[tuple[str, str, subprocess.Popen[str]]]:
    ep = f"tcp/127.0.0.1:{_free_port()}"
    proc = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "tools.router",
            "--listen",
            ep,
            "--no-multicast-scouting",
            "--insecure",
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
    assert wait_for.main(["nao/test/q", "--queryable", "--timeout", "1", "--connect", ep]) == 1
    with _session(ep) as s:
        q = s.declare_queryable("nao/test/q")
        assert wait_for.wait_for("nao/test/q", [ep], 15.0, False, queryable=True)
        pub = s.declare_publisher("nao/test/tick")
        stop = threading.Event()

        def tick() -> None:
            while not stop.wait(0.05):
                pub.put(b"x")

        t = threading.Thread(target=tick, daemon=True)
        t.start()
        try:
            assert wait_for.wait_for("nao/test/tick", [ep], 15.0, False)
        finally:
            stop.set()
            t.join(timeout=5)
        q.undeclare()


def test_router_cli_bad_endpoint(
    capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    assert router.main(["--listen", "nonsense", "--insecure"]) == 2
    assert "proto/address" in capsys.readouterr().err
    monkeypatch.delenv("NAO_CREDENTIALS", raising=False)
    assert router.main([]) == 2
    assert "no fleet credentials" in capsys.readouterr().err


def test_wait_for_cli_errors(capsys: pytest.CaptureFixture[str]) -> None:
    assert wait_for.main(["world/clock", "--timeout", "0"]) == 2
    assert wait_for.main(["bad//key", "--timeout", "1", "--no-multicast-scouting"]) == 2
    assert "wait_for:" in capsys.readouterr().err
