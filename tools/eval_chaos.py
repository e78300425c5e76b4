"""``python -m tools.eval_chaos``: the chaos soak (random mixes of faults; docs/design.md §6 fault
injection).

``tools.eval_faults`` injects one fault at one moment; a fleet in the field meets several
at once. Each run here gets a random mix of faults, its schedule drawn from a numpy
``Generator`` seeded by the run's seed (:mod:`tools.chaos_schedule`: reproducible, and
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
from collections import Counter
from dataclasses import asdict, dataclass, field
from pathlib import Path
from types import FrameType
from typing import Any, Protocol

from tools import netns
from tools.chaos_schedule import TAGS, Limits, Schedule, draw, with_injected
from tools.harness import report
from tools.harness.judge import FAILURES, outcome
from tools.harness.progress import Progress


@dataclass
class Run:
    seed: int
    mix: str  # the schedule's tags (tools.chaos_schedule), the table's group
    outcome: str
    contacts: int
    wall_s: float
    detail: str
    reply_delay_s: float = 0.0
    end_s: float | None = None  # the agents' time line: started -> the last one exited
    injected: int = 0  # faults injected
    dropped_packets: int = 0
    #: Schedule.to_dict(), each fault with ``injected_at_s`` (None: not) and ``note``
    schedule: dict[str, Any] = field(default_factory=dict)
    events: list[dict[str, Any]] = field(default_factory=list)  # what was done when


# =========================================================================== injection


class Levers(Protocol):
    """What the injector pulls (:class:`tools.harness.hosts.HostFleet`; a fake in tests)."""

    def running(self, rid: int) -> bool: ...

    def all_exited(self) -> bool: ...

    def kill_agent(self, rid: int) -> None: ...

    def start_agent(self, rid: int, append: bool = False) -> None: ...

    def kill_router(self) -> None: ...

    def start_router(self) -> None: ...

    def set_loss(self, loss: float) -> None: ...

    def clear_loss(self) -> None: ...


class Injector:
    """Walks a schedule's time line (:meth:`Schedule.actions`) on a fleet's levers.

    Robots of the schedule (1..robots) are the world's ids in order. A kill of an agent
    that has exited is skipped (its restart too); the router and the loss are left alone
    once every agent has exited and no restart is pending (the run is over)."""

    def __init__(self, sched: Schedule, fleet: Levers, ids: list[int], say: Any = None) -> None:
        self.sched, self.fleet, self.ids = sched, fleet, ids
        self.todo = sched.actions()
        self.k = 0
        self.down: set[int] = set()  # robots killed whose restart is pending
        self.router_down = False
        self.loss_on = False
        self.injected_at: dict[int, float] = {}
        self.notes: dict[int, str] = {}
        self.events: list[dict[str, Any]] = []
        self._say = say

    def pending(self) -> bool:
        """A restart is still to come."""
        return bool(self.down) or self.router_down

    def over(self) -> bool:
        return self.fleet.all_exited() and not self.pending()

    def step(self, now: float) -> None:
        """Do every action due at ``now`` (seconds after the agents started)."""
        while self.k < len(self.todo) and self.todo[self.k].t <= now:
            a = self.todo[self.k]
            self.k += 1
            rid = self.ids[a.robot - 1] if a.robot else 0
            done = self._do(a.what, a.fault, rid, a.robot, a.loss)
            if done:
                self.events.append({"t": round(now, 1), "action": a.what, "fault": a.fault,
                                    "robot": rid, "loss": a.loss})  # fmt: skip
                if a.what in ("kill", "kill-router", "loss-on"):
                    self.injected_at.setdefault(a.fault, round(now, 1))
                if self._say is not None:
                    extra = f" robot {rid}" if rid else f" {a.loss:.0%}" if a.loss else ""
                    self._say(f"[{now:6.1f}s] {a.what}{extra}")

    def _do(self, what: str, fault: int, rid: int, robot: int, loss: float) -> bool:
        f = self.fleet
        if what == "kill":
            if not f.running(rid):
                self.notes[fault] = f"robot {rid} had exited"
                return False
            f.kill_agent(rid)
            self.down.add(robot)
        elif what == "restart":
            if robot not in self.down:
                return False
            f.start_agent(rid, append=True)
            self.down.discard(robot)
        elif what in ("kill-router", "loss-on"):
            if self.over():
                self.notes[fault] = "the agents had finished"
                return False
            if what == "kill-router":
                f.kill_router()
                self.router_down = True
            else:
                f.set_loss(loss)
                self.loss_on = True
        elif what == "restart-router":
            if not self.router_down:
                return False
            f.start_router()
            self.router_down = False
        elif what == "loss-off":
            if not self.loss_on:
                return False
            f.clear_loss()
            self.loss_on = False
        return True

    def finish(self) -> None:
        """The run is over: the loss cleared, the faults never reached noted."""
        if self.loss_on:
            self.fleet.clear_loss()
            self.loss_on = False
        for i in range(len(self.sched.faults)):
            if i not in self.injected_at:
                self.notes.setdefault(i, "the agents had finished")

    def schedule_doc(self) -> dict[str, Any]:
        """The schedule with each fault's ``injected_at_s`` and ``note``."""
        doc = self.sched.to_dict()
        for i, f in enumerate(doc["faults"]):
            f["injected_at_s"] = self.injected_at.get(i)
            f["note"] = self.notes.get(i, "")
        doc["injected_tags"] = self.sched.tags(set(self.injected_at))
        return doc


