"""Neighbour check: which detection of robot i is robot j (NAO paper 4.1.2, Algorithm 2, eq. 9).

All fixed frames are parallel, so if robot i sees robot j at ``(x_ij, y_ij)`` and j sees i
at ``(x_ji, y_ji)``, then ideally ``x_ij + x_ji = 0`` and ``y_ij + y_ji = 0``. Eq. 9 accepts
a detection pair when ``|ε_x| < ε``, ``|ε_y| < ε`` and ``ε_d = sqrt(ε_x² + ε_y²) < ε``
(the paper writes ``ε_x < ε``; we read it as the absolute value, the only reading under
which the test is symmetric), and among several candidates keeps the one with minimum ε_d.

Reading of Algorithm 2 (it overwrites IDs while looping, so the literal loop depends on
the order of the records): we make "the candidate with minimum ε_d" order-independent
by a *global greedy matching*: every detection pair that meets eq. 9 is a candidate;
candidates are taken in increasing ε_d (ties: lower owner id, then detection index, in
the canonical record order of :mod:`records`), after one addition of ours: a candidate
with more *mutual support* goes first. The paper's test alone is fooled when a third
robot stands half-way between i and j (i sees it at v, j sees it at -v: ε ≈ 0 for the
wrong pair); the support counts the other detections of i that j also reports at the
place the candidate implies (see :func:`mutual_support`), which the right pair wins; a candidate is accepted when neither of
its two detections is already used and the two robots are not already a neighbour pair.
The second pass of the paper ("re-going through all the neighbours with their IDs and
delete those neighbour pairs whose errors do not meet (9)") is then applied to the
accepted pairs.

Detections seen by one side only (the other robot missed it, or it is clutter or an
obstacle) satisfy no candidate and stay *unidentified*; they never break the check.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from agent.core.formation.frame.records import NeighborRecord, canonical_records

#: Default ε (metres). Two independent detections with the real NAOs' error (±0.1 m,
#: paper 5.2) sum to at most ~0.2 m; a wrong pair sums to the distance between two
#: *different* robots, >= ~0.5 m for robots spaced 0.6-1.2 m as in the paper. 0.35 m
#: sits between the two.
DEFAULT_EPSILON = 0.35


@dataclass(frozen=True)
class NeighbourPair:
    """Robots i < j identified as neighbours: detection ``a`` of i is j, ``b`` of j is i."""

    i: int
    j: int
    a: int
    b: int
    v_ij: np.ndarray  # (2,) position of j in fixed-i, as measured by i
    v_ji: np.ndarray  # (2,) position of i in fixed-j, as measured by j
    eps_d: float
    w_ij: float = 1.0  # weight of i's measurement (its confidence λ, 1 if unknown)
    w_ji: float = 1.0


@dataclass(frozen=True)
class NeighbourGraph:
    """The outcome of the neighbour check on a canonical record set."""

    ids: tuple[int, ...]  # every robot that sent a record, ascending
    pairs: tuple[NeighbourPair, ...]  # sorted by (i, j)
    records: tuple[NeighborRecord, ...]  # canonical records the indices refer to
    epsilon: float

    def neighbours(self, robot_id: int) -> list[int]:
        """Identified neighbours of ``robot_id``, ascending."""
        out = [p.j for p in self.pairs if p.i == robot_id]
        out += [p.i for p in self.pairs if p.j == robot_id]
        return sorted(out)

    def degree(self) -> dict[int, int]:
        deg = dict.fromkeys(self.ids, 0)
        for p in self.pairs:
            deg[p.i] += 1
            deg[p.j] += 1
        return deg

    def unidentified(self) -> list[tuple[int, int]]:
        """(robot id, detection index) of detections that no pair explains."""
        used = {(p.i, p.a) for p in self.pairs} | {(p.j, p.b) for p in self.pairs}
        return [
            (r.robot_id, a)
            for r in self.records
            for a in range(r.count)
            if (r.robot_id, a) not in used
        ]


def meets_eq9(v_ij: np.ndarray, v_ji: np.ndarray, epsilon: float) -> tuple[bool, float]:
    """Eq. 9 for one detection pair: (accepted, ε_d)."""
    ex = float(v_ij[0] + v_ji[0])
    ey = float(v_ij[1] + v_ji[1])
    ed = math.hypot(ex, ey)
    return (abs(ex) < epsilon and abs(ey) < epsilon and ed < epsilon), ed


def mutual_support(
    r2: np.ndarray, c2: np.ndarray, owner: np.ndarray, vecs: np.ndarray, epsilon: float
) -> np.ndarray:
    """Mutual support of each candidate pair (detection r2 of i <-> detection c2 of k).

    If the candidate is right, k sits at ``p_i + v_ia``, so every other detection of i,
    shifted by ``-v_ia``, should appear among k's detections when k sees it too. The
    support is the number of i's other detections that do (within ε).

    Vectorised per k (~5 000 candidates at 50 NAOs took 0.14 CPU s one query at
    a time, twice per agent, 50 agents at once): every candidate's shifted detections
    are queried against k's KD-tree in one call; the counts are the same integers.
    """
    out = np.zeros(r2.shape[0], dtype=np.int64)
    if r2.size == 0:
        return out
    order = np.argsort(owner, kind="stable")  # detections grouped by owner
    owners, start, count = np.unique(owner[order], return_index=True, return_counts=True)
    gi = np.searchsorted(owners, owner[r2])  # i's group, per candidate
    gk = np.searchsorted(owners, owner[c2])  # k's group
    m, base = count[gi], start[gi]  # i's detections per candidate, and where they begin
    for g in np.unique(gk):
        ts = np.flatnonzero(gk == g)
        seg = np.repeat(ts, m[ts])  # candidate of each query
        ends = np.cumsum(m[ts])
        offs = np.arange(int(ends[-1])) - np.repeat(ends - m[ts], m[ts])
        det = order[base[seg] + offs]  # i's detections, in i's order
        keep = det != r2[seg]
        seg, det = seg[keep], det[keep]
        if seg.size == 0:
            continue
        tree = cKDTree(vecs[order[start[g] : start[g] + count[g]]])
        dist, _ = tree.query(vecs[det] - vecs[r2[seg]], distance_upper_bound=epsilon)
        out += np.bincount(seg[np.isfinite(dist)], minlength=out.size)
    return out


def identify_neighbours(
    records: Sequence[NeighborRecord], epsilon: float = DEFAULT_EPSILON
) -> NeighbourGraph:
    """Algorithm 2 + second pass: identified neighbour pairs of a record set."""
    if not (isinstance(epsilon, int | float) and math.isfinite(epsilon) and epsilon > 0):
        raise ValueError(f"epsilon must be a finite number > 0, got {epsilon!r}")
    recs = canonical_records(records)
    if not recs:
        raise ValueError("no records")
    ids = tuple(r.robot_id for r in recs)
    owner_list: list[int] = []
    index_list: list[int] = []
    vecs_list: list[np.ndarray] = []
    weights_list: list[float] = []
    for ri, r in enumerate(recs):
        for a in range(r.count):
            owner_list.append(ri)
            index_list.append(a)
            vecs_list.append(r.neighbours[a])
            weights_list.append(1.0 if r.confidences is None else float(r.confidences[a]))
    pairs: list[NeighbourPair] = []
    if len(vecs_list) >= 2:
        owner = np.asarray(owner_list)
        vecs = np.asarray(vecs_list)
        # v_ij + v_ji small  <=>  v_ij close to -v_ji: a KD-tree pair query in O(D log D).
        tree_pos = cKDTree(vecs)
        tree_neg = cKDTree(-vecs)
        cand = tree_pos.sparse_distance_matrix(tree_neg, epsilon, output_type="ndarray")
        rows = cand["i"].astype(np.int64)
        cols = cand["j"].astype(np.int64)
        keep = (rows < cols) & (owner[rows] != owner[cols])
        rows, cols = rows[keep], cols[keep]
        sums = vecs[rows] + vecs[cols]
        ed = np.hypot(sums[:, 0], sums[:, 1])
        ok = (np.abs(sums[:, 0]) < epsilon) & (np.abs(sums[:, 1]) < epsilon) & (ed < epsilon)
        rows, cols, ed = rows[ok], cols[ok], ed[ok]
        # Order the candidates by ε_d, then by the owner (record) order, then detection.
        # Make (rows, cols) start with the lower owner so the tie-break is symmetric.
        swap = owner[rows] > owner[cols]
        r2 = np.where(swap, cols, rows)
        c2 = np.where(swap, rows, cols)
        support = mutual_support(r2, c2, owner, vecs, epsilon)
        order = np.lexsort((c2, r2, ed, -support))
        used: set[int] = set()
        linked: set[tuple[int, int]] = set()
        for t in order:
            da, db = int(r2[t]), int(c2[t])
            oa, ob = int(owner[da]), int(owner[db])
            if da in used or db in used or (oa, ob) in linked:
                continue
            used.add(da)
            used.add(db)
            linked.add((oa, ob))
            pairs.append(
                NeighbourPair(
                    i=ids[oa],
                    j=ids[ob],
                    a=index_list[da],
                    b=index_list[db],
                    v_ij=vecs[da].copy(),
                    v_ji=vecs[db].copy(),
                    eps_d=float(ed[t]),
                    w_ij=weights_list[da],
                    w_ji=weights_list[db],
                )
            )
    # Second pass (paper): re-check every identified pair with eq. 9, drop failures.
    checked = [p for p in pairs if meets_eq9(p.v_ij, p.v_ji, epsilon)[0]]
    checked.sort(key=lambda p: (p.i, p.j))
    return NeighbourGraph(ids=ids, pairs=tuple(checked), records=recs, epsilon=float(epsilon))
