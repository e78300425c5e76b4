"""Release points: how far a robot must have walked before a robot waiting for it may
start (finer waits than whole waves; our addition to NAO paper 5.2.2 (iii) step 7, "the leader goes
to its destination firstly, and then the followers", and to the rule of :mod:`safety`).

A robot b that waits for robot a (a before b, :mod:`safety`'s ``ab_ok``) need not wait
for a to hold its slot: once a has walked past arc length ``s`` of its path, a stays on
the rest of it, ``path_a[s:]``, whatever the two speeds. So b may start as soon as

    d(path_b, path_a[s:]) >= the pair's clearance,                           (R1)

and, while b stands, a's whole path must clear b's start (part of ``ab_ok``). The
*release point* of the pair is the smallest such s: the last arc length of ``path_a``
within the clearance of ``path_b``. It is at most ``len(path_a)`` (then b waits for a to
hold, the old rule) and it is > 0 for every pair whose paths come within the clearance.
The robot waits for an *event* (a's published progress along its path reaches s), never
for a time: the rule holds at any speeds.

Computed exactly per segment pair (s of robot i, t of robot k, within the clearance): the
points of segment s within ``radius`` of segment t are the intersection of the segment
with a capsule (two discs and a band), an interval; its upper end, as an arc length of
i's path, is a candidate release point of i for k, and the largest candidate over the
pair's segment pairs is the release point. ``radius`` is the pair's clearance *without*
the rounding slack of :mod:`safety`, so (R1) holds with that slack to spare.

The event's other side, :func:`walked_along`: how far along its path a walking robot is,
at least (a robot off its leg counts as less far along), which the agent publishes.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

#: No point of the segment is within the radius.
NONE = -np.inf


def arc_offsets(owner: np.ndarray, seg_a: np.ndarray, seg_b: np.ndarray) -> np.ndarray:
    """Arc length of each segment's first point along its owner's path (segments of one
    path consecutive and in order, as :func:`close_pairs.path_segments` gives them)."""
    seg_len = np.hypot(*(seg_b - seg_a).T)
    if owner.size == 0:
        return np.zeros(0)
    cum = np.cumsum(seg_len) - seg_len
    first = np.r_[True, owner[1:] != owner[:-1]]
    base = np.maximum.accumulate(np.where(first, np.arange(owner.size), 0))
    return np.asarray(cum - cum[base])


def _disc_upper(p0: np.ndarray, d: np.ndarray, c: np.ndarray, r: np.ndarray) -> np.ndarray:
    """Largest u in [0, 1] with |p0 + u·d - c| < r (NONE if there is none)."""
    w = p0 - c
    a = np.einsum("ij,ij->i", d, d)
    b = np.einsum("ij,ij->i", d, w)
    cc = np.einsum("ij,ij->i", w, w) - r * r
    disc = b * b - a * cc
    moving = a > 0
    root = np.sqrt(np.maximum(disc, 0.0))
    safe_a = np.where(moving, a, 1.0)
    lo = (-b - root) / safe_a
    hi = (-b + root) / safe_a
    ok = moving & (disc > 0) & (hi > 0) & (lo < 1)
    out = np.where(ok, np.minimum(hi, 1.0), NONE)
    return np.where(moving, out, np.where(cc < 0, 1.0, NONE))


def _band_upper(
    p0: np.ndarray, d: np.ndarray, a: np.ndarray, b: np.ndarray, r: np.ndarray
) -> np.ndarray:
    """Largest u in [0, 1] with p0 + u·d inside the band of segment [a, b]: projection on
    the segment within [0, |ab|], distance to its line < r (NONE if there is none)."""
    ab = b - a
    ln = np.hypot(*ab.T)
    pos = ln > 0
    e = ab / np.where(pos, ln, 1.0)[:, None]
    nrm = np.c_[-e[:, 1], e[:, 0]]
    w = p0 - a
    lo = np.zeros(p0.shape[0])
    hi = np.ones(p0.shape[0])
    # each constraint alpha + beta·u in [low, high] cuts [lo, hi]
    for alpha, beta, low, high in (
        (np.einsum("ij,ij->i", w, e), np.einsum("ij,ij->i", d, e), 0.0 * ln, ln),
        (np.einsum("ij,ij->i", w, nrm), np.einsum("ij,ij->i", d, nrm), -r, r),
    ):
        still = beta == 0
        sb = np.where(still, 1.0, beta)
        u1, u2 = (low - alpha) / sb, (high - alpha) / sb
        lo = np.where(still, lo, np.maximum(lo, np.minimum(u1, u2)))
        hi = np.where(still, hi, np.minimum(hi, np.maximum(u1, u2)))
        outside = still & ((alpha < low) | (alpha > high))
        hi = np.where(outside, NONE, hi)
    return np.where(pos & (hi >= lo), hi, NONE)


def last_within(
    p0: np.ndarray, p1: np.ndarray, a: np.ndarray, b: np.ndarray, r: np.ndarray
) -> np.ndarray:
    """Largest u in [0, 1] with d(p0 + u·(p1 - p0), [a, b]) < r, per row (NONE: none)."""
    d = p1 - p0
    k = p0.shape[0]
    rr = np.broadcast_to(r, (k,))
    # the two discs (around a, around b) in one array
    disc = _disc_upper(
        np.concatenate((p0, p0)),
        np.concatenate((d, d)),
        np.concatenate((a, b)),
        np.concatenate((rr, rr)),
    )
    out = np.maximum(np.maximum(disc[:k], disc[k:]), _band_upper(p0, d, a, b, rr))
    return np.asarray(out)


def segment_releases(
    seg_a: np.ndarray,
    seg_b: np.ndarray,
    arc0: np.ndarray,
    s: np.ndarray,
    t: np.ndarray,
    radius: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """Per segment pair (s, t): the last arc length of s's path within ``radius`` of
    segment t, and of t's path within ``radius`` of segment s (NONE: not within)."""
    seg_len = np.hypot(*(seg_b - seg_a).T)
    k = s.size
    # both directions in one array: rows (s, t), then rows (t, s)
    own, other = np.concatenate((s, t)), np.concatenate((t, s))
    rr = np.broadcast_to(radius, (k,))
    u = last_within(seg_a[own], seg_b[own], seg_a[other], seg_b[other], np.concatenate((rr, rr)))
    arc = np.where(u > NONE, arc0[own] + np.maximum(u, 0.0) * seg_len[own], NONE)
    return arc[:k], arc[k:]


