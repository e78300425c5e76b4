"""The plan: from neighbour records to one safe plan of the formation's shape, the pyramid
by default (NAO paper 4.1-4.2, 5.2.2 (iii)).

Pipeline: neighbour check (Algorithm 2, eq. 9) -> common frame (eq. 10 or least
squares) -> pyramid frame (PCA eq. 12-13, or CP; a shape's frame, :mod:`layout`) ->
slots (AUV eqs. 5-7, or the shape's tree, ``PlanParams.shape``) ->
assignment (combined sub-groups + Lemma 1, exact, or bottleneck-bounded; compared by
:mod:`choice`) -> safe schedule (:mod:`scheduled`, :mod:`scheduler`: slot swaps and via
points until every close pair has a safe order under the rule of :mod:`safety`) ->
packing (:mod:`packing`: each robot starts once its own conflicts are clear) -> detours
that cut the critical chain (:mod:`detours`, small fleets) -> trajectories (η_i, d_i),
waves and ``after`` lists. The settings are :class:`params.PlanParams`. Whenever no
scheduled plan is found - and straight away above ``params.SCHEDULE_MAX_N`` robots - the
banded plan of :mod:`fallback`, which always exists, is used: a valid input never ends
in "no safe schedule" (obstacles aside: a robot walled in by obstacles has no safe path
at all). With obstacles, the ``near`` placement (:func:`obstacles.plan_near_obstacles`)
is tried first, the paper's 5.1.2 procedure (:func:`obstacles.plan_around_obstacles`)
after it (``PlanParams.obstacle_method``).

Execution (:mod:`execution`): a robot may start once every robot of its ``after`` list
has walked past the arc length of its path given in ``after_at`` (its release point,
:mod:`release`; its whole length: it holds its slot); waiting for every robot of every earlier ``wave`` is safe too (``after``
always points to earlier waves). The leader is in wave 0 (it starts at once), but not
necessarily alone.

Every quantity of a :class:`Plan` is in the *common frame* (the fixed frame of the frame
robot; :func:`plan_from_positions` uses the caller's frame and sets ``frame_robot=-1``).
``origin`` is o_p of eq. 13 (mean of the starts; moved with the pattern when obstacles
push it out). ``axis`` is the direction the pyramid faces (from the last layer toward the leader);
at the end every robot turns to face it. ``heading`` / ``distance`` describe the first
leg (to the first via point, or to the target); a robot already on its slot has
``distance == 0`` and ``heading == axis``.

The digest is sha256 over a canonical binary encoding (ids ascending, float64 bits),
so two agents holding the same record set compute bit-identical plans and digests. The
digest of a plan of any shape but the pyramid also covers the shape's own digest (the
pyramid's is the papers' plan's, as before shapes were data), so agents planning
different shapes never agree.
"""

from __future__ import annotations

import hashlib
import struct
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace

import numpy as np

from agent.core.formation.frame.common_frame import build_common_frame
from agent.core.formation.frame.fleet_frame import FleetFrame, fleet_frame
from agent.core.formation.frame.neighbour_check import identify_neighbours
from agent.core.formation.frame.records import NeighborRecord
from agent.core.formation.obstacle_map import common_frame_obstacles
from agent.core.formation.params import PlanParams
from agent.core.formation.paths.fallback import banded_plan
from agent.core.formation.shape.circle_pattern import circle
from agent.core.formation.shape.layout import shape_frame
from agent.core.formation.shape.pyramid import PyramidFrame
from agent.core.formation.shape.spec import PYRAMID, Shape
from agent.core.formation.waves.choice import choose, choose_anchored
from agent.core.formation.waves.obstacles import plan_around_obstacles, plan_near_obstacles
from agent.core.formation.waves.scheduled import Scheduled, scheduled_plan
from agent.core.perception.sighting_noise import SightingNoise


