"""``python -m tools.calibrate_dbase``: calibrate the distance model, build the D-base (NAO paper 5.2.1).

NAO-j is put at 37 distances 0.5-3.1 m (body centre to body centre: the paper's 20
distances 0.05 m apart up to 1.45 m, then 0.1 m apart up to 3.1 m, just past the 3 m
range) straight ahead of NAO-i for every M-base orientation (and, for the masks of turned
heads and side postures, in the pose each was rendered in) in the simulated world; the
samples and the fit of eq. 6 per mask are :mod:`tools.calibrate.distances`'s, which builds
a lab's D-base from its own captures the same way (``python -m tools.calibrate build``).
Table 1 (a, b, R², RMSE per mask) is printed and a figure like the paper's Figure 19 is
written.
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

from agent.core.perception.camera import CameraModel
from agent.core.perception.dbase import DBase
from agent.core.perception.detector import Recogniser
from agent.core.perception.mbase import DATA_DIR, MBase
from sim.physics.world import World
from sim.scenarios import RobotSpec, Scenario
from tools.calibrate.distances import (
    DISTANCES,
    MIN_SAMPLES,
    SCALE,
    Samples,
    camera_distance,
    figure,
    fit_all,
    sample_view,
    table,
)

NORTH = math.pi / 2


def calibration_poses(mb: MBase) -> list[tuple[int, float, float, list[int]]]:
    """What to render for each mask calibrated directly: (mask, observer head yaw,
    observed NAO's head yaw, masks sharing the view). Every "main" orientation (with its
    "reduced" variant), and, when the M-base records the head yaws it was rendered with,
    every "head" and "side" mask in its own pose."""
    kinds = mb.meta.get("kinds", ["main"] * len(mb))
    obs = mb.meta.get("observer_head_yaw_deg")
    tgt = mb.meta.get("observed_head_yaw_deg")
    out: list[tuple[int, float, float, list[int]]] = []
    for k0 in range(len(mb)):
        rel = float(mb.orientation[k0])
        if kinds[k0] == "main":
            same = [
                k
                for k in range(len(mb))
                if kinds[k] in ("main", "reduced") and abs(mb.orientation[k] - rel) < 1e-9
            ]
            out.append((k0, 0.0, 0.0, same))
        elif kinds[k0] in ("head", "side") and obs is not None and tgt is not None:
            out.append((k0, math.radians(obs[k0]), math.radians(tgt[k0]), [k0]))
    return out


def collect(
    mb: MBase, cam: CameraModel, distances: tuple[float, ...], seed: int
) -> tuple[Samples, dict[str, float]]:
    """Samples (r_g, d_cam) per mask and recognition statistics."""
    rec = Recogniser(mb, cam)
    poses = calibration_poses(mb)
    samples: Samples = {k: [] for k in range(len(mb))}
    seen = total = 0
    sc = Scenario(robots=(RobotSpec(1, 0.0, 0.0, NORTH), RobotSpec(2, 0.0, 1.0, NORTH)), seed=seed)
    with World(sc, noise=False) as w:
        for n_done, (k0, yaw, head, same) in enumerate(poses):
            rel = float(mb.orientation[k0])
            view = NORTH + yaw
            w.set_head_yaw(2, head)
            for d in distances:
                w.set_pose(2, d * math.cos(view), d * math.sin(view), view + rel)
                total += 1
                d_cam = camera_distance(cam, d, yaw)
                seen += sample_view(rec, w.render(1, yaw), yaw, d_cam, same, samples)
            print(f"\rpose {n_done + 1}/{len(poses)}", end="", file=sys.stderr)
        w.set_head_yaw(2, 0.0)
    print(file=sys.stderr)
    return samples, {"sightings": seen, "views": total}


def calibrate(
    mb: MBase, seed: int = 0, distances: tuple[float, ...] = DISTANCES
) -> tuple[DBase, Samples, dict[str, float]]:
    cam = CameraModel()
    samples, stats = collect(mb, cam, distances, seed)
    fits = fit_all(mb, samples)
    meta = {
        "paper": "Wang et al. 2019, eq. 6 and 5.2.1",
        "distances_m": list(distances),
        "model": "d = a / (r_g + c) + b",
        "scale": SCALE,
        "distance_reference": "optical centre (head yaw 0) to the observed NAO's body centre",
        "min_samples": MIN_SAMPLES,
        "seed": seed,
        "renderer": "sim.physics.world.World (PyBullet TinyRenderer), noise off",
        **stats,
    }
    return DBase(fits, mb.digest(), meta), samples, stats


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(
        prog="python -m tools.calibrate_dbase", description=__doc__.split("\n")[0]
    )
    ap.add_argument("--mbase", type=Path, default=DATA_DIR, help="directory of mbase.npz/json")
    ap.add_argument(
        "--out", type=Path, default=None, help="output directory (default: same as --mbase)"
    )
    ap.add_argument("--png", type=Path, default=Path("out/perception/dbase.png"))
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args(argv)
    try:
        mb = MBase.load(args.mbase)
    except ValueError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    db, samples, stats = calibrate(mb, args.seed)
    print(table(mb, db.fits))
    print(f"recognised {stats['sightings']}/{stats['views']} calibration views")
    path = db.save(args.out if args.out is not None else args.mbase)
    figure(mb, db.fits, samples, args.png)
    print(f"wrote {path} and {args.png}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
