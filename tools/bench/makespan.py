"""``python -m tools.bench makespan``: the planner on fleets it was not tuned on - its
makespan over CAPT's and over a lower bound, for the pyramid and every built-in shape, on a
tuned-on set and a held-out set of start families (docs/formation.md "The plan for any
shape"; CAPT and CAT-ORA in docs/papers.md).

The families (:func:`starts`; each seed also draws the family's own parameters, so two
seeds differ in layout, not only in jitter): ``nao`` (the simulator's paper-like group of
3-15 NAOs, d_e = 0.8 m), and at the paper's simulation spacing d_e = 2 m ``blobs`` (two
discs of unequal size, their gap and direction drawn), ``uniform`` (a rotated rectangle of
aspect 1-3), ``line`` (a rotated, slightly bent line, spacing 0.6-1.0·d_e), ``ring`` (a
circle or an arc of 0.5-1 turn) and ``clusters`` (3-6 small groups scattered over an area).
Starts stand >= 0.6·d_e apart (line and ring: their spacing).

The split, fixed before any measurement: the tuned-on set (``--set tuned``) is seeds 0-1 of
``nao``, ``blobs``, ``uniform``, ``line`` and ``ring``; the held-out set (``--set
held-out``) is seeds 1000-1002 of the same families and every seed of ``clusters``, a
family the planner was never looked at on. Held out means: never run while the planner is
changed; run once, before and after. The fresh set (``--set fresh``: seeds 2000-2002 of
the held-out set's families) is a second held-out set, run only once, after a change to
the planner is made, and reported as it comes out.

Per fleet (one line each, ``--json FILE`` appends the rows): the plan of ``default``
(``plan_from_positions``), its makespan as agents execute it (each robot walks at once
and holds before a step until its gates are open:
:func:`agent.core.formation.waves.gates.gated_makespan`; unit walking speed, so
metres), CAPT's (the longest straight path of the min-sum-of-squares assignment to the
shape's centred slots), the lower bound B* (the bottleneck assignment's longest straight
path to the same slots, ÷ the walking speed: no assignment to these slots finishes
sooner), the ratios ``ms/capt`` and ``ms/lb``, ``safe`` (the wave checker and the
dependency checker, with the release points and waiting until the robots waited for
hold their slots: timing-robust 2·radius clearance), the plan's seconds, its critical
chain under the start-only rule (:func:`critical_chain`: who waits for whom along the
path that ends last; ``--chain`` prints it), and ``start/capt``: the makespan if every
robot held at its start until the robots it waits for are past their release points
(the dependency rule of :mod:`agent.core.formation.waves.execution`). The summary gives
per family and over the set the median and worst ``ms/capt`` and ``start/capt``, and the
fleets that failed the clearance.

The runs are single-process and CPU-light but a plan of 100 robots in two blobs takes up
to a minute on a loaded machine: ``--families``, ``--sizes`` and ``--shapes`` cut a set
into runs of a minute or two, and ``--summary FILE`` summarises the rows appended so far.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from agent.core.control import STEP_LENGTH
from agent.core.formation.params import D_E as D_NAO
from agent.core.formation.params import PHI_E_DEG, PlanParams
from agent.core.formation.paths.assignment import min_bottleneck
from agent.core.formation.plan import Plan, plan_from_positions
from agent.core.formation.shape.layout import placed, shape_frame
from agent.core.formation.shape.spec import BUILTIN
from agent.core.formation.waves.execution import (
    capt_makespan,
    check_dependencies,
    dependency_makespan,
    dependency_starts,
    path_lengths,
    release_points,
)
from agent.core.formation.waves.gates import gated_makespan
from agent.core.formation.waves.safety import check_safety
from tools.bench.plan import _rows_after, _rows_at, nao_group

#: The paper's simulation spacing (m) of every family but ``nao``.
D_SIM = 2.0
PHI_E = math.radians(PHI_E_DEG)

TUNED_FAMILIES = ("nao", "blobs", "uniform", "line", "ring")
#: The held-out set's families: the tuned-on ones on other seeds, and one never tuned on.
HELD_OUT_FAMILIES = (*TUNED_FAMILIES, "clusters")
FAMILIES = HELD_OUT_FAMILIES
SETS: dict[str, dict[str, Any]] = {
    "tuned": {"families": TUNED_FAMILIES, "seeds": (0, 1)},
    "held-out": {"families": HELD_OUT_FAMILIES, "seeds": (1000, 1001, 1002)},
    "fresh": {"families": HELD_OUT_FAMILIES, "seeds": (2000, 2001, 2002)},
}
SIZES = (6, 10, 15, 30, 60, 100)
NAO_SIZES = (3, 4, 5, 6, 8, 10, 15)


def _spaced(rng: np.random.Generator, n: int, draw: Any, spacing: float) -> np.ndarray:
    """n points from ``draw()`` kept >= spacing apart (rejection; the areas below leave
    room, a failure is a bug of the family)."""
    pts: list[np.ndarray] = []
    for _ in range(400_000):
        if len(pts) == n:
            return np.array(pts)
        p = np.asarray(draw(), dtype=np.float64)
        if all(math.hypot(*(p - q)) >= spacing for q in pts):
            pts.append(p)
    raise RuntimeError(f"could not place {n} starts {spacing} m apart")


def _disc(rng: np.random.Generator, centre: np.ndarray, r: float) -> np.ndarray:
    a = rng.uniform(0, 2 * math.pi)
    return centre + r * math.sqrt(rng.uniform()) * np.array([math.cos(a), math.sin(a)])


def _turned(pts: np.ndarray, angle: float) -> np.ndarray:
    c, s = math.cos(angle), math.sin(angle)
    return np.asarray(pts @ np.array([[c, s], [-s, c]]))


def starts(family: str, n: int, seed: int) -> tuple[np.ndarray, float]:
    """The starts of one fleet of ``family`` (module doc) and its d_e (m)."""
    if family == "nao":
        return nao_group(n, seed), D_NAO
    if family not in FAMILIES:
        raise ValueError(f"unknown family {family!r}; one of {FAMILIES}")
    rng = np.random.default_rng([seed, n, FAMILIES.index(family), 7])
    d_e, sp = D_SIM, 0.6 * D_SIM
    turn = rng.uniform(0, 2 * math.pi)
    if family == "blobs":
        share = rng.uniform(0.3, 0.7)
        na = min(max(1, round(n * share)), n - 1)
        ra, rb = (math.sqrt(k) * 0.55 * d_e + 0.5 * d_e for k in (na, n - na))
        gap = rng.uniform(0.5, 3.0) * max(ra, rb) + d_e
        ca, cb = np.zeros(2), np.array([ra + rb + gap, 0.0])
        a = _spaced(rng, na, lambda: _disc(rng, ca, ra), sp)
        b = _spaced(rng, n - na, lambda: _disc(rng, cb, rb), sp)
        return _turned(np.vstack([a, b]), turn), d_e
    if family == "uniform":
        aspect = rng.uniform(1.0, 3.0)
        area = n * (0.9 * d_e) ** 2
        w, h = math.sqrt(area * aspect), math.sqrt(area / aspect)
        return _turned(_spaced(rng, n, lambda: rng.uniform((0, 0), (w, h)), sp), turn), d_e
    if family == "line":
        step = rng.uniform(0.6, 1.0) * d_e
        t = (np.arange(n) + rng.uniform(-0.05, 0.05, n)) * step
        bend = rng.uniform(-0.3, 0.3) / max(t[-1], 1.0)  # a gentle arc over the line
        y = bend * (t - t.mean()) ** 2 + rng.uniform(-0.1, 0.1, n) * d_e
        return _turned(np.c_[t, y], turn), d_e
    if family == "ring":
        turns = rng.uniform(0.5, 1.0)
        step = rng.uniform(0.6, 1.0) * d_e
        rad = max(n * step / (2 * math.pi * turns), step)
        th = np.arange(n) * 2 * math.pi * turns / n + rng.uniform(-0.02, 0.02, n)
        rr = rad + rng.uniform(-0.1, 0.1, n) * d_e
        return _turned(np.c_[rr * np.cos(th), rr * np.sin(th)], turn), d_e
    # clusters: 3-6 groups at random places over an area, each start drawn in one of them
    k = min(n, int(rng.integers(3, 7)))
    side = math.sqrt(n) * 2.0 * d_e
    centres = rng.uniform(0, side, (k, 2))
    r = math.sqrt(n / k) * 0.55 * d_e + 0.3 * d_e
    pos = _spaced(rng, n, lambda: _disc(rng, centres[int(rng.integers(k))], r), sp)
    return _turned(pos, turn), d_e


def evaluate(family: str, n: int, seed: int, shape: str, radius: float = 0.2) -> dict[str, Any]:
    """One fleet planned with ``default`` and measured (module doc)."""
    pos, d_e = starts(family, n, seed)
    params = PlanParams(d_e=d_e, phi_e=PHI_E, radius=radius, shape=BUILTIN[shape])
    ids = [int(i) + 1 for i in np.random.default_rng([seed, n]).permutation(n)]
    t0 = time.perf_counter()
    plan = plan_from_positions(ids, pos, params)
    dt = time.perf_counter() - t0
    frame = shape_frame(plan.starts(), params.orientation, params.shape)
    s_c = plan.starts()
    slots = frame.to_common(placed(params.shape, n, d_e, PHI_E, frame.to_pyramid(s_c), "centroid"))
    capt = capt_makespan(s_c, slots)
    lb = min_bottleneck(s_c, slots)
    ms = _makespan(plan, radius)
    start_only = _start_only(plan)
    return {
        "family": family,
        "n": n,
        "seed": seed,
        "shape": shape,
        "d_e": d_e,
        "strategy": plan.strategy,
        "waves": len(plan.waves),
        "makespan": ms,
        "capt": capt,
        "lb": lb,
        "ms_capt": ms / capt if capt > 1e-9 else 1.0,
        "ms_lb": ms / lb if lb > 1e-9 else 1.0,
        "lb_capt": lb / capt if capt > 1e-9 else 1.0,
        "start_only": start_only,
        "start_capt": start_only / capt if capt > 1e-9 else 1.0,
        "safe": _safe(plan, radius),
        "plan_s": dt,
        "chain": critical_chain(plan),
    }


def _makespan(plan: Plan, radius: float) -> float:
    """The plan's makespan as agents execute it: walked at once, held at its gates."""
    return gated_makespan(plan.paths(), _rows_after(plan), plan.wave_of(), 2.0 * radius,
                          STEP_LENGTH, _rows_at(plan))  # fmt: skip