@dataclass(frozen=True)
class RobotPlan:
    robot_id: int
    start: np.ndarray  # (2,)
    target: np.ndarray  # (2,)
    order: int
    parent: int  # parent robot id, -1 for the leader
    heading: float  # η_i of the first leg, rad, CCW from +x of the common frame
    distance: float  # d_i of the first leg
    via: tuple[np.ndarray, ...] = ()
    wave: int = 0
    # robot ids (ascending) this robot waits for before it starts: the dependency rule of
    # :mod:`execution` (always in earlier waves)
    after: tuple[int, ...] = ()
    # per ``after`` entry, the arc length of that robot's path it must have walked past
    # (its release point, :mod:`release`); its whole length: it must hold its slot.
    # Empty: every entry must hold its slot (the rule before release points)
    after_at: tuple[float, ...] = ()

    def waypoints(self) -> list[np.ndarray]:
        return [*self.via, self.target]

    def path(self) -> np.ndarray:
        """(m, 2) polyline start, via..., target."""
        return np.vstack([self.start, *self.via, self.target])

    def length(self) -> float:
        return float(np.sum(np.hypot(*np.diff(self.path(), axis=0).T)))


@dataclass(frozen=True)
class Plan:
    frame_robot: int
    leader: int
    axis: float
    origin: np.ndarray
    robots: tuple[RobotPlan, ...]  # sorted by id
    waves: tuple[tuple[int, ...], ...]
    digest: str
    strategy: str = ""
    obstacles: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    #: (N,) ψ of each robot (``robots`` order): its fixed frame turned from the common
    #: frame (docs/design.md §9); empty: all 0 (the papers' aligned starts)
    psi: np.ndarray = field(default_factory=lambda: np.zeros(0))
    #: robots left out by the consistency check: they stand still, planned around
    excluded: tuple[int, ...] = ()
    #: the consistency check's verdict (empty for :func:`plan_from_positions`)
    verdict: str = ""

    def psi_of(self, robot_id: int) -> float:
        """ψ of a planned robot (0 for a plan without poses); ``ValueError`` if absent."""
        k = self.ids.index(robot_id) if robot_id in self.ids else -1
        if k < 0:
            raise ValueError(f"robot {robot_id} is not in the plan")
        return float(self.psi[k]) if len(self.psi) else 0.0

    def robot(self, robot_id: int) -> RobotPlan:
        for r in self.robots:
            if r.robot_id == robot_id:
                return r
        raise ValueError(f"robot {robot_id} is not in the plan")

    @property
    def ids(self) -> tuple[int, ...]:
        return tuple(r.robot_id for r in self.robots)

    def starts(self) -> np.ndarray:
        return np.array([r.start for r in self.robots])

    def targets(self) -> np.ndarray:
        return np.array([r.target for r in self.robots])

    def paths(self) -> list[np.ndarray]:
        return [r.path() for r in self.robots]

    def wave_of(self) -> np.ndarray:
        return np.array([r.wave for r in self.robots], dtype=np.int64)


def _check_positions(ids: Sequence[int], positions: np.ndarray) -> tuple[list[int], np.ndarray]:
    id_list = []
    for i in ids:
        if isinstance(i, bool) or not isinstance(i, int | np.integer) or int(i) < 0:
            raise ValueError(f"robot ids must be non-negative ints, got {i!r}")
        id_list.append(int(i))
    pos = np.asarray(positions, dtype=np.float64)
    if pos.ndim != 2 or pos.shape[1] != 2:
        raise ValueError(f"positions must have shape (N, 2), got {pos.shape}")
    if pos.shape[0] != len(id_list):
        raise ValueError(f"{len(id_list)} ids but {pos.shape[0]} positions")
    if not id_list:
        raise ValueError("no robots")
    if len(set(id_list)) != len(id_list):
        dup = sorted({i for i in id_list if id_list.count(i) > 1}) if len(id_list) < 5000 else []
        raise ValueError(f"duplicate robot ids {dup}")
    if not np.all(np.isfinite(pos)):
        raise ValueError("positions contain non-finite values")
    return id_list, pos


def _f(x: float) -> bytes:
    return struct.pack("<d", float(x))


