"""``python -m tools.bench world``: camera latency over zenoh and sim speed.

1. Starts ``python -m sim`` (3 robots) listening on a loopback port, connects a zenoh
   session and times ``--requests`` camera queries at varying head yaws: render + encode
   (the world's default, :mod:`agent.wire.picture`) + transfer + decode of the reply
   (target: median under 100 ms at 640 x 480). The in-process render time and each
   encoding's encode time are measured too, for the breakdown.
2. For each fleet size (``--fleets``, default 3, 15, 50) keeps every robot busy
   (alternating 0.2 m walks and 15° turns, as the agents do) for ``--sim-seconds`` of
   sim time and prints how many times faster than real time the clock advanced (target:
   at least 10x with 15 robots): in-process (the world's own cost) and with
   ``python -m sim`` driven over zenoh (each next command sent when the last replies).

3. Camera throughput with 3 robots sweeping their heads at once, rendered in the world
   process and by 2 render workers (``--render-workers 2``).
4. Prints the heading error of one open-loop walk over 300 seeded robots against the NAO
   paper's Table 2.

Writes ``world_bench.png`` (latency histogram, speed bars) and ``noise_vs_table2.png``
into ``--out`` if given.
"""

from __future__ import annotations

import argparse
import json
import math
import queue
import sys
import threading
import time
from pathlib import Path
from typing import Any

import numpy as np

from agent.wire import picture
from tools.harness.procs import free_port, start_world, stop, wait_ready


class WorldProcess:
    """``python -m sim`` on a loopback port (``tools.harness``), waited for until it prints
    its ready line; its logs go nowhere."""

    def __init__(self, robots: int, seed: int, render_workers: int = 0) -> None:
        self.endpoint = f"tcp/127.0.0.1:{free_port()}"
        extra = ["--render-workers", str(render_workers)]
        self.world = start_world(robots, seed, self.endpoint, None, extra)
        try:
            wait_ready(self.world, 60.0)
        except RuntimeError:
            self.stop()
            raise

    def session(self) -> Any:
        import zenoh

        cfg = zenoh.Config()
        cfg.insert_json5("connect/endpoints", json.dumps([self.endpoint]))
        cfg.insert_json5("scouting/multicast/enabled", "false")
        return zenoh.open(cfg)

    def stop(self) -> None:
        stop(self.world, 20.0)


def camera_latency(requests: int, seed: int) -> list[float]:
    from agent.wire import CameraReply, CameraRequest, decode, encode, key_camera

    world = WorldProcess(3, seed)
    try:
        times: list[float] = []
        with world.session() as s:
            for i in range(requests + 3):
                yaw = math.radians(-119.5 + (i * 37.0) % 239.0)
                t0 = time.perf_counter()
                rep = None
                for r in s.get(key_camera(1), payload=encode(CameraRequest(yaw=yaw)), timeout=20):
                    if r.ok is not None:
                        rep = decode(r.ok.payload.to_bytes(), expect=CameraReply)
                if rep is None:
                    if i < 3:  # the link may still be coming up
                        time.sleep(0.2)
                        continue
                    raise RuntimeError("camera query got no reply")
                img = picture.picture_of(rep.encoding, rep.width, rep.height, rep.data)
                dt = time.perf_counter() - t0
                if img.shape != (480, 640, 3):
                    raise RuntimeError(f"camera reply is {img.shape}, not a 640x480 picture")
                if i >= 3:
                    times.append(dt)
                    print(f"  camera {i - 2}/{requests}: {dt * 1000:.0f} ms", file=sys.stderr)
        return times
    finally:
        world.stop()


def camera_throughput(seed: int, workers: int, clients: int = 3, each: int = 8) -> float:
    """Images per second when ``clients`` robots sweep their heads at the same time."""
    from agent.wire import CameraReply, CameraRequest, decode, encode, key_camera

    world = WorldProcess(clients, seed, render_workers=workers)
    try:
        with world.session() as s:
            for rid in range(1, clients + 1):  # warm up the links
                list(s.get(key_camera(rid), payload=encode(CameraRequest(yaw=0.0)), timeout=30))
            errors: list[str] = []

            def sweep(rid: int) -> None:
                for k in range(each):
                    yaw = math.radians(-100.0 + 200.0 * k / max(1, each - 1))
                    payload = encode(CameraRequest(yaw=yaw))
                    ok = False
                    for r in s.get(key_camera(rid), payload=payload, timeout=60):
                        if r.ok is not None:
                            ok = isinstance(decode(r.ok.payload.to_bytes()), CameraReply)
                    if not ok:
                        errors.append(f"robot {rid} request {k}")

            threads = [threading.Thread(target=sweep, args=(r,)) for r in range(1, clients + 1)]
            t0 = time.perf_counter()
            for t in threads:
                t.start()
            for t in threads:
                t.join()
            wall = time.perf_counter() - t0
            if errors:
                raise RuntimeError(f"camera requests failed: {errors[:3]}")
        return clients * each / wall
    finally:
        world.stop()


