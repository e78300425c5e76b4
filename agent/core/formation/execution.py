"""How a plan is executed, and how long it takes (our addition to NAO paper 5.2.2 (7)).

Two execution rules, both safe for every plan built by :mod:`plan`:

* **waves** (the paper's "leader first, then the followers", generalised): a robot
  starts when every robot of every earlier wave holds its slot.
* **dependencies**: a robot starts when every robot of its ``after`` list holds its slot
  (transitively, the ancestors of the robot in the ``after`` graph). Every robot pair
  whose paths come within the clearance and may not walk together is ordered by this
  graph in an order that the safety rule allows; pairs that are never close, or may walk
  together, are free. ``after`` always points to earlier waves, so the wave rule (which
  waits for a superset) stays safe too.

:func:`check_dependencies` is the checker of the second rule (the first one is
:func:`safety.check_safety`). Makespans are in path-length units (metres at unit speed):
:func:`wave_makespan` is the sum over waves of the longest path of the wave;
:func:`dependency_makespan` the longest chain of path lengths along ``after``;
:func:`capt_makespan` the longest straight path of the min-sum-of-squares assignment
(CAPT, Turpin et al. 2014: the synchronized makespan, our reference).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from scipy.optimize import linear_sum_assignment

from agent.core.formation.safety import PairFlags, Violation, pair_flags


def path_lengths(paths: Sequence[np.ndarray]) -> np.ndarray:
    """Length of every polyline."""
    out = np.empty(len(paths))
    for k, p in enumerate(paths):
        a = np.asarray(p, dtype=np.float64).reshape(-1, 2)
        out[k] = float(np.sum(np.hypot(*np.diff(a, axis=0).T))) if a.shape[0] > 1 else 0.0
    return out


def _check_after(after: Sequence[Sequence[int]], n: int) -> None:
    if len(after) != n:
        raise ValueError(f"{n} robots but {len(after)} dependency lists")
    for i, deps in enumerate(after):
        for j in deps:
            if isinstance(j, bool) or not isinstance(j, int | np.integer) or not 0 <= j < n:
                raise ValueError(f"robot {i} waits for {j!r}, not a robot row in [0, {n})")
            if j == i:
                raise ValueError(f"robot {i} waits for itself")


def wave_makespan(lengths: np.ndarray, waves: Sequence[int] | np.ndarray) -> float:
    """Sum over waves of the longest path in the wave."""
    w = np.asarray(waves, dtype=np.int64)
    lens = np.asarray(lengths, dtype=np.float64)
    if w.shape != lens.shape:
        raise ValueError(f"{lens.size} lengths but {w.size} wave numbers")
    if w.size == 0:
        return 0.0
    if np.any(w < 0):
        raise ValueError("wave numbers must be >= 0")
    top = np.zeros(int(w.max()) + 1)
    np.maximum.at(top, w, lens)
    return float(top.sum())


def dependency_makespan(
    lengths: np.ndarray, after: Sequence[Sequence[int]], waves: Sequence[int] | np.ndarray
) -> float:
    """Longest chain of path lengths along ``after`` (robots walk at unit speed)."""
    lens = np.asarray(lengths, dtype=np.float64)
    n = lens.size
    _check_after(after, n)
    w = np.asarray(waves, dtype=np.int64)
    if w.shape != lens.shape:
        raise ValueError(f"{n} lengths but {w.size} wave numbers")
    finish = np.zeros(n)
    for i in np.argsort(w, kind="stable").tolist():
        deps = after[i]
        if any(w[j] >= w[i] for j in deps):
            raise ValueError(f"robot {i} waits for a robot of the same or a later wave")
        start = max((finish[j] for j in deps), default=0.0)
        finish[i] = start + lens[i]
    return float(finish.max()) if n else 0.0


def _is_ancestor(
    a: int, b: int, after: Sequence[Sequence[int]], waves: np.ndarray, direct: list[set[int]]
) -> bool:
    """Does b wait for a, directly or through others? (search pruned by wave)"""
    if a in direct[b]:
        return True
    wa = waves[a]
    seen = {b}
    stack = [b]
    while stack:
        u = stack.pop()
        for v in after[u]:
            if v == a:
                return True
            if v not in seen and waves[v] > wa:
                seen.add(v)
                stack.append(v)
    return False


def check_dependencies(
    paths: Sequence[np.ndarray],
    after: Sequence[Sequence[int]],
    waves: Sequence[int] | np.ndarray,
    radius: float,
    flags: PairFlags | None = None,
) -> list[Violation]:
    """Every violation of the dependency rule (empty list = safe): a pair of robots whose
    paths come within 2·radius and that may not walk together must be ordered by
    ``after`` (transitively) in an order the clearance rule allows."""
    if not (math.isfinite(radius) and radius > 0):
        raise ValueError(f"radius must be > 0, got {radius!r}")
    n = len(paths)
    _check_after(after, n)
    w = np.asarray(waves, dtype=np.int64)
    if w.shape != (n,):
        raise ValueError(f"{n} paths but {w.size} wave numbers")
    if n == 0:
        return []
    f = pair_flags(paths, 2.0 * radius) if flags is None else flags
    direct = [set(d) for d in after]
    out: list[Violation] = []
    for k in np.flatnonzero(~f.same_ok).tolist():
        a, b = int(f.a[k]), int(f.b[k])
        if b >= n:
            continue
        req = float(f.required[k])
        if _is_ancestor(a, b, after, w, direct):
            if not f.ab_ok[k]:
                out.append(Violation(int(w[b]), a, b, "path-vs-standing", float(f.d_ab[k]), req))
        elif _is_ancestor(b, a, after, w, direct):
            if not f.ba_ok[k]:
                out.append(Violation(int(w[a]), a, b, "path-vs-standing", float(f.d_ba[k]), req))
        else:
            out.append(Violation(int(w[a]), a, b, "paths", float(f.d_path[k]), req))
    return out


def capt_assignment(starts: np.ndarray, slots: np.ndarray) -> np.ndarray:
    """perm[robot] = slot minimising the sum of squared distances (CAPT)."""
    d = starts[:, None, :] - slots[None, :, :]
    rows, cols = linear_sum_assignment(np.einsum("ijk,ijk->ij", d, d))
    perm = np.empty(starts.shape[0], dtype=np.int64)
    perm[rows] = cols
    return perm


def capt_makespan(starts: np.ndarray, slots: np.ndarray) -> float:
    """Longest straight path of the CAPT assignment of ``starts`` to ``slots`` (any order)."""
    s = np.asarray(starts, dtype=np.float64)
    f = np.asarray(slots, dtype=np.float64)
    if s.ndim != 2 or s.shape[1] != 2 or f.shape != s.shape or s.shape[0] == 0:
        raise ValueError(f"starts {s.shape} and slots {f.shape} must both be (N, 2), N >= 1")
    perm = capt_assignment(s, f)
    return float(np.max(np.hypot(*(s - f[perm]).T)))


def optimal_total(starts: np.ndarray, slots: np.ndarray) -> float:
    """Smallest total straight path of any assignment of ``starts`` to ``slots``."""
    s = np.asarray(starts, dtype=np.float64)
    f = np.asarray(slots, dtype=np.float64)
    if s.ndim != 2 or s.shape[1] != 2 or f.shape != s.shape or s.shape[0] == 0:
        raise ValueError(f"starts {s.shape} and slots {f.shape} must both be (N, 2), N >= 1")
    cost = np.hypot(s[:, None, 0] - f[None, :, 0], s[:, None, 1] - f[None, :, 1])
    rows, cols = linear_sum_assignment(cost)
    return float(cost[rows, cols].sum())
