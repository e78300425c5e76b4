"""Relative positions of neighbours in the local and the fixed frame (NAO paper 4.1.1, eqs. 3, 7, 8).

Frames (common.md): the body frame has x forward and bearings +left; the local frame
local-i has +y forward and +x to the robot's right, so a neighbour at body bearing φ_N
is at angle φ_l = φ_N + 90° in local-i (eq. 3) and at (d cos φ_l, d sin φ_l) there
(eq. 7). The fixed frame fixed-i is local-i at the start; after the robot has turned by
θ (visual compass, eq. 2) the local point is rotated by θ into fixed-i (eq. 8). With the
body heading ψ in the fixed frame (π/2 at the start), θ = ψ - π/2.

The same neighbour seen in several overlapping head-yaw images is merged into one
record entry by :func:`merge_sightings`.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Protocol

import numpy as np


class Sighting(Protocol):
    """What :func:`to_fixed_frame` needs of a detection."""

    @property
    def distance(self) -> float: ...

    @property
    def bearing(self) -> float: ...


def local_angle(bearing: float) -> float:
    """Eq. 3: φ_l = φ_N + 90° (rad)."""
    return bearing + math.pi / 2.0


def local_position(distance: float, bearing: float) -> tuple[float, float]:
    """Eq. 7: (x_l, y_l) = d (cos φ_l, sin φ_l) in local-i."""
    if not (math.isfinite(distance) and math.isfinite(bearing)) or distance < 0:
        raise ValueError(f"distance must be finite and >= 0, bearing finite: {distance}, {bearing}")
    phi = local_angle(bearing)
    return distance * math.cos(phi), distance * math.sin(phi)


def rotate(points: np.ndarray, theta: float) -> np.ndarray:
    """Eq. 8: rotate (k, 2) points by θ (CCW)."""
    pts = np.asarray(points, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] != 2:
        raise ValueError(f"points must have shape (k, 2), got {pts.shape}")
    if not math.isfinite(theta):
        raise ValueError(f"theta must be finite, got {theta}")
    c, s = math.cos(theta), math.sin(theta)
    return np.asarray(pts @ np.array([[c, s], [-s, c]]))


def to_fixed_frame(detections: Sequence[Sighting], body_heading: float) -> np.ndarray:
    """Neighbours' (x, y) in the fixed frame, shape (k, 2), in the order given.

    ``body_heading`` is the robot's heading in its fixed frame (π/2 at the start).
    """
    if not math.isfinite(body_heading):
        raise ValueError(f"body heading must be finite, got {body_heading}")
    local = np.array([local_position(d.distance, d.bearing) for d in detections], dtype=np.float64)
    if local.size == 0:
        return np.zeros((0, 2))
    return rotate(local, body_heading - math.pi / 2.0)


def cluster_sightings(points: np.ndarray, confidences: np.ndarray, radius: float) -> np.ndarray:
    """Cluster label (0..m-1) of each sighting; sightings within ``radius`` of a cluster's
    seed join it.

    Seeds are taken by decreasing confidence, ties by input index; a sighting joins the
    first seed (in seed order) within ``radius``. Labels are numbered in seed order.
    """
    pts = np.asarray(points, dtype=np.float64)
    conf = np.asarray(confidences, dtype=np.float64).reshape(-1)
    if pts.ndim != 2 or pts.shape[1] != 2:
        raise ValueError(f"points must have shape (k, 2), got {pts.shape}")
    if conf.shape[0] != pts.shape[0]:
        raise ValueError(f"{pts.shape[0]} points but {conf.shape[0]} confidences")
    if not (np.all(np.isfinite(pts)) and np.all(np.isfinite(conf))):
        raise ValueError("points and confidences must be finite")
    if not (math.isfinite(radius) and radius > 0):
        raise ValueError(f"radius must be finite and > 0, got {radius}")
    order = sorted(range(len(conf)), key=lambda i: (-conf[i], i))
    labels = np.full(len(conf), -1, dtype=np.int64)
    seeds: list[int] = []
    for i in order:
        for lab, s in enumerate(seeds):
            if float(np.hypot(*(pts[i] - pts[s]))) <= radius:
                labels[i] = lab
                break
        else:
            labels[i] = len(seeds)
            seeds.append(i)
    return labels


def merge_sightings(
    points: np.ndarray, confidences: np.ndarray, radius: float = 0.25
) -> np.ndarray:
    """One point per neighbour: the confidence-weighted mean of each cluster, shape (m, 2),
    in seed order (most confident first).

    The default radius (0.25 m) is below the smallest centre distance of two NAOs that do
    not touch (2 × 0.2 m robot radius) and above the detector's typical error.
    """
    labels = cluster_sightings(points, confidences, radius)
    pts = np.asarray(points, dtype=np.float64)
    conf = np.asarray(confidences, dtype=np.float64).reshape(-1)
    m = int(labels.max()) + 1 if labels.size else 0
    out = np.zeros((m, 2))
    for lab in range(m):
        sel = labels == lab
        w = np.clip(conf[sel], 1e-9, None)
        out[lab] = (pts[sel] * w[:, None]).sum(axis=0) / w.sum()
    return out
