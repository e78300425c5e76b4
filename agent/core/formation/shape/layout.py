"""Where a shape goes on the fleet: its frame (NAO eqs. 12-13, the pyramid's frame for any
shape), its slots placed in that frame, and the step of its slot columns (for the lanes of
:mod:`agent.core.formation.paths.lanes` and the columns of the banded plan).

* Frame: origin o_p = the mean of the starts; the axis β is the pyramid's
  (:func:`pyramid.pyramid_frame`: PCA with the skewness sign rule, or north) for a
  ``depth`` shape. A ``width`` shape lays its left-right axis along the fleet's principal
  axis instead: with PCA, β is the principal axis (same sign rule) turned by +90°; with
  ``north`` it is north, as for every shape.
* Placement: ``centroid`` (the slots' centroid at o_p, the translation that minimises
  Σ|slot − start|²) or ``front`` (moved along the axis until the rearmost slot is d_e
  ahead of the front-most start, so that no slot lies among the starts: used when the
  overlapping placement cannot be scheduled).
"""

from __future__ import annotations

import functools
import math

import numpy as np
from scipy.spatial import cKDTree

from agent.core.formation.shape.pyramid import (
    AXES,
    PyramidFrame,
    pca_axis,
    pyramid_frame,
)
from agent.core.formation.shape.spec import PYRAMID, Shape

#: The placement policies of :func:`placed` (module doc).
PLACEMENTS = ("centroid", "front")
#: Slot x coordinates closer than this (m) are one column.
COLUMN_TOL = 1e-9


def shape_frame(positions: np.ndarray, orientation: str, shape: Shape = PYRAMID) -> PyramidFrame:
    """The shape's frame on the starts (module doc); the pyramid's for a ``depth`` shape."""
    if shape.orient == "depth":
        return pyramid_frame(positions, orientation)
    pts = np.asarray(positions, dtype=np.float64)
    if orientation == "north":
        return PyramidFrame(origin=pts.mean(axis=0), beta=math.pi / 2)
    if orientation != "pca":
        raise ValueError(f"orientation must be one of {AXES}, got {orientation!r}")
    beta = math.remainder(pca_axis(pts) + math.pi / 2, 2.0 * math.pi)
    return PyramidFrame(origin=pts.mean(axis=0), beta=beta)


def centred(shape: Shape, n: int, d_e: float, phi_e: float) -> np.ndarray:
    """The shape's n slots in its frame, translated so that their centroid is o_p."""
    s = shape.slots(n, d_e, phi_e).positions
    return np.asarray(s - s.mean(axis=0))


def placed(
    shape: Shape, n: int, d_e: float, phi_e: float, starts_p: np.ndarray, placement: str
) -> np.ndarray:
    """The slots in the shape frame for a placement policy (module doc)."""
    s = centred(shape, n, d_e, phi_e)
    if placement == "centroid":
        return s
    if placement != "front":
        raise ValueError(f"placement must be one of {PLACEMENTS}, got {placement!r}")
    front = float(np.max(starts_p[:, 1])) if starts_p.size else 0.0
    shift = front + d_e - float(np.min(s[:, 1]))
    return np.asarray(s + np.array([0.0, max(shift, 0.0)]))


def columns(x: np.ndarray) -> np.ndarray:
    """Per slot, the rank of its column: slot x coordinates sorted, a new column wherever
    two consecutive ones are more than :data:`COLUMN_TOL` apart."""
    xs = np.asarray(x, dtype=np.float64)
    idx = np.argsort(xs, kind="stable")
    new = np.concatenate([[0], (np.diff(xs[idx]) > COLUMN_TOL).astype(np.int64)])
    col = np.empty(xs.shape[0], dtype=np.int64)
    col[idx] = np.cumsum(new)
    return col


def column_step(shape: Shape, slots_x: np.ndarray, d_e: float, phi_e: float) -> float:
    """The smallest gap (m) between two slot columns of ``slots_x`` (inf for one column):
    a line half-way between a column and its neighbour passes every slot at >= half of
    it. The pyramid's is AUV eq. 7's d_e·sin φ_e exactly."""
    if shape.rule == "pyramid":
        return d_e * math.sin(phi_e)
    xs = np.sort(np.asarray(slots_x, dtype=np.float64))
    gaps = np.diff(xs)
    gaps = gaps[gaps > COLUMN_TOL]
    return float(gaps.min()) if gaps.size else math.inf


@functools.lru_cache(maxsize=16)  # PlanParams checks every file shape it is given
def closest_slots(shape: Shape, d_e: float, phi_e: float) -> tuple[int, int, float]:
    """(slot a, slot b, distance m) of the two closest slots of a formation file's whole
    tree (a < b; ties: the lowest pair). Built-ins space their slots by d_e
    (:mod:`builtin`); a file may not."""
    cap = shape.capacity
    if cap is None:
        raise ValueError(f"the built-in shape {shape.name!r} has no fixed slots")
    pos = shape.slots(cap, d_e, phi_e).positions
    tree = cKDTree(pos)
    best: tuple[float, int, int] | None = None
    r = 1.0
    while best is None:  # every pair within r, r doubled until one exists
        pairs = tree.query_pairs(r, output_type="ndarray")
        if len(pairs):
            d = np.hypot(*(pos[pairs[:, 0]] - pos[pairs[:, 1]]).T)
            k = np.lexsort((pairs[:, 1], pairs[:, 0], d))[0]
            best = (float(d[k]), int(pairs[k, 0]), int(pairs[k, 1]))
        r *= 2.0
    return best[1], best[2], best[0]
