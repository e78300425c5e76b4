"""The fleet's frame for planning: poses, and the robot left out (docs/design.md §9).

NAO paper 4.1.3 builds the common frame from positions alone, assuming parallel fixed
frames (4.1.1). Here the common frame carries every robot's start *pose*, and every
frame is checked by the fault test of :mod:`fault_test` (one hypothesis test per
robot, on the measured sighting noise, at the false-alarm rate
:data:`fault_test.ALPHA`) before anyone plans on it.

Candidate frames, cheapest first (each built only when the ones before it fail):

1. **The papers' model** (eq. 9 pairs, least squares, ψ ≡ 0: :mod:`common_frame`), when it
   connects every robot: exactly the papers' frame for aligned starts.
2. **The papers' model with every sighting identified where it lands**
   (:func:`reidentify.refine_poses`), started from the firm eq. 9 pairs of a dense fleet
   (:func:`firm_pairs.firm_start`: its chance pairs left out), then from all pairs: in a
   dense fleet one sighting in ten pairs with the wrong robot.

   Neither aligned candidate is built when the masks of the eq. 9 pairs reject "every
   robot set down aligned" (:func:`masks_reject_alignment`, a likelihood ratio at the
   false-alarm rate :data:`ALIGNED_ALPHA`): a fleet plainly set down turned goes
   straight to the pose fit, which fits aligned fleets too (at 50 NAOs the second
   candidate alone costs ~2 CPU s).
3. **The pose fit** (:func:`poses.fit_from_graph`: the pairing of :mod:`pose_pairing`
   and a robust SE(2) fit, never the aligned model): robots set down facing any
   direction. A mask gives a heading only modulo π, and the fit can hold a robot half a
   turn off (a local minimum of its cost): when its test rejects robots, each (in the
   test's order) is fitted again half turned round (:func:`multi_start.half_turned`), and
   the first that fits better replaces the fit, which is tested again; the robots it
   still rejects are tried so in turn, each turned at most once (candidate 4 then builds
   on the last fit). Without it, a sound robot of fifty fitted 172° off is left out; and
   turning only the first, a fleet of fifty set down at random with two sound robots
   held half a turn off had the second left out.
4. **The pose fit with every sighting identified where it lands.**

A frame the fault test passes is planned on only if the others' masks together do not
say that some robots stand half a turn off in it (:func:`half_turn_test`, at
:data:`fault_test.ALPHA`): each mask off by π alone is a front/back confusion, and a
robot's own test reads its masks modulo π (seed 2681 of five, records with times: the
aligned model, its sightings identified where they land, holds robots 2, 4 and 5 half a
turn off with every robot passing; its ten masks between them and the others, all read
the other way round, reject it at p 5·10⁻⁵, and the pose fit is planned on). A frame it
rejects fails like one the fault test fails.

A frame with nobody named is preferred: the candidates are tried in order for one the
test passes with everyone, and it is planned on as it is (a refined candidate has
identified its sightings; an unrefined one is fitted again without its rejected pairs).
A frame that passes with everyone is *doubted* when it surprises the noise model at
:data:`DOUBT`: its global test gives p below it, or its most surprising robot does once
multiplied by the number of robots (Bonferroni over the fleet: some robot of n sound ones
looks that odd with at most that probability). The later candidates are then tried too,
and a frame that passes with everyone after a general candidate has named a robot is
not taken for its place in the order either: of every frame that passed, those naming
a robot included (judged on the rest, the named robot left out), the one whose global
test gives the largest p is kept (the fit the noise model finds
least surprising; tie: the earlier). A frame built on the aligned model can pass with
one robot fitted wrong, its sightings all landing nowhere (in five robots, four set down
within 16° of each other and one turned 130°: p 4·10⁻⁴), where the pose fit explains
every sighting (p 1); and identifying sightings where they land can absorb a faulty
robot, every sighting of it re-identified (p 10⁻³), where the pose fit names it and the
rest fits (p 0.4); or with a robot's sightings all shifted 0.5 m re-identified onto its
neighbours, every robot passing (the worst at p 3·10⁻⁴ of seven, its global test not
surprised) and one start 0.47 m off, where the pose fit names that robot.
Only if none passes so is the first general candidate (3, 4) that names a robot taken,
(a poor fit of a sound fleet must not blame a robot a better fit clears), and only if
that robot's record, tested alone against the rest the candidate fitted without it
(:func:`alone.alone_test`), does not pass there too (a rejection the record alone does not
confirm may be another robot's pull): fitted again
without it, the named robot standing still where the *others* saw it (where most of their
sightings of it agree, in the rest's frame: :func:`fault_test.seen_by_others`) and
planned around like an obstacle. The aligned model (1, 2) never names anyone: it would
blame a sound robot merely set down turned. A
candidate that identifies sightings where they land is tested on each sighting as it
identified it, and on each sighting it dropped as first paired
(:func:`tested_sightings`): a sighting that lands nowhere is evidence, and a wrong
pairing it corrected is not held against the robot first paired.

When nothing passes, the fleet is *framed again without a record*: "robot r is faulty"
means its record is untrusted, not merely its pairs, and the rest must then pass the
same test on a frame built from the others' records alone, paired and fitted from
scratch. Leaving out only the pairs a faulty robot's sightings made keeps what they did
to the rest: pairings made around its false places, a neighbour pulled round (in a fleet
of ten, a robot whose distances read 1.4 times too long left a sound robot it never saw
11° off, and the rest, fitted again from those pairs, failed). So each *suspect* of a
general candidate's failed test (:func:`alone.suspects_of`: the robots it rejects at
:data:`fault_test.ALPHA`, unless more than one faulty robot and ALPHA's false alarms
explain them, :func:`fault_test.one_fault_explains`; when it rejects nobody, the robots
whose pairs failed it) has its whole record set aside, smallest p first, and the
candidates run again on the others with nobody named (:func:`_without_record`), the
suspect standing where the others' sightings that land on none of them agree
(:func:`alone.unrecorded_place`: the rest is not blamed for seeing the robot set aside).
A suspect whose rest passes is named when its own test rejects it at ALPHA, in a
general candidate's frame or alone against the rest (:func:`alone.alone_test`: its
record tested with the rest held fixed, where a faulty robot cannot pull the fit
its way); exactly one is named, standing where the others saw it. None, or more than
one, and :func:`fleet_frame` raises ``ValueError`` with the reason of the last candidate
built, the same on every agent (they hold the same records): nobody moves. A sound robot
is so left out with at most 3·ALPHA per run. The search runs where the fleet would
otherwise stop, and where a frame passed with everyone but its screen
(:func:`alone.absorbed`: each robot tested alone, cheaply, against the others at the
frame's poses) rejects a robot at ALPHA: a faulty robot the frame absorbed, its
sightings pulling its pose their way or paired with whoever they landed on. It costs one
framing of the rest per suspect; the screen, 0.1 CPU s at fifty robots.

Every robot is then planned from its estimated start position, and walks in the common
frame by turning its own plan by its estimated start heading ψ (:mod:`own_frame`).

Deterministic: the same records in any order give bit-identical output (the pose fit's
own guarantee; the named robot's place is a consensus over sightings sorted by owner id).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace

import numpy as np

from agent.core.formation.frame.common_frame import build_common_frame
from agent.core.formation.frame.faults.alone import (
    absorbed,
    alone_test,
    set_aside,
    suspects_of,
    unrecorded_place,
)
from agent.core.formation.frame.faults.fault_test import (
    ALPHA,
    FaultVerdict,
    fault_test,
    seen_by_others,
)
from agent.core.formation.frame.firm_pairs import firm_start
from agent.core.formation.frame.multi_start import half_turn_test, half_turned
from agent.core.formation.frame.neighbour_check import NeighbourGraph, identify_neighbours
from agent.core.formation.frame.pose_pairing import identify_pairs
from agent.core.formation.frame.poses import (
    PoseFrame,
    PoseMeasurement,
    evaluate_poses,
    fit_from_graph,
    pair_measurements,
)
from agent.core.formation.frame.records import NeighborRecord
from agent.core.formation.frame.reidentify import refine_poses
from agent.core.perception.sighting_noise import SightingNoise, shipped_noise

#: The level at which a frame that passes the fault test is doubted (module docstring): a
#: passed frame whose :func:`surprise` is below it is
#: compared with the later candidates, and the one that fits best is kept. It decides
#: only how far the search goes (a correct frame is doubted in about 1 % of fleets, and
#: each doubt costs the later candidates: ~60 CPU s at 100 NAOs), never whether a frame
#: is accepted: that is :data:`fault_test.ALPHA`'s.
DOUBT = 0.01


@dataclass(frozen=True)
class FleetFrame:
    """Poses of the robots to plan, in the frame robot's fixed frame, and who is left out."""

    frame_robot: int
    ids: tuple[int, ...]  # ascending: the robots to plan
    positions: np.ndarray  # (N, 2)
    headings: np.ndarray  # (N,) ψ: each robot's fixed frame turned from the common frame
    aligned: bool  # the papers' aligned model was kept (every ψ exactly 0)
    excluded: tuple[int, ...] = ()  # robots left out: they stand still
    #: (len(excluded), 2): where the others saw the robots left out
    excluded_at: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    reason: str = ""  # the fault test's verdict

    def heading_of(self, robot_id: int) -> float:
        """ψ of a planned robot; ``ValueError`` for one not planned."""
        if robot_id not in self.ids:
            raise ValueError(f"robot {robot_id} is not planned")
        return float(self.headings[self.ids.index(robot_id)])


