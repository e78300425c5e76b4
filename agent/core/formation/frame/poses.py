"""Poses (x, y, ψ) of every robot in the common frame, without the papers' alignment
(docs/design.md §9; generalises NAO paper 4.1.3 eq. 10 and the least-squares variant of
:mod:`common_frame`).

Robot i's fixed frame is its own start pose: a point ``v`` of i's fixed frame is
``p_i + R(ψ_i) v`` in the common frame, the fixed frame of the *frame robot* (most
mutual pairs, tie: lowest id; ``p = 0``, ``ψ = 0``). The measurements
(:class:`PoseMeasurement`) are the sightings of the pairs of
:func:`pose_pairing.identify_pairs` (both directions) and the one-way sightings that,
placed from their owner's pose, fall within ε of exactly one robot. Each gives

* a position residual ``(p_j − p_i − R(ψ_i) v_ij)·√w / σ(d)``, ``σ(d) = σ₀ + σ₁·d``
  (:data:`SIGMA_POS`, :data:`SIGMA_REL`; ``w`` the confidence λ, 1 if unknown); the two
  sightings of a mutual pair together fix ψ_j − ψ_i = β_ij − β_ji + π, so the bearings'
  relative heading is in the fit through them and is not counted a second time;
* with a mask orientation θ, a heading residual ``√w · sin(2δ) / (2σ_m)``,
  ``δ = ψ_j − ψ_i − (β_ij + θ_ij − π/2)``: the mask's estimate modulo π
  (:func:`pose_pairing.mask_relative_heading`), weak (:data:`SIGMA_MASK`).

Robust least squares (soft-L1 loss, :func:`robust_lm.minimise`: Levenberg–Marquardt on
the sparse normal equations, with the analytic sparse Jacobian, Newton steps near the
minimum (the residuals' curvature: :meth:`_Problem.curvature`), fixed tolerances and a
fixed budget), started from the spanning tree: breadth-first from the frame robot
over mutual pairs, neighbours in ascending id, ``ψ_v = ψ_u + (β_uv − β_vu + π)``,
``p_v = p_u + R(ψ_u) v_uv``. No randomness: every agent gets bit-identical poses from the
same records (canonical order, :mod:`records`). One-way sightings are attached after a
first fit, and the fit runs once more from its poses (the start nearest the minimum).

**Aligned starts stay exactly as good as today.** The papers' model —
:func:`neighbour_check.identify_neighbours` + :func:`common_frame.lsq_positions`, ψ ≡ 0 —
is returned *exactly* (``aligned=True``, ψ = 0, its pairs' sightings as the
measurements) when it is connected and explains its pairs' sightings within the
consistency tolerances, and the unaligned fit is not a consistent alternative: it failed
(not connected), is inconsistent, or puts every |ψ| within :data:`ALIGNED_MAX_HEADING`.
So a robot turned by less than that at the start is treated as aligned, as today.

Residuals: per pair, the sum over its sightings of the position misfit (m) and the
largest mask misfit (rad, modulo π); its *score* is position / (:data:`POS_TOL` +
:data:`POS_TOL_REL`·d) (> 1: the pair is inconsistent); a robot's score is the median of
its pairs' scores. A single mask misfit does not make a pair inconsistent: wrong mask
matches are common (up to 90° in the simulator's 10-NAO runs, where the fit's ψ are right
to 2°). What masks do reveal is a robot whose estimated ψ is wrong as a whole (a record
turned by a broken compass: its own positions fit, ψ absorbs the turn): the others' masks
of it then agree on one offset (:func:`mask_offset`). The fleet is consistent when no pair
scores above 1 and no robot is *turned*; :mod:`fault_test` names a faulty robot.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy.sparse import coo_matrix, csc_matrix, csr_matrix
from scipy.spatial import cKDTree

from agent.core.formation.frame import robust_lm
from agent.core.formation.frame.common_frame import build_common_frame
from agent.core.formation.frame.neighbour_check import (
    DEFAULT_EPSILON,
    NeighbourGraph,
    identify_neighbours,
)
from agent.core.formation.frame.pose_pairing import (
    identify_pairs,
    mask_offset,
    wrap_angle,
    wrap_half,
)
from agent.core.formation.frame.records import NeighborRecord, mask_orientation, mask_view

SIGMA_POS = 0.05  #: σ₀ (m) of a sighting's position
SIGMA_REL = 0.05  #: σ₁: σ per metre of distance (±5 % distance, ±3° bearing)
SIGMA_MASK = math.radians(15.0)  #: σ_m of a mask's relative heading (5° masks, turned heads)
POS_TOL = 0.12  #: consistency: a pair's position misfit (m) allowed at distance 0 ...
POS_TOL_REL = 0.15  #: ... plus this per metre of distance
ALIGNED_MAX_HEADING = math.radians(10.0)  #: |ψ| within which the aligned model is kept
#: A robot is *turned* when the others' masks of it agree (within
#: :data:`pose_pairing.TURN_WINDOW`,
#: at least :data:`TURN_SIGHTINGS` of them and more than half) on an offset of its ψ of at
#: least this much. Measured on the simulator's runs: sound robots' offsets reach 29°
#: (masks biased as a whole, ψ right to 2°), a 40° broken compass shows 37-45°.
TURN_MIN = math.radians(33.0)
#: ... and at most this much: wrong mask matches cluster near ±90° (a NAO seen from the
#: side matched to a mask of its front or back), so an agreement there says nothing.
TURN_MAX = math.radians(65.0)
TURN_SIGHTINGS = 3  #: agreeing sightings (distinct owners) needed to call a robot turned
_TOL = 1e-12


@dataclass(frozen=True)
class PoseMeasurement:
    """One sighting: ``owner`` sees ``target`` at ``vector`` (owner's fixed frame)."""

    owner: int
    target: int
    vector: np.ndarray  # (2,)
    weight: float = 1.0  # confidence λ (1 if unknown)
    orientation: float = math.nan  # mask relative orientation θ (nan: none)
    mutual: bool = True  # part of a mutual pair (False: attached one-way sighting)
    view: float = math.nan  # θ as the camera read it, before the turn-back (nan: none)


@dataclass(frozen=True)
class PairResidual:
    """Misfit of every sighting between robots ``i < j`` at the estimated poses."""

    i: int
    j: int
    position: float  # m, sum over the pair's sightings
    heading: float  # rad, largest mask misfit modulo π (0 without masks)
    distance: float  # m, mean measured distance
    score: float  # position / (POS_TOL + POS_TOL_REL·d)


@dataclass(frozen=True)
class PoseFrame:
    """Every robot's start pose in the frame robot's fixed frame."""

    frame_robot: int
    ids: tuple[int, ...]  # ascending
    positions: np.ndarray  # (N, 2), row k is robot ids[k]; frame robot at (0, 0)
    headings: np.ndarray  # (N,) ψ in (−π, π]; frame robot 0
    scores: np.ndarray  # (N,) median score of each robot's pairs (0: no pair)
    pairs: tuple[PairResidual, ...]  # sorted by (i, j)
    measurements: tuple[PoseMeasurement, ...]
    aligned: bool  # True: the papers' aligned model (ψ ≡ 0) was kept, exactly
    #: robots whose ψ the others' masks agree is off (:func:`mask_offset`), ascending
    turned: tuple[int, ...] = ()

    @property
    def consistent(self) -> bool:
        """No pair scores above 1 and no robot is turned."""
        return not self.turned and all(p.score <= 1.0 for p in self.pairs)

    @property
    def positions_consistent(self) -> bool:
        """Every pair's sightings fit in position (masks aside)."""
        return all(p.position <= POS_TOL + POS_TOL_REL * p.distance for p in self.pairs)

    def to_common(self, robot_id: int, points: np.ndarray) -> np.ndarray:
        """Points (k, 2) of ``robot_id``'s fixed frame in the common frame."""
        if robot_id not in self.ids:
            raise ValueError(f"robot {robot_id} has no pose")
        k = self.ids.index(robot_id)
        pts = np.asarray(points, dtype=np.float64).reshape(-1, 2)
        return np.asarray(self.positions[k] + pts @ _rot(float(self.headings[k])).T)


def _rot(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s], [s, c]])


