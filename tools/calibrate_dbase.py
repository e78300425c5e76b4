"""``python -m tools.calibrate_dbase``: calibrate the distance model, build the D-base (NAO paper 5.2.1).

NAO-j is put at 37 distances 0.5-3.1 m (body centre to body centre: the paper's 20
distances 0.05 m apart up to 1.45 m, then 0.1 m apart up to 3.1 m, just past the 3 m
range) straight ahead of NAO-i for every M-base orientation (and, for the masks of turned
heads and side postures, in the pose each was rendered in); NAO-i recognises it (Algorithm 1)
and every sighting gives a sample (1/r_g, d) for the mask of that orientation and for
the mask the recogniser chose (so a mask that is picked for a neighbouring orientation
is calibrated for it too); d is from the optical centre (6.2 cm ahead of the neck axis
at head yaw 0) to NAO-j's body centre. d = a / (r_g + c) + b (eq. 6 with the pixel-rim
offset c, see ``agent/core/perception/dbase.py``; r_g measured on the box height) is fitted
per mask with scipy; Table 1 (a, b, R², RMSE per mask) is printed and a figure like the paper's
Figure 19 is written.
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from agent.core.perception.camera import CameraModel
from agent.core.perception.dbase import DBase, Fit, fit_distance_model
from agent.core.perception.detector import Recogniser
from agent.core.perception.mbase import DATA_DIR, MBase
from sim.scenarios import RobotSpec, Scenario
from sim.world import World

NORTH = math.pi / 2
DISTANCES = tuple(round(0.5 + 0.05 * i, 2) for i in range(20)) + tuple(
    round(1.5 + 0.1 * i, 2) for i in range(17)
)
MIN_SAMPLES = 3
SCALE = (
    "height"  # the D-base's scale: box height / mask height (see agent/core/perception/dbase.py)
)


def distance_scale(mb: MBase, k: int, box: tuple[int, int, int, int]) -> float:
    """The scale eq. 6 is fitted on: the group's box height over mask k's (``SCALE``)."""
    return box[3] / float(mb.sizes[k, 1])


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
) -> tuple[dict[int, list[tuple[float, float]]], dict[str, float]]:
    """Samples (r_g, d_cam) per mask and recognition statistics."""
    rec = Recogniser(mb, cam)
    poses = calibration_poses(mb)
    samples: dict[int, list[tuple[float, float]]] = {k: [] for k in range(len(mb))}
    seen = total = 0
    sc = Scenario(robots=(RobotSpec(1, 0.0, 0.0, NORTH), RobotSpec(2, 0.0, 1.0, NORTH)), seed=seed)
    with World(sc, noise=False) as w:
        for n_done, (k0, yaw, head, same) in enumerate(poses):
            rel = float(mb.orientation[k0])
            view = NORTH + yaw
            w.set_head_yaw(2, head)
            for d in distances:
                w.set_pose(2, d * math.cos(view), d * math.sin(view), view + rel)
                img = w.render(1, yaw)
                total += 1
                ms = rec.matches(img, yaw)
                if not ms:
                    continue
                m = min(ms, key=lambda m: abs(rec.body_column(m) - cam.cx))
                seen += 1
                d_cam = d - cam.cam_forward
                for k in sorted({m.mask, *same}):
                    if mb.n_tuples[k] != len(m.tuples):
                        continue
                    samples[k].append((distance_scale(mb, k, m.box), d_cam))
            print(f"\rpose {n_done + 1}/{len(poses)}", end="", file=sys.stderr)
        w.set_head_yaw(2, 0.0)
    print(file=sys.stderr)
    return samples, {"sightings": seen, "views": total}


def transfer(mb: MBase, fits: list[Fit | None]) -> list[Fit | None]:
    """Give a mask without samples the fit of the fitted mask nearest in orientation with
    the same tuple count, rescaled by their heights: r_g is measured against each mask's
    own size, so a_k = a_j · h_j / h_k and c_k = c_j · h_j / h_k (n = 0 marks a
    transferred entry)."""
    out = list(fits)
    for k, f in enumerate(fits):
        if f is not None:
            continue
        cands = [
            j
            for j, g in enumerate(fits)
            if g is not None and g.n > 0 and mb.n_tuples[j] == mb.n_tuples[k]
        ]
        if not cands:
            continue

        def gap(j: int, k: int = k) -> tuple[float, int]:
            d = abs(float(mb.orientation[j] - mb.orientation[k])) % (2 * math.pi)
            return (min(d, 2 * math.pi - d), j)

        j = min(cands, key=gap)
        g = fits[j]
        assert g is not None
        ratio = float(mb.sizes[j, 1] / mb.sizes[k, 1])
        out[k] = Fit(a=g.a * ratio, b=g.b, r2=g.r2, rmse=g.rmse, n=0, c=g.c * ratio)
    return out


def calibrate(
    mb: MBase, seed: int = 0, distances: tuple[float, ...] = DISTANCES
) -> tuple[DBase, dict[int, list[tuple[float, float]]], dict[str, float]]:
    cam = CameraModel()
    samples, stats = collect(mb, cam, distances, seed)
    fits: list[Fit | None] = []
    for k in range(len(mb)):
        s = samples[k]
        if len(s) >= MIN_SAMPLES and len({round(r, 6) for r, _ in s}) >= 3:
            arr = np.array(s)
            fits.append(fit_distance_model(arr[:, 0], arr[:, 1]))
        else:
            fits.append(None)
    fits = transfer(mb, fits)
    meta = {
        "paper": "Wang et al. 2019, eq. 6 and 5.2.1",
        "distances_m": list(distances),
        "model": "d = a / (r_g + c) + b",
        "scale": SCALE,
        "distance_reference": "optical centre (head yaw 0) to the observed NAO's body centre",
        "min_samples": MIN_SAMPLES,
        "seed": seed,
        "renderer": "sim.world.World (PyBullet TinyRenderer), noise off",
        **stats,
    }
    return DBase(fits, mb.digest(), meta), samples, stats


def table(mb: MBase, db: DBase) -> str:
    kinds = mb.meta.get("kinds", ["main"] * len(mb))
    lines = [
        "Table 1  D-base: d = a / (r_g + c) + b per mask",
        f"{'θ°':>6} {'kind':>8} {'n':>3} {'a':>8} {'b':>8} {'c':>8} {'R²':>7} {'RMSE m':>7}",
    ]
    for k, f in enumerate(db.fits):
        th = math.degrees(float(mb.orientation[k]))
        if f is None:
            lines.append(f"{th:6.1f} {kinds[k]:>8} {0:3d} {'(median fallback)':>42}")
        elif f.n == 0:
            lines.append(
                f"{th:6.1f} {kinds[k]:>8} {'-':>3} {f.a:8.4f} {f.b:8.4f} {f.c:8.4f} "
                f"{'(transferred)':>15}"
            )
        else:
            lines.append(
                f"{th:6.1f} {kinds[k]:>8} {f.n:3d} {f.a:8.4f} {f.b:8.4f} {f.c:8.4f} "
                f"{f.r2:7.4f} {f.rmse:7.4f}"
            )
    good = [f for f in db.fits if f is not None and f.n > 0]
    lines.append(
        f"fitted {len(good)}/{len(db.fits)} masks; R² median {np.median([f.r2 for f in good]):.4f} "
        f"min {min(f.r2 for f in good):.4f}; RMSE median {np.median([f.rmse for f in good]):.4f} m "
        f"max {max(f.rmse for f in good):.4f} m; a median {np.median([f.a for f in good]):.3f}, "
        f"b median {np.median([f.b for f in good]):.3f}, c median {np.median([f.c for f in good]):.4f}"
    )
    return "\n".join(lines)


def figure(mb: MBase, db: DBase, samples: dict[int, list[tuple[float, float]]], path: Path) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(11, 4))
    k180 = int(np.argmin(np.abs(mb.orientation - math.pi)))
    s = np.array(samples[k180]) if samples[k180] else np.zeros((0, 2))
    f = db.coefficients(k180)
    if s.size:
        x = 1.0 / s[:, 0]
        ax1.plot(x, s[:, 1], "o", label="samples")
        xx = np.linspace(x.min(), x.max(), 50)
        ax1.plot(
            xx,
            f.a / (1.0 / xx + f.c) + f.b,
            "-",
            label=f"d = {f.a:.3f}/(r_g {f.c:+.4f}) + {f.b:.3f}",
        )
    ax1.set_xlabel("1 / r_g")
    ax1.set_ylabel("d (m, from the optical centre)")
    ax1.set_title("Distance model, θ = 180° (cf. paper Fig. 19)")
    ax1.legend()
    th = np.degrees(mb.orientation)
    a = [db.coefficients(k).a for k in range(len(mb))]
    b = [db.coefficients(k).b for k in range(len(mb))]
    ax2.plot(th, a, "o", label="a")
    ax2.plot(th, b, "s", label="b")
    ax2.set_xlabel("mask orientation θ (deg)")
    ax2.set_title("D-base coefficients")
    ax2.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)


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
    print(table(mb, db))
    print(f"recognised {stats['sightings']}/{stats['views']} calibration views")
    path = db.save(args.out if args.out is not None else args.mbase)
    figure(mb, db, samples, args.png)
    print(f"wrote {path} and {args.png}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
