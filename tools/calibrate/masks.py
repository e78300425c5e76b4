"""The M-base from camera images, cut the paper's way (NAO paper 3.1.2 and 5.2.2 (i)).

One forehead image per view of a lone NAO-j at d_s (0.6 m) straight along NAO-i's camera
axis: segmented with the orange range (3.1.1), resampled to the cylindrical image
(``agent/core/perception/camera.py``) and cut to the box of its head cap and shoulder
covers (:func:`agent.core.perception.mbase.cut_mask`). Views come in three kinds:

- ``main``: head yaws 0, NAO-j turned through the orientations (the paper's 72, 5° apart);
  an orientation whose far shoulder is only a sliver (below ``SLIVER`` of the mask's
  area) also gets a ``reduced`` mask without it, the look of that NAO farther away;
- ``head``: NAO-j with its own head turned (neighbours sweep their heads too);
- ``side``: NAO-i's head at ±90° and NAO-j side-on (the paper's Figure 20 set-up).

The images may be renders (``python -m tools.build_mbase``) or a lab's captures
(``python -m tools.calibrate build``): the builder only sees pixels. With ``window_m``
only the orange within that half-width (m, at d_s) of the image centre counts, so
something orange at the edge of a real picture does not enter a mask.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np

from agent.core.perception.camera import CameraModel
from agent.core.perception.mbase import CANON_H, CANON_W, MBase, cut_mask
from agent.core.perception.segmentation import ORANGE, OrangeRange, extract_tuples, orange_mask

SLIVER = 0.12  # a tuple below this share of the mask's area may vanish with distance
KINDS = ("main", "reduced", "head", "side")


@dataclass(frozen=True)
class MaskView:
    """One image for the M-base: NAO-j at orientation ``orientation`` (rad, its heading
    minus NAO-i's viewing direction), the two head yaws (deg) it was taken with."""

    image: np.ndarray
    orientation: float
    kind: str = "main"
    observer_yaw_deg: float = 0.0
    subject_yaw_deg: float = 0.0


class MBaseBuilder:
    """Cuts masks from views, in the order they are added (the M-base's mask order)."""

    def __init__(
        self,
        camera: CameraModel | None = None,
        orange: OrangeRange = ORANGE,
        distance: float = 0.6,
        window_m: float | None = None,
    ) -> None:
        self.camera = CameraModel() if camera is None else camera
        self.orange = orange
        self.distance = distance
        cam = self.camera
        self.horizon = cam.cy + cam.fy * math.tan(cam.pitch)
        self._mx, self._my = cam.cylindrical_maps()
        self._half_px = (
            None if window_m is None else cam.fx * math.atan(window_m / max(distance, 1e-6))
        )
        self.masks: list[np.ndarray] = []
        self.orient: list[float] = []
        self.side: list[bool] = []
        self.ntup: list[int] = []
        self.tops: list[float] = []
        self.cents: list[float] = []
        self.kinds: list[str] = []
        self.poses: list[tuple[float, float]] = []  # (observer head yaw, observed head yaw)

    def cylindrical(self, image: np.ndarray) -> np.ndarray:
        """The orange of ``image`` in the cylindrical image, outside the window cleared."""
        cyl = cv2.remap(
            orange_mask(image, orange=self.orange), self._mx, self._my, cv2.INTER_NEAREST
        )
        if self._half_px is not None:
            c = self.camera.cx
            lo, hi = max(0, math.floor(c - self._half_px)), math.ceil(c + self._half_px)
            cyl[:, :lo] = 0
            cyl[:, hi:] = 0
        return cyl

    def _add(self, cyl: np.ndarray, rel: float, kind: str, drop: bool, pose: tuple) -> None:
        cut = cut_mask(cyl, self.horizon, self.camera.cx, drop_smallest=drop)
        self.masks.append(cut.crop)
        self.orient.append(rel % (2 * math.pi))
        self.ntup.append(cut.n_tuples)
        self.side.append(kind == "side" or (kind == "main" and cut.n_tuples == 2))
        self.tops.append(cut.top_offset)
        self.cents.append(cut.centre_offset)
        self.kinds.append(kind)
        self.poses.append(pose)

    def add(self, view: MaskView) -> int:
        """Cut the view's mask (and a ``reduced`` one for a main view with a sliver);
        returns how many masks were added. ``ValueError`` when no NAO is in the window."""
        if view.kind not in ("main", "head", "side"):
            raise ValueError(f"view kind {view.kind!r} is not main, head or side")
        cyl = self.cylindrical(view.image)
        pose = (float(view.observer_yaw_deg), float(view.subject_yaw_deg))
        self._add(cyl, view.orientation, view.kind, False, pose)
        if view.kind != "main":
            return 1
        _, tuples = extract_tuples(cyl)
        areas = sorted(t.area for t in tuples)
        if len(areas) >= 3 and areas[0] < SLIVER * sum(areas):
            self._add(cyl, view.orientation, "reduced", True, pose)
            return 2
        return 1

    def meta(self) -> dict[str, Any]:
        """What every M-base built this way records (the caller adds its source)."""
        cam = self.camera
        return {
            "paper": "Wang et al. 2019, 3.1.2 and 5.2.2 (i)",
            "distance_m": self.distance,
            "head_yaw_deg": 0.0,
            "sliver_share": SLIVER,
            "hsv_low": list(self.orange.low),
            "hsv_high": list(self.orange.high),
            "canonical_size": [CANON_W, CANON_H],
            "image": "cylindrical resampling of the 640x480 forehead camera (camera.py)",
            "camera": {
                "hfov_deg": math.degrees(cam.hfov),
                "height_m": cam.height_m,
                "pitch_deg": math.degrees(cam.pitch),
            },
            "kinds": list(self.kinds),
            # per mask, for the D-base calibration: the observer's and the observed NAO's
            # head yaw (deg) when it was taken
            "observer_head_yaw_deg": [p[0] for p in self.poses],
            "observed_head_yaw_deg": [p[1] for p in self.poses],
        }

    def build(self, meta: dict[str, Any] | None = None) -> MBase:
        """The M-base of the masks cut so far, with :meth:`meta` and ``meta``."""
        if not self.masks:
            raise ValueError("no masks: add views first")
        doc = self.meta()
        doc.update(meta or {})
        return MBase(
            self.masks,
            np.asarray(self.orient),
            np.asarray(self.side),
            np.asarray(self.ntup),
            np.asarray(self.tops),
            np.asarray(self.cents),
            doc,
        )