def plan_digest(plan_fields: dict[str, object], robots: Sequence[RobotPlan]) -> str:
    """sha256 over a canonical encoding: the plan fields by name, then (robots in the
    given order, ascending id in a Plan) one little-endian record per robot (id, order,
    parent, wave, via count, after count as int64; start, target, heading, distance as
    float64), then every via point (float64 x, y), then every after id (int64), then
    every ``after_at`` arc length (float64; an empty ``after_at`` counts as zeros: no
    plan makes a zero release point)."""
    h = hashlib.sha256(b"nao-formation/plan/v3")
    for key in sorted(plan_fields):
        h.update(key.encode())
        v = plan_fields[key]
        if isinstance(v, float):
            h.update(_f(v))
        elif isinstance(v, np.ndarray):
            h.update(np.ascontiguousarray(v, dtype="<f8").tobytes())
        else:
            h.update(str(v).encode())
    m = len(robots)
    ints = np.array(
        [(r.robot_id, r.order, r.parent, r.wave, len(r.via), len(r.after)) for r in robots],
        dtype="<i8",
    ).reshape(m, 6)
    floats = np.empty((m, 6), dtype="<f8")
    if m:
        floats[:, 0:2] = np.array([r.start for r in robots], dtype=np.float64).reshape(m, 2)
        floats[:, 2:4] = np.array([r.target for r in robots], dtype=np.float64).reshape(m, 2)
        floats[:, 4] = [r.heading for r in robots]
        floats[:, 5] = [r.distance for r in robots]
    h.update(ints.tobytes())
    h.update(floats.tobytes())
    vias = [v for r in robots for v in r.via]
    h.update(np.array(vias, dtype="<f8").reshape(-1, 2).tobytes())
    h.update(np.array([j for r in robots for j in r.after], dtype="<i8").tobytes())
    at = [x for r in robots for x in (r.after_at or (0.0,) * len(r.after))]
    h.update(np.array(at, dtype="<f8").tobytes())
    return h.hexdigest()


