"""Check: a calibration's recall, precision and distance error on held-out views (NAO paper
5.2.1-5.2.2: the recogniser's quality before a fleet relies on it).

The ``check`` views of a capture folder were not used by the build: NAO-j at distances
and orientations between the calibration's, NAO-i's head turned a little so that NAO-j
is off the image centre, and views with nothing in sight. The detector with the
calibration (:class:`agent.core.perception.detector.Detector`) looks at each:

- a detection within ``MATCH_TOL`` (``max(0.2 m, 0.2·d)``) of NAO-j's true place is a
  true positive, any other a false positive;
- recall: the views with NAO-j in which it was found; precision: true over all
  detections;
- distance: the relative error |d̂ - d| / d of the true positives up to ``RANGE_M``, and
  the share within ``WITHIN`` (5 %).

The result is compared with floors (by default the built-in calibration's quality on its
own renders: recall and precision 0.99, 95 % of distances within 5 %); below any of them
the command fails. :func:`figure` draws the estimates against the truth.
"""

from __future__ import annotations

import json
import math
from dataclasses import asdict, dataclass, field
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from agent.core.perception.calibration import Calibration
from agent.core.perception.detector import Detector
from tools.calibrate.folder import CaptureFolder

RANGE_M = 3.0
WITHIN = 0.05


def match_tol(d: float) -> float:
    """How far a detection may be from NAO-j's true place to count as NAO-j (m)."""
    return max(0.2, 0.2 * d)


@dataclass(frozen=True)
class Floors:
    """What a calibration must reach on the held-out views."""

    recall: float = 0.99
    precision: float = 0.99
    within: float = 0.95


@dataclass
class CheckResult:
    """The counts, the rates and each true positive's (true, estimated) distance."""

    views: int = 0
    positives: int = 0
    found: int = 0
    detections: int = 0
    true_detections: int = 0
    pairs: list[tuple[float, float]] = field(default_factory=list)
    missed: list[str] = field(default_factory=list)
    false: list[str] = field(default_factory=list)

    @property
    def recall(self) -> float:
        return self.found / self.positives if self.positives else float("nan")

    @property
    def precision(self) -> float:
        return self.true_detections / self.detections if self.detections else 1.0

    @property
    def within(self) -> float:
        errs = [abs(e - d) / d for d, e in self.pairs if d <= RANGE_M]
        return float(np.mean(np.array(errs) <= WITHIN)) if errs else float("nan")

    @property
    def median_error(self) -> float:
        errs = [abs(e - d) / d for d, e in self.pairs if d <= RANGE_M]
        return float(np.median(errs)) if errs else float("nan")

    def failures(self, floors: Floors) -> list[str]:
        """The floors not reached (none: the calibration passes)."""
        out = []
        for name in ("recall", "precision", "within"):
            got, want = getattr(self, name), getattr(floors, name)
            if not got >= want:  # NaN fails too
                out.append(f"{name} {got:.3f} < {want:.3f}")
        return out

    def summary(self) -> str:
        return (
            f"recall {self.recall:.3f} ({self.found}/{self.positives}), precision "
            f"{self.precision:.3f} ({self.true_detections}/{self.detections}), distances "
            f"within {WITHIN:.0%}: {self.within:.3f} (median error {self.median_error:.2%}) "
            f"on {self.views} held-out views"
        )

    def to_dict(self) -> dict[str, object]:
        doc = asdict(self)
        doc.update(recall=self.recall, precision=self.precision, within=self.within)
        return doc


def check(calibration: Calibration, captures: Path, set_: str = "check") -> CheckResult:
    """Run the detector with ``calibration`` on the views of set ``set_`` of ``captures``."""
    cf = CaptureFolder.load(captures)
    views = cf.taken(set_)
    if not views:
        raise ValueError(f"{captures} holds no {set_!r} views to check on")
    det = Detector(calibration.mbase, calibration.dbase, orange=calibration.orange)
    out = CheckResult()
    for r in views:
        s = r.shot
        out.views += 1
        dets = det.detect(cf.image(r), math.radians(r.observer_yaw_read_deg))
        out.detections += len(dets)
        if s.kind == "none":
            out.false.extend(r.shot.id for _ in dets)
            continue
        out.positives += 1
        b = math.radians(s.bearing_deg)
        tx, ty = s.distance * math.cos(b), s.distance * math.sin(b)
        near = [
            (
                math.hypot(
                    d.distance * math.cos(d.bearing) - tx, d.distance * math.sin(d.bearing) - ty
                ),
                d,
            )
            for d in dets
        ]
        hits = sorted((e, i) for i, (e, _) in enumerate(near) if e <= match_tol(s.distance))
        if hits:
            out.found += 1
            out.true_detections += 1
            out.pairs.append((s.distance, near[hits[0][1]][1].distance))
        else:
            out.missed.append(s.id)
        out.false.extend(s.id for _ in range(len(dets) - (1 if hits else 0)))
    return out


def figure(res: CheckResult, path: Path, title: str = "") -> None:
    """Estimated against true distance, the relative error with the ±5 % band, and the
    recall per distance."""
    path.parent.mkdir(parents=True, exist_ok=True)
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(11, 4))
    p = np.array(res.pairs) if res.pairs else np.zeros((0, 2))
    if p.size:
        ax1.plot(p[:, 0], p[:, 1], "o", ms=4)
        lim = [0.0, max(3.2, float(p.max()) + 0.1)]
        ax1.plot(lim, lim, "k-", lw=0.8)
        ax2.plot(p[:, 0], 100 * (p[:, 1] - p[:, 0]) / p[:, 0], "o", ms=4)
    ax1.set_xlabel("true distance d (m)")
    ax1.set_ylabel("estimated distance (m)")
    ax1.set_title(f"recall {res.recall:.3f}, precision {res.precision:.3f}")
    ax2.axhspan(-100 * WITHIN, 100 * WITHIN, color="tab:green", alpha=0.15)
    ax2.set_xlabel("true distance d (m)")
    ax2.set_ylabel("distance error (%)")
    ax2.set_title(f"{res.within:.1%} within {WITHIN:.0%} up to {RANGE_M:g} m")
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)


def write(res: CheckResult, floors: Floors, out: Path) -> list[str]:
    """``check.json`` and ``check.png`` in ``out``; returns the floors not reached."""
    failed = res.failures(floors)
    out.mkdir(parents=True, exist_ok=True)
    doc = {"floors": asdict(floors), "failed": failed, **res.to_dict()}
    (out / "check.json").write_text(json.dumps(doc, indent=1, sort_keys=True) + "\n")
    figure(res, out / "check.png")
    return failed
