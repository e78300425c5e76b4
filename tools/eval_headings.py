"""``python -m tools.eval_headings``: robots set down facing any direction.

The papers (NAO 4.1.1) assume every robot starts facing the same way. This tool runs the
fleet as ``tools.demo`` does (secure, a TLS router, one agent process per robot) on
generated scenarios whose start headings are ``aligned``, ``random`` (uniform over the
circle) or ``jitter:DEG``, optionally with one robot whose sensor is faulty (the agent's
test tool ``--sensor-fault rotate:DEG|scale:F|shift:M`` on robot ``1 + seed mod N``),
and judges every run from the ground truth with the one rule of
:func:`tools.harness.judge.outcome`:

* ``complete``: every agent done on identical plans, the true shape within tolerance,
  a robot left out only if it carries the injected fault;
* ``degraded``: the same, but the fleet left out a sound robot (a failure);
* ``unsafe``: a contact, a robot that moved (ground truth) off the plan the others share,
  or every agent reporting done on a formation the ground truth fails (a silent wrong "done");
* ``no_result``: the run gave no result (a failure);
* ``safe_abort``: everything else (the fleet stopped, and said why).

For a sensor fault it also records whom the fleet named (the robots the plan leaves out,
recomputed by the evaluator from the signed records: every agent that planned holds the
same plan digest). Writes the shared JSON (``{"runs": [...]}``, as ``tools.eval_faults``;
:mod:`tools.harness.report`) to ``--json`` and ``results.json``, ``headings.png``
(outcomes per case) under ``--out`` and prints a table; a progress line with an estimate
after every run.

    python -m tools.eval_headings --headings random --robots 4 --robots 6 --seeds 10
    python -m tools.eval_headings --headings jitter:20 --robots 10 --seeds 5
    python -m tools.eval_headings --robots 6 --sensor-fault rotate:40 --sensor-fault scale:1.4 \\
        --sensor-fault shift:0.5 --seeds 5
"""

from __future__ import annotations

import argparse
import sys
from collections import Counter
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any

from sim.scenarios import Headings
from tools.harness import report
from tools.harness.fleet import FleetSpec, run_fleet
from tools.harness.fleet_flags import parse_fleet_spec
from tools.harness.judge import outcome
from tools.harness.view.live import add_live_arguments, check_live_argument


@dataclass
class Run:
    case: str
    seed: int
    outcome: str
    contacts: int
    wall_s: float
    detail: str
    headings: str = "aligned"
    robots: int = 3
    fault: str = ""
    victim: int = -1
    named: list[int] = field(default_factory=list)
    verdicts_agree: bool = False
    silent_wrong: bool = False
    max_abs_r_d: float | None = None
    max_abs_r_phi: float | None = None


@dataclass(frozen=True)
class Case:
    headings: Headings
    robots: int
    fault: str = ""

    @property
    def name(self) -> str:
        return f"{self.headings} N={self.robots}" + (f" {self.fault}" if self.fault else "")

    def victim(self, seed: int) -> int:
        """The robot with the injected fault: 1 + seed mod N (-1 without a fault)."""
        return 1 + seed % self.robots if self.fault else -1


def run_one(args: argparse.Namespace, case: Case, seed: int, out: Path) -> Run:
    """One run of ``case`` at ``seed`` (module docstring)."""
    base: FleetSpec = args.fleet
    victim = case.victim(seed)
    fault = ((victim, f"--sensor-fault={case.fault}"),) if case.fault else ()
    spec = replace(base, robots=case.robots, seed=seed, headings=case.headings,
                   timeout=args.timeout, live=args.live or base.live,
                   agent_args=(*base.agent_args, *fault))  # fmt: skip
    try:
        r = run_fleet(spec, out)
    except RuntimeError as exc:
        r = {"no_result": f"demo: {exc}"}
    got, detail = outcome(r)
    return Run(
        case=case.name,
        seed=seed,
        outcome=got,
        contacts=int(r.get("contacts", 0)),
        wall_s=float(r.get("wall_total", 0.0)),
        detail=detail,
        headings=str(case.headings),
        robots=case.robots,
        fault=case.fault,
        victim=victim,
        named=[int(i) for i in r.get("excluded", [])],
        verdicts_agree=bool(r.get("verdicts_agree", False)),
        silent_wrong=bool(r.get("silent_wrong", False)),
        max_abs_r_d=_finite(r.get("max_abs_r_d")),
        max_abs_r_phi=_finite(r.get("max_abs_r_phi")),
    )


def _finite(v: Any) -> float | None:
    return float(v) if isinstance(v, int | float) and v == v else None


