"""Neighbour pairing without the papers' alignment (docs/design.md §9; generalises NAO paper
4.1.2, Algorithm 2, eq. 9).

Eq. 9 pairs robot i's sighting ``v_ij`` with robot j's sighting ``v_ji`` by requiring
``v_ij ≈ -v_ji``, which holds only when every fixed frame is parallel (4.1.1). Here the
fixed frames may differ by any rotation ψ_j − ψ_i, so a pair is recognised by what does
not depend on it:

* **distance agreement**: ``| |v_ij| − |v_ji| | ≤ ε + ρ·max(|v_ij|, |v_ji|)``
  (``ε`` the eq. 9 tolerance, ``ρ`` = :data:`PAIR_REL_TOL` for errors that grow with
  distance, and for a robot whose distances are wrong, so that the consistency check of
  :mod:`fault_test` still sees it);
* **relative heading** of a candidate, from the two bearings (:func:`relative_heading`):
  ``ψ_j − ψ_i = β_ij − β_ji + π``;
* **mask orientation** (3.1.2): the matched mask's relative orientation θ (the observed
  NAO's body heading minus the line of sight from the observer to it, as the M-base is
  rendered) gives ψ_j − ψ_i ≡ β_ij + θ_ij − π/2 modulo π (:func:`mask_relative_heading`;
  modulo π because the observed robot may be at θ = 0 or θ = 180° of its search, 5.2.2
  (iii)); its disagreement with the bearing estimate ranks candidates;
* **loop consistency** (the *support*, as :mod:`neighbour_check`'s but rotated): if the
  candidate is right, every other sighting ``v_ic`` of i, moved into j's frame as
  ``R(−Δ)(v_ic − v_ij)``, is one of j's sightings (within ε/2 + 0.08·|v_ic − v_ij|)
  when j sees c too: each such triangle i–j–c that closes counts one, from both sides
  (:mod:`pair_support`, for every candidate at once).

Candidates are taken globally greedy (as :func:`neighbour_check.identify_neighbours`) in
two passes. The first takes the supported candidates (support ≥ 1); the second the
unsupported ones, but only where one of the two robots has no pair after the first pass
(two robots alone, a robot whose own sightings are off): a leftover one-way sighting of
a well-connected robot is not paired on distance alone. Within a pass the order is:
more support first, then lower cost (normalised distance disagreement plus
normalised mask disagreement), then smaller |ψ_j − ψ_i| (so a configuration that is
truly ambiguous without headings, such as three robots on a line, resolves towards the
aligned start), then lower owner (record order, ascending id), then lower detection
index in the canonical record. A candidate is accepted when neither of its detections
is used and the two robots are not already a pair. With parallel frames this gives the
pairs of Algorithm 2 on the neighbour-check test cases.

The masks' other reading sits here too: :func:`mask_offset`, the offset most of a robot's
mask misfits agree on (how :mod:`poses` finds a robot turned as a whole).
"""

from __future__ import annotations

import math
from collections.abc import Iterator, Sequence

import numpy as np

from agent.core.formation.frame.neighbour_check import (
    DEFAULT_EPSILON,
    NeighbourGraph,
    NeighbourPair,
)
from agent.core.formation.frame.pair_support import support_one_side
from agent.core.formation.frame.records import NeighborRecord, canonical_records

#: ρ: distance disagreement allowed per metre of distance (on top of ε). Two sightings
#: with the paper's ±5 % distance error disagree by at most 10 %; a D-base off by 40 %
#: still pairs (and is then named by the consistency check).
PAIR_REL_TOL = 0.3
#: Loop-consistency tolerance per metre of lever arm (on top of ε/2): 3° bearing errors
#: on both sides turn the moved sighting by a few degrees. Tight on purpose: with a looser
#: one, chance matches support wrong pairs in dense fleets.
SUPPORT_REL_TOL = 0.08
#: Mask disagreement (rad) that costs as much as a distance disagreement of ε + ρ·d.
MASK_SCALE = math.radians(30.0)
#: Mask misfits within this of an offset agree with it (:func:`mask_offset`).
TURN_WINDOW = math.radians(30.0)
#: Most sighting pairs considered at once when the candidates are built.
BLOCK_ELEMENTS = 1 << 20

TWO_PI = 2.0 * math.pi


def wrap_angle(a: np.ndarray | float) -> np.ndarray:
    """Angle(s) wrapped to (−π, π]."""
    return np.pi - np.mod(np.pi - np.asarray(a, dtype=np.float64), TWO_PI)


