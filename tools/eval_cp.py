"""``python -m tools.eval_cp``: the AUV paper's comparison of the circle pattern (CP) and
PCA, Tables 1-3 (III.B.2 and IV; docs/formation.md "The circle pattern").

Every run is a fleet as ``tools.demo`` runs it (secure, one agent process per NAO, the
rendered perception), judged from the ground truth. Three variants, as the paper's rows
with images:

* ``pca``: the formation planned on the fleet's principal axis (NAO eq. 12), walked at once;
* ``cp-no-tune``: the circle round the frame robot walked first, no fine tuning on it
  (``--orientation cp --no-cp-tune``), then the formation from the circle;
* ``cp-tune``: the same, each robot fine-tuning its place on the circle from a look at the
  centre robot (``--orientation cp``).

By default every variant ends open-loop, as the paper's robots do (``--no-correct``: no
final alignment on the parent); ``--correct`` adds this project's final alignment.

The errors are the paper's: per child of the final pyramid (true final poses, the
judge's slot matching), x_err/x_d, y_err/y_d, dis_err/d_e and ang_err/φ_e, with
(x_a, y_a) the child's true offset from its parent in the formation's frame and
(x_d, y_d) = (d_e sin φ_e, d_e cos φ_e); "aver" is the mean of |err| in %, "stdev" the
sample standard deviation of err. The time is the building's sim time: from the last
agent planning to every robot settled within 2 cm of its end (the paper's Table 3
excludes the search too). Runs are kept under ``--out`` (one directory each, reused
when present, so that a matrix can be cut and resumed); the tables are printed beside
the paper's values and drawn to ``cp.png``.

    python -m tools.eval_cp --robots 4 --robots 6 --seeds 20
    python -m tools.eval_cp --variant cp-tune --robots 4 --seeds 5 --correct
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from tools.harness import report
from tools.harness.fleet import FleetSpec, run_fleet
from tools.harness.fleet_flags import parse_fleet_spec
from tools.harness.judge import outcome

VARIANTS = ("pca", "cp-no-tune", "cp-tune")
#: The paper's values: Table 1 (CP, with images: no tune, tune) and Table 2 (PCA, with
#: images), aver in % and stdev, for x, y, distance and angle; Table 3 in s (mean, sd).
PAPER = {
    "cp-no-tune": {"aver": (30.52, 11.45, 16.40, 33.33), "stdev": (0.28, 0.10, 0.15, 0.29)},
    "cp-tune": {"aver": (20.55, 7.35, 10.43, 14.46), "stdev": (0.17, 0.061, 0.075, 0.16)},
    "pca": {"aver": (25.94, 9.6, 14.63, 26.72), "stdev": (0.31, 0.087, 0.11, 0.27)},
}
PAPER_TIME = {"cp-no-tune": (300.0, 30.0), "cp-tune": (300.0, 30.0), "pca": (100.0, 15.0)}
ERRORS = ("x", "y", "distance", "angle")


@dataclass
class Run:
    case: str
    seed: int
    outcome: str
    contacts: int
    wall_s: float
    detail: str
    variant: str = "pca"
    robots: int = 4
    #: per child of the final formation: the relative errors (x, y, distance, angle)
    errors: list[list[float]] = field(default_factory=list)
    build_s: float | None = None


def relative_errors(pairs: list[dict[str, Any]], d_e: float, phi_e: float) -> list[list[float]]:
    """The paper's relative errors of each judged pair (module docstring): the child's
    true distance and angle off its parent's backward axis against d_e and φ_e."""
    x_d, y_d = d_e * math.sin(phi_e), d_e * math.cos(phi_e)
    out = []
    for p in pairs:
        d, a = float(p["distance"]), math.radians(float(p["angle_deg"]))
        x_a, y_a = d * math.sin(a), d * math.cos(a)
        out.append([(x_a - x_d) / x_d, (y_a - y_d) / y_d, (d - d_e) / d_e, (a - phi_e) / phi_e])
    return out


def spec_of(base: FleetSpec, variant: str, correct: bool) -> FleetSpec:
    """The fleet of ``variant`` (module docstring)."""
    if variant not in VARIANTS:
        raise ValueError(f"variant must be one of {VARIANTS}, got {variant!r}")
    agent = replace(
        base.agent,
        orientation="pca" if variant == "pca" else "cp",
        cp_tune=variant != "cp-no-tune",
        correct=correct,
    )
    return replace(base, agent=agent)