def sim_speed_bus(n: int, seed: int, sim_seconds: float) -> float:
    """Sim speed of ``python -m sim`` driven over zenoh: every robot gets its next walk or
    turn as soon as its previous one replies (what a fleet of agents does at most)."""
    from agent.wire import (
        CommandReply,
        TurnRequest,
        WalkRequest,
        decode,
        encode,
        key_turn,
        key_walk,
    )

    world = WorldProcess(n, seed)
    try:
        replies: queue.Queue[tuple[int, bytes | None]] = queue.Queue()
        with world.session() as s:
            count = dict.fromkeys(range(1, n + 1), 0)

            def send(rid: int) -> None:
                k = count[rid]
                count[rid] += 1
                if k % 2 == 0:
                    key, msg = key_walk(rid), encode(WalkRequest(distance=0.2))
                else:
                    angle = math.radians(15.0 if k % 4 == 1 else -15.0)
                    key, msg = key_turn(rid), encode(TurnRequest(angle=angle))

                def on_reply(r: Any, rid: int = rid) -> None:
                    replies.put((rid, r.ok.payload.to_bytes() if r.ok is not None else None))

                s.get(key, on_reply, payload=msg, timeout=60.0)

            t0 = time.perf_counter()
            for rid in range(1, n + 1):
                send(rid)
            t_sim = 0.0
            while t_sim < sim_seconds:
                rid, data = replies.get(timeout=60.0)
                if data is None:
                    raise RuntimeError(f"robot {rid}: error reply")
                rep = decode(data, expect=CommandReply)
                t_sim = max(t_sim, rep.t_sim)
                send(rid)
            wall = time.perf_counter() - t0
        return t_sim / wall
    finally:
        world.stop()


def render_breakdown(n: int, seed: int) -> tuple[float, float, dict[str, float]]:
    """Median render wall and CPU seconds of ``n`` pictures, and each encoding's median
    encode seconds."""
    from sim.physics.world import World
    from sim.scenarios import generate

    with World(generate(3, seed)) as w:
        tr: list[float] = []
        tc: list[float] = []
        te: dict[str, list[float]] = {e: [] for e in picture.ENCODINGS}
        for i in range(n):
            c0 = time.process_time()
            t0 = time.perf_counter()
            img = w.render(1, math.radians(-119.5 + (i * 37.0) % 239.0))
            t1 = time.perf_counter()
            tc.append(time.process_time() - c0)
            for enc, times in te.items():
                t2 = time.perf_counter()
                picture.picture_data(img, enc)
                times.append(time.perf_counter() - t2)
            tr.append(t1 - t0)
    return (
        float(np.median(tr)),
        float(np.median(tc)),
        {e: float(np.median(v)) for e, v in te.items()},
    )


def sim_speed(n: int, seed: int, sim_seconds: float) -> tuple[float, float]:
    """(sim seconds per wall second, per CPU second of this process) with ``n`` robots."""
    from sim.physics.world import World
    from sim.scenarios import generate

    with World(generate(n, seed)) as w:
        loco = w.locomotion
        nxt = {rid: 0 for rid in w.robot_ids}

        def command(rid: int) -> None:
            if nxt[rid] % 2 == 0:
                loco.walk(rid, 0.2)
            else:
                loco.turn(rid, math.radians(15.0 if nxt[rid] % 4 == 1 else -15.0))
            nxt[rid] += 1

        for rid in w.robot_ids:
            command(rid)
        t0 = time.perf_counter()
        c0 = time.process_time()
        while loco.t_sim < sim_seconds:
            done, _ = loco.step()
            for d in done:
                command(d.robot_id)
        wall = time.perf_counter() - t0
        cpu = time.process_time() - c0
    return loco.t_sim / wall, loco.t_sim / max(cpu, 1e-9)


# NAO paper Table 2: (distance m, heading error rad) of one NAO walking open loop; the two
# starred values (0.3 m: 0.3734, 0.7 m: 0.5292) are the paper's "heave sway" outliers.
TABLE2 = (
    (0.2, -0.0211), (0.2, 0.0957), (0.3, 0.3734), (0.3, -0.0379), (0.4, 0.0125),
    (0.4, -0.1579), (0.5, 0.1374), (0.5, 0.1698), (0.7, 0.5292), (0.7, 0.2274),
    (0.8, 0.334), (0.8, 0.4465), (1.0, 0.4493), (1.0, 0.4062),
)  # fmt: skip