def _papers_poses(graph: NeighbourGraph) -> PoseFrame | None:
    """The papers' model on ``graph`` (eq. 9 pairs, least squares, ψ ≡ 0) as poses with the
    residuals of its pairs' sightings, or None if it does not connect."""
    try:
        cf = build_common_frame(graph, "lsq")
    except ValueError:
        return None
    zero = np.zeros(len(cf.ids))
    return evaluate_poses(
        cf.ids, pair_measurements(graph), cf.positions, zero, cf.frame_robot, True
    )


#: The false-alarm rate of :func:`masks_reject_alignment`: a fleet set down aligned has its
#: aligned candidates (1, 2) skipped with at most this probability (then the pose fit,
#: which fits aligned fleets too, gives its frame).
ALIGNED_ALPHA = 1e-6
#: The spread of relative headings that :func:`masks_reject_alignment`'s alternative
#: describes beside uniform ones: robots set down within ±20° of a heading differ by a
#: triangular spread of σ 40°/√6 ≈ 16°. It shapes only the test's power, never its
#: false-alarm rate.
HEADING_SPREAD = math.radians(16.0)


def masks_reject_alignment(graph: NeighbourGraph, noise: SightingNoise) -> bool:
    """Whether the masks of the eq. 9 pairs of ``graph`` reject "every robot set down
    aligned" at :data:`ALIGNED_ALPHA` (the aligned candidates are then not built).

    Aligned (ψ ≡ 0), the mask of a sighting at bearing β with orientation θ (turned back
    to its target's start heading: :func:`records.mask_orientation`) misses the heading
    difference by ``δ = −(β + θ − π/2)`` modulo π, whatever robot it saw, with the mask
    model's density f (:meth:`SightingNoise.mask_density`: correct w0, side/front w90,
    uniform otherwise). Against the alternative density
    ``g = ½·(1/π) + ½·f_s`` (heading differences uniform, or spread by
    :data:`HEADING_SPREAD` s: f with σ_m² + s²), the likelihood ratio
    ``L = Π_k g(δ_k) / f(δ_k)`` of independent masks has expectation 1 under alignment,
    so ``P(L ≥ 1/α) ≤ α`` (Markov's inequality); alignment is rejected when
    ``log L ≥ log(1/α)``, α = :data:`ALIGNED_ALPHA`. The bound holds for any fixed g:
    ``HEADING_SPREAD`` sets only how soon robots set down within ±20° are told from
    aligned ones. A mask of aligned robots weighs log(g/f) = −0.76 on average (−1.4 at
    δ = 0), one off by a uniform offset +1.56 (at most 2.7): over many masks, alignment
    is rejected once about a third of them disagree with it. On the corpus's fleets of
    15 NAOs or more set down within ±20° or at random it is rejected in every run, in
    no run of an aligned fleet (its largest log L: −2.0)."""
    deltas = [-(math.atan2(float(m.vector[1]), float(m.vector[0])) + m.orientation - math.pi / 2)
              for m in pair_measurements(graph) if math.isfinite(m.orientation)]  # fmt: skip
    return alignment_log_ratio(np.array(deltas), noise) >= math.log(1.0 / ALIGNED_ALPHA)


