"""The visual compass: heading change between two images (NAO paper 3.2.1, eq. 2, 5.2.2 (ii)).

Like NAOqi's ALVisualCompass, it matches features (ORB) between the image before and
after a turn and reports the quality of the match (number of matches, inliers, inlier
ratio). Both images are resampled to the cylindrical image (camera.py), where a turn of
the body about the vertical axis is a horizontal shift of f_x·Δθ pixels, so every match
votes for one Δθ. A deterministic one-parameter RANSAC (every match is a hypothesis;
the one with most inliers within ``tol`` wins, ties to the smaller angle magnitude, then
to the smaller index) rejects wrong matches, and Δθ is the median of the inliers' votes.

When the view has too few features, the step was too large, or the votes do not agree,
the result is ``ok=False`` with a reason and Δθ = 0, never a wrong angle (the paper's
Figure 22 failure cases).

Cost, with the same answers: a robot measures each new picture against the one before
it, so the features of the last few pictures are kept (:data:`FEATURE_CACHE`, keyed by
a digest of the picture's bytes: a picture's features are a function of its bytes alone),
and each vote's inliers are counted from the votes sorted, each candidate window checked
with the very comparison ``|v_j − v_i| ≤ tol`` (O(m log m) instead of an m×m table).
"""

from __future__ import annotations

import hashlib
import math
from collections import OrderedDict
from dataclasses import dataclass

import cv2
import numpy as np

from agent.core.perception.camera import CameraModel
from agent.core.perception.segmentation import check_image


@dataclass(frozen=True)
class CompassResult:
    """``dtheta`` is the body turn from ``before`` to ``after`` (rad, +CCW)."""

    ok: bool
    dtheta: float
    matches: int
    inliers: int
    inlier_ratio: float
    reason: str


#: Pictures whose ORB features a compass keeps (module docstring): the one before and the
#: one after a measurement, and a reference a robot keeps across steps.
FEATURE_CACHE = 4


