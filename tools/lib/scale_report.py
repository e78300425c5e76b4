"""The rows and report of ``tools.eval_scale`` (docs/design.md §9 "Honest results"): a judged
``result.json`` as one :class:`Run` (:func:`row_of`), the table of runs and the slowest
agent's time per phase (printed, and as Markdown for docs/results.md), and the phase chart
(:func:`plot_phases`: where the wall time goes per fleet size).
"""

from __future__ import annotations

import statistics
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from agent.config import AgentConfig
from tools.harness import report
from tools.harness.judge import PHASE_ORDER, outcome

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
    agree_timeout_s: float = AgentConfig.timeout
    wave_timeout_s: float = AgentConfig.wave_timeout
    #: the 1-minute load average at the run's start, its mean over the run, at its end
    load_start: float = 0.0
    load_mean: float = 0.0
    load_end: float = 0.0
    #: the NAOs' own time at the run's end (s; the world's clock, which charges every
    #: motion and every picture's head turn, settling and capture)
    sim_s: float | None = None

    @property
    def realtime(self) -> float | None:
        """The real-time factor: the NAOs' own time over the wall time (None unknown)."""
        return None if self.sim_s is None or self.wall_s <= 0 else self.sim_s / self.wall_s

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
    agree_timeout_s: float = AgentConfig.timeout,
    wave_timeout_s: float = AgentConfig.wave_timeout,
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
        sim_s=_finite(r.get("t_sim_end")),
    )


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
            _s(r.realtime, ".2f"),
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
    "sim / wall",
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
