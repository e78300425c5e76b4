"""``python -m tools.eval_chaos``: the chaos soak (random mixes of faults; docs/design.md §6 fault
injection).

``tools.eval_faults`` injects one fault at one moment; a fleet in the field meets several
at once. Each run here gets a random mix of faults, its schedule drawn from a numpy
``Generator`` seeded by the run's seed (:mod:`tools.lib.chaos_schedule`: reproducible, and
written to ``schedule.json`` in the run's folder): agent kills at random times (SIGKILL,
restarted after a random 1–5 s with the same id and ``--state-dir``; also the same agent
twice in a row and two agents at once), router restarts on the same endpoint, loss
bursts of 0–50 % per direction on every agent host (``tools.packet_drop``, the world's
port exempt, as ``tools.eval_loss``) and a slow world (every camera and motion reply
held up to 2 s, ``python -m sim --reply-delay``). Every process runs on its own test
host (:mod:`tools.harness.hosts`, network namespaces: needs root, iproute2, iptables),
secure by default (a TLS router, signed messages).

A fault whose moment comes after the agents finished is not injected (noted in the
schedule); killing an agent that has exited is skipped. Each run is judged by the one
rule of :func:`tools.harness.judge.outcome` from the monitor's ground truth: ``complete``,
``degraded`` (formed, but without a sound robot), ``unsafe`` (a contact, a robot that moved
off the plan the movers share, or every agent done on a formation the ground truth fails;
robots the fleet left out only stand still), ``safe_abort``, or ``no_result`` (the
monitor wrote none). Writes ``--json`` and ``results.json`` (``{"runs": [...]}`` as
``tools.eval_faults``, each run with its schedule and what was done when), ``chaos.png``
(per run a time line: the faults as injected, the outcome's colour) under ``--out`` (one
folder per run with the processes' logs, ``schedule.json``, ``result.json``,
``formation.png`` and ``run.mcap``), prints a table and a progress line with an estimate.
Exit 0 when no run failed (degraded, unsafe or no result).

``python -m tools.eval_chaos --runs 10 --seed-start 1 [--robots 3] [--out DIR] [--json FILE]``
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import signal
import sys
import time
from dataclasses import asdict
from pathlib import Path
from types import FrameType

from tools import netns
from tools.harness import report
from tools.harness.fleet import FleetSpec
from tools.harness.fleet_flags import add_agent_arguments, agent_settings
from tools.harness.hosts import TCP_RTO_MAX_RANGE
from tools.harness.judge import outcome
from tools.lib.chaos_injector import Injector
from tools.lib.chaos_report import Run, plot, print_table
from tools.lib.chaos_schedule import Limits, Schedule, draw

# =========================================================================== one run


def run_one(args: argparse.Namespace, sched: Schedule, out: Path, credentials: str) -> Run:
    """One run of ``sched`` (see the module docstring); setting up the test hosts may raise
    ``RuntimeError`` or ``netns.NetnsError``."""
    from tools.harness.hosts import HostFleet, Hosts

    out.mkdir(parents=True, exist_ok=True)
    (out / "schedule.json").write_text(json.dumps(sched.to_dict(), indent=2))
    t_start = time.monotonic()

    def say(text: str) -> None:
        print(f"  {text}", file=sys.stderr, flush=True)

    hosts = Hosts(args.prefix, tcp_rto_max_ms=args.tcp_rto_max_ms)
    with HostFleet(fleet_spec(args, sched, credentials), out, hosts) as fleet:
        inj = Injector(sched, fleet, fleet.ids, say)

        def busy(now: float) -> bool:
            inj.step(now)
            return inj.pending()

        try:  # the schedule's resolution: 0.1 s
            fleet.wait(busy, period=0.1)
        except (RuntimeError, OSError) as exc:  # a lever failed (a router that won't start)
            fleet.cut = f"harness: {exc}"
        end_s = time.monotonic() - fleet.t_agents
        inj.finish()
        res = fleet.judge()
        dropped = fleet.dropped_packets
    cut = fleet.cut
    doc = inj.schedule_doc()
    (out / "schedule.json").write_text(json.dumps(doc, indent=2))
    got, detail = outcome(res or {"no_result": cut or "the monitor wrote no result"})
    if not inj.injected_at and sched.reply_delay_s == 0:
        detail = f"no fault injected; {detail}"
    return Run(
        seed=sched.seed,
        mix=sched.mix(set(inj.injected_at)),
        outcome=got,
        contacts=int(res.get("contacts", 0)),
        wall_s=round(time.monotonic() - t_start, 1),
        detail=detail[:400],
        reply_delay_s=sched.reply_delay_s,
        end_s=round(end_s, 1),
        injected=len(inj.injected_at),
        dropped_packets=dropped,
        schedule=doc,
        events=inj.events,
    )


def fleet_spec(args: argparse.Namespace, sched: Schedule, credentials: str) -> FleetSpec:
    """The fleet of a run: every agent with its journal (``--state-dir``); a slow world
    (``--reply-delay``) when the schedule says so."""
    slow = ("--reply-delay", f"{sched.reply_delay_s:g}") if sched.reply_delay_s > 0 else ()
    return FleetSpec(
        robots=args.robots,
        seed=sched.seed,
        agent=args.agent,
        agent_log_level=args.agent_log_level,
        journal=True,
        world_args=slow,
        insecure=not credentials,
        credentials=Path(credentials) if credentials else None,
        timeout=args.timeout,
    )


def write(args: argparse.Namespace, runs: list[Run]) -> None:
    """results.json, chaos.png and --json (after every run: a long soak can be cut)."""
    report.write_runs([asdict(r) for r in runs], args.out / "results.json", args.json)
    plot(runs, args.out / "chaos.png")


# =========================================================================== CLI


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    p = argparse.ArgumentParser(
        prog="python -m tools.eval_chaos", description=__doc__.split("\n\n")[0]
    )
    p.add_argument("--runs", type=int, default=3, help="runs, seeds S..S+N-1")
    p.add_argument("--seed-start", type=int, default=1, metavar="S")
    p.add_argument("--robots", type=int, default=3)
    p.add_argument("--json", type=Path, default=None)
    p.add_argument("--out", type=Path, default=Path("out/eval_chaos"))
    p.add_argument("--horizon", type=float, default=30.0, metavar="S",
                   help="faults strike within the first S seconds after the agents started")  # fmt: skip
    p.add_argument("--max-loss", type=float, default=0.5, help="loss bursts up to this")
    p.add_argument("--max-reply-delay", type=float, default=2.0, metavar="S",
                   help="a slow world's replies delayed up to this")  # fmt: skip
    p.add_argument("--timeout", type=float, default=600.0, help="wall limit of a run (s)")
    p.add_argument("--prefix", default="nch", help="test hosts' namespace prefix (tools.netns)")
    add_agent_arguments(p)
    p.add_argument("--tcp-rto-max-ms", type=int, default=0, metavar="MS",
                   help="cap TCP's retransmission timeout on the test hosts (as tools.eval_loss)")  # fmt: skip
    p.add_argument("--insecure", action="store_true", help="no TLS or signatures")
    p.add_argument("--dry-run", action="store_true",
                   help="run nothing: print the schedules (and write them under --out)")  # fmt: skip
    p.add_argument("--report", type=Path, nargs="+", default=None, metavar="JSON",
                   help="run nothing: the table and figure (under --out) of earlier --json files")  # fmt: skip
    a = p.parse_args(argv)
    a.agent = agent_settings(p, a, timeout=a.agree_timeout)
    if a.runs < 1 or a.seed_start < 0:
        p.error("--runs must be >= 1 and --seed-start >= 0")
    if not 2 <= a.robots <= 20:
        p.error("--robots must be in [2, 20] (two agents are killed at once)")
    if not a.horizon > 2.0 or not a.timeout > 0:
        p.error("--horizon must be > 2 s and --timeout > 0")
    if not 0.0 <= a.max_loss <= 1.0:
        p.error("--max-loss must be a probability in [0, 1]")
    if not 0.0 <= a.max_reply_delay <= 10.0:
        p.error("--max-reply-delay must be in [0, 10] s")
    lo, hi = TCP_RTO_MAX_RANGE
    if a.tcp_rto_max_ms and not lo <= a.tcp_rto_max_ms <= hi:
        p.error(f"--tcp-rto-max-ms must be 0 or in [{lo}, {hi}]")
    return a


def schedules(args: argparse.Namespace) -> list[Schedule]:
    limits = Limits(max_loss=args.max_loss, max_reply_delay_s=args.max_reply_delay)
    seeds = range(args.seed_start, args.seed_start + args.runs)
    return [draw(s, args.robots, args.horizon, limits) for s in seeds]


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    os.environ.setdefault("PYTHONUNBUFFERED", "1")
    plan = schedules(args)
    if args.report:
        return soak(args, plan)
    if args.dry_run:
        for s in plan:
            folder = args.out / f"seed-{s.seed:03d}"
            folder.mkdir(parents=True, exist_ok=True)
            (folder / "schedule.json").write_text(json.dumps(s.to_dict(), indent=2))
            print(f"seed {s.seed}: {s.mix()}" + "".join(f"\n  {f}" for f in s.faults))
        return 0
    try:
        netns.preflight()
        if shutil.which("iptables") is None:
            raise netns.NetnsError("iptables is not installed: apt-get install iptables")
    except netns.NetnsError as exc:
        print(f"eval_chaos: {exc}", file=sys.stderr)
        return 1

    def on_term(signum: int, frame: FrameType | None) -> None:
        raise KeyboardInterrupt  # unwinds through the test hosts, which are removed

    signal.signal(signal.SIGTERM, on_term)
    try:
        return soak(args, plan)
    except KeyboardInterrupt:
        print("eval_chaos: interrupted; test hosts removed", file=sys.stderr)
        return 130


def soak(args: argparse.Namespace, plan: list[Schedule]) -> int:
    """The runs of ``plan`` (or, with ``--report``, the rows of earlier files), reported."""
    from tools.harness.hosts import host_fleet_credentials

    args.out.mkdir(parents=True, exist_ok=True)
    mine = not (args.insecure or args.report)
    creds = host_fleet_credentials(args.out, args.robots) if mine else ""

    def one(sched: Schedule) -> Run:
        print(f"[eval_chaos] seed {sched.seed}: {sched.mix()}", file=sys.stderr, flush=True)
        return run_one(args, sched, args.out / f"seed-{sched.seed:03d}", creds)

    try:
        runs = report.run_matrix(
            plan,
            one,
            report=lambda runs: write(args, runs),
            progress="eval_chaos",
            label=lambda s, r: f"seed {s.seed} {r.mix}: {r.outcome} ({r.detail[:60]})",
            earlier=args.report,
            row=Run,
        )
    except (RuntimeError, netns.NetnsError, OSError) as exc:
        print(f"eval_chaos: run failed to start: {exc}", file=sys.stderr)
        return 1
    print_table(runs)
    if args.report:
        return 0
    print(f"wrote {args.out / 'results.json'}, {args.out / 'chaos.png'}")
    return report.exit_status(runs)


if __name__ == "__main__":
    raise SystemExit(main())
