"""``python -m tools.eval_faults``: crashed agents and restarted routers.

The papers assume robots and radios never fail. For each fault and seed this tool runs
the fleet as ``tools.demo`` does (secure by default: a TLS router, every process a
zenoh client of it; every agent with ``--state-dir``, its durable journal), injects
the fault, and judges the run from ground truth:

* ``kill-agent@P`` (P = search, agree, wait, move, hold): the first agent seen in phase
  P (search: while turning; move: as it starts, turning or walking) is killed (SIGKILL, no goodbye)
  and started again, same id, same state folder, ``--restart-after`` s later; it
  resumes from its journal (agent/phases/resume.py).
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
import signal
import sys
import time
from collections import Counter
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

from tools.harness import report
from tools.harness.judge import FAILURES, outcome, summarise
from tools.harness.live import add_live_arguments, check_live_argument, live_sinks
from tools.harness.observe import AgentView, Observer, Recorder, observe_for, observer_bus
from tools.harness.procs import (
    Proc,
    fleet_network,
    robot_ids,
    start_agent,
    start_router,
    start_world,
    stop,
    wait_ready,
)
from tools.harness.progress import Progress

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


@dataclass
class Run:
    seed: int
    fault: str
    outcome: str
    contacts: int
    wall_s: float
    detail: str
    victim: int = -1
    injected_at_s: float | None = None
    within_tolerance: bool = False


def triggered(view: AgentView, phase: str) -> bool:
    """Whether an agent's latest status is the moment to inject a fault at ``phase``."""
    if view.phase not in TRIGGER_PHASES[phase]:
        return False
    if phase == "search":  # during a turn: the heading is then in doubt
        return view.detail.startswith("turn to")
    return True


def run_one(args: argparse.Namespace, fault: str, seed: int, out: Path) -> Run:
    """One run of ``fault`` at ``seed`` (see the module docstring)."""
    out.mkdir(parents=True, exist_ok=True)
    what, phase = fault.split("@")
    n = args.robots
    net = fleet_network(args, out, n)
    t0 = time.monotonic()
    rec = Recorder(out / "run.mcap", sinks=live_sinks(args.live))
    obs = Observer(t0)
    procs: list[Proc] = []
    agents: dict[int, Proc] = {}
    router: Proc | None = None
    result: dict[str, Any] = {"robots": n, "seed": seed, "d_e": args.d_e}
    result.update(phi_e_deg=args.phi_e_deg, fault=fault)
    victim, injected, restart_at = -1, math.nan, math.inf
    state = ["--state-dir", str(out / "state")]
    if net.router:
        router = start_router(net.endpoint, out, net.flags)
    world_net = ["--connect" if net.router else "--listen", net.endpoint, *net.flags]
    bus = observer_bus(net)
    try:
        world = start_world(n, seed, net.endpoint, out, [], world_net)
        procs.append(world)

        def take() -> None:
            for ev in bus.drain(0.1):
                obs.take_event(ev, rec)

        wait_ready(world, args.world_timeout, take)
        ids = robot_ids(world.lines, n)
        agent_net = ["--connect", net.endpoint, *net.flags]
        for i in ids:
            agents[i] = start_agent(i, n, net.endpoint, out, args, agent_net, state)
        deadline = time.monotonic() + args.timeout
        while True:
            for ev in bus.drain(0.1):
                obs.take_event(ev, rec)
            now = time.monotonic()
            if math.isnan(injected):
                for i in ids:
                    view = obs.agents.get(i)
                    if (
                        view is not None
                        and agents[i].popen.poll() is None
                        and triggered(view, phase)
                    ):
                        injected, restart_at = now - t0, now + args.restart_after
                        if what == "kill-agent":
                            victim = i
                            agents[i].popen.send_signal(signal.SIGKILL)
                            agents[i].popen.wait()
                            agents[i].log.close()
                        elif router is not None:
                            router.popen.send_signal(signal.SIGKILL)
                            router.popen.wait()
                            router.log.close()
                        print(f"  [{injected:6.1f}s] {fault}: injected (robot {i} {view.phase})",
                              file=sys.stderr)  # fmt: skip
                        break
            elif now >= restart_at:
                restart_at = math.inf
                if what == "kill-agent":
                    agents[victim] = start_agent(
                        victim, n, net.endpoint, out, args, agent_net, state, append=True
                    )
                else:
                    router = start_router(net.endpoint, out, net.flags)
                print(f"  [{now - t0:6.1f}s] {fault}: restarted", file=sys.stderr)
            if restart_at == math.inf and all(p.popen.poll() is not None for p in agents.values()):
                break
            if now > deadline:
                result["timeout"] = f"agents still running after {args.timeout:g} s"
                break
        observe_for(bus, obs, rec, 1.5)  # the last truth after the motions
        result["wall_total"] = time.monotonic() - t0
    except RuntimeError as exc:
        result["timeout"] = f"harness: {exc}"
        ids = sorted(agents)
    finally:
        for p in reversed([*procs, *agents.values()]):
            stop(p)
        if router is not None:
            stop(router)
        bus.close()
        rec.close()
    for i, p in agents.items():
        obs.agents.setdefault(i, AgentView()).exit_code = p.popen.returncode
    if not math.isnan(injected) and restart_at != math.inf:
        result["timeout"] = "the run ended before the restart"
    res = summarise(obs, result, out, ids, args.d_e, math.radians(args.phi_e_deg), True)
    got, detail = outcome(res)
    if math.isnan(injected):
        detail = f"fault never injected (no agent reached {phase}); {detail}"
    return Run(
        seed=seed,
        fault=fault,
        outcome=got,
        contacts=int(res.get("contacts", 0)),
        wall_s=round(float(res.get("wall_total", time.monotonic() - t0)), 1),
        detail=detail[:400],
        victim=victim,
        injected_at_s=None if math.isnan(injected) else round(injected, 1),
        within_tolerance=bool(res.get("within_tolerance")),
    )


