"""Render workers of one run (cameras drawn beside the world; docs/world.md "Render workers"): their
command line, starting K of them beside the world, and what each one served.

``tools.demo --render-service K`` starts K ``python -m sim.server.render_worker`` processes with
shards 1/K..K/K once the world is ready and before the agents; each writes
``render-{i}.log``, whose summary line (``served camera=N ...``) says how many camera
queries it answered. :mod:`tools.harness.hosts` runs the same command line on test hosts.
"""

from __future__ import annotations

import re
import subprocess
import sys
import time
from pathlib import Path

from tools.harness.procs import ROOT, Proc, stop

#: Seconds a worker may take to fetch the scenario, build its room and see the poses.
READY_S = 180.0


def render_command(
    net: list[str],
    shard: tuple[int, int],
    renderer: str | None = None,
    encoding: str | None = None,
) -> list[str]:
    """The argv of ``python -m sim.server.render_worker`` (``net``: its join flags; ``renderer``:
    its ``--renderer``, ``encoding`` its ``--camera-encoding``; None for the worker's default)."""
    kind = ["--renderer", renderer] if renderer else []
    enc = ["--camera-encoding", encoding] if encoding else []
    return [
        sys.executable, "-m", "sim.server.render_worker", *net, "--shard", f"{shard[0]}/{shard[1]}",
        *kind, *enc,
    ]  # fmt: skip


def start_render_workers(
    k: int,
    net: list[str],
    out: Path,
    ready_s: float = READY_S,
    renderer: str | None = None,
    encoding: str | None = None,
) -> list[Proc]:
    """K render workers (shards 1/K..K/K) joining with ``net``; waits for every ready line."""
    procs: list[Proc] = []
    for i in range(1, k + 1):
        log = (out / f"render-{i}.log").open("wb")
        p = subprocess.Popen(
            render_command(net, (i, k), renderer, encoding),
            cwd=ROOT,
            stdout=log,
            stderr=subprocess.STDOUT,
        )
        procs.append(Proc(f"render {i}", p, log))
    deadline = time.monotonic() + ready_s
    for i, proc in enumerate(procs, 1):
        path = out / f"render-{i}.log"
        while "render ready" not in path.read_text(errors="replace"):
            if proc.popen.poll() is not None or time.monotonic() > deadline:
                for q in procs:
                    stop(q)
                raise RuntimeError(f"render worker {i} did not start; see {path}")
            time.sleep(0.1)  # polling the worker's log for its ready line, bounded above
    return procs


_SERVED = re.compile(r"served camera=(\d+)")


def served(log: Path) -> int | None:
    """Camera queries a stopped worker answered, from its summary line (None: no line)."""
    found = _SERVED.findall(log.read_text(errors="replace")) if log.is_file() else []
    return int(found[-1]) if found else None


def served_by(out: Path, k: int) -> dict[str, int | None]:
    """What each of K workers of a run under ``out`` served, by ``render-{i}``."""
    return {f"render-{i}": served(out / f"render-{i}.log") for i in range(1, k + 1)}
