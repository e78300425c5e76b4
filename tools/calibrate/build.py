"""Build: a calibration folder from a capture folder (NAO paper 3.1.1, 3.1.2, eq. 6, 5.2.1).

1. the orange range from the M-base views (:mod:`tools.calibrate.orange`), histogram drawn;
2. the M-base: the M-base views cut the paper's way with that range
   (:class:`tools.calibrate.masks.MBaseBuilder`), main views in orientation order, then the
   turned heads, then the side postures, as ``python -m tools.build_mbase`` orders them;
3. the D-base: every M-base and D-base view recognised with that M-base and range, eq. 6
   fitted per mask (:mod:`tools.calibrate.distances`), Table 1 and a figure like Figure 19;
4. the folder (:mod:`agent.core.perception.calibration`): the M-base, D-base and orange
   files and the manifest with the digest, where the views came from and how well eq. 6
   fits; the figures and Table 1 in its ``report/``.
"""

from __future__ import annotations

import math
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Any, TextIO

from agent.core.perception.calibration import Calibration, camera_params
from agent.core.perception.camera import CameraModel
from agent.core.perception.dbase import DBase
from agent.core.perception.detector import Recogniser
from tools.calibrate import distances, masks, orange
from tools.calibrate.folder import CaptureFolder, ShotRecord

REPORT = "report"
KIND_ORDER = {"main": 0, "head": 1, "side": 2}


@dataclass(frozen=True)
class Built:
    """A built calibration, the folder it is in, and what the build measured."""

    calibration: Calibration
    path: Path
    digest: str
    table: str
    views: int
    seen: int


def mask_order(r: ShotRecord) -> tuple[Any, ...]:
    """The M-base's order: main views by orientation, turned heads by orientation and head
    yaw, side postures NAO-i's head left first, then by orientation."""
    s = r.shot
    side = -s.observer_yaw_deg if s.kind == "side" else 0.0
    return (KIND_ORDER[s.kind], side, s.orientation_deg % 360.0, s.subject_yaw_deg, s.id)


def build(captures: Path, out: Path, stream: TextIO | None = None) -> Built:
    """Build the calibration of the capture folder ``captures`` into the folder ``out``."""
    log = stream if stream is not None else sys.stderr
    cf = CaptureFolder.load(captures)
    cam = CameraModel()
    if cf.header.get("camera") != camera_params(cam):
        raise ValueError(f"{captures} was captured with another camera model than the agent's")
    spec = cf.spec
    views = [r for r in cf.taken("mbase") if r.shot.kind in KIND_ORDER]
    if not views:
        raise ValueError(f"{captures} holds no M-base views: capture first")
    report = Path(out) / REPORT
    fit = orange.learn_orange([cf.image(r) for r in views if r.shot.kind == "main"], spec.d_s, cam)
    orange.figure(fit, report / "orange.png")
    o = fit.orange
    print(
        f"orange range: H {o.low[0]}-{o.high[0]}, S {o.low[1]}-{o.high[1]}, "
        f"V {o.low[2]}-{o.high[2]}; it keeps {100 * fit.kept:.1f} % of the caps' pixels and "
        f"{fit.background_share:.1e} of the background",
        file=log,
    )
    builder = masks.MBaseBuilder(cam, o, spec.d_s, window_m=orange.HALF_WIDTH)
    for r in sorted(views, key=mask_order):
        # labelled with the planned orientation: NAO-j turned to within the capture's
        # tolerance of it (the measured one is in the capture's manifest)
        view = masks.MaskView(
            cf.image(r),
            math.radians(r.shot.orientation_deg),
            r.shot.kind,
            r.shot.observer_yaw_deg,
            r.shot.subject_yaw_deg,
        )
        try:
            builder.add(view)
        except ValueError as exc:
            raise ValueError(f"{cf.path / r.file}: {exc}") from None
    source = {"captures": str(Path(captures).resolve()), "robots": cf.header.get("robots")}
    mb = builder.build({"step_deg": spec.step_deg, "source": source})
    rec = Recogniser(mb, cam, orange=o)
    samples: distances.Samples = {}
    seen = 0
    dviews = [r for r in cf.taken() if r.shot.set in ("mbase", "dbase") and r.shot.kind != "none"]
    for r in dviews:
        s = r.shot
        yaw = math.radians(s.observer_yaw_deg)
        d_cam = distances.camera_distance(cam, s.distance, yaw, math.radians(s.bearing_deg))
        same = distances.masks_of_view(
            mb, math.radians(s.orientation_deg), s.kind, s.observer_yaw_deg, s.subject_yaw_deg
        )
        seen += distances.sample_view(rec, cf.image(r), yaw, d_cam, same, samples)
    fits = distances.fit_all(mb, samples)
    quality = distances.quality(fits)
    db = DBase(
        fits,
        mb.digest(),
        {
            "paper": "Wang et al. 2019, eq. 6 and 5.2.1",
            "distances_m": sorted({r.shot.distance for r in dviews}),
            "model": "d = a / (r_g + c) + b",
            "scale": distances.SCALE,
            "distance_reference": "optical centre to the observed NAO's body centre",
            "min_samples": distances.MIN_SAMPLES,
            "source": source,
            "sightings": seen,
            "views": len(dviews),
        },
    )
    table = distances.table(mb, fits)
    report.mkdir(parents=True, exist_ok=True)
    (report / "table1.txt").write_text(table + "\n")
    distances.figure(mb, fits, samples, report / "dbase.png")
    cal = Calibration(mb, db, o, str(out))
    meta = {
        "paper": "Wang et al. 2019, 3.1.1, 3.1.2, eq. 6 and 5.2.1",
        "camera": camera_params(cam),
        "captures": source,
        "plan": spec.to_dict(),
        "look": cf.header.get("look", ""),
        "masks": len(mb),
        "dbase": {
            "fitted": quality.fitted,
            "r2_median": round(quality.r2_median, 6),
            "r2_min": round(quality.r2_min, 6),
            "rmse_median_m": round(quality.rmse_median, 6),
            "rmse_max_m": round(quality.rmse_max, 6),
            "sightings": seen,
            "views": len(dviews),
        },
        "orange": {
            "peak_hue": fit.peak_hue,
            "background_share": fit.background_share,
            "caps_kept": round(fit.kept, 4),
        },
        "report": [f"{REPORT}/orange.png", f"{REPORT}/dbase.png", f"{REPORT}/table1.txt"],
    }
    digest = cal.save(Path(out), meta)
    print(table, file=log)
    print(
        f"recognised NAO-j in {seen}/{len(dviews)} views; calibration {digest[:16]} in {out}",
        file=log,
    )
    return Built(cal, Path(out), digest, table, len(dviews), seen)