# --------------------------------------------------------------------------- report


def injected(row: report.Row) -> bool:
    """Whether the run's fault was injected (the others are counted apart)."""
    return row["injected_at_s"] is not None


def print_table(runs: list[Run]) -> None:
    report.print_runs([asdict(r) for r in runs], "fault")
    print(f"\n{'fault (injected runs)':22s} {'complete':>8} {'degraded':>8} {'safe_abort':>10} "
          f"{'unsafe':>6} {'no_result':>9} {'not injected':>12}")  # fmt: skip
    for fault in [*dict.fromkeys(r.fault for r in runs), "all"]:
        mine = [r for r in runs if fault in ("all", r.fault)]
        c = Counter(r.outcome for r in mine if r.injected_at_s is not None)
        missed = sum(1 for r in mine if r.injected_at_s is None)
        print(f"{fault:22s} {c['complete']:8d} {c['degraded']:8d} {c['safe_abort']:10d} "
              f"{c['unsafe']:6d} {c['no_result']:9d} {missed:12d}")  # fmt: skip


def plot(runs: list[Run], path: Path) -> None:
    """Outcomes per fault, of the runs in which it was injected."""
    done = [r for r in runs if r.injected_at_s is not None]
    report.plot_outcomes(
        report.count_outcomes([asdict(r) for r in runs], "fault", injected),
        path,
        f"Faults injected in {len(done)} runs: {report.outcome_counts(asdict(r) for r in done)}; "
        f"contacts {sum(r.contacts for r in runs)}",
        xlabel="runs (seeds) in which the fault was injected",
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
    p.add_argument("--d-e", type=float, default=0.8)
    p.add_argument("--phi-e-deg", type=float, default=30.0)
    p.add_argument("--timeout", type=float, default=900.0, help="wall limit of a run (s)")
    p.add_argument("--agree-timeout", type=float, default=120.0)
    p.add_argument("--world-timeout", type=float, default=120.0)
    p.add_argument("--agent-log-level", default="INFO", choices=("DEBUG", "INFO", "WARNING"))
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
    a.faults = [f.strip() for v in a.fault for f in v.split(",") if f.strip()] or list(FAULTS)
    bad = [f for f in a.faults if f not in FAULTS]
    if bad:
        p.error(f"unknown fault(s) {bad}; choose from {', '.join(FAULTS)}")
    if a.insecure and any(f.startswith("kill-router") for f in a.faults):
        p.error("kill-router needs the router of a secure run (drop --insecure)")
    if not (1 <= a.robots <= 64 and a.seeds >= 1 and a.restart_after >= 0):
        p.error("--robots in [1, 64], --seeds >= 1, --restart-after >= 0")
    a.plain_links = False
    return a


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    os.environ.setdefault("PYTHONUNBUFFERED", "1")
    runs: list[Run] = []
    if args.report:
        runs = [Run(**r) for r in report.read_runs(args.report)]
        write(args, runs)
        print_table(runs)
        return 0
    bar = Progress(len(args.faults) * args.seeds, "eval_faults")
    for fault in args.faults:
        for seed in range(args.seed_start, args.seed_start + args.seeds):
            r = run_one(args, fault, seed, args.out / fault.replace("@", "-") / f"seed-{seed:03d}")
            bar.step(f"{fault} seed {seed}: {r.outcome} ({r.detail[:100]})")
            runs.append(r)
            write(args, runs)
    print_table(runs)
    return 0 if all(r.outcome not in FAILURES for r in runs) else 1


def write(args: argparse.Namespace, runs: list[Run]) -> None:
    """results.json, faults.png and --json (after every run: a long matrix can be cut)."""
    report.write_runs([asdict(r) for r in runs], args.out / "results.json", args.json)
    plot(runs, args.out / "faults.png")


if __name__ == "__main__":
    raise SystemExit(main())