# =========================================================================== one run


def run_one(args: argparse.Namespace, sched: Schedule, out: Path, credentials: str) -> Run:
    """One run of ``sched`` (see the module docstring); setting up the test hosts may raise
    ``RuntimeError`` or ``netns.NetnsError``."""
    from tools.harness.hosts import HostFleet

    out.mkdir(parents=True, exist_ok=True)
    (out / "schedule.json").write_text(json.dumps(sched.to_dict(), indent=2))
    t_start = time.monotonic()
    slow = ["--reply-delay", f"{sched.reply_delay_s:g}"] if sched.reply_delay_s > 0 else []
    cut: str | None = None

    def say(text: str) -> None:
        print(f"  {text}", file=sys.stderr, flush=True)

    fleet = HostFleet(args, args.robots, sched.seed, out, args.prefix, credentials, slow)
    with fleet:
        inj = Injector(sched, fleet, fleet.ids, say)
        t0 = time.monotonic()
        for rid in fleet.ids:
            fleet.start_agent(rid)
        now = 0.0
        try:
            while True:
                now = time.monotonic() - t0
                inj.step(now)
                if inj.over():
                    break
                if now > args.timeout:
                    cut = f"agents still running after {args.timeout:g} s"
                    break
                time.sleep(0.1)  # the schedule's resolution; bounded by --timeout
        except (RuntimeError, OSError) as exc:  # a lever failed (a router that won't start)
            cut = f"harness: {exc}"
        end_s = time.monotonic() - t0
        inj.finish()
        res = fleet.judge(cut)
        dropped = fleet.dropped_packets
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


# =========================================================================== report


def print_table(runs: list[Run]) -> None:
    """One line per run (its injected mix), then the outcomes per fault kind injected."""
    report.print_runs([asdict(r) for r in runs], "mix", detail_width=70)
    print(f"\n{'fault (runs it hit)':20s} {'complete':>8} {'degraded':>8} {'safe_abort':>10} "
          f"{'unsafe':>6} {'no_result':>9}")  # fmt: skip
    for tag in [*TAGS, "all"]:
        mine = [r for r in runs if tag == "all" or tag in r.mix.split("+")]
        if mine:
            c = Counter(r.outcome for r in mine)
            print(f"{tag:20s} {c['complete']:8d} {c['degraded']:8d} {c['safe_abort']:10d} "
                  f"{c['unsafe']:6d} {c['no_result']:9d}")  # fmt: skip