class VisualCompass:
    """Heading change from two forehead images taken at the same head yaw."""

    def __init__(
        self,
        camera: CameraModel | None = None,
        min_matches: int = 15,
        min_inlier_ratio: float = 0.4,
        tol: float = math.radians(0.4),
        max_dv: float = 6.0,
        n_features: int = 1500,
    ) -> None:
        if min_matches < 3:
            raise ValueError(f"min_matches must be >= 3, got {min_matches}")
        if not 0.0 < min_inlier_ratio <= 1.0:
            raise ValueError(f"min_inlier_ratio must be in (0, 1], got {min_inlier_ratio}")
        if not (tol > 0 and max_dv > 0 and n_features > 0):
            raise ValueError("tol, max_dv and n_features must be > 0")
        self.camera = CameraModel() if camera is None else camera
        self.min_matches = min_matches
        self.min_inlier_ratio = min_inlier_ratio
        self.tol = tol
        self.max_dv = max_dv
        self._orb = cv2.ORB.create(nfeatures=n_features, fastThreshold=10)
        self._matcher = cv2.BFMatcher(cv2.NORM_HAMMING)
        self._map_x, self._map_y = self.camera.cylindrical_maps()
        w, h = self.camera.width, self.camera.height
        valid = (
            (self._map_x >= 0)
            & (self._map_x <= w - 1)
            & (self._map_y >= 0)
            & (self._map_y <= h - 1)
        ).astype(np.uint8)
        self._valid = cv2.erode(valid * 255, np.ones((33, 33), np.uint8))
        self._cache: OrderedDict[bytes, tuple[list[cv2.KeyPoint], np.ndarray | None]] = (
            OrderedDict()
        )

    def _features(self, image_bgr: np.ndarray) -> tuple[list[cv2.KeyPoint], np.ndarray | None]:
        img = np.ascontiguousarray(image_bgr)
        key = hashlib.blake2b(f"{img.shape} {img.dtype}".encode(), digest_size=16)
        key.update(img.data)
        digest = key.digest()
        hit = self._cache.get(digest)
        if hit is not None:
            self._cache.move_to_end(digest)
            return hit
        gray = cv2.cvtColor(img, cv2.COLOR_BGR2GRAY)
        cyl = cv2.remap(gray, self._map_x, self._map_y, cv2.INTER_LINEAR)
        kps, desc = self._orb.detectAndCompute(cyl, self._valid)
        out = (list(kps), desc)
        self._cache[digest] = out
        while len(self._cache) > FEATURE_CACHE:
            self._cache.popitem(last=False)
        return out

    def _fail(self, reason: str, matches: int = 0, inliers: int = 0) -> CompassResult:
        ratio = inliers / matches if matches else 0.0
        return CompassResult(False, 0.0, matches, inliers, ratio, reason)

    def measure(self, before_bgr: np.ndarray, after_bgr: np.ndarray) -> CompassResult:
        """The body turn between two images (see the module docstring)."""
        a = check_image(before_bgr)
        b = check_image(after_bgr)
        for name, img in (("before", a), ("after", b)):
            if img.shape[:2] != (self.camera.height, self.camera.width):
                raise ValueError(
                    f"{name} image is {img.shape[1]}x{img.shape[0]}, the camera model "
                    f"expects {self.camera.width}x{self.camera.height}"
                )
        kp_a, d_a = self._features(a)
        kp_b, d_b = self._features(b)
        if (
            d_a is None
            or d_b is None
            or len(kp_a) < self.min_matches
            or len(kp_b) < self.min_matches
        ):
            return self._fail(f"too few features ({len(kp_a)}, {len(kp_b)}): featureless view")
        pairs = self._matcher.knnMatch(d_a, d_b, k=2)
        good = [p[0] for p in pairs if len(p) == 2 and p[0].distance < 0.75 * p[1].distance]
        if len(good) < self.min_matches:
            return self._fail(f"too few matches ({len(good)} < {self.min_matches})", len(good))
        ua = np.array([kp_a[m.queryIdx].pt for m in good])
        ub = np.array([kp_b[m.trainIdx].pt for m in good])
        votes = (ub[:, 0] - ua[:, 0]) / self.camera.fx
        level = np.abs(ub[:, 1] - ua[:, 1]) <= self.max_dv
        counts = np.where(level, _within(votes, level, self.tol), -1)
        order = np.lexsort((np.arange(len(votes)), np.abs(votes), -counts))
        best = int(order[0])
        inl = (np.abs(votes - votes[best]) <= self.tol) & level
        n_in = int(inl.sum())
        ratio = n_in / len(good)
        if n_in < self.min_matches:
            return self._fail(f"too few inliers ({n_in} < {self.min_matches})", len(good), n_in)
        if ratio < self.min_inlier_ratio:
            return self._fail(
                f"inlier ratio {ratio:.2f} < {self.min_inlier_ratio:.2f}: matches disagree",
                len(good),
                n_in,
            )
        dtheta = float(np.median(votes[inl]))
        return CompassResult(True, dtheta, len(good), n_in, ratio, "ok")


def _within(votes: np.ndarray, level: np.ndarray, tol: float) -> np.ndarray:
    """For each vote i, how many level votes j have ``|v_j − v_i| ≤ tol`` (module
    docstring), the m×m table's counts. Rounding is monotone, so ``v_j − v_i`` computed
    grows with v_j and the j that pass are one run of the sorted level votes; its ends,
    first found by a search on ``v_i ∓ tol``, are moved until the comparison itself holds
    inside and fails outside (an empty run: the ends cross, and the count is 0)."""
    lv = np.sort(votes[level])
    n = len(lv)

    def ok(j: np.ndarray) -> np.ndarray:
        inside = (j >= 0) & (j < n)
        d = lv[np.clip(j, 0, max(n - 1, 0))] - votes if n else np.zeros(len(votes))
        return inside & (np.abs(d) <= tol)

    lo = np.searchsorted(lv, votes - tol, side="left")
    hi = np.searchsorted(lv, votes + tol, side="right")  # one past the run
    while True:  # a few steps at most: rounding moves an end by an element or so
        down = ok(lo - 1)
        up = ~ok(lo) & (lo < hi)
        grow = ok(hi)
        shrink = ~ok(hi - 1) & (hi > lo)
        if not (down.any() or up.any() or grow.any() or shrink.any()):
            return np.asarray(np.maximum(hi - lo, 0), dtype=np.int64)  # empty: the ends cross
        lo = lo - down + (up & ~down)
        hi = hi + grow - (shrink & ~grow)
