"""``python -m tools.eval_faults``: crashed agents and restarted routers.

The papers assume robots and radios never fail. For each fault and seed this tool runs
the fleet as ``tools.demo`` does (secure by default: a TLS router, every process a
zenoh client of it; every agent with ``--state-dir``, its durable journal), injects
the fault, and judges the run from ground truth:

* ``kill-agent@P`` (P = search, agree, wait, move, hold): the first agent seen in phase
  P (search: while turning; move: as it starts, turning or walking) is killed (SIGKILL, no goodbye)
  and started again, same id, same state folder, ``--restart-after`` s later; it
  resumes from its journal (agent/recovery/resume.py).
* ``kill-router@P`` (P = agree, move): the router is killed when the first agent is in
  P and started again on the same endpoint ``--restart-after`` s later; the clients
  reconnect and declare their tokens again, the membership grace period covers the gap.

Outcomes, by the one rule of :func:`tools.harness.judge.outcome`: ``complete`` (every
agent exited 0 in ``done``, identical plan digests, no contact, the true shape within the
demo's tolerances), ``degraded`` (the same, but a sound robot left out), ``unsafe`` (a
contact, a robot that moved, by the ground truth, off the plan the others share, or
every agent done on a formation the ground truth fails), else ``safe_abort``; ``detail``
says why. Exit 0 when no run failed (degraded, unsafe, no result). Writes ``--json`` (``{"runs": [...]}``),
``results.json`` and ``faults.png`` under ``--out`` (one directory per run with the
processes' logs, ``result.json``, ``formation.png`` and ``run.mcap``) and prints a table
(:mod:`tools.harness.report`, as every evaluation tool).

``python -m tools.eval_faults --fault kill-agent@move --robots 3 --seed-start 1 --seeds 3``
"""

from __future__ import annotations

import argparse
import math
import os
import sys
from dataclasses import asdict
from pathlib import Path

from tools.harness import report
from tools.harness.fleet import Fleet, FleetSpec
from tools.harness.fleet_flags import add_agent_arguments, agent_settings
from tools.harness.judge import outcome
from tools.harness.observe import AgentView
from tools.harness.view.live import add_live_arguments, check_live_argument
from tools.lib.faults_report import Run, plot, print_table

FAULTS = (
    "kill-agent@search",
    "kill-agent@agree",
    "kill-agent@wait",
    "kill-agent@move",
    "kill-agent@hold",
    "kill-router@agree",
    "kill-router@move",
)
#: The phases each fault's trigger accepts (``agree`` covers the whole exchange).
TRIGGER_PHASES = {
    "search": ("search",),
    "agree": ("exchange", "agree"),
    "wait": ("wait",),
    "move": ("move",),
    "hold": ("hold",),
}


def triggered(view: AgentView, phase: str) -> bool:
    """Whether an agent's latest status is the moment to inject a fault at ``phase``."""
    if view.phase not in TRIGGER_PHASES[phase]:
        return False
    if phase == "search":  # during a turn: the heading is then in doubt
        return view.detail.startswith("turn to")
    return True


def run_one(args: argparse.Namespace, fault: str, seed: int, out: Path) -> Run:
    """One run of ``fault`` at ``seed`` (see the module docstring)."""
    what, phase = fault.split("@")
    fleet = Fleet(fleet_spec(args, seed), out)
    fleet.result["fault"] = fault
    victim, injected, restart_at = -1, math.nan, math.inf

    def inject(now: float) -> bool:
        """Kill at the trigger, restart ``--restart-after`` s later; True while a restart
        is pending."""
        nonlocal victim, injected, restart_at
        if math.isnan(injected):
            for i in fleet.ids:
                view = fleet.obs.agents.get(i)
                if view is not None and fleet.running(i) and triggered(view, phase):
                    injected, restart_at = now, now + args.restart_after
                    if what == "kill-agent":
                        victim = i
                        fleet.kill_agent(i)
                    else:
                        fleet.kill_router()
                    print(f"  [{now:6.1f}s] {fault}: injected (robot {i} {view.phase})",
                          file=sys.stderr)  # fmt: skip
                    break
        elif now >= restart_at:
            restart_at = math.inf
            if what == "kill-agent":
                fleet.start_agent(victim, append=True)
            else:
                fleet.start_router()
            print(f"  [{now:6.1f}s] {fault}: restarted", file=sys.stderr)
        return restart_at != math.inf

    try:
        with fleet:
            fleet.wait(inject)
    except RuntimeError as exc:
        fleet.result["timeout"] = f"harness: {exc}"
    if not math.isnan(injected) and restart_at != math.inf:
        fleet.result["timeout"] = "the run ended before the restart"
    res = fleet.judge()
    got, detail = outcome(res)
    if math.isnan(injected):
        detail = f"fault never injected (no agent reached {phase}); {detail}"
    return Run(
        seed=seed,
        fault=fault,
        outcome=got,
        contacts=int(res.get("contacts", 0)),
        wall_s=round(float(res.get("wall_total", fleet.elapsed())), 1),
        detail=detail[:400],
        victim=victim,
        injected_at_s=None if math.isnan(injected) else round(injected, 1),
        within_tolerance=bool(res.get("within_tolerance")),
    )


