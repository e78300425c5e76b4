"""A robot tested alone against the others' frame: "r is faulty" once r's record is set
aside (docs/design.md §9, the fault test's last resort; the check the papers leave out:
NAO paper 4.1.2 trusts every record).

The fault test of :mod:`fault_test` tests each robot inside a frame fitted to every
record, r's own included, so a faulty r pulls the fit towards its own sightings and
hides behind the compromise: in a fleet of seven, a robot whose distances read 1.4 times
too long had four of its six pairs rejected (p 10⁻³) and a bias Λ of 21 (p 4·10⁻³), not
enough at α = 10⁻⁴, and the fleet stopped. When r's record is set aside and the rest is
framed from the others' records alone, r is still *seen*: the others' sightings of it
land where it stands. This module gives that place, and the test of r against the rest:

1. **Where a robot without a record stands** (:func:`unrecorded_place`). The rest's
   sightings that no measurement of the rest's fit uses and that land on no robot of the
   rest (within the sighting gate of :data:`fault_test.ALPHA_SIGHTING`) are sightings of
   something the rest does not hold: of r, or ghosts. r stands at the mean of the largest
   set of them, one per owner, that agree within the gate, each error taken as large
   again as the model's (two noisy sightings: χ² halved, as
   :func:`fault_test.seen_by_others`); tie: the set around the first sighting in (owner,
   record) order. The rest is tested with that place as one where a robot stands
   (``elsewhere`` of :func:`fault_test.fault_test`), so its sightings of r are not held
   against it as strays that land nowhere.
2. **r against the rest** (:func:`alone_test`), the rest held at its fitted poses:

   * r stands at that place; its heading ψ_r is the one, on a 1° grid, under which most
     of r's own sightings land on a robot of the rest (χ² halved again: r's place
     carries the others' errors), tie: the smaller sum of their χ² (each capped at the
     gate), then the smaller angle;
   * **position:** each of r's own sightings that lands on no robot at ψ_r is lost,
     which a sound robot's sighting is with the probability ``p_alone(d)`` measured with
     this very test on fault-free fleets (:class:`SightingNoise`); the p-value is the
     Poisson-binomial tail ``P(K ≥ lost)``, as step 2 of :mod:`fault_test`. (The fit's
     rate of lost strays, ``p_stray``, is a quarter of it: a sighting that pairs in the
     fit, rightly or as a wrong pairing, never counts there, and here every sighting
     does; with p_stray, a sound robot of thirty with four of its fifteen sightings landing
     nowhere would be rejected at p 10⁻⁶.);
   * **heading:** the others' masks of r (step 3 of :mod:`fault_test`, floored at ρ);
   * **bias:** :mod:`bias_test` on r's own sightings, all unlabelled, with the others'
     sightings of r pinning its position (step 4).

   r is rejected when ``3·min(p_pos, p_head, p_bias) < α`` (Bonferroni over the three,
   :data:`fault_test.ALPHA`), as in the fit. A robot fewer than :data:`outsiders.WITNESSES` of
   the others agree on is never rejected here: one sighting has no check, and a ghost,
   or a sighting of r that a wrong rest paired elsewhere leaving one behind, would stand
   for r (in five robots, the four framed without the faulty one's record 0.64 m off the
   truth, every one passing, one stray sighting left for it).
3. **The last resort** (:func:`set_aside`, what :func:`fleet_frame.fleet_frame` does when
   no candidate frame passes). Each *suspect* of a general candidate's failed test
   (:func:`suspects_of`: the robots it rejects, or, when it rejects nobody, those whose
   pairs failed it) has its record set aside, smallest p first, and the others are
   framed from scratch with nobody named, the suspect standing at its place of step 1.
   A suspect whose rest passes is *found* when its test rejects it at α, in the
   candidate's frame or alone (step 2). Exactly one found is named; none, or more than
   one, and the fleet stops. A sound robot is so named only if one of its tests rejects
   it at α (in one of the two general candidates, or alone) and the rest passes: at most
   3α per robot and run. It costs one framing of the rest per suspect.
4. **The screen of a frame that passes with everyone** (:func:`absorbed`). A frame can
   pass with a faulty robot in it: its own sightings pull its fitted pose their way, and
   a candidate that identifies sightings where they land pairs them with whoever they
   land on (in twelve robots, one whose distances read 1.4 times too long passed with
   five pairs called wrong pairings). Each robot is therefore tested as in step 2 but
   cheaply, with the others held at the frame's poses: it stands at the median of the
   others' sightings that land on it alone, at its fitted heading, and its position and
   heading tests are made there (0.1 CPU s for fifty robots). A robot either rejects at
   α is a suspect of step 3, whose full test on the others framed again names it or
   not; the screen only chooses whom to set aside.

Deterministic: records and sightings in (owner, record) order, the first of equal sets,
the smallest of equal angles.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Generic, Protocol, TypeVar

import numpy as np
from scipy.special import chdtri

from agent.core.formation.frame.faults.bias_test import bias_fit
from agent.core.formation.frame.faults.fault_test import (
    ALPHA,
    ALPHA_SIGHTING,
    FaultVerdict,
    RobotTest,
    one_fault_explains,
    seen_by_others,
    tail_at_least,
)
from agent.core.formation.frame.faults.heading_test import mask_deltas, mask_deltas_of, mask_test
from agent.core.formation.frame.faults.outsiders import (
    WITNESSES,
    agreeing_sets,
    agreement,
    best_heading,
    largest_set,
    loose_sightings,
    outsider_places,
    turn,
)
from agent.core.formation.frame.poses import PoseFrame, PoseMeasurement, evaluate_poses
from agent.core.formation.frame.records import NeighborRecord, mask_orientation
from agent.core.perception.sighting_noise import SightingNoise


@dataclass(frozen=True)
class Alone:
    """The test of a robot against the rest (module docstring, step 2)."""

    test: RobotTest
    #: (2,) where the others saw it, in the rest's frame; None: fewer than
    #: :data:`outsiders.WITNESSES` of them agree
    place: np.ndarray | None
    heading: float  #: ψ_r (rad) under which most of its sightings land

    def describe(self) -> str:
        return f"alone against the rest, {self.test.describe()}"


def _gate() -> float:
    return float(chdtri(2, ALPHA_SIGHTING))


def unrecorded_place(
    poses: PoseFrame,
    records: Sequence[NeighborRecord],
    noise: SightingNoise,
    robot: int = -1,
) -> tuple[np.ndarray | None, tuple[PoseMeasurement, ...]]:
    """Step 1 of the module docstring: where a robot without a record stands in ``poses``'
    frame, and the sightings of it as measurements with target ``robot`` (their masks as
    :func:`records.mask_orientation` turns them, when ``records`` holds ``robot``'s); (None,
    ()) when no sighting lands off the robots of ``poses``."""
    q = _gate()
    by_id = {r.robot_id: r for r in records}
    found = loose_sightings(poses, records, noise, q)
    best = largest_set(agreement(found, noise, q), found) if found else []
    if not best:
        return None, ()
    place = np.mean(np.array([found[j].at for j in best]), axis=0)
    target = by_id.get(robot)
    seen = tuple(
        PoseMeasurement(found[j].owner, robot, found[j].vector.copy(),
                        orientation=mask_orientation(by_id[found[j].owner], found[j].index, target))
        for j in best
    )  # fmt: skip
    return place, seen


def alone_test(
    rest: PoseFrame,
    records: Sequence[NeighborRecord],
    robot: int,
    noise: SightingNoise,
) -> Alone:
    """Step 2 of the module docstring: ``robot``'s record (in ``records``) tested against
    ``rest``, the frame of the others fitted without it.

    Raises
    ------
    ValueError
        ``robot`` is in ``rest``, or ``records`` holds no record of it.
    """
    if robot in rest.ids:
        raise ValueError(f"robot {robot} is in the rest's frame: it must be left out")
    mine = next((r for r in records if r.robot_id == robot), None)
    if mine is None:
        raise ValueError(f"no record of robot {robot}")
    own = np.asarray(mine.neighbours, dtype=np.float64).reshape(-1, 2)
    q = _gate()
    found = loose_sightings(rest, records, noise, q)
    sets = agreeing_sets(found, noise, q)  # NAOs the rest sees and holds no record of
    if not sets:
        untested = RobotTest(robot, 0, 0, len(own), 0, 1.0, 0, 0.0, 1.0)
        return Alone(untested, None, 0.0)
    places = np.array([np.mean(np.array([found[j].at for j in s]), axis=0) for s in sets])
    # it stands at the one its own record fits best (most of its sightings landing on the
    # rest and the others; tie: the first, the largest set): a bystander seen by more of
    # the rest than it is must not take its place
    choice: tuple[int, float, int] | None = None
    for i in range(len(sets)):
        around = np.vstack([rest.positions, np.delete(places, i, axis=0)]) - places[i]
        psi, hits = best_heading(around, own, noise, q)
        if choice is None or hits > choice[2]:
            choice = (i, psi, hits)
    assert choice is not None
    i, heading, lands = choice
    place = places[i]
    by_id = {r.robot_id: r for r in records}
    seen = tuple(
        PoseMeasurement(found[j].owner, robot, found[j].vector.copy(),
                        orientation=mask_orientation(by_id[found[j].owner], found[j].index, mine))
        for j in sets[i]
    )  # fmt: skip
    lost = len(own) - lands
    p_pos = tail_at_least([float(p) for p in noise.p_alone(np.hypot(*own.T))], lost)
    ids = tuple(sorted((*rest.ids, robot)))
    k = ids.index(robot)
    positions = np.insert(rest.positions, k, place, axis=0)
    headings = np.insert(rest.headings, k, heading)
    joint = evaluate_poses(ids, (*rest.measurements, *seen), positions, headings,
                           rest.frame_robot)  # fmt: skip
    deltas = mask_deltas(joint, robot)
    offset, p_h = mask_test(deltas, noise)
    timed = mine.stances is not None and len(mine.stances) > 0
    p_h = max(p_h, noise.rho if timed else noise.rho_untimed) if deltas else p_h
    # its sightings of the other NAOs without a record land there, in its bias test too
    fit = bias_fit(joint, robot, noise, noise.bias_scale, own, np.delete(places, i, axis=0))
    test = RobotTest(robot, len(seen), 0, len(own), lost, p_pos, len(deltas), offset, p_h,
                     fit.statistic, fit.p)  # fmt: skip
    return Alone(test, place, heading)


def absorbed(
    ids: Sequence[int],
    positions: np.ndarray,
    headings: np.ndarray,
    records: Sequence[NeighborRecord],
    noise: SightingNoise,
) -> list[tuple[int, float]]:
    """Step 4 of the module docstring, the screen of a frame that passes with everyone:
    (robot, p) of each robot that step 2's position or heading test, made at its fitted
    heading, rejects at :data:`fault_test.ALPHA`: its own sightings, seen from where the
    others saw it, land nowhere more often than ``p_alone`` allows, or the others' masks
    of it disagree with its heading; smallest p first, tie: lowest id. The screen only
    chooses whose record step 3 sets aside; the robot is named by step 2's full test on
    the others framed again (Bonferroni over its three tests there), so the screen's
    level sets the cost and the power, never the false-alarm rate. ``positions`` (n, 2) and
    ``headings`` (n,) of ``ids``, in any one frame.

    Where the others saw robot r is the median, per axis, of their sightings that land on r
    and on no other robot (the halved gate of step 1), the first of each owner: a faulty
    owner's sighting that lands on r by chance does not drag it; fewer than
    :data:`outsiders.WITNESSES` owners, and r is not screened.

    Raises
    ------
    ValueError
        ``positions`` or ``headings`` not one per robot of ``ids``.
    """
    ids = tuple(int(i) for i in ids)
    pos = np.asarray(positions, dtype=np.float64)
    psi = np.asarray(headings, dtype=np.float64)
    if pos.shape != (len(ids), 2) or psi.shape != (len(ids),):
        raise ValueError(
            f"need positions (n, 2) and headings (n,) for n = {len(ids)} robots, got "
            f"{pos.shape} and {psi.shape}"
        )
    if len(ids) < 2:
        return []
    q = _gate()
    by_id = {r.robot_id: r for r in records}
    # NAOs without a record, where its sightings also land; found only once some robot is
    # rejected without them (they only ever excuse lost sightings), the screen's usual case
    extra: np.ndarray | None = None
    seen: dict[int, dict[int, np.ndarray]] = {}  # target -> owner -> where it saw it
    masks: list[PoseMeasurement] = []  # those sightings, for the others' masks of each
    for k, rid in enumerate(ids):
        rec = by_id.get(rid)
        if rec is None or not len(rec.neighbours):
            continue
        own = np.asarray(rec.neighbours, dtype=np.float64).reshape(-1, 2)
        lands = _lands(turn(float(psi[k]), pos - pos[k]), own, noise, q)
        lands[:, k] = False
        at = pos[k] + turn(-float(psi[k]), own)
        for a in np.flatnonzero(lands.sum(axis=1) == 1):
            target = ids[int(np.argmax(lands[a]))]
            if rid in seen.setdefault(target, {}):
                continue
            seen[target][rid] = at[a]
            theta = mask_orientation(rec, int(a), by_id.get(target))
            masks.append(PoseMeasurement(rid, target, own[a].copy(), orientation=theta))
    out = []
    for k, rid in enumerate(ids):
        rec, witnesses = by_id.get(rid), seen.get(rid, {})
        if rec is None or len(witnesses) < WITNESSES:
            continue
        own = np.asarray(rec.neighbours, dtype=np.float64).reshape(-1, 2)
        place = np.median(np.array([witnesses[o] for o in sorted(witnesses)]), axis=0)
        rates = [float(x) for x in noise.p_alone(np.hypot(*own.T))]
        others = np.delete(pos, k, axis=0) - place
        lost = int((~_lands(turn(float(psi[k]), others), own, noise, q).any(axis=1)).sum())
        p_pos = tail_at_least(rates, lost)
        if p_pos < ALPHA and lost:
            if extra is None:
                extra = outsider_places(
                    evaluate_poses(ids, (), pos, psi, ids[0]), records, noise, q
                )
            if len(extra):
                others = np.vstack([np.delete(pos, k, axis=0), extra]) - place
                lands = _lands(turn(float(psi[k]), others), own, noise, q)
                p_pos = tail_at_least(rates, int((~lands.any(axis=1)).sum()))
        deltas = mask_deltas_of(ids, psi, masks, rid)
        p_head = mask_test(deltas, noise)[1] if deltas else 1.0
        timed = rec.stances is not None and len(rec.stances) > 0
        if deltas:
            p_head = max(p_head, noise.rho if timed else noise.rho_untimed)
        p = min(p_pos, p_head)
        if p < ALPHA:
            out.append((rid, p))
    return sorted(out, key=lambda t: (t[1], t[0]))


def _lands(rel: np.ndarray, own: np.ndarray, noise: SightingNoise, q: float) -> np.ndarray:
    """(k, n): whether each of ``own`` (k, 2) lands on each of the robots at ``rel`` (n, 2),
    both in the owner's frame, within the halved gate ``q``."""
    if not len(own) or not len(rel):
        return np.zeros((len(own), len(rel)), dtype=bool)
    err = (rel[None, :, :] - own[:, None, :]).reshape(-1, 2)
    x2 = 0.5 * noise.chi2(np.repeat(own, len(rel), axis=0), err)
    return np.asarray(x2.reshape(len(own), len(rel)) <= q)


