"""A run's ground truth read as a user would read it: who moved, and the formation's
shape (a tool's verdict comes from the ground truth, never from what the agents claim;
NAO paper 5.1.1 for r_d and r_φ; AUV paper II eqs. 5-7 for the pyramid's slots, the tree
of agent/core/formation/shape/tree.py for every shape).

Who moved (:func:`excursions`, :data:`MOVED_M`): a robot moved when its true position got
farther than :data:`MOVED_M` from where it stood when it published its last search record
(the position the plan starts from; before it, robots a re-search round sends exploring
walk on no plan by design, NAO paper 4.1.3 rule 2), whatever its statuses said.

The shape (:func:`judge_shape`), from the true final poses alone, never from the agents'
planner: the formation faces the mean of its members' true headings (a held formation
faces its axis); its slot tree is the shape's definition for that many members
(:func:`slot_links`: the leader, and per slot its parent's slot, distance and angle; the
pyramid's: eq. 6, d_e, ±φ_e); robots are matched to slots by position
(:func:`assign_slots`). :func:`check_shape` then judges the true poses against any
parent links: the leader in front of every robot whose slot lies behind it, each child at
its tree's distance (|r_d| <= ``R_D_MAX``) and angle from its parent (|r_φ| <=
``R_PHI_MAX``, r_φ = the angle error over φ_e, :func:`check_edge`: a pyramid's child on
the wrong side has r_φ near -200 %), every robot with a true pose in a slot.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from agent.core.formation.shape.spec import PYRAMID
from agent.core.formation.shape.spec import Shape as FormationShape
from agent.core.formation.shape.verdict import R_D_MAX, R_PHI_MAX, check_edge

Pose = tuple[float, float, float]
Truth = Sequence[tuple[float, Mapping[int, Pose]]]

#: A robot that got farther than this (m) from its reference position moved (the truth's
#: noise bound: a robot only turning on the spot stays well within it).
MOVED_M = 0.05


def excursions(truth: Truth, ids: Sequence[int], refs: Mapping[int, int]) -> dict[int, float]:
    """Per robot of ``ids`` with a true pose: the farthest (m) its true position got from
    where it stood at truth sample ``refs[i]`` (default 0; clipped to the stream), to the
    end of the stream."""
    out: dict[int, float] = {}
    for i in ids:
        k0 = min(max(int(refs.get(i, 0)), 0), max(len(truth) - 1, 0))
        track = [poses[i] for _, poses in truth[k0:] if i in poses]
        if track:
            x0, y0 = track[0][0], track[0][1]
            out[i] = max(math.hypot(p[0] - x0, p[1] - y0) for p in track)
    return out


#: A robot within this distance (m) of its final true position has settled there.
SETTLED_M = 0.02


def settled_at(truth: Truth, ids: Sequence[int]) -> float:
    """The sim time (s) from which every robot of ``ids`` stays within :data:`SETTLED_M`
    of its final true position to the end of the stream (its first sample's time when
    nobody moved; nan for an empty stream)."""
    if not truth:
        return math.nan
    final = truth[-1][1]
    t = truth[0][0]
    for k in range(len(truth) - 1, -1, -1):
        poses = truth[k][1]
        off = [
            math.hypot(poses[i][0] - final[i][0], poses[i][1] - final[i][1])
            for i in ids
            if i in poses and i in final
        ]
        if off and max(off) > SETTLED_M:
            t = truth[min(k + 1, len(truth) - 1)][0]
            break
    return float(t)


def slot_links(
    shape: FormationShape, k: int, d_e: float, phi_e: float
) -> list[tuple[int, float, float]]:
    """Per slot 0..k-1 of ``shape`` for ``k`` robots: (parent slot, distance, angle) of its
    tree (:mod:`agent.core.formation.shape.tree`); the leader's is (-1, 0, 0). The
    pyramid's: eq. 6, each child d_e behind its parent at φ_e on its side."""
    s = shape.slots(k, d_e, phi_e)
    return [(int(p), float(d), float(a)) for p, d, a in zip(s.parent, s.distance, s.angle)]


def facing_of(final: Mapping[int, Pose], members: Sequence[int]) -> float:
    """The formation's facing (rad, CCW from world +x): the circular mean of the true
    headings of ``members`` (those with a pose)."""
    hs = [final[i][2] for i in members if i in final]
    if not hs:
        raise ValueError("no member has a true pose")
    return math.atan2(sum(math.sin(h) for h in hs), sum(math.cos(h) for h in hs))


def _frame(facing: float) -> tuple[np.ndarray, np.ndarray]:
    """(forward, left) unit vectors of the facing frame in the world."""
    fwd = np.array([math.cos(facing), math.sin(facing)])
    return fwd, np.array([-fwd[1], fwd[0]])


def assign_slots(
    final: Mapping[int, Pose],
    members: Sequence[int],
    facing: float,
    d_e: float,
    phi_e: float,
    shape: FormationShape = PYRAMID,
) -> dict[int, int]:
    """robot -> slot order: the shape's slots for ``len(members)`` turned to ``facing`` and
    centred on the members' true centroid (the translation that fits any assignment
    best), matched to the members' true positions by least total squared distance."""
    from scipy.optimize import linear_sum_assignment

    ids = sorted(members)
    fwd, left = _frame(facing)
    slots = shape.slots(len(ids), d_e, phi_e).positions  # x to the right, y forward
    world = np.outer(slots[:, 1], fwd) - np.outer(slots[:, 0], left)
    pts = np.array([final[i][:2] for i in ids], dtype=np.float64)
    world += pts.mean(axis=0) - world.mean(axis=0)
    cost = ((pts[:, None, :] - world[None, :, :]) ** 2).sum(axis=2)
    rows, cols = linear_sum_assignment(cost)
    return {ids[int(r)]: int(c) for r, c in zip(rows, cols, strict=True)}


