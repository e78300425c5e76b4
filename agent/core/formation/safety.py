"""Execution waves and the safety checker (NAO paper 4.2 and 5.2.2(7): "the leader goes to its
destination firstly, and then the followers"; our strengthening of Lemma 1).

Lemma 1 only promises that matched straight paths do not *cross*; two robots on
non-crossing paths that walk at the same time can still brush each other. The
criterion here is speed-independent. A plan is split into waves; robots of one wave
walk at the same time at arbitrary speeds, a wave starts when the previous one is done.
With clearance ``c = 2·radius``, a plan is *safe* when for every wave w:

* any two robots walking in w: the distance between their whole paths (polylines,
  start -> via points -> target) is >= c;
* any robot walking in w and any robot standing during w (at its start if its wave is
  later, at its target if earlier): the distance from the path to that point is >= c.

Pairs whose estimated starts (or targets) are already closer than c - estimates can
be - are held to that smaller distance instead (they may not come closer than that).

The pair test reduces to three flags per pair (i, k): *same* (may walk together),
*i-before-k*, *k-before-i*. Only pairs whose paths come within c matter; they are
found exactly by spatial hashing (every segment entered in the cells of side 3c its
c/2-dilation may meet, same-cell pairs deduplicated by one int64 key, then measured),
so the checker and the scheduler cost ~ (total path length / c + close pairs) · log.
Between detour rounds only the pairs of the robots whose path changed are redone.

Scheduling (:func:`schedule`): wave 0 = the leader alone. Pairs that may not share a
wave but can go in either order must be in different waves; pairs that can only go in
one order give a precedence edge. Robots are taken in a topological order of the
precedence edges, ready robots by ascending pyramid order (then id); each gets the first
wave >= 1 after all its predecessors that no conflicting robot already holds. Pairs
that can go in no order, precedence cycles, and a leader whose path is blocked are
resolved by a detour: one via point on the side of the blocked path (candidates
perpendicular to the path at its middle, quarter and three-quarter points, offsets
1, 1.5, 2, 3, 4.5, 6 × c, left before right), the candidate with the fewest remaining
conflicts (then the shortest) wins; this repeats until nothing is left to resolve.
Robots are still taken one by one (a detour changes the score of the next ones), each
scored only against the robots that can matter (found for the whole round at once).
The waves found here certify that a safe order exists; :mod:`plan` then re-times the
robots from the same pair flags (:mod:`packing`), so each starts as soon as its own
conflicts are clear.

Distances are compared with a rounding slack (relative 1e-9 and 1e-12·c absolute), and
two segments only *cross* when every endpoint is clearly off the other's line (collinear
legs are measured by their endpoint distances).
"""

from __future__ import annotations

import heapq
import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

_SAME, _IK, _KI = 0, 1, 2

#: Absolute rounding slack of a required distance, in clearances.
_ABS_SLACK = 1e-12


class ScheduleError(ValueError):
    """No safe schedule; ``pairs`` are robot-row pairs that can go in no order (or, if
    there are none, pairs on precedence cycles) - candidates for a slot swap."""

    def __init__(
        self,
        message: str,
        robots: list[int],
        pairs: list[tuple[int, int]],
        vias: tuple[tuple[np.ndarray, ...], ...] = (),
        state: tuple[list[np.ndarray], PairFlags] | None = None,
    ) -> None:
        super().__init__(message)
        self.robots = robots
        self.pairs = pairs
        self.vias = vias  # the detours found so far, per robot row (may be kept)
        self.state = state  # the paths and their pair flags (see schedule(prior=...))


@dataclass(frozen=True)
class Violation:
    wave: int
    robot_a: int  # row indices (ascending-id order of the plan)
    robot_b: int
    kind: str  # "paths" | "path-vs-standing"
    distance: float
    required: float


@dataclass(frozen=True)
class PairFlags:
    """Robot pairs (rows a < b) whose paths come within c, with their three flags."""

    a: np.ndarray
    b: np.ndarray
    same_ok: np.ndarray
    ab_ok: np.ndarray  # a strictly before b
    ba_ok: np.ndarray
    d_path: np.ndarray
    d_ab: np.ndarray  # min(d(path_a, start_b), d(path_b, target_a))
    d_ba: np.ndarray
    required: np.ndarray


