"""Assignment of robots to pyramid slots (NAO paper 4.2, Lemma 1, eq. 11; AUV III.C steps 1-6).

Everything here works in the pyramid frame (x_p to the right, y_p = facing axis).
Robots are given in ascending-id order; the result ``perm`` maps robot row -> slot.

``paper`` - the combined-subgroup strategy, O(n log n), as we read it:

1. The leader is the robot nearest slot 0 (tie: lowest id); it takes slot 0.
2. (ranking criterion i / AUV steps 1-2) The other robots and slots are split by the
   principal axis into a left and a right group with ``|N_L - N_R| <= 1`` and equal
   sizes on both sides: the ``n_L`` robots (slots) of smallest x_p go left, which is
   "re-assigning the positions near the axis" when the raw split is uneven. ``n_L`` is
   ``M // 2`` for M = N - 1 followers, plus one when M is odd and strictly more
   robots start left of the axis than right of it. Ties in x_p: larger y_p first, then
   lower id / lower slot order.
3. (criterion ii / AUV steps 1-4) Each group is ranked top to bottom (y_p descending),
   left to right (x_p ascending). Slots of the same layer (equal y_p, AUV step 3) are
   ranked by x, and the initial positions at the same ranks are re-ranked by x; then
   every run of initial positions whose y_p lie within ε_y of the run's first one (AUV
   step 4) is ranked by x, and the slots at the same ranks are re-ranked by x. ε_y is
   taken inside the AUV's bounds ``(d_max - d_e)(1 - cos(φ_e/2)) < ε_y < d_e cos(φ_e/2)``:
   ``ε_y = min(1.01·lower + 1e-9, 0.5·upper)``.
4. (AUV step 5) Consecutive ranks form sub-groups of two (the last may be one); the
   k-th initial sub-group and the k-th slot sub-group form a combined sub-group.
5. (Lemma 1 / AUV step 6) Inside a combined sub-group of two, the pairing with the
   smaller sum of distances wins; equal sums -> the smaller maximum; still equal ->
   rank order.

``optimal`` - eq. 11 solved exactly: ``scipy.optimize.linear_sum_assignment`` on the
Euclidean distances (all N robots; the leader is whoever gets slot 0). O(n³).

``capt`` - the same on squared distances (the CAPT assignment of Turpin et al.).

``bottleneck`` - the longest path first, then the total (in the spirit of CAT-ORA, 2024):
the smallest achievable longest distance B* (binary search over the distinct distances,
a perfect matching on the pairs within the bound by ``maximum_bipartite_matching``), then
the min-sum assignment among the pairs within B*. O(n² log n + n³).
"""

from __future__ import annotations

import math

import numpy as np
from scipy.optimize import linear_sum_assignment

from agent.core.formation.paths.close_pairs import candidate_segment_pairs
from agent.core.formation.paths.geometry import paths_cross

STRATEGIES = ("paper", "optimal", "capt", "bottleneck")


def _rank(pts: np.ndarray, ids: np.ndarray) -> np.ndarray:
    """Indices sorted top to bottom (y desc), then left to right (x asc), then id."""
    return np.lexsort((ids, pts[:, 0], -pts[:, 1]))


def _runs(y: np.ndarray, tol: float) -> list[tuple[int, int]]:
    """Maximal runs [a, b) of a descending sequence with y[a] - y[k] < tol."""
    out: list[tuple[int, int]] = []
    a = 0
    n = len(y)
    while a < n:
        b = a + 1
        while b < n and y[a] - y[b] < tol:
            b += 1
        if b - a > 1:
            out.append((a, b))
        a = b
    return out


def _reorder_by_x(idx: np.ndarray, pts: np.ndarray, ids: np.ndarray, a: int, b: int) -> None:
    seg = idx[a:b]
    order = np.lexsort((ids[seg], pts[seg, 0]))
    idx[a:b] = seg[order]


