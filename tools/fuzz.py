"""``python -m tools.fuzz``: attack the wire codec and the world as an attacker would (every input
hardened).

    python -m tools.fuzz --n 1000000 [--seed 1] [--json FILE]
    python -m tools.fuzz --n 0 --flood                  (start a world on loopback)
    python -m tools.fuzz --n 0 --connect tcp/HOST:7447  (flood a running world)

Three measurements:

1. **Fuzz**: ``--n`` payloads, spread evenly over the message types, each derived from a
   valid message of its type (structure mutations: wrong types, extra and missing
   fields, odd versions and tags, long sequences, text/binary keys; byte mutations:
   flips, truncation, insertion, msgpack type bytes; random bytes) and fed to
   :func:`agent.wire.decode`. Prints per type: accepted / rejected (ProtocolError) /
   crashed (any other exception: a bug) and the time. Target: 0 crashes in 10^6.
2. **Memory** (``--no-memory`` skips it): the peak memory of decoding each of the worst
   payloads under the size limit (8 MiB of empty arrays, nesting, 8 MiB of short
   strings, the largest valid image message, ...), measured with ``tracemalloc``.
   Target: under 50 MB for any single payload.
3. **Flood** (``--flood`` or ``--connect``): 10 000 malformed requests (``--flood-n``) sent
   to a world without waiting, then a valid camera request, timed against the same
   request on an idle world. Target: delayed by under 1 s.

Exit status 0 when every target is met, 1 otherwise, 2 on bad arguments.
The payloads come from :mod:`tools.lib.fuzz_payloads`, whose generators tests/wire/test_fuzz.py
shares for a shorter fuzz in CI; this module runs them and reports.
"""

from __future__ import annotations

import argparse
import json
import math
import random
import shutil
import statistics
import sys
import threading
import time
import tracemalloc
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from agent import wire as P
from tools.harness.procs import free_port, start_world, stop, wait_ready
from tools.lib.fuzz_payloads import TAGS, malformed_requests, payloads, worst_payloads

MEMORY_TARGET = 50 * 1024 * 1024
FLOOD_TARGET_S = 1.0

# ===================================================================== fuzz


@dataclass
class TypeCounts:
    accepted: int = 0
    rejected: int = 0
    crashed: int = 0
    seconds: float = 0.0
    crashes: list[str] = field(default_factory=list)  # first few: exception and payload


def decode_one(data: bytes, c: TypeCounts) -> None:
    try:
        P.decode(data)
        c.accepted += 1
    except P.ProtocolError:
        c.rejected += 1
    except Exception as exc:  # the bug this tool hunts
        c.crashed += 1
        if len(c.crashes) < 5:
            c.crashes.append(f"{type(exc).__name__}: {P.reason(exc, 120)} on {data[:64].hex()}")


def fuzz(
    n: int, seed: int = 1, progress: Callable[[str], None] | None = None
) -> dict[str, TypeCounts]:
    """``n`` payloads spread over the message types through ``decode``."""
    per = max(1, math.ceil(n / len(TAGS))) if n > 0 else 0
    out: dict[str, TypeCounts] = {}
    for tag in TAGS:
        c = TypeCounts()
        t0 = time.perf_counter()
        for data in payloads(seed, tag, per):
            decode_one(data, c)
        c.seconds = time.perf_counter() - t0
        out[tag] = c
        if progress is not None:
            progress(f"{tag:10s} {per} payloads in {c.seconds:.1f} s")
    return out


# ===================================================================== memory


@dataclass
class MemoryResult:
    name: str
    size: int
    peak: int
    seconds: float
    outcome: str


