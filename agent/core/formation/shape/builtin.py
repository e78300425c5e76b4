"""The built-in shapes and how each scales with the fleet size N (the pyramid of AUV paper
II eqs. 5-7; the others are our additions, on the tree conventions of :mod:`tree`).

Every built-in spaces its neighbours by the agreed spacing d_e (``PlanParams.d_e``, the
AUV paper's d_e), so that every two slots are >= d_e apart (the pyramid:
``min(d_e, 2·d_e·sin φ_e, 2·d_e·cos φ_e)``, its neighbours in a layer and a slot and the
one two layers behind it), and each places the leader (slot 0) at the front:

* ``pyramid`` (AUV eqs. 5-7, :mod:`pyramid`): layer L holds L robots, each child d_e
  behind its parent at φ_e off the backward axis; N robots fill ⌈layers⌉ left-aligned.
  Slot positions are eq. 7's closed form, bit for bit.
* ``line`` (side by side): the leader in the middle; slot k >= 1 stands d_e to the left
  (k odd) or right (k even) of slot k − 2 (the leader for k <= 2): ⌈(N−1)/2⌉ robots on
  the left, ⌊(N−1)/2⌋ on the right.
* ``column`` (one behind the other): slot k stands d_e behind slot k − 1.
* ``wedge`` (a V, apex ahead): two arms from the leader, each child d_e behind its parent
  at :data:`WEDGE_ANGLE` off the backward axis, left arm for odd k, right arm for even k
  (parent: slot k − 2, the leader for k <= 2).
* ``circle``: N robots evenly spaced on a circle, neighbours d_e apart (radius
  R = d_e / (2 sin(π/N))), the leader at its front; the others go round it from the leader,
  left for odd k, right for even k, each child the next on the circle after its parent
  (slot k − 2, the leader for k <= 2). N = 2: the second robot d_e behind the leader.
* ``grid``: C = ⌈√N⌉ columns d_e apart and ⌈N / C⌉ rows d_e apart; the leader in the front
  row's middle column (the ⌊(C−1)/2⌋-th from the left), the front row filled from it
  outwards (left, then right, alternately), each child d_e beside its neighbour nearer
  the leader; every later row behind the front row, column by column in the same order
  (a short last row is centred like the front row), each child d_e behind the slot in
  front of it.

Which way a shape lies on the fleet (:data:`ORIENT`, used with PCA, NAO eq. 12): a
``depth`` shape is laid with its facing axis along the fleet's principal axis (the
papers' pyramid), a ``width`` shape with its left-right axis along it (its wider
direction: line, wedge, grid).
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from agent.core.formation.shape.pyramid import (
    check_geometry,
    parents,
    right_children,
    slot_positions,
)
from agent.core.formation.shape.tree import Slots, compose

#: The wedge's arms: this far off the backward axis (rad).
WEDGE_ANGLE = math.radians(45.0)

#: How the fleet's principal axis lies on each built-in (see the module doc).
ORIENT = {
    "pyramid": "depth",
    "line": "width",
    "column": "depth",
    "wedge": "width",
    "circle": "depth",
    "grid": "width",
}

NAMES = tuple(ORIENT)


def _check_n(n: int) -> int:
    if isinstance(n, bool) or not isinstance(n, int | np.integer) or n < 1:
        raise ValueError(f"number of robots must be an int >= 1, got {n!r}")
    return int(n)


def _slots(parent: np.ndarray, distance: np.ndarray, angle: np.ndarray) -> Slots:
    parent = np.asarray(parent, dtype=np.int64)
    distance = np.asarray(distance, dtype=np.float64)
    angle = np.asarray(angle, dtype=np.float64)
    distance[0] = angle[0] = 0.0
    return Slots(parent, distance, angle, compose(parent, distance, angle))


def pyramid(n: int, d_e: float, phi_e: float) -> Slots:
    """AUV eqs. 5-7 (module doc); positions exactly :func:`pyramid.slot_positions`."""
    n = _check_n(n)
    pos = slot_positions(n, d_e, phi_e)  # checks d_e and φ_e
    k = np.arange(n)
    right = right_children(k)
    angle = np.where(right, phi_e - math.pi, math.pi - phi_e)
    angle[0] = 0.0
    distance = np.full(n, float(d_e))
    distance[0] = 0.0
    return Slots(parents(k), distance, angle, pos)


def _two_arms(n: int, d_e: float, left: float) -> Slots:
    """Slot k >= 1 on the left arm (k odd, angle ``left``) or the right one (k even, angle
    −``left``), d_e from slot k − 2 (the leader for k <= 2)."""
    k = np.arange(n)
    parent = np.where(k <= 2, 0, k - 2)
    parent[0] = -1
    angle = np.where(k % 2 == 1, left, -left)
    return _slots(parent, np.full(n, float(d_e)), angle)


def line(n: int, d_e: float, phi_e: float) -> Slots:
    """Side by side, the leader in the middle (module doc)."""
    check_geometry(d_e, phi_e)
    return _two_arms(_check_n(n), d_e, math.pi / 2)


def wedge(n: int, d_e: float, phi_e: float) -> Slots:
    """A V with its apex, the leader, ahead (module doc)."""
    check_geometry(d_e, phi_e)
    return _two_arms(_check_n(n), d_e, math.pi - WEDGE_ANGLE)


def column(n: int, d_e: float, phi_e: float) -> Slots:
    """One behind the other (module doc)."""
    check_geometry(d_e, phi_e)
    n = _check_n(n)
    k = np.arange(n)
    return _slots(k - 1, np.full(n, float(d_e)), np.full(n, math.pi))


def circle(n: int, d_e: float, phi_e: float) -> Slots:
    """Evenly spaced on a circle, neighbours d_e apart, the leader at the front (module
    doc). The chord from the (j−1)-th to the j-th robot round the left side points
    along the circle's tangent at their middle, ψ_m = π/2 + (j − ½)·2π/N, so its angle is
    ψ_m; on the right side it is ψ_m + π with ψ_m = π/2 − (j − ½)·2π/N."""
    check_geometry(d_e, phi_e)
    n = _check_n(n)
    k = np.arange(n)
    step = 2.0 * math.pi / n
    j = (k + 1) // 2  # steps round the circle from the leader
    left = k % 2 == 1
    angle = np.where(left, math.pi / 2 + (j - 0.5) * step, math.pi / 2 - (j - 0.5) * step + math.pi)
    angle = np.remainder(angle + math.pi, 2.0 * math.pi) - math.pi
    parent = np.where(k <= 2, 0, k - 2)
    parent[0] = -1
    return _slots(parent, np.full(n, float(d_e)), angle)


def grid_columns(n: int) -> int:
    """C = ⌈√N⌉, the grid's column count."""
    r = math.isqrt(n)
    return r if r * r == n else r + 1


