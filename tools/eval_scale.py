"""``python -m tools.eval_scale``: the fleet at 10, 30, 50 and 100 NAOs and where the wall
time goes (fifty NAOs and beyond; docs/design.md §1 phases, §9 "Honest results").

Runs the fleet as ``tools.demo`` does (secure, a TLS router, the world and one agent
process per robot, camera frames for viewers off) once per fleet size and seed, one run
at a time, and judges every run from the ground truth with the one rule of
:func:`tools.harness.judge.outcome` (``complete``, ``degraded``, ``safe_abort``,
``unsafe``, ``unjudged``, ``no_result``; a silent wrong "done" is unsafe; exit 0 when no
run failed: degraded, unsafe or no result). Per run it keeps the contacts, the wall time, the agreement's
own time (``agreement_s``: the last agent entering exchange to the last one planning),
the exchange bytes per agent (records and digests, the largest and the median agent),
the slowest agent's wall time in each phase (``result.json``'s ``phases``) and the
machine's 1-minute load average while it ran (start, mean, end): on a shared 2-core
machine the load is part of every number.

Writes the shared JSON (``{"runs": [...]}``; :mod:`tools.harness.report`) to
``results.json`` under ``--out`` (and ``--json``), the *phase chart* ``scale_phases.png``
(one stacked bar per run: the world's start-up, then the slowest agent's time in each
phase, the run's wall time marked) and ``table.md`` (the table as Markdown), after every
run; prints the table and a progress line per run. ``--report`` redraws all of it from
earlier JSON files without running anything.

    python -m tools.eval_scale --robots 10 --robots 30 --robots 50 --robots 100 --seeds 1
    python -m tools.eval_scale --robots 50 --seed-start 11 --seeds 1 --timeout 3600
    python -m tools.eval_scale --report out/eval_scale/results.json --out docs/img
"""

from __future__ import annotations

import argparse
import os
import sys
import threading
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import asdict, replace
from pathlib import Path

from agent.config import AgentConfig
from tools.harness import report
from tools.harness.fleet import MAX_ROBOTS, FleetSpec, run_fleet
from tools.harness.fleet_flags import parse_fleet_spec
from tools.lib.scale_report import (
    FIGURE,
    Run,
    markdown,
    plot_phases,
    print_table,
    row_of,
)


@contextmanager
def load_samples(
    period: float = 5.0, read: Callable[[], float] = lambda: os.getloadavg()[0]
) -> Iterator[list[float]]:
    """The 1-minute load average, sampled every ``period`` s while the block runs (the
    first sample at its start, the last at its end)."""
    samples = [read()]
    stop = threading.Event()

    def sample() -> None:
        while not stop.wait(period):
            samples.append(read())

    t = threading.Thread(target=sample, daemon=True)
    t.start()
    try:
        yield samples
    finally:
        stop.set()
        t.join()
        samples.append(read())


def agree_timeout(args: argparse.Namespace, robots: int) -> float:
    """The agents' agreement timeout (``python -m agent --timeout``): ``--agree-timeout``,
    or by default max(120, 3·N) s. An agent's agreement times out that long after the
    fleet's last news (a new record or digest), and the world renders every robot's
    search on its own cores, so the gaps between the last searches' ends grow with N
    (120 s is the agents' default, enough for 30 NAOs)."""
    given: float | None = args.agree_timeout
    return given if given is not None else max(AgentConfig.timeout, 3.0 * robots)


def wave_timeout(args: argparse.Namespace) -> float:
    """The agents' wait limit for earlier waves and for the fleet to hold (``python -m
    agent --wave-timeout``, wall s): ``--wave-timeout``, or by default the run's
    ``--timeout``. The agents' default (600 s) is shorter than the waves of 100 NAOs on
    a loaded 2-core machine take; the run's own limit still bounds every run."""
    given: float | None = args.wave_timeout
    return given if given is not None else float(args.timeout)


