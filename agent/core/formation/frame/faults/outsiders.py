"""NAOs the fleet holds no record of: where the others' loose sightings agree
(docs/design.md §9; the papers assume every NAO in sight is a member, NAO paper 4.1.2).

A room may hold NAOs that run no agent: switched off, fallen, another team's. Each
member that sees one has a sighting that pairs with no member and lands on no fitted
robot. Counted as a *lost stray* (step 2 of :mod:`fault_test`), it is held against the
robot that saw it, as a ghost detection would be; a bystander seen by the whole fleet
then fails the fleet's global test, or names whichever member saw it most.

The model separates the two by what a ghost cannot do: agree with another robot's
sighting. A *loose* sighting (no measurement of the fit uses it, and it lands on no
fitted robot nor on a place already known, within the sighting gate of step 1) is either
a ghost, which each sighting is independently with the measured rate ``p_stray(d)`` and
which lands anywhere, or a sighting of a NAO without a record. Two ghosts of different
owners landing within the gate of each other is an event of the product of both rates
times the gate's share of the room (here 0.56 % each, a halved gate ~0.1 m across at
1.5 m in a room of ~25 m²: ~10⁻⁷ per pair of sightings), so a place
where loose sightings of at least :data:`WITNESSES` different owners agree (each within
the gate halved for the two noisy sightings, as :func:`fault_test.seen_by_others`) is
taken as a NAO standing there: an *outsider*. Its sightings are not lost strays; a
sighting seen by one owner alone keeps counting as one.

Found greedily (:func:`agreeing_sets`): the largest set of loose sightings, one per
owner, that agree with one of them, tie: the set around the first sighting in (owner,
record) order; then every loose sighting that lands on its place is explained, and the
next set is sought among the rest. The outsider stands at the mean of its set.
Deterministic: robots in ascending id, sightings in record order.

A NAO without a record is told from a member the fit put in the wrong place by what
each leaves behind. A member fitted away from where it stands (its own sightings all
shifted, the fit moving it to match them) leaves the others' sightings of it loose and
agreeing where it truly stands, exactly as a bystander does; but then no other robot's
sighting lands where the fit puts it. So each member that no other robot's sighting
lands on (:func:`unseen`: a record whose NAO nobody sees) cancels the outsider nearest
to it (members in ascending id; tie: the one found first): one NAO too few where the fit
puts a robot and one too many nearby are one misplaced robot, and its sightings stay
lost strays, for the fault test to judge. Without this, a robot whose sightings read
0.5 m shifted passed in three fleets of the corpus, its true place taken for a bystander.

A wrong frame leaves the same trace wholesale: a group of robots fitted turned or moved
as one leaves the others' sightings of them loose and agreeing where they truly stand,
and the members nobody sees are few (in five robots set down in two groups, the aligned
model, half of every robot's sightings landing, left four such places). Such a place is
where a member's own record fits: standing there, at its best heading, it lands more of
its sightings than where the fit puts it (:func:`member_fits_there`). A place a member
fits better than its own is that member, misplaced, and not a NAO without a record; its
sightings stay lost strays. A bystander's place is where no member's record fits.

A robot whose record the fleet sets aside is found the same way
(:func:`alone.unrecorded_place`: the first set, of any size).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from agent.core.formation.frame.poses import PoseFrame
from agent.core.formation.frame.records import NeighborRecord
from agent.core.perception.sighting_noise import SightingNoise

#: Owners whose loose sightings must agree for a NAO without a record to stand there.
WITNESSES = 2
#: Headings searched for a robot placed where its heading is free: every degree.
HEADING_GRID = np.radians(np.arange(0.0, 360.0, 1.0))


@dataclass(frozen=True)
class Loose:
    """A sighting no pair of the fit explains (module docstring)."""

    owner: int
    index: int  #: its place in the owner's record
    vector: np.ndarray  #: (2,) in the owner's fixed frame
    at: np.ndarray  #: (2,) where it lands, common frame
    psi: float  #: the owner's fitted start heading ψ


def turn(psi: float, points: np.ndarray) -> np.ndarray:
    """Points (k, 2) of a frame turned by ``psi`` written in it: R(−ψ)·p."""
    c, s = math.cos(psi), math.sin(psi)
    return np.stack([c * points[:, 0] + s * points[:, 1], -s * points[:, 0] + c * points[:, 1]], 1)


def _sightings(
    poses: PoseFrame, records: Sequence[NeighborRecord]
) -> tuple[list[tuple[int, int, int]], np.ndarray]:
    """Every sighting of ``records``' robots in ``poses``: (owner id, its row in
    ``poses``, its place in the record) in ascending owner id and record order, and
    their vectors (k, 2)."""
    by_id = {r.robot_id: r for r in records}
    rows: list[tuple[int, int, int]] = []
    vectors: list[np.ndarray] = []
    for k, rid in enumerate(poses.ids):
        rec = by_id.get(rid)
        if rec is None:
            continue
        own = np.asarray(rec.neighbours, dtype=np.float64).reshape(-1, 2)
        rows += [(rid, k, a) for a in range(len(own))]
        vectors.append(own)
    return rows, (np.vstack(vectors) if vectors else np.zeros((0, 2)))


def _landing(
    poses: PoseFrame,
    rows: list[tuple[int, int, int]],
    vectors: np.ndarray,
    targets: np.ndarray,
    noise: SightingNoise,
) -> np.ndarray:
    """(k, t): χ² of each sighting against each of ``targets`` (t, 2, common frame), in
    its owner's fixed frame."""
    k = np.array([row for _, row, _ in rows], dtype=np.intp)
    psi = poses.headings[k]
    c, s = np.cos(psi)[:, None], np.sin(psi)[:, None]
    rel = targets[None, :, :] - poses.positions[k][:, None, :]  # common frame
    own = np.stack([c * rel[..., 0] + s * rel[..., 1], -s * rel[..., 0] + c * rel[..., 1]], -1)
    err = (own - vectors[:, None, :]).reshape(-1, 2)
    x2 = noise.chi2(np.repeat(vectors, len(targets), axis=0), err)
    return np.asarray(x2.reshape(len(rows), len(targets)))