def grid(n: int, d_e: float, phi_e: float) -> Slots:
    """⌈√N⌉ columns, rows behind the leader's front row (module doc)."""
    check_geometry(d_e, phi_e)
    n = _check_n(n)
    cols = grid_columns(n)
    c0 = (cols - 1) // 2
    seq = [c0]  # the columns in filling order: from the leader's outwards, left first
    for m in range(1, cols):
        seq += [c for c in (c0 - m, c0 + m) if 0 <= c < cols]
    rank = {c: i for i, c in enumerate(seq)}
    parent = np.empty(n, dtype=np.int64)
    angle = np.empty(n, dtype=np.float64)
    for k in range(n):
        row, c = divmod(k, cols)
        col = seq[c]
        if row > 0:  # behind the slot in front of it
            parent[k], angle[k] = k - cols, math.pi
        elif col == c0:
            parent[k], angle[k] = -1, 0.0
        else:  # beside its neighbour nearer the leader: that one's right (left) side
            towards = col + 1 if col < c0 else col - 1
            parent[k] = rank[towards]
            angle[k] = math.pi / 2 if col < c0 else -math.pi / 2
    return _slots(parent, np.full(n, float(d_e)), angle)


RULES: dict[str, Callable[[int, float, float], Slots]] = {
    "pyramid": pyramid,
    "line": line,
    "column": column,
    "wedge": wedge,
    "circle": circle,
    "grid": grid,
}