def plan_from_positions(
    ids: Sequence[int],
    positions: np.ndarray,
    params: PlanParams = PlanParams(),
    obstacles: np.ndarray | None = None,
    frame_robot: int = -1,
    anchor: int | None = None,
) -> Plan:
    """Plan the shape of ``params`` (the pyramid by default) for robots at known
    positions (caller's frame).

    Wave 0 is the leader alone, unless the leader's slot lies within 2·radius of another
    robot's start: then the robots that must clear it go first (see :mod:`scheduler`).

    ``anchor``: a robot id that takes the shape's slot 0 where it stands and does not
    move; the shape frame's origin is its start, its axis the orientation's
    (:func:`choice.choose_anchored`; the circle pattern, AUV III.B.2.a). Raises
    ``ValueError`` for an anchor not among ``ids``, or no safe plan with it in place.
    """
    id_list, pos = _check_positions(ids, positions)
    order_idx = np.argsort(np.asarray(id_list), kind="stable")
    sorted_ids = [id_list[k] for k in order_idx]
    pos = pos[order_idx]
    obs = np.zeros((0, 2)) if obstacles is None else np.asarray(obstacles, dtype=np.float64)
    if obs.size == 0:
        obs = obs.reshape(0, 2)
    if obs.ndim != 2 or obs.shape[1] != 2 or not np.all(np.isfinite(obs)):
        raise ValueError(f"obstacles must be a finite (M, 2) array, got shape {obs.shape}")
    n = len(sorted_ids)
    strategy = params.resolved_strategy(n + obs.shape[0])
    if anchor is not None:
        if anchor not in sorted_ids:
            raise ValueError(f"anchor {anchor!r} is not one of the robots {sorted_ids}")
        row = sorted_ids.index(anchor)
        beta = shape_frame(pos, params.axis, params.shape).beta
        frame = PyramidFrame(origin=pos[row].copy(), beta=beta)
        frame_origin = frame.origin
        anchored = choose_anchored(pos, frame, row, obs, params)
        if anchored is None:
            raise ValueError(f"no safe plan with robot {anchor} holding slot 0 where it stands")
        best = anchored
    elif obs.shape[0]:
        if params.strategy == "banded":
            raise ValueError("strategy 'banded' takes no obstacles (see fallback)")
        near = None
        if params.obstacle_method != "paper":
            near = plan_near_obstacles(pos, obs, params, params.resolved_strategy(n))
            if near is None and params.obstacle_method == "near":
                raise ValueError("obstacles: no safe schedule for the near placement")
        if near is not None:
            best, frame_origin, beta = near
        else:
            op = plan_around_obstacles(pos, obs, params, strategy)
            frame_origin, beta = op.origin, op.beta
            best = scheduled_plan(pos, op.targets, op.order, op.vias, obs, params, strategy)
    else:
        frame = shape_frame(pos, params.axis, params.shape)
        starts_p = frame.to_pyramid(pos)
        frame_origin, beta = frame.origin, frame.beta
        chosen = choose(pos, frame, starts_p, params)
        if chosen is None:  # the plan that always exists (see fallback)
            bp = banded_plan(pos, frame, params.d_e, params.phi_e, params.radius, params.shape)
            frame_origin = bp.origin
            chosen = Scheduled(bp.order, bp.targets, bp.vias, bp.waves, bp.after, "banded")
        best = chosen
    strategy = best.strategy
    order, targets, vias_rows = best.order, best.targets, best.vias
    waves_rows, after_rows = best.waves, best.after
    # none (the banded plan): every robot waited for must hold its slot
    at_rows = best.after_at or tuple(() for _ in range(n))
    leader_row = int(np.flatnonzero(order == 0)[0])
    dense = np.unique(waves_rows, return_inverse=True)[1].reshape(-1)
    # first legs, vectorised: heading/distance of (first via or target) - start
    has_via = np.array([len(v) > 0 for v in vias_rows], dtype=bool)
    first = np.array(targets, dtype=np.float64, copy=True)
    if has_via.any():
        first[has_via] = np.array([vias_rows[k][0] for k in np.flatnonzero(has_via)])
    leg = first - pos
    dist_a = np.hypot(leg[:, 0], leg[:, 1])
    head_a = np.where(dist_a > 1e-12, np.arctan2(leg[:, 1], leg[:, 0]), float(beta))
    ids_arr = np.asarray(sorted_ids, dtype=np.int64)
    row_of_order = np.empty(n, dtype=np.int64)
    row_of_order[order] = np.arange(n)
    par_order = params.shape.slots(n, params.d_e, params.phi_e).parent[order]
    parent_ids = np.where(par_order < 0, -1, ids_arr[row_of_order[np.maximum(par_order, 0)]])
    starts_c = pos.copy()
    targets_c = np.array(targets, dtype=np.float64, copy=True)
    id_l, order_l, par_l = sorted_ids, order.tolist(), parent_ids.tolist()
    head_l, dist_l, wave_l = head_a.tolist(), dist_a.tolist(), dense.tolist()
    robots: list[RobotPlan] = [
        RobotPlan(
            robot_id=id_l[k],
            start=starts_c[k],
            target=targets_c[k],
            order=order_l[k],
            parent=par_l[k],
            heading=head_l[k],
            distance=dist_l[k],
            via=tuple(np.asarray(v, dtype=np.float64) for v in vias_rows[k]),
            wave=wave_l[k],
            after=tuple(id_l[j] for j in after_rows[k]),
            after_at=tuple(float(x) for x in at_rows[k]),
        )
        for k in range(n)
    ]
    n_waves = int(dense.max()) + 1
    members = np.argsort(dense, kind="stable")
    bounds = np.searchsorted(dense[members], np.arange(n_waves + 1)).tolist()
    ids_sorted_by_wave = ids_arr[members].tolist()
    waves = tuple(tuple(ids_sorted_by_wave[bounds[w] : bounds[w + 1]]) for w in range(n_waves))
    leader = sorted_ids[leader_row]
    fields_ = {
        "frame_robot": int(frame_robot),
        "leader": leader,
        "axis": float(beta),
        "origin": np.asarray(frame_origin, dtype=np.float64),
        "strategy": strategy,
        "obstacles": obs,
        "params": repr((params.d_e, params.phi_e, params.radius, params.orientation)),
    }
    if params.shape.digest != PYRAMID.digest:  # the pyramid's plan digest is as it was
        fields_["shape"] = params.shape.digest
    return Plan(
        frame_robot=int(frame_robot),
        leader=leader,
        axis=float(beta),
        origin=np.asarray(frame_origin, dtype=np.float64),
        robots=tuple(robots),
        waves=waves,
        digest=plan_digest(fields_, robots),
        strategy=strategy,
        obstacles=obs,
    )


