"""The visual compass: heading change between two images (NAO paper 3.2.1, eq. 2, 5.2.2 (ii)).

Like NAOqi's ALVisualCompass, it matches features (ORB) between the image before and
after a turn and reports the quality of the match (number of matches, inliers, inlier
ratio). Both images are resampled to the cylindrical image (camera.py), where a turn of
the body about the vertical axis is a horizontal shift of f_x·Δθ pixels (eq. 2): a right
match keeps its row, and every match votes for one Δθ. A deterministic one-parameter
RANSAC (every match is a hypothesis; the one with most inliers within ``tol`` wins, ties
to the smaller angle magnitude, then to the smaller angle) rejects wrong matches, and Δθ
is the median of the inliers' votes.

**Guided matching.** The turn's model says where a feature's match can be: in the same
row band of the other picture, ``|v_after − v_before| ≤ max_dv``, the epipolar line of a
pure rotation about the vertical axis widened by ``max_dv`` for the camera's small
off-axis parallax. So each feature of ``before`` is compared only with the features of
``after`` in its band, and Lowe's ratio test (:data:`RATIO`) is taken among those
candidates (:func:`guided_matches`): the standard guided match along an epipolar line
(Hartley & Zisserman, docs/papers.md). A match outside the band could never vote (it
contradicts the model), so nothing the votes could use is lost; a feature with fewer
than two candidates has no ratio test and no match. The kept match of a feature is its
unique nearest candidate (two equally near fail the ratio test), so no tie is ever
resolved: the answer does not depend on the order of the keypoints, and the RANSAC's
last tie-break is the angle itself.

**The inlier ratio.** Its denominator is the number of band matches, not the number of
all ratio-test matches of a full match: matches off the band (parallax when the robot
moved, radial expansion after a step, wrong matches) do not count against the ratio, and
among fewer candidates the ratio test passes more matches. For the same pictures the
ratio therefore reads higher, and :data:`MIN_INLIER_RATIO` is 0.5 where a full match
takes 0.4. Measured on rendered pairs (``tools.eval_perception``, and pairs held out
from the choice): in-place turns of 5–40° read ≥ 0.72; views 0.25–2 m from the reference
(parallax, which the pure-rotation model does not explain) fail about as often as with
the full match at 0.4, with the same errors (a few more of 60 readings pass at 1–2 m);
unrelated views never reach ``min_matches`` inliers. The walk compass
(``agent/adapters.py``, central band, 1° vote tolerance) would take 0.1 with a full
match, because a step's radial expansion moves most right matches off their row; guided,
those drop out of the denominator and a step's band reads ≥ 0.72, while banded views 40°
apart reach 15–17 inliers at ratios ≤ 0.36 (at 0.1 they would read wrong angles): it
takes the same 0.5.

When the view has too few features, the step was too large, or the votes do not agree,
the result is ``ok=False`` with a reason and Δθ = 0, never a wrong angle (the paper's
Figure 22 failure cases).

Cost: a robot measures each new picture against the one before it, so the features of
the last few pictures are kept (:data:`FEATURE_CACHE`, keyed by a digest of the
picture's bytes: a picture's features are a function of its bytes alone); the guided
match compares a feature with the few dozen features of its band instead of all of them;
and each vote's inliers are counted from the votes sorted, each candidate window checked
with the very comparison ``|v_j − v_i| ≤ tol`` (O(m log m) instead of an m×m table). The
ORB pyramid has :data:`ORB_LEVELS` levels, not OpenCV's 8: a turn in place does not
change the scale of the view, and a 20–40 cm step scales what is 2 m away by 1.1–1.25,
about one level's factor 1.2; with 2 levels the measured answers of the turn and walk
compasses (turns, steps, double steps, sidesteps, views away from the reference) are
those of 8 levels, at half the ORB time. A picture keeps its :data:`ORB_FEATURES`
strongest corners: a textured view has hundreds of inliers either way (``min_matches``
is 15), a view with fewer corners keeps them all, and on the same rendered pairs 1200
give the answers and failures of 1500 at 12 % less time.
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
#: Lowe's ratio test: a feature's nearest candidate is its match when its Hamming
#: distance is below this share of the second nearest's.
RATIO = 0.75
#: The share of the band matches that must agree (module docstring).
MIN_INLIER_RATIO = 0.5
#: Levels of the ORB pyramid, a factor 1.2 apart (module docstring).
ORB_LEVELS = 2
#: The most ORB features kept of a picture, the strongest corners (module docstring).
ORB_FEATURES = 1200
#: Features of ``before``, in row order, matched against their bands in one call: their
#: bands overlap, so one call covers a few rows more than each needs.
_CHUNK = 64

#: A picture's features: keypoint positions (n, 2) as (u, v) on the cylindrical image,
#: and their ORB descriptors (n, 32) (None when there are none).
Features = tuple[np.ndarray, np.ndarray | None]


def guided_matches(
    v_a: np.ndarray, d_a: np.ndarray, v_b: np.ndarray, d_b: np.ndarray, max_dv: float
) -> tuple[np.ndarray, np.ndarray]:
    """The guided match (module docstring): for each feature i of ``before`` (row
    ``v_a[i]``, binary descriptor ``d_a[i]``), the features j of ``after`` with
    ``|v_b[j] − v_a[i]| ≤ max_dv`` are its candidates; its nearest candidate by Hamming
    distance is its match when it passes the ratio test against the second nearest
    (:data:`RATIO`). Returns (i ascending, j) of the matches.

    Both sides are sorted by row (ties by index); the features of ``before`` are taken
    :data:`_CHUNK` at a time, compared with the run of ``after``'s features whose rows can
    be in any of their bands (a pixel more each side than the bands, so that rounding in
    ``v ± max_dv`` loses none), and that comparison is masked to each band exactly.

    Ties: a kept match is its feature's unique nearest candidate (with two equally near,
    ``d1 < RATIO·d1`` is false), so which of equal candidates comes first never changes
    the answer; it equals the brute-force match that breaks ties to the lower index of
    ``after`` (tests), and any order of the inputs gives the same pairs.
    """
    if d_a.ndim != 2 or d_b.ndim != 2 or d_a.dtype != np.uint8 or d_b.dtype != np.uint8:
        raise ValueError("descriptors must be 2-D uint8 arrays")
    if d_a.shape[1] != d_b.shape[1]:
        raise ValueError(f"descriptor widths differ: {d_a.shape[1]} and {d_b.shape[1]} bytes")
    v_a = np.asarray(v_a, dtype=np.float64)
    v_b = np.asarray(v_b, dtype=np.float64)
    if v_a.shape != (len(d_a),) or v_b.shape != (len(d_b),):
        raise ValueError("one row per descriptor: v_a, v_b must match d_a, d_b")
    if not (math.isfinite(max_dv) and max_dv > 0):
        raise ValueError(f"max_dv must be finite and > 0, got {max_dv}")
    if not (np.isfinite(v_a).all() and np.isfinite(v_b).all()):
        raise ValueError("rows must be finite")
    none = np.zeros(0, dtype=np.intp)
    n_a, n_b = len(v_a), len(v_b)
    if n_a == 0 or n_b < 2:
        return none, none
    ob = np.lexsort((np.arange(n_b), v_b))
    vb, db = v_b[ob], d_b[ob]
    oa = np.lexsort((np.arange(n_a), v_a))
    va, da = v_a[oa], d_a[oa]
    lo = np.searchsorted(vb, va - max_dv - 1.0, side="left")
    hi = np.searchsorted(vb, va + max_dv + 1.0, side="right")
    dist = np.zeros((n_a, 2), dtype=np.int32)
    nearest = np.full((n_a, 2), -1, dtype=np.int32)  # positions in ``vb``; -1: none
    for s in range(0, n_a, _CHUNK):
        e = min(s + _CHUNK, n_a)
        first, last = int(lo[s]), int(hi[e - 1])  # rows sorted: the chunk's run of ``after``
        if last - first < 2:
            continue
        band = np.abs(vb[first:last] - va[s:e, None]) <= max_dv
        d, j = cv2.batchDistance(
            da[s:e], db[first:last], cv2.CV_32S, normType=cv2.NORM_HAMMING, K=2,
            mask=band.view(np.uint8),
        )  # fmt: skip
        dist[s:e] = d
        nearest[s:e] = np.where(j >= 0, j + first, -1)
    keep = (nearest[:, 1] >= 0) & (dist[:, 0] < RATIO * dist[:, 1])
    qi, tj = oa[keep], ob[nearest[keep, 0]]
    order = np.argsort(qi, kind="stable")
    return qi[order].astype(np.intp), tj[order].astype(np.intp)


class VisualCompass:
    """Heading change from two forehead images taken at the same head yaw."""

    def __init__(
        self,
        camera: CameraModel | None = None,
        min_matches: int = 15,
        min_inlier_ratio: float = MIN_INLIER_RATIO,
        tol: float = math.radians(0.4),
        max_dv: float = 6.0,
        n_features: int = ORB_FEATURES,
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
        self._orb = cv2.ORB.create(nfeatures=n_features, nlevels=ORB_LEVELS, fastThreshold=10)
        self._map_x, self._map_y = self.camera.cylindrical_maps()
        w, h = self.camera.width, self.camera.height
        valid = (
            (self._map_x >= 0)
            & (self._map_x <= w - 1)
            & (self._map_y >= 0)
            & (self._map_y <= h - 1)
        ).astype(np.uint8)
        self._valid = cv2.erode(valid * 255, np.ones((33, 33), np.uint8))
        self._cache: OrderedDict[bytes, Features] = OrderedDict()

    def _features(self, image_bgr: np.ndarray) -> Features:
        img = np.ascontiguousarray(image_bgr)
        key = hashlib.sha256(f"{img.shape} {img.dtype}".encode())
        key.update(img.data)
        digest = key.digest()
        hit = self._cache.get(digest)
        if hit is not None:
            self._cache.move_to_end(digest)
            return hit
        gray = cv2.cvtColor(img, cv2.COLOR_BGR2GRAY)
        cyl = cv2.remap(gray, self._map_x, self._map_y, cv2.INTER_LINEAR)
        kps, desc = self._orb.detectAndCompute(cyl, self._valid)
        uv = np.array(cv2.KeyPoint.convert(kps), dtype=np.float64).reshape(-1, 2)
        out = (uv, desc)
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
        return self.compare(self._features(a), self._features(b))

    def compare(self, before: Features, after: Features) -> CompassResult:
        """The body turn between two pictures' features (:data:`Features`), in any order."""
        (uv_a, d_a), (uv_b, d_b) = before, after
        if (
            d_a is None
            or d_b is None
            or len(uv_a) < self.min_matches
            or len(uv_b) < self.min_matches
        ):
            return self._fail(f"too few features ({len(uv_a)}, {len(uv_b)}): featureless view")
        qa, tb = guided_matches(uv_a[:, 1], d_a, uv_b[:, 1], d_b, self.max_dv)
        m = len(qa)
        if m < self.min_matches:
            return self._fail(f"too few matches ({m} < {self.min_matches})", m)
        votes = (uv_b[tb, 0] - uv_a[qa, 0]) / self.camera.fx
        counts = _within(votes, self.tol)
        best = int(np.lexsort((votes, np.abs(votes), -counts))[0])
        inl = np.abs(votes - votes[best]) <= self.tol
        n_in = int(inl.sum())
        ratio = n_in / m
        if n_in < self.min_matches:
            return self._fail(f"too few inliers ({n_in} < {self.min_matches})", m, n_in)
        if ratio < self.min_inlier_ratio:
            return self._fail(
                f"inlier ratio {ratio:.2f} < {self.min_inlier_ratio:.2f}: matches disagree",
                m,
                n_in,
            )
        dtheta = float(np.median(votes[inl]))
        return CompassResult(True, dtheta, m, n_in, ratio, "ok")


def _within(votes: np.ndarray, tol: float) -> np.ndarray:
    """For each vote i, how many votes j have ``|v_j − v_i| ≤ tol`` (module docstring),
    the m×m table's counts. Rounding is monotone, so ``v_j − v_i`` computed grows with
    v_j and the j that pass are one run of the sorted votes; its ends, first found by a
    search on ``v_i ∓ tol``, are moved until the comparison itself holds inside and
    fails outside (an empty run: the ends cross, and the count is 0)."""
    lv = np.sort(votes)
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
