"""``python -m tools.bench perception``: recognition time per 640x480 frame (target: median <= 30 ms).

Renders a seeded set of views (1-3 NAOs at 0.4-3.15 m, orange clutter, head yaws across
the range; ``--overlap``: views where NAOs overlap in the image) once, then times :meth:`Detector.detect` on each (``--repeat`` times, best kept per
frame) and the visual compass on consecutive pairs of views (each measurement after the
first meets one new picture, the other's features kept, as a robot's do). Prints median
and p95 of the wall time and of the CPU time (the machine may be shared).
"""

from __future__ import annotations

import argparse
import itertools
import math
import os
import sys
import time

import numpy as np

from agent.core.perception.compass import VisualCompass
from agent.core.perception.detector import Detector
from tools.eval_perception import run_views


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(
        prog="python -m tools.bench perception", description=__doc__.split("\n")[0]
    )
    ap.add_argument("--frames", type=int, default=40)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--seed", type=int, default=5)
    ap.add_argument("--overlap", action="store_true", help="views with NAOs overlapping")
    args = ap.parse_args(argv)
    if args.frames < 1 or args.repeat < 1:
        print("error: --frames and --repeat must be >= 1", file=sys.stderr)
        return 2
    det = Detector()
    views = run_views(
        args.seed, args.frames, True, det, keep_images=args.frames, overlap=args.overlap
    )
    imgs = [(v.image, v) for v in views if v.image is not None]
    times = []
    cpu = []
    for img, _ in imgs:
        assert img is not None
        best = best_cpu = math.inf
        for _ in range(args.repeat):
            t0, c0 = time.perf_counter(), time.process_time()
            det.detect(img, 0.0)  # the head yaw does not change the work done
            best = min(best, time.perf_counter() - t0)
            best_cpu = min(best_cpu, time.process_time() - c0)
        times.append(best * 1e3)
        cpu.append(best_cpu * 1e3)
    t = np.array(times)
    c = np.array(cpu)
    n_tuples = [len(v.detections) for _, v in imgs]
    print(f"perception: {len(t)} frames, {sum(n_tuples)} detections")
    print(
        f"detect ms per frame (wall): median {np.median(t):.1f}  p95 {np.percentile(t, 95):.1f}  "
        f"max {t.max():.1f}  (target median <= 30)"
    )
    print(
        f"detect ms per frame (CPU):  median {np.median(c):.1f}  p95 {np.percentile(c, 95):.1f}  "
        f"max {c.max():.1f}"
    )
    print(f"load average while measuring: {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores")
    vc = VisualCompass()
    ct, cc = [], []
    for (a, _), (b, _) in itertools.pairwise(imgs):
        assert a is not None and b is not None
        t0, c0 = time.perf_counter(), time.process_time()
        vc.measure(a, b)
        ct.append((time.perf_counter() - t0) * 1e3)
        cc.append((time.process_time() - c0) * 1e3)
    if ct:
        w, c = np.array(ct), np.array(cc)
        print(
            f"compass ms per measurement (wall): median {np.median(w):.1f}  p95 {np.percentile(w, 95):.1f}"
        )
        print(
            f"compass ms per measurement (CPU):  median {np.median(c):.1f}  p95 {np.percentile(c, 95):.1f}"
        )
    return 0 if np.median(t) <= 30.0 else 1