def tail(path: np.ndarray, s: float) -> np.ndarray:
    """``path[s:]``: the polyline from arc length ``s`` on (its last point if s >= the
    length; the whole path if s <= 0)."""
    p = np.asarray(path, dtype=np.float64).reshape(-1, 2)
    if s <= 0.0 or p.shape[0] < 2:
        return p
    seg = np.hypot(*np.diff(p, axis=0).T)
    cum = np.r_[0.0, np.cumsum(seg)]
    if s >= cum[-1]:
        return p[-1:]
    k = int(np.searchsorted(cum, s, side="right")) - 1
    f = (s - cum[k]) / seg[k] if seg[k] > 0 else 0.0
    return np.vstack([p[k] + f * (p[k + 1] - p[k]), p[k + 1 :]])


def walked_along(goals: Sequence[np.ndarray], leg: int, position: np.ndarray) -> float:
    """How far along the path start (0, 0) -> ``goals`` (this robot's fixed frame, from
    its start) a robot walking leg ``leg`` at ``position`` is, at least: the legs
    before, plus the leg's length less the distance still to its goal (a robot off the
    leg is counted as less far along). Never above the path's length."""
    prev = np.zeros(2)
    done = 0.0
    for k, g in enumerate(goals):
        g = np.asarray(g, dtype=np.float64)
        seg = float(np.hypot(*(g - prev)))
        if k == leg:
            left = float(np.hypot(*(g - np.asarray(position, dtype=np.float64))))
            return done + max(0.0, seg - left)
        done += seg
        prev = g
    return done
