"""Which path segments come within a distance c: exact close-pair search by spatial
hashing (the pair search behind the safety rule of :mod:`safety`, our strengthening of
NAO paper Lemma 1, and behind Lemma 1's crossing repair in :mod:`assignment`).

Only pairs whose paths come within c matter; they are found exactly: every segment is
entered in the cells (side 3c) that its c/2-dilation may meet - two segments within c
share such a cell - so only same-cell pairs are candidates; they are deduplicated by one
int64 key, then measured (:func:`geometry.seg_seg_dist`). The cost is ~ (total path
length / c + close pairs) · log. A query mask restricts the search to the pairs of some
segments (the robots whose path changed), so that pair flags are updated, not redone; a
small query (query segments x segments <= ``_DIRECT``) is measured pair by pair without the
grid, which gives the same pairs. :func:`close_segment_pairs` also returns the distances
measured, so that :mod:`safety` does not measure them again, and :func:`replace_paths`
the segments of paths of which a few changed, from those before the change.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from agent.core.formation.paths.geometry import seg_seg_dist


def path_segments(paths: Sequence[np.ndarray]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
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


def replace_paths(
    segments: tuple[np.ndarray, np.ndarray, np.ndarray],
    rows: Sequence[int],
    paths: Sequence[np.ndarray],
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`path_segments` of ``paths`` from ``segments``, those of paths that differ
    only in ``rows`` (the other paths' segments are copied, not rebuilt)."""
    seg_a, seg_b, owner = segments
    rows = sorted(set(rows))
    los = np.searchsorted(owner, rows, side="left").tolist()
    his = np.searchsorted(owner, rows, side="right").tolist()
    pa: list[np.ndarray] = []
    pb: list[np.ndarray] = []
    po: list[np.ndarray] = []
    prev = 0
    for r, lo, hi in zip(rows, los, his, strict=True):
        p = np.asarray(paths[r], dtype=np.float64).reshape(-1, 2)
        if p.shape[0] == 0:
            raise ValueError("a path has no points")
        a, b = (p[:-1], p[1:]) if p.shape[0] > 1 else (p, p)
        pa += [seg_a[prev:lo], a]
        pb += [seg_b[prev:lo], b]
        po += [owner[prev:lo], np.full(a.shape[0], r, dtype=owner.dtype)]
        prev = hi
    pa.append(seg_a[prev:])
    pb.append(seg_b[prev:])
    po.append(owner[prev:])
    return np.concatenate(pa), np.concatenate(pb), np.concatenate(po)


def sorted_unique(a: np.ndarray) -> np.ndarray:
    """The distinct values of ``a``, ascending."""
    if a.size == 0:
        return a
    a = np.sort(a, kind="stable")
    return a[np.r_[True, a[1:] != a[:-1]]]


#: Cells per side of the hash grid, in units of the clearance (see candidate_segment_pairs).
_CELL_PER_C = 3.0
#: Raw same-cell pairs handled per chunk (bounds memory at 10^5 robots).
_CHUNK = 1 << 22
_OFF = 1 << 30
#: Query segments x segments up to which a query is measured pair by pair, without the
#: grid (a few changed robots among a few hundred segments: the grid costs more).
_DIRECT = 1 << 12


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


def _query_pairs(
    seg_a: np.ndarray,
    seg_b: np.ndarray,
    owner: np.ndarray,
    c: float,
    query: np.ndarray,
    cross_only: bool,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`close_segment_pairs` of a query by measuring every pair with a query segment (the
    same pairs as the grid, which only skips pairs farther apart than c)."""
    m = seg_a.shape[0]
    q = np.flatnonzero(query)
    other = np.flatnonzero(~query) if cross_only else np.arange(m)
    s, t = np.repeat(q, other.size), np.tile(other, q.size)
    os_, ot = owner[s], owner[t]
    keep = os_ != ot
    if not cross_only:  # two query segments: once
        keep &= ~query[t] | (s < t)
    flip = os_ > ot
    s, t = np.where(flip, t, s)[keep], np.where(flip, s, t)[keep]
    u = np.sort(s * m + t)
    s, t = u // m, u % m
    d = seg_seg_dist(seg_a[s], seg_b[s], seg_a[t], seg_b[t])
    near = d <= c
    return s[near], t[near], d[near]


def close_segment_pairs(
    seg_a: np.ndarray,
    seg_b: np.ndarray,
    owner: np.ndarray,
    c: float,
    query: np.ndarray | None = None,
    cross_only: bool = False,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Segment pairs (s, t), owner[s] < owner[t], within c, with their distances
    (:func:`geometry.seg_seg_dist` of segments s and t, in that order); with ``query``
    (bool per segment) only the pairs with at least one query segment (``cross_only``:
    exactly one)."""
    m = seg_a.shape[0]
    empty = np.zeros(0, dtype=np.int64)
    if m == 0 or (query is not None and not np.any(query)):
        return empty, empty, np.zeros(0)
    lim = float(np.max(np.abs(np.concatenate([seg_a, seg_b]))))
    h = _CELL_PER_C * c
    if not (math.isfinite(lim) and c > 0 and lim / h < _OFF / 4):
        raise ValueError("segments must be finite and c > 0 (and coordinates / c < 2^26)")
    if query is not None and int(np.count_nonzero(query)) * m <= _DIRECT:
        return _query_pairs(seg_a, seg_b, owner, c, query, cross_only)
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
    out_d: list[np.ndarray] = []
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
            u = sorted_unique(s * m + t)
            s, t = u // m, u % m
            d = seg_seg_dist(seg_a[s], seg_b[s], seg_a[t], seg_b[t])
            near = d <= c
            out.append(u[near])
            out_d.append(d[near])
        lo = hi
    if not out:
        return empty, empty, np.zeros(0)
    u, d = np.concatenate(out), np.concatenate(out_d)
    if len(out) > 1 and u.size > 1:  # a pair met in two chunks: once (the same distance)
        order = np.argsort(u, kind="stable")
        u, d = u[order], d[order]
        first = np.r_[True, u[1:] != u[:-1]]
        u, d = u[first], d[first]
    return u // m, u % m, d


def candidate_segment_pairs(
    seg_a: np.ndarray, seg_b: np.ndarray, owner: np.ndarray, c: float
) -> tuple[np.ndarray, np.ndarray]:
    """Segment index pairs (s, t), owner[s] < owner[t], whose distance is <= c.

    Exact (every such pair, no other), sorted by (s, t). Spatial hashing: each segment
    is entered in every cell (side 3c) its c/2-dilation may meet - two segments within
    c share such a cell - so only same-cell pairs are candidates; they are deduplicated
    with one int64 key, then measured. Cost ~ total path length / c + candidates.
    """
    s, t, _ = close_segment_pairs(seg_a, seg_b, owner, c)
    return s, t
