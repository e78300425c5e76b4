"""The integrated image-processing method of the NAO paper, section 3: image → neighbours.

Segmentation (3.1.1) → cylindrical resampling (camera.py) → tuples, plus the pieces of
tuples merged by overlapping NAOs (overlap.py) → recognition by the
M-base (Algorithm 1) → distance by the D-base (eq. 6, on the box height's scale) → bearing by the angle model
(eq. 3: head yaw) plus the detection's offset from the image centre. The distance and
bearing of a :class:`Detection` are of the neighbour's body centre relative to the
observer's body centre, in the observer's body frame (x forward, bearing +left), so the
camera's offset from the neck axis is accounted for. A NAO touching the left or right
image border is not reported (its box, hence its distance, would be truncated).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from agent.core.nao import HEAD_YAW_LIMIT
from agent.core.perception.camera import CameraModel
from agent.core.perception.dbase import DBase
from agent.core.perception.mbase import MBase
from agent.core.perception.overlap import split_merged
from agent.core.perception.recognition import LAMBDA_TH, Match, recognise
from agent.core.perception.segmentation import (
    ORANGE,
    OrangeRange,
    check_image,
    extract_tuples,
    orange_mask,
)

# A NAO cut by the left or right image border has a truncated box, hence a wrong r_g and
# distance: such groups are dropped (the sweep's overlapping head yaws see it whole).
BORDER_PX = 2
TWO_PI = 2.0 * math.pi


def check_view(camera: CameraModel, image_bgr: object, head_yaw: float) -> np.ndarray:
    """Validate an image of ``camera`` and a head yaw (``ValueError``); return the image."""
    img = check_image(image_bgr)
    if img.shape[:2] != (camera.height, camera.width):
        raise ValueError(
            f"image is {img.shape[1]}x{img.shape[0]}, the camera model expects "
            f"{camera.width}x{camera.height}"
        )
    if not isinstance(head_yaw, int | float) or not math.isfinite(head_yaw):
        raise ValueError(f"head yaw must be a finite number, got {head_yaw!r}")
    if abs(head_yaw) > HEAD_YAW_LIMIT + 1e-9:
        raise ValueError(f"head yaw {math.degrees(head_yaw):.1f}° outside ±119.5°")
    return img


@dataclass(frozen=True)
class Detection:
    """One recognised neighbour.

    ``distance`` (m, eq. 6 through the D-base of the matched mask) and ``bearing`` (rad,
    +left, body frame: head yaw + pixel offset) locate its body centre from the observer's
    body centre. ``orientation`` is the matched mask's relative orientation: the observed
    NAO's heading minus the line of sight to it (rad, [0, 2π)), ``scale`` is r_g, ``box`` (x, y, w, h) is in the
    input image's pixels, ``side`` marks a side-posture (2-tuple) match.
    """

    distance: float
    bearing: float
    confidence: float
    orientation: float
    scale: float
    box: tuple[int, int, int, int]
    side: bool


class Recogniser:
    """Segmentation, cylindrical resampling and Algorithm 1 on one image (no distances).

    The calibration tool uses it before a D-base exists; :class:`Detector` builds on it.
    """

    def __init__(
        self,
        mbase: MBase,
        camera: CameraModel | None = None,
        threshold: float = LAMBDA_TH,
        orange: OrangeRange = ORANGE,
    ) -> None:
        if not 0.0 < threshold <= 1.0:
            raise ValueError(f"threshold must be in (0, 1], got {threshold}")
        self.mbase = mbase
        self.camera = CameraModel() if camera is None else camera
        self.threshold = threshold
        self.orange = orange
        self._map_x, self._map_y = self.camera.cylindrical_maps()
        cam = self.camera
        self.horizon_row = cam.cy + cam.fy * math.tan(cam.pitch)

    def cylindrical(self, mask: np.ndarray) -> np.ndarray:
        """Resample a perspective binary mask to the cylindrical image (nearest pixel)."""
        return cv2.remap(mask, self._map_x, self._map_y, cv2.INTER_NEAREST)

    def check(self, image_bgr: object, head_yaw: float) -> np.ndarray:
        """Validate an image and a head yaw; return the image."""
        return check_view(self.camera, image_bgr, head_yaw)

    def matches(self, image_bgr: np.ndarray, head_yaw: float = 0.0) -> list[Match]:
        """Accepted tuple groups of one image (boxes in the cylindrical image)."""
        img = self.check(image_bgr, head_yaw)
        mask = orange_mask(img, orange=self.orange)
        if not mask.any():
            return []
        labels, tuples = extract_tuples(self.cylindrical(mask))
        p = split_merged(labels, tuples)
        return recognise(
            p.labels, p.tuples, self.mbase, self.horizon_row, self.threshold, p.atoms, p.parent
        )

    def body_column(self, m: Match) -> float:
        """The cylindrical column of the matched NAO's body centre."""
        x, _, w, _ = m.box
        return x + w / 2.0 + m.scale * float(self.mbase.centre_offset[m.mask])


