"""Fitting the poses again from more than one start (docs/design.md §9).

The robust SE(2) fit of :mod:`poses` is local: Levenberg–Marquardt on a soft-L1 cost,
from a start. Recorded fleets showed two starts that miss the best fit, each for a
known reason:

* **A warm start keeps a robot pulled off by a faulty one.** When the fault test leaves a
  robot out and fits the rest again, the poses fitted with it are a natural start; but a
  neighbour its misfits pulled round stays there (in a fleet of ten, a robot whose
  distances read 1.4 times too long had pulled a neighbour 11° off, and the rest, fitted
  warm, still failed). :func:`refit` fits from the warm start and from the spanning tree
  and keeps the better.
* **A mask gives a heading only modulo π**, and the position misfits of a robot with
  few sightings can hold a heading half a turn off (in a fleet of fifty, a sound robot
  fitted 172° off was rejected, and the rest passed without it: a sound robot left out).
  :func:`half_turned` fits again with one robot turned half round, when that robot,
  turned, fits its own sightings and the others' of it better (its pose alone refitted,
  the others held: some 10 ms, where a whole fit of fifty costs ~0.2 CPU s and the
  fault test of a fleet with a faulty robot may reject thirty robots, each tried).

Of fits of the same measurements, the one with the lowest robust cost
(:func:`poses.fit_cost`, the M-estimator's own objective) is the estimate the model
prefers: no new threshold. Tie (costs within :data:`TIE` of each other, relatively): the
first start. Deterministic: every start is a function of the poses and measurements.

A fit can also hold *several* robots half a turn off together, each fitting its own
sightings: :func:`half_turn_test` tests the fleet's masks at once for that, and a frame
it rejects is not planned on (:mod:`fleet_frame`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from agent.core.formation.frame import robust_lm
from agent.core.formation.frame.poses import (
    PoseFrame,
    PoseMeasurement,
    _Problem,
    fit_cost,
    fit_poses,
)
from agent.core.formation.frame.records import NeighborRecord
from agent.core.perception.sighting_noise import SightingNoise

#: Two costs within this fraction of each other are a tie (the first start is kept): two
#: starts that reach the same minimum agree far closer (the fit stops when a step lowers
#: the cost by less than ``robust_lm.FTOL``, 1e-12, of it).
TIE = 1e-6


def better(a: PoseFrame, b: PoseFrame) -> PoseFrame:
    """``b`` if its cost is lower than ``a``'s beyond :data:`TIE`, else ``a``: two fits
    of the same measurements in the same robot's frame (the soft-L1 loss acts per axis,
    so the cost of the same poses moves slightly with the frame)."""
    ca, cb = fit_cost(a), fit_cost(b)
    return b if cb < ca - TIE * max(ca, 1e-12) else a


def in_frame_of(
    poses: PoseFrame, ids: tuple[int, ...], frame: int
) -> tuple[np.ndarray, np.ndarray]:
    """Poses of ``ids`` (ascending) re-expressed in ``frame``'s fixed frame: a start."""
    k = poses.ids.index(frame)
    c, s = math.cos(-poses.headings[k]), math.sin(-poses.headings[k])
    rows = [poses.ids.index(i) for i in ids]
    rel = poses.positions[rows] - poses.positions[k]
    pos = np.stack([c * rel[:, 0] - s * rel[:, 1], s * rel[:, 0] + c * rel[:, 1]], axis=1)
    psi = np.asarray((poses.headings[rows] - poses.headings[k] + math.pi) % (2 * math.pi) - math.pi)
    return pos, psi


def refit(
    poses: PoseFrame, ids: Sequence[int], keep: Sequence[PoseMeasurement]
) -> PoseFrame | None:
    """The robust fit again over ``ids`` and the measurements ``keep``: from the spanning
    tree and from the current poses, the better of the two (module docstring); None when
    they no longer connect at least two robots."""
    rid = tuple(sorted(ids))
    if len(rid) < 2:
        return None
    try:
        first = fit_poses(rid, keep)  # validates, and picks the frame robot
        warm = fit_poses(rid, keep, first.frame_robot, in_frame_of(poses, rid, first.frame_robot))
    except ValueError:
        return None
    return better(warm, first)