def _start_only(plan: Plan) -> float:
    """The makespan if every robot held at its start until its release points."""
    lengths = path_lengths(plan.paths())
    return dependency_makespan(lengths, _rows_after(plan), plan.wave_of(), _rows_at(plan))


def critical_chain(plan: Plan) -> list[tuple[int, float, float]]:
    """What the start-only makespan is made of: from the first robot to start to the last to hold,
    per robot of the waiting chain (robot id, its path length m, how far along it the
    next robot of the chain waits for it: its release point; the last robot: its whole
    length). The makespan is the sum of the last column (unit speed)."""
    lengths = path_lengths(plan.paths())
    after, at, waves = _rows_after(plan), _rows_at(plan), plan.wave_of()
    start = dependency_starts(lengths, after, waves, at)
    rel = release_points(lengths, after, at)
    i = int(np.argmax(start + lengths))
    chain = [(plan.robots[i].robot_id, float(lengths[i]), float(lengths[i]))]
    while after[i]:
        k = max(range(len(after[i])), key=lambda m: (start[after[i][m]] + rel[i][m], -m))
        j = after[i][k]
        chain.append((plan.robots[j].robot_id, float(lengths[j]), float(rel[i][k])))
        i = j
    return chain[::-1]


def _safe(plan: Plan, radius: float) -> bool:
    """Timing-robust clearance: the wave rule, the dependency rule with the release points,
    and the dependency rule waiting until those waited for hold their slots."""
    paths, waves, after = plan.paths(), plan.wave_of(), _rows_after(plan)
    return (
        not check_safety(paths, waves, radius)
        and not check_dependencies(paths, after, waves, radius, after_at=_rows_at(plan))
        and not check_dependencies(paths, after, waves, radius)
    )