def loose_sightings(
    poses: PoseFrame,
    records: Sequence[NeighborRecord],
    noise: SightingNoise,
    gate: float,
    places: np.ndarray | None = None,
) -> list[Loose]:
    """Every sighting of ``records``' robots in ``poses`` that no measurement uses and that
    lands on no other robot of ``poses`` nor on ``places`` ((k, 2), common frame) within
    the χ² ``gate``; robots in ascending id, sightings in record order."""
    rows, vectors = _sightings(poses, records)
    if not rows:
        return []
    used = {(m.owner, float(m.vector[0]), float(m.vector[1])) for m in poses.measurements}
    extra = np.zeros((0, 2)) if places is None else np.asarray(places, np.float64).reshape(-1, 2)
    x2 = _landing(poses, rows, vectors, np.vstack([poses.positions, extra]), noise)
    x2[np.arange(len(rows)), [row for _, row, _ in rows]] = np.inf  # not on its owner
    lands = x2.min(axis=1) <= gate
    out: list[Loose] = []
    for (rid, k, a), v, hit in zip(rows, vectors, lands.tolist(), strict=True):
        if hit or (rid, float(v[0]), float(v[1])) in used:
            continue
        psi = float(poses.headings[k])
        at = poses.positions[k] + turn(-psi, v[None])[0]
        out.append(Loose(rid, a, v, at, psi))
    return out


def agreement(found: Sequence[Loose], noise: SightingNoise, gate: float) -> np.ndarray:
    """(n, n): sighting j lands on sighting i's place within the halved gate."""
    rot = np.array([[math.cos(f.psi), math.sin(f.psi)] for f in found])
    at = np.array([f.at for f in found])
    vec = np.array([f.vector for f in found])
    gap = at[:, None, :] - at[None, :, :]  # centre i minus place j, turned into j's frame
    err = np.stack([rot[None, :, 0] * gap[..., 0] + rot[None, :, 1] * gap[..., 1],
                    -rot[None, :, 1] * gap[..., 0] + rot[None, :, 0] * gap[..., 1]], -1)  # fmt: skip
    n = len(found)
    x2 = noise.chi2(np.tile(vec, (n, 1)), err.reshape(-1, 2)).reshape(n, n)
    return np.asarray(0.5 * x2 <= gate)