def half_turned(poses: PoseFrame, robot: int) -> PoseFrame | None:
    """The fit again from ``poses`` with ``robot`` turned half round where it stands, when
    it fits better than ``poses`` (module docstring), else None. ``poses`` must be a fit
    of their own measurements (:func:`poses.fit_poses`): a minimum of the cost to compare
    with. Turning the frame robot (held at ψ = 0) is turning every other robot half round
    about it.

    Raises
    ------
    ValueError
        ``robot`` has no pose in ``poses``.
    """
    if robot not in poses.ids:
        raise ValueError(f"robot {robot} is not among {list(poses.ids)}")
    if not _turn_helps(poses, robot):
        return None
    pos = poses.positions.copy()
    psi = poses.headings.copy()
    if robot == poses.frame_robot:
        pos, psi = -pos, psi + math.pi
        psi[poses.ids.index(robot)] = 0.0
    else:
        psi[poses.ids.index(robot)] += math.pi
    psi = (psi + math.pi) % (2 * math.pi) - math.pi
    try:
        turned = fit_poses(poses.ids, poses.measurements, poses.frame_robot, (pos, psi))
    except ValueError:
        return None
    best = better(poses, turned)
    return None if best is poses else best


def _turn_helps(poses: PoseFrame, robot: int) -> bool:
    """Whether ``robot``, turned half round and its pose alone fitted again (the others
    held at ``poses``), fits its own sightings and the others' sightings of it better
    than where it stands (the soft-L1 cost of the fit, over its sightings; ``poses`` is a
    minimum of it): a robot held half a turn off by its own position misfits fits them
    better turned, whatever its neighbours. Only then is the whole fleet fitted again
    from the turned start (at 50 NAOs ~0.2 CPU s a fit, this some 10 ms)."""
    if robot == poses.frame_robot:
        return True  # every other robot turns about it: only the whole fit can tell
    k = poses.ids.index(robot)
    mine = [m for m in poses.measurements if robot in (m.owner, m.target)]
    if not mine:
        return False
    prob = _Problem(poses.ids, mine, poses.ids.index(poses.frame_robot))
    x = prob.pack(poses.positions, poses.headings)
    c = int(prob.col[k])
    here = robust_lm.soft_l1_cost(prob.fun(x))  # a minimum already: the fit's
    return _alone(prob, x, c, k, math.pi) < here - TIE * max(here, 1e-12)


#: Levenberg-Marquardt steps of one robot's pose at most, and the relative decrease of
#: its cost below which it stops (the screen compares two such fits, no more).
ALONE_ITER = 60
ALONE_FTOL = 1e-10


