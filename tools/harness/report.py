"""The report of an evaluation matrix (docs/design.md §9 "Honest results"; docs/faults.md).

Runs judged by the one rule of :func:`tools.harness.judge.outcome` (``complete``,
``degraded``, ``safe_abort``, ``unsafe``, ``unjudged``, ``no_result``) are written as the shared ``{"runs": [...]}`` JSON, printed
as a table with one line per run and drawn as one figure of the outcomes per group (a
loss rate, a fault, a case): the one copy that ``tools.eval_loss``, ``tools.eval_faults``
and ``tools.eval_headings`` use.

A run row holds at least ``seed``, ``outcome``, ``contacts``, ``wall_s`` and ``detail``,
the key of its group (``loss``, ``fault``, ``case``) and whatever its tool adds.

:func:`run_matrix` is every tool's loop over its matrix: the cases (a group and a seed)
run one after the other, the tool's report written after each (so that a long matrix can
be read while it goes on, or cut) and a progress line with an estimate; with ``--report``
files it runs nothing and reports their rows together.
"""

from __future__ import annotations

import json
from collections import Counter
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import asdict
from pathlib import Path
from typing import Any, TypeVar

from tools.harness.judge import FAILURES, OUTCOMES
from tools.harness.progress import Progress

Case = TypeVar("Case")
R = TypeVar("R")

Row = Mapping[str, Any]

COLOURS = {
    "complete": "tab:green",
    "degraded": "tab:olive",
    "safe_abort": "tab:orange",
    "unsafe": "tab:red",
    "unjudged": "tab:grey",
    "no_result": "black",
}


def failures(rows: Iterable[Row]) -> int:
    """How many runs ended in a failure (:data:`tools.harness.judge.FAILURES`: degraded,
    unsafe, no result): an evaluation tool exits non-zero when there is any."""
    return sum(1 for r in rows if r["outcome"] in FAILURES)


def outcome_counts(rows: Iterable[Row]) -> str:
    """``complete 3, degraded 1, ...``: every outcome that occurred, in :data:`OUTCOMES`' order."""
    c = Counter(str(r["outcome"]) for r in rows)
    return ", ".join(f"{o} {c[o]}" for o in OUTCOMES if c[o])


def write_runs(rows: Sequence[Row], *paths: Path | None) -> None:
    """``{"runs": rows}`` as indented JSON to every path given (folders made; None: left
    out). Written after every run, so that a long matrix can be read while it goes on,
    or cut."""
    doc = json.dumps({"runs": [dict(r) for r in rows]}, indent=2)
    for path in paths:
        if path is not None:
            path.parent.mkdir(parents=True, exist_ok=True)
            path.write_text(doc)


def read_runs(paths: Iterable[Path]) -> list[dict[str, Any]]:
    """The rows of earlier run files, file after file (``--report``)."""
    rows: list[dict[str, Any]] = []
    for path in paths:
        rows += json.loads(path.read_text())["runs"]
    return rows


def run_matrix(
    cases: Sequence[Case],
    run_one: Callable[[Case], R],
    *,
    report: Callable[[list[R]], None],
    progress: str,
    label: Callable[[Case, R], str],
    earlier: Sequence[Path] | None = None,
    row: Callable[..., R] | None = None,
) -> list[R]:
    """The runs of ``cases``, one after the other: after each, ``report(runs so far)`` (the
    tool's JSON and figure) and the progress line named ``progress``, ending with
    ``label(case, run)``. With ``earlier`` (``--report`` files) nothing runs: their rows,
    each made a run by ``row(**fields)``, are reported together and returned."""
    if earlier:
        assert row is not None, "earlier runs need the row type"
        runs = [row(**r) for r in read_runs(earlier)]
        report(runs)
        return runs
    bar = Progress(len(cases), progress)
    runs = []
    for case in cases:
        r = run_one(case)
        runs.append(r)
        report(runs)
        bar.step(label(case, r))
    return runs


def exit_status(runs: Iterable[Any]) -> int:
    """An evaluation tool's exit status: 1 when a run (a dataclass row) failed, else 0."""
    return 1 if failures(asdict(r) for r in runs) else 0


def label(value: object) -> str:
    """A group's name in tables and figures: a number as ``%g``, anything else as text."""
    return format(value, "g") if isinstance(value, float) else str(value)


def count_outcomes(
    rows: Sequence[Row],
    group: str,
    counted: Callable[[Row], bool] | None = None,
    name: Callable[[Any], str] = label,
) -> dict[str, Counter[str]]:
    """Outcomes per group, named by ``name`` (groups in the order they first appear), of
    the rows that ``counted`` accepts (default: all)."""
    counts: dict[str, Counter[str]] = {name(r[group]): Counter() for r in rows}
    for r in rows:
        if counted is None or counted(r):
            counts[name(r[group])][str(r["outcome"])] += 1
    return counts


def print_runs(rows: Sequence[Row], group: str, detail_width: int = 90) -> None:
    """One line per run: its group, seed, outcome, contacts, wall time and detail."""
    names = [label(r[group]) for r in rows]
    w = max([len(group), *map(len, names)])
    print(f"\n{group:{w}s} {'seed':>4} {'outcome':10s} {'contacts':>8} {'wall (s)':>8}  detail")
    for name, r in zip(names, rows, strict=True):
        print(f"{name:{w}s} {r['seed']:4d} {r['outcome']:10s} {r['contacts']:8d} "
              f"{r['wall_s']:8.0f}  {str(r['detail'])[:detail_width]}")  # fmt: skip


def plot_outcomes(
    counts: Mapping[str, Counter[str]],
    path: Path,
    title: str,
    xlabel: str = "runs (seeds)",
    ylabel: str = "",
) -> None:
    """Stacked horizontal bars: per group (top to bottom in ``counts``' order) its runs by
    outcome, each bar labelled with its count."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.ticker import MaxNLocator

    groups = list(counts)
    fig, ax = plt.subplots(figsize=(8, 1.5 + 0.45 * len(groups)))
    for y, name in enumerate(groups):
        left = 0
        c = counts[name]
        for o in OUTCOMES:
            if c[o]:
                ax.barh(y, c[o], left=left, color=COLOURS[o])
                ax.text(left + c[o] / 2, y, str(c[o]), ha="center", va="center", color="white")
                left += c[o]
    handles = [plt.Rectangle((0, 0), 1, 1, color=COLOURS[o]) for o in OUTCOMES]
    ax.legend(handles, OUTCOMES, loc="lower right", fontsize=8)
    ax.set_yticks(range(len(groups)), groups)
    ax.xaxis.set_major_locator(MaxNLocator(integer=True))  # whole runs
    ax.invert_yaxis()
    ax.set_xlabel(xlabel)
    if ylabel:
        ax.set_ylabel(ylabel)
    ax.set_title(title, fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