def _match_group(
    r_idx: np.ndarray,
    s_idx: np.ndarray,
    starts: np.ndarray,
    slots: np.ndarray,
    rid: np.ndarray,
    sid: np.ndarray,
    eps_y: float,
    perm: np.ndarray,
) -> None:
    r = r_idx[_rank(starts[r_idx], rid[r_idx])]
    s = s_idx[_rank(slots[s_idx], sid[s_idx])]
    # AUV step 3: equal-y slots (one layer) -> both reordered by x at the same ranks.
    layer_tol = 1e-9 * max(1.0, float(np.max(np.abs(slots[:, 1]))) if len(slots) else 1.0)
    for a, b in _runs(slots[s, 1], layer_tol):
        _reorder_by_x(s, slots, sid, a, b)
        _reorder_by_x(r, starts, rid, a, b)
    # AUV step 4: near-equal-y initial positions -> both reordered by x.
    for a, b in _runs(starts[r, 1], eps_y):
        _reorder_by_x(r, starts, rid, a, b)
        _reorder_by_x(s, slots, sid, a, b)
    # Steps 5-6: combined sub-groups of two, matched by Lemma 1.
    for k in range(0, len(r), 2):
        if k + 1 >= len(r):
            perm[r[k]] = s[k]
            break
        p, q = starts[r[k]], starts[r[k + 1]]
        f, g = slots[s[k]], slots[s[k + 1]]
        d_pf, d_qg = float(np.hypot(*(p - f))), float(np.hypot(*(q - g)))
        d_pg, d_qf = float(np.hypot(*(p - g))), float(np.hypot(*(q - f)))
        same, cross = d_pf + d_qg, d_pg + d_qf
        tol = 1e-12 * max(1.0, same, cross)
        swap = cross < same - tol or (
            abs(cross - same) <= tol and max(d_pg, d_qf) < max(d_pf, d_qg) - tol
        )
        if swap:
            perm[r[k]], perm[r[k + 1]] = s[k + 1], s[k]
        else:
            perm[r[k]], perm[r[k + 1]] = s[k], s[k + 1]


def paper_assignment(starts: np.ndarray, slots: np.ndarray, d_e: float, phi_e: float) -> np.ndarray:
    """The combined-subgroup strategy (see module doc). Returns perm[robot] = slot."""
    n = starts.shape[0]
    perm = np.full(n, -1, dtype=np.int64)
    d0 = np.sum((starts - slots[0]) ** 2, axis=1)
    leader = int(np.flatnonzero(d0 == d0.min())[0])
    perm[leader] = 0
    if n == 1:
        return perm
    rid = np.arange(n)
    sid = np.arange(n)
    robots = np.array([k for k in range(n) if k != leader], dtype=np.int64)
    slot_idx = np.arange(1, n, dtype=np.int64)
    m = n - 1
    left_count = int(np.sum(starts[robots, 0] < 0))
    right_count = int(np.sum(starts[robots, 0] > 0))
    n_left = m // 2 + (1 if (m % 2 == 1 and left_count > right_count) else 0)
    r_sorted = robots[np.lexsort((rid[robots], -starts[robots, 1], starts[robots, 0]))]
    s_sorted = slot_idx[np.lexsort((sid[slot_idx], -slots[slot_idx, 1], slots[slot_idx, 0]))]
    # ε_y inside the AUV bounds (step 4).
    d_max = (
        float(np.max(np.hypot(*(starts[:, None, :] - slots[None, :, :]).T)))
        if n <= 2000
        else (_dmax_bound(starts, slots))
    )
    lower = max(d_max - d_e, 0.0) * (1.0 - math.cos(phi_e / 2.0))
    upper = d_e * math.cos(phi_e / 2.0)
    eps_y = min(1.01 * lower + 1e-9, 0.5 * upper)
    for grp_r, grp_s in (
        (r_sorted[:n_left], s_sorted[:n_left]),
        (r_sorted[n_left:], s_sorted[n_left:]),
    ):
        if len(grp_r):
            _match_group(grp_r, grp_s, starts, slots, rid, sid, eps_y, perm)
    return perm


def _dmax_bound(starts: np.ndarray, slots: np.ndarray) -> float:
    """max distance between a start and a slot, via the extreme points of both sets (O(n))."""
    # the farthest pair between two sets involves hull vertices; bounding boxes suffice
    # for a deterministic upper bound that is tight to within a factor sqrt(2).
    lo = np.minimum(starts.min(axis=0), slots.min(axis=0))
    hi = np.maximum(starts.max(axis=0), slots.max(axis=0))
    return float(np.hypot(*(hi - lo)))


def optimal_assignment(starts: np.ndarray, slots: np.ndarray, squared: bool = False) -> np.ndarray:
    diff = starts[:, None, :] - slots[None, :, :]
    cost = np.einsum("ijk,ijk->ij", diff, diff)
    if not squared:
        cost = np.sqrt(cost)
    rows, cols = linear_sum_assignment(cost)
    perm = np.full(starts.shape[0], -1, dtype=np.int64)
    perm[rows] = cols
    return perm


