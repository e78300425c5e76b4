"""Consistency check of the common frame: name the robot whose sightings do not fit
(docs/design.md §9, "per-pair residuals name a robot whose sightings do not fit").

A robot with a broken compass (its sightings rotated), a wrong D-base (its distances
scaled) or a lying insider (its sightings shifted) disagrees with what the others saw of
it. Rotating all of one robot's sightings is absorbed by its unknown ψ; only the others'
mask orientations (modulo π) reveal it, so that fault is found only when the records
carry orientations.

Rule (deterministic, on the poses of :func:`poses.build_poses`):

1. the fleet is *consistent* when every pair's position misfit is within
   :data:`poses.POS_TOL` + :data:`poses.POS_TOL_REL`·d and no robot is turned (the others'
   masks agree that its ψ is off, :func:`poses.turned_robots`): nobody is named;
2. otherwise: misfit pairs that are *isolated* (neither robot has another) are wrong
   pairings (:func:`drop_wrong_pairings`): dropped, and if the refit is consistent nobody
   is named. Otherwise exactly one turned robot whose leaving makes the rest consistent
   is named. Otherwise each robot r (ascending id) that may explain the misfit
   (:func:`may_explain`: turned or an end of a misfit pair, and every misfit pair it is
   not part of isolated) is left out in turn: its sightings and the others' sightings of
   it are dropped and the rest is fitted again (same pairing); r is a *candidate* when
   the rest is connected (at least two robots) and consistent; only when no robot is,
   when the rest is consistent once its own isolated misfit pairs are dropped
   (:func:`consistent_rest`);
3. exactly one candidate: it is named. Several (typically the faulty robot and the
   partner of its worst pair): with the robust z-score ``(s_r − median(s)) /
   (1.4826·MAD(s))`` of the robot scores s (MAD floored at :data:`MAD_FLOOR`), the
   candidate is named that both has the highest score (tie: lowest id) and, left out,
   leaves the lowest worst pair score (tie: lowest id), when its z ≥ :data:`Z_AGREE`;
   failing that, the only candidate with z ≥ :data:`Z_MIN`; otherwise nobody
   (ambiguous). No candidate: nobody (more than one robot would have to be left out).

4. the name is corroborated (:func:`check_frame`): the robot is turned, or at least
   :data:`MIN_BAD_PAIRS` of its pairs misfit in position, or the other end of its one
   misfit pair was tested and does not explain it; otherwise nobody is named.

The reason text says which of these happened, with the figures.
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from agent.core.formation.frame.neighbour_check import DEFAULT_EPSILON
from agent.core.formation.frame.pose_pairing import identify_pairs
from agent.core.formation.frame.poses import (
    POS_TOL,
    POS_TOL_REL,
    PoseFrame,
    fit_poses,
    poses_from_graph,
)
from agent.core.formation.frame.records import NeighborRecord

#: :func:`drop_wrong_pairings` over several rounds drops at most this share of the pairs
MAX_DROPPED_SHARE = 0.01
#: A robot is named on positions alone only when at least this many of its pairs misfit:
#: a single misfit pair (a neighbour half hidden, a wrong pairing) could be either end's
#: fault, unless the other end was tested and does not explain it.
MIN_BAD_PAIRS = 2
Z_MIN = 3.5  #: robust z-score a robot must reach to be named among several candidates
Z_AGREE = 1.0  #: z-score enough when both tie-breaks among candidates agree (rule 3)
MAD_FLOOR = 0.1  #: smallest MAD of robot scores (scores are in units of the tolerance)


@dataclass(frozen=True)
class PoseVerdict:
    """The named robot(s) (empty: none) and why, with the poses the check ran on."""

    named: tuple[int, ...]
    reason: str
    poses: PoseFrame


def robust_z(scores: np.ndarray) -> np.ndarray:
    """``(s − median) / (1.4826·max(MAD, MAD_FLOOR))`` of each robot score."""
    s = np.asarray(scores, dtype=np.float64)
    if s.size == 0:
        return s
    med = float(np.median(s))
    mad = max(float(np.median(np.abs(s - med))), MAD_FLOOR)
    return (s - med) / (1.4826 * mad)


def leave_out(poses: PoseFrame, robot: int) -> PoseFrame | None:
    """The fit without ``robot`` and every sighting of or by it; None when the rest is
    fewer than two robots or not connected by mutual pairs."""
    if robot not in poses.ids:
        raise ValueError(f"robot {robot} has no pose")
    rest = [i for i in poses.ids if i != robot]
    if len(rest) < 2:
        return None
    meas = [m for m in poses.measurements if robot not in (m.owner, m.target)]
    try:
        return fit_poses(rest, meas)
    except ValueError:
        return None


def check_poses(records: Sequence[NeighborRecord], epsilon: float = DEFAULT_EPSILON) -> PoseVerdict:
    """Pair, fit and check a record set (module docstring).

    Raises
    ------
    ValueError
        As :func:`poses.build_poses` (bad records or ε, a fleet not connected).
    """
    graph = identify_pairs(records, epsilon)
    return check_frame(poses_from_graph(graph, records))


def bad_pairs(poses: PoseFrame, robot: int) -> list[tuple[int, int]]:
    """Pairs of ``robot`` whose sightings misfit in position beyond the tolerance."""
    return [
        (q.i, q.j)
        for q in poses.pairs
        if robot in (q.i, q.j) and q.position > POS_TOL + POS_TOL_REL * q.distance
    ]


def check_frame(poses: PoseFrame) -> PoseVerdict:
    """The rule of the module docstring on fitted poses, then corroborated: a robot is
    named only when it is turned, or at least :data:`MIN_BAD_PAIRS` of its pairs misfit
    in position, or the other end of its one misfit pair was tested (left out, the rest
    still connected) and does not explain it."""
    first = _check_frame(poses)
    if not first.named:
        return first
    (r,) = first.named
    if len(poses.turned) == 1 and poses.turned[0] != r:
        return PoseVerdict(
            (), f"ambiguous: robot {poses.turned[0]} is turned, yet {first.reason}", poses
        )
    bad = bad_pairs(poses, r)
    if r in poses.turned or len(bad) >= MIN_BAD_PAIRS:
        return first
    others = [i if j == r else j for i, j in bad]
    if others and all(_tested_and_cleared(poses, s) for s in others):
        return first
    return PoseVerdict(
        (), f"nobody named, < {MIN_BAD_PAIRS} pairs misfit in position: {first.reason}", poses
    )


def _tested_and_cleared(poses: PoseFrame, robot: int) -> bool:
    """Left out, ``robot`` leaves a connected rest that is still inconsistent."""
    rest = leave_out(poses, robot)
    return rest is not None and not rest.consistent


def drop_wrong_pairings(poses: PoseFrame, rounds: int = 1) -> PoseVerdict | None:
    """The fit again without the misfit pairs, when each is *isolated* (neither of its
    robots has another misfit pair) and the rest is then connected and consistent; else
    None.

    An isolated misfit pair between robots whose other pairs all fit is a wrong pairing
    (two robots' sightings of different NAOs matched on distance: 10 NAOs within ±20° of
    north, a pair misfit by 3.06 m while every ψ was right to 1.3°), not a faulty robot:
    a robot with a wrong record misfits with most of its pairs. Nobody is named.

    ``rounds`` > 1 (the fast aligned path only, :mod:`fleet_frame`): a refit whose own
    misfit pairs are again isolated drops those too, up to ``rounds`` fits and at most
    :data:`MAX_DROPPED_SHARE` of the pairs in all (at least two). Dropping a pair moves
    the fit, and in a dense fleet the tail of the long sightings' noise then crosses the
    tolerance on another pair: 50 NAOs, seed 12, 478 pairs, 5-10 and 7-46 at scores
    1.07 and 1.25, then 16-46 and 42-48 at 1.02 and 1.01, then none; every robot stayed
    within 0.21 m of its true start throughout."""
    if rounds < 1:
        raise ValueError(f"rounds must be at least 1, got {rounds}")
    many = max(2, int(MAX_DROPPED_SHARE * len(poses.pairs)))
    budget = len(poses.pairs) if rounds == 1 else many  # one round: every isolated pair
    drop: set[tuple[int, int]] = set()
    current = poses
    for _ in range(rounds):
        bad = [p for p in current.pairs if p.score > 1.0]
        ends = Counter(r for p in bad for r in (p.i, p.j))
        if not bad or any(ends[p.i] > 1 or ends[p.j] > 1 for p in bad):
            return None
        drop |= {(p.i, p.j) for p in bad}
        if len(drop) > budget:
            return None
        meas = [
            m
            for m in poses.measurements
            if (min(m.owner, m.target), max(m.owner, m.target)) not in drop
        ]
        try:
            current = fit_poses(poses.ids, meas, poses.frame_robot)
        except ValueError:
            return None
        if current.consistent:
            names = ", ".join(f"{i}-{j}" for i, j in sorted(drop))
            why = f"consistent without the misfit pair(s) {names} (wrong pairings)"
            return PoseVerdict((), why, current)
        if current.turned:
            return None
    return None


def consistent_rest(poses: PoseFrame, robot: int, cleaning: bool = True) -> PoseFrame | None:
    """The fit without ``robot`` when it is connected and consistent, or (``cleaning``)
    becomes so once its isolated misfit pairs are dropped as wrong pairings (a fault and a
    wrong pairing in one fleet: 6 NAOs, one D-base off by 40 %); else None."""
    rest = leave_out(poses, robot)
    if rest is None or rest.consistent:
        return rest
    if rest.turned or not cleaning:
        return None
    cleaned = drop_wrong_pairings(rest)
    return None if cleaned is None else cleaned.poses


def quick_check(poses: PoseFrame) -> PoseVerdict | None:
    """:func:`check_frame`'s verdict where it needs no robot left out: the fit consistent,
    or (nobody turned) consistent once its isolated misfit pairs are dropped as wrong
    pairings; else None (then only :func:`check_frame`'s search over the robots tells).

    The search fits the fleet again once per robot (twice with the wrong pairings
    dropped): ~100 fits of ~1 s at 50 NAOs. :func:`fleet_frame.fleet_frame` asks this
    first, and searches only when the frame is not the papers' aligned one anyway."""
    if poses.consistent:
        return PoseVerdict((), "consistent: every pair within tolerance", poses)
    if not poses.turned:
        return drop_wrong_pairings(poses)
    return None


def may_explain(poses: PoseFrame, cleaning: bool) -> list[int]:
    """The robots (ascending) whose leaving out :func:`consistent_rest` is asked about: a
    turned robot or an end of a misfit pair, and only if the misfit pairs it is not part
    of are none (``cleaning`` False) or isolated (True: the wrong pairings that
    :func:`drop_wrong_pairings` may drop).

    Leaving a robot out drops its own pairs and nobody else's; the robust (soft-L1) fit
    bounds what its sightings did to the others' poses, so a misfit pair between two other
    robots stays misfit in the rest. Without this rule the search fitted the fleet once
    per robot, twice over: ~100 fits, ~100 CPU s at 50 NAOs whose misfit pairs spread
    over the whole fleet, to find what this rule says at once: nobody."""
    bad = [p for p in poses.pairs if p.score > 1.0]
    ends = {r for p in bad for r in (p.i, p.j)} | set(poses.turned)
    out = []
    for r in poses.ids:
        if r not in ends:
            continue
        others = Counter(x for p in bad if r not in (p.i, p.j) for x in (p.i, p.j))
        if not others or (cleaning and max(others.values()) == 1):
            out.append(r)
    return out


def _check_frame(poses: PoseFrame) -> PoseVerdict:
    """Steps 1-3 of the module docstring."""
    quick = quick_check(poses)
    if quick is not None:
        return quick
    if len(poses.turned) == 1:
        (t,) = poses.turned
        rest = leave_out(poses, t)
        if rest is not None and rest.consistent:
            return PoseVerdict(
                (t,),
                f"robot {t}: the others' masks agree its heading is off, and the others are "
                "consistent without it",
                poses,
            )
    worst = max(poses.pairs, key=lambda p: (p.score, -p.i, -p.j))
    bad = f"pair {worst.i}-{worst.j} misfit {worst.position:.2f} m, " + (
        f"{math.degrees(worst.heading):.0f}° (score {worst.score:.1f})"
    )
    candidates: list[int] = []
    rest_max: dict[int, float] = {}
    for cleaning in (False, True):  # as they are first; only if none, with wrong pairings dropped
        for r in may_explain(poses, cleaning):
            rest = consistent_rest(poses, r, cleaning)
            if rest is not None:
                candidates.append(r)
                rest_max[r] = max((p.score for p in rest.pairs), default=0.0)
        if candidates:
            break
    z = robust_z(poses.scores)
    zs = {rid: float(z[k]) for k, rid in enumerate(poses.ids)}
    score = {rid: float(poses.scores[k]) for k, rid in enumerate(poses.ids)}
    if len(candidates) == 1:
        r = candidates[0]
        return PoseVerdict(
            (r,),
            f"robot {r}: the others are consistent without it ({bad}; its score "
            f"{float(poses.scores[poses.ids.index(r)]):.1f}, z {zs[r]:.1f})",
            poses,
        )
    if candidates:
        worst_robot = min(candidates, key=lambda r: (-score[r], r))
        cleanest = min(candidates, key=lambda r: (rest_max[r], r))
        if worst_robot == cleanest and zs[worst_robot] >= Z_AGREE:
            r = worst_robot
            return PoseVerdict(
                (r,),
                f"robot {r}: of {candidates}, it has the highest score "
                f"({score[r]:.2f}, z {zs[r]:.1f}) and leaving it out leaves the lowest "
                f"worst pair score ({rest_max[r]:.2f}) ({bad})",
                poses,
            )
        high = [r for r in candidates if zs[r] >= Z_MIN]
        if len(high) == 1:
            r = high[0]
            return PoseVerdict(
                (r,),
                f"robot {r}: the only one of {candidates} whose leaving makes the rest "
                f"consistent with z {zs[r]:.1f} >= {Z_MIN} ({bad})",
                poses,
            )
        return PoseVerdict(
            (),
            f"ambiguous: leaving out any of {candidates} makes the rest consistent ({bad})",
            poses,
        )
    return PoseVerdict(
        (), f"inconsistent beyond one robot: no single robot explains it ({bad})", poses
    )