def run_one(args: argparse.Namespace, variant: str, n: int, seed: int, out: Path) -> Run:
    """One run (module docstring); a run directory with a result is read, not run again."""
    kept = out / "result.json"
    if kept.exists():
        r = json.loads(kept.read_text())
    else:
        spec = replace(spec_of(args.fleet, variant, args.correct), robots=n, seed=seed,
                       timeout=args.timeout)  # fmt: skip
        try:
            r = run_fleet(spec, out)
        except RuntimeError as exc:
            r = {"no_result": f"demo: {exc}"}
    got, detail = outcome(r)
    d_e, phi_e = float(r.get("d_e", 0.0) or 0.0), math.radians(float(r.get("phi_e_deg", 30.0)))
    start, end = r.get("t_sim_plan"), r.get("t_sim_settled")
    build = float(end) - float(start) if start is not None and end is not None else None
    return Run(
        case=f"{variant} n={n}",
        seed=seed,
        outcome=got,
        contacts=int(r.get("contacts", 0)),
        wall_s=float(r.get("wall_total", 0.0)),
        detail=detail,
        variant=variant,
        robots=n,
        errors=relative_errors(r.get("pairs", []), d_e, phi_e) if d_e > 0 else [],
        build_s=build if build is not None and math.isfinite(build) else None,
    )


def tables(runs: list[Run]) -> list[dict[str, Any]]:
    """Per variant and fleet size (and all sizes together, ``robots`` 0): the runs, the
    complete ones, contacts, aver and stdev of each error, and the building time."""
    rows = []
    for variant in VARIANTS:
        mine = [r for r in runs if r.variant == variant]
        for n in [*sorted({r.robots for r in mine}), 0]:
            sel = [r for r in mine if n in (0, r.robots)]
            if not sel:
                continue
            e = np.array([x for r in sel for x in r.errors], dtype=np.float64).reshape(-1, 4)
            t = np.array([r.build_s for r in sel if r.build_s is not None], dtype=np.float64)
            rows.append({
                "variant": variant,
                "robots": n,
                "runs": len(sel),
                "complete": sum(r.outcome == "complete" for r in sel),
                "contacts": sum(r.contacts for r in sel),
                "pairs": int(e.shape[0]),
                "aver": [float(v) for v in 100.0 * np.mean(np.abs(e), axis=0)] if len(e) else [],
                "stdev": [float(v) for v in np.std(e, axis=0, ddof=1)] if len(e) > 1 else [],
                "time": [float(t.mean()), float(t.std(ddof=1)) if len(t) > 1 else 0.0]
                if len(t) else [],
            })  # fmt: skip
    return rows


def print_tables(rows: list[dict[str, Any]]) -> None:
    """Tables 1-2 (errors) and 3 (time), each row beside the paper's."""
    print("\nTables 1-2: final relative errors (aver: mean |err| %; stdev: of err), with images")
    head = "  ".join(f"{e:>15s}" for e in ERRORS)
    print(f"{'variant':11s} {'N':>3s} {'runs':>4s} {'pairs':>5s}  {head}")
    for r in rows:
        if not r["aver"]:
            continue
        n = "all" if r["robots"] == 0 else str(r["robots"])
        paper = PAPER[r["variant"]]
        ours = "  ".join(
            f"{a:6.2f} ({p:6.2f})" for a, p in zip(r["aver"], paper["aver"], strict=True)
        )
        print(f"{r['variant']:11s} {n:>3s} {r['runs']:4d} {r['pairs']:5d}  aver  {ours}")
        if r["stdev"]:
            sd = "  ".join(
                f"{a:6.3f} ({p:6.3f})" for a, p in zip(r["stdev"], paper["stdev"], strict=True)
            )
            print(f"{'':11s} {'':>3s} {'':>4s} {'':>5s}  stdev {sd}")
    print("(the paper's values in brackets: AUV Table 1 img_no_tune / img_tune, Table 2 img)")
    print("\nTable 3: building the formation, sim s (from the last plan to every robot settled)")
    for r in rows:
        if r["time"]:
            n = "all" if r["robots"] == 0 else str(r["robots"])
            pm, ps = PAPER_TIME[r["variant"]]
            print(f"{r['variant']:11s} {n:>3s}  {r['time'][0]:6.1f} ± {r['time'][1]:5.1f}   "
                  f"(paper {pm:.0f} ± {ps:.0f})   complete {r['complete']}/{r['runs']}, "
                  f"contacts {r['contacts']}")  # fmt: skip