def first_shape(params: PlanParams, n: int) -> Shape:
    """The shape the plan of :func:`plan_from_records` builds for ``n`` planned robots:
    the circle pattern's circle with the orientation ``cp`` (n >= 2), else
    ``params.shape``."""
    if params.orientation == "cp" and n > 1:
        return circle(n, params.d_e)
    return params.shape


def plan_from_records(
    records: Sequence[NeighborRecord],
    params: PlanParams = PlanParams(),
    obstacles: np.ndarray | None = None,
    sightings: Mapping[int, np.ndarray] | None = None,
    noise: SightingNoise | None = None,
) -> Plan:
    """The whole pipeline on a record set (any order): the same records -> the same plan.

    The common frame holds every robot's start pose (:mod:`fleet_frame`, docs/design.md §9;
    ``frame_method`` ``bfs`` or ``lsq``: positions on the papers' aligned frames instead). A robot the
    consistency check names is left out (``Plan.excluded``): it stands still where the
    others saw it and is planned around like an obstacle. ``obstacles`` (M, 2), if any, are
    positions in the common frame (the frame robot's fixed frame). ``sightings`` maps a
    robot id to the obstacles it saw, in its fixed frame: they are placed in the common
    frame (turned by its ψ) and merged (:mod:`obstacle_map`), then planned around with the
    others. ``noise`` is the sighting noise the fault test rests on (default: the shipped
    model of the rendered perception; synthetic records pass theirs). With the
    orientation ``cp`` the plan is the circle pattern's circle round the frame robot, which
    stands still (:mod:`agent.core.formation.shape.circle_pattern`); the formation is then
    planned from the circle (:func:`agent.core.formation.reshape.from_circle`). The digest of a plan
    with aligned starts and nobody left out is the papers' plan's; otherwise it also
    covers every ψ, who is left out and why.

    Raises ``ValueError`` for bad records, a fleet that is not connected through
    identified neighbours, sightings no single robot can be blamed for, or (with
    obstacles only) no safe schedule.
    """
    if params.frame_method != "default":  # the papers' aligned frames, as asked
        graph = identify_neighbours(records, params.epsilon)
        cf = build_common_frame(graph, params.frame_method)
        ff = FleetFrame(cf.frame_robot, cf.ids, cf.positions, np.zeros(len(cf.ids)), True)
    else:
        ff = fleet_frame(records, params.epsilon, noise)
    given = np.zeros((0, 2)) if obstacles is None else np.asarray(obstacles, dtype=np.float64)
    extra = [given.reshape(-1, 2)]
    if sightings:
        mine = {i: s for i, s in sightings.items() if i in ff.ids}
        seen = common_frame_obstacles(ff.ids, ff.positions, mine, headings=ff.headings)
        extra.append(seen)
    extra.append(ff.excluded_at.reshape(-1, 2))
    obs = np.vstack(extra)
    anchor = None
    first = first_shape(params, len(ff.ids))
    if first != params.shape:  # the circle pattern's circle first, round the frame robot
        params = replace(params, shape=first)
        anchor = ff.frame_robot
    plan = plan_from_positions(
        ff.ids,
        ff.positions,
        params,
        obs if len(obs) else obstacles,
        frame_robot=ff.frame_robot,
        anchor=anchor,
    )
    if ff.aligned and not ff.excluded:
        return plan
    psi = np.asarray(ff.headings, dtype=np.float64)
    h = hashlib.sha256(b"nao-formation/plan-poses/v1")
    h.update(plan.digest.encode())
    h.update(np.ascontiguousarray(psi, dtype="<f8").tobytes())
    h.update(repr((ff.excluded, ff.reason)).encode())
    return replace(plan, psi=psi, excluded=ff.excluded, verdict=ff.reason, digest=h.hexdigest())
