"""``python -m tools.eval_frames DIR... [--png FILE] [--json FILE]``: the fleet's frame,
re-estimated offline from recorded runs and judged against their ground truth.

A run of ``tools.demo`` (and of every eval tool built on it) leaves ``run.mcap`` with the
neighbour records the robots published, and ``result.json`` with the true start poses and
the agent arguments (``--sensor-fault`` says which robot's record is corrupted). This tool
runs today's :func:`agent.core.formation.frame.fleet_frame.fleet_frame` on the last record of
every robot of every run found under the folders given, with no simulator and no robot,
and compares it with the truth (docs/design.md §9):

* the frame's error: the estimated start positions, fitted to the true ones by a rigid
  motion (the common frame is any robot's fixed frame), worst position error (m) and
  worst start-heading error (°) of the robots planned;
* the naming: which robot the fleet leaves out, against the robot carrying a fault.

So a change of the pairing, the fit or the check is measured on real rendered records in
seconds, before a single robot walks. A row is *bad* when a planned robot's start heading
is off by more than ``--psi-tol`` (default 10°), its position by more than ``--pos-tol``
(0.15 m), a sound robot is left out, or planning stops where nobody carries a fault.
Prints one line per run and a summary, writes the rows as JSON and draws the errors
(PNG). Exit status 0 when no row is bad, 1 otherwise.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from agent.adapters import FormationAdapter
from agent.core.formation.frame.fleet_frame import fleet_frame
from agent.core.formation.frame.neighbour_check import DEFAULT_EPSILON
from agent.wire import NeighborRecordMsg, decode
from tools.harness.frame_fit import common_frame_pose
from tools.harness.judge import injected_faults


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

    def bad(self, pos_tol: float, psi_tol: float) -> bool:
        if self.stopped:
            return self.faulty < 0
        wrongly_left_out = any(r != self.faulty for r in self.excluded)
        return wrongly_left_out or self.pos_err > pos_tol or self.psi_err > psi_tol


def records_of(mcap: Path) -> tuple[NeighborRecordMsg, ...]:
    """The last neighbour record each robot published in a recording (ascending id)."""
    from mcap.reader import make_reader

    last: dict[int, NeighborRecordMsg] = {}
    with mcap.open("rb") as f:
        for _, channel, message in make_reader(f).iter_messages(log_time_order=True):
            if channel.message_encoding != "msgpack" or not channel.topic.endswith("/record"):
                continue
            msg = decode(message.data)
            if isinstance(msg, NeighborRecordMsg):
                last[msg.sender] = msg
    return tuple(last[k] for k in sorted(last))


def faulty_robot(result: dict[str, object]) -> int:
    """The robot whose agent ran with ``--sensor-fault`` (-1: none; the lowest of several)."""
    return min(injected_faults(dict(result)), default=-1)


def _wrap_deg(a: float) -> float:
    return abs(math.degrees(math.remainder(a, 2 * math.pi)))


def judge_run(run: Path) -> FrameRow:
    """Re-estimate the frame of one run folder (``run.mcap`` + ``result.json``)."""
    result = json.loads((run / "result.json").read_text())
    truth = {int(k): (float(v[0]), float(v[1]), float(v[2])) for k, v in result["starts"].items()}
    msgs = records_of(run / "run.mcap")
    faulty = faulty_robot(result)
    try:
        ff = fleet_frame(FormationAdapter.records(msgs), DEFAULT_EPSILON)
    except ValueError as exc:
        nan = math.nan
        return FrameRow(str(run), len(msgs), faulty, excluded=(), aligned=False, stopped=str(exc), pos_err=nan,
                        psi_err=nan, reason="")  # fmt: skip
    ids = [i for i in ff.ids if i != faulty and i in truth]
    est = {i: ff.positions[ff.ids.index(i)] for i in ids}
    x, y, h = common_frame_pose(est, truth)
    c, s = math.cos(h - math.pi / 2), math.sin(h - math.pi / 2)
    world = {i: np.array([x, y]) + np.array([[c, -s], [s, c]]) @ est[i] for i in ids}
    pos_err = max(float(np.hypot(*(world[i] - np.array(truth[i][:2])))) for i in ids)
    # a robot faces +y (π/2) in its own fixed frame: its true heading is h + ψ
    psi_err = max(_wrap_deg(truth[i][2] - (h + ff.heading_of(i))) for i in ids)
    return FrameRow(str(run), len(msgs), faulty, excluded=ff.excluded, aligned=ff.aligned, stopped="",
                    pos_err=pos_err, psi_err=psi_err, reason=ff.reason)  # fmt: skip


def find_runs(roots: list[Path]) -> list[Path]:
    """Every folder under ``roots`` holding both a recording and a result (sorted)."""
    found = {p.parent for root in roots for p in root.rglob("run.mcap")}
    return sorted(p for p in found if (p / "result.json").exists())


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


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(
        prog="python -m tools.eval_frames", description=(__doc__ or "").split("\n\n")[0]
    )
    ap.add_argument("roots", nargs="+", type=Path, help="folders searched for run folders")
    ap.add_argument("--psi-tol", type=float, default=10.0, help="start-heading error (°)")
    ap.add_argument("--pos-tol", type=float, default=0.15, help="start-position error (m)")
    ap.add_argument("--png", type=Path, default=Path("out/eval_frames.png"))
    ap.add_argument("--json", type=Path, default=None)
    args = ap.parse_args(argv)
    runs = find_runs(args.roots)
    if not runs:
        print(f"no run folders (run.mcap + result.json) under {args.roots}", file=sys.stderr)
        return 2
    rows: list[FrameRow] = []
    for k, run in enumerate(runs, 1):
        row = judge_run(run)
        rows.append(row)
        mark = "BAD" if row.bad(args.pos_tol, args.psi_tol) else "ok "
        what = (f"stop: {row.stopped[:70]}" if row.stopped else
                f"left out {list(row.excluded)} pos {row.pos_err:.2f} m psi {row.psi_err:4.1f}°")  # fmt: skip
        print(f"[{k}/{len(runs)}] {mark} {run}: N={row.robots} faulty {row.faulty:2d} {what}")
    bad = [r for r in rows if r.bad(args.pos_tol, args.psi_tol)]
    faulty = [r for r in rows if r.faulty >= 0]
    named = sum(r.excluded == (r.faulty,) for r in faulty)
    print(f"{len(rows)} runs: {len(bad)} bad; faulty robot named in {named}/{len(faulty)}; "
          f"sound robots left out in {sum(bool(r.excluded) for r in rows if r.faulty < 0)}/"
          f"{len(rows) - len(faulty)}")  # fmt: skip
    draw(rows, args.png, args.psi_tol)
    print(f"figure: {args.png}")
    if args.json is not None:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps({"rows": [asdict(r) for r in rows]}, indent=2))
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
