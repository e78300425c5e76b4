"""Loop-consistency support of candidate pairs, for every candidate at once (docs/design.md §9;
the triangles of NAO paper 4.1.2's neighbour check, eq. 9, rotated by the candidate's
relative heading).

A candidate ``t`` pairs sighting ``src[t]`` of robot i with sighting ``dst[t]`` of robot j,
at the relative heading ``turn[t]`` = ψ_j − ψ_i it implies. Every *other* sighting k of i
is moved into j's frame,

    m_k = R(−turn[t]) (v_k − v_src),

and counts one when the nearest of j's sightings (all of them, ``dst`` included) lies
within ``ε/2 + rel_tol·|v_k − v_src|`` of m_k and is not ``dst`` itself: the triangle
i–j–c closes. :mod:`pose_pairing` adds the counts of both sides.

This is the same count a k-d tree per robot gives, computed without a Python loop over the
candidates (a 50-NAO record set has ~10⁵ candidates, a 100-NAO one ~7·10⁵, and
every agent plans on the same records): candidates are grouped by the sighting counts of
their two robots, and within a group the nearest sighting is found by brute force over
j's sightings (a robot reports at most ``MAX_NEIGHBOURS``), one sighting of j at a time
over every (candidate, sighting of i) of a chunk of at most :data:`CHUNK_ELEMENTS`.
Determinism: elementwise arithmetic only (no BLAS, so no host-dependent summation order),
and of two equidistant sightings of j the one with the lower index is the nearest (a
strictly nearer one replaces it, as ``np.argmin`` picks the first).
"""

from __future__ import annotations

import numpy as np

#: Most (candidate, sighting of i) distances held at once (256 kB an array; of 2^13 ..
#: 2^17, 2^15 measured fastest on a 50-NAO record set, by a few per cent).
CHUNK_ELEMENTS = 1 << 15


def support_one_side(
    src: np.ndarray,
    dst: np.ndarray,
    turn: np.ndarray,
    owner: np.ndarray,
    vecs: np.ndarray,
    epsilon: float,
    rel_tol: float,
) -> np.ndarray:
    """Triangles closed from ``src``'s side, one count per candidate (module docstring).

    Parameters
    ----------
    src, dst : (T,) int arrays
        Sighting indices (rows of ``vecs``) of each candidate's two sides.
    turn : (T,) float array
        ψ_j − ψ_i of each candidate (rad).
    owner : (S,) int array
        The robot (record index) of each sighting, ascending: a robot's sightings are
        consecutive rows.
    vecs : (S, 2) float array
        The sightings, each in its owner's fixed frame (m).
    epsilon, rel_tol : float
        The tolerance ``ε/2 + rel_tol·|v_k − v_src|`` (m, m per m).

    Raises
    ------
    ValueError
        When the shapes disagree, an index is out of range or ``owner`` is not ascending.
    """
    src = np.asarray(src, dtype=np.int64)
    dst = np.asarray(dst, dtype=np.int64)
    turn = np.asarray(turn, dtype=np.float64)
    owner = np.asarray(owner, dtype=np.int64)
    vecs = np.asarray(vecs, dtype=np.float64)
    t = src.shape[0]
    if src.shape != (t,) or dst.shape != (t,) or turn.shape != (t,):
        raise ValueError(
            f"src, dst and turn must be (T,), got {src.shape}, {dst.shape}, {turn.shape}"
        )
    s = owner.shape[0]
    if owner.shape != (s,) or vecs.shape != (s, 2):
        raise ValueError(f"owner must be (S,) and vecs (S, 2), got {owner.shape}, {vecs.shape}")
    out = np.zeros(t, dtype=np.int64)
    if t == 0:
        return out
    if s == 0 or min(src.min(), dst.min()) < 0 or max(src.max(), dst.max()) >= s:
        raise ValueError("a candidate names a sighting out of range")
    if owner.min() < 0 or np.any(np.diff(owner) < 0):
        raise ValueError("owner must be ascending and >= 0 (a robot's sightings consecutive)")
    counts = np.bincount(owner)
    starts = np.concatenate(([0], np.cumsum(counts)))
    oi, oj = owner[src], owner[dst]
    di, dj = counts[oi], counts[oj]
    # a robot with no other sighting closes no triangle, and one whose only sighting is
    # dst has no hit that counts
    live = np.flatnonzero((di > 1) & (dj > 1))
    if live.size == 0:
        return out
    # group by (a, b) = (di, dj), one integer key each; members in ascending order
    key = di[live] * (int(counts.max()) + 1) + dj[live]
    by_key = np.argsort(key, kind="stable")
    keys, first = np.unique(key[by_key], return_index=True)
    bounds = [*first.tolist(), live.size]
    width = int(counts.max()) + 1
    for g, k in enumerate(keys.tolist()):
        a, b = divmod(k, width)
        members = live[by_key[bounds[g] : bounds[g + 1]]]
        step = max(1, CHUNK_ELEMENTS // a)
        for lo in range(0, members.size, step):
            cand = members[lo : lo + step]
            out[cand] = _count(cand, a, b, src, dst, turn, oi, oj, starts, vecs, epsilon, rel_tol)
    return out


def _count(
    cand: np.ndarray,
    a: int,
    b: int,
    src: np.ndarray,
    dst: np.ndarray,
    turn: np.ndarray,
    oi: np.ndarray,
    oj: np.ndarray,
    starts: np.ndarray,
    vecs: np.ndarray,
    epsilon: float,
    rel_tol: float,
) -> np.ndarray:
    """Counts of the candidates ``cand``, whose robots have ``a`` and ``b`` sightings."""
    ki = starts[oi[cand]][:, None] + np.arange(a)[None, :]  # (C, a) sightings of i
    hj = starts[oj[cand]][:, None] + np.arange(b)[None, :]  # (C, b) sightings of j
    base = vecs[src[cand]]
    rx = vecs[ki, 0] - base[:, 0:1]
    ry = vecs[ki, 1] - base[:, 1:2]
    c = np.cos(-turn[cand])[:, None]
    s = np.sin(-turn[cand])[:, None]
    mx = rx * c - ry * s  # (v_k − v_src) · [[c, s], [−s, c]], row vector times matrix
    my = rx * s + ry * c
    # the nearest of j's sightings, one sighting of j at a time (the first of equal
    # distances, as np.argmin over them): (C, a) arrays, no (C, a, b) one
    hx, hy = vecs[hj, 0], vecs[hj, 1]
    d2 = np.full(mx.shape, np.inf)
    near = np.zeros(mx.shape, dtype=np.int64)
    dx = np.empty_like(mx)
    dy = np.empty_like(mx)
    closer = np.empty(mx.shape, dtype=bool)
    for h in range(b):
        np.subtract(mx, hx[:, h : h + 1], out=dx)
        np.subtract(my, hy[:, h : h + 1], out=dy)
        np.multiply(dx, dx, out=dx)
        np.multiply(dy, dy, out=dy)
        np.add(dx, dy, out=dx)  # dx² + dy², as one (C, a, b) array held it
        np.less(dx, d2, out=closer)
        np.copyto(d2, dx, where=closer)
        np.copyto(near, h, where=closer)
    dist = np.sqrt(d2)
    hit = np.take_along_axis(hj, near, axis=1)
    tol = 0.5 * epsilon + rel_tol * np.sqrt(rx * rx + ry * ry)
    ok = (dist <= tol) & (hit != dst[cand][:, None]) & (ki != src[cand][:, None])
    return np.asarray(ok.sum(axis=1), dtype=np.int64)
