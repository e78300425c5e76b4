"""``python -m tools.bench plan``: planning time, makespan, waves and path vs fleet size.

Scale table. Fleet: a jittered square grid with the paper's simulation spacing (d_e = 2 m,
starts 0.9·d_e apart ± 0.15·d_e, robot radius 0.2 m), ids shuffled. Per n and strategy:

* ``plan s``: wall seconds of ``plan_from_positions`` in this process (``cpu s``: its
  CPU seconds; the machine may be shared);
* ``cli s``: wall seconds of the whole ``python -m tools.plan`` process (JSON in, JSON
  out: start-up, parsing, planning, output), with ``--cli``;
* ``ms/capt``: makespan under the dependency rule over CAPT's (the longest straight path
  of the min-sum-of-squares assignment to the centred pyramid); ``wave``: the same under
  the wave rule; ``waves``; ``path/opt``: total path over the min-sum optimum. CAPT and
  the optimum are exact up to ``--exact-max`` robots; above, lower bounds replace them
  (sorted 1-D matchings of the projections on 64 directions, see ``_bounds``) and the
  ratio is printed as an upper bound ``<=x``;
* ``safe``: the plan passed the wave checker and the dependency checker (up to
  ``--check-max`` robots).

The growth exponent k of t ~ n^k is fitted over the sizes from 10^3 to 10^5. Sizes
above ``--isolate`` run in a child process stopped after ``--limit`` seconds. A
*never stuck* row plans ``--stuck-n`` robots (30 000) with the ``paper`` strategy, whose
slot-swap repair gives up at that size: the plan must still come (the banded plan).

Families table (``--families``, on by default): 67 seeded fleets - NAO-like groups of
3-6 at d_e = 0.8 m and uniform, two blobs, line, ring and grid fleets of 6-100 robots at
d_e = 2 m - planned with ``default``: median and worst makespan over CAPT (both rules),
path over the optimum, the share of plans passing both checkers, and, for a 15-robot
demo-like fleet, the robots' summed waiting over their summed walking.

``--png`` draws time vs n (log-log) and makespan over CAPT / waves vs n.
"""

from __future__ import annotations

import argparse
import json
import math
import subprocess
import sys
import time
from typing import Any

import numpy as np

from agent.core.formation.params import D_E as D_NAO  # the real NAOs' d_e (demo_wait)
from agent.core.formation.params import PlanParams
from agent.core.formation.plan import Plan, plan_from_positions
from agent.core.formation.shape.layout import placed
from agent.core.formation.shape.pyramid import pyramid_frame
from agent.core.formation.shape.spec import PYRAMID
from agent.core.formation.waves.execution import (
    capt_makespan,
    check_dependencies,
    dependency_makespan,
    dependency_starts,
    optimal_total,
    path_lengths,
    wave_makespan,
)
from agent.core.formation.waves.safety import check_safety

D_E = 2.0
PHI_E = math.radians(30)
RADIUS = 0.2


def fleet(n: int, seed: int = 0) -> tuple[list[int], np.ndarray]:
    rng = np.random.default_rng(seed)
    g = math.ceil(math.sqrt(n))
    grid = np.stack(np.meshgrid(np.arange(g), np.arange(g)), -1).reshape(-1, 2)[:n].astype(float)
    pos = (grid + rng.uniform(-1 / 6, 1 / 6, grid.shape)) * 0.9 * D_E
    ids = [int(i) for i in rng.permutation(n)]
    return ids, pos


# ----------------------------------------------------------------- fleet families


def _spaced(rng: np.random.Generator, n: int, draw: Any, spacing: float) -> np.ndarray:
    """n points from ``draw()`` kept >= spacing apart (rejection)."""
    pts: list[np.ndarray] = []
    for _ in range(200_000):
        if len(pts) == n:
            break
        p = np.asarray(draw(), dtype=np.float64)
        if all(math.hypot(*(p - q)) >= spacing for q in pts):
            pts.append(p)
    if len(pts) < n:  # pragma: no cover - the areas below leave room
        raise RuntimeError("could not place the fleet")
    return np.array(pts)


def nao_group(n: int, seed: int) -> np.ndarray:
    """The simulator's paper-like start (sim.scenarios.generate's rule): each robot 0.6-1.2
    m from one placed before it, >= 0.6 m from all."""
    rng = np.random.default_rng([seed, n, 0])
    pts = [(0.0, 0.0)]
    while len(pts) < n:
        px, py = pts[int(rng.integers(len(pts)))]
        a, d = rng.uniform(0, 2 * math.pi), rng.uniform(0.6, 1.2)
        q = (px + d * math.cos(a), py + d * math.sin(a))
        if all(math.hypot(q[0] - x, q[1] - y) >= 0.6 for x, y in pts):
            pts.append(q)
    return np.array(pts)


