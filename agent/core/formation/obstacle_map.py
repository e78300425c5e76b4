"""Perceived obstacles in the common frame (NAO paper 5.1.2, with 4.1.3 eq. 10).

The paper plans around obstacles at known positions. Here every robot reports the
obstacles it saw in its own fixed frame (its record's ``obstacles``; the fixed frames are
parallel, 4.1.1), so a sighting ``o`` of robot ``i`` lies at ``p_i + o`` in the common
frame (eq. 10, as for neighbours). Several robots, and one robot from several head
yaws, see the same cylinder: :func:`merge_sightings` makes one obstacle of them.

Merging is single-linkage clustering: two sightings closer than ``radius`` belong to
the same obstacle (the connected components of that relation; they do not depend on
the order of the sightings). An obstacle is the weighted mean of its sightings, the
weight of a sighting ``1 / max(d, D_MIN)`` with ``d`` its distance from the robot that
saw it (a far sighting errs more, 1-3 % of d). The result is sorted by (x, y): the
tie-break, so every agent with the same records gets bit-identical obstacles (sums are
taken in (x, y, weight) order of the sightings).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

#: Sightings of one obstacle scatter by a few cm; distinct cylinders (radius 0.15 m)
#: stand at least 0.3 m apart: closer sightings are the same obstacle.
MERGE_RADIUS = 0.25
D_MIN = 0.5  # m: the detector's nearest range; nearer sightings weigh as much as this


def merge_sightings(
    points: np.ndarray, distances: np.ndarray, radius: float = MERGE_RADIUS
) -> np.ndarray:
    """One (x, y) per obstacle from sightings ``points`` (K, 2) seen from ``distances`` (K,).

    Returns (M, 2) sorted by x then y. ``ValueError`` on bad shapes or non-finite values.
    """
    pts = np.asarray(points, dtype=np.float64)
    if pts.size == 0:
        pts = pts.reshape(0, 2)
    dist = np.asarray(distances, dtype=np.float64).reshape(-1)
    if pts.ndim != 2 or pts.shape[1] != 2 or dist.shape[0] != pts.shape[0]:
        raise ValueError(
            f"need points (K, 2) and K distances, got {np.shape(points)} and {np.shape(distances)}"
        )
    if not (np.all(np.isfinite(pts)) and np.all(np.isfinite(dist))):
        raise ValueError("obstacle sightings contain non-finite values")
    if not (np.isfinite(radius) and radius > 0):
        raise ValueError(f"merge radius must be a finite distance > 0, got {radius!r}")
    if pts.shape[0] == 0:
        return np.zeros((0, 2))
    w = 1.0 / np.maximum(np.abs(dist), D_MIN)
    # canonical order first: equal inputs in any order give bit-identical sums
    idx = np.lexsort((w, pts[:, 1], pts[:, 0]))
    pts, w = pts[idx], w[idx]
    pairs = cKDTree(pts).query_pairs(radius, output_type="ndarray")
    k = pts.shape[0]
    adj = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(k, k))
    m, labels = connected_components(adj, directed=False)
    out = np.zeros((m, 2))
    for lab in range(m):
        sel = labels == lab
        out[lab] = (w[sel, None] * pts[sel]).sum(axis=0) / w[sel].sum()
    return out[np.lexsort((out[:, 1], out[:, 0]))]


def common_frame_obstacles(
    ids: Sequence[int],
    positions: np.ndarray,
    sightings: Mapping[int, np.ndarray],
    radius: float = MERGE_RADIUS,
    headings: np.ndarray | None = None,
) -> np.ndarray:
    """Obstacles (M, 2) in the common frame from each robot's fixed-frame ``sightings``.

    ``ids``/``positions`` are the robots' starts in the common frame
    (:class:`~agent.core.formation.frame.common_frame.CommonFrame`), ``headings`` their ψ (each
    fixed frame turned from the common frame; None: all 0, the papers' aligned frames);
    sightings of robots not among them (not reachable, hence not placed) are left out.
    """
    index = {int(r): k for k, r in enumerate(ids)}
    pos = np.asarray(positions, dtype=np.float64).reshape(-1, 2)
    pts: list[np.ndarray] = []
    dist: list[np.ndarray] = []
    for rid in sorted(sightings):
        if rid not in index:
            continue
        own = np.asarray(sightings[rid], dtype=np.float64).reshape(-1, 2)
        dist.append(np.hypot(own[:, 0], own[:, 1]))
        if headings is not None and float(headings[index[rid]]) != 0.0:
            a = float(headings[index[rid]])
            c, s = math.cos(a), math.sin(a)
            own = own @ np.array([[c, s], [-s, c]])  # row vectors turned by +ψ
        pts.append(own + pos[index[rid]])
    if not pts:
        return np.zeros((0, 2))
    return merge_sightings(np.concatenate(pts), np.concatenate(dist), radius)