def alignment_log_ratio(deltas: np.ndarray, noise: SightingNoise) -> float:
    """``log L = Σ_k log g(δ_k) / f(δ_k)`` of :func:`masks_reject_alignment` over mask
    misses ``deltas`` (rad, modulo π; 0 for none)."""
    d = np.asarray(deltas, dtype=np.float64).reshape(-1)
    if d.size == 0:
        return 0.0
    spread = math.sqrt(noise.sigma_mask**2 + HEADING_SPREAD**2)
    wide = replace(noise, sigma_mask=min(spread, math.pi / 4 - 1e-9))
    g = 0.5 / math.pi + 0.5 * wide.mask_density(d)
    return float(np.log(g / noise.mask_density(d)).sum())


@dataclass(frozen=True)
class _Candidate:
    """A way to build a frame: its name, whether it is general (may name a robot), and
    the builder of (the poses to plan on, the poses to test) (None: it does not connect
    every robot). A candidate that identifies sightings again where they land is tested
    on the sightings as first paired, at its refined poses: a sighting that lands nowhere
    is evidence, not something to drop before the test."""

    name: str
    general: bool
    build: Callable[[], tuple[PoseFrame, PoseFrame] | None]
    #: given the robots its test rejected (in the test's order), fits its poses again
    #: with one of them half turned round, and says which robot fitted better so (None:
    #: none did; else the candidate, and those built on it, build on the better fit)
    turn: Callable[[Sequence[int]], int | None] | None = None


