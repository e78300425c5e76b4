"""``python -m tools.eval_frames DIR... [--png FILE] [--json FILE]``: the fleet's frame,
re-estimated offline from recorded runs and judged against their ground truth.

``--corpus DIR`` judges the runs of a corpus of rendered records instead
(``python -m tools.corpus``; ``tests/data/frames`` ships one): every fleet as published
and with each injected fault, the tuned-on and the held-out fleets reported apart, and
the exit status says whether the gates hold: no sound robot left out, the faulty robot
named in at least ``--min-named`` of the fault runs, planning refused on at most
``--max-refused`` of the fault-free runs.

A run of ``tools.demo`` (and of every eval tool built on it) leaves ``run.mcap`` with the
neighbour records the robots published, and ``result.json`` with the true start poses and
the agent arguments (``--sensor-fault`` says which robot's record is corrupted). This tool
runs today's :func:`agent.core.formation.frame.fleet_frame.fleet_frame` on the last record of
every robot of every run found under the folders given, with no simulator and no robot,
and compares it with the truth (docs/design.md §9):

* the frame's error: the estimated start positions, fitted to the true ones by a rigid
  motion (the common frame is any robot's fixed frame), worst position error (m) and
  worst start-heading error (°) of the robots planned;
* the naming: which robot the fleet leaves out, against the robot carrying a fault. A
  robot left out that nobody injected a fault into is *sound* only if its own record
  fits the truth: tested alone against the others held at their true poses (as
  ``--ceiling``), it passes at α. One whose record the truth itself rejects carries a
  fault perception made (a bystander merged into its detections, distances read 10-16 %
  long), and leaving it out is the test doing its work; the rows count it apart.

So a change of the pairing, the fit or the check is measured on real rendered records in
seconds, before a single robot walks. A row is *bad* when a planned robot's start heading
is off by more than ``--psi-tol`` (default 10°), its position by more than ``--pos-tol``
(0.15 m), a sound robot is left out, or planning stops where nobody carries a fault.
Prints one line per run and a summary, writes the rows as JSON and draws the errors
(PNG). Exit status 0 when no row is bad, 1 otherwise.

``--corpus DIR --alone-null N`` measures instead the false alarms of the test of a robot
alone against the rest (:mod:`agent.core.formation.frame.faults.alone`, docs/design.md §9): in
every fault-free fleet of at most N robots, each robot's record is set aside, the others
framed without it, and the robot tested alone against them; it prints how many of those
sound robots the test rejects below 10⁻², 10⁻³ and α, and the worst.

``--corpus DIR --ceiling [--min-revealed SHARE]`` adds what the records hold: each fault
run's faulty robot tested alone against the others held at their *true* start poses (a
perfect frame of the rest, which no fleet has), standing where the others' sightings put
it, at the heading its own sightings choose. A miss the fleet shares with that test is beyond the
records at α: its faulty robot's sightings, and the others' of it, are as likely from a
sound robot as the false-alarm rate allows (a compass turned 40° that one mask sees, a
robot seen by two others in a fleet of four). The runs the records reveal (the faulty
robot rejected so) are the ones a fleet must name: ``--min-revealed`` fails below that
share of them named.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
from collections.abc import Callable
from concurrent.futures import ProcessPoolExecutor
from dataclasses import asdict, replace
from functools import partial
from pathlib import Path
from typing import TypeVar

from agent.adapters import FormationAdapter
from agent.core.formation.frame.faults.alone import alone_test
from agent.core.formation.frame.faults.fault_test import ALPHA
from agent.core.formation.frame.fleet_frame import fleet_frame, frame_rest
from agent.core.formation.frame.neighbour_check import DEFAULT_EPSILON
from agent.core.formation.frame.poses import evaluate_poses
from agent.core.perception.sighting_noise import shipped_noise
from agent.wire import NeighborRecordMsg, decode
from tools.harness.judge import injected_faults
from tools.lib.frame_fit import frame_error, truth_in_frame
from tools.lib.frames_report import FrameRow, draw, scores, summary

T = TypeVar("T")


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


def judge_run(run: Path) -> FrameRow:
    """Re-estimate the frame of one run folder (``run.mcap`` + ``result.json``)."""
    result = json.loads((run / "result.json").read_text())
    truth = {int(k): (float(v[0]), float(v[1]), float(v[2])) for k, v in result["starts"].items()}
    return judge_records(str(run), records_of(run / "run.mcap"), truth, faulty_robot(result))


def judge_records(
    name: str,
    msgs: tuple[NeighborRecordMsg, ...],
    truth: dict[int, tuple[float, float, float]],
    faulty: int,
    fault: str = "",
    held_out: bool = False,
) -> FrameRow:
    """Today's frame of one record set against its truth (``faulty``: -1 for none)."""
    row = _judge(name, msgs, truth, faulty)
    return replace(row, fault=fault, held_out=held_out)


