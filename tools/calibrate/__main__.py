"""``python -m tools.calibrate {capture,build,check,rehearse}``: calibrate the recogniser on a
lab's own NAOs (NAO paper 3.1.1, 3.1.2, eq. 6, 5.2.1; the steps: ``tools/calibrate/``).

Exit status: 0 done; 1 a robot or the check failed (``check``, ``rehearse``: below a
floor); 2 bad options or folders; 130 stopped by Ctrl-C (``capture`` resumes when run
again with the same options).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from agent.core.nao import NAOQI_PORT
from sim.camera.look import HELP as LOOK_HELP
from sim.camera.look import look_arg
from tools.calibrate.check import Floors
from tools.calibrate.plan import PlanSpec, coarse

GRIDS = ("paper", "quick", "coarse")


def grid(args: argparse.Namespace) -> PlanSpec:
    """The plan of ``--grid`` with the overrides given."""
    base = {
        "paper": PlanSpec(),
        "quick": PlanSpec(dbase_step_deg=15.0, dbase_poses=False),
        "coarse": coarse(),
    }[args.grid]
    doc = base.to_dict()
    if args.step is not None:
        doc["step_deg"] = args.step
    if args.dbase_step is not None:
        doc["dbase_step_deg"] = args.dbase_step
    if args.distances is not None:
        doc["distances"] = args.distances
    if args.check_distances is not None:
        doc["check_distances"] = args.check_distances
    return PlanSpec.from_dict(doc)


def _floats(text: str) -> list[float]:
    try:
        return [float(v) for v in text.split(",") if v.strip()]
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected comma-separated metres, got {text!r}") from None


def _grid_args(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--grid",
        choices=GRIDS,
        default="paper",
        help="paper: 72 masks 5° apart with turned heads and side postures, the D-base at "
        "37 distances 0.5-3.1 m at every mask's pose (about 4700 views); quick: the D-base "
        "every 15° without head and side poses (about 1100 views); coarse: a rehearsal's "
        "78 views",
    )
    p.add_argument("--step", type=float, default=None, help="M-base orientation step (deg)")
    p.add_argument("--dbase-step", type=float, default=None, help="D-base orientation step (deg)")
    p.add_argument("--distances", type=_floats, default=None, help="D-base distances (m, a,b,c)")
    p.add_argument(
        "--check-distances", type=_floats, default=None, help="held-out distances (m, a,b,c)"
    )


def _floor_args(p: argparse.ArgumentParser) -> None:
    f = Floors()
    p.add_argument("--min-recall", type=float, default=f.recall)
    p.add_argument("--min-precision", type=float, default=f.precision)
    p.add_argument(
        "--min-within", type=float, default=f.within, help="share of distances within 5 %%"
    )


def parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(
        prog="python -m tools.calibrate", description=__doc__.split("\n")[0]
    )
    sub = ap.add_subparsers(dest="command", required=True)
    c = sub.add_parser("capture", help="take the views with two NAOs over qi")
    c.add_argument(
        "--observer",
        required=True,
        metavar="URL",
        help=f"NAO-i, e.g. tcp://nao-1.local:{NAOQI_PORT}",
    )
    c.add_argument("--subject", required=True, metavar="URL", help="NAO-j")
    c.add_argument("--observer-id", type=int, default=1)
    c.add_argument("--subject-id", type=int, default=2)
    c.add_argument("--out", type=Path, required=True, help="capture folder (resumed if it exists)")
    c.add_argument("--no-compass", action="store_true", help="trust NAO-j's turns as commanded")
    _grid_args(c)
    b = sub.add_parser("build", help="orange range, M-base and D-base from a capture folder")
    b.add_argument("--captures", type=Path, required=True)
    b.add_argument("--out", type=Path, required=True, help="the calibration folder to write")
    k = sub.add_parser("check", help="recall, precision and distance error on held-out views")
    k.add_argument("--calibration", type=Path, default=None, help="default: the built-in one")
    k.add_argument("--captures", type=Path, required=True)
    k.add_argument("--set", default="check", choices=("check", "dbase", "mbase"))
    k.add_argument("--report", type=Path, default=None, help="default: CALIBRATION/report")
    _floor_args(k)
    r = sub.add_parser("rehearse", help="capture, build and check against virtual NAOs")
    r.add_argument(
        "--look",
        type=lambda text: str(look_arg(text)),
        default="default",
        metavar="SPEC",
        help=LOOK_HELP,
    )
    r.add_argument("--out", type=Path, required=True, help="DIR/captures and DIR/calibration")
    r.add_argument("--seed", type=int, default=0, help="the room's texture and motion noise")
    r.add_argument("--no-noise", action="store_true", help="turn NAO-j without motion noise")
    _grid_args(r)
    _floor_args(r)
    return ap


def floors(args: argparse.Namespace) -> Floors:
    return Floors(args.min_recall, args.min_precision, args.min_within)


def main(argv: list[str] | None = None) -> int:
    ap = parser()
    args = ap.parse_args(argv)
    try:
        spec = grid(args) if args.command in ("capture", "rehearse") else None
    except ValueError as exc:
        ap.error(str(exc))
    try:
        return run(args, spec)
    except KeyboardInterrupt:
        print("stopped: run the same command again to resume", file=sys.stderr)
        return 130


def run(args: argparse.Namespace, spec: PlanSpec | None) -> int:
    from agent.body.base import BodyError
    from agent.core.perception import calibration as calib
    from tools.calibrate import build, check

    if args.command == "capture":
        from agent.body.naoqi import NaoqiBody
        from agent.core.perception.camera import CameraModel
        from tools.calibrate.capture import CaptureError, capture
        from tools.calibrate.folder import CaptureFolder

        assert spec is not None
        robots = {
            "observer": {"id": args.observer_id, "url": args.observer},
            "subject": {"id": args.subject_id, "url": args.subject},
        }
        try:
            folder = CaptureFolder.create_or_resume(args.out, spec, robots, CameraModel())
        except ValueError as exc:
            print(f"error: {exc}", file=sys.stderr)
            return 2
        left = len(spec.shots()) - len(folder.records)
        print(f"{left} views to take into {args.out}", file=sys.stderr)
        bodies: list[NaoqiBody] = []
        try:
            bodies.append(NaoqiBody(args.observer, args.observer_id))
            bodies.append(NaoqiBody(args.subject, args.subject_id))
            capture(bodies[0], bodies[1], folder, compass=not args.no_compass)
        except (BodyError, CaptureError) as exc:
            print(f"capture stopped: {exc}; run the same command again to resume", file=sys.stderr)
            return 1
        finally:
            for b in bodies:
                b.close()
        print(f"captured {len(folder.records)} views; contact sheet {args.out}/contact_sheet.png")
        return 0
    if args.command == "build":
        try:
            built = build.build(args.captures, args.out)
        except ValueError as exc:
            print(f"error: {exc}", file=sys.stderr)
            return 2
        print(f"calibration {built.digest} in {built.path}")
        return 0
    if args.command == "check":
        try:
            cal = calib.builtin() if args.calibration is None else calib.load(args.calibration)
            res = check.check(cal, args.captures, args.set)
        except ValueError as exc:
            print(f"error: {exc}", file=sys.stderr)
            return 2
        report = args.report or (args.calibration or Path("out/calibrate")) / "report"
        failed = check.write(res, floors(args), report)
        print(f"calibration {cal.digest[:16]} ({cal.source}): {res.summary()}")
        print(f"report: {report}/check.json, {report}/check.png")
        if failed:
            print(f"below the floors: {'; '.join(failed)}", file=sys.stderr)
            return 1
        return 0
    from tools.calibrate.capture import CaptureError
    from tools.calibrate.rehearse import rehearse

    assert spec is not None
    try:
        r = rehearse(
            args.look, args.out, spec, seed=args.seed, noise=not args.no_noise, floors=floors(args)
        )
    except (BodyError, CaptureError) as exc:
        print(f"rehearsal stopped: {exc}", file=sys.stderr)
        return 1
    except ValueError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    print(f"calibration {r.digest} in {r.calibration} (captures in {r.captures})")
    if r.failed:
        print(f"below the floors: {'; '.join(r.failed)}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
