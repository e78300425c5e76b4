"""The rows and report of ``tools.eval_faults`` (docs/faults.md "Crashed agents and restarted routers"): one
:class:`Run` per fault and seed, the table of outcomes per fault among the runs in which it
was injected, and their figure; the shared JSON and outcome rule are
:mod:`tools.harness.report`'s.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import asdict, dataclass
from pathlib import Path

from tools.harness import report


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
