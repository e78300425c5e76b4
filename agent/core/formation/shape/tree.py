"""A formation as a tree of slots: the leader at the root, every other slot at a distance
and an angle from its parent (the AUV paper's pattern, II: "each robot keeps its parent at
d_e and φ_e"; here any distance and angle per slot, so that shapes other than the pyramid
are data).

Conventions (one for every shape):

* the *shape frame* is the pyramid frame of NAO eqs. 12-13: y forward (the facing axis
  every robot turns to once it holds its slot), x to the right of it;
* every robot of a held formation faces the axis, so a parent's own frame is the shape
  frame moved to the parent: a slot's ``angle`` (rad) is measured counter-clockwise from
  the parent's facing (0 ahead, π/2 to its left, π behind, −π/2 to its right) and its
  offset from the parent is ``distance·(−sin angle, cos angle)``;
* slot 0 is the leader (order 0 of AUV eq. 5); every other slot's parent is an earlier
  slot, so any prefix of the slots is a tree (connected, acyclic) and a fleet of n robots
  takes slots 0..n−1 (robot orders, as in :mod:`plan`).

:func:`compose` turns the tree into slot positions (pointer jumping: log₂(depth) numpy
passes, deterministic, 10⁵ slots in milliseconds); :class:`Slots` holds both.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Slots:
    """n slots of a shape: per slot its parent (−1 for the leader), distance (m) and angle
    (rad) from that parent, and its position (n, 2) in the shape frame, leader at (0, 0)."""

    parent: np.ndarray
    distance: np.ndarray
    angle: np.ndarray
    positions: np.ndarray

    @property
    def n(self) -> int:
        return int(self.parent.shape[0])

    def edge(self, k: int) -> tuple[int, float, float]:
        """(parent, distance, angle) of slot ``k`` (``ValueError`` for the leader or out of
        range)."""
        if isinstance(k, bool) or not isinstance(k, int | np.integer) or not 0 < k < self.n:
            raise ValueError(f"slot must be a child slot in 1..{self.n - 1}, got {k!r}")
        return int(self.parent[k]), float(self.distance[k]), float(self.angle[k])


def offsets(distance: np.ndarray, angle: np.ndarray) -> np.ndarray:
    """(n, 2) offsets child − parent in the shape frame: ``distance·(−sin a, cos a)``."""
    d = np.asarray(distance, dtype=np.float64)
    a = np.asarray(angle, dtype=np.float64)
    return np.stack([-d * np.sin(a), d * np.cos(a)], axis=-1)


def check_tree(parent: np.ndarray, distance: np.ndarray, angle: np.ndarray) -> None:
    """``ValueError`` unless slot 0 is the root (parent −1) and every other slot's parent
    is an earlier slot, with a finite distance > 0 and a finite angle."""
    p = np.asarray(parent)
    n = p.shape[0]
    if n < 1 or p.ndim != 1 or np.shape(distance) != (n,) or np.shape(angle) != (n,):
        raise ValueError("a tree needs >= 1 slot and one parent, distance, angle per slot")
    if int(p[0]) != -1:
        raise ValueError("slot 0 (the leader) has no parent")
    k = np.arange(n)
    bad = np.flatnonzero((p[1:] < 0) | (p[1:] >= k[1:])) + 1
    if bad.size:
        raise ValueError(f"slot {int(bad[0])}: its parent must be an earlier slot")
    d = np.asarray(distance, dtype=np.float64)[1:]
    a = np.asarray(angle, dtype=np.float64)[1:]
    if not (np.all(np.isfinite(d)) and np.all(d > 0)):
        raise ValueError("every child's distance must be finite and > 0")
    if not np.all(np.isfinite(a)):
        raise ValueError("every child's angle must be finite")


def compose(parent: np.ndarray, distance: np.ndarray, angle: np.ndarray) -> np.ndarray:
    """Slot positions (n, 2) in the shape frame from the tree, leader at (0, 0).

    Pointer jumping: ``pos[i]`` holds the sum of the offsets from slot i up to (not
    including) ``anc[i]``; each pass adds the ancestor's sum and jumps to its ancestor,
    until every ``anc`` is the root's −1. The same tree gives bit-identical positions.
    """
    check_tree(parent, distance, angle)
    pos = offsets(distance, angle)
    pos[0] = 0.0
    anc = np.asarray(parent, dtype=np.int64).copy()
    while True:
        has = np.flatnonzero(anc >= 0)
        if has.size == 0:
            return pos
        up = anc[has]
        add = pos[up]  # the ancestors' sums before this pass
        nxt = anc[up]
        pos[has] += add
        anc[has] = nxt


def wrap(a: float) -> float:
    """An angle wrapped to (−π, π]."""
    w = math.remainder(a, 2.0 * math.pi)
    return math.pi if w == -math.pi else w
