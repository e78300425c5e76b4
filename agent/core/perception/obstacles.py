"""Perceived static obstacles (NAO paper 5.1.2): rose cylinders → distance and bearing.

The paper plans around obstacles whose positions are known; here each robot measures
them with its forehead camera, in the images of its search sweep. Obstacles are upright
cylinders of one distinctive colour and a known radius (:mod:`agent.core.nao`:
``OBSTACLE_HSV_LO``/``HI``, ``OBSTACLE_RADIUS``). Per image:

1. **Segmentation.** HSV threshold in the obstacle range, Gaussian blur before and a
   closing then opening after (as for the NAO orange, 3.1.1).
2. **Runs.** Per image column, the lowest obstacle pixel (the silhouette's bottom).
   Columns of one connected component are cut into *runs* where the bottom jumps by more
   than ``JUMP_PX``: two cylinders one behind the other (the nearer one's bottom is
   lower). A run's edge is *true* unless it touches the image border or a nearer run.
3. **Distance.** When the bottom is inside the image, its lowest pixel is the base
   circle's point nearest the camera: its ray, cut with the floor (camera height and
   pitch of :class:`CameraModel`), gives the ground distance ``g`` of that point, and the
   axis is ``g + r`` away (accurate to ~1 % at 3 m). When the bottom is below the image
   (a near cylinder), the angular width ``w`` between two true edges gives it:
   ``r / sin(w / 2)``.
   A run whose top stays below the horizon is flat and not reported
   (:data:`UPRIGHT_TOL_PX`): cylinders are taller than the camera.
4. **Bearing.** The middle of two true edges; with one true edge, that edge moved by the
   half-width ``asin(r / D)`` inwards. With the bottom in view, an edge is true only
   where the base ellipse's bottom has risen as it does at a silhouette's side (a NAO
   in front cuts the run where the bottom is still low). A run with no true edge, with no bottom and not
   two true edges, or whose two edges are not as far apart as ``D`` says (a NAO in front
   hides one of them, which the mask cannot show) is not reported: the sweep's other
   images and the other robots see that cylinder too.

Like :class:`~agent.core.perception.detector.Detection`, an :class:`ObstacleDetection` is the
cylinder's axis relative to the observer's body centre, in its body frame (x forward,
bearing +left), so :func:`agent.core.perception.localise.to_fixed_frame` takes it as is.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass

import cv2
import numpy as np

from agent.core import nao
from agent.core.perception.camera import CameraModel
from agent.core.perception.detector import check_view

#: A bottom jump (px) between adjacent columns above this separates two cylinders. One
#: cylinder's own bottom edge (an ellipse) rises by less between neighbouring columns
#: while its bottom is inside the image (farther than ~1.15 m).
JUMP_PX = 8
#: Columns narrower than this, or components smaller than MIN_AREA px, are noise.
MIN_WIDTH_PX = 4
MIN_AREA = 60
#: Farthest reported obstacle (m): beyond it a pixel is more than 3 % of the distance.
MAX_RANGE = 3.5
#: Two true edges must be as far apart as the distance says, within this many pixels
#: or 50 % of the half-width; else an edge is hidden (by a NAO) and the run is dropped.
WIDTH_TOL_PX = 4.0
#: With its bottom in view, a true edge is where the base ellipse's bottom has risen by
#: at least RISE_FRACTION of its minor half-axis (tested when that is MIN_RISE_PX or more).
RISE_FRACTION = 0.35
MIN_RISE_PX = 3.0
BLUR = 3
MORPH = 5
#: A cylinder is taller than the camera (``nao.OBSTACLE_HEIGHT`` > camera height), so its
#: silhouette reaches the horizon at any distance; a run whose top stays more than this
#: many pixels below the horizon is flat (50 NAOs, seed 12: rose-ish floor letters, lit
#: into the obstacle range, gave 14 robots phantom obstacles and a plan out of the room).
UPRIGHT_TOL_PX = 3.0


@dataclass(frozen=True)
class ObstacleDetection:
    """One cylinder: its axis at ``distance`` (m) and ``bearing`` (rad, +left) from the
    observer's body centre; ``box`` (x, y, w, h) is the run in image pixels and
    ``by_width`` tells that the distance came from the width (bottom below the image)."""

    distance: float
    bearing: float
    box: tuple[int, int, int, int]
    by_width: bool


def obstacle_mask(image_bgr: np.ndarray) -> np.ndarray:
    """Binary (0/255) mask of obstacle-coloured pixels after blur, closing and opening."""
    img = cv2.GaussianBlur(image_bgr, (BLUR, BLUR), 0)
    hsv = cv2.cvtColor(img, cv2.COLOR_BGR2HSV)
    lo, hi = np.array(nao.OBSTACLE_HSV_LO, np.uint8), np.array(nao.OBSTACLE_HSV_HI, np.uint8)
    mask = cv2.inRange(hsv, lo, hi)
    k = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (MORPH, MORPH))
    mask = cv2.morphologyEx(mask, cv2.MORPH_CLOSE, k)
    return cv2.morphologyEx(mask, cv2.MORPH_OPEN, k)


@dataclass(frozen=True)
class _Run:
    c0: int  # first column
    c1: int  # last column (inclusive)
    bottom: np.ndarray  # lowest mask row per column
    top: int


def _runs(mask: np.ndarray) -> list[tuple[_Run, bool, bool]]:
    """Runs of every component with flags (left edge true, right edge true)."""
    h, w = mask.shape
    n, labels, stats, _ = cv2.connectedComponentsWithStats(
        (mask > 0).astype(np.uint8), connectivity=8
    )
    rows = np.arange(h)[:, None]
    out: list[tuple[_Run, bool, bool]] = []
    for lab in range(1, n):
        if stats[lab, cv2.CC_STAT_AREA] < MIN_AREA:
            continue
        x0 = int(stats[lab, cv2.CC_STAT_LEFT])
        x1 = x0 + int(stats[lab, cv2.CC_STAT_WIDTH]) - 1
        sub = labels[:, x0 : x1 + 1] == lab
        has = sub.any(axis=0)
        bottom = np.where(sub, rows, -1).max(axis=0)
        top = np.where(sub, rows, h).min(axis=0)
        # cut at empty columns and at bottom jumps
        cuts = [0]
        for c in range(1, sub.shape[1]):
            if has[c] != has[c - 1] or (
                has[c] and abs(int(bottom[c]) - int(bottom[c - 1])) > JUMP_PX
            ):
                cuts.append(c)
        cuts.append(sub.shape[1])
        pieces = [(a, b) for a, b in itertools.pairwise(cuts) if has[a]]
        for k, (a, b) in enumerate(pieces):
            run = _Run(x0 + a, x0 + b - 1, bottom[a:b].copy(), int(top[a:b].min()))
            # an edge is false at the image border or against a nearer (lower) run
            left = run.c0 > 0 and not (
                k > 0 and pieces[k - 1][1] == a and bottom[a - 1] > bottom[a]
            )
            right = run.c1 < w - 1 and not (
                k + 1 < len(pieces) and pieces[k + 1][0] == b and bottom[b] > bottom[b - 1]
            )
            out.append((run, left, right))
    return out


def _ground_distance(cam: CameraModel, u: float, v: float) -> float | None:
    """Horizontal distance (m) from the optical centre to the floor point seen at (u, v)."""
    xc = (u - cam.cx) / cam.fx
    yc = (v - cam.cy) / cam.fy  # + down
    down = -cam.pitch
    sp, cp = math.sin(down), math.cos(down)
    fall = sp + yc * cp  # downward component of the ray (fwd, left, up) per unit depth
    if fall <= 1e-6:
        return None  # at or above the horizon
    t = cam.height_m / fall
    return t * math.hypot(cp - yc * sp, xc)


def horizon_row(cam: CameraModel) -> float:
    """Image row (px, down) of the horizon: rays at the camera's height."""
    return float(cam.cy - cam.fy * math.tan(-cam.pitch))