def _judge(
    run: str,
    msgs: tuple[NeighborRecordMsg, ...],
    truth: dict[int, tuple[float, float, float]],
    faulty: int,
) -> FrameRow:
    try:
        ff = fleet_frame(FormationAdapter.records(msgs), DEFAULT_EPSILON)
    except ValueError as exc:
        nan = math.nan
        return FrameRow(run, len(msgs), faulty, excluded=(), aligned=False, stopped=str(exc), pos_err=nan,
                        psi_err=nan, reason="")  # fmt: skip
    est = {i: (ff.positions[ff.ids.index(i)], ff.heading_of(i)) for i in ff.ids if i != faulty}
    pos_err, psi = frame_error(est, truth)
    psi_err = math.degrees(psi)
    # a robot left out that nobody injected a fault into: is its record wrong by the truth?
    wrong = tuple(r for r in ff.excluded
                  if r != faulty and r in truth and ceiling_p(msgs, truth, r) < ALPHA)  # fmt: skip
    return FrameRow(run, len(msgs), faulty, excluded=ff.excluded, aligned=ff.aligned, stopped="",
                    pos_err=pos_err, psi_err=psi_err, reason=ff.reason, record_wrong=wrong)  # fmt: skip


def find_runs(roots: list[Path]) -> list[Path]:
    """Every folder under ``roots`` holding both a recording and a result (sorted)."""
    found = {p.parent for root in roots for p in root.rglob("run.mcap")}
    return sorted(p for p in found if (p / "result.json").exists())


def _call(job: Callable[[], T]) -> T:
    return job()


def _jobs(args: argparse.Namespace) -> list[Callable[[], FrameRow]]:
    """One judge per run: every run of ``--corpus``, or every run folder under the roots."""
    if args.corpus is not None:
        from tools.corpus import held_out, load_corpus

        return [partial(judge_records, r.name, r.records, r.truth, r.victim, r.fault, held_out(r.seed))
                for r in load_corpus(args.corpus)]  # fmt: skip
    return [partial(judge_run, run) for run in find_runs(args.roots)]


def alone_null(name: str, msgs: tuple[NeighborRecordMsg, ...]) -> list[tuple[str, int, float, str]]:
    """Every robot of one fault-free fleet tested alone against the others framed without
    its record (``--alone-null``): (fleet, robot, p, the test's words); p nan where the
    rest does not pass."""
    records = FormationAdapter.records(msgs)
    model = shipped_noise()
    out = []
    for robot in sorted(r.robot_id for r in records):
        rest = [r for r in records if r.robot_id != robot]
        inner = frame_rest(rest, DEFAULT_EPSILON, model)
        if inner is None:
            out.append((name, robot, math.nan, "the rest does not pass"))
            continue
        poses = evaluate_poses(inner.ids, (), inner.positions, inner.headings, inner.frame_robot)
        alone = alone_test(poses, records, robot, model)
        out.append((name, robot, alone.test.p, alone.describe()))
    return out


def ceiling_p(
    msgs: tuple[NeighborRecordMsg, ...], truth: dict[int, tuple[float, float, float]], faulty: int
) -> float:
    """p of the faulty robot's record tested alone (:func:`alone.alone_test`) against the
    others held at their *true* start poses (``--ceiling``): what the test alone could
    say of it with a perfect frame of the rest, which no fleet has. The faulty robot
    still stands where the others' sightings put it, at the heading its own sightings
    choose, as in the fleet."""
    records = FormationAdapter.records(msgs)
    ids = sorted(r.robot_id for r in records if r.robot_id != faulty)
    positions, headings = truth_in_frame(truth, ids, ids[0])
    rest = evaluate_poses(tuple(ids), (), positions, headings, ids[0])
    return alone_test(rest, records, faulty, shipped_noise()).test.p


