"""Render workers and the world over real zenoh sessions: a camera query asked
with the best-matching target goes to the worker serving that robot, and back to the
world's own (not complete) camera when the worker is gone."""

from __future__ import annotations

import json
import math
import os
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import pytest
import zenoh

from agent.wire import CameraReply, CameraRequest, decode, encode, key_camera
from tools.harness.procs import ROOT, free_port, start_world, stop, wait_ready

pytestmark = pytest.mark.system


def session(endpoint: str) -> Any:
    cfg = zenoh.Config()
    cfg.insert_json5("mode", json.dumps("client"))
    cfg.insert_json5("connect/endpoints", json.dumps([endpoint]))
    cfg.insert_json5("scouting/multicast/enabled", "false")
    return zenoh.open(cfg)


def picture(s: Any, rid: int, yaw: float) -> CameraReply:
    for r in s.get(
        key_camera(rid),
        payload=encode(CameraRequest(yaw=yaw)),
        target=zenoh.QueryTarget.BEST_MATCHING,
        timeout=60,
    ):
        if r.ok is not None:
            rep = decode(r.ok.payload.to_bytes())
            assert isinstance(rep, CameraReply), rep
            return rep
    raise AssertionError(f"no picture for robot {rid}")


def test_queries_go_to_the_worker_of_their_robot_then_back_to_the_world(tmp_path: Path) -> None:
    ep = f"tcp/127.0.0.1:{free_port()}"
    net = ["--connect", ep, "--no-multicast-scouting", "--insecure"]
    router = subprocess.Popen(
        [sys.executable, "-m", "tools.router", "--insecure", "--listen", ep,
         "--no-multicast-scouting"],
        cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
    )  # fmt: skip
    world = start_world(3, 7, ep, tmp_path, [], net)
    logs = [(tmp_path / f"w{i}.log").open("wb") for i in (1, 2)]
    workers = [
        subprocess.Popen(
            [sys.executable, "-m", "sim.server.render_worker", *net, "--shard", f"{i}/2"],
            cwd=ROOT,
            stdout=logs[i - 1],
            stderr=subprocess.STDOUT,
        )
        for i in (1, 2)
    ]
    try:
        wait_ready(world, 120)
        deadline = time.monotonic() + 180
        for i in (1, 2):
            while "render ready" not in (tmp_path / f"w{i}.log").read_text(errors="replace"):
                assert workers[i - 1].poll() is None and time.monotonic() < deadline
                time.sleep(0.2)  # polling the worker's ready line, bounded by the deadline
        assert "robots=1,3 shard=1/2" in (tmp_path / "w1.log").read_text()
        assert "robots=2 shard=2/2" in (tmp_path / "w2.log").read_text()
        time.sleep(1.0)  # the router learns the workers' queryables
        with session(ep) as s:
            for rid in (1, 2, 3):
                assert picture(s, rid, math.radians(20)).robot_id == rid
            # worker 2 (robot 2) goes away without a goodbye: robot 2's camera is the world's
            os.kill(workers[1].pid, signal.SIGKILL)
            workers[1].wait(30)
            time.sleep(1.0)
            assert picture(s, 2, 0.0).robot_id == 2
            assert picture(s, 1, 0.0).robot_id == 1
    finally:
        for w in workers:
            if w.poll() is None:
                w.send_signal(signal.SIGINT)
                w.wait(30)
        stop(world, 20)
        router.send_signal(signal.SIGINT)
        router.wait(30)
        for f in logs:
            f.close()
    w1 = (tmp_path / "w1.log").read_text()
    assert "served camera=3 " in w1, w1[-1000:]  # robots 1, 3, then 1 again
    cams = [p for p in (tmp_path / "world.log").read_text().split() if p.startswith("camera=")]
    assert cams == ["camera=1"], cams  # the world drew robot 2's picture after the worker