def pair_measurements(graph: NeighbourGraph) -> list[PoseMeasurement]:
    """Both sightings of every pair of ``graph``, as measurements, in pair order."""
    recs = {r.robot_id: r for r in graph.records}
    out: list[PoseMeasurement] = []
    for p in graph.pairs:
        for o, t, idx, v, w in ((p.i, p.j, p.a, p.v_ij, p.w_ij), (p.j, p.i, p.b, p.v_ji, p.w_ji)):
            theta, view = mask_orientation(recs[o], idx, recs.get(t)), mask_view(recs[o], idx)
            out.append(PoseMeasurement(o, t, np.array(v, dtype=np.float64), w, theta, True, view))
    return out


def choose_pose_frame_robot(ids: Sequence[int], measurements: Sequence[PoseMeasurement]) -> int:
    """The robot in the most mutual pairs; ties -> lowest id."""
    deg = dict.fromkeys(ids, 0)
    for m in measurements:
        if m.mutual:
            deg[m.owner] += 1
    best = max(deg.values())
    return min(i for i, d in deg.items() if d == best)


def _spanning_tree(
    ids: tuple[int, ...], measurements: Sequence[PoseMeasurement], frame: int
) -> tuple[np.ndarray, np.ndarray]:
    """Initial poses by breadth-first search over mutual pairs (ascending neighbour id)."""
    seen: dict[tuple[int, int], np.ndarray] = {}
    for m in measurements:
        if m.mutual:
            seen.setdefault((m.owner, m.target), m.vector)
    adj: dict[int, list[int]] = {i: [] for i in ids}
    for o, t in seen:
        if (t, o) in seen and o in adj and t in adj:
            adj[o].append(t)
    pose: dict[int, tuple[np.ndarray, float]] = {frame: (np.zeros(2), 0.0)}
    queue = deque([frame])
    while queue:
        u = queue.popleft()
        pu, hu = pose[u]
        for v in sorted(set(adj[u])):
            if v in pose:
                continue
            a, b = seen[(u, v)], seen[(v, u)]
            turn = math.atan2(a[1], a[0]) - math.atan2(b[1], b[0]) + math.pi
            pose[v] = (pu + _rot(hu) @ a, float(wrap_angle(hu + turn)))
            queue.append(v)
    missing = sorted(set(ids) - set(pose))
    if missing:
        isolated = [i for i in missing if not adj[i]]
        extra = f" ({len(isolated)} with no mutual pair: {isolated})" if isolated else ""
        raise ValueError(
            f"fleet not connected: robots {missing} cannot be reached from frame robot "
            f"{frame} through mutual pairs{extra}; they must search again"
        )
    return (
        np.array([pose[i][0] for i in ids], dtype=np.float64).reshape(-1, 2),
        np.array([pose[i][1] for i in ids], dtype=np.float64),
    )


