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
import statistics
import sys
import threading
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from tools.demo import MAX_ROBOTS
from tools.harness import report
from tools.harness.judge import FAILURES, PHASE_ORDER, outcome
from tools.harness.progress import Progress

#: The phases drawn, in the order of docs/design.md §1 (``done`` ends a run: no duration).
PHASES = tuple(p for p in PHASE_ORDER if p != "done")
#: The world's start-up before the agents start: the first segment of a bar.
WORLD = "world start"
FIGURE = "scale_phases.png"


@dataclass
class Run:
    robots: int
    seed: int
    outcome: str
    contacts: int
    wall_s: float
    detail: str
    silent_wrong: bool = False
    agreement_s: float | None = None
    exchange_bytes_max: int = 0
    exchange_bytes_median: float = 0.0
    world_ready_s: float = 0.0
    #: the slowest agent's wall time in each phase (s), as ``result.json``'s ``phases``
    phases: dict[str, float] = field(default_factory=dict)
    max_abs_r_d: float | None = None
    max_abs_r_phi: float | None = None
    min_separation: float | None = None
    #: bus events the observer dropped unread (its queue full: it lagged; phase times are
    #: when the observer read the statuses, and dropped records are missing from the bytes)
    dropped: int = 0
    #: the agents' agreement timeout and wait limit for earlier waves of the run (s)
    agree_timeout_s: float = 120.0
    wave_timeout_s: float = 600.0
    #: the 1-minute load average at the run's start, its mean over the run, at its end
    load_start: float = 0.0
    load_mean: float = 0.0
    load_end: float = 0.0

    @property
    def name(self) -> str:
        return f"N={self.robots} seed {self.seed}"


def _finite(v: Any) -> float | None:
    return float(v) if isinstance(v, int | float) and v == v else None


def row_of(
    r: dict[str, Any],
    robots: int,
    seed: int,
    load: Sequence[float],
    agree_timeout_s: float = 120.0,
    wave_timeout_s: float = 600.0,
) -> Run:
    """A judged ``result.json`` (``tools.harness.judge.summarise``) as one row."""
    got, detail = outcome(r)
    exch = sorted(int(v) for v in r.get("exchange_bytes", {}).values())
    phases = r.get("phases", {})
    return Run(
        robots=robots,
        seed=seed,
        outcome=got,
        contacts=int(r.get("contacts", 0)),
        wall_s=float(r.get("wall_total", 0.0)),
        detail=detail,
        silent_wrong=bool(r.get("silent_wrong", False)),
        agreement_s=_finite(r.get("agreement_s")),
        exchange_bytes_max=exch[-1] if exch else 0,
        exchange_bytes_median=float(statistics.median(exch)) if exch else 0.0,
        world_ready_s=float(r.get("wall_world_ready", 0.0)),
        phases={p: float(phases[p]["wall_max"]) for p in PHASES if p in phases},
        max_abs_r_d=_finite(r.get("max_abs_r_d")),
        max_abs_r_phi=_finite(r.get("max_abs_r_phi")),
        min_separation=_finite(r.get("min_separation")),
        dropped=int(r.get("dropped", 0)),
        load_start=load[0] if load else 0.0,
        load_mean=statistics.fmean(load) if load else 0.0,
        load_end=load[-1] if load else 0.0,
        agree_timeout_s=agree_timeout_s,
        wave_timeout_s=wave_timeout_s,
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
    (120 s is the agents' and the demo's default, enough for 30 NAOs)."""
    given: float | None = args.agree_timeout
    return given if given is not None else max(120.0, 3.0 * robots)


def wave_timeout(args: argparse.Namespace) -> float:
    """The agents' wait limit for earlier waves and for the fleet to hold (``python -m
    agent --wave-timeout``, wall s): ``--wave-timeout``, or by default the run's
    ``--timeout``. The agents' default (600 s) is shorter than the waves of 100 NAOs on
    a loaded 2-core machine take; the run's own limit still bounds every run."""
    given: float | None = args.wave_timeout
    return given if given is not None else float(args.timeout)


def run_one(args: argparse.Namespace, robots: int, seed: int, out: Path) -> Run:
    """One run of ``robots`` NAOs at ``seed`` (module docstring)."""
    from tools.demo import parse_args
    from tools.harness.run import run_once

    argv = ["--robots", str(robots), "--seed", str(seed), "--out", str(out)]
    argv += ["--timeout", str(args.timeout), "--world-timeout", str(args.world_timeout)]
    agree_s = agree_timeout(args, robots)
    argv += ["--agree-timeout", f"{agree_s:g}"]
    wave_s = wave_timeout(args)
    argv += [f"--agent-arg={i}:--wave-timeout={wave_s:g}" for i in range(1, robots + 1)]
    argv += ["--no-publish-camera", *args.demo_arg]
    with load_samples() as load:
        try:
            r = run_once(parse_args(argv), seed, out, quiet=True)
        except RuntimeError as exc:
            r = {"no_result": f"demo: {exc}"}
    return row_of(r, robots, seed, load, agree_s, wave_s)


# ===================================================================== table


def _s(v: float | None, spec: str = ".0f") -> str:
    return "-" if v is None else format(v, spec)


def table_rows(runs: Sequence[Run]) -> list[list[str]]:
    """The table's cells, one row per run (``print_table``, ``markdown``)."""
    return [
        [
            str(r.robots),
            str(r.seed),
            r.outcome,
            str(r.contacts),
            f"{r.wall_s:.0f}",
            _s(r.agreement_s, ".1f"),
            f"{r.exchange_bytes_max / 1000:.1f} / {r.exchange_bytes_median / 1000:.1f}",
            "yes" if r.silent_wrong else "no",
            f"{r.load_start:.0f} / {r.load_mean:.0f} / {r.load_end:.0f}",
            str(r.dropped),
            r.detail,
        ]
        for r in runs
    ]