def _has_perfect_matching(ok: np.ndarray) -> bool:
    from scipy.sparse import csr_matrix
    from scipy.sparse.csgraph import maximum_bipartite_matching

    match = maximum_bipartite_matching(csr_matrix(ok), perm_type="column")
    return bool(np.all(match >= 0))


def _distances(starts: np.ndarray, slots: np.ndarray) -> np.ndarray:
    return np.asarray(
        np.hypot(starts[:, None, 0] - slots[None, :, 0], starts[:, None, 1] - slots[None, :, 1])
    )


def min_bottleneck(starts: np.ndarray, slots: np.ndarray) -> float:
    """The smallest longest distance B* of any assignment (see module doc)."""
    cost = _distances(starts, slots)
    vals = np.unique(cost)
    lo, hi = 0, vals.size - 1  # vals[hi] (the largest) always admits a perfect matching
    while lo < hi:
        mid = (lo + hi) // 2
        if _has_perfect_matching(cost <= vals[mid]):
            hi = mid
        else:
            lo = mid + 1
    return float(vals[lo])


def bounded_assignment(starts: np.ndarray, slots: np.ndarray, bound: float) -> np.ndarray:
    """Min-sum assignment among the pairs no longer than ``bound`` (>= B*, else the
    longer pairs are used as little as the min-sum allows). perm[robot] = slot."""
    cost = _distances(starts, slots)
    big = 1.0 + float(cost.sum())
    rows, cols = linear_sum_assignment(np.where(cost <= bound, cost, big + cost))
    perm = np.full(starts.shape[0], -1, dtype=np.int64)
    perm[rows] = cols
    return perm


def bottleneck_assignment(starts: np.ndarray, slots: np.ndarray) -> np.ndarray:
    """Min-sum assignment among the pairs no longer than B* (see module doc)."""
    return bounded_assignment(starts, slots, min_bottleneck(starts, slots))


def assign(
    starts: np.ndarray, slots: np.ndarray, strategy: str, d_e: float, phi_e: float
) -> np.ndarray:
    """perm[robot row] = slot index, by ``strategy`` (paper | optimal | capt | bottleneck)."""
    s = np.asarray(starts, dtype=np.float64)
    f = np.asarray(slots, dtype=np.float64)
    if s.ndim != 2 or s.shape[1] != 2 or f.shape != s.shape:
        raise ValueError(f"starts {s.shape} and slots {f.shape} must both be (N, 2)")
    if strategy == "paper":
        perm = paper_assignment(s, f, d_e, phi_e)
    elif strategy == "optimal":
        perm = optimal_assignment(s, f)
    elif strategy == "capt":
        perm = optimal_assignment(s, f, squared=True)
    elif strategy == "bottleneck":
        perm = bottleneck_assignment(s, f)
    else:
        raise ValueError(f"strategy must be one of {STRATEGIES}, got {strategy!r}")
    if sorted(perm.tolist()) != list(range(len(perm))):  # pragma: no cover - invariant
        raise ValueError("internal error: assignment is not a permutation")
    return perm


def uncross(
    starts: np.ndarray, targets: np.ndarray, scale: float, max_rounds: int = 100
) -> np.ndarray:
    """Lemma 1 as a repair: swap the targets of every two straight paths that cross.

    For two properly crossing segments p->f, p'->f', the pairing p->f', p'->f is strictly
    shorter (triangle inequality), so the total length decreases at every swap and the
    loop ends. Crossing pairs are found by spatial hashing (``scale`` sets the sampling,
    e.g. d_e) and swapped in ascending row order, each robot at most once per round.
    Returns ``perm`` with ``targets[perm]`` the repaired targets.
    """
    n = starts.shape[0]
    perm = np.arange(n)
    if n < 2:
        return perm
    owner = np.arange(n)
    for _ in range(max_rounds):
        t = targets[perm]
        s_idx, t_idx = candidate_segment_pairs(starts, t, owner, scale)
        if s_idx.size == 0:
            break
        cross = paths_cross(starts[s_idx], t[s_idx], starts[t_idx], t[t_idx])
        pairs = np.stack([s_idx[cross], t_idx[cross]], axis=1)
        if pairs.shape[0] == 0:
            break
        pairs = pairs[np.lexsort((pairs[:, 1], pairs[:, 0]))]
        touched = np.zeros(n, dtype=bool)
        for a, b in pairs:
            if touched[a] or touched[b]:
                continue
            touched[a] = touched[b] = True
            perm[[a, b]] = perm[[b, a]]
    return perm