class _Problem:
    """Residuals and Jacobian of the robust SE(2) fit (the frame robot held at 0)."""

    def __init__(
        self, ids: tuple[int, ...], measurements: Sequence[PoseMeasurement], anchor: int
    ) -> None:
        index = {rid: k for k, rid in enumerate(ids)}
        self.n = len(ids)
        self.anchor = anchor
        self.col = np.full(self.n, -1, dtype=np.int64)
        free = [k for k in range(self.n) if k != anchor]
        self.col[free] = 3 * np.arange(len(free))
        self.nvar = 3 * len(free)
        self.o = np.array([index[m.owner] for m in measurements], dtype=np.int64)
        self.t = np.array([index[m.target] for m in measurements], dtype=np.int64)
        self.v = np.array([m.vector for m in measurements], dtype=np.float64).reshape(-1, 2)
        w = np.sqrt(np.maximum([m.weight for m in measurements], 1e-6))
        d = np.hypot(self.v[:, 0], self.v[:, 1])
        self.sp = w / (SIGMA_POS + SIGMA_REL * d)
        theta = np.array([m.orientation for m in measurements], dtype=np.float64)
        self.has_mask = np.isfinite(theta)
        self.mask_ref = np.where(
            self.has_mask, np.arctan2(self.v[:, 1], self.v[:, 0]) + theta - np.pi / 2, 0.0
        )
        self.sm = np.where(self.has_mask, w / SIGMA_MASK, 0.0)
        self.m = len(measurements)
        self._layout: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
        self._vals = np.zeros(0)
        # where each measurement's owner and target read x, y and ψ in x with a 0 appended
        # (the frame robot's pose, held at 0, reads that 0): what :meth:`unpack` gives
        at = np.where(self.col >= 0, self.col, self.nvar)
        step = np.where(self.col >= 0, 1, 0)
        self._reads = tuple(
            np.ascontiguousarray((at + k * step)[idx]) for idx in (self.o, self.t) for k in range(3)
        )
        self._vx = np.ascontiguousarray(self.v[:, 0])
        self._vy = np.ascontiguousarray(self.v[:, 1])

    def unpack(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        pos = np.zeros((self.n, 2))
        psi = np.zeros(self.n)
        free = self.col >= 0
        c = self.col[free]
        pos[free, 0], pos[free, 1], psi[free] = x[c], x[c + 1], x[c + 2]
        return pos, psi

    def pack(self, pos: np.ndarray, psi: np.ndarray) -> np.ndarray:
        x = np.zeros(self.nvar)
        free = self.col >= 0
        c = self.col[free]
        x[c], x[c + 1], x[c + 2] = pos[free, 0], pos[free, 1], psi[free]
        return x

    def misfit(self, pos: np.ndarray, psi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Position misfit (m, 2) in metres and mask misfit δ (m,) in rad (modulo π)."""
        e = self._position_misfit(pos, psi)
        delta = np.where(self.has_mask, wrap_half(psi[self.t] - psi[self.o] - self.mask_ref), 0.0)
        return e, delta

    def _position_misfit(self, pos: np.ndarray, psi: np.ndarray) -> np.ndarray:
        c, s = np.cos(psi[self.o]), np.sin(psi[self.o])
        rv = np.stack([c * self.v[:, 0] - s * self.v[:, 1], s * self.v[:, 0] + c * self.v[:, 1]], 1)
        return np.asarray(pos[self.t] - pos[self.o] - rv)

    def fun(self, x: np.ndarray) -> np.ndarray:
        """The residuals: each sighting's position misfit (x, y) times its weight, then
        each mask's. The floats of ``pos[t] − pos[o] − R(ψ_o)v`` at :meth:`unpack`'s
        poses, read from ``x`` directly."""
        xe = np.empty(self.nvar + 1)
        xe[:-1] = x
        xe[-1] = 0.0
        xo, yo, po, xt, yt, pt = (xe[r] for r in self._reads)
        c, s = np.cos(po), np.sin(po)
        m = self.m
        out = np.empty(3 * m)
        out[0 : 2 * m : 2] = ((xt - xo) - (c * self._vx - s * self._vy)) * self.sp
        out[1 : 2 * m : 2] = ((yt - yo) - (s * self._vx + c * self._vy)) * self.sp
        out[2 * m :] = self.sm * np.sin(2.0 * (pt - po - self.mask_ref)) / 2.0
        return out

    def jac(self, x: np.ndarray) -> csr_matrix:
        """The Jacobian, sparse: each sighting touches its two robots' columns only."""
        xe = np.empty(self.nvar + 1)
        xe[:-1] = x
        xe[-1] = 0.0
        po, pt = xe[self._reads[2]], xe[self._reads[5]]
        c, s = np.cos(po), np.sin(po)
        m = self.m
        if self._layout is None:
            self._layout = self._jac_layout(self.col[self.o], self.col[self.t])
            # the values the layout takes: 1·sp twice, dm, −1·sp twice, −1·dm, then the
            # ψ derivatives; those of sp stay
            self._vals = np.concatenate([1.0 * self.sp, 1.0 * self.sp, np.zeros(m),
                                         -1.0 * self.sp, -1.0 * self.sp, np.zeros(3 * m)])  # fmt: skip
        vals = self._vals
        # d(R(ψ)v)/dψ = [-s vx - c vy, c vx - s vy]
        vals[6 * m : 7 * m] = -(-s * self._vx - c * self._vy) * self.sp
        vals[7 * m :] = -(c * self._vx - s * self._vy) * self.sp
        dm = self.sm * np.cos(2.0 * (pt - po - self.mask_ref))
        vals[2 * m : 3 * m] = dm
        vals[5 * m : 6 * m] = -1.0 * dm
        take, cols, indptr = self._layout
        out = csr_matrix((vals[take], cols.copy(), indptr.copy()), shape=(3 * self.m, self.nvar))
        out.has_canonical_format = True  # sorted, no duplicates: as tocsr() leaves it
        return out

    def curvature(self, x: np.ndarray, u: np.ndarray) -> csc_matrix:
        """``Σ_k u_k ∇²f_k`` at ``x`` (the Newton term of :func:`robust_lm.minimise`): a
        position residual bends in its owner's ψ alone (``∂²/∂ψ_o²`` of ``−R(ψ_o)v·sp``
        is ``R(ψ_o)v·sp``), a mask residual ``sm·sin(2δ)/2`` in δ = ψ_t − ψ_o − ref
        (second derivative −4 times itself)."""
        xe = np.append(x, 0.0)
        po, pt = xe[self._reads[2]], xe[self._reads[5]]
        c, s, m = np.cos(po), np.sin(po), self.m
        bend = (u[0 : 2 * m : 2] * (c * self._vx - s * self._vy) + u[1 : 2 * m : 2]
                * (s * self._vx + c * self._vy)) * self.sp  # fmt: skip
        mask = -4.0 * u[2 * m :] * (self.sm * np.sin(2.0 * (pt - po - self.mask_ref)) / 2.0)
        co, ct = self.col[self.o] + 2, self.col[self.t] + 2  # the ψ columns (1: none)
        rows = np.concatenate([co, ct, co, ct])
        cols = np.concatenate([co, ct, ct, co])
        vals = np.concatenate([bend + mask, mask, -mask, -mask])
        keep = (rows >= 2) & (cols >= 2)
        shape = (self.nvar, self.nvar)
        return coo_matrix((vals[keep], (rows[keep], cols[keep])), shape=shape).tocsc()

    def _jac_layout(
        self, co: np.ndarray, ct: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Where the Jacobian's entries go, the same at every x: which of the values
        :meth:`jac` lists are kept, in CSR order, their columns and the row pointers."""
        rows = np.arange(self.m)
        # (row, column, value) of every entry, as three per row at most: each sighting's
        # position rows touch both robots' columns and the owner's ψ, its mask row both ψ
        rows = np.concatenate([2 * rows, 2 * rows + 1, 2 * self.m + rows] * 2
                              + [2 * rows, 2 * rows + 1])  # fmt: skip
        cols = np.concatenate([ct, ct + 1, ct + 2, co, co + 1, co + 2, co + 2, co + 2])
        have = np.flatnonzero(np.concatenate([ct >= 0] * 3 + [co >= 0] * 5))
        rows, cols = rows[have], cols[have]
        # as ``coo_matrix(...).tocsr()`` gives it: rows in order, columns ascending in each
        order = np.argsort(rows * self.nvar + cols, kind="stable")
        indptr = np.zeros(3 * self.m + 1, dtype=np.int32)
        np.cumsum(np.bincount(rows, minlength=3 * self.m), out=indptr[1:])
        return have[order], cols[order].astype(np.int32), indptr


def _residuals(
    ids: tuple[int, ...],
    measurements: Sequence[PoseMeasurement],
    pos: np.ndarray,
    psi: np.ndarray,
) -> tuple[tuple[PairResidual, ...], np.ndarray]:
    """Per-pair residuals and per-robot scores at the given poses."""
    if not measurements:
        return (), np.zeros(len(ids))
    prob = _Problem(ids, measurements, 0)
    e, delta = prob.misfit(pos, psi)
    err = np.hypot(e[:, 0], e[:, 1])
    dist = np.hypot(prob.v[:, 0], prob.v[:, 1])
    acc: dict[tuple[int, int], list[tuple[float, float, float]]] = {}
    for m, e, dl, d in zip(measurements, err.tolist(), delta.tolist(), dist.tolist(), strict=True):
        key = (min(m.owner, m.target), max(m.owner, m.target))
        acc.setdefault(key, []).append((e, abs(dl), d))
    pairs = []
    for (i, j), vals in sorted(acc.items()):
        position = math.fsum(v[0] for v in vals)
        heading = max(v[1] for v in vals)
        d = math.fsum(v[2] for v in vals) / len(vals)
        score = position / (POS_TOL + POS_TOL_REL * d)
        pairs.append(PairResidual(i, j, position, heading, d, score))
    per: dict[int, list[float]] = {i: [] for i in ids}
    for p in pairs:
        per[p.i].append(p.score)
        per[p.j].append(p.score)
    scores = np.array([float(np.median(per[i])) if per[i] else 0.0 for i in ids])
    return tuple(pairs), scores


def turn_offsets(
    ids: tuple[int, ...], measurements: Sequence[PoseMeasurement], psi: np.ndarray
) -> dict[int, float]:
    """Robots whose ψ the others' masks agree is off by :data:`TURN_MIN` to :data:`TURN_MAX`,
    with that offset (rad, modulo π: :func:`mask_offset`), by ascending id."""
    index = {rid: k for k, rid in enumerate(ids)}
    masked = [m for m in sorted(measurements, key=lambda m: (m.target, m.owner))
              if math.isfinite(m.orientation)]  # fmt: skip
    ref = [math.atan2(float(m.vector[1]), float(m.vector[0])) + m.orientation - math.pi / 2
           for m in masked]  # fmt: skip
    t = np.array([index[m.target] for m in masked], dtype=np.intp)
    o = np.array([index[m.owner] for m in masked], dtype=np.intp)
    head = np.asarray(psi, dtype=np.float64)
    seen: dict[int, list[float]] = {}
    for m, delta in zip(masked, wrap_half(head[t] - head[o] - np.array(ref)).tolist(), strict=True):
        seen.setdefault(m.target, []).append(delta)
    out = {}
    for rid, deltas in sorted(seen.items()):
        offset, count = mask_offset(deltas)
        agreed = count >= TURN_SIGHTINGS and 2 * count > len(deltas)
        if agreed and TURN_MIN <= abs(offset) <= TURN_MAX:
            out[rid] = offset
    return out


def turned_robots(
    ids: tuple[int, ...], measurements: Sequence[PoseMeasurement], psi: np.ndarray
) -> tuple[int, ...]:
    """Robots whose ψ the others' masks agree is off by :data:`TURN_MIN` to :data:`TURN_MAX`."""
    return tuple(turn_offsets(ids, measurements, psi))


def evaluate_poses(
    ids: tuple[int, ...],
    measurements: Sequence[PoseMeasurement],
    positions: np.ndarray,
    headings: np.ndarray,
    frame_robot: int,
    aligned: bool = False,
) -> PoseFrame:
    """A :class:`PoseFrame` of given poses with its residuals (no fitting)."""
    pos = np.asarray(positions, dtype=np.float64).reshape(len(ids), 2)
    psi = np.asarray(headings, dtype=np.float64).reshape(len(ids))
    pairs, scores = _residuals(ids, measurements, pos, psi)
    turned = turned_robots(ids, measurements, psi)
    meas = tuple(measurements)
    return PoseFrame(frame_robot, ids, pos, psi, scores, pairs, meas, aligned, turned)


def fit_poses(
    ids: Sequence[int],
    measurements: Sequence[PoseMeasurement],
    frame_robot: int | None = None,
    start: tuple[np.ndarray, np.ndarray] | None = None,
) -> PoseFrame:
    """Robust SE(2) least squares over ``measurements`` (see the module docstring).

    Parameters
    ----------
    ids : sequence of int
        The robots to place (sorted here); every measurement must name two of them.
    measurements : sequence of PoseMeasurement
        Sightings; the mutual ones must connect every robot to the frame robot.
    frame_robot : int, optional
        Defaults to :func:`choose_pose_frame_robot`.
    start : (positions (N, 2), headings (N,)), optional
        Initial poses in ascending id order, in the frame robot's frame (default: the
        spanning tree over mutual pairs, which must then connect every robot).

    Raises
    ------
    ValueError
        No robots, duplicate ids, a measurement naming an unknown robot or itself, or a
        fleet that the mutual pairs do not connect (the message names the robots).
    """
    rid = tuple(sorted(int(i) for i in ids))
    if not rid:
        raise ValueError("no robots to place")
    if len(set(rid)) != len(rid):
        raise ValueError(f"duplicate robot ids in {list(rid)}")
    known = set(rid)
    for m in measurements:
        if m.owner not in known or m.target not in known:
            raise ValueError(
                f"measurement {m.owner} -> {m.target} names a robot not in {list(rid)}"
            )
        if m.owner == m.target:
            raise ValueError(f"robot {m.owner} cannot see itself")
    frame = choose_pose_frame_robot(rid, measurements) if frame_robot is None else frame_robot
    if frame not in known:
        raise ValueError(f"frame robot {frame} is not among {list(rid)}")
    if start is None:
        pos0, psi0 = _spanning_tree(rid, measurements, frame)
    else:
        pos0 = np.array(start[0], dtype=np.float64).reshape(len(rid), 2)
        psi0 = np.array(start[1], dtype=np.float64).reshape(len(rid))
    anchor = rid.index(frame)
    prob = _Problem(rid, measurements, anchor)
    if prob.nvar and prob.m:
        x, _ = robust_lm.minimise(prob.fun, prob.jac, prob.pack(pos0, psi0), prob.curvature)
        pos, psi = prob.unpack(x)
    else:
        pos, psi = pos0, psi0
    return evaluate_poses(rid, measurements, pos, wrap_angle(psi), frame)


def fit_cost(poses: PoseFrame) -> float:
    """The objective of :func:`fit_poses` (its soft-L1 cost) at ``poses``, over their
    measurements: of two fits of the same measurements, the lower is the better estimate."""
    prob = _Problem(poses.ids, poses.measurements, poses.ids.index(poses.frame_robot))
    if not prob.m:
        return 0.0
    return robust_lm.soft_l1_cost(prob.fun(prob.pack(poses.positions, poses.headings)))


def one_way_measurements(graph: NeighbourGraph, frame: PoseFrame) -> list[PoseMeasurement]:
    """Unpaired sightings that, placed from their owner's pose, fall within ε of exactly one
    other robot not yet linked to the owner (as :func:`common_frame.lsq_positions`)."""
    if len(frame.ids) < 2:
        return []
    index = {rid: k for k, rid in enumerate(frame.ids)}
    linked = {(m.owner, m.target) for m in frame.measurements}
    tree = cKDTree(frame.positions)
    recs = {r.robot_id: r for r in graph.records}
    out: list[PoseMeasurement] = []
    for rid, a in graph.unidentified():
        if rid not in index:
            continue
        rec = recs[rid]
        guess = frame.to_common(rid, rec.neighbours[a])[0]
        hits = [h for h in sorted(tree.query_ball_point(guess, graph.epsilon)) if h != index[rid]]
        if len(hits) != 1 or (rid, frame.ids[hits[0]]) in linked:
            continue
        w = 1.0 if rec.confidences is None else float(rec.confidences[a])
        target = frame.ids[hits[0]]
        theta, view = mask_orientation(rec, a, recs.get(target)), mask_view(rec, a)
        out.append(PoseMeasurement(rid, target, rec.neighbours[a].copy(), w, theta, False, view))
        linked.add((rid, target))
    return out


def build_poses(records: Sequence[NeighborRecord], epsilon: float = DEFAULT_EPSILON) -> PoseFrame:
    """Pairing (:func:`pose_pairing.identify_pairs`) + robust SE(2) fit of a record set.

    Parameters
    ----------
    records : sequence of NeighborRecord
        One per robot, any order; the output is bit-identical for any order.
    epsilon : float
        ε of eq. 9 (m), for pairing and for attaching one-way sightings.

    Returns
    -------
    PoseFrame
        Poses in the frame robot's fixed frame; exactly the papers' aligned result when
        that model explains the records (module docstring).

    Raises
    ------
    ValueError
        Bad records or ε (see :func:`identify_pairs`), or a fleet the mutual pairs do not
        connect (the message names the unreachable robots).
    """
    graph = identify_pairs(records, epsilon)
    return poses_from_graph(graph, records)


def fit_from_graph(graph: NeighbourGraph) -> PoseFrame:
    """The robust SE(2) fit of a pairing's sightings, the one-way sightings attached after a
    first fit (:func:`one_way_measurements`) and fitted again from it: never the aligned model.

    Raises ``ValueError`` as :func:`fit_poses` (a fleet the mutual pairs do not connect)."""
    meas = pair_measurements(graph)
    pf = fit_poses(graph.ids, meas)
    extra = one_way_measurements(graph, pf)
    start = (pf.positions, pf.headings)
    return fit_poses(graph.ids, [*meas, *extra], pf.frame_robot, start) if extra else pf


def poses_from_graph(graph: NeighbourGraph, records: Sequence[NeighborRecord]) -> PoseFrame:
    """:func:`build_poses` after the pairing (``records`` for the aligned model)."""
    aligned = _aligned_model(records, graph.epsilon)
    try:
        pf = fit_from_graph(graph)
    except ValueError:
        if aligned is None:
            raise
        return aligned
    if aligned is not None and (
        not pf.consistent or float(np.max(np.abs(pf.headings))) <= ALIGNED_MAX_HEADING
    ):
        return aligned
    return pf


def _aligned_model(records: Sequence[NeighborRecord], epsilon: float) -> PoseFrame | None:
    """Today's result (eq. 9 pairs + lsq, ψ ≡ 0) when it is connected and explains its
    own pairs' sightings within the consistency tolerances; else None."""
    today = identify_neighbours(records, epsilon)
    try:
        cf = build_common_frame(today, "lsq")
    except ValueError:
        return None
    cand = evaluate_poses(
        cf.ids, pair_measurements(today), cf.positions, np.zeros(len(cf.ids)), cf.frame_robot, True
    )
    return cand if cand.consistent else None