def print_table(runs: list[Run]) -> None:
    print(f"\n{'case':28s} {'seed':>4} {'outcome':10s} {'named':>8} {'max|r_d|':>8} "
          f"{'max|r_phi|':>10} {'wall':>6}  detail")  # fmt: skip
    for r in runs:
        rd = "-" if r.max_abs_r_d is None else f"{r.max_abs_r_d:.1%}"
        rp = "-" if r.max_abs_r_phi is None else f"{r.max_abs_r_phi:.1%}"
        named = ",".join(map(str, r.named)) or "-"
        print(f"{r.case:28s} {r.seed:4d} {r.outcome:10s} {named:>8} {rd:>8} {rp:>10} "
              f"{r.wall_s:6.0f}  {r.detail[:80]}")  # fmt: skip
    print(f"\n{'case':28s} {'complete':>8} {'degraded':>8} {'safe_abort':>10} {'unsafe':>6} "
          f"{'no_result':>9} {'contacts':>8} {'named right':>11} {'verdicts agree':>14}")  # fmt: skip
    for case in [*dict.fromkeys(r.case for r in runs), "all"]:
        mine = [r for r in runs if case in ("all", r.case)]
        c = Counter(r.outcome for r in mine)
        faulty = [r for r in mine if r.fault]
        right = f"{sum(r.named == [r.victim] for r in faulty)}/{len(faulty)}" if faulty else "-"
        agree = f"{sum(r.verdicts_agree for r in mine)}/{len(mine)}"
        print(f"{case:28s} {c['complete']:8d} {c['degraded']:8d} {c['safe_abort']:10d} "
              f"{c['unsafe']:6d} {c['no_result']:9d} {sum(r.contacts for r in mine):8d} "
              f"{right:>11} {agree:>14}")  # fmt: skip


def plot(runs: list[Run], path: Path) -> None:
    """Outcomes per case."""
    report.plot_outcomes(
        report.count_outcomes([asdict(r) for r in runs], "case"),
        path,
        f"Start headings: {len(runs)} runs, {report.outcome_counts(asdict(r) for r in runs)}; "
        f"silent wrong 'done' {sum(r.silent_wrong for r in runs)}",
    )


def write(args: argparse.Namespace, runs: list[Run]) -> None:
    """results.json, headings.png and --json (after every run: a long matrix can be cut)."""
    report.write_runs([asdict(r) for r in runs], args.out / "results.json", args.json)
    plot(runs, args.out / "headings.png")


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    p = argparse.ArgumentParser(
        prog="python -m tools.eval_headings", description=__doc__.split("\n\n")[0]
    )
    p.add_argument("--headings", action="append", type=Headings.parse, default=[],
                   metavar="KIND", help="aligned | random | jitter:DEG (repeat; default random)")  # fmt: skip
    p.add_argument("--robots", action="append", type=int, default=[],
                   help="fleet size (repeat; default 4)")  # fmt: skip
    p.add_argument("--sensor-fault", action="append", default=[], metavar="KIND:AMOUNT",
                   help="one case per fault on robot 1 + seed mod N (the agent's test tool)")  # fmt: skip
    p.add_argument("--seed-start", type=int, default=1)
    p.add_argument("--seeds", type=int, default=10)
    p.add_argument("--timeout", type=float, default=900.0, help="wall limit of a run (s)")
    p.add_argument("--demo-arg", action="append", default=[], metavar="ARG",
                   help="one more tools.demo argument for every run (repeat)")  # fmt: skip
    p.add_argument("--json", type=Path, default=None)
    p.add_argument("--out", type=Path, default=Path("out/eval_headings"))
    add_live_arguments(p)
    p.add_argument("--report", type=Path, nargs="+", default=None, metavar="JSON",
                   help="run nothing: the table and figure of earlier --json files together")  # fmt: skip
    a = p.parse_args(argv)
    check_live_argument(p, a.live)
    a.headings = a.headings or [Headings("random")]
    a.robots = a.robots or [4]
    if any(not 2 <= n <= 64 for n in a.robots) or a.seeds < 1:
        p.error("--robots in [2, 64], --seeds >= 1")
    from agent.core.perception.sensor_fault import SensorFault

    for f in a.sensor_fault:
        try:
            SensorFault.parse(f)
        except ValueError as exc:
            p.error(str(exc))
    # every run's fleet: no camera frames for viewers unless asked (--demo-arg=--publish-camera)
    a.fleet = parse_fleet_spec(["--no-publish-camera", *a.demo_arg], "--demo-arg")
    faults = a.sensor_fault or [""]
    a.cases = [Case(h, n, f) for h in a.headings for n in a.robots for f in faults]
    return a


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    cases = [
        (c, s) for c in args.cases for s in range(args.seed_start, args.seed_start + args.seeds)
    ]

    def one(c: tuple[Case, int]) -> Run:
        slug = c[0].name.replace(" ", "_").replace(":", "-").replace("=", "")
        return run_one(args, c[0], c[1], args.out / slug / f"seed-{c[1]:03d}")

    runs = report.run_matrix(
        cases,
        one,
        report=lambda runs: write(args, runs),
        progress="eval_headings",
        label=lambda c, r: f"{c[0].name} seed {c[1]}: {r.outcome} ({r.detail[:70]})",
        earlier=args.report,
        row=Run,
    )
    print_table(runs)
    if args.report:
        return 0
    print(f"figure: {args.out / 'headings.png'}", file=sys.stderr)
    return report.exit_status(runs)


if __name__ == "__main__":
    raise SystemExit(main())
