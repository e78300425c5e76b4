"""``python -m tools.eval_perception``: measure the perception of the NAO paper, section 3.

Renders N labelled views in the simulated world: an observer with a random
heading and head yaw across ±119.5°, 1-3 other NAOs at 0.4 m to ``--max-distance`` +
0.15 m (default 3.0 m) with any orientation in its field of view, optionally orange
lookalike clutter in the room; runs the
:class:`~agent.core.perception.detector.Detector` on each view and prints recall, precision,
distance and bearing errors (median, p95, share within 0.1 m, within 5 % of the distance
and within 3°, overall and per distance band), the recognition time per frame, and the
visual compass error per turn step in the textured room.

The views and their labels (which robots count for recall, measured occlusion with
``--overlap``) are made by :mod:`tools.lib.perception_scenes`; this module detects, and
:mod:`tools.lib.perception_report` matches, scores and reports. A detection is true when its bearing lies within a robot's angular
extent (+1°) of any robot in view (greedy by bearing difference); other detections are
false positives. Errors are measured on matched robots that count for recall.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import math
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

from agent.core.perception.calibration import builtin, load
from agent.core.perception.compass import VisualCompass
from agent.core.perception.detector import Detector
from sim.camera.look import HELP as LOOK_HELP
from sim.camera.look import Look, look_arg
from sim.camera.renderer import RENDERERS, choose
from sim.physics.world import World
from sim.scenarios import RobotSpec, Scenario
from tools.lib.perception_report import (
    ViewResult,
    figure,
    match,
    print_summary,
    save_view,
    summarise,
)
from tools.lib.perception_scenes import RANGE, scenes

COMPASS_STEPS_DEG = (5.0, 10.0, 15.0, 20.0, 30.0, 40.0)
#: How far from the reference view's place the compass is measured (``--compass-away``), m.
COMPASS_AWAY_M = (0.0, 0.25, 0.5, 1.0, 1.5, 2.0)


def run_views(
    seed: int,
    n_views: int,
    clutter: bool,
    detector: Detector,
    keep_images: int = 0,
    neighbour_heads: bool = False,
    max_distance: float = RANGE[1],
    overlap: bool = False,
    renderer: str = "tiny",
    look: Look | None = None,
) -> list[ViewResult]:
    """The labelled views of :func:`tools.lib.perception_scenes.scenes` (in ``look``) through ``detector``,
    each matched with its labels and timed (the first ``keep_images`` keep their picture)."""
    out: list[ViewResult] = []
    views = scenes(
        seed,
        n_views,
        clutter,
        detector.camera,
        neighbour_heads,
        max_distance,
        overlap,
        renderer=renderer,
        look=look,
    )
    with contextlib.closing(views):
        for v, scene in enumerate(views):
            img, yaw, truths = scene.image, scene.yaw, scene.truths
            t0 = time.perf_counter()
            dets = detector.detect(img, yaw)
            dt = time.perf_counter() - t0
            res = ViewResult(truths, dets, dt, img if v < keep_images else None, head_yaw=yaw)
            res.pairs = match(truths, dets)
            out.append(res)
            if (v + 1) % 10 == 0 or v + 1 == n_views:
                print(f"\rview {v + 1}/{n_views}", end="", file=sys.stderr)
    print(file=sys.stderr)
    return out


def compass_room(seed: int, renderer: str, look: Look | None) -> World:
    """The textured 4 m room with one observer, noiseless, in ``look`` (the compass's scene)."""
    sc = Scenario(
        robots=(RobotSpec(1, 0.0, 0.0, math.pi / 2),), seed=seed, room=4.0, look=look or Look()
    )
    return World(sc, noise=False, renderer=renderer)


def run_compass(
    seed: int,
    samples: int,
    steps_deg: tuple[float, ...],
    renderer: str = "tiny",
    look: Look | None = None,
) -> dict[str, Any]:
    """Compass error per turn step: the observer turns its body in place in the textured
    room (head yaw 0, the world in ``look``) and the compass measures the turn."""
    rng = np.random.default_rng([seed, 0xC0C0])
    vc = VisualCompass()
    res: dict[str, Any] = {}
    with compass_room(seed, renderer, look) as w:
        for step in steps_deg:
            errs = []
            fails = 0
            for _ in range(samples):
                x, y = (float(v) for v in rng.uniform(-1.5, 1.5, size=2))
                h0 = float(rng.uniform(-math.pi, math.pi))
                sgn = 1.0 if rng.random() < 0.5 else -1.0
                w.set_pose(1, x, y, h0)
                a = w.render(1, 0.0)
                w.set_pose(1, x, y, h0 + sgn * math.radians(step))
                b = w.render(1, 0.0)
                r = vc.measure(a, b)
                if not r.ok:
                    fails += 1
                    continue
                errs.append(abs(math.degrees(r.dtheta) - sgn * step))
            e = np.array(errs) if errs else np.array([np.nan])
            res[f"{step:g}"] = {
                "n": samples,
                "failures": fails,
                "median_err_deg": float(np.nanmedian(e)),
                "p95_err_deg": float(np.nanpercentile(e, 95)),
                "max_err_deg": float(np.nanmax(e)),
                "within_2deg": float(np.mean(e <= 2.0)) if errs else 0.0,
            }
            print(f"\rcompass step {step:g}°", end="", file=sys.stderr)
    print(file=sys.stderr)
    blank = np.full((480, 640, 3), 127, np.uint8)
    r = vc.measure(blank, blank)
    res["featureless"] = {"ok": r.ok, "reason": r.reason}
    return res


def run_compass_away(
    seed: int,
    samples: int,
    away_m: tuple[float, ...],
    renderer: str = "tiny",
    look: Look | None = None,
) -> dict[str, Any]:
    """Compass error against a reference view taken elsewhere: the observer's reference is
    drawn at one place, the second view ``d`` metres away in a random direction and turned by
    up to ±20° (a resumed robot turned back to θ = 0 by its estimate). The pure-rotation
    model of the compass then meets parallax; the RMS error per ``d`` is the compass's
    noise away from its reference (:data:`agent.core.control.heading_fix.COMPASS_AWAY`)."""
    rng = np.random.default_rng([seed, 0xA3A7])
    vc = VisualCompass()
    res: dict[str, Any] = {}
    with compass_room(seed, renderer, look) as w:
        for d in away_m:
            errs, fails = [], 0
            for _ in range(samples):
                x, y = (float(v) for v in rng.uniform(-1.5, 1.5, size=2))
                h0 = float(rng.uniform(-math.pi, math.pi))
                way = float(rng.uniform(-math.pi, math.pi))
                turn = float(rng.uniform(-1.0, 1.0)) * math.radians(20.0)
                w.set_pose(1, x, y, h0)
                a = w.render(1, 0.0)
                w.set_pose(1, x + d * math.cos(way), y + d * math.sin(way), h0 + turn)
                r = vc.measure(a, w.render(1, 0.0))
                if not r.ok:
                    fails += 1
                    continue
                errs.append(math.degrees(r.dtheta - turn))
            e = np.array(errs) if errs else np.array([np.nan])
            res[f"{d:g}"] = {
                "n": samples,
                "failures": fails,
                "rms_err_deg": float(np.sqrt(np.nanmean(e**2))),
                "p95_err_deg": float(np.nanpercentile(np.abs(e), 95)),
                "max_err_deg": float(np.nanmax(np.abs(e))),
            }
            print(f"\rcompass {d:g} m away", end="", file=sys.stderr)
    print(file=sys.stderr)
    return res


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(
        prog="python -m tools.eval_perception", description=__doc__.split("\n")[0]
    )
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--views", type=int, default=100)
    ap.add_argument("--clutter", action="store_true", help="orange lookalike cubes in the room")
    ap.add_argument(
        "--neighbour-heads",
        action="store_true",
        help="the observed NAOs' heads at random yaws (as while they sweep), not straight",
    )
    ap.add_argument(
        "--max-distance",
        type=float,
        default=RANGE[1],
        help=f"farthest counted robot, m (default {RANGE[1]:g}; the paper's range ends at 1.45)",
    )
    ap.add_argument(
        "--overlap",
        action="store_true",
        help="every view puts a NAO partly behind another in the image (measured occlusion)",
    )
    ap.add_argument(
        "--renderer",
        choices=RENDERERS,
        default="tiny",
        help="the views' renderer (sim/camera/renderer.py; default tiny, the reference pictures)",
    )
    ap.add_argument(
        "--look", type=look_arg, default=Look(), metavar="SPEC", help="the views' " + LOOK_HELP
    )
    ap.add_argument("--json", action="store_true", help="print the summary as one JSON object")
    ap.add_argument(
        "--compass-samples", type=int, default=10, help="turns per compass step (0: skip)"
    )
    ap.add_argument(
        "--compass-away",
        type=int,
        default=0,
        metavar="N",
        help="turns per distance from the compass's reference view (parallax; 0: skip)",
    )
    ap.add_argument("--png", type=Path, default=Path("out/perception/eval.png"))
    ap.add_argument("--view-png", type=Path, default=None, help="also save one annotated view here")
    ap.add_argument(
        "--calibration",
        type=Path,
        default=None,
        metavar="DIR",
        help="a calibration folder (python -m tools.calibrate build); default: the built-in one",
    )
    args = ap.parse_args(argv)
    if args.views < 1 or args.compass_samples < 0 or args.compass_away < 0:
        print(
            "error: --views must be >= 1, --compass-samples and --compass-away >= 0",
            file=sys.stderr,
        )
        return 2
    if not RANGE[0] < args.max_distance <= 4.0:
        print(f"error: --max-distance must be in ({RANGE[0]}, 4.0]", file=sys.stderr)
        return 2
    try:
        cal = builtin() if args.calibration is None else load(args.calibration)
        det = Detector(cal.mbase, cal.dbase, orange=cal.orange)
    except ValueError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    drawn = choose(args.renderer)  # once: a new world every few views
    print(f"renderer {drawn.name} ({drawn.why})", file=sys.stderr)
    views = run_views(
        args.seed,
        args.views,
        args.clutter,
        det,
        keep_images=min(args.views, 20),
        neighbour_heads=args.neighbour_heads,
        max_distance=args.max_distance,
        overlap=args.overlap,
        renderer=drawn.name,
        look=args.look,
    )
    summary: dict[str, Any] = {
        "seed": args.seed,
        "calibration": cal.digest,
        "renderer": drawn.name,
        "look": str(args.look),
        "clutter": args.clutter,
        "neighbour_heads": args.neighbour_heads,
        "max_distance": args.max_distance,
        "overlap_views": args.overlap,
        **summarise(views),
    }
    if args.compass_samples:
        summary["compass"] = run_compass(
            args.seed, args.compass_samples, COMPASS_STEPS_DEG, drawn.name, args.look
        )
    if args.compass_away:
        summary["compass_away"] = run_compass_away(
            args.seed, args.compass_away, COMPASS_AWAY_M, drawn.name, args.look
        )
    figure(views, summary, args.png)
    if args.view_png is not None:
        save_view(views, args.view_png)
    if args.json:
        print(json.dumps(summary, sort_keys=True))
        return 0
    print_summary(summary, args.seed, args.clutter)
    print(f"wrote {args.png}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