def suspects_of(verdict: FaultVerdict) -> list[RobotTest]:
    """Step 3's suspects of a general candidate's test: the robots it rejects at
    :data:`fault_test.ALPHA`, unless more than one faulty robot and ALPHA's false alarms
    explain (:func:`fault_test.one_fault_explains`: a wrong frame, whose rejections say
    nothing of any one robot); when it rejects nobody and fails, those with a rejected
    pair or a lost stray (the frame failed on their pairs, or on the fleet's count of
    them)."""
    rejected = [t for t in verdict.tests if t.p < ALPHA]
    if rejected:
        return rejected if one_fault_explains(len(rejected), len(verdict.tests)) else []
    if verdict.ok:
        return []
    return [t for t in verdict.tests if t.rejected_edges or t.lost]


class RestFrame(Protocol):
    """The frame of the others that :func:`set_aside` tests a robot against."""

    @property
    def frame_robot(self) -> int: ...
    @property
    def ids(self) -> tuple[int, ...]: ...
    @property
    def positions(self) -> np.ndarray: ...
    @property
    def headings(self) -> np.ndarray: ...


R = TypeVar("R", bound=RestFrame)


@dataclass(frozen=True)
class SetAside(Generic[R]):
    """The robot named by step 3, the others' frame, and where it stands in it."""

    robot: int
    rest: R
    place: np.ndarray  #: (2,) in the rest's frame
    why: str  #: which test rejects it


