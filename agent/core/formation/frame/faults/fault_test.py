"""Which robot's sightings do not fit: one hypothesis test per robot, on the measured
sighting noise (docs/design.md §9; the check the papers leave out: NAO paper 4.1.2 trusts
every record).

The model (:class:`agent.core.perception.sighting_noise.SightingNoise`, fitted on
rendered records with their truth) gives each sighting ``v_ij`` of the pose fit a
normalised residual ``χ²_ij`` (two degrees of freedom: along and across the line of
sight, σ_r(d) and σ_t(d)). Then:

1. **Rejected sightings.** A sighting is *rejected* when ``χ²_ij > q``, q the χ²₂
   quantile at :data:`ALPHA_SIGHTING`. A pair of robots (an *edge*: its one or two
   sightings) is rejected when one of its sightings is. A sound robot's edge is rejected
   with probability ``p_reject(d)``, the model's rate of rejected edges at distance d,
   measured on fault-free rendered fleets with this very test (a wrong pairing, a merged
   detection: gross errors happen).
2. **Per robot, its position test.** Robot r has ``n_r`` edges, ``k_r`` of them rejected,
   and ``s_r`` *lost strays* among its ``m_r`` own sightings (a sighting no pair of the
   fit uses that lands on no robot, nor on a NAO without a record where several owners'
   loose sightings agree (:mod:`outsiders`), within the χ² gate of the fitted frame). If r is
   sound, its edges are rejected independently with probabilities ``p_reject(d)`` (a
   faulty neighbour explains its one shared edge) and each of its sightings ends up a
   lost stray with ``p_stray(d)`` (a ghost or merged detection), both measured on
   fault-free fleets, so ``k_r + s_r`` is Poisson-binomial over ``n_r + m_r`` trials
   and the p-value is ``P(K ≥ k_r + s_r)``.
   A robot with wrong distances or a lying record has its own sightings off: those that
   pair are rejected, those that do not pair land nowhere.
3. **Per robot, its heading test** (:mod:`heading_test`). A robot whose compass is broken has its own
   sightings turned: its estimated ψ absorbs the turn, positions all fit, and only the
   others' masks of it (modulo π) disagree, all by one offset Δ. With the mask model's
   density f (the correct mask, the side/front confusion at ±90°, uniform otherwise),
   the generalised likelihood ratio ``2·max_Δ Σ log f(δ_k − Δ)/f(δ_k)`` over the
   others' masks δ_k of r is χ²₁ under "r is sound" (Wilks; Δ on a 1° grid) *if the
   masks err independently*. They do not always: a sound robot is seen turned as a whole
   with the measured probability ``rho`` (what the model of the masks leaves out), which
   a broken compass cannot be told from. So the heading test's p-value is
   ``max(p_Wilks, rho)``: masks name a robot only once they are better than that. The
   masks are those turned back to r's start heading by the times of the records
   (:func:`records.mask_orientation`; a mask of r seen while r turned is set aside); for
   a robot whose record carries no times (an older agent) the floor is ``rho_untimed``,
   the rate measured on records without times, where a robot seen mid-turn in its own
   search looks exactly like a broken compass.
4. **Per robot, its bias test** (:mod:`bias_test`): are r's own sightings all wrong the
   same way (its distances scaled, or every sighting shifted)? A likelihood-ratio test of
   a bias (s, b) fitted to r's sightings against none, with the others held at their
   fitted poses; its statistic over sound robots is χ²₃ (measured: ``bias_scale``). Four
   sightings 0.3 m off in one pattern are plain here long before each is rejected alone.
   r's own sightings enter it unlabelled, the unpaired ones too (:func:`unpaired`), each
   matched to the robot it lands nearest to: a scaled robot's sightings mostly fail to
   pair, or pair wrongly, at s = 1.
5. **The fleet's global test** (the overall model test before any robot is blamed, as
   in geodesy's data snooping): all rejected edges and lost strays of the fleet together,
   ``K``, against the same rates, Poisson-binomial over every edge and sighting. A frame
   can be wrong without any one robot standing out (a sparse fleet fitted into a wrong
   shape, each robot with a few sightings landing nowhere); ``P(K ≥ k) < ALPHA`` then
   fails the frame, and a robot left out must leave a rest that passes it too.
6. **The verdict.** A robot is *rejected* when the smallest of its three p-values,
   tripled (Bonferroni over the three tests), is below :data:`ALPHA` (the false-alarm
   rate per robot and run). Nobody rejected and the global test passed: the fleet is
   consistent; its rejected edges are wrong pairings, dropped, and the rest fitted
   again. Someone rejected: each rejected robot r (smallest p first, tie: lowest id) is
   left out (its sightings and the others' sightings of it) and the rest fitted again
   (:func:`multi_start.refit`: warm, and from the spanning tree); r is a *candidate*
   when the rest is connected and nobody in it is rejected. A robot is not tried when
   another rejected robot shares no sighting with it: leaving r out changes the others'
   evidence through their sightings of each other, so it cannot be what rejected a
   robot it never saw nor was seen by (and in a dense fleet each such search is a fit).
   Exactly one candidate is *named*; none, or more than one, and nobody can be trusted: the fleet
   stops (same reason on every agent). One threshold with a meaning (:data:`ALPHA`)
   replaces the rules of thumb. Deterministic: measurements are taken in canonical order
   (owner, target) and ties broken by id, so every agent names the same robot from the
   same records, in any order.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field, replace

import numpy as np
from scipy.special import bdtrc, chdtri

from agent.core.formation.frame.faults.bias_test import BiasFit, bias_fits
from agent.core.formation.frame.faults.heading_test import mask_deltas, mask_test
from agent.core.formation.frame.faults.outsiders import outsider_places
from agent.core.formation.frame.multi_start import refit
from agent.core.formation.frame.poses import PoseFrame, PoseMeasurement
from agent.core.formation.frame.records import NeighborRecord
from agent.core.perception.sighting_noise import SightingNoise

#: The false-alarm rate of the per-robot test, per robot and run: a sound robot is
#: rejected (and, if the rest then passes, left out) with at most this probability.
ALPHA = 1e-4


def one_fault_explains(rejected: int, robots: int) -> bool:
    """Whether a frame whose test rejects ``rejected`` of its ``robots`` robots at
    :data:`ALPHA` is consistent, at ALPHA itself, with the single-fault model: at most one
    faulty robot, each sound robot rejected independently with probability ALPHA, so
    P(Binomial(robots − 1, ALPHA) >= rejected − 1) >= ALPHA. A frame that fails it is a
    wrong frame (a wrong model or pairing of the fleet), and its rejections say nothing
    of any one robot (``fleet_frame``'s suspects). ``ValueError`` for negative counts or
    more rejected robots than robots."""
    if rejected < 0 or robots < 0 or rejected > robots:
        raise ValueError(f"need 0 <= rejected <= robots, got {rejected} of {robots}")
    if rejected <= 1:
        return True
    return float(bdtrc(rejected - 2, robots - 1, ALPHA)) >= ALPHA


#: The level of one sighting's χ² test (step 1). Any level is sound, since ``p_reject``
#: is measured at this same level; a small one rejects few sound pairs (the residuals'
#: tail is heavier than a Gaussian's) while a faulty robot's misfits, tens of σ, are
#: rejected anyway.
ALPHA_SIGHTING = 1e-6


@dataclass(frozen=True)
class RobotTest:
    """One robot's three tests (module docstring, steps 2-4)."""

    robot: int
    edges: int
    rejected_edges: int
    strays: int  #: its own sightings no pair uses
    lost: int  #: of which land on no robot
    p_position: float
    masks: int  #: the others' masks of it
    mask_offset: float  #: rad, the offset Δ the masks agree on best (modulo π)
    p_heading: float
    bias: float = 0.0  #: Λ of its bias test (:mod:`bias_test`)
    p_bias: float = 1.0

    @property
    def p(self) -> float:
        """Bonferroni over the three tests."""
        return min(1.0, 3.0 * min(self.p_position, self.p_heading, self.p_bias))

    def describe(self) -> str:
        return (
            f"robot {self.robot}: {self.rejected_edges}/{self.edges} pairs rejected, "
            f"{self.lost}/{self.strays} strays lost (p {self.p_position:.1e}), masks "
            f"{math.degrees(self.mask_offset):+.0f}° over {self.masks} (p {self.p_heading:.1e}), "
            f"bias Λ {self.bias:.0f} (p {self.p_bias:.1e})"
        )


@dataclass(frozen=True)
class FaultVerdict:
    """The outcome of the test: who is named, what to plan on, and why.

    ``poses`` is the fit to plan on (rejected edges dropped, the named robot left out);
    None when the fleet must stop (``ok`` False)."""

    ok: bool
    named: tuple[int, ...]
    poses: PoseFrame | None
    dropped: tuple[tuple[int, int], ...]
    tests: tuple[RobotTest, ...]
    reason: str
    #: step 5's global test of the robots to plan, as tested (before wrong pairings are
    #: dropped; the named robot left out): how well the frame fits, to choose between
    #: frames that pass
    fleet: FleetCount | None = None


def _edge(m: PoseMeasurement) -> tuple[int, int]:
    return (min(m.owner, m.target), max(m.owner, m.target))


def sighting_chi2(poses: PoseFrame, noise: SightingNoise) -> np.ndarray:
    """χ² of every measurement of ``poses`` (in its order), in its owner's fixed frame."""
    return noise.chi2(*misfits(poses))


def misfits(poses: PoseFrame) -> tuple[np.ndarray, np.ndarray]:
    """Every measurement's vector and its misfit at the fitted poses, (k, 2) each, in
    its owner's fixed frame (in the measurements' order)."""
    if not poses.measurements:
        return np.zeros((0, 2)), np.zeros((0, 2))
    index = {rid: k for k, rid in enumerate(poses.ids)}
    o = np.array([index[m.owner] for m in poses.measurements])
    t = np.array([index[m.target] for m in poses.measurements])
    v = np.array([m.vector for m in poses.measurements], dtype=np.float64).reshape(-1, 2)
    psi = poses.headings[o]
    c, s = np.cos(psi), np.sin(psi)
    rel = poses.positions[t] - poses.positions[o]  # common frame
    own = np.stack([c * rel[:, 0] + s * rel[:, 1], -s * rel[:, 0] + c * rel[:, 1]], axis=1)
    return v, own - v


def tail_at_least(p: Sequence[float], k: int) -> float:
    """``P(K ≥ k)`` for K the number of successes of independent trials with
    probabilities ``p`` (Poisson-binomial, exact by dynamic programming)."""
    if k <= 0:
        return 1.0
    # after i trials only counts 0 .. i can be non-zero: with finite probabilities the
    # rest stays exactly 0 (0·(1 − q) + 0·q), so it is left out of the step
    finite = all(math.isfinite(q) for q in p)
    if len(p) <= 64:  # a robot's few dozen: the same products and sums, as floats
        d = [1.0] + [0.0] * len(p)
        for i, q in enumerate(p):
            for j in range(i + 1 if finite else len(p), 0, -1):
                d[j] = d[j] * (1.0 - q) + d[j - 1] * q
            d[0] *= 1.0 - q
        return float(min(1.0, max(0.0, np.array(d[k:]).sum())))
    dist = np.zeros(len(p) + 1)
    dist[0] = 1.0
    for i, q in enumerate(p):
        top = i + 2 if finite else len(dist)
        dist[1:top] = dist[1:top] * (1.0 - q) + dist[: top - 1] * q
        dist[0] *= 1.0 - q
    return float(min(1.0, max(0.0, dist[k:].sum())))


def rejected_edges(poses: PoseFrame, noise: SightingNoise) -> dict[tuple[int, int], bool]:
    """Every edge of ``poses`` (ascending) and whether it is rejected (step 1)."""
    q = float(chdtri(2, ALPHA_SIGHTING))
    x2 = sighting_chi2(poses, noise)
    out: dict[tuple[int, int], bool] = {}
    for k, m in enumerate(poses.measurements):
        e = _edge(m)
        out[e] = out.get(e, False) or bool(x2[k] > q)
    return dict(sorted(out.items()))


def unpaired(poses: PoseFrame, records: Sequence[NeighborRecord]) -> dict[int, np.ndarray]:
    """Each fitted robot's own sightings that no measurement of ``poses`` uses, (k, 2) in
    its fixed frame, in record order (robots with none left out)."""
    used: dict[int, set[tuple[float, float]]] = {}
    for m in poses.measurements:
        used.setdefault(m.owner, set()).add((float(m.vector[0]), float(m.vector[1])))
    out: dict[int, np.ndarray] = {}
    for rec in sorted(records, key=lambda r: r.robot_id):
        if rec.robot_id not in poses.ids:
            continue
        mine = used.get(rec.robot_id, set())
        vecs = np.asarray(rec.neighbours, dtype=np.float64).reshape(-1, 2)
        keep = [v for v in vecs if (float(v[0]), float(v[1])) not in mine]
        if keep:
            out[rec.robot_id] = np.array(keep)
    return out


def strays(
    poses: PoseFrame,
    records: Sequence[NeighborRecord],
    noise: SightingNoise,
    elsewhere: np.ndarray | None = None,
) -> dict[int, list[tuple[float, bool]]]:
    """Each robot's stray sightings (step 2): (distance, lands on a robot) in record order.
    ``elsewhere`` (k, 2): more places, common frame, where a robot stands that ``poses``
    leaves out (a sighting of it lands)."""
    q = float(chdtri(2, ALPHA_SIGHTING))
    index = {rid: k for k, rid in enumerate(poses.ids)}
    out: dict[int, list[tuple[float, bool]]] = {}
    for rid, v in unpaired(poses, records).items():
        k = index[rid]
        c, s = math.cos(poses.headings[k]), math.sin(poses.headings[k])
        others = np.delete(np.arange(len(poses.ids)), k)
        places = poses.positions[others]
        if elsewhere is not None and len(elsewhere):
            places = np.vstack([places, np.asarray(elsewhere, dtype=np.float64).reshape(-1, 2)])
        rel = places - poses.positions[k]  # common frame
        own = np.stack([c * rel[:, 0] + s * rel[:, 1], -s * rel[:, 0] + c * rel[:, 1]], axis=1)
        row = []
        for x in v:
            e = own - x  # to every other robot, in this robot's fixed frame
            lands = bool(len(e)) and float(noise.chi2(np.repeat(x[None], len(e), 0), e).min()) <= q
            row.append((float(np.hypot(*x)), lands))
        out[rid] = row
    return out


@dataclass(frozen=True)
class _Evidence:
    """What the tests count, gathered once per fitted frame: each edge and whether it is
    rejected, each edge's base rate of rejection, each robot's strays (distance, lands) and
    the rate ``p_stray`` of every sighting of each record."""

    edges: dict[tuple[int, int], bool]
    p_edge: dict[tuple[int, int], float]  #: p_reject at the edge's mean sighting distance
    stray: dict[int, list[tuple[float, bool]]]
    sighted: dict[int, list[float]]  #: p_stray at each sighting's distance, by record
    #: robots whose records carry stances: their masks are turned back to their start
    #: heading (records.mask_orientation), the others' are as recorded
    timed: frozenset[int] = frozenset()
    #: each robot's own sightings no pair uses (:func:`unpaired`), for its bias test
    loose: dict[int, np.ndarray] = field(default_factory=dict)
    #: places (common frame) where a robot the frame leaves out stands
    elsewhere: np.ndarray | None = None
    #: each robot's tests without its bias test (steps 2-3), as first asked for
    cheap: dict[int, RobotTest] = field(default_factory=dict)


def _evidence(
    poses: PoseFrame,
    noise: SightingNoise,
    records: Sequence[NeighborRecord],
    elsewhere: np.ndarray | None,
) -> _Evidence:
    dist: dict[tuple[int, int], list[float]] = {}
    vectors = np.array([m.vector for m in poses.measurements], dtype=np.float64).reshape(-1, 2)
    for m, d in zip(poses.measurements, np.hypot(*vectors.T).tolist(), strict=True):
        dist.setdefault(_edge(m), []).append(d)
    sighted = {
        rec.robot_id: noise.p_stray(np.hypot(*rec.neighbours.reshape(-1, 2).T)).tolist()
        for rec in records
        if rec.robot_id in poses.ids
    }
    # np.mean of one or two distances is d₀ and (d₀ + d₁) / 2, bit for bit
    mean = [d[0] if len(d) == 1 else (d[0] + d[1]) / 2 if len(d) == 2 else float(np.mean(d))
            for d in (dist[e] for e in sorted(dist))]  # fmt: skip
    p_edge = dict(zip(sorted(dist), noise.p_reject(np.array(mean)).tolist(), strict=True))
    timed = frozenset(r.robot_id for r in records if r.stances is not None and len(r.stances))
    # NAOs without a record where loose sightings of several owners agree (bystanders):
    # their sightings land (:mod:`outsiders`)
    found = outsider_places(poses, records, noise, float(chdtri(2, ALPHA_SIGHTING)), elsewhere)
    if len(found):
        elsewhere = (
            found if elsewhere is None else np.vstack([np.reshape(elsewhere, (-1, 2)), found])
        )
    return _Evidence(rejected_edges(poses, noise), p_edge,
                     strays(poses, records, noise, elsewhere), sighted, timed,
                     unpaired(poses, records), elsewhere)  # fmt: skip


def robot_tests(
    poses: PoseFrame,
    noise: SightingNoise,
    records: Sequence[NeighborRecord] = (),
    elsewhere: np.ndarray | None = None,
) -> tuple[RobotTest, ...]:
    """Steps 1-4 for every robot of ``poses`` (ascending id); ``records`` give the
    strays (none without), ``elsewhere`` as :func:`strays`."""
    return _robot_tests(poses, noise, _evidence(poses, noise, records, elsewhere))


def _robot_tests(
    poses: PoseFrame, noise: SightingNoise, ev: _Evidence, bias: bool = True
) -> tuple[RobotTest, ...]:
    """Steps 2-4 from gathered evidence; ``bias`` False: without the bias test (step 4,
    the costly one: p_bias 1). The robots' bias tests are fitted side by side
    (:func:`bias_test.bias_fits`)."""
    fits = _bias_fits(poses, noise, ev) if bias else {}
    return tuple(_robot_test(poses, noise, ev, r, fits.get(r)) for r in poses.ids)


def _bias_fits(poses: PoseFrame, noise: SightingNoise, ev: _Evidence) -> dict[int, BiasFit]:
    """Step 4 for every robot of ``poses``."""
    return bias_fits(poses, poses.ids, noise, noise.bias_scale, ev.loose, ev.elsewhere)


def _robot_test(
    poses: PoseFrame, noise: SightingNoise, ev: _Evidence, r: int, fit: BiasFit | None
) -> RobotTest:
    """Steps 2-4 for robot ``r``, its bias test ``fit`` (None: without it, p_bias 1);
    steps 2-3 once per evidence (``ev.cheap``)."""
    if r not in ev.cheap:
        mine = [e for e in ev.edges if r in e]
        own = ev.stray.get(r, [])
        probs = [ev.p_edge[e] for e in mine]
        # every sighting of r's own could have ended up a lost stray (step 2)
        probs += ev.sighted.get(r, [])
        k = sum(ev.edges[e] for e in mine)
        lost = sum(not lands for _, lands in own)
        deltas = mask_deltas(poses, r)
        offset, p_h = mask_test(deltas, noise)
        p_h = max(p_h, noise.rho if r in ev.timed else noise.rho_untimed) if deltas else p_h
        p_pos = tail_at_least(probs, k + lost)
        ev.cheap[r] = RobotTest(r, len(mine), k, len(own), lost, p_pos, len(deltas), offset, p_h)
    test = ev.cheap[r]
    return test if fit is None else replace(test, bias=fit.statistic, p_bias=fit.p)


def _rejects_anyone(poses: PoseFrame, noise: SightingNoise, ev: _Evidence, alpha: float) -> bool:
    """Whether any robot's test (steps 2-4) rejects it at ``alpha``: the same answer as
    :func:`_robot_tests`, the costly bias tests run only when nobody is rejected without
    them (the cheap tests of every robot first; a robot's p only falls when its bias test
    is added)."""
    if any(_robot_test(poses, noise, ev, r, None).p < alpha for r in poses.ids):
        return True
    fits = _bias_fits(poses, noise, ev)
    return any(_robot_test(poses, noise, ev, r, fits[r]).p < alpha for r in poses.ids)


@dataclass(frozen=True)
class FleetCount:
    """Step 5's global test: rejected edges and lost strays of the whole fleet."""

    failures: int  #: rejected edges + lost strays
    trials: int  #: edges + sightings
    p: float  #: P(K ≥ failures) under "every robot is sound"

    def describe(self) -> str:
        return f"{self.failures} of its {self.trials} pairs and sightings fail (p {self.p:.1e})"


def _fleet_count(noise: SightingNoise, ev: _Evidence) -> FleetCount:
    probs = [ev.p_edge[e] for e in ev.edges]
    probs += [p for r in sorted(ev.sighted) for p in ev.sighted[r]]
    k = sum(ev.edges.values()) + sum(not lands for r in ev.stray for _, lands in ev.stray[r])
    return FleetCount(k, len(probs), tail_at_least(probs, k))


def fleet_count(
    poses: PoseFrame,
    noise: SightingNoise,
    records: Sequence[NeighborRecord] = (),
    elsewhere: np.ndarray | None = None,
) -> FleetCount:
    """The global test of step 5 on a fitted frame (arguments as :func:`robot_tests`)."""
    return _fleet_count(noise, _evidence(poses, noise, records, elsewhere))


def seen_by_others(
    poses: PoseFrame, rest: PoseFrame, robot: int, noise: SightingNoise
) -> np.ndarray:
    """Where ``rest`` (the fit without ``robot``) saw it, in ``rest``'s frame: the mean of
    the largest set of the others' sightings of it that agree with one of them within the
    sighting gate (step 1's χ² level, each sighting's error taken as large again as the
    model's for the pair of two noisy sightings; tie: the set around the lowest owner's
    sighting). One sighting paired with the wrong robot so never drags the place off the
    others' consensus, where a mean of all would (and every sighting of the consensus
    would then land nowhere). With no sighting of it, its own estimate in ``poses`` mapped
    into ``rest``'s frame through the robots both share."""
    seen = [
        (m.owner, np.asarray(m.vector, dtype=np.float64), rest.to_common(m.owner, m.vector)[0])
        for m in sorted(poses.measurements, key=lambda m: (m.owner, m.target))
        if m.target == robot and m.owner in rest.ids
    ]
    if seen:
        q = float(chdtri(2, ALPHA_SIGHTING))
        best: list[int] = []
        for _, _, centre in seen:
            agree = []
            for j, (owner, vector, at) in enumerate(seen):
                psi = float(rest.headings[rest.ids.index(owner)])
                c, s = math.cos(psi), math.sin(psi)
                d = centre - at  # common frame, turned into the owner's fixed frame
                err = np.array([[c * d[0] + s * d[1], -s * d[0] + c * d[1]]])
                if 0.5 * float(noise.chi2(vector.reshape(1, 2), err)[0]) <= q:
                    agree.append(j)
            if len(agree) > len(best):
                best = agree
        return np.asarray(np.mean(np.array([seen[j][2] for j in best]), axis=0))
    common = [i for i in rest.ids if i in poses.ids]
    a = np.array([poses.positions[poses.ids.index(i)] for i in common])
    b = np.array([rest.positions[rest.ids.index(i)] for i in common])
    ca, cb = a.mean(axis=0), b.mean(axis=0)
    u, _, vt = np.linalg.svd((a - ca).T @ (b - cb))
    r = vt.T @ u.T
    if np.linalg.det(r) < 0:
        vt[-1] *= -1
        r = vt.T @ u.T
    return np.asarray(cb + r @ (poses.positions[poses.ids.index(robot)] - ca))


def _without(poses: PoseFrame, robot: int) -> PoseFrame | None:
    rest = [i for i in poses.ids if i != robot]
    keep = [m for m in poses.measurements if robot not in (m.owner, m.target)]
    return refit(poses, rest, keep)


def _clean(
    poses: PoseFrame, noise: SightingNoise
) -> tuple[PoseFrame | None, tuple[tuple[int, int], ...]]:
    """``poses`` with its rejected edges dropped (wrong pairings) and fitted again; None
    when the rest no longer connects every robot."""
    edges = rejected_edges(poses, noise)
    drop = tuple(e for e, bad in edges.items() if bad)
    if not drop:
        return poses, ()
    keep = [m for m in poses.measurements if not edges[_edge(m)]]
    again = refit(poses, poses.ids, keep)
    if again is None or set(again.ids) != set(poses.ids):
        return None, drop
    return again, drop


def _names(drop: Sequence[tuple[int, int]], most: int = 8) -> str:
    """The pairs ``i-j`` (the first ``most``, and how many more)."""
    shown = ", ".join(f"{i}-{j}" for i, j in drop[:most])
    return shown + (f" and {len(drop) - most} more" if len(drop) > most else "")


def fault_test(
    poses: PoseFrame,
    noise: SightingNoise,
    records: Sequence[NeighborRecord] = (),
    alpha: float = ALPHA,
    search: bool = True,
    elsewhere: np.ndarray | None = None,
) -> FaultVerdict:
    """The test of the module docstring on a fitted :class:`PoseFrame`; ``search``
    False: a rejected robot is not sought to be named (no fit without it: a frame that may
    not name anyone needs no search, and each fit costs ~1 CPU s at 100 NAOs);
    ``elsewhere`` (k, 2): places, common frame, where robots stand that ``poses`` holds no
    record of (:func:`alone.unrecorded_place`), as :func:`strays`, for the frame as tested
    (a search fits the rest again, in a frame of its own: pass ``search`` False with it).

    Raises
    ------
    ValueError
        ``alpha`` outside (0, 1), or ``elsewhere`` with ``search``.
    """
    if not 0.0 < alpha < 1.0:
        raise ValueError(f"alpha must be in (0, 1), got {alpha}")
    if elsewhere is not None and search:
        raise ValueError("elsewhere holds for the frame as tested: a search needs it False")
    ev = _evidence(poses, noise, records, elsewhere)
    whole = _fleet_count(noise, ev)
    if not search:
        # a frame that may not name anyone fails on the first rejection: the cheap tests
        # first, the bias test only if they all pass
        cheap = _robot_tests(poses, noise, ev, bias=False)
        worst = min(cheap, key=lambda t: (t.p, t.robot))
        if worst.p < alpha or whole.p < alpha:
            why = (f"robot(s) rejected ({worst.describe()})" if worst.p < alpha
                   else f"the fleet as a whole does not fit: {whole.describe()}")  # fmt: skip
            return FaultVerdict(False, (), None, (), cheap, why + "; not searched", whole)
    tests = _robot_tests(poses, noise, ev)
    rejected = sorted((t for t in tests if t.p < alpha), key=lambda t: (t.p, t.robot))
    if not rejected and whole.p < alpha:
        why = (f"the fleet as a whole does not fit: {whole.describe()}, and no robot's own "
               "test rejects it; nobody moves")  # fmt: skip
        return FaultVerdict(False, (), None, (), tests, why, whole)
    if not rejected:
        clean, drop = _clean(poses, noise)
        if clean is None:
            return FaultVerdict(False, (), None, drop, tests,
                                f"the pairs {_names(drop)} do not fit and without them the fleet is "
                                "not connected; nobody moves", whole)  # fmt: skip
        why = "every robot passes its test" + (
            f"; pairs {_names(drop)} rejected (wrong pairings)" if drop else ""
        )
        return FaultVerdict(True, (), clean, drop, tests, why, whole)
    if not search:
        why = f"{len(rejected)} robot(s) rejected ({rejected[0].describe()}); not searched"
        return FaultVerdict(False, (), None, (), tests, why, whole)
    candidates: list[tuple[int, PoseFrame, tuple[tuple[int, int], ...], FleetCount]] = []
    seen_with: dict[int, set[int]] = {i: {i} for i in poses.ids}
    for m in poses.measurements:
        seen_with[m.owner].add(m.target)
        seen_with[m.target].add(m.owner)
    for t in rejected:
        if any(u.robot not in seen_with[t.robot] for u in rejected):
            continue  # another robot rejected that shares no sighting with it: not its doing
        rest = _without(poses, t.robot)
        if rest is None or len(rest.ids) != len(poses.ids) - 1:
            continue
        at = seen_by_others(poses, rest, t.robot, noise).reshape(1, 2)
        rest_ev = _evidence(rest, noise, records, at)
        # the global test first: either failing rules the candidate out, and it is cheap
        rest_count = _fleet_count(noise, rest_ev)
        if rest_count.p < alpha or _rejects_anyone(rest, noise, rest_ev, alpha):
            continue
        clean, drop = _clean(rest, noise)
        if clean is not None:
            candidates.append((t.robot, clean, drop, rest_count))
    first = rejected[0].describe()
    if len(candidates) == 1:
        r, clean, drop, rest_count = candidates[0]
        extra = f"; pairs {_names(drop)} rejected (wrong pairings)" if drop else ""
        why = (f"robot {r} named: its sightings do not fit at p < {alpha:g} and the others pass "
               f"without it ({next(t for t in tests if t.robot == r).describe()}){extra}")  # fmt: skip
        return FaultVerdict(True, (r,), clean, drop, tests, why, rest_count)
    if candidates:
        names = sorted(c[0] for c in candidates)
        why = f"ambiguous: leaving out any of {names} makes the rest pass ({first}); nobody moves"
        return FaultVerdict(False, (), None, (), tests, why, whole)
    why = f"inconsistent beyond one robot: no single robot explains it ({first}); nobody moves"
    return FaultVerdict(False, (), None, (), tests, why, whole)
