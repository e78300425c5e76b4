"""The chaos soak's rows and report (``tools.eval_chaos``; docs/faults.md "Chaos soak"): one
:class:`Run` per schedule, the table of outcomes per fault kind injected, and the figure of
every run's time line; the shared JSON and outcome rule are :mod:`tools.harness.report`'s.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from tools.harness import report
from tools.lib.chaos_schedule import TAGS, Schedule, with_injected


@dataclass
class Run:
    seed: int
    mix: str  # the schedule's tags (tools.lib.chaos_schedule), the table's group
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