@dataclass(frozen=True)
class Link:
    """A child of the shape's tree, its parent, and where it belongs from that parent:
    ``distance`` (m) and ``angle`` (rad, CCW from the facing)."""

    child: int
    parent: int
    distance: float
    angle: float

    @property
    def side(self) -> str:
        """``left`` or ``right`` of its parent's facing axis, or ``on axis`` (ahead or
        behind)."""
        s = math.sin(self.angle)
        return "left" if s > 1e-9 else "right" if s < -1e-9 else "on axis"


def links_of(
    slot_of: Mapping[int, int], shape: FormationShape, d_e: float, phi_e: float
) -> tuple[int, list[Link]]:
    """(leader, links) of an assignment robot -> slot of a whole shape (:func:`slot_links`)."""
    robot_at = {s: i for i, s in slot_of.items()}
    tree = slot_links(shape, len(robot_at), d_e, phi_e)
    links = [
        Link(robot_at[s], robot_at[p], dist, ang) for s, (p, dist, ang) in enumerate(tree) if p >= 0
    ]
    return robot_at[0], sorted(links, key=lambda lk: lk.child)


@dataclass(frozen=True)
class Shape:
    """The verdict of :func:`check_shape`: ``rows`` per link (child, parent, side, distance,
    angle_deg on its own side, r_d, r_phi), whether the leader is in front, the robots
    without a true pose, and whether all of it holds (``ok``)."""

    leader: int
    facing: float
    rows: list[dict[str, Any]] = field(default_factory=list)
    leader_in_front: bool = True
    missing: list[int] = field(default_factory=list)

    @property
    def ok(self) -> bool:
        return (
            self.leader_in_front
            and not self.missing
            and all(abs(r["r_d"]) <= R_D_MAX and abs(r["r_phi"]) <= R_PHI_MAX for r in self.rows)
        )

    def summary(self) -> dict[str, Any]:
        return {
            "leader": self.leader,
            "facing_deg": math.degrees(self.facing),
            "leader_in_front": self.leader_in_front,
            "missing": self.missing,
            "ok": self.ok,
        }


def _behind_leader(leader: int, links: Sequence[Link]) -> list[int]:
    """The robots whose slot lies behind the leader's (the tree's offsets composed from
    the leader, more than 1 mm back along the facing)."""
    ahead = {leader: 0.0}
    children: dict[int, list[Link]] = {}
    for lk in links:
        children.setdefault(lk.parent, []).append(lk)
    todo = [leader]
    while todo:
        p = todo.pop()
        for lk in children.get(p, []):
            if lk.child not in ahead:
                ahead[lk.child] = ahead[p] + lk.distance * math.cos(lk.angle)
                todo.append(lk.child)
    return sorted(i for i, y in ahead.items() if y < -1e-3)


def check_shape(
    final: Mapping[int, Pose],
    leader: int,
    links: Sequence[Link],
    phi_e: float,
    facing: float | None = None,
) -> Shape:
    """Judge the true final poses against the parent links (module docstring). ``facing``
    (rad): the formation's facing in the world; default: :func:`facing_of` its robots.
    Per link r_d and r_φ by the robots' own formula
    (:func:`agent.core.formation.shape.verdict.check_edge`); ``angle_deg`` is the true
    angle between the parent's backward axis and the line parent -> child, positive
    towards the child's own side (the pyramid's: φ_e when right, near −φ_e on the wrong
    side)."""
    robots = sorted({leader, *(lk.child for lk in links), *(lk.parent for lk in links)})
    missing = [i for i in robots if i not in final]
    if facing is None:
        facing = facing_of(final, robots)
    if missing:
        return Shape(leader, facing, leader_in_front=False, missing=missing)
    fwd, _ = _frame(facing)
    rows = []
    for lk in links:
        offset = np.array(final[lk.parent][:2]) - np.array(final[lk.child][:2])
        c = check_edge(lk.child, lk.parent, offset, facing, lk.distance, lk.angle, phi_e)
        off_back = math.pi - abs(lk.angle) + c.r_phi * phi_e
        rows.append({
            "child": lk.child, "parent": lk.parent, "side": lk.side,
            "distance": c.distance, "angle_deg": math.degrees(off_back),
            "r_d": c.r_d, "r_phi": c.r_phi,
        })  # fmt: skip
    along = {i: float(np.array(final[i][:2]) @ fwd) for i in robots}
    front = all(along[leader] > along[i] for i in _behind_leader(leader, links))
    return Shape(leader, facing, rows, front, [])


def judge_shape(
    final: Mapping[int, Pose],
    members: Sequence[int],
    d_e: float,
    phi_e: float,
    shape: FormationShape = PYRAMID,
) -> Shape:
    """The formation of ``members`` judged from their true final poses alone: facing
    (:func:`facing_of`), slots of ``shape`` by matching (:func:`assign_slots`), then
    :func:`check_shape`. A member without a true pose fails it (``missing``)."""
    if not members:
        raise ValueError("no members to judge")
    missing = sorted(i for i in members if i not in final)
    if missing:
        facing = facing_of(final, members) if len(missing) < len(members) else 0.0
        return Shape(min(members), facing, leader_in_front=False, missing=missing)
    facing = facing_of(final, members)
    slot_of = assign_slots(final, members, facing, d_e, phi_e, shape)
    leader, links = links_of(slot_of, shape, d_e, phi_e)
    return check_shape(final, leader, links, phi_e, facing)
