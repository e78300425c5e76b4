"""The D-base from camera images: eq. 6 fitted per mask (NAO paper 3.2.3 eq. 6, 5.2.1,
Table 1, Figure 19).

NAO-j stands at known distances straight along NAO-i's camera axis, at the orientations
(and head yaws, postures) of the M-base's masks. NAO-i recognises it (Algorithm 1) and
every sighting gives a sample (r_g, d) for the mask of that view and for the mask the
recogniser chose (so a mask picked for a neighbouring orientation is calibrated for it
too); d runs from the optical centre to NAO-j's body centre. d = a / (r_g + c) + b (eq. 6
with the pixel-rim offset c, ``agent/core/perception/dbase.py``; r_g measured on the box
height) is fitted per mask with scipy; a mask without samples takes its nearest fitted
neighbour's fit (:func:`transfer`). :func:`table` prints Table 1's columns, :func:`figure`
draws Figure 19's.

The images may be renders (``python -m tools.calibrate_dbase``) or a lab's captures
(``python -m tools.calibrate build``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from agent.core.perception.camera import CameraModel
from agent.core.perception.dbase import Fit, fit_distance_model
from agent.core.perception.detector import Recogniser
from agent.core.perception.mbase import MBase

#: NAO-j's distances (body centre to body centre): the paper's 20, 0.05 m apart up to
#: 1.45 m, then 0.1 m apart up to 3.1 m, just past the 3 m range
DISTANCES = tuple(round(0.5 + 0.05 * i, 2) for i in range(20)) + tuple(
    round(1.5 + 0.1 * i, 2) for i in range(17)
)
MIN_SAMPLES = 3
SCALE = "height"  # the D-base's scale: box height / mask height (agent/core/perception/dbase.py)

Samples = dict[int, list[tuple[float, float]]]


def distance_scale(mb: MBase, k: int, box: tuple[int, int, int, int]) -> float:
    """The scale eq. 6 is fitted on: the group's box height over mask k's (``SCALE``)."""
    return box[3] / float(mb.sizes[k, 1])


def camera_distance(
    cam: CameraModel, distance: float, yaw: float, bearing: float | None = None
) -> float:
    """From the optical centre (head at ``yaw``) to a NAO whose body centre is
    ``distance`` m from the observer's at ``bearing`` (default: along the camera axis)."""
    b = yaw if bearing is None else bearing
    ox, oy = cam.body_offset(yaw)
    return math.hypot(distance * math.cos(b) - ox, distance * math.sin(b) - oy)


def masks_of_view(
    mb: MBase, orientation: float, kind: str, observer_yaw_deg: float, subject_yaw_deg: float
) -> list[int]:
    """The masks cut from (or for) a view of this pose: a main view's main and reduced
    masks of its orientation; a head or side view's mask of its orientation and head yaws
    (when the M-base records them)."""
    kinds = mb.meta.get("kinds", ["main"] * len(mb))
    obs = mb.meta.get("observer_head_yaw_deg", [0.0] * len(mb))
    tgt = mb.meta.get("observed_head_yaw_deg", [0.0] * len(mb))
    rel = orientation % (2 * math.pi)
    out = []
    for k in range(len(mb)):
        d = abs(float(mb.orientation[k]) - rel) % (2 * math.pi)
        if min(d, 2 * math.pi - d) > 1e-6:
            continue
        main = kind == "main" and kinds[k] in ("main", "reduced")
        posed = (
            kind in ("head", "side")
            and kinds[k] == kind
            and abs(obs[k] - observer_yaw_deg) < 1e-6
            and abs(tgt[k] - subject_yaw_deg) < 1e-6
        )
        if main or posed:
            out.append(k)
    return out


def sample_view(
    rec: Recogniser,
    image: np.ndarray,
    yaw: float,
    d_cam: float,
    same: list[int],
    samples: Samples,
) -> bool:
    """Recognise NAO-j in one image (the match nearest the image centre) and add its
    samples to the masks ``same`` and to the matched one; False when it was not seen."""
    mb, cam = rec.mbase, rec.camera
    ms = rec.matches(image, yaw)
    if not ms:
        return False
    m = min(ms, key=lambda m: abs(rec.body_column(m) - cam.cx))
    for k in sorted({m.mask, *same}):
        if mb.n_tuples[k] != len(m.tuples):
            continue
        samples.setdefault(k, []).append((distance_scale(mb, k, m.box), d_cam))
    return True


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