def _disc(rng: np.random.Generator, centre: np.ndarray, r: float) -> np.ndarray:
    a = rng.uniform(0, 2 * math.pi)
    return centre + r * math.sqrt(rng.uniform()) * np.array([math.cos(a), math.sin(a)])


def family(name: str, n: int, seed: int, d_e: float = D_E) -> np.ndarray:
    """A seeded fleet of one family (starts >= 0.6·d_e apart, except line and ring)."""
    rng = np.random.default_rng([seed, n, sum(map(ord, name))])
    sp = 0.6 * d_e
    if name == "uniform":
        side = math.sqrt(n) * 0.9 * d_e
        return _spaced(rng, n, lambda: rng.uniform(0, side, 2), sp)
    if name == "blobs":
        r = math.sqrt(n / 2) * 0.55 * d_e
        c0, c1 = np.zeros(2), np.array([3.0 * r + d_e, rng.uniform(-r, r)])
        a = _spaced(rng, n // 2, lambda: _disc(rng, c0, r), sp)
        b = _spaced(rng, n - n // 2, lambda: _disc(rng, c1, r), sp)
        return np.vstack([a, b])
    if name == "line":
        ang = rng.uniform(0, math.pi)
        t = (np.arange(n) * 0.75 + rng.uniform(-0.05, 0.05, n)) * d_e
        off = rng.uniform(-0.1, 0.1, n) * d_e
        return np.c_[
            t * math.cos(ang) - off * math.sin(ang), t * math.sin(ang) + off * math.cos(ang)
        ]
    if name == "ring":
        rad = n * 0.75 * d_e / (2 * math.pi)
        th = np.arange(n) * 2 * math.pi / n + rng.uniform(-0.1, 0.1, n) / max(rad, 1.0)
        rr = rad + rng.uniform(-0.1, 0.1, n) * d_e
        return np.c_[rr * np.cos(th), rr * np.sin(th)]
    if name == "grid":
        g = math.ceil(math.sqrt(n))
        grid = np.stack(np.meshgrid(np.arange(g), np.arange(g)), -1).reshape(-1, 2)[:n]
        return (grid.astype(float) + rng.uniform(-1 / 6, 1 / 6, grid.shape)) * 0.9 * d_e
    raise ValueError(f"unknown family {name!r}")


FAMILIES = ("uniform", "blobs", "line", "ring", "grid")
FAMILY_SIZES = (6, 8, 10, 15, 20, 30, 40, 50, 65, 80, 100)


def all_fleets() -> list[tuple[str, int, float, np.ndarray]]:
    """The 67 fleets: (family, n, d_e, positions)."""
    out = [("nao", n, 0.8, nao_group(n, seed)) for n in (3, 4, 5, 6) for seed in range(3)]
    for name in FAMILIES:
        for k, n in enumerate(FAMILY_SIZES):
            out.append((name, n, D_E, family(name, n, k)))
    return out


# ----------------------------------------------------------------- measures


def _rows_after(plan: Plan) -> list[list[int]]:
    row = {r.robot_id: k for k, r in enumerate(plan.robots)}
    return [[row[j] for j in r.after] for r in plan.robots]


def _rows_at(plan: Plan) -> list[list[float]] | None:
    """The plan's release points (what the agents wait for); None: hold (old plans)."""
    if any(len(r.after_at) != len(r.after) for r in plan.robots):
        return None
    return [list(r.after_at) for r in plan.robots]


def _bounds(starts: np.ndarray, slots: np.ndarray, k: int = 64) -> tuple[float, float]:
    """Lower bounds of the longest path of any assignment (so of CAPT's makespan) and of
    the min-sum total: projected on a direction, any assignment costs at least the sorted
    1-D matching (optimal in 1-D for both the sum and the maximum), and projections
    never lengthen a distance. The best of ``k`` directions."""
    best_max, best_sum = 0.0, 0.0
    for j in range(k):
        e = np.array([math.cos(math.pi * j / k), math.sin(math.pi * j / k)])
        d = np.abs(np.sort(starts @ e) - np.sort(slots @ e))
        best_max, best_sum = max(best_max, float(d.max())), max(best_sum, float(d.sum()))
    return best_max, best_sum


def measures(
    plan: Plan, d_e: float, exact_max: int, check_max: int, radius: float = RADIUS
) -> dict[str, Any]:
    """Makespans over CAPT, waves, path over optimum, safety of one plan."""
    starts = plan.starts()
    n = starts.shape[0]
    frame = pyramid_frame(starts)
    slots = frame.to_common(placed(PYRAMID, n, d_e, PHI_E, frame.to_pyramid(starts), "centroid"))
    lengths = path_lengths(plan.paths())
    waves = plan.wave_of()
    after = _rows_after(plan)
    at = _rows_at(plan)
    if n <= exact_max:
        capt, opt, exact = capt_makespan(starts, slots), optimal_total(starts, slots), True
    else:
        capt, opt = _bounds(starts, slots)
        exact = False
    dep = dependency_makespan(lengths, after, waves, at)
    out: dict[str, Any] = {
        "waves": len(plan.waves),
        "strategy": plan.strategy,
        "makespan": dep / capt if capt > 1e-9 else 1.0,
        "wave_makespan": wave_makespan(lengths, waves) / capt if capt > 1e-9 else 1.0,
        "path": float(lengths.sum()) / opt if opt > 1e-9 else 1.0,
        "exact": exact,
        "safe": None,
    }
    if n <= check_max:
        paths = plan.paths()
        out["safe"] = not check_safety(paths, waves, radius) and not check_dependencies(
            paths, after, waves, radius, after_at=at
        )
    return out


def run_one(strategy: str, n: int, exact_max: int, check_max: int) -> dict[str, Any]:
    ids, pos = fleet(n)
    t0 = time.perf_counter()
    c0 = time.process_time()
    try:
        plan = plan_from_positions(ids, pos, PlanParams(d_e=D_E, strategy=strategy))
    except ValueError as exc:
        return {"error": f"fail: {exc}"[:70]}
    out = {"time": time.perf_counter() - t0, "cpu": time.process_time() - c0}
    out.update(measures(plan, D_E, exact_max, check_max))
    return out


def run_cli(n: int, strategy: str, limit: float) -> float | str:
    """Wall seconds of ``python -m tools.plan`` on the n-robot fleet (or a reason)."""
    ids, pos = fleet(n)
    doc = {
        "robots": [{"id": i, "x": float(x), "y": float(y)} for i, (x, y) in zip(ids, pos.tolist())],
        "d_e": D_E,
        "strategy": strategy,
    }
    text = json.dumps(doc)
    t0 = time.perf_counter()
    try:
        res = subprocess.run(
            [sys.executable, "-m", "tools.plan"],
            input=text,
            capture_output=True,
            text=True,
            timeout=limit,
            check=False,
        )
    except subprocess.TimeoutExpired:
        return f"> {limit:g} s"
    dt = time.perf_counter() - t0
    if res.returncode != 0:
        return "fail: " + res.stderr.strip()[:50]
    return dt


def families_summary(check: bool = True) -> dict[str, Any]:
    rows = []
    for fam, n, d_e, pos in all_fleets():
        ids = [int(i) + 1 for i in np.random.default_rng(n).permutation(n)]
        t0 = time.perf_counter()
        plan = plan_from_positions(ids, pos, PlanParams(d_e=d_e))
        dt = time.perf_counter() - t0
        m = measures(plan, d_e, 10**9, 10**9 if check else 0)
        rows.append((fam, n, m, dt))
    ms = np.array([r[2]["makespan"] for r in rows])
    wm = np.array([r[2]["wave_makespan"] for r in rows])
    po = np.array([r[2]["path"] for r in rows])
    safe = [r[2]["safe"] for r in rows]
    per_family = {}
    for fam in ("nao", *FAMILIES):
        sel = [r for r in rows if r[0] == fam]
        per_family[fam] = {
            "median": float(np.median([r[2]["makespan"] for r in sel])),
            "worst": float(max(r[2]["makespan"] for r in sel)),
            "wave_median": float(np.median([r[2]["wave_makespan"] for r in sel])),
            "wave_worst": float(max(r[2]["wave_makespan"] for r in sel)),
            "path_worst": float(max(r[2]["path"] for r in sel)),
            "time_max": float(max(r[3] for r in sel)),
        }
    return {
        "fleets": len(rows),
        "makespan_median": float(np.median(ms)),
        "makespan_worst": float(ms.max()),
        "wave_makespan_median": float(np.median(wm)),
        "wave_makespan_worst": float(wm.max()),
        "path_median": float(np.median(po)),
        "path_worst": float(po.max()),
        "safe": sum(1 for s in safe if s),
        "checked": sum(1 for s in safe if s is not None),
        "per_family": per_family,
        "demo15": demo_wait(),
    }


def demo_wait(n: int = 15, seed: int = 1) -> dict[str, float]:
    """Summed waiting over summed walking of a paper-like 15-robot fleet at d_e = 0.8 m
    (unit speed), under the wave rule and the dependency rule."""
    pos = nao_group(n, seed)
    plan = plan_from_positions(list(range(1, n + 1)), pos, PlanParams(d_e=D_NAO))
    lengths = path_lengths(plan.paths())
    waves = plan.wave_of()
    top = np.zeros(int(waves.max()) + 1)
    np.maximum.at(top, waves, lengths)
    wave_start = np.r_[0.0, np.cumsum(top)][waves]
    dep_start = dependency_starts(lengths, _rows_after(plan), waves, _rows_at(plan))
    walk = float(lengths.sum())
    return {
        "walk": walk,
        "wait_waves": float(wave_start.sum()),
        "wait_dependencies": float(dep_start.sum()),
    }


# ----------------------------------------------------------------- output


def _fmt(v: Any, exact: bool = True, digits: int = 2) -> str:
    if v is None:
        return "-"
    if isinstance(v, str):
        return v
    s = f"{v:.{digits}f}"
    return s if exact else "<=" + s


def _exponent(points: list[tuple[int, float]]) -> str:
    pts = [(n, t) for n, t in points if 1000 <= n <= 100_000 and t > 0]
    if len(pts) < 2:
        return "-"
    x, y = np.log([p[0] for p in pts]), np.log([p[1] for p in pts])
    return f"{np.polyfit(x, y, 1)[0]:.2f}"


def draw(results: dict[str, dict[int, dict[str, Any]]], path: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(11, 4.5))
    for s, table in results.items():
        ns = sorted(n for n, r in table.items() if "time" in r)
        if not ns:
            continue
        ax1.loglog(ns, [table[n]["time"] for n in ns], "o-", label=f"{s}: plan")
        cli = [(n, table[n]["cli"]) for n in ns if isinstance(table[n].get("cli"), float)]
        if cli:
            ax1.loglog(*zip(*cli, strict=True), "s--", label=f"{s}: tools.plan end to end")
        ax2.loglog(ns, [table[n]["makespan"] for n in ns], "o-", label=f"{s}: makespan/CAPT")
        ax2.loglog(ns, [table[n]["waves"] for n in ns], "^:", label=f"{s}: waves")
    if ax1.lines:
        ref = ax1.lines[0].get_xdata()
        ax1.loglog(ref, [10.0] * len(ref), "k:", lw=1, label="10 s")
    ax1.set_xlabel("robots")
    ax1.set_ylabel("wall seconds")
    ax1.set_title("planning time")
    ax1.grid(True, which="both", alpha=0.3)
    ax1.legend(fontsize=8)
    ax2.set_xlabel("robots")
    ax2.set_title("makespan / CAPT (dependency rule) and waves")
    ax2.grid(True, which="both", alpha=0.3)
    ax2.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(
        prog="python -m tools.bench plan", description=__doc__.splitlines()[0]
    )
    ap.add_argument("--sizes", default="10,100,1000,10000,100000,1000000")
    ap.add_argument("--strategies", default="default")
    ap.add_argument("--exact-max", type=int, default=2000)
    ap.add_argument("--check-max", type=int, default=10000)
    ap.add_argument("--limit", type=float, default=180.0, help="child process limit (s)")
    ap.add_argument("--isolate", type=int, default=10000, help="larger sizes in a child")
    ap.add_argument("--cli", action=argparse.BooleanOptionalAction, default=True)
    ap.add_argument("--stuck-n", type=int, default=30000, help="never-stuck row (0: skip)")
    ap.add_argument("--families", action=argparse.BooleanOptionalAction, default=True)
    ap.add_argument("--png", default="out/bench_plan.png")
    ap.add_argument("--json", action="store_true", help="print the results as JSON")
    ap.add_argument("--one", nargs=2, metavar=("STRATEGY", "N"), help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.one:
        print(json.dumps(run_one(args.one[0], int(args.one[1]), args.exact_max, args.check_max)))
        return 0
    try:
        sizes = [int(x) for x in args.sizes.split(",") if x]
    except ValueError:
        print("error: --sizes must be a comma list of ints", file=sys.stderr)
        return 2
    if not sizes or min(sizes) < 1:
        print("error: --sizes must be a comma list of ints >= 1", file=sys.stderr)
        return 2
    strategies = [s for s in args.strategies.split(",") if s]
    results: dict[str, dict[int, dict[str, Any]]] = {s: {} for s in strategies}

    def child(strategy: str, n: int) -> dict[str, Any]:
        cmd = [sys.executable, "-m", "tools.bench.plan", "--one", strategy, str(n)]
        cmd += ["--exact-max", str(args.exact_max), "--check-max", str(args.check_max)]
        try:
            res = subprocess.run(
                cmd, capture_output=True, text=True, timeout=args.limit, check=False
            )
            out: dict[str, Any] = json.loads(res.stdout.strip().splitlines()[-1])
            return out
        except subprocess.TimeoutExpired:
            return {"error": f"not done within --limit {args.limit:g} s"}
        except (ValueError, IndexError):
            return {"error": "child process gave no result"}

    for s in strategies:
        for n in sizes:
            print(f"[bench plan] {s} n={n} ...", file=sys.stderr)
            r = child(s, n) if n > args.isolate else run_one(s, n, args.exact_max, args.check_max)
            if args.cli and "error" not in r:
                r["cli"] = run_cli(n, s, args.limit)
            results[s][n] = r
    stuck: dict[str, Any] | None = None
    if args.stuck_n > 0:
        print(f"[bench plan] never stuck: paper n={args.stuck_n} ...", file=sys.stderr)
        stuck = child("paper", args.stuck_n)
    fam = None
    if args.families:
        print("[bench plan] 67 fleet families ...", file=sys.stderr)
        fam = families_summary()
    # ---- print
    head = ["n", "plan s", "cpu s", "cli s", "ms/capt", "wave", "waves", "path/opt", "safe", "plan"]
    for s in strategies:
        print(f"strategy {s}")
        print("  " + " ".join(f"{h:>10s}" for h in head))
        for n in sizes:
            r = results[s][n]
            if "error" in r:
                print(f"  {n:>10d} {r['error']}")
                continue
            cli = r.get("cli")
            row = [
                f"{n:>10d}",
                _fmt(r["time"]),
                _fmt(r["cpu"]),
                _fmt(cli) if cli is not None else "-",
                _fmt(r["makespan"], r["exact"]),
                _fmt(r["wave_makespan"], r["exact"]),
                str(r["waves"]),
                _fmt(r["path"], r["exact"], 3),
                {True: "yes", False: "NO", None: "-"}[r["safe"]],
                r["strategy"],
            ]
            print("  " + " ".join(f"{c:>10s}" for c in row))
        pts = [(n, r["time"]) for n, r in results[s].items() if "time" in r]
        cpts = [(n, r["cli"]) for n, r in results[s].items() if isinstance(r.get("cli"), float)]
        upts = [(n, r["cpu"]) for n, r in results[s].items() if "cpu" in r]
        print(
            f"  growth exponent 10^3..10^5: plan {_exponent(pts)}, cpu {_exponent(upts)}, "
            f"cli {_exponent(cpts)}"
        )
    if stuck is not None:
        if "error" in stuck:
            print(f"never stuck, paper n={args.stuck_n}: {stuck['error']}")
        else:
            print(
                f"never stuck, paper n={args.stuck_n}: plan found in {stuck['time']:.1f} s "
                f"({stuck['strategy']}, {stuck['waves']} waves)"
            )
    if fam is not None:
        print(
            f"families ({fam['fleets']} fleets, default): makespan/CAPT median "
            f"{fam['makespan_median']:.2f} worst {fam['makespan_worst']:.2f} (dependency rule), "
            f"median {fam['wave_makespan_median']:.2f} worst {fam['wave_makespan_worst']:.2f} "
            f"(wave rule); path/opt median {fam['path_median']:.3f} worst "
            f"{fam['path_worst']:.3f}; safe {fam['safe']}/{fam['checked']}"
        )
        for name, f in fam["per_family"].items():
            print(
                f"  {name:8s} makespan/CAPT median {f['median']:.2f} worst {f['worst']:.2f} | "
                f"waves rule {f['wave_median']:.2f} / {f['wave_worst']:.2f} | path/opt worst "
                f"{f['path_worst']:.3f} | slowest plan {f['time_max']:.2f} s"
            )
        d = fam["demo15"]
        print(
            f"  demo-like 15 robots: walking {d['walk']:.1f} m, waiting {d['wait_waves']:.1f} m "
            f"(wave rule) / {d['wait_dependencies']:.1f} m (dependency rule), summed over robots"
        )
    if args.png:
        import os

        os.makedirs(os.path.dirname(args.png) or ".", exist_ok=True)
        draw(results, args.png)
        print(f"figure: {args.png}")
    if args.json:
        print(json.dumps({"scale": results, "never_stuck": stuck, "families": fam}))
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
