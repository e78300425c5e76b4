"""System-test helper: the world as a process and an observer of statuses and truth."""

from __future__ import annotations

import json
import math
import subprocess
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from agent.config import AgentConfig
from agent.net.bus import Bus, BusConfig
from agent.wire import KEY_STATUS_ALL, KEY_WORLD_TRUTH_ALL, StatusMsg, TruthPosesMsg
from tools.harness.procs import (
    ROOT,
    Proc,
    agent_command,
    free_port,
    robot_ids,
    start_agent,
    start_world,
    stop,
    wait_ready,
)


def agent_on(ep: str, cfg: AgentConfig, out: Path) -> Proc:
    """Robot ``cfg.robot_id``'s agent (its flags: ``cfg.to_argv()``) joining the insecure world
    at ``ep``; its log ``out/agent-ID.log``."""
    net = ["--connect", ep, "--no-multicast-scouting", "--insecure"]
    return start_agent(agent_command(cfg, net), out / f"agent-{cfg.robot_id}.log")


def run_demo(tmp_path: Path, *args: str) -> tuple[subprocess.CompletedProcess[str], dict[str, Any]]:
    """``python -m tools.demo ARGS`` into ``tmp_path/demo`` (bounded: 400 s for the agents,
    480 s in all); its completed process and ``result.json``."""
    out, path = tmp_path / "demo", tmp_path / "result.json"
    res = subprocess.run(
        [sys.executable, "-m", "tools.demo", *args, "--out", str(out), "--json", str(path),
         "--timeout", "400"],
        cwd=ROOT, capture_output=True, text=True, timeout=480,
    )  # fmt: skip
    result = json.loads(path.read_text()) if path.is_file() else {}
    return res, result


@contextmanager
def watched_world(
    tmp_path: Path, robots: int, seed: int
) -> Iterator[tuple[str, Bus, list[int], list[Proc]]]:
    """``python -m sim`` (insecure, loopback) and a bus subscribed to statuses and truth.

    Yields (endpoint, bus, robot ids, processes) once the world is ready (bounded wait);
    every process in the list (the caller appends its agents) is stopped at the end."""
    ep = f"tcp/127.0.0.1:{free_port()}"
    bus = Bus(BusConfig(connect=(ep,), multicast_scouting=False))
    bus.subscribe(KEY_STATUS_ALL)
    bus.subscribe(KEY_WORLD_TRUTH_ALL)
    world = start_world(robots, seed, ep, tmp_path, [])
    procs = [world]
    try:
        wait_ready(world, 120, lambda: bus.drain(0.1))
        yield ep, bus, robot_ids(world.lines, robots), procs
    finally:
        for p in reversed(procs):
            stop(p)
        bus.close()


@dataclass
class Watch:
    """What the observer saw: each robot's first and last true position, latest status."""

    first: dict[int, tuple[float, float]] = field(default_factory=dict)
    last: dict[int, tuple[float, float]] = field(default_factory=dict)
    final: dict[int, StatusMsg] = field(default_factory=dict)

    def take(self, msg: Any) -> None:
        if isinstance(msg, TruthPosesMsg):
            for rid, x, y, _ in msg.poses:
                self.first.setdefault(rid, (x, y))
                self.last[rid] = (x, y)
        elif isinstance(msg, StatusMsg):
            self.final[msg.sender] = msg

    def moved(self, rid: int) -> float:
        """How far robot ``rid`` stands from where it started (m)."""
        return math.hypot(
            self.last[rid][0] - self.first[rid][0], self.last[rid][1] - self.first[rid][1]
        )
