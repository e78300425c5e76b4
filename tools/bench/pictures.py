"""``python -m tools.bench pictures``: EGL's pictures against TinyRenderer's
(sim/camera/renderer.py).

    python -m tools.bench pictures --fleets 3,10 --seeds 1,2,3 --views 6

For each fleet size and seed it builds the same generated scenario twice, once per
renderer, draws ``--views`` pictures of each (observers and head yaws cycling) and
prints the pixel difference (mean and 95th percentile of |EGL - Tiny| over every
channel, share of pixels differing by more than 16) and, for each NAO in view (its
bounding box projected into the picture, :func:`sim.camera.camera.project`), the IoU of the
detector's orange mask (H 2-10, S >= 170, V >= 50) inside that box. ``--png DIR`` saves
each pair side by side.
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import cv2
import numpy as np

from sim.camera import camera
from sim.physics.nao_model import BOUNDING_RADIUS, HEIGHT
from sim.physics.world import World
from sim.scenarios import generate

ORANGE_LO, ORANGE_HI = (2, 170, 50), (10, 255, 255)


def orange(img: np.ndarray) -> np.ndarray:
    return cv2.inRange(cv2.cvtColor(img, cv2.COLOR_BGR2HSV), ORANGE_LO, ORANGE_HI) > 0


def robot_box(w: World, observer: int, yaw: float, rid: int) -> tuple[int, int, int, int] | None:
    """(u0, v0, u1, v1) of robot ``rid``'s bounding cylinder in ``observer``'s picture."""
    x, y, th = w.pose(observer)
    rx, ry, _ = w.pose(rid)
    ring = [
        (rx + BOUNDING_RADIUS * math.cos(a), ry + BOUNDING_RADIUS * math.sin(a), z)
        for a in np.linspace(0, 2 * math.pi, 12, False)
        for z in (0.0, HEIGHT)
    ]
    uv = camera.project(x, y, th, yaw, np.array(ring))
    if np.isnan(uv).any():
        return None
    u0, v0 = np.floor(uv.min(axis=0)).astype(int)
    u1, v1 = np.ceil(uv.max(axis=0)).astype(int)
    u0, v0, u1, v1 = max(u0, 0), max(v0, 0), min(u1, camera.WIDTH), min(v1, camera.HEIGHT)
    return (int(u0), int(v0), int(u1), int(v1)) if u1 > u0 and v1 > v0 else None


def compare(n: int, seed: int, views: int, png: Path | None) -> dict[str, float]:
    sc = generate(n, seed)
    yaws = [math.radians(-100.0 + (i * 53.0) % 200.0) for i in range(views)]
    with (
        World(sc, noise=False, renderer="tiny") as tiny,
        World(sc, noise=False, renderer="egl") as egl,
    ):
        if egl.renderer != "egl":
            raise RuntimeError(f"EGL unusable: {egl.renderer_why}")
        diffs, big, ious = [], [], []
        for i, yaw in enumerate(yaws):
            obs = tiny.robot_ids[i % len(tiny.robot_ids)]
            a, b = tiny.render(obs, yaw), egl.render(obs, yaw)
            d = np.abs(a.astype(np.int16) - b.astype(np.int16))
            diffs.append(d)
            big.append(float((d.max(axis=2) > 16).mean()))
            ma, mb = orange(a), orange(b)
            for rid in tiny.robot_ids:
                box = None if rid == obs else robot_box(tiny, obs, yaw, rid)
                if box is None:
                    continue
                u0, v0, u1, v1 = box
                ra, rb = ma[v0:v1, u0:u1], mb[v0:v1, u0:u1]
                if ra.sum() + rb.sum() >= 40:  # the robot's orange shows (not wholly hidden)
                    ious.append(float((ra & rb).sum() / (ra | rb).sum()))
            if png is not None:
                png.mkdir(parents=True, exist_ok=True)
                cv2.imwrite(str(png / f"n{n}-s{seed}-v{i}.png"), np.hstack([a, b]))
    all_d = np.concatenate([d.ravel() for d in diffs])
    return {
        "mean_abs": float(all_d.mean()),
        "p95_abs": float(np.percentile(all_d, 95)),
        "share_over_16": float(np.mean(big)),
        "robots": len(ious),
        "iou_median": float(np.median(ious)) if ious else math.nan,
        "iou_min": float(min(ious)) if ious else math.nan,
    }


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m tools.bench pictures", description=__doc__)
    p.add_argument("--fleets", default="3,10", help="NAOs per generated scenario")
    p.add_argument("--seeds", default="1,2,3")
    p.add_argument("--views", type=int, default=6, help="pictures per scenario and renderer")
    p.add_argument("--png", type=Path, default=None, help="save each pair side by side here")
    a = p.parse_args(argv)
    for n in (int(v) for v in a.fleets.split(",")):
        for seed in (int(v) for v in a.seeds.split(",")):
            try:
                r = compare(n, seed, a.views, a.png)
            except RuntimeError as exc:
                print(f"compare: {exc}", file=sys.stderr)
                return 1
            print(
                f"{n:3d} NAOs seed {seed}: |EGL-Tiny| mean {r['mean_abs']:.2f}, p95 {r['p95_abs']:.0f}, "
                f"{100 * r['share_over_16']:.1f} % of pixels off by > 16; orange IoU over "
                f"{r['robots']} robots in view: median {r['iou_median']:.3f}, min {r['iou_min']:.3f}",
                flush=True,
            )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