def noise_vs_table2(robots: int, out: Path | None) -> None:
    """Heading error after one open-loop walk, over seeded robots, against Table 2."""
    from sim.physics.locomotion import Locomotion

    class Store:
        robot_ids: tuple[int, ...] = (1,)

        def __init__(self) -> None:
            self.p = (0.0, 0.0, math.pi / 2)

        def pose(self, robot_id: int) -> tuple[float, float, float]:
            return self.p

        def set_pose(self, robot_id: int, x: float, y: float, heading: float) -> None:
            self.p = (x, y, heading)

    dists = (0.2, 0.3, 0.4, 0.5, 0.7, 0.8, 1.0)
    errs: dict[float, np.ndarray] = {}
    for d in dists:
        e: list[float] = []
        for seed in range(robots):
            st = Store()
            loco = Locomotion(st, seed=seed)
            loco.walk(1, d)
            loco.run_until_idle()
            e.append(st.p[2] - math.pi / 2)
        errs[d] = np.array(e)
    print("heading error after one walk (rad): distance, model RMS, model mean|e|, Table 2")
    for d in dists:
        t2 = ", ".join(f"{v:+.3f}" for dd, v in TABLE2 if dd == d)
        ed = errs[d]
        print(f"  {d:.1f} m: {np.sqrt(np.mean(ed**2)):.3f}  {np.mean(np.abs(ed)):.3f}   [{t2}]")
    if out is None:
        return
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6, 4))
    for d in dists:
        ax.scatter(np.full(60, d) + np.linspace(-0.02, 0.02, 60), errs[d][:60], s=4, c="0.6")
    rms = [float(np.sqrt(np.mean(errs[d] ** 2))) for d in dists]
    ax.plot(dists, rms, "b-", label="model RMS (over robots)")
    ax.plot(dists, [-r for r in rms], "b-")
    ax.scatter([d for d, _ in TABLE2], [e for _, e in TABLE2], c="r", marker="x", s=40,
               label="NAO paper Table 2")  # fmt: skip
    ax.set_xlabel("open-loop walk (m)")
    ax.set_ylabel("heading error (rad)")
    ax.legend()
    fig.tight_layout()
    fig.savefig(out / "noise_vs_table2.png", dpi=90)
    plt.close(fig)
    print(f"wrote {out / 'noise_vs_table2.png'}")


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(
        prog="python -m tools.bench world", description=__doc__.split("\n")[0]
    )
    p.add_argument("--requests", type=int, default=30)
    p.add_argument("--fleets", default="3,15,50")
    p.add_argument("--sim-seconds", type=float, default=60.0)
    p.add_argument("--seed", type=int, default=1)
    p.add_argument("--out", help="directory for world_bench.png")
    args = p.parse_args(argv)
    if args.out:
        Path(args.out).mkdir(parents=True, exist_ok=True)
    try:
        fleets = [int(v) for v in args.fleets.split(",") if v]
    except ValueError:
        print("--fleets: comma-separated robot counts", file=sys.stderr)
        return 2
    print(f"camera over zenoh (loopback, 640x480 {picture.DEFAULT_ENCODING}) ...", file=sys.stderr)
    lat = np.array(camera_latency(args.requests, args.seed)) * 1000
    render_s, render_cpu_s, encode_s = render_breakdown(10, args.seed)
    encodes = ", ".join(f"{e} encode {t * 1000:.1f} ms" for e, t in encode_s.items())
    print(
        f"camera request: median {np.median(lat):.1f} ms, p95 {np.percentile(lat, 95):.1f} ms "
        f"(n={lat.size}; in-process render {render_s * 1000:.1f} ms wall / "
        f"{render_cpu_s * 1000:.1f} ms CPU, {encodes})"
    )
    for workers in (0, 2):
        print(f"camera throughput, render workers {workers} ...", file=sys.stderr)
        rate = camera_throughput(args.seed, workers)
        print(
            f"camera throughput, 3 robots sweeping at once, render workers {workers}: "
            f"{rate:.1f} images/s"
        )
    speeds = {}
    for n in fleets:
        print(f"sim speed with {n} robots walking ...", file=sys.stderr)
        speeds[n], per_cpu = sim_speed(n, args.seed, args.sim_seconds)
        bus = sim_speed_bus(n, args.seed, args.sim_seconds)
        print(
            f"sim speed, {n:3d} robots walking: {speeds[n]:7.1f}x real time in-process "
            f"({per_cpu:.1f}x per CPU second), {bus:7.1f}x driven over zenoh"
        )
    noise_vs_table2(300, Path(args.out) if args.out else None)
    if args.out:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        out = Path(args.out)
        fig, (a, b) = plt.subplots(1, 2, figsize=(10, 4))
        a.hist(lat, bins=20)
        a.axvline(100, color="r", ls="--", label="target 100 ms")
        a.set_xlabel("camera request latency (ms)")
        a.legend()
        b.bar([str(n) for n in speeds], list(speeds.values()))
        b.axhline(10, color="r", ls="--", label="target 10x (15 robots)")
        b.set_xlabel("robots walking")
        b.set_ylabel("x real time")
        b.set_yscale("log")
        b.legend()
        fig.tight_layout()
        fig.savefig(out / "world_bench.png", dpi=90)
        print(f"wrote {out / 'world_bench.png'}")
    return 0