def wrap_half(a: np.ndarray | float) -> np.ndarray:
    """Angle(s) wrapped to (−π/2, π/2]: the difference of two headings known modulo π."""
    return np.pi / 2 - np.mod(np.pi / 2 - np.asarray(a, dtype=np.float64), np.pi)


def relative_heading(v_ij: np.ndarray, v_ji: np.ndarray) -> float:
    """ψ_j − ψ_i from a mutual pair (docs/design.md §9), wrapped to (−π, π].

    Parameters
    ----------
    v_ij : (2,) array
        Robot j as robot i sees it, in i's fixed frame (bearing β_ij).
    v_ji : (2,) array
        Robot i as robot j sees it, in j's fixed frame (bearing β_ji).

    Returns
    -------
    float
        ``β_ij − β_ji + π``: a world direction α of the line of sight i→j reads
        β_ij = α − ψ_i in i's frame, and j sees i the other way, β_ji = α + π − ψ_j.

    Raises
    ------
    ValueError
        When a vector is not (2,) and finite, is zero, or the two distances disagree by
        more than ε + ρ·d (:data:`PAIR_REL_TOL`, ε = ``DEFAULT_EPSILON``).
    """
    a = _vector("v_ij", v_ij)
    b = _vector("v_ji", v_ji)
    da, db = math.hypot(*a), math.hypot(*b)
    if abs(da - db) > DEFAULT_EPSILON + PAIR_REL_TOL * max(da, db):
        raise ValueError(f"the two distances disagree: |v_ij| = {da:.3f} m, |v_ji| = {db:.3f} m")
    beta_ij = math.atan2(a[1], a[0])
    beta_ji = math.atan2(b[1], b[0])
    return float(wrap_angle(beta_ij - beta_ji + math.pi))


def mask_relative_heading(v_ij: np.ndarray, theta_ij: float) -> float:
    """ψ_j − ψ_i modulo π from one sighting's mask orientation, in (−π/2, π/2].

    Parameters
    ----------
    v_ij : (2,) array
        Robot j as robot i sees it, in i's fixed frame (bearing β_ij); one-way is enough.
    theta_ij : float
        The matched mask's relative orientation (M-base convention, 3.1.2): j's body
        heading minus the line of sight i→j. Every robot faces π/2 in its own fixed frame
        at the start (and π/2 + π after the search's half turn), hence
        ``ψ_j − ψ_i ≡ β_ij + θ_ij − π/2 (mod π)``.

    Raises
    ------
    ValueError
        When ``v_ij`` is not a finite non-zero (2,) vector or ``theta_ij`` is not finite.
    """
    a = _vector("v_ij", v_ij)
    if not math.isfinite(theta_ij):
        raise ValueError(f"mask orientation must be finite, got {theta_ij!r}")
    return float(wrap_half(math.atan2(a[1], a[0]) + theta_ij - math.pi / 2))


def _vector(name: str, v: np.ndarray) -> np.ndarray:
    arr = np.asarray(v, dtype=np.float64)
    if arr.shape != (2,) or not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} must be a finite (2,) vector, got {v!r}")
    if not np.any(arr):
        raise ValueError(f"{name} is zero: a sighting has a bearing only at a distance > 0")
    return arr