def fleet_spec(args: argparse.Namespace, seed: int) -> FleetSpec:
    """The fleet of every run: as the demo's, every agent with its journal (``--state-dir``)."""
    return FleetSpec(
        robots=args.robots,
        seed=seed,
        agent=args.agent,
        agent_log_level=args.agent_log_level,
        journal=True,
        credentials=args.credentials,
        insecure=args.insecure,
        timeout=args.timeout,
        world_timeout=args.world_timeout,
        live=args.live,
    )


# --------------------------------------------------------------------------- CLI


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    p = argparse.ArgumentParser(
        prog="python -m tools.eval_faults", description=__doc__.split("\n\n")[0]
    )
    p.add_argument("--fault", action="append", default=[],
                   help=f"one of {', '.join(FAULTS)} (repeat or comma-separate; default: all)")  # fmt: skip
    p.add_argument("--restart-after", type=float, default=3.0, metavar="S")
    p.add_argument("--robots", type=int, default=3)
    p.add_argument("--seed-start", type=int, default=1)
    p.add_argument("--seeds", type=int, default=3)
    p.add_argument("--json", type=Path, default=None)
    p.add_argument("--out", type=Path, default=Path("out/eval_faults"))
    add_agent_arguments(p)
    p.add_argument("--timeout", type=float, default=900.0, help="wall limit of a run (s)")
    p.add_argument("--world-timeout", type=float, default=FleetSpec.world_timeout)
    p.add_argument("--credentials", type=Path, default=None)
    p.add_argument("--insecure", action="store_true", help="no TLS/router (kill-router needs one)")
    add_live_arguments(p)  # every run of the matrix on one live server
    p.add_argument(
        "--report",
        type=Path,
        nargs="+",
        default=None,
        metavar="JSON",
        help="run nothing: the table and figure (under --out) of earlier --json files together",
    )
    a = p.parse_args(argv)
    check_live_argument(p, a.live)
    a.agent = agent_settings(p, a, timeout=a.agree_timeout)
    a.faults = [f.strip() for v in a.fault for f in v.split(",") if f.strip()] or list(FAULTS)
    bad = [f for f in a.faults if f not in FAULTS]
    if bad:
        p.error(f"unknown fault(s) {bad}; choose from {', '.join(FAULTS)}")
    if a.insecure and any(f.startswith("kill-router") for f in a.faults):
        p.error("kill-router needs the router of a secure run (drop --insecure)")
    if not (1 <= a.robots <= 64 and a.seeds >= 1 and a.restart_after >= 0):
        p.error("--robots in [1, 64], --seeds >= 1, --restart-after >= 0")
    return a


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    os.environ.setdefault("PYTHONUNBUFFERED", "1")
    cases = [
        (f, s) for f in args.faults for s in range(args.seed_start, args.seed_start + args.seeds)
    ]
    runs = report.run_matrix(
        cases,
        lambda c: run_one(args, c[0], c[1], args.out / c[0].replace("@", "-") / f"seed-{c[1]:03d}"),
        report=lambda runs: write(args, runs),
        progress="eval_faults",
        label=lambda c, r: f"{c[0]} seed {c[1]}: {r.outcome} ({r.detail[:100]})",
        earlier=args.report,
        row=Run,
    )
    print_table(runs)
    return 0 if args.report else report.exit_status(runs)


def write(args: argparse.Namespace, runs: list[Run]) -> None:
    """results.json, faults.png and --json (after every run: a long matrix can be cut)."""
    report.write_runs([asdict(r) for r in runs], args.out / "results.json", args.json)
    plot(runs, args.out / "faults.png")


if __name__ == "__main__":
    raise SystemExit(main())