def _candidates(
    records: Sequence[NeighborRecord], epsilon: float, noise: SightingNoise | None = None
) -> list[_Candidate]:
    """The candidate frames of the module docstring, in order (each built lazily, once);
    the aligned ones (1, 2) none when the masks reject alignment
    (:func:`masks_reject_alignment`, on ``noise``'s mask model: default the shipped one,
    whose masks every model shares, :meth:`SightingNoise.synthetic`)."""
    everyone = {r.robot_id for r in records}
    graph = identify_neighbours(records, epsilon)
    memo: dict[str, PoseFrame | None] = {}
    masks = shipped_noise() if noise is None else noise
    aligned = not masks_reject_alignment(graph, masks)

    def once(key: str, make: Callable[[], PoseFrame | None]) -> Callable[[], PoseFrame | None]:
        def get() -> PoseFrame | None:
            if key not in memo:
                frame = make()
                memo[key] = frame if frame is not None and set(frame.ids) == everyone else None
            return memo[key]

        return get

    papers = once("papers", lambda: _papers_poses(graph) if aligned else None)

    def fit() -> PoseFrame | None:
        try:
            return fit_from_graph(identify_pairs(records, epsilon))
        except ValueError:
            return None

    fitted = once("fit", fit)

    def turn(rejected: Sequence[int]) -> int | None:
        base = fitted()
        if base is None:
            return None
        for robot in rejected:
            better = half_turned(base, robot)
            if better is not None:
                memo["fit"] = better
                return robot
        return None

    def firm() -> PoseFrame | None:
        start = firm_start(graph) if aligned else None
        return None if start is None else _papers_poses(start)

    def as_is(
        get: Callable[[], PoseFrame | None],
    ) -> Callable[[], tuple[PoseFrame, PoseFrame] | None]:
        def build() -> tuple[PoseFrame, PoseFrame] | None:
            poses = get()
            return None if poses is None else (poses, poses)

        return build

    def again(
        *bases: Callable[[], PoseFrame | None],
    ) -> Callable[[], tuple[PoseFrame, PoseFrame] | None]:
        def build() -> tuple[PoseFrame, PoseFrame] | None:
            base = next((b for b in (get() for get in bases) if b is not None), None)
            if base is None:
                return None
            fine = refine_poses(base, records)
            test = evaluate_poses(fine.ids, tested_sightings(base, fine), fine.positions,
                                  fine.headings, fine.frame_robot, fine.aligned)  # fmt: skip
            return fine, test

        return build

    return [
        _Candidate("the papers' aligned model", False, as_is(papers)),
        _Candidate(
            "the aligned model, sightings identified where they land",
            False,
            again(once("firm", firm), papers),
        ),
        _Candidate("the pose fit", True, as_is(fitted), turn),
        _Candidate("the pose fit, sightings identified where they land", True, again(fitted)),
    ]