def memory(names: list[str] | None = None) -> list[MemoryResult]:
    """Peak traced memory of taking each worst payload out of a zenoh ``ZBytes`` and
    decoding it, as the bus and the world do (the ZBytes itself, in zenoh's memory, is
    not counted; the copy out of it is)."""
    import zenoh

    out = []
    for name, raw in worst_payloads().items():
        if names and name not in names:
            continue
        zb = zenoh.ZBytes(raw)
        tracemalloc.start()
        tracemalloc.reset_peak()
        base = tracemalloc.get_traced_memory()[0]
        t0 = time.perf_counter()
        try:
            msg = P.decode(P.take_payload(zb, P.MAX_MESSAGE_BYTES))
            outcome = f"accepted {type(msg).__name__}"
            del msg
        except P.ProtocolError as exc:
            outcome = f"rejected: {P.reason(exc, 70)}"
        except Exception as exc:
            outcome = f"CRASHED {P.reason(exc, 70)}"
        dt = time.perf_counter() - t0
        peak = tracemalloc.get_traced_memory()[1] - base
        tracemalloc.stop()
        out.append(MemoryResult(name, len(raw), peak, dt, outcome))
    return out


# ===================================================================== flood


@dataclass
class FloodResult:
    n: int
    baseline_s: list[float]
    send_s: float
    during_s: float
    after_s: float
    error_replies: int
    finished: int
    all_done_s: float = math.nan  # from the first malformed request to the last one's end
    world_summary: str = ""

    @property
    def delay_s(self) -> float:
        return self.during_s - statistics.median(self.baseline_s)


def _timed_camera(session: Any, timeout: float = 60.0) -> float:
    t0 = time.perf_counter()
    for r in session.get(
        P.key_camera(1), payload=P.encode(P.CameraRequest(yaw=0.2)), timeout=timeout
    ):
        if r.ok is not None and isinstance(P.decode(r.ok.payload.to_bytes()), P.CameraReply):
            return time.perf_counter() - t0
    raise RuntimeError("no camera reply")


def flood(endpoint: str | None, n: int = 10_000, seed: int = 1) -> FloodResult:
    """Baseline camera requests, then ``n`` malformed requests without waiting and a valid
    camera request timed while they are served. Starts a world when ``endpoint`` is None."""
    import zenoh

    world = None
    log_dir = None
    if endpoint is None:
        endpoint = f"tcp/127.0.0.1:{free_port()}"
        import tempfile

        log_dir = Path(tempfile.mkdtemp(prefix="fuzz-world-"))
        world = start_world(3, 7, endpoint, log_dir, [])
    cfg = zenoh.Config()
    cfg.insert_json5("connect/endpoints", json.dumps([endpoint]))
    cfg.insert_json5("scouting/multicast/enabled", "false")
    rng = random.Random(seed)
    counts = {"error": 0, "done": 0}
    last_done = [0.0]
    lock = threading.Lock()

    def on_reply(r: Any) -> None:
        if r.ok is not None:
            with lock:
                counts["error"] += 1

    def on_done() -> None:
        with lock:
            counts["done"] += 1
            last_done[0] = time.perf_counter()

    try:
        if world is not None:
            wait_ready(world, 120.0)
        with zenoh.open(cfg) as s:
            deadline = time.monotonic() + 60.0
            while True:  # until the route to the world exists
                try:
                    _timed_camera(s, 5.0)
                    break
                except RuntimeError:
                    if time.monotonic() > deadline:
                        raise
            baseline = [_timed_camera(s) for _ in range(5)]
            t0 = time.perf_counter()
            for key, payload in malformed_requests(rng, n):
                s.get(
                    key, zenoh.handlers.Callback(on_reply, on_done), payload=payload, timeout=30.0
                )
            send = time.perf_counter() - t0
            during = _timed_camera(s)
            after = _timed_camera(s)
            end = time.monotonic() + 60.0
            while time.monotonic() < end and counts["done"] < n:
                time.sleep(0.05)  # polling the reply counter, bounded by the deadline
        result = FloodResult(
            n, baseline, send, during, after, counts["error"], counts["done"], last_done[0] - t0
        )
    finally:
        if world is not None:
            stop(world, 30.0)
    if log_dir is not None:
        log_path = log_dir / "world.log"
        lines = [ln for ln in log_path.read_text(errors="replace").splitlines() if "served" in ln]
        result.world_summary = lines[-1] if lines else ""
        shutil.rmtree(log_dir)
    return result