def summary(rows: Sequence[dict[str, Any]]) -> dict[str, Any]:
    """Per shape, per family and over all: fleets, median and worst ms/capt (and the worst
    fleet), the median ms/lb, the unsafe fleets."""
    out: dict[str, Any] = {}
    for shape in sorted({r["shape"] for r in rows}):
        mine = [r for r in rows if r["shape"] == shape]
        groups = {f: [r for r in mine if r["family"] == f] for f in FAMILIES}
        groups["all"] = mine
        out[shape] = {name: _stats(sel) for name, sel in groups.items() if sel}
    return out


def _stats(sel: Sequence[dict[str, Any]]) -> dict[str, Any]:
    worst = max(sel, key=lambda r: r["ms_capt"])
    start = [float(r["start_capt"]) for r in sel if "start_capt" in r]
    return {
        "fleets": len(sel),
        "median": float(np.median([r["ms_capt"] for r in sel])),
        "worst": float(worst["ms_capt"]),
        "worst_fleet": f"{worst['family']} n={worst['n']} seed={worst['seed']}",
        "median_ms_lb": float(np.median([r["ms_lb"] for r in sel])),
        "start_median": float(np.median(start)) if start else math.nan,
        "start_worst": max(start, default=math.nan),
        "unsafe": [f"{r['family']} n={r['n']} seed={r['seed']}" for r in sel if not r["safe"]],
        "plan_s_max": float(max(r["plan_s"] for r in sel)),
    }