def _ceiling(rows: list[FrameRow], jobs: int, corpus: Path) -> float:
    """``--ceiling``: the fault runs whose faulty robot the test alone rejects at α against
    the others' true poses (the records *reveal* it), beside the fleet's own naming; the
    share of the revealed runs the fleet names (1 with none)."""
    from tools.corpus import load_corpus

    runs = {r.name: r for r in load_corpus(corpus) if r.victim >= 0}
    names = sorted(runs)
    calls = [partial(ceiling_p, runs[n].records, runs[n].truth, runs[n].victim) for n in names]
    pool = ProcessPoolExecutor(jobs) if jobs > 1 else None
    ps = dict(zip(names, pool.map(_call, calls) if pool else map(_call, calls), strict=True))
    if pool is not None:
        pool.shutdown()
    missed = [r.run for r in rows if r.faulty >= 0 and not r.named]
    beyond = [n for n in missed if ps.get(n, 1.0) >= ALPHA]
    revealed = {n for n, p in ps.items() if p < ALPHA}
    named = sum(r.named for r in rows if r.run in revealed)
    share = named / len(revealed) if revealed else 1.0
    print(f"ceiling: the test alone against the others' true poses rejects the faulty robot "
          f"in {len(revealed)}/{len(ps)} fault runs (α {ALPHA:g}); the fleet names it in "
          f"{named} of them ({share:.1%}); of the {len(missed)} runs the fleet does not "
          f"name, {len(beyond)} are beyond the records")  # fmt: skip
    for n in beyond:
        print(f"  beyond the records at α: {n} (p {ps[n]:.1e})")
    return share


