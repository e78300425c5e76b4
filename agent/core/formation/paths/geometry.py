"""Segment geometry of the safety rule: point-to-segment and segment-to-segment
distances, and Lemma 1's crossing test (NAO paper 4.2, Lemma 1: matched straight paths
do not *intercross*; :mod:`safety` measures how close they come).

Every function is vectorized (broadcast over leading axes of (..., 2) arrays). For the
distance, two segments only *cross* (distance 0) when every endpoint is clearly off the
other's line (orientations within a rounding slack of 0 are no crossing): collinear
legs, e.g. on one corridor line, are measured by their endpoint distances instead.
:func:`paths_cross` is the plain sign test of Lemma 1's repair (:mod:`assignment`).
"""

from __future__ import annotations

import numpy as np


def point_seg_dist(p: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Distance from points p to segments [a, b] (broadcast over leading axes)."""
    ax, ay = a[..., 0], a[..., 1]
    px, py = p[..., 0], p[..., 1]
    abx, aby = b[..., 0] - ax, b[..., 1] - ay
    apx, apy = px - ax, py - ay
    den = abx * abx + aby * aby
    pos = den > 0
    t = np.where(pos, (apx * abx + apy * aby) / np.where(pos, den, 1.0), 0.0)
    t = np.minimum(np.maximum(t, 0.0), 1.0)  # clipped to [0, 1]
    return np.asarray(np.hypot(px - (ax + t * abx), py - (ay + t * aby)))


def _cross(o: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    out = (a[..., 0] - o[..., 0]) * (b[..., 1] - o[..., 1]) - (a[..., 1] - o[..., 1]) * (
        b[..., 0] - o[..., 0]
    )
    return np.asarray(out)


def seg_seg_dist(a0: np.ndarray, a1: np.ndarray, b0: np.ndarray, b1: np.ndarray) -> np.ndarray:
    """Distance between segments [a0, a1] and [b0, b1] (0 if they cross)."""
    d = np.minimum(
        np.minimum(point_seg_dist(a0, b0, b1), point_seg_dist(a1, b0, b1)),
        np.minimum(point_seg_dist(b0, a0, a1), point_seg_dist(b1, a0, a1)),
    )
    o1, o2 = _cross(a0, a1, b0), _cross(a0, a1, b1)
    o3, o4 = _cross(b0, b1, a0), _cross(b0, b1, a1)
    # a proper crossing needs every endpoint clearly off the other line: orientations
    # within rounding of 0 (collinear legs, e.g. on one corridor line) are no crossing -
    # if such segments do meet, an endpoint lies on the other one and d is ~0 already
    la = np.hypot(a1[..., 0] - a0[..., 0], a1[..., 1] - a0[..., 1])
    lb = np.hypot(b1[..., 0] - b0[..., 0], b1[..., 1] - b0[..., 1])
    tol = 1e-12 * (la + lb) * (la + lb + np.hypot(b0[..., 0] - a0[..., 0], b0[..., 1] - a0[..., 1]))
    clear = (np.abs(o1) > tol) & (np.abs(o2) > tol) & (np.abs(o3) > tol) & (np.abs(o4) > tol)
    crossing = (o1 * o2 < 0) & (o3 * o4 < 0) & clear
    return np.where(crossing, 0.0, d)


def paths_cross(a0: np.ndarray, a1: np.ndarray, b0: np.ndarray, b1: np.ndarray) -> np.ndarray:
    """True where the two segments properly cross (Lemma 1's 'intercrossing')."""
    o1, o2 = _cross(a0, a1, b0), _cross(a0, a1, b1)
    o3, o4 = _cross(b0, b1, a0), _cross(b0, b1, a1)
    return np.asarray((o1 * o2 < 0) & (o3 * o4 < 0))
