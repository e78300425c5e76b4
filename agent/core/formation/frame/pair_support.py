"""Loop-consistency support of candidate pairs, for every candidate at once (docs/design.md §9;
the triangles of NAO paper 4.1.2's neighbour check, eq. 9, rotated by the candidate's
relative heading).

A candidate ``t`` pairs sighting ``src[t]`` of robot i with sighting ``dst[t]`` of robot j,
at the relative heading ``turn[t]`` = ψ_j − ψ_i it implies. Every *other* sighting k of i
is moved into j's frame,

    m_k = R(−turn[t]) (v_k − v_src),

and counts one when the nearest of j's sightings (all of them, ``dst`` included; of equal
distances the one of lower index, as ``np.argmin`` picks) lies within
``tol = ε/2 + rel_tol·|v_k − v_src|`` of m_k and is not ``dst`` itself: the triangle i–j–c
closes. :mod:`pose_pairing` adds the counts of both sides.

This is the count of a brute force over all of j's sightings, computed without a Python
loop over the candidates (a 50-NAO record set has ~3·10⁵ candidates and ~5·10⁶
(candidate, sighting of i) entries a side, and every agent plans on the same records),
looking only at the sightings of j that can be within tol:

* **distance window**: a rotation keeps lengths, |m_k| = |v_k − v_src|, so a sighting h
  of j within tol of m_k lies within tol of that distance from j (triangle inequality).
  Each robot's sightings are kept sorted by distance (:class:`_Shelf`), and an entry
  looks at the slice that bounds [|v_k − v_src| − tol, |v_k − v_src| + tol] from
  outside (bands of :data:`BAND_WIDTH`, widened by :data:`SLACK` for rounding). The least
  d² over the window is the least over all of j whenever either is within tol; outside
  tol neither counts.
* **the nearest is dst**: an entry whose least d² is within tol does not count when dst
  is at that d² and no sighting of j of lower index is (those would be in the window
  too), as the argmin over all of j decides.

Every d² is computed as the brute force computes it, ``(mx − hx)² + (my − hy)²`` in
elementwise float64 operations (no BLAS, so no host-dependent summation order, and the
same floats wherever an entry sits in an array), so the counts are the brute force's
exactly. Sightings so far away that squares could overflow (beyond :data:`HUGE` m), or
non-finite input, take the brute force itself (:func:`_count_all`).
"""

from __future__ import annotations

import math

import numpy as np

#: Most (candidate, sighting of i) entries held at once.
CHUNK_ELEMENTS = 1 << 15
#: Width (m) of the distance bands that bound a window of j's sightings (a power of two,
#: so that a distance divides by it exactly), and the most bands (wider for far sightings).
BAND_WIDTH = 1.0 / 64.0
MAX_BANDS = 512
#: Relative widening of a distance window, far above float rounding (~1e-15).
SLACK = 1e-9
#: Largest sighting coordinate (m) of the windowed count: d² of up to ~1e201 is finite.
HUGE = 1e100


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
    # a robot with no other sighting closes no triangle, and one whose only sighting is
    # dst has no hit that counts
    live = np.flatnonzero((counts[oi] > 1) & (counts[oj] > 1))
    if live.size == 0:
        return out
    tame = bool(np.all(np.abs(vecs) <= HUGE) and np.all(np.isfinite(turn)))
    shelf = _Shelf(owner, vecs, starts) if tame else None
    # chunks of whole candidates, at most CHUNK_ELEMENTS (candidate, other sighting of i)
    # entries each (one candidate at least)
    ends = np.cumsum(counts[oi[live]] - 1)
    lo = 0
    while lo < live.size:
        done = int(ends[lo - 1]) if lo else 0
        hi = max(lo + 1, int(np.searchsorted(ends, done + CHUNK_ELEMENTS, side="right")))
        cand = live[lo:hi]
        side = _Side(src[cand], dst[cand], turn[cand], oi[cand], oj[cand])
        if shelf is None:
            out[cand] = _count_all(side, starts, counts, vecs, epsilon, rel_tol)
        else:
            out[cand] = _count(side, starts, counts, shelf, epsilon, rel_tol)
        lo = hi
    return out


class _Side:
    """A chunk of candidates: their sightings, turns and robots (i = src's, j = dst's)."""

    def __init__(
        self, src: np.ndarray, dst: np.ndarray, turn: np.ndarray, oi: np.ndarray, oj: np.ndarray
    ) -> None:
        self.src, self.dst, self.turn, self.oi, self.oj = src, dst, turn, oi, oj


