"""The planar pyramid pattern and its frame (AUV paper II, III.B eqs. 5-8; NAO paper 4.2 eqs. 12-13).

Definition (AUV II): the leader has order 0; layer L (1-based) holds L robots with orders
L(L-1)/2 ... L(L+1)/2 - 1, filled left to right; every robot but the leader has a parent
in the layer before, at distance d_e and at angle φ_e off the backward axis.

* :func:`layer_of` is eq. 5, :func:`parent_of` is eq. 6 (the last robot of a *full*
  layer is the right-back child of the previous layer's last robot; every other robot
  is the left-back child of the robot with the same index in the layer before).
* :func:`slot_positions` applies eq. 7 (``x_child = x_parent ∓ d_e sin φ_e``,
  ``y_child = y_parent - d_e cos φ_e``) from the leader at (0, 0). A partial last layer
  is therefore left-aligned, exactly as eqs. 5-7 define it (the papers only show
  triangular N).

Pyramid frame (eq. 13): origin o_p = mean of the start positions, y_p = the pyramid
axis at angle β in the common frame, x_p = y_p turned -90° (to the right of the
facing direction): ``c = x_p·(sin β, -cos β) + y_p·(cos β, sin β) + o_p``.

* ``pca`` (eq. 12): β = direction of the eigenvector of the larger eigenvalue of the
  position covariance. Sign (the papers leave it open): the pyramid has one robot in
  front and many behind, so its front is the sparse tail of the distribution; we point
  y_p so that the third central moment of the projections is >= 0. If that moment is
  ~0 (|m3| <= 1e-9·σ³), y_p points to the half-plane of positive common y (then +x).
  N = 1 or all starts equal: β = π/2.
* ``north`` (AUV III.B.2.a): β = π/2, the common frame's y axis. It is the axis of the
  circle pattern, where the robot at 90° of the common frame is the leader and its y axis
  (all fixed frames are parallel) is the pyramid's; the circle itself is walked by
  ``PlanParams.orientation == "cp"`` (:mod:`circle_pattern`).

Placement (the papers give the leader's y only as ``y_min + layer_all·d·θ``, which is
not dimensionally sound): the slots are translated so that their centroid is o_p,
which is the translation that minimises Σ|slot - start|² for the chosen axis.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

#: How the frame's axis is chosen: the principal axis (NAO eq. 12) or the common frame's
#: north (the circle pattern's axis, AUV III.B.2.a).
AXES = ("pca", "north")


def layer_of(order: int) -> int:
    """Eq. 5: the 1-based layer of the robot with this order."""
    if isinstance(order, bool) or not isinstance(order, int | np.integer) or order < 0:
        raise ValueError(f"order must be an int >= 0, got {order!r}")
    tmp = math.isqrt(1 + 8 * int(order))
    if tmp % 2 == 0:
        tmp -= 1
    return (tmp - 1) // 2 + 1


def parent_of(order: int) -> int:
    """Eq. 6: the parent's order (-1 for the leader)."""
    layer = layer_of(order)
    if layer == 1:
        return -1
    last_in_layer = layer * (layer + 1) // 2 - 1
    if order == last_in_layer:
        return int(order) - layer
    return int(order) - (layer - 1)