HEADER = [
    "N",
    "seed",
    "outcome",
    "contacts",
    "wall (s)",
    "agreement (s)",
    "exchange kB/agent (max / median)",
    "silent wrong",
    "load (start / mean / end)",
    "observer dropped",
    "detail",
]


def phase_rows(runs: Sequence[Run]) -> tuple[list[str], list[list[str]]]:
    """Header and rows of the slowest agent's wall time per phase (s) per run."""
    shown = [p for p in PHASES if any(p in r.phases for r in runs)]
    head = ["N", "seed", WORLD, *shown, "wall"]
    rows = [
        [str(r.robots), str(r.seed), f"{r.world_ready_s:.0f}"]
        + [_s(r.phases.get(p)) for p in shown]
        + [f"{r.wall_s:.0f}"]
        for r in runs
    ]
    return head, rows


def print_table(runs: Sequence[Run]) -> None:
    for head, rows in ((HEADER, table_rows(runs)), phase_rows(runs)):
        widths = [max(len(h), *(len(c[k]) for c in rows)) for k, h in enumerate(head)]
        widths[-1] = len(head[-1])  # the last column is not padded
        print()
        for cells in (head, *rows):
            print("  ".join(c.ljust(w) for c, w in zip(cells, widths, strict=True)).rstrip())


def markdown(runs: Sequence[Run]) -> str:
    """The two tables (runs, phases) as Markdown, for docs/results.md."""

    def md(head: Sequence[str], rows: Sequence[Sequence[str]]) -> str:
        lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
        lines += ["| " + " | ".join(c.replace("|", "/") for c in row) + " |" for row in rows]
        return "\n".join(lines)

    return md(HEADER, table_rows(runs)) + "\n\n" + md(*phase_rows(runs)) + "\n"


# ===================================================================== phase chart


def plot_phases(runs: Sequence[Run], path: Path) -> None:
    """The phase chart: one horizontal bar per run (top to bottom in the given order),
    stacked from the world's start-up and the slowest agent's wall time in each phase,
    with the run's wall time marked (the slowest agents of two phases may differ, so
    the stack need not add up to the wall time); its outcome and load beside it."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.artist import Artist

    segments = [WORLD, *PHASES]
    shown = [s for s in segments if any(_duration(r, s) > 0 for r in runs)]
    cmap = plt.get_cmap("tab20")
    colour = {s: cmap(k % 20) for k, s in enumerate(segments)}
    fig, ax = plt.subplots(figsize=(10, 2.6 + 0.55 * len(runs)))
    right = max([r.wall_s for r in runs] + [sum(_duration(r, s) for s in shown) for r in runs])
    for y, r in enumerate(runs):
        left = 0.0
        for s in shown:
            w = _duration(r, s)
            if w <= 0:
                continue
            ax.barh(y, w, left=left, color=colour[s], edgecolor="white", linewidth=0.5)
            if w >= 0.04 * right:
                ax.text(left + w / 2, y, f"{w:.0f}", ha="center", va="center", fontsize=7)
            left += w
        ax.plot([r.wall_s], [y], marker="D", color="black", markersize=5)
        ax.text(
            max(left, r.wall_s) + 0.01 * right,
            y,
            f"{r.outcome}, {r.contacts} contacts, load {r.load_mean:.0f}",
            va="center",
            fontsize=7,
            color=report.COLOURS.get(r.outcome, "black"),
        )
    handles: list[Artist] = [plt.Rectangle((0, 0), 1, 1, color=colour[s]) for s in shown]
    handles.append(plt.Line2D([], [], marker="D", color="black", linestyle=""))
    ax.legend(
        handles, [*shown, "run's wall time"], fontsize=7, ncol=6, loc="upper center",
        bbox_to_anchor=(0.5, -0.25 if len(runs) > 2 else -0.45),
    )  # fmt: skip
    ax.set_yticks(range(len(runs)), [r.name for r in runs])
    ax.invert_yaxis()
    ax.set_xlim(0, right * 1.35)
    ax.set_xlabel("wall time (s): the slowest agent in each phase")
    ax.set_title(
        "Where the wall time goes per fleet size (one process per NAO, 2-core machine)",
        fontsize=10,
    )
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _duration(r: Run, segment: str) -> float:
    return r.world_ready_s if segment == WORLD else r.phases.get(segment, 0.0)


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
    return a


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    runs: list[Run] = []
    if args.report:
        runs = [Run(**r) for r in report.read_runs(args.report)]
        write(args, runs)
        print_table(runs)
        return 0
    seeds = range(args.seed_start, args.seed_start + args.seeds)
    bar = Progress(len(args.robots) * len(seeds), "eval_scale")
    for n in args.robots:
        for seed in seeds:
            r = run_one(args, n, seed, args.out / f"n{n:03d}" / f"seed-{seed:03d}")
            runs.append(r)
            write(args, runs)
            bar.step(
                f"N={n} seed {seed}: {r.outcome}, wall {r.wall_s:.0f} s, "
                f"load {r.load_mean:.0f} ({r.detail[:60]})"
            )
    print_table(runs)
    print(f"figure: {args.figure or args.out / FIGURE}", file=sys.stderr)
    return 0 if all(r.outcome not in FAILURES for r in runs) else 1


if __name__ == "__main__":
    raise SystemExit(main())
