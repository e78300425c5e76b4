"""``python -m tools.build_mbase``: render the M-base the paper's way (NAO paper 3.1.2, 5.2.2 (i)).

Observer NAO-i at the origin facing +y (north), NAO-j 0.6 m ahead, turned in 5° steps:
72 masks of head cap + shoulders, cut from the world's forehead-camera renders at head
yaw 0. Supplementary side-posture masks are rendered with the observer's head at ±90°
and NAO-j side-on at 0.6 m along the camera axis (the paper's Figure 20 set-up).
Orientations where the far shoulder is only a sliver that vanishes with distance also
get a variant without that sliver ("reduced", same orientation). Since the neighbours
sweep their heads as well, every 30° of orientation also gets masks with the observed
NAO's head turned by ±45° and ±90° ("head"; an addition to the paper).

The result (``mbase.npz`` + ``mbase.json`` with the parameters and a content digest) is
written to ``agent/core/perception/data`` unless ``--out`` says otherwise; the renderer is
deterministic, so regenerating gives the same digest. The masks are cut from the renders
by :class:`tools.calibrate.masks.MBaseBuilder`, as ``python -m tools.calibrate build`` cuts
them from a lab's captures.
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import numpy as np

from agent.core.perception.camera import CameraModel
from agent.core.perception.mbase import DATA_DIR, MBase
from sim.physics import nao_model
from sim.physics.world import World
from sim.scenarios import RobotSpec, Scenario
from tools.calibrate.masks import MaskView, MBaseBuilder

NORTH = math.pi / 2
HEAD_YAWS_DEG = (-90.0, -45.0, 45.0, 90.0)  # the observed NAO's head, for "head" masks
HEAD_EVERY = 6  # every 6th orientation (30°) gets the turned-head masks


def render_target(w: World, cam: CameraModel, dist: float, rel: float, yaw: float) -> np.ndarray:
    """Observer 1 at the origin facing north, head at ``yaw``; NAO 2 at ``dist`` along the
    camera axis from the neck, its heading = viewing direction + ``rel``."""
    view = NORTH + yaw
    w.set_pose(2, dist * math.cos(view), dist * math.sin(view), view + rel)
    return w.render(1, yaw)


def build(step_deg: float = 5.0, distance: float = 0.6, seed: int = 0) -> MBase:
    """Render the views and cut them with :class:`tools.calibrate.masks.MBaseBuilder`."""
    cam = CameraModel()
    mb = MBaseBuilder(cam, distance=distance)
    n = round(360.0 / step_deg)
    sc = Scenario(
        robots=(RobotSpec(1, 0.0, 0.0, NORTH), RobotSpec(2, 0.0, distance, NORTH)), seed=seed
    )
    with World(sc, noise=False) as w:
        for i in range(n):
            rel = math.radians(i * step_deg)
            mb.add(MaskView(render_target(w, cam, distance, rel, 0.0), rel, "main"))
            print(f"\rmask {i + 1}/{n}", end="", file=sys.stderr)
        # neighbours sweep their heads too: masks of NAOs with the head turned
        for i in range(0, n, HEAD_EVERY):
            rel = math.radians(i * step_deg)
            for hy in HEAD_YAWS_DEG:
                w.set_head_yaw(2, math.radians(hy))
                img = render_target(w, cam, distance, rel, 0.0)
                mb.add(MaskView(img, rel, "head", 0.0, hy))
            w.set_head_yaw(2, 0.0)
        for yaw_deg in (90.0, -90.0):
            for rel_deg in (90.0, 270.0):
                rel = math.radians(rel_deg)
                img = render_target(w, cam, distance, rel, math.radians(yaw_deg))
                mb.add(MaskView(img, rel, "side", yaw_deg, 0.0))
    print(file=sys.stderr)
    return mb.build(
        {
            "step_deg": step_deg,
            "side_head_yaw_deg": [90.0, -90.0],
            "side_orientations_deg": [90.0, 270.0],
            "head_masks": {
                "observed_head_yaw_deg": list(HEAD_YAWS_DEG),
                "every_deg": HEAD_EVERY * step_deg,
            },
            "seed": seed,
            "renderer": "sim.physics.world.World (PyBullet TinyRenderer), noise off",
            "nao_model": {
                "height": nao_model.HEIGHT,
                "width": nao_model.WIDTH,
                "camera_forward": nao_model.CAMERA_FORWARD,
            },
        }
    )


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(
        prog="python -m tools.build_mbase", description=__doc__.split("\n")[0]
    )
    ap.add_argument(
        "--out", type=Path, default=DATA_DIR, help="output directory (default: the package data)"
    )
    ap.add_argument(
        "--step", type=float, default=5.0, help="orientation step in degrees (paper: 5)"
    )
    ap.add_argument("--distance", type=float, default=0.6, help="d_s in metres (paper: 0.6)")
    ap.add_argument("--seed", type=int, default=0, help="room texture seed (no orange either way)")
    args = ap.parse_args(argv)
    if not (0 < args.step <= 90 and 0.3 <= args.distance <= 2.0):
        print("error: --step must be in (0, 90] and --distance in [0.3, 2.0]", file=sys.stderr)
        return 2
    mb = build(args.step, args.distance, args.seed)
    npz, js = mb.save(args.out)
    counts = {k: mb.meta["kinds"].count(k) for k in ("main", "reduced", "head", "side")}
    print(f"M-base: {len(mb)} masks {counts}, digest {mb.digest()[:16]}")
    print(f"wrote {npz} ({npz.stat().st_size} bytes) and {js}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
