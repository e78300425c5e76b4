"""The safety rule and its checker (NAO paper 4.2 and 5.2.2 (iii) step 7: "the leader goes to its
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
*i-before-k*, *k-before-i* (:class:`PairFlags`), with the pair's two release points
(:mod:`release`: how far the first must have walked before the second may start, for
the dependency rule of :mod:`execution`; the wave rule waits until it holds). Only pairs whose paths come within c
matter; they are found exactly by the spatial hashing of :mod:`close_pairs`. Between
detour rounds only the pairs of the robots whose path changed are redone
(:func:`update_flags`). The wave scheduler that builds safe plans from these flags is
:mod:`scheduler`.

Distances are compared with a rounding slack (relative 1e-9 and 1e-12·c absolute), and
two segments only *cross* when every endpoint is clearly off the other's line (see
:mod:`geometry`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from agent.core.formation.paths.close_pairs import close_segment_pairs, path_segments
from agent.core.formation.paths.geometry import point_seg_dist, seg_seg_dist
from agent.core.formation.waves.release import arc_offsets, segment_releases

#: Absolute rounding slack of a required distance, in clearances.
ABS_SLACK = 1e-12


@dataclass(frozen=True)
class Violation:
    """One pair that breaks the rule in a wave (see :func:`check_safety`)."""

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
    #: release points (:mod:`release`): a before b, b may start once a has walked past
    #: arc length ``rel_ab`` of its path (``rel_ba``: b before a, on b's path)
    rel_ab: np.ndarray
    rel_ba: np.ndarray


def _flags_from_pairs(
    starts: np.ndarray,
    targets: np.ndarray,
    seg_a: np.ndarray,
    seg_b: np.ndarray,
    owner: np.ndarray,
    s: np.ndarray,
    t: np.ndarray,
    clearance: float,
    d_st: np.ndarray | None = None,
) -> PairFlags:
    """Per robot pair flags from its segment pairs (s, t), owner[s] < owner[t] (``d_st``:
    their distances, if known)."""
    n = starts.shape[0]
    if s.size == 0:
        z = np.zeros(0, dtype=np.int64)
        zf = np.zeros(0)
        zb = np.zeros(0, dtype=bool)
        return PairFlags(z, z, zb, zb, zb, zf, zf, zf, zf, zf, zf)
    i, k = owner[s], owner[t]
    d_ss = seg_seg_dist(seg_a[s], seg_b[s], seg_a[t], seg_b[t]) if d_st is None else d_st
    # start k to segment s, target i to t, start i to t, target k to s: one array
    seg = np.concatenate((s, t, t, s))
    d_pt = point_seg_dist(
        np.concatenate((starts[k], targets[i], starts[i], targets[k])), seg_a[seg], seg_b[seg]
    )
    pk = i * n + k
    order = np.argsort(pk, kind="stable")
    pk = pk[order]
    first = np.flatnonzero(np.r_[True, pk[1:] != pk[:-1]])
    a = pk[first] // n
    b = pk[first] % n
    # per robot pair: the least of each distance over its segment pairs
    low = np.minimum.reduceat(
        np.concatenate((d_ss[None], d_pt.reshape(4, -1)))[:, order], first, axis=1
    )
    d_path = low[0]
    d_ab = np.minimum(low[1], low[2])
    d_ba = np.minimum(low[3], low[4])
    d_start = np.hypot(*(starts[a] - starts[b]).T)
    d_target = np.hypot(*(targets[a] - targets[b]).T)
    # release points against the clearance without the rounding slack (see release)
    room = np.minimum(clearance, np.minimum(d_start, d_target))
    pair_of = np.repeat(np.arange(first.size), np.diff(np.r_[first, pk.size]))
    arc0 = arc_offsets(owner, seg_a, seg_b)
    arc_i, arc_k = segment_releases(seg_a, seg_b, arc0, s[order], t[order], room[pair_of])
    total = np.zeros(n)
    np.maximum.at(total, owner, arc0 + np.hypot(*(seg_b - seg_a).T))
    # a release point is > 0 for every close pair (release); rounding aside: if not,
    # the old rule (wait until the robot holds its slot: its whole length)
    rel_ab = np.maximum.reduceat(arc_i, first)
    rel_ba = np.maximum.reduceat(arc_k, first)
    rel_ab = np.where(rel_ab > 0, np.minimum(rel_ab, total[a]), total[a])
    rel_ba = np.where(rel_ba > 0, np.minimum(rel_ba, total[b]), total[b])
    # rounding slack: relative 1e-9, and 1e-12·c absolute (starts 1e-300 m apart are one)
    req = (
        np.minimum(clearance, np.minimum(d_start, d_target)) * (1.0 - 1e-9) - ABS_SLACK * clearance
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
        rel_ab=rel_ab,
        rel_ba=rel_ba,
    )


def _ends(paths: Sequence[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    arrs = [np.asarray(p, dtype=np.float64).reshape(-1, 2) for p in paths]
    return np.array([p[0] for p in arrs]), np.array([p[-1] for p in arrs])


def pair_flags(paths: Sequence[np.ndarray], clearance: float) -> PairFlags:
    """Flags of every robot pair whose paths come within ``clearance`` (sorted by (a, b);
    pairs farther apart can share a wave and go in either order)."""
    starts, targets = _ends(paths)
    seg_a, seg_b, owner = path_segments(paths)
    s, t, d = close_segment_pairs(seg_a, seg_b, owner, clearance)
    return _flags_from_pairs(starts, targets, seg_a, seg_b, owner, s, t, clearance, d)


def update_flags(
    flags: PairFlags,
    paths: Sequence[np.ndarray],
    changed: Sequence[int],
    clearance: float,
    ends: tuple[np.ndarray, np.ndarray] | None = None,
    segments: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
) -> PairFlags:
    """:func:`pair_flags` after the paths of ``changed`` robots changed (same result).
    ``ends``: the (starts, targets) of the paths, ``segments``: their
    :func:`close_pairs.path_segments`, if known."""
    n = len(paths)
    starts, targets = _ends(paths) if ends is None else ends
    seg_a, seg_b, owner = path_segments(paths) if segments is None else segments
    moved = np.zeros(n, dtype=bool)
    moved[np.asarray(changed, dtype=np.int64)] = True
    s, t, d = close_segment_pairs(seg_a, seg_b, owner, clearance, query=moved[owner])
    new = _flags_from_pairs(starts, targets, seg_a, seg_b, owner, s, t, clearance, d)
    keep = ~(moved[flags.a] | moved[flags.b])
    parts = [(getattr(flags, f)[keep], getattr(new, f)) for f in PairFlags.__dataclass_fields__]
    merged = {
        f: np.concatenate(p) for f, p in zip(PairFlags.__dataclass_fields__, parts, strict=True)
    }
    order = np.argsort(merged["a"] * n + merged["b"], kind="stable")
    return PairFlags(**{f: v[order] for f, v in merged.items()})


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
