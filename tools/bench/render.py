"""``python -m tools.bench render``: camera throughput of the render service (render workers, for
large fleets).

For each setting (``--modes``, default ``0,1,2``: the world draws every picture itself,
or K render workers with shards 1/K..K/K draw them) it starts a router
(``python -m tools.router --insecure``), the world (``python -m sim``, 3 robots by default)
and the workers as separate processes on loopback, then has one client thread per robot
sweep its head (``--frames`` pictures in all, after ``--warmup`` each) the way an agent
asks: zenoh's best-matching target, one query at a time per robot. It measures the
wall time and the CPU time of the serving processes (world + workers + router, from
``/proc/PID/stat``; the clients' own CPU is reported apart) over the timed frames and
prints frames per wall second, frames per CPU-second and CPU-seconds per frame, and who
served how many (from the processes' summary lines).

On a 2-core machine shared with other jobs wall-time throughput cannot grow with the
workers; CPU-seconds per frame is the number that carries to a machine with more cores
(there frames per second should scale with the workers, up to one core per worker).
Writes ``render_bench.json`` and ``render_bench.png`` into ``--out`` if given.

``--renderer`` and ``--camera-encoding`` are passed to the world and the workers
(:mod:`sim.camera.renderer`, :mod:`agent.wire.picture`). With
``--in-process`` it instead times ``World.render`` itself, no processes, no encoding, no bus:
for each renderer of ``--renderers`` and each fleet size of ``--fleets`` it draws
``--frames`` pictures (observers and head yaws cycling, after 2 untimed ones) and prints
frames per CPU-second of this process (every thread: llvmpipe's too) and per wall
second, each beside the 1-minute load average.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Any

import zenoh

from agent.wire import CameraReply, CameraRequest, decode, encode, key_camera
from agent.wire.picture import DEFAULT_ENCODING, ENCODINGS
from sim.camera.renderer import RENDERERS, check
from tools.harness.procs import ROOT, Proc, free_port, stop
from tools.harness.render import served, start_render_workers

TICKS = os.sysconf("SC_CLK_TCK")


def cpu_s(pid: int) -> float:
    """User + system CPU seconds of process ``pid`` (its own, not its children's)."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / TICKS


def _start(name: str, cmd: list[str], out: Path, ready: str, timeout: float = 120.0) -> Proc:
    log = (out / f"{name}.log").open("wb")
    p = subprocess.Popen(cmd, cwd=ROOT, stdout=log, stderr=subprocess.STDOUT)
    proc = Proc(name, p, log)
    deadline = time.monotonic() + timeout
    while ready not in (out / f"{name}.log").read_text(errors="replace"):
        if p.poll() is not None or time.monotonic() > deadline:
            stop(proc)
            raise RuntimeError(f"{name} did not start; see {out / f'{name}.log'}")
        time.sleep(0.1)  # polling the log for the ready line, bounded by the deadline
    return proc


def sweep(endpoint: str, robots: int, frames: int, warmup: int) -> tuple[float, float, list[float]]:
    """(wall s, client CPU s, per-frame latencies) of ``frames`` timed pictures, one
    thread per robot, each first asking ``warmup`` untimed ones."""
    cfg = zenoh.Config()
    cfg.insert_json5("mode", json.dumps("client"))
    cfg.insert_json5("connect/endpoints", json.dumps([endpoint]))
    cfg.insert_json5("scouting/multicast/enabled", "false")
    lat: list[float] = []
    lock = threading.Lock()
    start = threading.Barrier(robots + 1)
    with zenoh.open(cfg) as s:

        def ask(rid: int, i: int) -> float:
            yaw = math.radians(-119.0 + (i * 37.0) % 238.0)
            t0 = time.perf_counter()
            for r in s.get(
                key_camera(rid),
                payload=encode(CameraRequest(yaw=yaw)),
                target=zenoh.QueryTarget.BEST_MATCHING,
                timeout=60,
            ):
                if r.ok is not None:
                    decode(r.ok.payload.to_bytes(), expect=CameraReply)
                    return time.perf_counter() - t0
            raise RuntimeError(f"no picture for robot {rid}")

        def run(rid: int, n: int) -> None:
            for i in range(warmup):
                ask(rid, i)
            start.wait()
            for i in range(n):
                dt = ask(rid, warmup + i)
                with lock:
                    lat.append(dt)

        share = [frames // robots + (1 if k < frames % robots else 0) for k in range(robots)]
        threads = [
            threading.Thread(target=run, args=(rid, share[rid - 1])) for rid in range(1, robots + 1)
        ]
        for t in threads:
            t.start()
        start.wait()
        c0, t0 = time.process_time(), time.perf_counter()
        for t in threads:
            t.join()
        return time.perf_counter() - t0, time.process_time() - c0, lat


def in_process(renderer: str, robots: int, seed: int, frames: int) -> dict[str, Any]:
    """Frames per CPU-second and per wall second of ``World.render`` with ``robots`` NAOs."""
    from sim.physics.world import World
    from sim.scenarios import generate

    with World(generate(robots, seed), noise=False, renderer=renderer) as w:
        ids = w.robot_ids
        for rid in ids[:2]:
            w.render(rid, 0.0)
        c0, t0 = time.process_time(), time.perf_counter()
        for i in range(frames):
            w.render(ids[i % len(ids)], math.radians(-119.0 + (i * 37.0) % 238.0))
        cpu, wall = time.process_time() - c0, time.perf_counter() - t0
        used = w.renderer
    return {
        "renderer": used,
        "robots": robots,
        "frames": frames,
        "frames_per_cpu_s": frames / cpu,
        "cpu_ms_per_frame": 1000 * cpu / frames,
        "frames_per_s": frames / wall,
        "load_average_1min": os.getloadavg()[0],
    }


def measure(
    workers: int,
    robots: int,
    seed: int,
    frames: int,
    warmup: int,
    out: Path,
    renderer: str | None = None,
    encoding: str = DEFAULT_ENCODING,
) -> dict[str, Any]:
    out.mkdir(parents=True, exist_ok=True)
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    net = ["--connect", endpoint, "--no-multicast-scouting", "--insecure"]
    procs: list[Proc] = []
    try:
        router = [sys.executable, "-m", "tools.router", "--insecure", "--listen", endpoint,
                  "--no-multicast-scouting"]  # fmt: skip
        procs.append(_start("router", router, out, "router ready"))
        kind = ["--renderer", renderer] if renderer else []
        world = [sys.executable, "-m", "sim", "--robots", str(robots), "--seed", str(seed), *net,
                 *kind, "--camera-encoding", encoding]  # fmt: skip
        procs.append(_start("world", world, out, "sim ready"))
        if workers:
            procs.extend(
                start_render_workers(workers, net, out, renderer=renderer, encoding=encoding)
            )
        time.sleep(1.0)  # let the router learn every queryable
        before = {p.name: cpu_s(p.popen.pid) for p in procs}
        t_wall, t_client, lat = sweep(endpoint, robots, frames, warmup)
        after = {p.name: cpu_s(p.popen.pid) for p in procs}
    finally:
        for p in reversed(procs):
            stop(p, 20.0)
    cpu = {k: after[k] - before[k] for k in before}
    serving = sum(cpu.values())
    lat.sort()
    world_log = (out / "world.log").read_text(errors="replace")
    world_cam = 0
    for part in world_log.split():
        if part.startswith("camera="):
            world_cam = int(part.split("=")[1])
    return {
        "workers": workers,
        "camera_encoding": encoding,
        "load_average_1min": os.getloadavg()[0],
        "frames": len(lat),
        "wall_s": t_wall,
        "frames_per_s": len(lat) / t_wall,
        "cpu_s": cpu,
        "serving_cpu_s": serving,
        "client_cpu_s": t_client,
        "frames_per_cpu_s": len(lat) / serving,
        "cpu_s_per_frame": serving / len(lat),
        "latency_median_s": lat[len(lat) // 2],
        "served": {"world": world_cam, **{f"render-{i}": served(out / f"render-{i}.log")
                                           for i in range(1, workers + 1)}},
    }  # fmt: skip


def plot(rows: list[dict[str, Any]], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    modes = sorted({r["workers"] for r in rows})
    labels = ["in the world" if k == 0 else f"{k} worker{'s' * (k > 1)}" for k in modes]
    fig, ax = plt.subplots(1, 2, figsize=(9.5, 3.6))
    for x, k in enumerate(modes):  # every run a dot (repeats), the bar their mean
        mine = [r for r in rows if r["workers"] == k]
        per_cpu = [r["frames_per_cpu_s"] for r in mine]
        per_s = [r["frames_per_s"] for r in mine]
        ax[0].bar(x, sum(per_cpu) / len(per_cpu), color="#4a7", alpha=0.7)
        ax[0].plot([x] * len(mine), per_cpu, "ko", ms=4)
        ax[1].bar(x, sum(per_s) / len(per_s), color="#47a", alpha=0.7)
        ax[1].plot([x] * len(mine), per_s, "ko", ms=4)
        for r in mine:
            ax[1].annotate(
                f"load {r['load_average_1min']:.0f}",
                (x, r["frames_per_s"]),
                xytext=(6, -3),
                textcoords="offset points",
                fontsize=7,
            )
    ax[0].set_ylabel("frames per CPU-second")
    ax[0].set_title("per CPU-second (world + workers + router)", fontsize=10)
    ax[1].set_ylabel("frames per wall second")
    ax[1].set_title(f"per wall second, {os.cpu_count()} cores shared (1-min load)", fontsize=10)
    for a in ax:
        a.set_xticks(range(len(modes)), labels, fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def in_process_table(renderers: list[str], fleets: list[str], seed: int, frames: int) -> int:
    for n in (int(f) for f in fleets):
        for kind in renderers:
            r = in_process(check(kind), n, seed, frames)
            print(
                f"{r['robots']:3d} NAOs {r['renderer']:>4}: {r['frames_per_cpu_s']:5.1f} frames per "
                f"CPU-second ({r['cpu_ms_per_frame']:.1f} CPU-ms a frame), "
                f"{r['frames_per_s']:5.1f} per wall second; load {r['load_average_1min']:.1f}",
                flush=True,
            )
    return 0


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(
        prog="python -m tools.bench render", description=__doc__.split("\n")[0]
    )
    p.add_argument("--modes", default="0,1,2", help="render workers per run (0: the world draws)")
    p.add_argument("--robots", type=int, default=3)
    p.add_argument("--seed", type=int, default=7)
    p.add_argument("--frames", type=int, default=60, help="timed pictures per run")
    p.add_argument("--out", type=Path, default=Path("out/bench_render"))
    p.add_argument("--warmup", type=int, default=1, help="untimed pictures per robot first")
    p.add_argument("--renderer", choices=RENDERERS, default=None, help="the world's and workers'")
    p.add_argument(
        "--camera-encoding",
        choices=ENCODINGS,
        default=DEFAULT_ENCODING,
        help="the world's and workers' (agent/wire/picture.py)",
    )
    p.add_argument("--in-process", action="store_true", help="time World.render itself")
    p.add_argument("--renderers", default="tiny,egl", help="with --in-process: renderers")
    p.add_argument("--fleets", default="3,10,50", help="with --in-process: NAOs per world")
    a = p.parse_args(argv)
    if a.in_process:
        return in_process_table(a.renderers.split(","), a.fleets.split(","), a.seed, a.frames)
    rows = []
    for k in (int(x) for x in a.modes.split(",")):
        out = a.out / f"workers-{k}"
        r = measure(k, a.robots, a.seed, a.frames, a.warmup, out, a.renderer, a.camera_encoding)
        rows.append(r)
        print(
            f"workers={k} {a.camera_encoding}: {r['frames']} frames in {r['wall_s']:.1f} s wall "
            f"({r['frames_per_s']:.2f}/s, median {1000 * r['latency_median_s']:.0f} ms); "
            f"serving CPU {r['serving_cpu_s']:.1f} s -> {r['frames_per_cpu_s']:.2f} frames per "
            f"CPU-second, {1000 * r['cpu_s_per_frame']:.0f} CPU-ms per frame; served {r['served']}",
            flush=True,
        )
    a.out.mkdir(parents=True, exist_ok=True)
    (a.out / "render_bench.json").write_text(json.dumps(rows, indent=1))
    plot(rows, a.out / "render_bench.png")
    print(f"wrote {a.out / 'render_bench.json'} and {a.out / 'render_bench.png'}")
    return 0
