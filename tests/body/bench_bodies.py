"""What a body costs per camera frame and per motion, by body (the zenoh, NAOqi and in-process
bodies measured).

    python -m tests.body.bench_bodies [--n 40]

The same world (robot 1 facing robot 2, as in the contract suite) behind each body of
:mod:`tests.body.conftest`: in-process (the world's own cost: render, stepping), zenoh
(PNG + msgpack over a zenoh query to the world loop) and NAOqi (qi call to a virtual
NAO, which queues the request on the same world loop; raw BGR over qi). Prints the
median and 90th percentile wall time of ``camera(yaw)``, ``walk(0.02)`` and
``turn(0.05)``, and each body's overhead over the in-process one (median of paired
differences: the three bodies take turns, so a busy machine slows them alike).
Not collected by pytest (no ``test_`` prefix).
"""

from __future__ import annotations

import argparse
import contextlib
import statistics
import time
from collections.abc import Callable

from agent.body.base import Body
from tests.body.conftest import FACING, KINDS, rig


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m tests.body.bench_bodies")
    p.add_argument("--n", type=int, default=40, help="repetitions of each action")
    args = p.parse_args(argv)
    actions: dict[str, Callable[[Body, int], object]] = {
        "camera": lambda b, i: b.camera((0.0, 0.4, -0.4)[i % 3]),
        "walk": lambda b, i: b.walk(0.02 if i % 2 == 0 else -0.02),
        "turn": lambda b, i: b.turn(0.05 if i % 2 == 0 else -0.05),
    }
    times: dict[str, dict[str, list[float]]] = {k: {a: [] for a in actions} for k in KINDS}
    with contextlib.ExitStack() as stack:
        bodies = {k: stack.enter_context(rig(k, FACING)).make(1) for k in KINDS}
        for act, fn in actions.items():
            for b in bodies.values():
                fn(b, 0)  # warm up (connections, first render)
            # round robin over the bodies: a busy machine slows all three alike
            for i in range(args.n):
                for k, b in bodies.items():
                    t = time.perf_counter()
                    fn(b, i)
                    times[k][act].append(time.perf_counter() - t)
    print(f"{'body':8} {'action':7} {'median ms':>10} {'p90 ms':>8} {'overhead ms':>12}")
    for kind, acts in times.items():
        for act, ts in acts.items():
            med = statistics.median(ts)
            p90 = sorted(ts)[int(0.9 * (len(ts) - 1))]
            # median of the paired differences to the in-process body
            over = statistics.median(a - b for a, b in zip(ts, times["world"][act], strict=True))
            print(f"{kind:8} {act:7} {1000 * med:10.2f} {1000 * p90:8.2f} {1000 * over:12.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
