"""``python -m tools.bench plan``: planning time vs fleet size, per strategy.

Fleet: a jittered square grid with the paper's simulation spacing (d_e = 2 m, starts
0.9·d_e apart ± 0.15·d_e, robot radius 0.2 m), ids shuffled; the clock covers
``plan_from_positions`` (pyramid, assignment, safety waves and detours). Exact solvers
(``optimal``, ``capt``) run only up to ``--exact-max`` robots. Prints a table of seconds,
the fitted growth exponent k of t ~ n^k per strategy (fit over n >= 1000), and whether
the plan of every run passed the safety checker (checked outside the clock, up to
``--check-max`` robots). A size is skipped, with the reason printed, once one run of
the strategy took longer than ``--budget`` seconds, when the previous size predicts
(growth n^1.5) more than ``--limit`` seconds, or - sizes above ``--isolate`` run in a
child process instead - when it is not done within ``--limit`` seconds. Wall-clock seconds are the table; the
process CPU seconds follow (the machine is shared, so wall time includes waiting).
"""

from __future__ import annotations

import argparse
import json
import math
import subprocess
import sys
import time

import numpy as np

from agent.formation.plan import PlanParams, plan_from_positions
from agent.formation.safety import check_safety

D_E = 2.0


def fleet(n: int, seed: int = 0) -> tuple[list[int], np.ndarray]:
    rng = np.random.default_rng(seed)
    g = math.ceil(math.sqrt(n))
    grid = np.stack(np.meshgrid(np.arange(g), np.arange(g)), -1).reshape(-1, 2)[:n].astype(float)
    pos = (grid + rng.uniform(-1 / 6, 1 / 6, grid.shape)) * 0.9 * D_E
    ids = [int(i) for i in rng.permutation(n)]
    return ids, pos


def run_one(strategy: str, n: int, check_max: int) -> tuple[float, float, str]:
    """(wall s, CPU s, verdict) of one planning run (nan seconds if it failed)."""
    ids, pos = fleet(n)
    t0 = time.perf_counter()
    c0 = time.process_time()
    try:
        plan = plan_from_positions(ids, pos, PlanParams(d_e=D_E, strategy=strategy))
    except ValueError as exc:
        return float("nan"), float("nan"), f"fail: {exc}"[:60]
    dt = time.perf_counter() - t0
    dc = time.process_time() - c0
    if n <= check_max:
        ok = not check_safety(plan.paths(), plan.wave_of(), 0.2)
        return dt, dc, f"safe, {len(plan.waves)} waves" if ok else "UNSAFE"
    return dt, dc, f"{len(plan.waves)} waves (not checked)"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(
        prog="python -m tools.bench plan", description=__doc__.splitlines()[0]
    )
    ap.add_argument("--sizes", default="10,100,1000,10000,100000")
    ap.add_argument("--strategies", default="paper,default,optimal,capt")
    ap.add_argument("--exact-max", type=int, default=2000)
    ap.add_argument("--check-max", type=int, default=10000)
    ap.add_argument(
        "--budget", type=float, default=120.0, help="skip larger n once one run exceeds this (s)"
    )
    ap.add_argument(
        "--limit", type=float, default=60.0, help="skip n if predicted (n^1.5) above this (s)"
    )
    ap.add_argument(
        "--isolate",
        type=int,
        default=10000,
        help="sizes above this run in a child process stopped after --limit seconds",
    )
    ap.add_argument("--one", nargs=2, metavar=("STRATEGY", "N"), help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.one:
        print(json.dumps(run_one(args.one[0], int(args.one[1]), args.check_max)))
        return 0
    try:
        sizes = [int(x) for x in args.sizes.split(",") if x]
    except ValueError:
        print("error: --sizes must be a comma list of ints", file=sys.stderr)
        return 2
    strategies = [s for s in args.strategies.split(",") if s]
    times: dict[str, dict[int, float]] = {s: {} for s in strategies}
    cpu: dict[str, dict[int, float]] = {s: {} for s in strategies}
    safe: dict[str, dict[int, str]] = {s: {} for s in strategies}
    for s in strategies:
        skip = False
        last: tuple[int, float] | None = None
        for n in sizes:
            predicted = last[1] * (n / last[0]) ** 1.5 if last else 0.0
            if skip or (s in ("optimal", "capt") and n > args.exact_max):
                safe[s][n] = "skipped (budget)" if skip else "skipped (exact solver)"
                continue
            if predicted > args.limit and n <= args.isolate:
                safe[s][n] = f"skipped (predicted {predicted:.0f} s > --limit {args.limit:g} s)"
                continue
            print(f"[bench plan] {s} n={n} ...", file=sys.stderr)
            if n > args.isolate:  # in a child process, stopped after --limit seconds
                cmd = [sys.executable, "-m", "tools.bench.plan", "--one", s, str(n)]
                cmd += ["--check-max", str(args.check_max)]
                try:
                    res = subprocess.run(
                        cmd, capture_output=True, text=True, timeout=args.limit, check=False
                    )
                    dt, dc, verdict = json.loads(res.stdout.strip().splitlines()[-1])
                except subprocess.TimeoutExpired:
                    safe[s][n] = f"skipped (not done within --limit {args.limit:g} s)"
                    skip = True
                    continue
                except (ValueError, IndexError):
                    safe[s][n] = "fail: child process gave no result"
                    continue
            else:
                dt, dc, verdict = run_one(s, n, args.check_max)
            times[s][n] = dt
            safe[s][n] = verdict
            if math.isfinite(dt):
                cpu[s][n] = dc
                last = (n, dt)
                if dt > args.budget:
                    skip = True
    for title, table in (("wall s", times), ("cpu s", cpu)):
        print(f"{title:10s} " + " ".join(f"{n:>10d}" for n in sizes) + "   exponent")
        for s in strategies:
            row = []
            for n in sizes:
                t = table[s].get(n)
                row.append(f"{'-':>10s}" if t is None else f"{t:10.3f}")
            pts = [(n, t) for n, t in table[s].items() if n >= 1000 and math.isfinite(t) and t > 0]
            if len(pts) < 2:
                pts = [(n, t) for n, t in table[s].items() if math.isfinite(t) and t > 0]
            exp = "-"
            if len(pts) >= 2:
                x = np.log([p[0] for p in pts])
                y = np.log([p[1] for p in pts])
                exp = f"{np.polyfit(x, y, 1)[0]:.2f}"
            print(f"{s:10s} " + " ".join(row) + f"   {exp}")
    print(
        "safety: "
        + "; ".join(
            f"{s} " + ", ".join(f"n={n}: {v}" for n, v in safe[s].items()) for s in strategies
        )
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