def _alone_null_main(args: argparse.Namespace) -> int:
    from tools.corpus import load_corpus

    runs = [
        r for r in load_corpus(args.corpus) if r.victim < 0 and len(r.records) <= args.alone_null
    ]
    jobs = [partial(alone_null, r.name, r.records) for r in runs]
    pool = ProcessPoolExecutor(args.jobs) if args.jobs > 1 else None
    rows: list[tuple[str, int, float, str]] = []
    for k, out in enumerate(pool.map(_call, jobs) if pool else map(_call, jobs), 1):
        rows += out
        print(
            f"[{k}/{len(jobs)}] {out[0][0]}: smallest p {min((r[2] for r in out), default=1.0):.1e}"
        )
    if pool is not None:
        pool.shutdown()
    ps = [r[2] for r in rows if not math.isnan(r[2])]
    print(f"{len(rows)} sound robots of {len(runs)} fault-free fleets; {len(ps)} rests pass; "
          + ", ".join(f"{sum(p < a for p in ps)} below {a:g}" for a in (1e-2, 1e-3, ALPHA)))  # fmt: skip
    for row in sorted((r for r in rows if not math.isnan(r[2])), key=lambda r: r[2])[:3]:
        print(f"  {row[0]} robot {row[1]}: p {row[2]:.1e} ({row[3]})")
    if args.json is not None:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps({"alone_null": rows}, indent=2))
    return 0


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(
        prog="python -m tools.eval_frames", description=(__doc__ or "").split("\n\n")[0]
    )
    ap.add_argument("roots", nargs="*", type=Path, help="folders searched for run folders")
    ap.add_argument(
        "--corpus",
        type=Path,
        default=None,
        help="a corpus of rendered records (python -m tools.corpus) instead",
    )
    ap.add_argument("--psi-tol", type=float, default=10.0, help="start-heading error (°)")
    ap.add_argument("--pos-tol", type=float, default=0.15, help="start-position error (m)")
    ap.add_argument("--png", type=Path, default=Path("out/eval_frames.png"))
    ap.add_argument("--json", type=Path, default=None)
    ap.add_argument("--jobs", type=int, default=os.cpu_count() or 1,
                    help="runs judged in parallel processes (rows print in order)")  # fmt: skip
    ap.add_argument(
        "--min-named",
        type=float,
        default=0.0,
        help="fail below this share of fault runs with the faulty robot named",
    )
    ap.add_argument("--max-left-out", type=int, default=0, metavar="N",
                    help="fail above N runs with a sound robot left out (default 0)")  # fmt: skip
    ap.add_argument(
        "--max-refused",
        type=float,
        default=1.0,
        help="fail above this share of fault-free runs where planning stops",
    )
    ap.add_argument("--alone-null", type=int, default=0, metavar="N",
                    help="with --corpus: the test alone's false alarms on fault-free fleets "
                    "of at most N robots, instead")  # fmt: skip
    ap.add_argument("--ceiling", action="store_true",
                    help="with --corpus: also each faulty robot tested alone against the "
                    "others' true poses (what the records hold at α)")  # fmt: skip
    ap.add_argument("--min-revealed", type=float, default=0.0, metavar="SHARE",
                    help="with --ceiling: fail below this share of the fault runs whose "
                    "records reveal the faulty robot at α with it named")  # fmt: skip
    args = ap.parse_args(argv)
    if (args.ceiling or args.min_revealed) and args.corpus is None:
        ap.error("--ceiling needs --corpus")
    if args.min_revealed and not args.ceiling:
        ap.error("--min-revealed needs --ceiling")
    if args.alone_null:
        if args.corpus is None:
            ap.error("--alone-null needs --corpus")
        return _alone_null_main(args)
    jobs = _jobs(args)
    if not jobs:
        print(f"no run folders (run.mcap + result.json) under {args.roots}", file=sys.stderr)
        return 2
    rows: list[FrameRow] = []
    pool = ProcessPoolExecutor(args.jobs) if args.jobs > 1 else None
    done = pool.map(_call, jobs) if pool is not None else map(_call, jobs)
    for k, row in enumerate(done, 1):
        rows.append(row)
        mark = "BAD" if row.bad(args.pos_tol, args.psi_tol) else "ok "
        what = (f"stop: {row.stopped[:70]}" if row.stopped else
                f"left out {list(row.excluded)} pos {row.pos_err:.2f} m psi {row.psi_err:4.1f}°")  # fmt: skip
        print(f"[{k}/{len(jobs)}] {mark} {row.run}: N={row.robots} faulty {row.faulty:2d} {what}")
    bad = [r for r in rows if r.bad(args.pos_tol, args.psi_tol)]
    failed = False
    for part, sel in (("all", rows), ("tuned on", [r for r in rows if not r.held_out]),
                      ("held out", [r for r in rows if r.held_out])):  # fmt: skip
        if sel and (part == "all" or args.corpus is not None):
            print(f"{part}: " + summary(sel, args.pos_tol, args.psi_tol))
    s = scores(rows, args.pos_tol, args.psi_tol)
    if s["sound_left_out"] > args.max_left_out:
        print(f"FAIL: a sound robot left out in {s['sound_left_out']} runs > {args.max_left_out}")
        failed = True
    if s["fault_runs"] and s["named"] / s["fault_runs"] < args.min_named:
        print(f"FAIL: faulty robot named in {s['named']}/{s['fault_runs']} < {args.min_named:.0%}")
        failed = True
    if s["clean_runs"] and s["refused"] / s["clean_runs"] > args.max_refused:
        print(
            f"FAIL: planning refused on {s['refused']}/{s['clean_runs']} fault-free runs > {args.max_refused:.0%}"
        )
        failed = True
    if pool is not None:
        pool.shutdown()
    if args.ceiling:
        share = _ceiling(rows, args.jobs, args.corpus)
        if share < args.min_revealed:
            print(f"FAIL: faulty robot named in {share:.1%} of the runs the records reveal "
                  f"< {args.min_revealed:.0%}")  # fmt: skip
            failed = True
    draw(rows, args.png, args.psi_tol)
    print(f"figure: {args.png}")
    if args.json is not None:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps({"rows": [asdict(r) for r in rows]}, indent=2))
    return 1 if failed or (bad and args.corpus is None) else 0


if __name__ == "__main__":
    sys.exit(main())