class _Shelf:
    """Every robot's sightings sorted by distance from it, and where each distance band
    starts: the sightings of robot j at distances in [low, high] are within a slice of
    :attr:`order` that :meth:`window` gives."""

    def __init__(self, owner: np.ndarray, vecs: np.ndarray, starts: np.ndarray) -> None:
        self.vx = np.ascontiguousarray(vecs[:, 0])
        self.vy = np.ascontiguousarray(vecs[:, 1])
        norm = np.hypot(self.vx, self.vy)
        #: sightings by robot, then distance, then index
        self.order = np.lexsort((np.arange(owner.size), norm, owner))
        self.x = self.vx[self.order]
        self.y = self.vy[self.order]
        top = float(norm.max())
        #: band width (m), a power of two: x / width and b · width are exact
        self.width = max(BAND_WIDTH, 2.0 ** math.ceil(math.log2(max(top, 1e-300) / MAX_BANDS)))
        self.bands = int(top / self.width) + 2  # bands · width > every distance
        edges = np.arange(self.bands + 1) * self.width
        sorted_norm = norm[self.order]
        robots = starts.size - 1
        # below[r, b]: position in order of robot r's first sighting at >= b · width m
        below = np.empty((robots, self.bands + 1), dtype=np.int64)
        for r in range(robots):
            seg = sorted_norm[starts[r] : starts[r + 1]]
            below[r] = starts[r] + np.searchsorted(seg, edges, side="left")
        self.below = below.ravel()

    def window(
        self, robot: np.ndarray, low: np.ndarray, high: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """[lo, hi) positions in :attr:`order` holding every sighting of ``robot`` at a
        distance in [low, high] (finite bounds), and possibly a few more."""
        row = robot * (self.bands + 1)
        inv = 1.0 / self.width
        # floor(low / width) (truncation is floor for >= 0): band edge <= low
        a = np.clip(low * inv, 0.0, self.bands).astype(np.int64)
        # floor(high / width) + 1: band edge > high
        b = np.clip(high * inv + 1.0, 0.0, self.bands).astype(np.int64)
        return self.below[row + a], self.below[row + b]


def _count(
    side: _Side,
    starts: np.ndarray,
    counts: np.ndarray,
    shelf: _Shelf,
    epsilon: float,
    rel_tol: float,
) -> np.ndarray:
    """Counts of a chunk (module docstring), one entry per (candidate, other sighting k
    of i), looking at each entry's distance window of j's sightings only."""
    per = counts[side.oi] - 1
    n = int(per.sum())
    row = np.repeat(np.arange(per.size), per)  # the entry's candidate
    # every sighting of i but src: ki = start of i + running index, skipping src
    ki = np.arange(n) + np.repeat(starts[side.oi] - (np.cumsum(per) - per), per)
    ki += ki >= np.repeat(side.src, per)
    rx = shelf.vx[ki] - np.repeat(shelf.vx[side.src], per)
    ry = shelf.vy[ki] - np.repeat(shelf.vy[side.src], per)
    c = np.repeat(np.cos(-side.turn), per)
    s = np.repeat(np.sin(-side.turn), per)
    mx = rx * c - ry * s  # (v_k − v_src) · [[c, s], [−s, c]], row vector times matrix
    my = rx * s + ry * c
    lever = np.sqrt(rx * rx + ry * ry)
    tol = 0.5 * epsilon + rel_tol * lever
    slack = tol + SLACK * (1.0 + lever + tol)
    lo, hi = shelf.window(np.repeat(side.oj, per), lever - slack, lever + slack)
    span = hi - lo
    # entries by window length, longest first: the p-th sighting of the windows is then
    # looked at for a prefix of the entries (a stable radix sort on small keys)
    top = int(span.max())
    key = (top - span).astype(np.uint16 if top < 1 << 16 else np.int64)
    by_span = np.argsort(key, kind="stable")
    lo_s, mx_s, my_s = lo[by_span], mx[by_span], my[by_span]
    live = n - np.cumsum(np.bincount(span))  # live[p]: entries with span > p
    best = np.full(n, np.inf)  # the least d² over the window
    for p in range(top):
        m = int(live[p])
        pos = lo_s[:m] + p
        dx = mx_s[:m] - shelf.x[pos]
        dy = my_s[:m] - shelf.y[pos]
        np.multiply(dx, dx, out=dx)
        np.multiply(dy, dy, out=dy)
        np.add(dx, dy, out=dx)  # dx² + dy², as the brute force computes it
        np.minimum(best[:m], dx, out=best[:m])
    least = np.empty(n)
    least[by_span] = best
    hit = np.flatnonzero(np.sqrt(least) <= tol)  # the nearest of j is within tol
    # ... and is dst when dst is at that d² and no sighting of lower index is
    d = side.dst[row[hit]]
    dx = mx[hit] - shelf.vx[d]
    dy = my[hit] - shelf.vy[d]
    at_dst = dx * dx + dy * dy == least[hit]
    tied = hit[at_dst]
    at_dst[at_dst] = ~_lower_tie(tied, lo[tied], span[tied], d[at_dst], mx, my, least, shelf)
    return np.bincount(row[hit[~at_dst]], minlength=per.size)


def _lower_tie(
    e: np.ndarray,
    lo: np.ndarray,
    span: np.ndarray,
    d: np.ndarray,
    mx: np.ndarray,
    my: np.ndarray,
    least: np.ndarray,
    shelf: _Shelf,
) -> np.ndarray:
    """Whether a sighting of index below ``d`` is at d² ``least`` too, for the entries
    ``e`` with windows ``[lo, lo + span)`` (each holds every sighting of j at that d²)."""
    which = np.repeat(np.arange(e.size), span)
    pos = np.repeat(lo - (np.cumsum(span) - span), span) + np.arange(int(span.sum()))
    f = e[which]
    dx = mx[f] - shelf.x[pos]
    dy = my[f] - shelf.y[pos]
    tie = (dx * dx + dy * dy == least[f]) & (shelf.order[pos] < d[which])
    return np.bincount(which[tie], minlength=e.size) > 0


def _count_all(
    side: _Side,
    starts: np.ndarray,
    counts: np.ndarray,
    vecs: np.ndarray,
    epsilon: float,
    rel_tol: float,
) -> np.ndarray:
    """Counts of a chunk by brute force over all of j's sightings, one of j at a time
    (the first of equal distances the nearest, as np.argmin over them)."""
    total = np.zeros(side.src.size, dtype=np.int64)
    for a in np.unique(counts[side.oi]).tolist():
        for b in np.unique(counts[side.oj]).tolist():
            sel = np.flatnonzero((counts[side.oi] == a) & (counts[side.oj] == b))
            if sel.size:
                total[sel] = _count_group(sel, a, b, side, starts, vecs, epsilon, rel_tol)
    return total


def _count_group(
    sel: np.ndarray,
    a: int,
    b: int,
    side: _Side,
    starts: np.ndarray,
    vecs: np.ndarray,
    epsilon: float,
    rel_tol: float,
) -> np.ndarray:
    """Brute-force counts of the candidates ``sel`` whose robots have ``a`` and ``b``
    sightings."""
    ki = starts[side.oi[sel]][:, None] + np.arange(a)[None, :]  # (C, a) sightings of i
    hj = starts[side.oj[sel]][:, None] + np.arange(b)[None, :]  # (C, b) sightings of j
    base = vecs[side.src[sel]]
    rx = vecs[ki, 0] - base[:, 0:1]
    ry = vecs[ki, 1] - base[:, 1:2]
    c = np.cos(-side.turn[sel])[:, None]
    s = np.sin(-side.turn[sel])[:, None]
    mx = rx * c - ry * s
    my = rx * s + ry * c
    d2 = np.full(mx.shape, np.inf)
    near = np.zeros(mx.shape, dtype=np.int64)
    for h in range(b):
        dx = mx - vecs[hj[:, h : h + 1], 0]
        dy = my - vecs[hj[:, h : h + 1], 1]
        dd = dx * dx + dy * dy
        closer = dd < d2
        np.copyto(d2, dd, where=closer)
        np.copyto(near, h, where=closer)
    hit = np.take_along_axis(hj, near, axis=1)
    tol = 0.5 * epsilon + rel_tol * np.sqrt(rx * rx + ry * ry)
    ok = (np.sqrt(d2) <= tol) & (hit != side.dst[sel][:, None]) & (ki != side.src[sel][:, None])
    return np.asarray(ok.sum(axis=1), dtype=np.int64)
