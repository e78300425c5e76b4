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
``--overlap``) are made by :mod:`tools.perception_scenes`; this module detects, matches,
scores and reports. A detection is true when its bearing lies within a robot's angular
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
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from agent.core.perception.calibration import builtin, load
from agent.core.perception.compass import VisualCompass
from agent.core.perception.detector import Detection, Detector
from sim.renderer import RENDERERS, choose
from sim.scenarios import RobotSpec, Scenario
from sim.world import World
from tools.perception_scenes import RANGE, VISIBLE_MIN, Truth, scenes, wrap

BANDS = ((0.5, 1.5), (1.5, 2.25), (2.25, 3.0))
COMPASS_STEPS_DEG = (5.0, 10.0, 15.0, 20.0, 30.0, 40.0)


@dataclass
class ViewResult:
    truths: list[Truth]
    detections: list[Detection]
    seconds: float
    image: np.ndarray | None = None
    pairs: list[tuple[int, int]] = field(default_factory=list)  # (truth idx, detection idx)
    head_yaw: float = 0.0


def match(truths: list[Truth], dets: list[Detection]) -> list[tuple[int, int]]:
    """Greedy pairs (truth, detection): the bearing within the robot's extent (+1°), by
    increasing bearing difference (in extents) plus relative distance difference (robots
    overlapping in the image differ in distance)."""
    cand = []
    for i, t in enumerate(truths):
        for j, d in enumerate(dets):
            diff = abs(wrap(d.bearing - t.bearing))
            if diff <= t.half_angle + math.radians(1.0):
                cost = diff / t.half_angle + abs(d.distance - t.distance) / t.distance
                cand.append((cost, i, j))
    cand.sort()
    used_t: set[int] = set()
    used_d: set[int] = set()
    pairs = []
    for _, i, j in cand:
        if i in used_t or j in used_d:
            continue
        used_t.add(i)
        used_d.add(j)
        pairs.append((i, j))
    return pairs


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
) -> list[ViewResult]:
    """The labelled views of :func:`tools.perception_scenes.scenes` through ``detector``,
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


def run_compass(
    seed: int, samples: int, steps_deg: tuple[float, ...], renderer: str = "tiny"
) -> dict[str, Any]:
    """Compass error per turn step: the observer turns its body in place in the textured
    room (head yaw 0) and the compass measures the turn."""
    rng = np.random.default_rng([seed, 0xC0C0])
    vc = VisualCompass()
    res: dict[str, Any] = {}
    sc = Scenario(robots=(RobotSpec(1, 0.0, 0.0, math.pi / 2),), seed=seed, room=4.0)
    with World(sc, noise=False, renderer=renderer) as w:
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


def _errors(rows: list[tuple[float, bool, float, float]]) -> dict[str, Any]:
    """Recall and error statistics of (true distance, found, distance err, bearing err°)."""
    found = [r for r in rows if r[1]]
    da = np.abs(np.array([r[2] for r in found])) if found else np.array([np.nan])
    rel = np.abs(np.array([r[2] / r[0] for r in found])) if found else np.array([np.nan])
    ba = np.abs(np.array([r[3] for r in found])) if found else np.array([np.nan])
    return {
        "robots": len(rows),
        "found": len(found),
        "recall": len(found) / len(rows) if rows else float("nan"),
        "distance_error_m": {
            "median": float(np.median(da)),
            "p95": float(np.percentile(da, 95)),
            "within_0.1": float(np.mean(da <= 0.1)) if found else 0.0,
            "within_5pct": float(np.mean(rel <= 0.05)) if found else 0.0,
            "bias": float(np.mean([r[2] for r in found])) if found else float("nan"),
        },
        "bearing_error_deg": {
            "median": float(np.median(ba)),
            "p95": float(np.percentile(ba, 95)),
            "within_3": float(np.mean(ba <= 3.0)) if found else 0.0,
        },
    }


def summarise(views: list[ViewResult]) -> dict[str, Any]:
    n_det = false_pos = over = over_found = clut = clut_found = 0
    rows: list[tuple[float, bool, float, float]] = []
    roles: dict[str, list[tuple[float, bool, float, float]]] = {"front": [], "back": []}
    vis_bins = ((0.8, 0.9), (0.9, 0.99), (0.99, 1.01))
    by_vis: list[list[bool]] = [[] for _ in vis_bins]
    hidden = hidden_found = 0
    for v in views:
        n_det += len(v.detections)
        paired_d = {j for _, j in v.pairs}
        false_pos += len(v.detections) - len(paired_d)
        by_t = dict(v.pairs)
        for i, t in enumerate(v.truths):
            if t.in_range and t.overlapped and t.visible is None:
                over += 1
                over_found += int(i in by_t)
            if t.counts and t.cluttered:
                clut += 1
                clut_found += int(i in by_t)
            if (
                t.visible is not None
                and t.role == "back"
                and t.in_view
                and not t.in_range
                and RANGE[0] <= t.distance <= t.max_distance
                and t.visible > 0
            ):
                hidden += 1
                hidden_found += int(i in by_t)
            if not t.counts:
                continue
            if i in by_t:
                d = v.detections[by_t[i]]
                row = (
                    t.distance,
                    True,
                    d.distance - t.distance,
                    math.degrees(wrap(d.bearing - t.bearing)),
                )
            else:
                row = (t.distance, False, 0.0, 0.0)
            rows.append(row)
            if t.role in roles:
                roles[t.role].append(row)
            if t.visible is not None:
                for k, (lo, hi) in enumerate(vis_bins):
                    if lo <= t.visible < hi:
                        by_vis[k].append(row[1])
    times = np.array([v.seconds for v in views]) * 1e3
    overall = _errors(rows)
    bands = {}
    for lo, hi in BANDS:
        sel = [r for r in rows if lo <= r[0] < hi or (hi == BANDS[-1][1] and r[0] == hi)]
        if sel:
            bands[f"{lo:g}-{hi:g}"] = _errors(sel)
    out: dict[str, Any] = {
        "views": len(views),
        "robots_counted": overall["robots"],
        "recall": overall["recall"],
        "left_out_robot_behind": {"robots": over, "found": over_found},
        "clutter_behind": {"robots": clut, "found": clut_found},
        "detections": n_det,
        "false_positives": false_pos,
        "precision": (n_det - false_pos) / n_det if n_det else float("nan"),
        "distance_error_m": overall["distance_error_m"],
        "bearing_error_deg": overall["bearing_error_deg"],
        "bands": bands,
        "time_ms": {"median": float(np.median(times)), "p95": float(np.percentile(times, 95))},
    }
    if any(t.visible is not None for v in views for t in v.truths):
        out["overlap"] = {
            "visible_min": VISIBLE_MIN,
            "front": _errors(roles["front"]),
            "back": _errors(roles["back"]),
            "recall_by_visible": {
                f"{lo:g}-{min(hi, 1.0):g}": {
                    "robots": len(f),
                    "recall": sum(f) / len(f) if f else float("nan"),
                }
                for (lo, hi), f in zip(vis_bins, by_vis, strict=True)
            },
            "back_hidden_more": {"robots": hidden, "found": hidden_found},
        }
    return out


def draw(img: np.ndarray, dets: list[Detection], truths: list[Truth] | None = None) -> np.ndarray:
    """The view with each detection's box, λ, distance and bearing drawn on it."""
    out = img.copy()
    for d in dets:
        x, y, w, h = d.box
        cv2.rectangle(out, (x, y), (x + w, y + h), (0, 255, 0), 2)
        label = f"l={d.confidence:.2f} d={d.distance:.2f}m b={math.degrees(d.bearing):+.1f}"
        ty = y - 8 if y > 20 else y + h + 16
        cv2.putText(out, label, (max(0, x - 10), ty), cv2.FONT_HERSHEY_SIMPLEX, 0.48, (0, 0, 0), 3)
        cv2.putText(
            out, label, (max(0, x - 10), ty), cv2.FONT_HERSHEY_SIMPLEX, 0.48, (0, 255, 0), 1
        )
    if truths is not None:
        lines = [
            f"truth: d={t.distance:.2f}m b={math.degrees(t.bearing):+.1f}"
            for t in truths
            if t.in_view
        ]
        for i, s in enumerate(lines):
            cv2.putText(out, s, (8, 470 - 18 * i), cv2.FONT_HERSHEY_SIMPLEX, 0.48, (0, 0, 0), 3)
            cv2.putText(
                out, s, (8, 470 - 18 * i), cv2.FONT_HERSHEY_SIMPLEX, 0.48, (255, 255, 255), 1
            )
    return out


