"""Via points for the wave scheduler: detour candidates, their scores, and which robots
can matter to a detour (NAO paper 4.2 and Lemma 1: straight paths, bent only where the
safety rule of :mod:`safety` needs it; the resolution step of :mod:`scheduler`).

A robot whose pair can go in no order, that sits on a precedence cycle, or a leader
whose path is blocked, gets one via point on the side of its straight path:
:func:`detour_candidates` are perpendicular to the path at its middle, quarter and
three-quarter points, offsets 1, 1.5, 2, 3, 4.5, 6 × c, left before right. Each is
scored (:func:`score_paths`) by the clearance it still misses against the robots near
it and by the pairs that still may not share a wave; the scheduler keeps the candidate
with the fewest remaining conflicts (then the shortest). Only the robots that can matter
are scored against, found for the whole round at once (:func:`near_sets`).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from agent.core.formation.paths.close_pairs import (
    candidate_segment_pairs,
    close_segment_pairs,
    path_segments,
    sorted_unique,
)
from agent.core.formation.paths.geometry import point_seg_dist, seg_seg_dist
from agent.core.formation.waves.safety import ABS_SLACK


def detour_candidates(p: np.ndarray, q: np.ndarray, c: float) -> list[np.ndarray]:
    """Via points beside the straight path p -> q (none for a robot already there)."""
    d = q - p
    length = float(np.hypot(*d))
    if length < 1e-9:
        return []
    u = d / length
    nrm = np.array([-u[1], u[0]])
    out = []
    for frac in (0.5, 0.25, 0.75):
        base = p + frac * d
        for off in (1.0, 1.5, 2.0, 3.0, 4.5, 6.0):
            for sign in (1.0, -1.0):
                out.append(base + sign * off * c * nrm)
    return out


def score_paths(
    cands: np.ndarray,
    seg_a: np.ndarray,
    seg_b: np.ndarray,
    first: np.ndarray,
    starts: np.ndarray,
    targets: np.ndarray,
    c: float,
) -> tuple[np.ndarray, np.ndarray]:
    """Score K candidate paths (K, m, 2) of one robot against the m' robots near it
    (their path segments, robot by robot: robot q owns segments first[q]..first[q+1]-1;
    their starts and targets).

    Returns (total clearance deficit of blocked pairs, pairs that may not share a wave),
    each (K,). For each other robot k, the deficit of an order is the sum of the
    clearance missing from its two point-to-path tests; a pair's deficit is that of its
    better order. A robot whose path stays >= c from every candidate adds 0 (each
    distance of a term is >= the path distance).
    """
    k_cand = cands.shape[0]
    m = starts.shape[0]
    if m == 0:
        return np.zeros(k_cand), np.zeros(k_cand, dtype=np.int64)
    ca = cands[:, :-1, :].reshape(-1, 1, 2)  # (K*(n-1), 1, 2) candidate segments
    cb = cands[:, 1:, :].reshape(-1, 1, 2)
    nseg = cands.shape[1] - 1
    # candidate segments vs other robots' segments -> min per (candidate, robot)
    dss = seg_seg_dist(ca, cb, seg_a[None], seg_b[None]).reshape(k_cand, nseg, -1).min(axis=1)
    d_path = np.minimum.reduceat(dss, first[:-1], axis=1)  # (K, m)
    close = np.flatnonzero(d_path.min(axis=0) < c)
    if close.size == 0:
        return np.zeros(k_cand), np.zeros(k_cand, dtype=np.int64)
    d_path = d_path[:, close]
    st, tg = starts[close], targets[close]
    d_i_s = point_seg_dist(st[None], ca, cb).reshape(k_cand, nseg, -1).min(axis=1)
    d_i_t = point_seg_dist(tg[None], ca, cb).reshape(k_cand, nseg, -1).min(axis=1)
    own_s, own_t = cands[0, 0], cands[0, -1]
    d_k_si = np.minimum.reduceat(point_seg_dist(own_s[None], seg_a, seg_b), first[:-1])[close]
    d_k_ti = np.minimum.reduceat(point_seg_dist(own_t[None], seg_a, seg_b), first[:-1])[close]
    req = (
        np.minimum(c, np.minimum(np.hypot(*(st - own_s).T), np.hypot(*(tg - own_t).T)))
        * (1.0 - 1e-9)
        - ABS_SLACK * c
    )
    i_first = np.maximum(req - d_i_s, 0) + np.maximum(req - d_k_ti, 0)
    k_first = np.maximum(req - d_k_si, 0) + np.maximum(req - d_i_t, 0)
    deficit = np.minimum(i_first, k_first).sum(axis=1)
    return deficit, np.sum(d_path < req, axis=1)


#: Farthest a detour candidate strays from the straight path, in clearances (the largest
#: offset of :func:`detour_candidates`).
_MAX_OFFSET = 6.0


def near_sets(
    todo: Sequence[int],
    starts: np.ndarray,
    targets: np.ndarray,
    paths: Sequence[np.ndarray],
    c: float,
    segs: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
) -> list[np.ndarray]:
    """For each robot r of ``todo``: a superset of the robots whose path may come within
    c of r's path or of one of its detour candidates during the round. Every candidate
    lies within 6c of the straight segment start -> target, so: the robots whose
    current path comes within 7c of that segment or within c of r's current path, and
    the other robots of ``todo`` whose segments come within 13c (their path may change
    first). Robots farther away add nothing to a score (each term of
    :func:`score_paths` is 0)."""
    total = len(paths)
    rob = np.asarray(todo, dtype=np.int64)
    m = rob.size
    pa, pb, po = path_segments(paths) if segs is None else segs
    qa, qb = starts[rob], targets[rob]
    bent = [j for j, r in enumerate(todo) if paths[r].shape[0] > 2]  # others: in the capsule
    found: list[np.ndarray] = []

    def cross(sa: np.ndarray, sb: np.ndarray, so: np.ndarray, dist: float) -> None:
        seg_a = np.concatenate([pa, sa])
        seg_b = np.concatenate([pb, sb])
        owner = np.concatenate([po, total + so])
        query = np.r_[np.zeros(pa.shape[0], dtype=bool), np.ones(sa.shape[0], dtype=bool)]
        s, t, _ = close_segment_pairs(seg_a, seg_b, owner, dist, query=query, cross_only=True)
        found.append((owner[t] - total) * total + owner[s])

    cross(qa, qb, np.arange(m), (_MAX_OFFSET + 1.0) * c)
    if bent:
        ca, cb, co = path_segments([paths[todo[j]] for j in bent])
        cross(ca, cb, np.asarray(bent, dtype=np.int64)[co], c)
    s, t = candidate_segment_pairs(qa, qb, np.arange(m), (2 * _MAX_OFFSET + 1.0) * c)
    found.append(s * total + rob[t])
    found.append(t * total + rob[s])
    key = sorted_unique(np.concatenate(found))
    qs, ks = key // total, key % total
    keep = ks != rob[qs]
    qs, ks = qs[keep], ks[keep]
    ptr = np.searchsorted(qs, np.arange(m + 1))
    return [ks[ptr[j] : ptr[j + 1]] for j in range(m)]