def plot(rows: list[dict[str, Any]], path: Path) -> None:
    """Bars: aver per error and variant (all sizes), ours beside the paper's; and time."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    every = [r for r in rows if r["robots"] == 0 and r["aver"]]
    if not every:
        return
    fig, (ax, bx) = plt.subplots(1, 2, figsize=(11, 4), gridspec_kw={"width_ratios": [3, 1]})
    w = 0.8 / (2 * len(every))
    for k, r in enumerate(every):
        x = np.arange(4) + (2 * k) * w
        ax.bar(x, r["aver"], w, label=f"{r['variant']} (here)")
        ax.bar(x + w, PAPER[r["variant"]]["aver"], w, alpha=0.45, label=f"{r['variant']} (paper)")
        if r["time"]:
            bx.bar(2 * k, r["time"][0], yerr=r["time"][1], color=f"C{2 * k}")
            bx.bar(2 * k + 1, PAPER_TIME[r["variant"]][0], yerr=PAPER_TIME[r["variant"]][1],
                   color=f"C{2 * k + 1}", alpha=0.45)  # fmt: skip
    ax.set_xticks(np.arange(4) + 0.4 - w / 2, [f"{e} err" for e in ERRORS])
    ax.set_ylabel("mean |relative error| (%)")
    ax.legend(fontsize=7, ncol=3)
    ax.set_title("AUV Tables 1-2: final relative errors, with images", fontsize=10)
    bx.set_xticks(range(2 * len(every)), [f"{r['variant']}\n{s}" for r in every
                                         for s in ("here", "paper")], fontsize=6,
                  rotation=45)  # fmt: skip
    bx.set_ylabel("sim s")
    bx.set_title("Table 3: building time", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def write(args: argparse.Namespace, runs: list[Run]) -> None:
    rows = tables(runs)
    args.out.mkdir(parents=True, exist_ok=True)
    payload = {"runs": [asdict(r) for r in runs], "tables": rows, "correct": args.correct}
    for path in (args.json, args.out / "results.json"):
        if path is not None:
            path.write_text(json.dumps(payload, indent=1))
    plot(rows, args.out / "cp.png")


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    p = argparse.ArgumentParser(
        prog="python -m tools.eval_cp", description=__doc__.split("\n\n")[0]
    )
    p.add_argument("--variant", action="append", choices=VARIANTS, default=[],
                   help="repeat; default all three")  # fmt: skip
    p.add_argument("--robots", action="append", type=int, default=[], help="repeat; default 4, 6")
    p.add_argument("--seed-start", type=int, default=1)
    p.add_argument("--seeds", type=int, default=20)
    p.add_argument("--correct", action="store_true",
                   help="end with this project's final alignment on the parent (not the paper's)")  # fmt: skip
    p.add_argument("--timeout", type=float, default=600.0, help="wall limit of a run (s)")
    p.add_argument("--demo-arg", action="append", default=[], metavar="ARG",
                   help="one more tools.demo argument for every run (repeat)")  # fmt: skip
    p.add_argument("--json", type=Path, default=None)
    p.add_argument("--out", type=Path, default=Path("out/eval_cp"))
    a = p.parse_args(argv)
    a.variant = a.variant or list(VARIANTS)
    a.robots = a.robots or [4, 6]
    if any(not 2 <= n <= 30 for n in a.robots) or a.seeds < 1:
        p.error("--robots in [2, 30], --seeds >= 1")
    a.fleet = parse_fleet_spec(["--no-publish-camera", *a.demo_arg], "--demo-arg")
    return a


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    seeds = range(args.seed_start, args.seed_start + args.seeds)
    cases = [(v, n, s) for v in args.variant for n in args.robots for s in seeds]
    ending = "correct" if args.correct else "open"

    def one(c: tuple[str, int, int]) -> Run:
        v, n, s = c
        return run_one(args, v, n, s, args.out / f"{v}-{ending}" / f"n{n:02d}" / f"seed-{s:03d}")

    runs = report.run_matrix(
        cases,
        one,
        report=lambda runs: write(args, runs),
        progress="eval_cp",
        label=lambda c, r: f"{c[0]} n={c[1]} seed {c[2]}: {r.outcome} ({r.detail[:60]})",
    )
    print_tables(tables(runs))
    print(f"figure: {args.out / 'cp.png'}", file=sys.stderr)
    return report.exit_status(runs)


if __name__ == "__main__":
    raise SystemExit(main())