def _alone(prob: _Problem, x: np.ndarray, c: int, k: int, turn: float) -> float:
    """The soft-L1 cost of ``prob`` (one robot's sightings) at the pose of robot ``k``
    (columns ``c``..``c + 2`` of ``x``) that fits them best from its pose turned by
    ``turn``, the others held: Levenberg-Marquardt on three unknowns (as
    :func:`robust_lm.minimise`, with its Newton steps near the minimum, the residuals'
    curvature in ψ alone as :meth:`poses._Problem.curvature` gives it; its normal
    equations dense: each entry the sum of one contiguous row of products, as ``np.sum``
    of that row alone adds it)."""
    m = prob.m
    sign = (prob.t == k).astype(np.float64) - (prob.o == k)  # +1 target, -1 owner
    owner = prob.o == k
    vx, vy = prob.v[:, 0], prob.v[:, 1]
    # the Jacobian's columns as rows: d/dx, d/dy, d/dψ of every residual
    jt = np.zeros((3, 3 * m))
    jt[0, 0 : 2 * m : 2] = sign * prob.sp
    jt[1, 1 : 2 * m : 2] = sign * prob.sp

    def fun(y: np.ndarray) -> np.ndarray:
        z = x.copy()
        z[c : c + 3] = y
        return prob.fun(z)

    def jac(y: np.ndarray) -> np.ndarray:
        _, psi = prob.unpack(np.concatenate([x[:c], y, x[c + 3 :]]))
        cs, sn = math.cos(float(y[2])), math.sin(float(y[2]))
        delta = psi[prob.t] - psi[prob.o] - prob.mask_ref
        jt[2, 0 : 2 * m : 2] = np.where(owner, (sn * vx + cs * vy) * prob.sp, 0.0)
        jt[2, 1 : 2 * m : 2] = np.where(owner, -(cs * vx - sn * vy) * prob.sp, 0.0)
        jt[2, 2 * m :] = sign * prob.sm * np.cos(2.0 * delta)
        return jt

    def bend(y: np.ndarray, u: np.ndarray) -> float:
        """``Σ u_k ∂²f_k/∂ψ²`` (:meth:`_Problem.curvature`'s, robot k's ψ alone)."""
        cs, sn = math.cos(float(y[2])), math.sin(float(y[2]))
        pos = u[0 : 2 * m : 2] * (cs * vx - sn * vy) + u[1 : 2 * m : 2] * (sn * vx + cs * vy)
        mask = -4.0 * u[2 * m :] * f[2 * m :]
        return float(np.sum(np.where(owner, pos * prob.sp, 0.0)) + np.sum(mask))

    def step_of(a: np.ndarray, g: np.ndarray) -> np.ndarray | None:
        """The step −a⁻¹·g; None when ``a`` is singular."""
        try:
            return np.asarray(-np.linalg.solve(a, g))
        except np.linalg.LinAlgError:
            return None

    def lowered(step: np.ndarray) -> tuple[np.ndarray, float] | None:
        """The residuals and cost at ``y + step`` when it lowers the cost, else None."""
        f_new = fun(y + step)
        cost_new = robust_lm.soft_l1_cost(f_new)
        return (f_new, cost_new) if cost_new < cost else None

    y = x[c : c + 3] + np.array([0.0, 0.0, turn])
    f = fun(y)
    cost = robust_lm.soft_l1_cost(f)
    lam = robust_lm.LAMBDA0
    near, switch = False, robust_lm.NEAR  # Newton's steps near the minimum, as minimise's
    for _ in range(ALONE_ITER):
        j = jac(y)
        w = 1.0 / np.sqrt(1.0 + f * f)
        jw = j / np.sqrt(1.0 + f * f)[None, :]
        h = (jw[:, None, :] * j[None, :, :]).sum(axis=-1)
        g = (jw * f).sum(axis=-1)
        if near:
            jw3 = j * (w * w * w)[None, :]
            exact = (jw3[:, None, :] * j[None, :, :]).sum(axis=-1)
            exact[2, 2] += bend(y, w * f)
            step = step_of(exact, g)
            if step is not None:
                better = lowered(step)
                if better is not None:
                    small = cost - better[1] <= ALONE_FTOL * cost
                    near = cost - better[1] <= switch * cost
                    y, (f, cost) = y + step, better
                    if small:
                        break
                    continue
                if 0.0 < -0.5 * float(np.sum(g * step)) <= ALONE_FTOL * cost:
                    break  # the model's decrease is below the rounding of the cost
            near, switch = False, switch * robust_lm.NEAR_TIGHTEN
        d = np.maximum(np.diag(h), 1e-12)
        while True:
            step = step_of(h + np.diag(lam * d), g)
            better = None if step is None else lowered(step)
            if step is not None and better is not None:
                small = cost - better[1] <= ALONE_FTOL * cost
                near = cost - better[1] <= switch * cost
                y, (f, cost) = y + step, better
                lam = max(lam / 3.0, 1e-12)
                break
            lam *= 4.0
            if lam > robust_lm.LAMBDA_MAX:
                return cost
        if small:
            break
    return cost


@dataclass(frozen=True)
class HalfTurn:
    """The joint test of the fleet's masks (:func:`half_turn_test`): the robots the masks
    would rather see turned half round (the side of the split without the frame robot;
    none: no split fits them better), ``log L_S`` of that alternative and its p-value
    ``min(1, 1/(w_S·L_S))``."""

    robots: tuple[int, ...]
    log_ratio: float
    p: float

    def describe(self) -> str:
        return (f"robots {list(self.robots)} read half a turn off by the others' masks "
                f"(log L {self.log_ratio:.1f}, p {self.p:.1e})")  # fmt: skip


