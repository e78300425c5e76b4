"""The scoring and report of ``tools.eval_perception`` (NAO paper section 3): detections
matched to the labelled robots of a view (:func:`match`), the recall, precision and error
statistics overall and per distance band (:func:`summarise`), the figure, an annotated
view, and the printed summary.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from agent.core.perception.detector import Detection
from tools.lib.perception_scenes import RANGE, VISIBLE_MIN, Truth, wrap

BANDS = ((0.5, 1.5), (1.5, 2.25), (2.25, 3.0))


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


def save_view(views: list[ViewResult], path: Path) -> None:
    """One annotated view at ``path``: the one that shows the most (a robot behind
    another found, robots in several distance bands, every detection true)."""
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
    path.parent.mkdir(parents=True, exist_ok=True)
    cv2.imwrite(str(path), draw(best.image, best.detections, best.truths))


def print_summary(summary: dict[str, Any], seed: int, clutter: bool) -> None:
    """The summary as text: recall, precision, errors, bands, overlap, time, compass."""
    de, be = summary["distance_error_m"], summary["bearing_error_deg"]
    print(
        f"views {summary['views']} (seed {seed}, clutter {clutter}); robots counted {summary['robots_counted']}"
    )
    if "calibration" in summary:
        print(f"calibration {str(summary['calibration'])[:16]}")
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
    for away, c in summary.get("compass_away", {}).items():
        print(
            f"compass {away:>4} m from its reference view: failures {c['failures']}/{c['n']}, "
            f"error rms {c['rms_err_deg']:.2f}°, p95 {c['p95_err_deg']:.2f}°, max {c['max_err_deg']:.2f}°"
        )
