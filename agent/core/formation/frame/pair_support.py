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
loop over the candidates and without moving every sighting of i for every candidate (a
50-NAO record set has ~3·10⁵ candidates and ~5·10⁶ (candidate, sighting of i) entries a
side, and every agent plans on the same records). Only the pairs (candidate, sighting h
of j) that can be within tol are looked at, found from what does not depend on the
candidate's turn:

* **distance window**: a rotation keeps lengths, |m_k| = |v_k − v_src| = L, so a sighting
  h of j within tol of m_k lies within tol of that distance from j (triangle inequality).
  Each robot's sightings are kept sorted by distance (:class:`_Shelf`), and each
  (src, k) looks at the slice of j's sightings that bounds [L − tol, L + tol] from
  outside (bands of :data:`BAND_WIDTH`, tol widened by :data:`SLACK` for rounding).
  This depends on src, k and j only: it is found once for all the candidates of src
  with robot j (a *group*), not once per candidate.
* **turn arc**: h at distance r and bearing α is within tol' (the widened tol) of
  m_k, at bearing φ_k − turn, exactly when ``cos(φ_k − turn − α) ≥ C``,
  ``C = (L² + r² − tol'²) / (2 L r)`` (the law of cosines), i.e. for the turns within
  ``arccos C`` of ``φ_k − α``. The arc is widened by :data:`ARC_SLACK` (its rounding is
  below 1e-7 rad once L and r exceed tol', else every turn is taken), and the group's
  candidates are kept sorted into :data:`TURN_BINS` bins of their turn, so an arc
  reads the candidates of the bins it touches, a slice.
* **the exact test** on those pairs only: d² computed as the brute force computes it,
  ``(mx − hx)² + (my − hy)²`` with ``m = (rx·c − ry·s, rx·s + ry·c)``,
  ``c, s = cos(−turn), sin(−turn)``, in elementwise float64 operations (no BLAS, so no
  host-dependent summation order: the same floats wherever an entry sits in an array).
  Every h the brute force finds within tol is among them, so the nearest is too
  whenever it is within tol (``√d² ≤ tol`` is monotone in d²), and (candidate, k)
  counts when some h other than dst is within tol and dst is not the nearest (a smaller
  d², or an equal one at a lower index).

So the counts are the brute force's exactly. Sightings so far away that squares could
overflow (beyond :data:`HUGE` m), or non-finite input, take the brute force itself
(:func:`_count_all`).
"""

from __future__ import annotations

import math

import numpy as np

#: Most (candidate, sighting of i) entries held at once by the brute force.
CHUNK_ELEMENTS = 1 << 15
#: Most (group, other sighting of i) blocks held at once by the windowed count.
CHUNK_BLOCKS = 1 << 12
#: Width (m) of the distance bands that bound a window of j's sightings (a power of two,
#: so that a distance divides by it exactly), and the most bands (wider for far sightings).
BAND_WIDTH = 1.0 / 64.0
MAX_BANDS = 512
#: Relative widening of a distance window, far above float rounding (~1e-15).
SLACK = 1e-9
#: Bins of a group's candidate turns over the full circle (an arc reads whole bins).
TURN_BINS = 64
#: Widening (rad) of a turn arc, far above the rounding of its ends (< 1e-7 rad).
ARC_SLACK = 1e-6
#: Largest sighting coordinate (m) of the windowed count: d² of up to ~1e201 is finite.
HUGE = 1e100

TWO_PI = 2.0 * math.pi


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
    if tame:
        out[live] = _count_arcs(src[live], dst[live], turn[live], owner, vecs, starts, counts,
                                epsilon, rel_tol)  # fmt: skip
        return out
    # chunks of whole candidates, at most CHUNK_ELEMENTS (candidate, other sighting of i)
    # entries each (one candidate at least)
    ends = np.cumsum(counts[oi[live]] - 1)
    lo = 0
    while lo < live.size:
        done = int(ends[lo - 1]) if lo else 0
        hi = max(lo + 1, int(np.searchsorted(ends, done + CHUNK_ELEMENTS, side="right")))
        cand = live[lo:hi]
        side = _Side(src[cand], dst[cand], turn[cand], oi[cand], oj[cand])
        out[cand] = _count_all(side, starts, counts, vecs, epsilon, rel_tol)
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
    :attr:`order` that :meth:`window` gives (with their distances and bearings, in that
    order)."""

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
        #: bearing of each sighting (in :attr:`order`), in turn bins
        self.bin_of = np.arctan2(self.y, self.x) * (TURN_BINS / TWO_PI)
        robots = starts.size - 1
        # below[r, b]: position in order of robot r's first sighting at >= b · width m
        below = np.empty((robots, self.bands + 1), dtype=np.int64)
        for r in range(robots):
            seg = sorted_norm[starts[r] : starts[r + 1]]
            below[r] = starts[r] + np.searchsorted(seg, edges, side="left")
        self.below = below.ravel()

    def bands_of(self, low: np.ndarray, high: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Band edges (indices) bounding [low, high] from outside (finite bounds)."""
        inv = 1.0 / self.width
        # floor(low / width) (truncation is floor for >= 0): band edge <= low
        a = np.clip(low * inv, 0.0, self.bands).astype(np.int64)
        # floor(high / width) + 1: band edge > high
        b = np.clip(high * inv + 1.0, 0.0, self.bands).astype(np.int64)
        return a, b


class _Levers:
    """Every (src, k) of one robot, k ≠ src (by src, then k ascending): the lever
    ``v_k − v_src`` (rx, ry), its tol, distance bands and turn arc (module docstring).
    Shared by every candidate of src."""

    def __init__(
        self,
        owner: np.ndarray,
        starts: np.ndarray,
        counts: np.ndarray,
        shelf: _Shelf,
        epsilon: float,
        rel_tol: float,
    ) -> None:
        per = counts[owner] - 1
        #: rows of sighting s: base[s] .. base[s + 1]
        self.base = np.concatenate(([0], np.cumsum(per)))
        n = int(self.base[-1])
        src = np.repeat(np.arange(owner.size), per)
        # every sighting of src's robot but src: its start + running index, skipping src
        k = np.arange(n) - np.repeat(self.base[:-1], per) + np.repeat(starts[owner], per)
        k += k >= src
        self.rx = shelf.vx[k] - shelf.vx[src]
        self.ry = shelf.vy[k] - shelf.vy[src]
        length = np.sqrt(self.rx * self.rx + self.ry * self.ry)
        self.tol = 0.5 * epsilon + rel_tol * length
        wide = self.tol + SLACK * (1.0 + length + self.tol)
        self.low, self.high = shelf.bands_of(length - wide, length + wide)
        # the turn arc, in bins: every point within `wide` of the moved lever lies within
        # asin(wide / length) of its bearing (the tangents from j); a lever shorter than
        # `wide`, or an arc of nearly every turn, takes every bin
        bins = TURN_BINS / TWO_PI
        with np.errstate(divide="ignore", invalid="ignore"):
            half = np.arcsin(np.minimum(wide / length, 1.0)) + ARC_SLACK
        every = ~(length > wide) | (half >= math.pi - 2.0 * TWO_PI / TURN_BINS)
        bearing = np.arctan2(self.ry, self.rx)
        #: bin of the arc's ends, bearing of the sighting of j not yet subtracted
        self.first = np.where(every, 0.0, (bearing - half) * bins)
        self.last = np.where(every, 4.0 * TURN_BINS, (bearing + half) * bins)


class _Groups:
    """The candidates sorted by group (src, j), then turn bin: each group's slice
    ``start[g]:start[g + 1]``, its src and j, and each candidate's rotation and dst."""

    def __init__(
        self, src: np.ndarray, dst: np.ndarray, turn: np.ndarray, owner: np.ndarray, robots: int
    ) -> None:
        c = np.cos(-turn)
        s = np.sin(-turn)
        # the turn each rotation stands for, in [0, 2π], and its bin
        u = np.mod(np.arctan2(-s, c), TWO_PI)
        tbin = np.minimum((u * (TURN_BINS / TWO_PI)).astype(np.int64), TURN_BINS - 1)
        key = src * robots + owner[dst]
        self.order = np.argsort(key * TURN_BINS + tbin, kind="stable")
        key = key[self.order]
        first = np.flatnonzero(np.concatenate(([True], key[1:] != key[:-1])))
        self.start = np.append(first, self.order.size)
        self.size = np.diff(self.start)
        self.src = src[self.order[first]]
        self.j = owner[dst[self.order[first]]]
        self.c, self.s = c[self.order], s[self.order]
        self.dst, self.bin = dst[self.order], tbin[self.order]


def _count_arcs(
    src: np.ndarray,
    dst: np.ndarray,
    turn: np.ndarray,
    owner: np.ndarray,
    vecs: np.ndarray,
    starts: np.ndarray,
    counts: np.ndarray,
    epsilon: float,
    rel_tol: float,
) -> np.ndarray:
    """Counts of candidates whose robots have two sightings or more (finite input within
    :data:`HUGE`), by groups, distance windows and turn arcs (module docstring)."""
    shelf = _Shelf(owner, vecs, starts)
    levers = _Levers(owner, starts, counts, shelf, epsilon, rel_tol)
    groups = _Groups(src, dst, turn, owner, counts.size)
    blocks = counts[owner[groups.src]] - 1  # (group, other sighting of i) blocks
    ends = np.cumsum(blocks)
    hits = np.zeros(src.size, dtype=np.int64)
    g0 = 0
    while g0 < blocks.size:
        done = int(ends[g0 - 1]) if g0 else 0
        g1 = max(g0 + 1, int(np.searchsorted(ends, done + CHUNK_BLOCKS, side="right")))
        lo, hi = int(groups.start[g0]), int(groups.start[g1])
        hits[lo:hi] = _count_chunk(g0, g1, blocks, groups, levers, shelf)
        g0 = g1
    out = np.zeros(src.size, dtype=np.int64)
    out[groups.order] = hits
    return out


def _count_chunk(
    g0: int, g1: int, blocks: np.ndarray, groups: _Groups, levers: _Levers, shelf: _Shelf
) -> np.ndarray:
    """Counts of the candidates of groups ``g0 .. g1 − 1`` (in the groups' order)."""
    gs = np.arange(g0, g1)
    per = blocks[gs]
    nb = int(per.sum())
    bg = np.repeat(gs, per)  # each block's group
    row = np.repeat(levers.base[groups.src[gs]] - (np.cumsum(per) - per), per) + np.arange(nb)
    # the distance window of j's sightings of each block: one triple per sighting in it
    band = groups.j[bg] * (shelf.bands + 1)
    lo = shelf.below[band + levers.low[row]]
    span = shelf.below[band + levers.high[row]] - lo
    tb = np.repeat(np.arange(nb), span)  # each triple's block
    pos = np.repeat(lo - (np.cumsum(span) - span), span) + np.arange(int(span.sum()))
    tr = row[tb]
    # each triple's arc, [a, a + n] in bins (a in [0, TURN_BINS), n < TURN_BINS)
    at = shelf.bin_of[pos]
    a = np.floor(levers.first[tr] - at).astype(np.int64)
    n = np.minimum(np.floor(levers.last[tr] - at).astype(np.int64) - a, TURN_BINS - 1)
    a &= TURN_BINS - 1
    # the chunk's candidates, each group's twice over (bins 0 .. 2·TURN_BINS − 1), so
    # that an arc across bin 0 is one slice
    first = int(groups.start[g0])
    size = groups.size[gs]
    twice = 2 * size
    grp = np.repeat(np.arange(gs.size), twice)
    lap = np.arange(int(twice.sum())) - np.repeat(np.cumsum(twice) - twice, twice)
    dbl = groups.start[gs][grp] - first + lap % np.repeat(size, twice)  # chunk candidate
    key = (
        grp * (2 * TURN_BINS)
        + (lap >= np.repeat(size, twice)) * TURN_BINS
        + groups.bin[dbl + first]
    )
    cum = np.concatenate(([0], np.cumsum(np.bincount(key, minlength=gs.size * 2 * TURN_BINS))))
    base = (bg - g0)[tb] * (2 * TURN_BINS) + a
    lo = cum[base]
    n = cum[base + n + 1] - lo
    pt = np.repeat(np.arange(tb.size), n)  # each pair's triple
    q = dbl[np.repeat(lo - (np.cumsum(n) - n), n) + np.arange(int(n.sum()))] + first
    # the exact test, as the brute force computes it
    pr, pp = tr[pt], pos[pt]
    rx, ry, c, s = levers.rx[pr], levers.ry[pr], groups.c[q], groups.s[q]
    dx = (rx * c - ry * s) - shelf.x[pp]
    dy = (rx * s + ry * c) - shelf.y[pp]
    d2 = dx * dx + dy * dy
    near = np.flatnonzero(np.sqrt(d2) <= levers.tol[pr])
    d2, q, h, blk = d2[near], q[near], shelf.order[pp[near]], tb[pt[near]]
    return _closed(d2, q, h, blk, bg, groups, first, int(groups.start[g1]) - first)


def _closed(
    d2: np.ndarray,
    q: np.ndarray,
    h: np.ndarray,
    blk: np.ndarray,
    bg: np.ndarray,
    groups: _Groups,
    first: int,
    count: int,
) -> np.ndarray:
    """Per candidate ``first .. first + count − 1``, its entries (block, candidate) that
    close a triangle, from the pairs within tol: candidate ``q``, sighting ``h`` of j at
    ``d2``, in block ``blk`` (of group ``bg[blk]``). An entry closes when a sighting other
    than dst is within tol and dst is not the nearest (a smaller d², or an equal one at a
    lower index, as np.argmin)."""
    size = groups.size[bg]
    offset = np.cumsum(size) - size
    entries = int(size.sum())
    e = offset[blk] + q - groups.start[bg[blk]]
    at_dst = h == groups.dst[q]
    other = np.flatnonzero(~at_dst)
    eo = e[other]
    one = np.empty(entries, dtype=np.int64)
    one[eo] = other  # one pair of each entry stands for it
    keep = other[one[eo] == other]
    if np.any(at_dst):
        de = e[at_dst]
        nearest = np.zeros(entries, dtype=bool)
        nearest[de] = True
        d_dst = np.empty(entries)
        d_dst[de] = d2[at_dst]
        o = other[nearest[eo]]
        eo = e[o]
        beats = (d2[o] < d_dst[eo]) | ((d2[o] == d_dst[eo]) & (h[o] < groups.dst[q[o]]))
        nearest[eo[beats]] = False
        keep = keep[~nearest[e[keep]]]
    return np.bincount(q[keep] - first, minlength=count)


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