def _flatten(
    recs: tuple[NeighborRecord, ...],
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """owner (record index), detection index, vectors, orientations (nan: none), weights."""
    owner: list[int] = []
    index: list[int] = []
    vecs: list[np.ndarray] = []
    ori: list[float] = []
    w: list[float] = []
    for ri, r in enumerate(recs):
        for a in range(r.count):
            owner.append(ri)
            index.append(a)
            vecs.append(r.neighbours[a])
            ori.append(math.nan if r.orientations is None else float(r.orientations[a]))
            w.append(1.0 if r.confidences is None else float(r.confidences[a]))
    return (
        np.asarray(owner, dtype=np.int64),
        np.asarray(index, dtype=np.int64),
        np.asarray(vecs, dtype=np.float64).reshape(-1, 2),
        np.asarray(ori, dtype=np.float64),
        np.asarray(w, dtype=np.float64),
    )


def identify_pairs(
    records: Sequence[NeighborRecord],
    epsilon: float = DEFAULT_EPSILON,
) -> NeighbourGraph:
    """Mutual neighbour pairs of a record set whose fixed frames are not parallel.

    Parameters
    ----------
    records : sequence of NeighborRecord
        One record per robot, in any order (made canonical first).
    epsilon : float
        ε of eq. 9 (m): the absolute part of the distance-agreement and loop tolerances.

    Returns
    -------
    NeighbourGraph
        As :func:`neighbour_check.identify_neighbours` returns it; ``eps_d`` of a pair is
        its distance disagreement ``| |v_ij| − |v_ji| |`` (m).

    Raises
    ------
    ValueError
        For a bad ε, no records, or duplicate robot ids.
    """
    if not (isinstance(epsilon, int | float) and math.isfinite(epsilon) and epsilon > 0):
        raise ValueError(f"epsilon must be a finite number > 0, got {epsilon!r}")
    recs = canonical_records(records)
    if not recs:
        raise ValueError("no records")
    ids = tuple(r.robot_id for r in recs)
    owner, index, vecs, ori, weights = _flatten(recs)
    pairs: list[NeighbourPair] = []
    if vecs.shape[0] >= 2:
        dist = np.hypot(vecs[:, 0], vecs[:, 1])
        bearing = np.arctan2(vecs[:, 1], vecs[:, 0])
        ra, rb, key_cost, key_turn, support = _scored_candidates(
            owner, vecs, ori, dist, bearing, epsilon
        )
        used: set[int] = set()
        linked: set[tuple[int, int]] = set()
        paired: set[int] = set()  # robots (record index) paired by supported candidates
        taken = _Taken(owner, ra, rb, len(recs))
        for t in taken.ordered(support, key_cost, key_turn):
            da, db = int(ra[t]), int(rb[t])
            oa, ob = int(owner[da]), int(owner[db])
            if da in used or db in used or (oa, ob) in linked:
                continue
            if support[t] == 0 and not paired:
                paired = {o for pair in linked for o in pair} | {-1}
            if support[t] == 0 and oa in paired and ob in paired:
                continue
            used.update((da, db))
            linked.add((oa, ob))
            taken.take(da, db, oa, ob)
            pairs.append(
                NeighbourPair(
                    i=ids[oa],
                    j=ids[ob],
                    a=int(index[da]),
                    b=int(index[db]),
                    v_ij=vecs[da].copy(),
                    v_ji=vecs[db].copy(),
                    eps_d=float(abs(dist[da] - dist[db])),
                    w_ij=float(weights[da]),
                    w_ji=float(weights[db]),
                )
            )
    pairs.sort(key=lambda p: (p.i, p.j))
    return NeighbourGraph(ids=ids, pairs=tuple(pairs), records=recs, epsilon=float(epsilon))


def _scored_candidates(
    owner: np.ndarray,
    vecs: np.ndarray,
    ori: np.ndarray,
    dist: np.ndarray,
    bearing: np.ndarray,
    epsilon: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Every candidate (sighting ``ra`` of a robot, ``rb`` of a later one) that passes the
    distance agreement, with its sort keys: cost, |ψ_j − ψ_i| and support.

    Built in blocks of at most :data:`BLOCK_ELEMENTS` sighting pairs (at 100
    NAOs the 2 409 sightings give 2.9 M ordered pairs and 1.87 M candidates; built at
    once, ~470 MB an agent, and 100 agents on one host were stopped by the OOM killer).
    Every key is elementwise per candidate, so the blocks change no value; what is kept
    is 28 bytes a candidate."""
    n = vecs.shape[0]
    step = max(1, BLOCK_ELEMENTS // n)
    parts: list[tuple[np.ndarray, ...]] = []
    for lo in range(0, n, step):
        ra, rb = np.nonzero(owner[lo : lo + step, None] < owner[None, :])
        ra = ra + lo
        dmax = np.maximum(dist[ra], dist[rb])
        derr = np.abs(dist[ra] - dist[rb])
        tol = epsilon + PAIR_REL_TOL * dmax
        ok = (derr <= tol) & (dist[ra] > 0) & (dist[rb] > 0)
        ra, rb, derr, tol = ra[ok], rb[ok], derr[ok], tol[ok]
        turn = wrap_angle(bearing[ra] - bearing[rb] + np.pi)  # ψ_j − ψ_i of each candidate
        # rounded so that float noise does not decide between exact ties (|Δ| does)
        cost = np.round(derr / tol + _mask_cost(turn, bearing, ori, ra, rb) / MASK_SCALE, 9)
        support = support_one_side(
            ra, rb, turn, owner, vecs, epsilon, SUPPORT_REL_TOL
        ) + support_one_side(rb, ra, -turn, owner, vecs, epsilon, SUPPORT_REL_TOL)
        parts.append(
            (ra.astype(np.int32), rb.astype(np.int32), cost, np.abs(turn), support.astype(np.int32))
        )
    ra_all, rb_all, cost_all, turn_all, sup_all = (
        np.concatenate(c) for c in zip(*parts, strict=True)
    )
    return ra_all, rb_all, cost_all, turn_all, sup_all


class _Taken:
    """The sightings used and robot pairs linked so far, as arrays: :meth:`open` passes
    over the candidates that an earlier acceptance already rules out, a slice at a time
    (the greedy loop checks the rest one at a time, so it accepts the same candidates; most
    of ~10⁵ candidates fall here, in one array operation rather than one Python step)."""

    def __init__(self, owner: np.ndarray, ra: np.ndarray, rb: np.ndarray, robots: int) -> None:
        self.owner, self.ra, self.rb = owner, ra, rb
        self.used = np.zeros(owner.size, dtype=bool)
        self.linked = np.zeros((robots, robots), dtype=bool)

    def take(self, da: int, db: int, oa: int, ob: int) -> None:
        """Sightings ``da``, ``db`` of robots ``oa``, ``ob`` are paired."""
        self.used[da] = self.used[db] = True
        self.linked[oa, ob] = True

    def ordered(self, support: np.ndarray, cost: np.ndarray, turn: np.ndarray) -> Iterator[int]:
        """The candidates in the greedy order (more support, lower cost, smaller |turn|,
        lower ``ra``, lower ``rb``), as :meth:`open` passes them. The candidates come
        sorted by (``ra``, ``rb``) (:func:`_scored_candidates`), so a stable sort on the
        other keys breaks the last ties alike; each level of support is sorted only when
        it is reached, without the candidates an earlier acceptance already rules out
        (most of them, in a dense fleet)."""
        by_support = np.argsort(-support.astype(np.int64), kind="stable")
        cuts = np.flatnonzero(np.diff(support[by_support])) + 1
        for level in np.split(by_support, cuts):
            level = level[self._free(level)]
            yield from self.open(level[np.lexsort((turn[level], cost[level]))])

    def _free(self, t: np.ndarray) -> np.ndarray:
        """Whether each candidate of ``t`` has both sightings unused and its robots unlinked."""
        a, b = self.ra[t], self.rb[t]
        free: np.ndarray = ~(
            self.used[a] | self.used[b] | self.linked[self.owner[a], self.owner[b]]
        )
        return free

    def open(self, order: np.ndarray, size: int = 1 << 12) -> Iterator[int]:
        """The candidates of ``order`` as Python ints, but those whose sightings are used
        or whose robots are linked when their slice is reached."""
        for lo in range(0, order.size, size):
            t = order[lo : lo + size]
            yield from t[self._free(t)].tolist()


def _mask_cost(
    turn: np.ndarray, bearing: np.ndarray, ori: np.ndarray, ra: np.ndarray, rb: np.ndarray
) -> np.ndarray:
    """Mean |disagreement| (rad, modulo π) of the candidates' mask orientations (0: none)."""
    # side a: ψ_j − ψ_i ≡ β_a + θ_a − π/2; side b: ψ_i − ψ_j ≡ β_b + θ_b − π/2 (mod π)
    ea = np.abs(wrap_half(turn - (bearing[ra] + ori[ra] - np.pi / 2)))
    eb = np.abs(wrap_half(-turn - (bearing[rb] + ori[rb] - np.pi / 2)))
    both = np.stack([ea, eb])
    have = np.isfinite(both)
    n = have.sum(axis=0)
    total = np.where(have, both, 0.0).sum(axis=0)
    return np.where(n > 0, total / np.maximum(n, 1), 0.0)


def mask_offset(deltas: Sequence[float]) -> tuple[float, int]:
    """The offset (rad, modulo π) most of a robot's mask misfits agree on, and how many.

    ``deltas`` are the signed misfits δ = ψ_t − ψ_o − (β + θ − π/2), wrapped to
    (−π/2, π/2], of the others' mask sightings of one robot t. Each δ is taken as the
    centre; the one with the most misfits within :data:`TURN_WINDOW` wins (ties: the
    smaller sum of squared distances, then the smaller |centre|, then input order); the
    offset is the circular mean, modulo π, of the misfits that agree with it.
    """
    d = np.asarray(deltas, dtype=np.float64)
    if d.size == 0:
        return 0.0, 0
    diff = wrap_half(d[None, :] - d[:, None])
    near = np.abs(diff) <= TURN_WINDOW
    count = near.sum(axis=1)
    spread = np.round(np.where(near, diff**2, 0.0).sum(axis=1), 12)
    best = int(np.lexsort((np.abs(d), spread, -count))[0])
    agree = d[near[best]]
    mean = 0.5 * math.atan2(float(np.sin(2 * agree).sum()), float(np.cos(2 * agree).sum()))
    return float(wrap_half(mean)), int(count[best])