def set_aside(
    records: Sequence[NeighborRecord],
    suspects: Mapping[int, tuple[float, PoseFrame]],
    noise: SightingNoise,
    frame_rest: Callable[[Sequence[NeighborRecord]], R | None],
) -> SetAside[R] | None:
    """Step 3 of the module docstring: each suspect (its smallest p in a general candidate's
    test and the poses it was tested on; smallest p first, tie: lowest id) has its record
    set aside and the others framed by ``frame_rest`` (None: they fail); it is *found*
    when that frame passes and its test rejects it at :data:`fault_test.ALPHA`, in the
    candidate's frame or alone against the rest (:func:`alone_test`). Exactly one found is
    named; None when none is, or more than one (nobody can be trusted)."""
    found: list[SetAside[R]] = []
    for robot, (p, tested) in sorted(suspects.items(), key=lambda kv: (kv[1][0], kv[0])):
        inner = frame_rest([r for r in records if r.robot_id != robot])
        if inner is None:
            continue
        poses = evaluate_poses(inner.ids, (), inner.positions, inner.headings, inner.frame_robot)
        alone = alone_test(poses, records, robot, noise)
        if p < ALPHA:
            why = f"its sightings do not fit at p {p:.1e} < {ALPHA:g}"
        elif alone.test.p < ALPHA:
            why = f"its record does not fit the others' frame ({alone.describe()})"
        else:
            continue
        at = seen_by_others(tested, poses, robot, noise) if alone.place is None else alone.place
        found.append(SetAside(robot, inner, np.asarray(at, dtype=np.float64).reshape(2), why))
        if len(found) > 1:
            return None
    return found[0] if found else None