def layers(order: np.ndarray) -> np.ndarray:
    """Eq. 5 on an array of orders (see :func:`layer_of`): exact integer fix-up of the
    float square root."""
    o = np.asarray(order, dtype=np.int64)
    t = np.floor(np.sqrt(1.0 + 8.0 * o)).astype(np.int64)
    t = np.where((t + 1) ** 2 <= 1 + 8 * o, t + 1, t)
    t = np.where(t * t > 1 + 8 * o, t - 1, t)
    t = np.where(t % 2 == 0, t - 1, t)
    return np.asarray((t - 1) // 2 + 1)


def parents(order: np.ndarray) -> np.ndarray:
    """Eq. 6 on an array of orders (see :func:`parent_of`), -1 for the leader."""
    o = np.asarray(order, dtype=np.int64)
    layer = layers(o)
    last = layer * (layer + 1) // 2 - 1
    par = np.where(o == last, o - layer, o - (layer - 1))
    return np.asarray(np.where(layer == 1, -1, par))


def right_children(order: np.ndarray) -> np.ndarray:
    """Per order, whether it is its parent's right-back child (eq. 6: the last robot of
    a full layer, the leader excepted); every other child is a left-back one."""
    o = np.asarray(order, dtype=np.int64)
    layer = layers(o)
    return np.asarray((layer > 1) & (o == layer * (layer + 1) // 2 - 1))


def slot_positions(n: int, d_e: float, phi_e: float) -> np.ndarray:
    """(n, 2) slots in the pyramid frame with the leader at (0, 0), by eq. 7 from parents."""
    if isinstance(n, bool) or not isinstance(n, int | np.integer) or n < 1:
        raise ValueError(f"number of robots must be an int >= 1, got {n!r}")
    check_geometry(d_e, phi_e)
    orders = np.arange(int(n))
    t = np.floor(np.sqrt(1.0 + 8.0 * orders)).astype(np.int64)
    # exact integer fix-up of the float sqrt, then eq. 5
    t = np.where((t + 1) ** 2 <= 1 + 8 * orders, t + 1, t)
    t = np.where(t * t > 1 + 8 * orders, t - 1, t)
    t = np.where(t % 2 == 0, t - 1, t)
    layer = (t - 1) // 2 + 1
    k = orders - layer * (layer - 1) // 2  # index inside the layer, 0 = leftmost
    sx = d_e * math.sin(phi_e)
    cy = d_e * math.cos(phi_e)
    x = (2.0 * k - (layer - 1)) * sx
    y = -(layer - 1) * cy
    return np.stack([x, y], axis=-1).astype(np.float64)


def check_geometry(d_e: float, phi_e: float) -> None:
    if not (isinstance(d_e, int | float) and math.isfinite(d_e) and d_e > 0):
        raise ValueError(f"d_e must be a finite distance > 0, got {d_e!r}")
    if not (isinstance(phi_e, int | float) and math.isfinite(phi_e) and 0 < phi_e < math.pi / 2):
        raise ValueError(f"phi_e must lie in (0, 90°), got {phi_e!r} rad")


@dataclass(frozen=True)
class PyramidFrame:
    origin: np.ndarray  # (2,) o_p in the common frame
    beta: float  # angle of y_p (the facing axis) in the common frame, rad

    def to_common(self, pts: np.ndarray) -> np.ndarray:
        sb, cb = math.sin(self.beta), math.cos(self.beta)
        p = np.asarray(pts, dtype=np.float64)
        x = p[..., 0] * sb + p[..., 1] * cb + self.origin[0]
        y = -p[..., 0] * cb + p[..., 1] * sb + self.origin[1]
        return np.stack([x, y], axis=-1)

    def to_pyramid(self, pts: np.ndarray) -> np.ndarray:
        sb, cb = math.sin(self.beta), math.cos(self.beta)
        d = np.asarray(pts, dtype=np.float64) - self.origin
        x = d[..., 0] * sb - d[..., 1] * cb
        y = d[..., 0] * cb + d[..., 1] * sb
        return np.stack([x, y], axis=-1)


def pca_axis(positions: np.ndarray) -> float:
    """β by PCA (eq. 12) with the deterministic sign described in the module doc."""
    pts = np.asarray(positions, dtype=np.float64)
    if pts.shape[0] < 2:
        return math.pi / 2
    mean = pts.mean(axis=0)
    d = pts - mean
    cov = d.T @ d / pts.shape[0]
    if not np.any(cov):
        return math.pi / 2
    w, v = np.linalg.eigh(cov)
    u = v[:, int(np.argmax(w))]
    proj = d @ u
    sigma = math.sqrt(max(float(np.mean(proj**2)), 0.0))
    m3 = float(np.mean(proj**3))
    if abs(m3) > 1e-9 * sigma**3:
        if m3 < 0:
            u = -u
    elif u[1] < 0 or (u[1] == 0 and u[0] < 0):
        u = -u
    return math.atan2(float(u[1]), float(u[0]))


def pyramid_frame(positions: np.ndarray, orientation: str = "pca") -> PyramidFrame:
    pts = np.asarray(positions, dtype=np.float64)
    if orientation == "pca":
        beta = pca_axis(pts)
    elif orientation == "north":
        beta = math.pi / 2
    else:
        raise ValueError(f"orientation must be one of {AXES}, got {orientation!r}")
    return PyramidFrame(origin=pts.mean(axis=0), beta=beta)


def nearest_to(point: np.ndarray, positions: np.ndarray) -> int:
    """Index of the position nearest ``point`` (ties: lowest index = lowest id)."""
    d2 = np.sum((np.asarray(positions) - np.asarray(point)) ** 2, axis=1)
    return int(np.flatnonzero(d2 == d2.min())[0])