def largest_set(agree: np.ndarray, found: Sequence[Loose]) -> list[int]:
    """The largest set of ``found`` (indices), one per owner, that agree with one of them
    (``agree[i, j]``: j agrees with centre i); tie: the first centre; within a centre,
    each owner's first sighting. Empty for no sightings."""
    best: list[int] = []
    for i in range(len(found)):
        chosen: list[int] = []
        owners: set[int] = set()
        for j in np.flatnonzero(agree[i]).tolist():
            if found[j].owner not in owners:
                chosen.append(j)
                owners.add(found[j].owner)
        if len(chosen) > len(best):
            best = chosen
    return best


def agreeing_sets(
    found: Sequence[Loose], noise: SightingNoise, gate: float, witnesses: int = WITNESSES
) -> list[list[int]]:
    """The sets of the module docstring, greedily (indices into ``found``): each the
    largest of at least ``witnesses`` owners among the sightings no set before it
    explains (lands on its mean place, within ``gate``)."""
    if not found:
        return []
    agree = agreement(found, noise, gate)
    left = np.ones(len(found), dtype=bool)
    sets: list[list[int]] = []
    while left.any():
        sub: list[int] = np.flatnonzero(left).tolist()
        best = [sub[j] for j in largest_set(agree[np.ix_(sub, sub)], [found[k] for k in sub])]
        if len(best) < witnesses:
            break
        sets.append(best)
        place = np.mean(np.array([found[j].at for j in best]), axis=0)
        for j in sub:
            f = found[j]
            err = turn(f.psi, (place - f.at)[None])
            if j in best or float(noise.chi2(f.vector[None], err)[0]) <= gate:
                left[j] = False
    return sets


def unseen(
    poses: PoseFrame, records: Sequence[NeighborRecord], noise: SightingNoise, gate: float
) -> list[int]:
    """The robots of ``poses`` (ascending) on whose fitted place no sighting of another
    robot of ``records`` lands within the χ² ``gate``."""
    rows, vectors = _sightings(poses, records)
    if not rows:
        return list(poses.ids)
    x2 = _landing(poses, rows, vectors, poses.positions, noise)
    x2[np.arange(len(rows)), [row for _, row, _ in rows]] = np.inf  # not by itself
    seen = (x2 <= gate).any(axis=0)
    return [rid for rid, hit in zip(poses.ids, np.asarray(seen).tolist(), strict=True) if not hit]


def best_heading(
    rel: np.ndarray,
    own: np.ndarray,
    noise: SightingNoise,
    q: float,
    pairs: np.ndarray | None = None,
) -> tuple[float, int]:
    """(ψ, how many of ``own`` land) for a robot standing at a place, its heading free:
    ``rel`` (n, 2) the robots and places it may see, from the place, common frame; ``own``
    (k, 2) its sightings, in its fixed frame. A sighting lands within the halved gate
    ``q`` (the place carries the others' errors); the heading on :data:`HEADING_GRID` under
    which most land, tie: the smaller sum of their χ² (each capped at the gate), then the
    smaller angle. ``pairs`` (n, k), optional: the robots each sighting can land on at
    some heading (a sighting's χ² on any other is beyond the gate, so capped: the same
    answer, computed on fewer pairs)."""
    if not len(own) or not len(rel):
        return 0.0, 0
    c, s = np.cos(HEADING_GRID), np.sin(HEADING_GRID)
    # every robot as seen from the place at every heading: (h, n, 2)
    seen = np.stack([c[:, None] * rel[None, :, 0] + s[:, None] * rel[None, :, 1],
                     -s[:, None] * rel[None, :, 0] + c[:, None] * rel[None, :, 1]], axis=2)  # fmt: skip
    h, n, k = len(HEADING_GRID), len(rel), len(own)
    if pairs is None:
        t, j = np.divmod(np.arange(n * k), k)
    else:  # only the (robot, sighting) pairs that can land: the others are capped anyway
        t, j = np.nonzero(np.asarray(pairs, dtype=bool).reshape(n, k))
    err = seen[:, t, :] - own[None, j, :]  # (h, m, 2)
    vec = np.broadcast_to(own[None, j, :], err.shape).reshape(-1, 2)
    x2 = 0.5 * noise.chi2(vec, err.reshape(-1, 2)).reshape(h, len(t))
    best = np.full((h, k), np.inf)  # (h, k): each sighting's nearest robot at each heading
    for col in range(k):
        hit = j == col
        if hit.any():
            best[:, col] = x2[:, hit].min(axis=1)
    lands = (best <= q).sum(axis=1)
    cost = np.minimum(best, q).sum(axis=1)
    order = np.lexsort((np.arange(len(HEADING_GRID)), cost, -lands))
    h = int(order[0])
    psi = float(HEADING_GRID[h])
    return math.atan2(math.sin(psi), math.cos(psi)), int(lands[h])