def half_turn_test(
    poses: PoseFrame, noise: SightingNoise, records: Sequence[NeighborRecord]
) -> HalfTurn:
    """Whether the masks of several robots together say that some of them stand half a
    turn off in ``poses`` (docs/design.md §9): the test of all masks at once that no
    robot's own test makes, since each mask off by π is alone a front/back confusion.

    A mask turned back to its target's start heading (its owner's record carries
    ``seen_at`` and its target's ``stances``: :func:`records.mask_orientation`) misses
    ψ_t − ψ_o by ``δ = ψ_t − ψ_o − (β + θ − π/2)`` modulo 2π, and reads its target the
    other way round (|δ| > π/2) with probability ``q_k = noise.reversal(view_k)`` when the
    frame is right, q_k set by what the mask read (its target from the front or from
    behind: :meth:`SightingNoise.reversal`), independently of the other masks given their
    readings. Turning a set S of robots half round changes only the masks between S and
    the rest, each by π, so its likelihood ratio is ``L_S = Π_k ((1 − q_k)/q_k)^(±1)``
    over those masks, + for a mask read the other way round in the frame, − for one read
    the right way; each factor has expectation 1 when the frame is right, so L_S has too.
    Each S (the frame robot outside it, 1 ≤ |S| ≤ n − 1) gets the
    weight ``w_S = 1 / ((n − 1)·C(n − 1, |S|))``, so ``Σ_S w_S·L_S`` has expectation 1 when
    the frame is right and exceeds 1/α with probability at most α (Markov's inequality);
    ``w_S·L_S ≥ 1/α`` for one S implies it, so the p-value ``1/(w_S·L_S)`` of any S is
    valid, whichever way S is found. S is sought by local search over the splits
    (toggle the robot that gains most, tie: the lowest id, while one gains), from no
    split and from each robot alone; the best S visited is kept (tie: the first). Masks
    of records without times are left out (their target may have turned half round in
    its own search; so are those of a record with no stances). A mask whose rate is ½
    weighs nothing, one above ½ counts against the split it crosses the other way round;
    rates are clipped away from 0 and 1 (:meth:`SightingNoise.reversal`), so every weight
    is finite. Deterministic: the masks' log ratios summed in the order of the
    measurements, robots in ascending id."""
    ids, n = poses.ids, len(poses.ids)
    none = HalfTurn((), 0.0, 1.0)
    if n < 2:
        return none
    index = {rid: k for k, rid in enumerate(ids)}
    recs = {r.robot_id: r for r in records}
    # log((1 − q)/q) of a mask the other way round, its negative for one the right way
    votes = np.zeros((n, n), dtype=np.float64)
    for m in poses.measurements:
        owner, target = recs.get(m.owner), recs.get(m.target)
        if owner is None or owner.seen_at is None or target is None:
            continue
        if target.stances is None or not len(target.stances) or not math.isfinite(m.orientation):
            continue  # as recorded (no stances: records.heading_at), or none
        o, t = index[m.owner], index[m.target]
        ref = math.atan2(float(m.vector[1]), float(m.vector[0])) + m.orientation - math.pi / 2
        miss = math.remainder(float(poses.headings[t] - poses.headings[o]) - ref, 2 * math.pi)
        q = noise.reversal(m.view)
        vote = math.log((1.0 - q) / q) * (1.0 if abs(miss) > math.pi / 2 else -1.0)
        votes[o, t] += vote
        votes[t, o] += vote
    if not votes.any():
        return none
    anchor = ids.index(poses.frame_robot)
    best, score = none, 0.0  # score: log(w_S·L_S) of the best S
    for start in range(-1, n):
        side = np.ones(n, dtype=np.int64)  # ±1: the two sides of the split
        if start >= 0:
            side[start] = -1
        while True:
            turned = side != side[anchor]
            size = int(turned.sum())
            cut = float(votes[np.ix_(turned, ~turned)].sum())  # log L_S
            # log(1/w_S) = log((n − 1)·C(n − 1, |S|))
            log_w = math.log(n - 1) + math.lgamma(n) - math.lgamma(size + 1)
            log_w -= math.lgamma(n - size)
            if size and cut - log_w > score:
                score = cut - log_w
                robots = tuple(i for i, x in zip(ids, turned, strict=True) if x)
                best = HalfTurn(robots, cut, math.exp(-score))
            toggle = side * (votes @ side)  # what toggling each robot adds to log L_S
            k = int(np.argmax(toggle))
            if toggle[k] <= 0:
                break
            side[k] = -side[k]
    return best
