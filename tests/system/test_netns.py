"""System tests on test hosts (tools.netns) with real zenoh sessions and real packet loss.

Three network namespaces on one bridge: a router (tools.router) on host 1, a subscriber on
host 2, a re-publishing sender on host 3, both given only the router's endpoint,
multicast scouting off. Then 30 % of the sender host's packets are dropped in both
directions (tools.packet_drop): the sender still gets through (TCP retransmits) and the
drop counters rise. Everything is torn down even when an assertion fails.
"""

from __future__ import annotations

import os
import queue
import subprocess
import sys
import threading
import time
from collections.abc import Callable
from pathlib import Path

import pytest

from tools import netns
from tools.packet_drop import Dropper

REPO = Path(__file__).resolve().parents[2]

pytestmark = [
    pytest.mark.netns,
    pytest.mark.system,
    pytest.mark.usefixtures("netns_hosts"),  # skipped without test hosts; failed under CI=1
]

PREFIX = f"nt{os.getpid() % 100000}"

# A tiny zenoh program: "pub" re-publishes an increasing counter every 20 ms, "sub" prints
# every counter it receives, one per line. Both are given only the
# router's endpoint (they may then also link directly, learning of each other by gossip).
HELPER = r"""
import json, sys, time, queue, zenoh
role, router = sys.argv[1], sys.argv[2]
cfg = zenoh.Config()
cfg.insert_json5("mode", json.dumps("peer"))
cfg.insert_json5("connect/endpoints", json.dumps([router]))
cfg.insert_json5("scouting/multicast/enabled", "false")
with zenoh.open(cfg) as s:
    if role == "pub":
        pub = s.declare_publisher("nao/test/seq")
        n = 0
        while True:
            pub.put(str(n).encode())
            n += 1
            time.sleep(0.02)
    else:
        q = queue.Queue()
        sub = s.declare_subscriber("nao/test/seq", lambda smp: q.put(smp.payload.to_bytes()))
        print("ready", flush=True)
        while True:
            print(int(q.get().decode()), flush=True)
"""


def _lines(proc: subprocess.Popen[str]) -> queue.Queue[str]:
    out: queue.Queue[str] = queue.Queue()

    def pump() -> None:
        assert proc.stdout is not None
        for line in proc.stdout:
            out.put(line.strip())

    threading.Thread(target=pump, daemon=True).start()
    return out


def _wait_for(pred: Callable[[], bool], deadline_s: float, what: str) -> None:
    end = time.monotonic() + deadline_s
    while time.monotonic() < end:
        if pred():
            return
        time.sleep(0.05)
    raise AssertionError(f"timed out after {deadline_s} s waiting for {what}")


def _wait_line(lines: queue.Queue[str], prefix: str, deadline_s: float) -> None:
    end = time.monotonic() + deadline_s
    while time.monotonic() < end:
        try:
            if lines.get(timeout=0.2).startswith(prefix):
                return
        except queue.Empty:
            pass
    raise AssertionError(f"timed out after {deadline_s} s waiting for a line {prefix!r}")


def test_fabric_hosts_reach_each_other_and_vanish(tmp_path: Path) -> None:
    probe = tmp_path / "udp.py"
    probe.write_text(
        "import socket, sys\n"
        "s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)\n"
        "if sys.argv[1] == 'recv':\n"
        "    s.bind(('0.0.0.0', 9999)); s.settimeout(10); print(s.recvfrom(64)[0].decode())\n"
        "else:\n"
        "    s.sendto(b'hello', (sys.argv[2], 9999))\n"
    )
    with netns.Fabric(2, prefix=PREFIX) as fab:
        assert fab.hosts == [f"{PREFIX}-h1", f"{PREFIX}-h2"]
        assert set(fab.hosts) <= set(netns.list_namespaces())
        recv = fab.popen(1, [sys.executable, str(probe), "recv"])
        lines = _lines(recv)

        def delivered() -> bool:
            fab.run(2, [sys.executable, str(probe), "send", fab.address(1)])
            try:
                return lines.get(timeout=0.3) == "hello"
            except queue.Empty:
                return False

        _wait_for(delivered, 15.0, "a UDP datagram from host 2 to host 1")
        # no default route: the hosts can reach nothing outside the test /24
        routes = fab.run(1, ["ip", "route"]).stdout
        assert "default" not in routes
    left = [n for n in netns.list_namespaces() if n.startswith(f"{PREFIX}-")]
    assert left == []


def test_cleanup_after_exception() -> None:
    with pytest.raises(RuntimeError, match="boom"), netns.Fabric(1, prefix=PREFIX):
        raise RuntimeError("boom")
    assert not [n for n in netns.list_namespaces() if n.startswith(f"{PREFIX}-")]


def test_zenoh_through_router_survives_30_percent_loss(tmp_path: Path) -> None:
    helper = tmp_path / "zhelper.py"
    helper.write_text(HELPER)
    with netns.Fabric(3, prefix=PREFIX) as fab:
        router_ep = f"tcp/{fab.address(1)}:7447"
        router = fab.popen(
            1,
            [
                sys.executable,
                "-m",
                "tools.router",
                "--listen",
                router_ep,
                "--no-multicast-scouting",
                "--insecure",
            ],
            cwd=str(REPO),
        )
        rlines = _lines(router)
        _wait_line(rlines, "router ready", 20.0)

        sub = fab.popen(2, [sys.executable, str(helper), "sub", router_ep])
        slines = _lines(sub)
        _wait_line(slines, "ready", 20.0)
        fab.popen(3, [sys.executable, str(helper), "pub", router_ep])

        seen: list[int] = []

        def got_more(than: int) -> Callable[[], bool]:
            def pred() -> bool:
                while True:
                    try:
                        seen.append(int(slines.get_nowait()))
                    except queue.Empty:
                        break
                return len(seen) > than

            return pred

        _wait_for(got_more(20), 20.0, "20 messages without loss")

        dropper = Dropper(fab.name(3))
        # No port filter: zenoh peers learn of each other from the router (gossip) and
        # also link directly on ephemeral ports, which a port-7447 rule would miss.
        dropper.install(0.3, direction="both")
        mark = max(seen)
        count = len(seen)
        # fresh messages, published after the loss began, still arrive
        _wait_for(got_more(count + 100), 40.0, "100 more messages at 30 % loss")
        assert max(seen) > mark + 100
        drops = dropper.dropped_packets()
        print(f"dropped {drops} packets; received {len(seen)}")
        assert drops > 0, "no packet was dropped: the rules did not apply"
        rows = dropper.counters()
        assert {r.direction for r in rows} == {"in", "out"}
        assert all("probability 0.3" in r.rule or "0.29" in r.rule for r in rows)
        assert dropper.clear() is True
        assert dropper.counters() == []