def member_fits_there(
    poses: PoseFrame,
    records: Sequence[NeighborRecord],
    noise: SightingNoise,
    gate: float,
    places: np.ndarray,
    elsewhere: np.ndarray,
) -> list[int | None]:
    """For each of ``places`` (m, 2), common frame: the first robot of ``poses`` (ascending
    id) whose own record, standing there at its best heading, lands more of its
    sightings than where the fit puts it, or None. Both counts within the halved gate, on
    the fitted robots and ``elsewhere`` (the places known). Such a robot is held in the
    wrong place by the fit, and the place is where it stands. Only a robot some of whose
    sightings land nowhere where the fit puts it can gain."""
    at = np.asarray(places, dtype=np.float64).reshape(-1, 2)
    rows, vectors = _sightings(poses, records)
    if not rows:
        return [None] * len(at)
    targets = np.vstack([poses.positions, np.asarray(elsewhere, dtype=np.float64).reshape(-1, 2)])
    x2 = _landing(poses, rows, vectors, targets, noise)
    x2[np.arange(len(rows)), [row for _, row, _ in rows]] = np.inf  # not on its owner
    lands = (0.5 * x2).min(axis=1) <= gate
    owners = np.array([rid for rid, _, _ in rows])
    dist = np.hypot(*vectors.T)
    # whatever the heading, a sighting lands only on a robot whose distance from the
    # place differs from the sighting's by at most its misfit, which the halved gate
    # bounds by √(2q)·max(σ_r, σ_t): a bound without the heading search
    slack = math.sqrt(2.0 * gate) * np.maximum(
        noise.sigma_radial(dist), noise.sigma_tangential(dist)
    )
    out: list[int | None] = []
    for place in at:
        radius = np.hypot(*(targets - place).T)
        near = np.abs(radius[None, :] - dist[:, None]) <= slack[:, None]  # (k, targets)
        out.append(None)
        for k, rid in enumerate(poses.ids):
            mine = owners == rid
            here = int(lands[mine].sum())
            reach = near[mine]
            reach[:, k] = False  # not on itself
            if here == int(mine.sum()) or int(reach.any(axis=1).sum()) <= here:
                continue  # it cannot land more there, whatever its heading
            # only the robots some sighting of it can reach: the others land nowhere anyway
            cols = reach.any(axis=0)
            rel = targets[cols] - place
            if best_heading(rel, vectors[mine], noise, gate, reach[:, cols].T)[1] > here:
                out[-1] = rid
                break
    return out


def outsider_places(
    poses: PoseFrame,
    records: Sequence[NeighborRecord],
    noise: SightingNoise,
    gate: float,
    places: np.ndarray | None = None,
) -> np.ndarray:
    """(k, 2), common frame: where NAOs without a record stand in ``poses`` beyond
    ``places`` (module docstring: each member nobody sees cancels the nearest, and a place
    some member's record fits better than its own is that member), in the order found;
    (0, 2) for none."""
    found = loose_sightings(poses, records, noise, gate, places)
    sets = agreeing_sets(found, noise, gate)
    if not sets:
        return np.zeros((0, 2))
    at = [np.mean(np.array([found[j].at for j in s]), axis=0) for s in sets]
    for rid in unseen(poses, records, noise, gate):
        if not at:
            break
        p = poses.positions[poses.ids.index(rid)]
        at.pop(int(np.argmin([float(np.hypot(*(a - p))) for a in at])))
    known = np.zeros((0, 2)) if places is None else np.asarray(places, np.float64).reshape(-1, 2)
    # a place where a member's own record fits better than where the fit puts it is that
    # member, misplaced (a wrong frame), not a NAO without a record; both on the fitted
    # robots and the places known, never on the places in question (a wrong frame's
    # places are where its members' loose sightings land)
    fits = member_fits_there(poses, records, noise, gate, np.array(at).reshape(-1, 2), known)
    kept = [p for p, rid in zip(at, fits, strict=True) if rid is None]
    return np.array(kept) if kept else np.zeros((0, 2))