def fit_all(mb: MBase, samples: Samples) -> list[Fit | None]:
    """Eq. 6 per mask with at least ``MIN_SAMPLES`` samples of 3 distinct scales, then
    :func:`transfer` for the others."""
    fits: list[Fit | None] = []
    for k in range(len(mb)):
        s = samples.get(k, [])
        if len(s) >= MIN_SAMPLES and len({round(r, 6) for r, _ in s}) >= 3:
            arr = np.array(s)
            fits.append(fit_distance_model(arr[:, 0], arr[:, 1]))
        else:
            fits.append(None)
    return transfer(mb, fits)


@dataclass(frozen=True)
class Quality:
    """Table 1's summary: masks fitted, R² and RMSE over them, median coefficients."""

    fitted: int
    total: int
    r2_median: float
    r2_min: float
    rmse_median: float
    rmse_max: float


def quality(fits: list[Fit | None]) -> Quality:
    good = [f for f in fits if f is not None and f.n > 0]
    if not good:
        raise ValueError("no mask was fitted: NAO-j was never recognised at 3 distances")
    return Quality(
        fitted=len(good),
        total=len(fits),
        r2_median=float(np.median([f.r2 for f in good])),
        r2_min=min(f.r2 for f in good),
        rmse_median=float(np.median([f.rmse for f in good])),
        rmse_max=max(f.rmse for f in good),
    )


def table(mb: MBase, fits: list[Fit | None]) -> str:
    """Table 1 of the paper: a, b (and c), R² and RMSE per mask."""
    kinds = mb.meta.get("kinds", ["main"] * len(mb))
    lines = [
        "Table 1  D-base: d = a / (r_g + c) + b per mask",
        f"{'θ°':>6} {'kind':>8} {'n':>3} {'a':>8} {'b':>8} {'c':>8} {'R²':>7} {'RMSE m':>7}",
    ]
    for k, f in enumerate(fits):
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
    good = [f for f in fits if f is not None and f.n > 0]
    q = quality(fits)
    lines.append(
        f"fitted {q.fitted}/{q.total} masks; R² median {q.r2_median:.4f} min {q.r2_min:.4f}; "
        f"RMSE median {q.rmse_median:.4f} m max {q.rmse_max:.4f} m; "
        f"a median {np.median([f.a for f in good]):.3f}, "
        f"b median {np.median([f.b for f in good]):.3f}, "
        f"c median {np.median([f.c for f in good]):.4f}"
    )
    return "\n".join(lines)


def figure(mb: MBase, fits: list[Fit | None], samples: Samples, path: Path) -> None:
    """Figure 19's kind: the samples and fit of the mask nearest θ = 180°, and a, b per
    mask."""
    path.parent.mkdir(parents=True, exist_ok=True)
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(11, 4))
    k180 = int(np.argmin(np.abs(mb.orientation - math.pi)))
    s = np.array(samples.get(k180, [])) if samples.get(k180) else np.zeros((0, 2))
    f = fits[k180]
    if s.size and f is not None:
        x = 1.0 / s[:, 0]
        ax1.plot(x, s[:, 1], "o", label="samples")
        xx = np.linspace(x.min(), x.max(), 50)
        ax1.plot(
            xx,
            f.a / (1.0 / xx + f.c) + f.b,
            "-",
            label=f"d = {f.a:.3f}/(r_g {f.c:+.4f}) + {f.b:.3f}",
        )
        ax1.legend()
    th = math.degrees(float(mb.orientation[k180]))
    ax1.set_xlabel("1 / r_g")
    ax1.set_ylabel("d (m, from the optical centre)")
    ax1.set_title(f"Distance model, θ = {th:.0f}° (cf. paper Fig. 19)")
    pts = [(math.degrees(float(mb.orientation[k])), g) for k, g in enumerate(fits) if g]
    ax2.plot([p[0] for p in pts], [p[1].a for p in pts], "o", label="a")
    ax2.plot([p[0] for p in pts], [p[1].b for p in pts], "s", label="b")
    ax2.set_xlabel("mask orientation θ (deg)")
    ax2.set_title("D-base coefficients")
    ax2.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)