def plot(runs: list[Run], path: Path) -> None:
    """Per run a time line from the agents' start: the bar in the outcome's colour, the
    loss bursts shaded (their rate written), agent kills (x; the line: down until the
    restart, then the robot's id) and router restarts (v); faults not injected in grey."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.artist import Artist

    fig, ax = plt.subplots(figsize=(10, 1.8 + 0.55 * len(runs)))
    for y, r in enumerate(runs):
        sched = Schedule.from_dict(r.schedule)
        hit = with_injected(r.schedule.get("faults", []))
        end = r.end_s if r.end_s is not None else max((f.end() for f in sched.faults), default=1)
        ax.barh(y, end, height=0.6, color=report.COLOURS[r.outcome], alpha=0.45)
        for i, f in enumerate(sched.faults):
            ink = "black" if i in hit else "0.6"
            if f.kind == "loss":
                ax.barh(y, f.duration_s, left=f.t, height=0.6, color="tab:blue",
                        alpha=(0.15 + 0.6 * f.loss) if i in hit else 0.1)  # fmt: skip
                ax.text(f.t + f.duration_s / 2, y + 0.05, f"{f.loss:.0%}", ha="center",
                        va="center", fontsize=7, color=ink)  # fmt: skip
            elif f.kind == "kill-router":
                ax.plot([f.t, f.t + f.down_s[0]], [y - 0.2] * 2, color="tab:purple" if i in hit else ink, lw=3)  # fmt: skip
                ax.plot(f.t, y - 0.2, "v", color=ink, ms=7)
            else:
                for k, (rob, d) in enumerate(zip(f.robots, f.down_s, strict=True)):
                    yy = y + 0.18 - 0.14 * k
                    ax.plot([f.t, f.t + d], [yy] * 2, color=ink, lw=2)
                    ax.plot(f.t, yy, "x", color=ink, ms=7, mew=2)
                    ax.text(f.t + d + 0.3, yy, str(rob), va="center", fontsize=7, color=ink)
    labels = [f"seed {r.seed}" + (f", slow {r.reply_delay_s:g} s" if r.reply_delay_s else "")
              for r in runs]  # fmt: skip
    ax.set_yticks(range(len(runs)), labels, fontsize=8)
    ax.invert_yaxis()
    handles: list[Artist] = [
        plt.Rectangle((0, 0), 1, 1, color=report.COLOURS[o], alpha=0.45) for o in report.COLOURS
    ]
    handles += [
        plt.Line2D(
            [], [], color="black", marker="x", lw=2, label="agent killed .. restarted (its id)"
        ),
        plt.Line2D([], [], color="tab:purple", marker="v", lw=3, label="router restart"),
        plt.Rectangle((0, 0), 1, 1, color="tab:blue", alpha=0.4, label="loss burst"),
    ]
    names = [*report.COLOURS, "agent killed .. restarted (its id)", "router restart", "loss burst"]
    ax.legend(handles, names, loc="upper center", bbox_to_anchor=(0.5, -0.5 / (1 + len(runs) / 3)),
              ncol=3, fontsize=8)  # fmt: skip
    ax.set_title(f"Chaos soak, {len(runs)} runs: {report.outcome_counts(asdict(r) for r in runs)}; "
                 f"contacts {sum(r.contacts for r in runs)} (grey: not injected)", fontsize=10)  # fmt: skip
    ax.set_xlabel("seconds after the agents started")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


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
    p.add_argument("--d-e", type=float, default=0.8)
    p.add_argument("--phi-e-deg", type=float, default=30.0)
    p.add_argument("--agree-timeout", type=float, default=120.0)
    p.add_argument("--agent-log-level", default="INFO", choices=("DEBUG", "INFO", "WARNING"))
    p.add_argument("--tcp-rto-max-ms", type=int, default=0, metavar="MS",
                   help="cap TCP's retransmission timeout on the test hosts (as tools.eval_loss)")  # fmt: skip
    p.add_argument("--insecure", action="store_true", help="no TLS or signatures")
    p.add_argument("--dry-run", action="store_true",
                   help="run nothing: print the schedules (and write them under --out)")  # fmt: skip
    p.add_argument("--report", type=Path, nargs="+", default=None, metavar="JSON",
                   help="run nothing: the table and figure (under --out) of earlier --json files")  # fmt: skip
    a = p.parse_args(argv)
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
    if a.tcp_rto_max_ms and not 1000 <= a.tcp_rto_max_ms <= 120000:
        p.error("--tcp-rto-max-ms must be 0 or in [1000, 120000]")
    return a


def schedules(args: argparse.Namespace) -> list[Schedule]:
    limits = Limits(max_loss=args.max_loss, max_reply_delay_s=args.max_reply_delay)
    seeds = range(args.seed_start, args.seed_start + args.runs)
    return [draw(s, args.robots, args.horizon, limits) for s in seeds]


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    os.environ.setdefault("PYTHONUNBUFFERED", "1")
    if args.report:
        runs = [Run(**r) for r in report.read_runs(args.report)]
        write(args, runs)
        print_table(runs)
        return 0
    plan = schedules(args)
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
    from tools.harness.hosts import host_fleet_credentials

    args.out.mkdir(parents=True, exist_ok=True)
    creds = "" if args.insecure else host_fleet_credentials(args.out, args.robots)
    progress = Progress(len(plan), "eval_chaos")
    runs: list[Run] = []
    for sched in plan:
        print(f"[eval_chaos] seed {sched.seed}: {sched.mix()}", file=sys.stderr, flush=True)
        try:
            r = run_one(args, sched, args.out / f"seed-{sched.seed:03d}", creds)
        except (RuntimeError, netns.NetnsError, OSError) as exc:
            print(f"eval_chaos: run failed to start: {exc}", file=sys.stderr)
            return 1
        runs.append(r)
        write(args, runs)
        progress.step(f"seed {sched.seed} {r.mix}: {r.outcome} ({r.detail[:60]})")
    print_table(runs)
    print(f"wrote {args.out / 'results.json'}, {args.out / 'chaos.png'}")
    return 0 if all(r.outcome not in FAILURES for r in runs) else 1


if __name__ == "__main__":
    raise SystemExit(main())