# ----------------------------------------------------------------- geometry (vectorized)


def point_seg_dist(p: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Distance from points p to segments [a, b] (broadcast over leading axes)."""
    ax, ay = a[..., 0], a[..., 1]
    abx, aby = b[..., 0] - ax, b[..., 1] - ay
    apx, apy = p[..., 0] - ax, p[..., 1] - ay
    den = abx * abx + aby * aby
    pos = den > 0
    t = np.where(pos, (apx * abx + apy * aby) / np.where(pos, den, 1.0), 0.0)
    t = np.clip(t, 0.0, 1.0)
    return np.hypot(p[..., 0] - (ax + t * abx), p[..., 1] - (ay + t * aby))


def _cross(o: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return (a[..., 0] - o[..., 0]) * (b[..., 1] - o[..., 1]) - (a[..., 1] - o[..., 1]) * (
        b[..., 0] - o[..., 0]
    )


def seg_seg_dist(a0: np.ndarray, a1: np.ndarray, b0: np.ndarray, b1: np.ndarray) -> np.ndarray:
    """Distance between segments [a0, a1] and [b0, b1] (0 if they cross)."""
    d = np.minimum(
        np.minimum(point_seg_dist(a0, b0, b1), point_seg_dist(a1, b0, b1)),
        np.minimum(point_seg_dist(b0, a0, a1), point_seg_dist(b1, a0, a1)),
    )
    o1, o2 = _cross(a0, a1, b0), _cross(a0, a1, b1)
    o3, o4 = _cross(b0, b1, a0), _cross(b0, b1, a1)
    # a proper crossing needs every endpoint clearly off the other line: orientations
    # within rounding of 0 (collinear legs, e.g. on one corridor line) are no crossing -
    # if such segments do meet, an endpoint lies on the other one and d is ~0 already
    la = np.hypot(a1[..., 0] - a0[..., 0], a1[..., 1] - a0[..., 1])
    lb = np.hypot(b1[..., 0] - b0[..., 0], b1[..., 1] - b0[..., 1])
    tol = 1e-12 * (la + lb) * (la + lb + np.hypot(b0[..., 0] - a0[..., 0], b0[..., 1] - a0[..., 1]))
    clear = (np.abs(o1) > tol) & (np.abs(o2) > tol) & (np.abs(o3) > tol) & (np.abs(o4) > tol)
    crossing = (o1 * o2 < 0) & (o3 * o4 < 0) & clear
    return np.where(crossing, 0.0, d)


def paths_cross(a0: np.ndarray, a1: np.ndarray, b0: np.ndarray, b1: np.ndarray) -> np.ndarray:
    """True where the two segments properly cross (Lemma 1's 'intercrossing')."""
    o1, o2 = _cross(a0, a1, b0), _cross(a0, a1, b1)
    o3, o4 = _cross(b0, b1, a0), _cross(b0, b1, a1)
    return (o1 * o2 < 0) & (o3 * o4 < 0)


# ----------------------------------------------------------------- segments and hashing


def _segments(paths: Sequence[np.ndarray]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Flatten polylines to segments (a, b, owner). A one-point path is one point segment."""
    arrs = [np.asarray(p, dtype=np.float64).reshape(-1, 2) for p in paths]
    lens = np.fromiter((p.shape[0] for p in arrs), dtype=np.int64, count=len(arrs))
    if np.any(lens == 0):
        raise ValueError("a path has no points")
    pts = np.concatenate(arrs)
    first = np.cumsum(lens) - lens
    nseg = np.maximum(lens - 1, 1)
    owner = np.repeat(np.arange(len(arrs)), nseg)
    ia = first[owner] + (np.arange(owner.size) - np.repeat(np.cumsum(nseg) - nseg, nseg))
    ib = ia + (lens[owner] > 1)
    return pts[ia], pts[ib], owner


def _sorted_unique(a: np.ndarray) -> np.ndarray:
    if a.size == 0:
        return a
    a = np.sort(a, kind="stable")
    return a[np.r_[True, a[1:] != a[:-1]]]


#: Cells per side of the hash grid, in units of the clearance (see candidate_segment_pairs).
_CELL_PER_C = 3.0
#: Raw same-cell pairs handled per chunk (bounds memory at 10^5 robots).
_CHUNK = 1 << 22
_OFF = 1 << 30


def _register(
    seg_a: np.ndarray, seg_b: np.ndarray, r: float, h: float
) -> tuple[np.ndarray, np.ndarray]:
    """(cell key, segment) for every grid cell (side h) that may meet a segment dilated by r.

    Column by column: the part of the segment whose x lies within r of the column, its
    y range widened by r. A superset of the exact cells, each (cell, segment) once.
    """
    m = seg_a.shape[0]
    x0 = np.minimum(seg_a[:, 0], seg_b[:, 0])
    x1 = np.maximum(seg_a[:, 0], seg_b[:, 0])
    cx0 = np.floor((x0 - r) / h).astype(np.int64)
    ncol = np.floor((x1 + r) / h).astype(np.int64) - cx0 + 1
    sc = np.repeat(np.arange(m), ncol)
    col = cx0[sc] + (np.arange(sc.size) - np.repeat(np.cumsum(ncol) - ncol, ncol))
    ax, ay = seg_a[sc, 0], seg_a[sc, 1]
    dx = seg_b[sc, 0] - ax
    dy = seg_b[sc, 1] - ay
    xl = np.maximum(col * h - r, x0[sc])
    xr = np.minimum((col + 1) * h + r, x1[sc])
    slanted = np.abs(dx) > 0
    sdx = np.where(slanted, dx, 1.0)
    tl = np.clip(np.where(slanted, (xl - ax) / sdx, 0.0), 0.0, 1.0)
    tr = np.clip(np.where(slanted, (xr - ax) / sdx, 1.0), 0.0, 1.0)
    ya = ay + tl * dy
    yb = ay + tr * dy
    cy0 = np.floor((np.minimum(ya, yb) - r) / h).astype(np.int64)
    ncell = np.floor((np.maximum(ya, yb) + r) / h).astype(np.int64) - cy0 + 1
    idx = np.repeat(np.arange(sc.size), ncell)
    cy = cy0[idx] + (np.arange(idx.size) - np.repeat(np.cumsum(ncell) - ncell, ncell))
    return (col[idx] + _OFF) * (1 << 31) + (cy + _OFF), sc[idx]


def _segment_pairs(
    seg_a: np.ndarray,
    seg_b: np.ndarray,
    owner: np.ndarray,
    c: float,
    query: np.ndarray | None = None,
    cross_only: bool = False,
) -> tuple[np.ndarray, np.ndarray]:
    """Segment pairs (s, t), owner[s] < owner[t], within c; with ``query`` (bool per
    segment) only the pairs with at least one query segment (``cross_only``: exactly one)."""
    m = seg_a.shape[0]
    empty = np.zeros(0, dtype=np.int64)
    if m == 0 or (query is not None and not np.any(query)):
        return empty, empty
    lim = float(np.max(np.abs(np.concatenate([seg_a, seg_b]))))
    h = _CELL_PER_C * c
    if not (math.isfinite(lim) and c > 0 and lim / h < _OFF / 4):
        raise ValueError("segments must be finite and c > 0 (and coordinates / c < 2^26)")
    key, seg = _register(seg_a, seg_b, 0.5 * c * (1 + 1e-6) + 1e-9, h)
    # within a cell: ascending segment (query: the other segments first)
    order = np.argsort(key, kind="stable") if query is None else np.lexsort((query[seg], key))
    key = key[order]
    seg = seg[order]
    e = key.size
    gend = np.r_[np.flatnonzero(key[1:] != key[:-1]) + 1, e]
    gsize = np.diff(np.r_[0, gend])
    if query is None:  # each entry with the later entries of its cell
        ent = np.arange(e)
        cnt = np.repeat(gend, gsize) - ent - 1
        first = ent + 1
    else:  # each query entry with every other (cross_only: non-query) entry of its cell
        isq = query[seg]
        ent = np.flatnonzero(isq)
        if cross_only:
            cnt = np.repeat(np.add.reduceat((~isq).astype(np.int64), gend - gsize), gsize)[ent]
        else:
            cnt = np.repeat(gsize, gsize)[ent]
        first = np.repeat(gend - gsize, gsize)[ent]
    csum = np.cumsum(cnt)
    out: list[np.ndarray] = []
    lo = 0
    while lo < ent.size:
        base = int(csum[lo - 1]) if lo else 0
        hi = max(int(np.searchsorted(csum, base + _CHUNK, side="right")), lo + 1)
        c_cnt = cnt[lo:hi]
        total = int(c_cnt.sum())
        if total:
            src = np.repeat(ent[lo:hi], c_cnt)
            offs = np.arange(total) - np.repeat(np.cumsum(c_cnt) - c_cnt, c_cnt)
            dst = np.repeat(first[lo:hi], c_cnt) + offs
            s, t = seg[src], seg[dst]
            os_, ot = owner[s], owner[t]
            keep = os_ != ot
            flip = os_ > ot
            s, t = np.where(flip, t, s)[keep], np.where(flip, s, t)[keep]
            u = _sorted_unique(s * m + t)
            s, t = u // m, u % m
            near = seg_seg_dist(seg_a[s], seg_b[s], seg_a[t], seg_b[t]) <= c
            out.append(u[near])
        lo = hi
    if not out:
        return empty, empty
    u = _sorted_unique(np.concatenate(out))
    return u // m, u % m


def candidate_segment_pairs(
    seg_a: np.ndarray, seg_b: np.ndarray, owner: np.ndarray, c: float
) -> tuple[np.ndarray, np.ndarray]:
    """Segment index pairs (s, t), owner[s] < owner[t], whose distance is <= c.

    Exact (every such pair, no other), sorted by (s, t). Spatial hashing: each segment
    is entered in every cell (side 3c) its c/2-dilation may meet - two segments within
    c share such a cell - so only same-cell pairs are candidates; they are deduplicated
    with one int64 key, then measured. Cost ~ total path length / c + candidates.
    """
    return _segment_pairs(seg_a, seg_b, owner, c)


def _flags_from_pairs(
    starts: np.ndarray,
    targets: np.ndarray,
    seg_a: np.ndarray,
    seg_b: np.ndarray,
    owner: np.ndarray,
    s: np.ndarray,
    t: np.ndarray,
    clearance: float,
) -> PairFlags:
    """Per robot pair flags from its segment pairs (s, t), owner[s] < owner[t]."""
    n = starts.shape[0]
    if s.size == 0:
        z = np.zeros(0, dtype=np.int64)
        zf = np.zeros(0)
        zb = np.zeros(0, dtype=bool)
        return PairFlags(z, z, zb, zb, zb, zf, zf, zf, zf)
    i, k = owner[s], owner[t]
    d_ss = seg_seg_dist(seg_a[s], seg_b[s], seg_a[t], seg_b[t])
    d_i_sk = point_seg_dist(starts[k], seg_a[s], seg_b[s])
    d_k_ti = point_seg_dist(targets[i], seg_a[t], seg_b[t])
    d_k_si = point_seg_dist(starts[i], seg_a[t], seg_b[t])
    d_i_tk = point_seg_dist(targets[k], seg_a[s], seg_b[s])
    pk = i * n + k
    order = np.argsort(pk, kind="stable")
    pk = pk[order]
    first = np.flatnonzero(np.r_[True, pk[1:] != pk[:-1]])
    a = pk[first] // n
    b = pk[first] % n
    d_path = np.minimum.reduceat(d_ss[order], first)
    d_ab = np.minimum(
        np.minimum.reduceat(d_i_sk[order], first), np.minimum.reduceat(d_k_ti[order], first)
    )
    d_ba = np.minimum(
        np.minimum.reduceat(d_k_si[order], first), np.minimum.reduceat(d_i_tk[order], first)
    )
    d_start = np.hypot(*(starts[a] - starts[b]).T)
    d_target = np.hypot(*(targets[a] - targets[b]).T)
    # rounding slack: relative 1e-9, and 1e-12·c absolute (starts 1e-300 m apart are one)
    req = (
        np.minimum(clearance, np.minimum(d_start, d_target)) * (1.0 - 1e-9) - _ABS_SLACK * clearance
    )
    return PairFlags(
        a=a,
        b=b,
        same_ok=d_path >= req,
        ab_ok=d_ab >= req,
        ba_ok=d_ba >= req,
        d_path=d_path,
        d_ab=d_ab,
        d_ba=d_ba,
        required=req,
    )


def _ends(paths: Sequence[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    arrs = [np.asarray(p, dtype=np.float64).reshape(-1, 2) for p in paths]
    return np.array([p[0] for p in arrs]), np.array([p[-1] for p in arrs])


def pair_flags(paths: Sequence[np.ndarray], clearance: float) -> PairFlags:
    """Flags of every robot pair whose paths come within ``clearance`` (sorted by (a, b);
    pairs farther apart can share a wave and go in either order)."""
    starts, targets = _ends(paths)
    seg_a, seg_b, owner = _segments(paths)
    s, t = _segment_pairs(seg_a, seg_b, owner, clearance)
    return _flags_from_pairs(starts, targets, seg_a, seg_b, owner, s, t, clearance)


def _update_flags(
    flags: PairFlags,
    paths: Sequence[np.ndarray],
    changed: Sequence[int],
    clearance: float,
    ends: tuple[np.ndarray, np.ndarray] | None = None,
) -> PairFlags:
    """:func:`pair_flags` after the paths of ``changed`` robots changed (same result).
    ``ends``: the (starts, targets) of the paths, if known."""
    n = len(paths)
    starts, targets = _ends(paths) if ends is None else ends
    seg_a, seg_b, owner = _segments(paths)
    moved = np.zeros(n, dtype=bool)
    moved[np.asarray(changed, dtype=np.int64)] = True
    s, t = _segment_pairs(seg_a, seg_b, owner, clearance, query=moved[owner])
    new = _flags_from_pairs(starts, targets, seg_a, seg_b, owner, s, t, clearance)
    keep = ~(moved[flags.a] | moved[flags.b])
    parts = [(getattr(flags, f)[keep], getattr(new, f)) for f in PairFlags.__dataclass_fields__]
    merged = {
        f: np.concatenate(p) for f, p in zip(PairFlags.__dataclass_fields__, parts, strict=True)
    }
    order = np.argsort(merged["a"] * n + merged["b"], kind="stable")
    return PairFlags(**{f: v[order] for f, v in merged.items()})


# ----------------------------------------------------------------- the checker


def check_safety(
    paths: Sequence[np.ndarray], waves: Sequence[int] | np.ndarray, radius: float
) -> list[Violation]:
    """Every violation of the wave-safety criterion (empty list = safe).

    ``paths[i]`` is robot i's polyline (start, via..., target) as an (m, 2) array and
    ``waves[i]`` its wave number.
    """
    if not (math.isfinite(radius) and radius > 0):
        raise ValueError(f"radius must be > 0, got {radius!r}")
    if len(paths) != len(waves):
        raise ValueError(f"{len(paths)} paths but {len(waves)} wave numbers")
    if not paths:
        return []
    flags = pair_flags(paths, 2.0 * radius)
    w = np.asarray(waves, dtype=np.int64)
    out: list[Violation] = []
    wa, wb = w[flags.a], w[flags.b]
    bad_same = (wa == wb) & ~flags.same_ok
    bad_ab = (wa < wb) & ~flags.ab_ok
    bad_ba = (wa > wb) & ~flags.ba_ok
    for idx in np.flatnonzero(bad_same | bad_ab | bad_ba):
        a, b = int(flags.a[idx]), int(flags.b[idx])
        if bad_same[idx]:
            out.append(
                Violation(
                    int(wa[idx]),
                    a,
                    b,
                    "paths",
                    float(flags.d_path[idx]),
                    float(flags.required[idx]),
                )
            )
        elif bad_ab[idx]:
            out.append(
                Violation(
                    int(wb[idx]),
                    a,
                    b,
                    "path-vs-standing",
                    float(flags.d_ab[idx]),
                    float(flags.required[idx]),
                )
            )
        else:
            out.append(
                Violation(
                    int(wa[idx]),
                    a,
                    b,
                    "path-vs-standing",
                    float(flags.d_ba[idx]),
                    float(flags.required[idx]),
                )
            )
    return out


# ----------------------------------------------------------------- the scheduler


@dataclass(frozen=True)
class Schedule:
    waves: np.ndarray  # (N,) wave of each robot row
    vias: tuple[tuple[np.ndarray, ...], ...]  # per robot row
    flags: PairFlags | None = None  # pair flags of the final paths (robots, then obstacles)


def _adjacency(u: np.ndarray, v: np.ndarray, n: int) -> list[list[int]]:
    """Adjacency lists of the edges u -> v (in the order of the edge arrays)."""
    order = np.argsort(u, kind="stable")
    vl = v[order].tolist()
    ptr = np.searchsorted(u[order], np.arange(n + 1)).tolist()
    return [vl[ptr[i] : ptr[i + 1]] for i in range(n)]


def _assign_waves(
    n: int, leader: int, priority: np.ndarray, flags: PairFlags
) -> tuple[np.ndarray, list[int]]:
    """Topological wave assignment. Returns (waves, robots left in cycles / blocked).

    The leader goes first (wave 0, alone) unless some robot *must* move before it (its
    slot lies within the clearance of that robot's start): those ancestors of the leader
    in the precedence graph go first, then the leader alone, then everyone else.
    Rows >= n are static obstacles: standing in every wave, never scheduled.
    """
    ns = np.flatnonzero(~flags.same_ok)
    fa, fb, fab, fba = flags.a[ns], flags.b[ns], flags.ab_ok[ns], flags.ba_ok[ns]
    obst = fb >= n  # a robot path too close to an obstacle (a < b always)
    problems: set[int] = set(fa[obst & (fa < n)].tolist())
    fa, fb, fab, fba = fa[~obst], fb[~obst], fab[~obst], fba[~obst]
    both, only_ab, only_ba = fab & fba, fab & ~fba, fba & ~fab
    neither = ~fab & ~fba
    problems.update(fa[neither].tolist())
    problems.update(fb[neither].tolist())
    src = np.concatenate([fa[only_ab], fb[only_ba]])
    dst = np.concatenate([fb[only_ab], fa[only_ba]])
    succ = _adjacency(src, dst, n)
    pred = _adjacency(dst, src, n)
    conflict = _adjacency(
        np.concatenate([fa[both], fb[both]]), np.concatenate([fb[both], fa[both]]), n
    )
    # ancestors of the leader
    anc: set[int] = set()
    stack = list(pred[leader])
    while stack:
        u = stack.pop()
        if u not in anc:
            anc.add(u)
            stack.extend(pred[u])
    waves = [-1] * n
    earliest = [0] * n
    indeg = [len(p) for p in pred]
    prio = [int(p) for p in priority.tolist()]

    def run(members: set[int] | None, floor: int) -> None:
        heap = [
            (prio[i], i)
            for i in range(n)
            if waves[i] < 0 and indeg[i] == 0 and (members is None or i in members)
        ]
        heapq.heapify(heap)
        while heap:
            _, i = heapq.heappop(heap)
            w = max(earliest[i], floor)
            if conflict[i]:
                taken = {waves[j] for j in conflict[i]}
                while w in taken:
                    w += 1
            waves[i] = w
            for j in succ[i]:
                if earliest[j] < w + 1:
                    earliest[j] = w + 1
                indeg[j] -= 1
                if indeg[j] == 0 and (members is None or j in members):
                    heapq.heappush(heap, (prio[j], j))

    if leader in anc:
        problems.add(leader)  # the leader is on a precedence cycle
    else:
        if anc:
            run(anc, 0)
        if all(waves[i] >= 0 for i in anc):
            lw = max((waves[i] for i in anc), default=-1) + 1
            waves[leader] = lw
            for j in succ[leader]:
                earliest[j] = max(earliest[j], lw + 1)
                indeg[j] -= 1
            run(None, lw + 1)
    wv = np.array(waves, dtype=np.int64)
    left = np.flatnonzero(wv < 0)
    if left.size:
        # robots on precedence cycles (strongly connected components of size > 1)
        from scipy.sparse import coo_matrix
        from scipy.sparse.csgraph import connected_components

        graph = coo_matrix((np.ones(src.size), (src, dst)), shape=(n, n))
        _, label = connected_components(graph, directed=True, connection="strong")
        sizes = np.bincount(label)
        problems.update(int(i) for i in left if sizes[label[i]] > 1)
        if leader in left:
            problems.add(leader)
        if not problems:  # pragma: no cover - left nodes always descend from a cycle
            problems.update(int(i) for i in left)
    return wv, sorted(problems)


def _detour_candidates(p: np.ndarray, q: np.ndarray, c: float) -> list[np.ndarray]:
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


def _score_paths(
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
        - _ABS_SLACK * c
    )
    i_first = np.maximum(req - d_i_s, 0) + np.maximum(req - d_k_ti, 0)
    k_first = np.maximum(req - d_k_si, 0) + np.maximum(req - d_i_t, 0)
    deficit = np.minimum(i_first, k_first).sum(axis=1)
    return deficit, np.sum(d_path < req, axis=1)


#: Farthest a detour candidate strays from the straight path, in clearances (the largest
#: offset of :func:`_detour_candidates`).
_MAX_OFFSET = 6.0


def _near_sets(
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
    :func:`_score_paths` is 0)."""
    total = len(paths)
    rob = np.asarray(todo, dtype=np.int64)
    m = rob.size
    pa, pb, po = _segments(paths) if segs is None else segs
    qa, qb = starts[rob], targets[rob]
    bent = [j for j, r in enumerate(todo) if paths[r].shape[0] > 2]  # others: in the capsule
    found: list[np.ndarray] = []

    def cross(sa: np.ndarray, sb: np.ndarray, so: np.ndarray, dist: float) -> None:
        seg_a = np.concatenate([pa, sa])
        seg_b = np.concatenate([pb, sb])
        owner = np.concatenate([po, total + so])
        query = np.r_[np.zeros(pa.shape[0], dtype=bool), np.ones(sa.shape[0], dtype=bool)]
        s, t = _segment_pairs(seg_a, seg_b, owner, dist, query=query, cross_only=True)
        found.append((owner[t] - total) * total + owner[s])

    cross(qa, qb, np.arange(m), (_MAX_OFFSET + 1.0) * c)
    if bent:
        ca, cb, co = _segments([paths[todo[j]] for j in bent])
        cross(ca, cb, np.asarray(bent, dtype=np.int64)[co], c)
    s, t = candidate_segment_pairs(qa, qb, np.arange(m), (2 * _MAX_OFFSET + 1.0) * c)
    found.append(s * total + rob[t])
    found.append(t * total + rob[s])
    key = _sorted_unique(np.concatenate(found))
    qs, ks = key // total, key % total
    keep = ks != rob[qs]
    qs, ks = qs[keep], ks[keep]
    ptr = np.searchsorted(qs, np.arange(m + 1))
    return [ks[ptr[j] : ptr[j + 1]] for j in range(m)]


def schedule(
    starts: np.ndarray,
    targets: np.ndarray,
    leader: int,
    priority: np.ndarray,
    radius: float,
    max_rounds: int = 30,
    fixed_vias: Sequence[tuple[np.ndarray, ...]] | None = None,
    obstacles: np.ndarray | None = None,
    prior: ScheduleError | None = None,
) -> Schedule:
    """Waves (+ via points where needed) that pass :func:`check_safety`.

    ``fixed_vias`` are via points the caller wants (e.g. the obstacle procedure); a robot
    whose path cannot be scheduled may have them replaced by a detour. ``obstacles``
    (M, 2) stand still in every wave and are held to the same clearance. ``prior``, the
    error of a previous call on (mostly) the same paths, only saves time: the pair
    flags of the paths that did not change are taken from it.
    """
    n = starts.shape[0]
    c = 2.0 * radius
    vias: list[tuple[np.ndarray, ...]] = (
        [() for _ in range(n)] if fixed_vias is None else [tuple(v) for v in fixed_vias]
    )
    obs = np.zeros((0, 2)) if obstacles is None else np.asarray(obstacles, dtype=np.float64)
    detoured: set[int] = set()

    def path(i: int) -> np.ndarray:
        if not vias[i]:
            return np.array([starts[i], targets[i]], dtype=np.float64)
        return np.vstack([starts[i], *vias[i], targets[i]])

    paths = [path(i) for i in range(n)] + [np.array([o, o]) for o in obs]
    all_s = np.concatenate([starts, obs]).reshape(-1, 2)
    all_t = np.concatenate([targets, obs]).reshape(-1, 2)
    if prior is not None and prior.state is not None and len(prior.state[0]) == len(paths):
        old_paths, old_flags = prior.state
        changed0 = [
            i
            for i, (p, q) in enumerate(zip(paths, old_paths, strict=True))
            if p.shape != q.shape or not np.array_equal(p, q)
        ]
        flags = (
            _update_flags(old_flags, paths, changed0, c, (all_s, all_t)) if changed0 else old_flags
        )
    else:
        flags = pair_flags(paths, c)
    for _ in range(max_rounds):
        waves, problems = _assign_waves(n, leader, priority, flags)
        if not problems:
            return Schedule(waves=waves[:n], vias=tuple(vias), flags=flags)
        # Try a detour for every problem robot (the leader first, then by priority),
        # each scored against the current paths of the robots near it.
        ordered = sorted(problems, key=lambda r: (r != leader, int(priority[r])))
        todo: list[tuple[int, np.ndarray]] = []
        for r in ordered:
            if r in detoured:
                continue
            cands = _detour_candidates(starts[r], targets[r], c)
            if cands:
                todo.append((r, np.array([[starts[r], v, targets[r]] for v in cands])))
        if not todo:
            break
        pa, pb, po = _segments(paths)
        near_of = _near_sets([r for r, _ in todo], starts, targets, paths, c, (pa, pb, po))
        ptr = np.searchsorted(po, np.arange(len(paths) + 1))
        changed: list[int] = []
        for (r, stack), near in zip(todo, near_of, strict=True):
            # segments of the near robots (robots that changed this round: their new path)
            fresh = np.isin(near, changed)
            if fresh.any():
                na, nb, no = _segments([paths[k] for k in near])
                nfirst = np.searchsorted(no, np.arange(near.size + 1))
            else:
                cnt = ptr[near + 1] - ptr[near]
                idx = np.repeat(ptr[near], cnt) + (
                    np.arange(int(cnt.sum())) - np.repeat(np.cumsum(cnt) - cnt, cnt)
                )
                na, nb = pa[idx], pb[idx]
                nfirst = np.r_[0, np.cumsum(cnt)]
            args = (na, nb, nfirst, all_s[near], all_t[near], c)
            base = paths[r]
            if base.shape[0] == 2:  # the straight path as [s, s, t]: the same distances
                both_d, both_c = _score_paths(
                    np.concatenate([np.array([[base[0], base[0], base[1]]]), stack]), *args
                )
                base_d, base_c = both_d[:1], both_c[:1]
                deficit, conflicts = both_d[1:], both_c[1:]
            else:
                base_d, base_c = _score_paths(base[None], *args)
                deficit, conflicts = _score_paths(stack, *args)
            lengths = np.sum(np.hypot(*np.diff(stack, axis=1).transpose(2, 0, 1)), axis=1)
            pick = int(np.lexsort((np.arange(len(stack)), lengths, conflicts, deficit))[0])
            if deficit[pick] < base_d[0] - 1e-12 or (
                deficit[pick] <= base_d[0] + 1e-12 and conflicts[pick] < base_c[0]
            ):
                vias[r] = (stack[pick, 1].copy(),)
                paths[r] = path(r)
                detoured.add(r)
                changed.append(r)
        if not changed:
            break
        flags = _update_flags(flags, paths, changed, c, (all_s, all_t))
    blocked = [
        (int(flags.a[k]), int(flags.b[k]))
        for k in np.flatnonzero(~flags.same_ok & ~flags.ab_ok & ~flags.ba_ok)
        if flags.b[k] < n
    ]
    if not blocked:
        # precedence cycles: offer the one-order pairs among the stuck robots for swapping
        stuck = set(problems)
        one_order = ~flags.same_ok & (flags.ab_ok ^ flags.ba_ok)
        blocked = [
            (int(flags.a[k]), int(flags.b[k]))
            for k in np.flatnonzero(one_order)
            if int(flags.a[k]) in stuck and int(flags.b[k]) in stuck
        ]
    raise ScheduleError(
        f"no safe schedule found: robots {problems[:10]} stay blocked after detours",
        problems,
        blocked,
        vias=tuple(vias),
        state=(list(paths), flags),
    )