def figure(views: list[ViewResult], summary: dict[str, Any], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    path.parent.mkdir(parents=True, exist_ok=True)
    derr, berr, dist = [], [], []
    for v in views:
        by_t = dict(v.pairs)
        for i, t in enumerate(v.truths):
            if t.counts and i in by_t:
                d = v.detections[by_t[i]]
                derr.append(d.distance - t.distance)
                berr.append(math.degrees(wrap(d.bearing - t.bearing)))
                dist.append(t.distance)
    shots = [v for v in views if v.image is not None and v.detections][:2]
    fig = plt.figure(figsize=(13, 8))
    ax1 = fig.add_subplot(2, 2, 1)
    ax1.plot(dist, derr, ".", alpha=0.6)
    xs = np.array([RANGE[0], max(dist, default=RANGE[1])])
    ax1.plot(xs, 0.05 * xs, "r-", lw=0.8, label="±5 %")
    ax1.plot(xs, -0.05 * xs, "r-", lw=0.8)
    ax1.legend(loc="upper left")
    ax1.set_xlabel("true distance (m)")
    ax1.set_ylabel("distance error (m)")
    ax1.set_title(f"recall {summary['recall']:.3f}, precision {summary['precision']:.3f}")
    ax2 = fig.add_subplot(2, 2, 2)
    ax2.hist(berr, bins=40)
    ax2.set_xlabel("bearing error (deg)")
    ax2.set_title(f"within 3°: {summary['bearing_error_deg']['within_3']:.3f}")
    for k, v in enumerate(shots):
        ax = fig.add_subplot(2, 2, 3 + k)
        assert v.image is not None
        ax.imshow(cv2.cvtColor(draw(v.image, v.detections, v.truths), cv2.COLOR_BGR2RGB))
        ax.axis("off")
    fig.tight_layout()
    fig.savefig(path, dpi=80)
    plt.close(fig)


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
        help="the views' renderer (sim/renderer.py; default tiny, the reference pictures)",
    )
    ap.add_argument("--json", action="store_true", help="print the summary as one JSON object")
    ap.add_argument(
        "--compass-samples", type=int, default=10, help="turns per compass step (0: skip)"
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
    if args.views < 1 or args.compass_samples < 0:
        print("error: --views must be >= 1 and --compass-samples >= 0", file=sys.stderr)
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
    )
    summary: dict[str, Any] = {
        "seed": args.seed,
        "calibration": cal.digest,
        "renderer": drawn.name,
        "clutter": args.clutter,
        "neighbour_heads": args.neighbour_heads,
        "max_distance": args.max_distance,
        "overlap_views": args.overlap,
        **summarise(views),
    }
    if args.compass_samples:
        summary["compass"] = run_compass(
            args.seed, args.compass_samples, COMPASS_STEPS_DEG, drawn.name
        )
    figure(views, summary, args.png)
    if args.view_png is not None:
        best = max(
            (v for v in views if v.image is not None),
            key=lambda v: (
                any(v.truths[i].role == "back" and v.truths[i].counts for i, _ in v.pairs),
                len({min(int(v.truths[i].distance / 0.75), 3) for i, _ in v.pairs}),
                len(v.pairs),
                len(v.detections) == len(v.pairs),
            ),
        )
        assert best.image is not None
        args.view_png.parent.mkdir(parents=True, exist_ok=True)
        cv2.imwrite(str(args.view_png), draw(best.image, best.detections, best.truths))
    if args.json:
        print(json.dumps(summary, sort_keys=True))
        return 0
    de, be = summary["distance_error_m"], summary["bearing_error_deg"]
    print(
        f"views {summary['views']} (seed {args.seed}, clutter {args.clutter}); robots counted {summary['robots_counted']}"
    )
    print(f"calibration {cal.digest[:16]} ({cal.source})")
    print(f"recall    {summary['recall']:.4f}   (target >= 0.95)")
    cb, lo = summary["clutter_behind"], summary["left_out_robot_behind"]
    print(
        f"          (counted, with clutter behind them in the image: {cb['robots']}, found "
        f"{cb['found']}; left out, a robot behind overlaps them: {lo['robots']}, found {lo['found']})"
    )
    print(
        f"precision {summary['precision']:.4f}   ({summary['false_positives']} false of {summary['detections']}; target >= 0.99)"
    )
    print(
        f"distance error: median {de['median']:.3f} m, p95 {de['p95']:.3f} m, within 0.1 m {de['within_0.1']:.3f}, "
        f"within 5 % {de['within_5pct']:.3f} (target >= 0.95), bias {de['bias']:+.3f} m"
    )
    print(
        f"bearing error:  median {be['median']:.2f}°, p95 {be['p95']:.2f}°, within 3° {be['within_3']:.3f} (target >= 0.95)"
    )
    for name, b in summary["bands"].items():
        print(
            f"  band {name:>9} m: robots {b['robots']:3d}, recall {b['recall']:.3f}, distance within 5 % "
            f"{b['distance_error_m']['within_5pct']:.3f} (p95 {b['distance_error_m']['p95']:.3f} m), "
            f"bearing within 3° {b['bearing_error_deg']['within_3']:.3f} (p95 {b['bearing_error_deg']['p95']:.2f}°)"
        )
    if "overlap" in summary:
        o = summary["overlap"]
        print(
            f"overlap (robots with >= {o['visible_min']:.0%} of their orange visible): front "
            f"{o['front']['found']}/{o['front']['robots']}, back {o['back']['found']}/"
            f"{o['back']['robots']}; recall by visible fraction: "
            + ", ".join(
                f"{k} {r['recall']:.3f} ({r['robots']})" for k, r in o["recall_by_visible"].items()
            )
        )
        hm = o["back_hidden_more"]
        print(
            f"          (back robots hidden more, not counted: {hm['robots']}, found {hm['found']})"
        )
    print(
        f"recognition time per frame: median {summary['time_ms']['median']:.1f} ms, p95 {summary['time_ms']['p95']:.1f} ms"
    )
    for step, c in summary.get("compass", {}).items():
        if step == "featureless":
            print(f"compass, featureless view: ok={c['ok']} ({c['reason']})")
        else:
            print(
                f"compass step {step:>3}°: failures {c['failures']}/{c['n']}, error median {c['median_err_deg']:.2f}°, "
                f"p95 {c['p95_err_deg']:.2f}°, max {c['max_err_deg']:.2f}°, within 2° {c['within_2deg']:.2f}"
            )
    print(f"wrote {args.png}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