# ===================================================================== main


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m tools.fuzz", description=__doc__.split("\n")[0])
    ap.add_argument(
        "--n", type=int, default=100_000, help="fuzzed payloads in all (default 100000)"
    )
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--no-memory", action="store_true", help="skip the memory measurement")
    ap.add_argument("--flood", action="store_true", help="flood a world started on loopback")
    ap.add_argument("--connect", default=None, help="flood the running world at this endpoint")
    ap.add_argument("--flood-n", type=int, default=10_000, help="malformed requests (10000)")
    ap.add_argument("--json", type=Path, default=None, help="write the results here")
    args = ap.parse_args(argv)
    if args.n < 0 or args.flood_n < 1:
        print("fuzz: --n must be >= 0 and --flood-n >= 1", file=sys.stderr)
        return 2
    ok = True
    report: dict[str, Any] = {"seed": args.seed}
    if args.n:
        t0 = time.perf_counter()
        from tools.harness.progress import Progress

        bar = Progress(len(TAGS), "fuzz")
        res = fuzz(args.n, args.seed, progress=bar.step)
        total = time.perf_counter() - t0
        print(f"{'type':10s} {'accepted':>9s} {'rejected':>9s} {'crashed':>8s} {'time':>8s}")
        for tag, c in res.items():
            print(f"{tag:10s} {c.accepted:9d} {c.rejected:9d} {c.crashed:8d} {c.seconds:7.1f}s")
            for line in c.crashes:
                print(f"    crash: {line}")
        n = sum(c.accepted + c.rejected + c.crashed for c in res.values())
        crashed = sum(c.crashed for c in res.values())
        print(f"{'all':10s} {sum(c.accepted for c in res.values()):9d} "
              f"{sum(c.rejected for c in res.values()):9d} {crashed:8d} {total:7.1f}s "
              f"({n / total:,.0f} payloads/s)")  # fmt: skip
        report["fuzz"] = {tag: vars(c) for tag, c in res.items()}
        report["fuzz_total"] = {"n": n, "crashed": crashed, "seconds": total}
        ok &= crashed == 0
    if not args.no_memory:
        print(
            f"\n{'worst payload under the size limit':38s} {'size':>9s} {'peak':>9s} {'time':>8s}"
        )
        mem = memory()
        for m in mem:
            print(f"{m.name:38s} {m.size / 2**20:6.2f} MiB {m.peak / 2**20:6.2f} MiB "
                  f"{1000 * m.seconds:6.1f} ms  {m.outcome}")  # fmt: skip
        worst = max(mem, key=lambda m: m.peak)
        print(f"worst: {worst.name}: {worst.peak / 2**20:.1f} MiB (target < 50 MB)")
        report["memory"] = [vars(m) for m in mem]
        ok &= worst.peak < MEMORY_TARGET and not any("CRASHED" in m.outcome for m in mem)
    if args.flood or args.connect:
        fr = flood(args.connect, args.flood_n, args.seed)
        base = statistics.median(fr.baseline_s)
        print(f"\nflood: {fr.n} malformed requests sent in {fr.send_s:.2f} s")
        print(f"  valid camera request: idle {base:.3f} s (median of 5), during the flood "
              f"{fr.during_s:.3f} s, after {fr.after_s:.3f} s: delayed {fr.delay_s:+.3f} s "
              f"(target < {FLOOD_TARGET_S:g} s)")  # fmt: skip
        print(f"  malformed: {fr.error_replies} error replies, {fr.finished} queries finished, "
              f"the last {fr.all_done_s:.2f} s after the first was sent")  # fmt: skip
        if fr.world_summary:
            print(f"  world: {fr.world_summary}")
        report["flood"] = dict(vars(fr), delay_s=fr.delay_s)
        ok &= fr.delay_s < FLOOD_TARGET_S
    if args.json is not None:
        args.json.write_text(json.dumps(report, indent=1, default=str))
    print("\nall targets met" if ok else "\nTARGET MISSED")
    return 0 if ok else 1


if __name__ == "__main__":
    raise SystemExit(main())
