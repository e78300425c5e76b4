"""The live view: foxglove-sdk's WebSocket server fed by the same scene
builder as the recorder (tools/harness/view/live.py, tools/view.py). A client of the Foxglove
WebSocket protocol (the ``websockets`` package) joins, receives ``advertise``, subscribes
and receives messages; the source is a real 3-NAO demo run (its recording,
tests/data/demo-3-seed1.mcap, replayed by ``python -m tools.view --replay``) or the
recorder itself fed that run's messages.

Every wait polls with a deadline (the machine is shared and slow).
"""

from __future__ import annotations

import asyncio
import json
import os
import subprocess
import sys
import time
from collections import defaultdict
from pathlib import Path
from typing import Any

import pytest

from agent.wire import decode
from tools.harness.observe import Observer, Recorder
from tools.harness.procs import free_port
from tools.harness.view.live import Fanout, LiveServer, parse_address
from tools.view import wire_messages

ROOT = Path(__file__).resolve().parents[2]
RUN = ROOT / "tests" / "data" / "demo-3-seed1.mcap"  # python -m tools.demo --robots 3 --seed 1
PROTOCOL = "foxglove.sdk.v1"


async def _listen(url: str, seconds: float, until: int) -> dict[str, Any]:
    """Join ``url``, subscribe to every advertised channel, collect messages for at most
    ``seconds`` or until ``until`` messages have come. Retries the connection until the
    deadline (the server may still be starting)."""
    import websockets

    deadline = time.monotonic() + seconds
    while True:
        try:
            ws = await websockets.connect(url, subprotocols=[PROTOCOL])  # type: ignore[list-item]
            break
        except OSError:
            if time.monotonic() > deadline:
                raise
            await asyncio.sleep(0.2)
    seen: dict[str, Any] = {"ops": [], "channels": {}, "messages": defaultdict(list)}
    subs: dict[int, str] = {}  # subscription id -> topic
    asked: dict[int, tuple[float, int]] = {}  # subscription id -> (when, channel id)
    heard: set[str] = set()
    next_sub = 1
    count = 0

    async def subscribe(channels: list[tuple[int, str]]) -> None:
        # fresh subscription ids, as the page does (tools/web/view.js)
        nonlocal next_sub
        add = []
        for cid, topic in channels:
            subs[next_sub] = topic
            asked[next_sub] = (time.monotonic(), cid)
            add.append({"id": next_sub, "channelId": cid})
            next_sub += 1
        await ws.send(json.dumps({"op": "subscribe", "subscriptions": add}))

    async with ws:
        assert ws.subprotocol == PROTOCOL
        while time.monotonic() < deadline and count < until:
            # a subscription can reach the server before the channel it just advertised
            # (foxglove-sdk: "attempted to subscribe to unknown channel"): ask again for
            # every topic still silent 3 s after it was asked, as the page does
            now = time.monotonic()
            stale = [k for k, (t, _) in asked.items() if now - t > 3.0 and subs[k] not in heard]
            if stale:
                await ws.send(json.dumps({"op": "unsubscribe", "subscriptionIds": stale}))
                again = [(asked[k][1], subs[k]) for k in stale]
                for k in stale:
                    del asked[k]
                await subscribe(again)
            try:
                frame = await asyncio.wait_for(ws.recv(), 0.5)
            except TimeoutError:
                continue
            except websockets.ConnectionClosed:
                break  # the server stopped: what came is what counts
            if isinstance(frame, str):
                op = json.loads(frame)
                seen["ops"].append(op["op"])
                if op["op"] == "advertise":
                    for ch in op["channels"]:
                        seen["channels"][ch["topic"]] = ch
                    await subscribe([(ch["id"], ch["topic"]) for ch in op["channels"]])
                continue
            assert frame[0] == 1  # message data
            sub = int.from_bytes(frame[1:5], "little")
            t_ns = int.from_bytes(frame[5:13], "little")
            heard.add(subs[sub])
            seen["messages"][subs[sub]].append((t_ns, json.loads(frame[13:])))
            count += 1
    return seen


def listen(url: str, seconds: float = 60.0, until: int = 200) -> dict[str, Any]:
    return asyncio.run(_listen(url, seconds, until))


def robots_in(scene: dict[str, Any]) -> set[int]:
    return {int(e["id"].split("/")[1]) for e in scene["entities"] if e["id"].startswith("robot/")}