def print_summary(summ: dict[str, Any], file: Any = None) -> None:
    file = sys.stdout if file is None else file
    for shape, groups in summ.items():
        print(f"shape {shape}", file=file)
        for name, s in groups.items():
            unsafe = ", ".join(s["unsafe"]) if s["unsafe"] else "none"
            print(
                f"  {name:9s} {s['fleets']:3d} fleets  ms/capt median {s['median']:.2f} worst "
                f"{s['worst']:.2f} ({s['worst_fleet']})  ms/lb median {s['median_ms_lb']:.2f}  "
                f"unsafe: {unsafe}  slowest plan {s['plan_s_max']:.1f} s  start/capt median "
                f"{s['start_median']:.2f} worst {s['start_worst']:.2f}",
                file=file,
            )


def _ints(text: str) -> tuple[int, ...]:
    try:
        vals = tuple(int(x) for x in text.split(",") if x.strip())
    except ValueError as exc:
        raise argparse.ArgumentTypeError(f"expected a comma list of ints, got {text!r}") from exc
    if not vals or min(vals) < 1:
        raise argparse.ArgumentTypeError(f"expected ints >= 1, got {text!r}")
    return vals


def _names(allowed: Sequence[str]) -> Any:
    def parse(text: str) -> tuple[str, ...]:
        vals = tuple(x.strip() for x in text.split(",") if x.strip())
        bad = [v for v in vals if v not in allowed]
        if not vals or bad:
            raise argparse.ArgumentTypeError(f"expected some of {', '.join(allowed)}, got {text!r}")
        return vals

    return parse


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(
        prog="python -m tools.bench makespan", description=__doc__.splitlines()[0]
    )
    ap.add_argument("--set", choices=tuple(SETS), default="tuned", dest="which")
    ap.add_argument("--shapes", type=_names(tuple(BUILTIN)), default=("pyramid",),
                    help="built-in shapes, comma list (default pyramid)")  # fmt: skip
    ap.add_argument("--families", type=_names(FAMILIES), default=None,
                    help="a part of the set's families (default: all of them)")  # fmt: skip
    ap.add_argument("--sizes", type=_ints, default=None,
                    help=f"fleet sizes (default {','.join(map(str, SIZES))}; nao: "
                    f"{','.join(map(str, NAO_SIZES))} unless given)")  # fmt: skip
    ap.add_argument("--seeds", type=int, default=None, help="the set's first K seeds only")
    ap.add_argument("--chain", action="store_true", help="print each plan's critical chain")
    ap.add_argument("--json", type=Path, default=None, help="append one row per fleet")
    ap.add_argument("--summary", type=Path, default=None,
                    help="summarise the rows of this file (no planning)")  # fmt: skip
    a = ap.parse_args(argv)
    if a.summary is not None:
        lines = a.summary.read_text().splitlines()
        print_summary(summary([json.loads(x) for x in lines if x.strip()]))
        return 0
    spec = SETS[a.which]
    families = a.families or spec["families"]
    out_of_set = [f for f in families if f not in spec["families"]]
    if out_of_set:
        ap.error(f"--families {','.join(out_of_set)}: not in the {a.which} set")
    seeds = spec["seeds"][: a.seeds] if a.seeds else spec["seeds"]
    rows: list[dict[str, Any]] = []
    for shape in a.shapes:
        for fam in families:
            sizes = a.sizes or (NAO_SIZES if fam == "nao" else SIZES)
            for n in sizes:
                for seed in seeds:
                    r = evaluate(fam, n, seed, shape)
                    rows.append(r)
                    print(
                        f"{shape:8s} {fam:9s} n={n:<4d} seed={seed:<5d} ms/capt "
                        f"{r['ms_capt']:.2f}  lb/capt {r['lb_capt']:.2f}  ms/lb "
                        f"{r['ms_lb']:.2f}  makespan {r['makespan']:.1f} m  capt "
                        f"{r['capt']:.1f} m  lb {r['lb']:.1f} m  "
                        f"{'safe' if r['safe'] else 'UNSAFE'}  {r['plan_s']:.1f} s  "
                        f"start/capt {r['start_capt']:.2f}",
                        flush=True,
                    )
                    if a.chain:
                        print("    chain (id, path m, walked when the next starts m): " + ", ".join(
                            f"{i} {ln:.1f}/{x:.1f}" for i, ln, x in r["chain"]
                        ))  # fmt: skip
                    if a.json is not None:
                        with a.json.open("a") as f:
                            f.write(json.dumps(r) + "\n")
    print_summary(summary(rows))
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
