"""What a body costs per camera frame and per motion, by body (issue #11 measurements).

    python -m tests.body.bench_bodies [--n 40]

The same world (robot 1 facing robot 2, as in the contract suite) behind each body of
:mod:`tests.body.conftest`: in-process (the world's own cost: render, stepping), zenoh
(PNG + msgpack over a zenoh query to the world loop) and NAOqi (qi call to a virtual
NAO, which queues the request on the same world loop; raw BGR over qi). Prints the
median and 90th percentile wall time of ``camera(yaw)``, ``walk(0.02)`` and
``turn(0.05)``, and each body's overhead over the in-process one (median difference).
Not collected by pytest (no ``test_`` prefix).
"""

from __future__ import annotations

import argparse
import statistics
import time
from collections.abc import Callable

from tests.body.conftest import FACING, KINDS, rig


def timed(fn: Callable[[], object], n: int) -> list[float]:
    fn()  # warm up (connections, first render)
    out = []
    for _ in range(n):
        t = time.perf_counter()
        fn()
        out.append(time.perf_counter() - t)
    return out


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m tests.body.bench_bodies")
    p.add_argument("--n", type=int, default=40, help="repetitions of each action")
    args = p.parse_args(argv)
    rows: dict[str, dict[str, list[float]]] = {}
    for kind in KINDS:
        with rig(kind, FACING) as r:
            body = r.make(1)
            yaws = iter([0.0, 0.4, -0.4] * (args.n + 1))
            steps = iter([0.02, -0.02] * (args.n + 1))
            turns = iter([0.05, -0.05] * (args.n + 1))
            rows[kind] = {
                "camera": timed(lambda: body.camera(next(yaws)), args.n),  # noqa: B023
                "walk": timed(lambda: body.walk(next(steps)), args.n),  # noqa: B023
                "turn": timed(lambda: body.turn(next(turns)), args.n),  # noqa: B023
            }
    print(f"{'body':8} {'action':7} {'median ms':>10} {'p90 ms':>8} {'overhead ms':>12}")
    for kind, acts in rows.items():
        for act, ts in acts.items():
            med = statistics.median(ts)
            p90 = sorted(ts)[int(0.9 * (len(ts) - 1))]
            base = statistics.median(rows["world"][act])
            print(
                f"{kind:8} {act:7} {1000 * med:10.2f} {1000 * p90:8.2f} {1000 * (med - base):12.2f}"
            )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