def test_the_address_of_live() -> None:
    assert parse_address("127.0.0.1:8765") == ("127.0.0.1", 8765)
    assert parse_address(":0") == ("127.0.0.1", 0)
    assert parse_address("[::1]:9000") == ("::1", 9000)
    with pytest.raises(ValueError):
        parse_address("host:port")


def test_a_client_joins_live_receives_advertise_then_messages_of_a_real_run(
    tmp_path: Path,
) -> None:
    """``python -m tools.view --replay`` of a real 3-NAO run, ``--live`` on a free port."""
    port = free_port()
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    cmd = [sys.executable, "-m", "tools.view", "--replay", str(RUN), "--speed", "4", "--loop"]
    cmd += ["--live", f"127.0.0.1:{port}", "--for", "120"]
    log = (tmp_path / "view.log").open("w")
    proc = subprocess.Popen(cmd, cwd=ROOT, env=env, stdout=log, stderr=subprocess.STDOUT)
    try:
        seen = listen(f"ws://127.0.0.1:{port}", seconds=90.0, until=300)
    finally:
        proc.terminate()
        proc.wait(30)
    text = (tmp_path / "view.log").read_text()
    assert seen["ops"][:2] == ["serverInfo", "advertise"], text
    chans = seen["channels"]
    assert chans["/scene"]["schemaName"] == "foxglove.SceneUpdate", chans
    assert chans["/scene"]["encoding"] == "json"
    assert chans["/log"]["schemaName"] == "foxglove.Log"
    msgs = seen["messages"]
    assert msgs["/scene"], (sorted(msgs), text)
    assert set().union(*(robots_in(m) for _, m in msgs["/scene"])) == {1, 2, 3}
    assert {f"/robots/{i}/status" for i in (1, 2, 3)} <= set(chans)
    times = [t for t, _ in msgs["/scene"]]
    assert max(times) > 0  # world times (t_sim), as in the recording


def test_the_recorder_fans_the_scene_out_to_the_live_server(tmp_path: Path) -> None:
    """One scene builder, two sinks: the messages of a real run go to run.mcap and to a
    live client alike; a failing extra sink costs neither the recording nor the others."""
    live = LiveServer("127.0.0.1", 0)

    class Broken:
        def emit(self, topic: str, schema: Any, message: Any, t_ns: int) -> None:
            raise RuntimeError("a viewer that fails")

    rec = Recorder(tmp_path / "run.mcap", sinks=[Broken(), live])
    obs = Observer(time.monotonic())
    msgs = wire_messages(RUN)
    result: dict[str, Any] = {}

    def client() -> None:
        result.update(listen(live.url, seconds=60.0, until=10**6))

    import threading

    t = threading.Thread(target=client, daemon=True)
    t.start()
    try:
        waited = False
        fed = 0
        while fed < len(msgs):
            _, key, data = msgs[fed]
            obs.take(key, decode(data), rec)
            fed += 1
            if not waited and "/scene" in live.topics():
                # /scene is advertised: feed on once the client has subscribed to it (a
                # deadline, not a guess at how long the subscription takes)
                waited, deadline = True, time.monotonic() + 30.0
                while "/scene" not in live.subscribed() and time.monotonic() < deadline:
                    time.sleep(0.05)
            time.sleep(0.002)
        time.sleep(1.0)
    finally:
        rec.close()
        live.close()
        t.join(30)
    assert rec.fanout.rejected > 0  # the broken sink, counted
    assert rec.scene_rejected == 0 and obs.rejected == 0
    assert result["messages"]["/scene"], sorted(result["messages"])
    assert live.sent > 0
    from mcap.reader import make_reader

    with (tmp_path / "run.mcap").open("rb") as f:
        topics = {c.topic for _, c, _ in make_reader(f).iter_messages()}
    assert {"/scene", "/log", "world/truth/poses"} <= topics


def test_a_failing_extra_sink_never_stops_the_primary() -> None:
    got: list[str] = []

    class Bad:
        def emit(self, topic: str, schema: Any, message: Any, t_ns: int) -> None:
            raise ValueError("x" * 1000)

    class Good:
        def emit(self, topic: str, schema: Any, message: Any, t_ns: int) -> None:
            got.append("good " + topic)

    lines: list[str] = []
    fan = Fanout(
        lambda topic, s, m, t: got.append("primary " + topic), [Bad(), Good()], lines.append
    )
    fan("/scene", {}, {}, 0)
    assert got == ["primary /scene", "good /scene"]
    assert fan.rejected == 1 and lines and len(lines[0]) < 400
