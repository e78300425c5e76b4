"""The rows and report of ``tools.eval_frames`` (docs/design.md §9): one run's frame against
its truth (:class:`FrameRow`), the counts the targets are stated in (:func:`scores`), their
one-line summary and the figure of the errors and the naming.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np


@dataclass(frozen=True)
class FrameRow:
    """One run's frame against its truth."""

    run: str
    robots: int
    faulty: int  # the robot with --sensor-fault (-1: none)
    excluded: tuple[int, ...]
    aligned: bool
    stopped: str  # planning's ValueError ("" when it planned)
    pos_err: float  # m, worst planned robot (nan when stopped)
    psi_err: float  # deg, worst planned robot (nan when stopped)
    reason: str
    fault: str = ""  # the injected fault, e.g. "scale:1.4" ("": none, or unknown)
    held_out: bool = False  # a corpus fleet the estimator is never tuned on
    #: robots left out, other than the injected one, whose own record the test alone
    #: rejects at α even against the others' *true* poses: a record perception got wrong
    #: (a fault nobody injected), not a false alarm of the fleet's test
    record_wrong: tuple[int, ...] = ()

    @property
    def sound_left_out(self) -> bool:
        """A robot without a fault, its record consistent with the truth, was left out."""
        return any(r != self.faulty and r not in self.record_wrong for r in self.excluded)

    @property
    def named(self) -> bool:
        """The robot with the fault was left out, and only it."""
        return self.faulty >= 0 and self.excluded == (self.faulty,)

    def bad(self, pos_tol: float, psi_tol: float) -> bool:
        if self.stopped:
            return self.faulty < 0
        return self.sound_left_out or self.pos_err > pos_tol or self.psi_err > psi_tol


def draw(rows: list[FrameRow], path: Path, psi_tol: float) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (a, b) = plt.subplots(1, 2, figsize=(11, 4))
    planned = [r for r in rows if not r.stopped]
    x = np.arange(len(planned))
    colours = ["tab:red" if r.faulty >= 0 else "tab:blue" for r in planned]
    a.bar(x, [r.psi_err for r in planned], color=colours)
    a.axhline(psi_tol, color="k", lw=0.8, ls="--")
    a.set(xlabel="run", ylabel="worst start-heading error (°)",
          title="frame error per run (red: a robot with a sensor fault)")  # fmt: skip
    faulty = [r for r in rows if r.faulty >= 0]
    named = sum(r.excluded == (r.faulty,) for r in faulty)
    stopped = sum(bool(r.stopped) for r in faulty)
    sound = [r for r in rows if r.faulty < 0]
    wrong = sum(bool(r.excluded) or bool(r.stopped) for r in sound)
    b.bar(["faulty:\nnamed", "faulty:\nstop", "faulty:\nmissed", "sound:\nleft out/stop"],
          [named, stopped, len(faulty) - named - stopped, wrong],
          color=["tab:green", "tab:orange", "tab:red", "tab:red"])  # fmt: skip
    b.set(ylabel="runs", title=f"naming ({len(faulty)} runs with a fault, {len(sound)} without)")
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)


#: The share of fault runs of the corpus in which today's estimator names the faulty
#: robot (docs/results.md, "Frame and fault naming on the corpus"): the CI gate against a
#: regression (today 0.969, 872 of 900 runs).
NAMED_FLOOR = 0.96
#: The share of the fault runs whose records reveal the faulty robot at α
#: (``tools.eval_frames --ceiling``) in which the fleet must name it: the naming target
#: (today 0.990, 858 of 867). Of all fault runs, 98 % is beyond the records at α on the
#: shipped corpus (19 of its 900 runs reveal nothing the false-alarm rate allows naming).
REVEALED_TARGET = 0.98


def scores(rows: list[FrameRow], pos_tol: float, psi_tol: float) -> dict[str, int]:
    """The counts the targets are stated in (docs/results.md, "Frame and fault naming")."""
    clean = [r for r in rows if r.faulty < 0]
    faulty = [r for r in rows if r.faulty >= 0]
    planned = [r for r in rows if not r.stopped]
    return {
        "runs": len(rows),
        "clean_runs": len(clean),
        "fault_runs": len(faulty),
        "sound_left_out": sum(r.sound_left_out for r in rows),
        "record_wrong": sum(bool(r.record_wrong) for r in rows),
        "refused": sum(bool(r.stopped) for r in clean),
        "named": sum(r.named for r in faulty),
        "fault_stopped": sum(bool(r.stopped) for r in faulty),
        "planned": len(planned),
        "accurate": sum(r.pos_err <= pos_tol and r.psi_err <= psi_tol for r in planned),
    }


def summary(rows: list[FrameRow], pos_tol: float, psi_tol: float) -> str:
    """One line of :func:`scores`, with the named rate per fault kind."""
    s = scores(rows, pos_tol, psi_tol)
    kinds = sorted({r.fault.partition(":")[0] for r in rows if r.faulty >= 0 and r.fault})
    per = ", ".join(
        f"{k} {sum(r.named for r in rows if r.fault.startswith(k))}/"
        f"{sum(r.fault.startswith(k) for r in rows)}"
        for k in kinds
    )
    return (
        f"{s['runs']} runs; {s['sound_left_out']} with a sound robot left out"
        + (
            f" ({s['record_wrong']} more whose own record the truth rejects)"
            if s["record_wrong"]
            else ""
        )
        + "; without a fault: "
        f"{s['refused']}/{s['clean_runs']} refused; with one: named {s['named']}/{s['fault_runs']}"
        f"{f' ({per})' if per else ''}, {s['fault_stopped']} stopped; every planned start within "
        f"{pos_tol} m and {psi_tol:g}° in {s['accurate']}/{s['planned']}"
    )