def tested_sightings(base: PoseFrame, fine: PoseFrame) -> list[PoseMeasurement]:
    """The sightings a refined candidate is tested on: each as ``fine`` identified it
    where it lands, and each ``fine`` dropped (it landed on nobody) as ``base`` first
    paired it. So a wrong pairing that re-identification corrected is not held against
    the robot it was first paired with, and a sighting that lands nowhere stays evidence
    (a faulty robot's sightings are the ones that land nowhere)."""
    used = {(m.owner, float(m.vector[0]), float(m.vector[1])) for m in fine.measurements}
    kept = [m for m in base.measurements
            if (m.owner, float(m.vector[0]), float(m.vector[1])) not in used]  # fmt: skip
    return sorted([*fine.measurements, *kept], key=lambda m: (m.owner, m.target))


def _framed(
    fine: PoseFrame, test: PoseFrame, verdict: FaultVerdict, how: str, noise: SightingNoise
) -> FleetFrame:
    """The frame to plan on from a passed verdict: the candidate's own poses when nobody is
    named (a refined candidate has already identified its sightings where they land; an
    unrefined one is fitted again without its rejected pairs), else the fit without the
    named robot."""
    reason = f"{how}: {verdict.reason}"
    if not verdict.named:
        plan_on = fine if fine is not test or not verdict.dropped else verdict.poses
        assert plan_on is not None  # a passed verdict carries its poses
        aligned = plan_on.aligned and not verdict.dropped
        return FleetFrame(plan_on.frame_robot, plan_on.ids, plan_on.positions, plan_on.headings,
                          aligned, reason=reason)  # fmt: skip
    plan_on = verdict.poses
    assert plan_on is not None
    (robot,) = verdict.named
    at = seen_by_others(test, plan_on, robot, noise)
    return FleetFrame(plan_on.frame_robot, plan_on.ids, plan_on.positions, plan_on.headings, False,
                      excluded=(robot,), excluded_at=at.reshape(1, 2), reason=reason)  # fmt: skip


def surprise(verdict: FaultVerdict) -> float:
    """How well a frame that passed fits (module docstring, *doubted*): the smaller of its
    global test's p and its most surprising robot's p times the number of robots."""
    if verdict.fleet is None:
        raise ValueError("a verdict without its global test (a frame that did not pass)")
    worst = min((t.p for t in verdict.tests), default=1.0)
    return min(verdict.fleet.p, worst * max(1, len(verdict.tests)))


def fleet_frame(
    records: Sequence[NeighborRecord], epsilon: float, noise: SightingNoise | None = None
) -> FleetFrame:
    """The first candidate frame the fault test passes (module docstring).

    Parameters
    ----------
    records : sequence of NeighborRecord
        One per robot, any order.
    epsilon : float
        ε of eq. 9 (m).
    noise : SightingNoise, optional
        The sighting noise model (default: the shipped one, fitted on rendered records).

    Raises
    ------
    ValueError
        Bad records or ε, a fleet no candidate connects, or a fleet no candidate frame
        passes the fault test (more than one robot would have to be left out, or which
        one is ambiguous): the reason says which.
    """
    model = shipped_noise() if noise is None else noise
    suspects: dict[int, tuple[float, PoseFrame]] = {}
    frame, last = _first_passed(records, epsilon, model, suspects)
    if frame is not None:
        if frame.excluded:
            return frame
        odd = absorbed(frame.ids, frame.positions, frame.headings, records, model)
        if not odd:
            return frame
        fit = evaluate_poses(frame.ids, (), frame.positions, frame.headings, frame.frame_robot)
        # they passed in the fit (p 1 below): only the test alone can find them
        named = _without_record(records, epsilon, model, {r: (1.0, fit) for r, _ in odd})
        return frame if named is None else named
    named = _without_record(records, epsilon, model, suspects)
    if named is not None:
        return named
    raise ValueError(f"no frame passes the fault test ({last})")