class ObstacleDetector:
    """Finds the obstacle cylinders in forehead images (no state per call)."""

    def __init__(self, camera: CameraModel | None = None, radius: float = nao.OBSTACLE_RADIUS):
        if not (math.isfinite(radius) and radius > 0):
            raise ValueError(f"obstacle radius must be a finite distance > 0, got {radius!r}")
        self.camera = CameraModel() if camera is None else camera
        self.radius = float(radius)

    def detect(self, image_bgr: np.ndarray, head_yaw: float) -> list[ObstacleDetection]:
        """All obstacles in one BGR image taken at ``head_yaw``; sorted by bearing (left first)."""
        cam = self.camera
        img = check_view(cam, image_bgr, head_yaw)
        mask = obstacle_mask(img)
        out = []
        for run, left, right in _runs(mask):
            found = self._locate(run, left, right, cam.height)
            if found is None:
                continue
            d_cam, b_cam, by_width = found
            if d_cam > MAX_RANGE:
                continue
            ox, oy = cam.body_offset(head_yaw)
            px = ox + d_cam * math.cos(head_yaw + b_cam)
            py = oy + d_cam * math.sin(head_yaw + b_cam)
            top = run.top
            box = (run.c0, top, run.c1 - run.c0 + 1, int(run.bottom.max()) - top + 1)
            out.append(ObstacleDetection(math.hypot(px, py), math.atan2(py, px), box, by_width))
        out.sort(key=lambda d: (-d.bearing, d.distance))
        return out

    def _locate(
        self, run: _Run, left: bool, right: bool, height: int
    ) -> tuple[float, float, bool] | None:
        """(distance of the axis from the optical centre, its bearing, by width) or None."""
        cam = self.camera
        if run.c1 - run.c0 + 1 < MIN_WIDTH_PX or not (left or right):
            return None
        if run.top > horizon_row(cam) + UPRIGHT_TOL_PX:
            return None  # flat: a rose patch on the floor, not a cylinder taller than the camera
        # angles (+left) of the run's outer pixel edges
        b_left = cam.pixel_bearing(float(run.c0))
        b_right = cam.pixel_bearing(float(run.c1 + 1))
        low = int(run.bottom.max())
        d_cam: float | None = None
        by_width = low >= height - 1
        if not by_width:
            cols = np.flatnonzero(run.bottom == low)
            u = run.c0 + (float(cols[0]) + float(cols[-1])) / 2.0 + 0.5
            g = _ground_distance(cam, u, low + 1.0)
            if g is None:
                return None
            d_cam = g + self.radius
        elif left and right:
            half = (b_left - b_right) / 2.0
            if half <= 0:
                return None
            d_cam = self.radius / math.sin(half)
        if d_cam is None:
            return None
        half = math.asin(min(1.0, self.radius / d_cam))
        if not by_width:
            # the base is an ellipse: at a true edge its bottom has risen by about its
            # minor half-axis; a NAO in front cuts the run where the bottom is still low
            rise = half * cam.fx * math.sin(math.atan2(cam.height_m, d_cam))
            if rise >= MIN_RISE_PX:
                left = left and low - int(run.bottom[0]) >= RISE_FRACTION * rise
                right = right and low - int(run.bottom[-1]) >= RISE_FRACTION * rise
                if not (left or right):
                    return None
        if left and right:
            # a NAO in front hides an edge without a trace in the mask: the width tells
            if abs((b_left - b_right) - 2.0 * half) * cam.fx > max(WIDTH_TOL_PX, half * cam.fx):
                return None
            bearing = (b_left + b_right) / 2.0
        else:
            bearing = b_left - half if left else b_right + half
        return d_cam, bearing, by_width