class Detector:
    """Recognises NAOs in forehead-camera images and locates them (no state per call).

    M-base, D-base and orange range default to the built-in calibration; a lab's own
    come from a calibration folder (:mod:`agent.core.perception.calibration`).
    """

    def __init__(
        self,
        mbase: MBase | None = None,
        dbase: DBase | None = None,
        camera: CameraModel | None = None,
        threshold: float = LAMBDA_TH,
        orange: OrangeRange = ORANGE,
    ) -> None:
        self.mbase = MBase.load() if mbase is None else mbase
        self.dbase = DBase.load() if dbase is None else dbase
        self.camera = CameraModel() if camera is None else camera
        if len(self.dbase) != len(self.mbase):
            raise ValueError(
                f"D-base has {len(self.dbase)} entries, M-base {len(self.mbase)} masks"
            )
        if self.dbase.mbase_digest != self.mbase.digest():
            raise ValueError("the D-base was calibrated for another M-base (digest mismatch)")
        self.recogniser = Recogniser(self.mbase, self.camera, threshold, orange)

    def detect(self, image_bgr: np.ndarray, head_yaw: float) -> list[Detection]:
        """All NAOs in one BGR image taken at ``head_yaw``; sorted by bearing (left first)."""
        rec = self.recogniser
        cam = self.camera
        out = []
        for m in rec.matches(image_bgr, head_yaw):
            box = self._perspective_box(m.box)
            if box[0] < BORDER_PX or box[0] + box[2] > cam.width - BORDER_PX:
                continue
            beta = cam.cyl_bearing(rec.body_column(m))
            rd = self.dbase.group_scale(m.scale, m.box[3], float(self.mbase.sizes[m.mask, 1]))
            d_cam = self.dbase.distance(m.mask, rd)
            ox, oy = cam.body_offset(head_yaw)
            px = ox + d_cam * math.cos(head_yaw + beta)
            py = oy + d_cam * math.sin(head_yaw + beta)
            # the matched mask's orientation: the observed NAO's heading minus the line of
            # sight (mbase.py), which is what a record carries (docs/design.md §9 pose fit)
            orient = float(self.mbase.orientation[m.mask]) % TWO_PI
            out.append(
                Detection(
                    distance=math.hypot(px, py),
                    bearing=math.atan2(py, px),
                    confidence=m.confidence,
                    orientation=orient,
                    scale=m.scale,
                    box=box,
                    side=bool(self.mbase.side[m.mask]),
                )
            )
        out.sort(key=lambda d: (-d.bearing, d.distance))
        return out

    def _perspective_box(self, box: tuple[int, int, int, int]) -> tuple[int, int, int, int]:
        """Map a cylindrical-image box back to the input image's pixels."""
        cam = self.camera
        x, y, w, h = box
        us = np.array([x, x + w], dtype=np.float64)
        xs = np.tan((us - cam.cx) / cam.fx)
        u = cam.cx + cam.fx * xs
        scale = np.sqrt(1.0 + xs**2)
        v = np.array([[cam.cy + (yy - cam.cy) * s for s in scale] for yy in (y, y + h)])
        x0, x1 = math.floor(u.min()), math.ceil(u.max())
        y0, y1 = math.floor(v.min()), math.ceil(v.max())
        x0, y0 = max(0, x0), max(0, y0)
        x1, y1 = min(cam.width, x1), min(cam.height, y1)
        return x0, y0, max(1, x1 - x0), max(1, y1 - y0)