def _first_passed(
    records: Sequence[NeighborRecord],
    epsilon: float,
    model: SightingNoise,
    suspects: dict[int, tuple[float, PoseFrame]] | None,
    unrecorded: bool = False,
) -> tuple[FleetFrame | None, str]:
    """The candidate loop of the module docstring: (the frame, None if none passes; the
    reason of the last candidate tried). ``suspects`` None: no robot may be named (the
    general candidates are tested without a search); else it collects the suspects of
    every general candidate's test (:func:`alone.suspects_of`), each with its smallest p and the
    poses it was tested on. ``unrecorded``: one robot stands among ``records``' robots
    without a record of its own (its record set aside), where the others' sightings that
    land on none of them agree (:func:`alone.unrecorded_place`)."""
    last = "no candidate frame connects every robot through identified neighbours"
    passed: list[tuple[float, bool, FleetFrame]] = []  # (global p, names a robot, frame)
    for cand in _candidates(records, epsilon, model):
        built = cand.build()
        if built is None:
            continue
        fine, test = built
        searched = any(named for _, named, _ in passed)
        search = suspects is not None and cand.general and not searched and not unrecorded
        elsewhere = None
        if unrecorded:
            place, _ = unrecorded_place(test, records, model)
            elsewhere = None if place is None else place.reshape(1, 2)
        verdict = fault_test(test, model, records, search=search, elsewhere=elsewhere)
        rejected = _rejected(verdict)
        turned: set[int] = set()  # each rejected robot is turned round at most once
        while cand.turn is not None:
            robot = cand.turn([r for r in rejected if r not in turned])
            if robot is None:
                break
            turned.add(robot)
            built = cand.build()
            assert built is not None  # a better fit of the same robots
            fine, test = built
            verdict = fault_test(test, model, records, search=False)
            rejected = _rejected(verdict)
        if turned and search:
            verdict = fault_test(test, model, records, search=True)
        if suspects is not None and cand.general:
            for t in suspects_of(verdict):
                if t.robot not in suspects or t.p < suspects[t.robot][0]:
                    suspects[t.robot] = (t.p, test)
        last = f"{cand.name}: {verdict.reason}"
        if not verdict.ok or (verdict.named and not cand.general):
            continue
        judged = verdict.poses if verdict.named else test  # the named robot left out
        assert judged is not None  # a passed verdict carries its poses
        if verdict.named:
            # its record against the rest held fixed: a robot whose record fits the rest
            # was rejected for another's fault pulling the fit (alone.py, step 2)
            (robot,) = verdict.named
            alone = alone_test(judged, records, robot, model)
            if alone.place is not None and alone.test.p >= ALPHA:
                last = f"{cand.name}: robot {robot} not named: its record fits the rest ({alone.describe()})"
                continue
        half = half_turn_test(judged, model, records)
        if half.p < ALPHA:
            last = f"{cand.name}: {half.describe()}"
            continue
        assert verdict.fleet is not None  # a passed verdict carries its global test
        frame = _framed(fine, test, verdict, cand.name, model)
        if not verdict.named and not searched and surprise(verdict) >= DOUBT:
            return frame, last
        passed.append((verdict.fleet.p, bool(verdict.named), frame))
    if any(not named for _, named, _ in passed):
        # every frame that passed with everyone is doubted: the best fit of all that passed
        return max(passed, key=lambda c: c[0])[2], last  # the first of equal p
    if passed:
        return passed[0][2], last  # the first general candidate that names a robot
    return None, last


def _rejected(verdict: FaultVerdict) -> list[int]:
    """The robots ``verdict``'s tests reject at :data:`fault_test.ALPHA`, in the test's
    order (smallest p first, tie: lowest id)."""
    return [t.robot for t in sorted(verdict.tests, key=lambda t: (t.p, t.robot)) if t.p < ALPHA]


def frame_rest(
    rest: Sequence[NeighborRecord], epsilon: float, noise: SightingNoise | None = None
) -> FleetFrame | None:
    """The others framed without a robot's record (module docstring, *framed again without
    a record*): the candidates on ``rest`` with nobody named, one robot standing among
    them without a record; None when no candidate passes with every robot of ``rest``."""
    model = shipped_noise() if noise is None else noise
    inner, _ = _first_passed(rest, epsilon, model, None, unrecorded=True)
    return inner if inner is not None and len(inner.ids) == len(rest) else None


def _without_record(
    records: Sequence[NeighborRecord],
    epsilon: float,
    model: SightingNoise,
    suspects: dict[int, tuple[float, PoseFrame]],
) -> FleetFrame | None:
    """The last resort of the module docstring (*framed again without its record*,
    :func:`alone.set_aside`): the frame of the others, with the robot named, or None."""

    found = set_aside(records, suspects, model, lambda rest: frame_rest(rest, epsilon, model))
    if found is None:
        return None
    inner = found.rest
    reason = (f"robot {found.robot} named: {found.why}, and the others, framed again "
              f"without its record, pass ({inner.reason})")  # fmt: skip
    return FleetFrame(inner.frame_robot, inner.ids, inner.positions, inner.headings, False,
                      excluded=(found.robot,), excluded_at=found.place.reshape(1, 2),
                      reason=reason)  # fmt: skip