def run_one(args: argparse.Namespace, robots: int, seed: int, out: Path) -> Run:
    """One run of ``robots`` NAOs at ``seed`` (module docstring)."""
    base: FleetSpec = args.fleet
    agree_s, wave_s = agree_timeout(args, robots), wave_timeout(args)
    spec = replace(base, robots=robots, seed=seed, timeout=args.timeout,
                   world_timeout=args.world_timeout,
                   agent=replace(base.agent, timeout=agree_s, wave_timeout=wave_s))  # fmt: skip
    with load_samples() as load:
        try:
            r = run_fleet(spec, out)
        except RuntimeError as exc:
            r = {"no_result": f"demo: {exc}"}
    return row_of(r, robots, seed, load, agree_s, wave_s)


# ===================================================================== CLI


def write(args: argparse.Namespace, runs: list[Run]) -> None:
    """results.json (and --json), the phase chart and table.md; after every run."""
    report.write_runs([asdict(r) for r in runs], args.out / "results.json", args.json)
    plot_phases(runs, args.figure or args.out / FIGURE)
    (args.out / "table.md").write_text(markdown(runs))


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    p = argparse.ArgumentParser(
        prog="python -m tools.eval_scale", description=__doc__.split("\n\n")[0]
    )
    p.add_argument("--robots", action="append", type=int, default=[],
                   help=f"fleet size in [2, {MAX_ROBOTS}] (repeat; default 10, 30, 50)")  # fmt: skip
    p.add_argument("--seed-start", type=int, default=1)
    p.add_argument("--seeds", type=int, default=1)
    p.add_argument("--timeout", type=float, default=2400.0, help="wall limit of a run (s)")
    p.add_argument("--world-timeout", type=float, default=300.0,
                   help="wall limit of the world's start-up (s)")  # fmt: skip
    p.add_argument("--agree-timeout", type=float, default=None, metavar="S",
                   help="the agents' agreement timeout (default max(120, 3 N) s)")  # fmt: skip
    p.add_argument("--wave-timeout", type=float, default=None, metavar="S",
                   help="the agents' wait for earlier waves (default: --timeout)")  # fmt: skip
    p.add_argument("--demo-arg", action="append", default=[], metavar="ARG",
                   help="one more tools.demo argument for every run (repeat)")  # fmt: skip
    p.add_argument("--json", type=Path, default=None)
    p.add_argument("--out", type=Path, default=Path("out/eval_scale"))
    p.add_argument("--figure", type=Path, default=None,
                   help=f"the phase chart's path (default OUT/{FIGURE})")  # fmt: skip
    p.add_argument("--report", type=Path, nargs="+", default=None, metavar="JSON",
                   help="run nothing: the table and chart of earlier --json files together")  # fmt: skip
    a = p.parse_args(argv)
    a.robots = a.robots or [10, 30, 50]
    if any(not 2 <= n <= MAX_ROBOTS for n in a.robots) or a.seeds < 1:
        p.error(f"--robots in [2, {MAX_ROBOTS}], --seeds >= 1")
    given = [t for t in (a.agree_timeout, a.wave_timeout) if t is not None]
    if not (a.timeout > 0 and a.world_timeout > 0 and all(t > 0 for t in given)):
        p.error("--timeout, --world-timeout, --agree-timeout and --wave-timeout must be > 0")
    # every run's fleet: camera frames for viewers off
    a.fleet = parse_fleet_spec(["--no-publish-camera", *a.demo_arg], "--demo-arg")
    return a


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    cases = [
        (n, s) for n in args.robots for s in range(args.seed_start, args.seed_start + args.seeds)
    ]
    runs = report.run_matrix(
        cases,
        lambda c: run_one(args, c[0], c[1], args.out / f"n{c[0]:03d}" / f"seed-{c[1]:03d}"),
        report=lambda runs: write(args, runs),
        progress="eval_scale",
        label=lambda c, r: (
            f"N={c[0]} seed {c[1]}: {r.outcome}, wall {r.wall_s:.0f} s, "
            f"load {r.load_mean:.0f} ({r.detail[:60]})"
        ),
        earlier=args.report,
        row=Run,
    )
    print_table(runs)
    if args.report:
        return 0
    print(f"figure: {args.figure or args.out / FIGURE}", file=sys.stderr)
    return report.exit_status(runs)


if __name__ == "__main__":
    raise SystemExit(main())
