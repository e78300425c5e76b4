"""How a plan is executed, and how long it takes (our addition to NAO paper 5.2.2 (iii) step 7).

Two execution rules, both safe for every plan built by :mod:`plan`:

* **waves** (the paper's "leader first, then the followers", generalised): a robot
  starts when every robot of every earlier wave holds its slot.
* **dependencies** (finer waits): a robot starts when every robot j of its
  ``after`` list has walked past the arc length ``after_at`` of its path (j's release
  point, :mod:`release`; j's whole length: j holds its slot, the rule before release
  points, still what ``after_at=None`` means). Every robot pair whose paths come within
  the clearance and may not walk together is ordered by this graph in an order that the
  safety rule allows, and the robot waited for is far enough along its path: the rest
  of its path clears the whole path of the waiting one; pairs that are never close, or
  may walk together, are free. ``after`` always points to earlier waves, so the wave
  rule (which waits for a superset: every robot of an earlier wave holds) stays safe.

:func:`check_dependencies` is the checker of the second rule (the first one is
:func:`safety.check_safety`). Makespans are in path-length units (metres at unit speed):
:func:`wave_makespan` is the sum over waves of the longest path of the wave;
:func:`dependency_makespan` the time the last robot holds when every robot starts as
soon as the robots it waits for are past their release points (unit speed: a robot
is at arc length s of its path s after it started);
:func:`capt_makespan` the longest straight path of the min-sum-of-squares assignment
(CAPT, Turpin et al. 2014: the synchronized makespan, our reference).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from scipy.optimize import linear_sum_assignment

from agent.core.formation.paths.geometry import seg_seg_dist
from agent.core.formation.waves.release import tail
from agent.core.formation.waves.safety import PairFlags, Violation, pair_flags


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


def release_points(
    lengths: np.ndarray,
    after: Sequence[Sequence[int]],
    after_at: Sequence[Sequence[float]] | None,
) -> list[list[float]]:
    """``after_at`` checked against ``after`` (None: every robot waited for must hold,
    its whole length): per entry a finite arc length in (0, that robot's length], else
    ``ValueError``."""
    lens = np.asarray(lengths, dtype=np.float64)
    if after_at is None:
        return [[float(lens[j]) for j in deps] for deps in after]
    if len(after_at) != len(after):
        raise ValueError(f"{len(after)} dependency lists but {len(after_at)} release lists")
    out = []
    for i, (deps, at) in enumerate(zip(after, after_at, strict=True)):
        if len(at) != len(deps):
            raise ValueError(f"robot {i} waits for {len(deps)} robots, {len(at)} release points")
        row = []
        for j, x in zip(deps, at, strict=True):
            x = float(x)
            if not (math.isfinite(x) and 0.0 < x <= lens[j] * (1 + 1e-12) + 1e-12):
                raise ValueError(
                    f"robot {i} waits for robot {j} at arc length {x!r}, "
                    f"not in (0, {float(lens[j])!r}]"
                )
            row.append(x)
        out.append(row)
    return out


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


def dependency_starts(
    lengths: np.ndarray,
    after: Sequence[Sequence[int]],
    waves: Sequence[int] | np.ndarray,
    after_at: Sequence[Sequence[float]] | None = None,
) -> np.ndarray:
    """Start time of every robot at unit speed: the latest time a robot it waits for
    passes its release point (``after_at``; None: holds its slot)."""
    lens = np.asarray(lengths, dtype=np.float64)
    n = lens.size
    _check_after(after, n)
    w = np.asarray(waves, dtype=np.int64)
    if w.shape != lens.shape:
        raise ValueError(f"{n} lengths but {w.size} wave numbers")
    at = release_points(lens, after, after_at)
    start = np.zeros(n)
    for i in np.argsort(w, kind="stable").tolist():
        deps = after[i]
        if any(w[j] >= w[i] for j in deps):
            raise ValueError(f"robot {i} waits for a robot of the same or a later wave")
        start[i] = max((start[j] + x for j, x in zip(deps, at[i], strict=True)), default=0.0)
    return start


def dependency_makespan(
    lengths: np.ndarray,
    after: Sequence[Sequence[int]],
    waves: Sequence[int] | np.ndarray,
    after_at: Sequence[Sequence[float]] | None = None,
) -> float:
    """When the last robot holds, under the dependency rule at unit speed."""
    lens = np.asarray(lengths, dtype=np.float64)
    start = dependency_starts(lens, after, waves, after_at)
    return float(np.max(start + lens)) if lens.size else 0.0


def _progress(
    a: int,
    b: int,
    after: Sequence[Sequence[int]],
    at: Sequence[Sequence[float]],
    waves: np.ndarray,
    full: bool,
) -> float:
    """How far robot a has walked, at least, when robot b starts: the largest release
    point of a that b or a robot b waits for (transitively) waits for; -1 if b does not
    wait for a. Without ``full``, b's own entry for a is enough when it is there. The
    search only follows robots of later waves than a's."""
    best = -1.0
    if a in after[b]:
        best = at[b][list(after[b]).index(a)]
        if not full:
            return best
    wa = waves[a]
    seen = {b}
    stack = [b]
    while stack:
        u = stack.pop()
        for v, x in zip(after[u], at[u], strict=True):
            if v == a:
                best = max(best, x)
            elif v not in seen and waves[v] > wa:
                seen.add(v)
                stack.append(v)
    return best


def _tail_clear(first: np.ndarray, walked: float, second: np.ndarray) -> float:
    """d(second, first[walked:]): the rest of the first path against the second."""
    p = tail(first, walked)
    q = np.asarray(second, dtype=np.float64).reshape(-1, 2)
    if p.shape[0] == 1:
        p = np.vstack([p, p])
    if q.shape[0] == 1:
        q = np.vstack([q, q])
    d = seg_seg_dist(p[:-1, None, :], p[1:, None, :], q[None, :-1, :], q[None, 1:, :])
    return float(np.min(d))


def check_dependencies(
    paths: Sequence[np.ndarray],
    after: Sequence[Sequence[int]],
    waves: Sequence[int] | np.ndarray,
    radius: float,
    flags: PairFlags | None = None,
    after_at: Sequence[Sequence[float]] | None = None,
) -> list[Violation]:
    """Every violation of the dependency rule (empty list = safe): a pair of robots whose
    paths come within 2·radius and that may not walk together must be ordered by
    ``after`` (transitively) in an order the clearance rule allows (the first one's
    path clears the second's start, and its target the second's path), and when the
    second starts the first must be past a point from which the rest of its path
    clears the second's whole path (``after_at``; None: the first holds its slot).
    Kinds: ``paths`` (not ordered), ``path-vs-standing`` (the order is not allowed),
    ``released-early`` (the release point is too early)."""
    if not (math.isfinite(radius) and radius > 0):
        raise ValueError(f"radius must be > 0, got {radius!r}")
    n = len(paths)
    _check_after(after, n)
    w = np.asarray(waves, dtype=np.int64)
    if w.shape != (n,):
        raise ValueError(f"{n} paths but {w.size} wave numbers")
    if n == 0:
        return []
    lens = path_lengths(paths)
    at = release_points(lens, after, after_at)
    f = pair_flags(paths, 2.0 * radius) if flags is None else flags
    out: list[Violation] = []
    for k in np.flatnonzero(~f.same_ok).tolist():
        a, b = int(f.a[k]), int(f.b[k])
        if b >= n:
            continue
        req = float(f.required[k])
        for first, second, ok, d_ok in ((a, b, f.ab_ok, f.d_ab), (b, a, f.ba_ok, f.d_ba)):
            g = _progress(first, second, after, at, w, full=False)
            if g < 0:
                continue
            if not ok[k]:
                out.append(Violation(int(w[second]), a, b, "path-vs-standing", float(d_ok[k]), req))
            elif g < lens[first]:
                d = _tail_clear(paths[first], g, paths[second])
                if d < req:
                    g = _progress(first, second, after, at, w, full=True)
                    d = _tail_clear(paths[first], g, paths[second])
                if d < req:
                    out.append(Violation(int(w[second]), a, b, "released-early", d, req))
            break
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
