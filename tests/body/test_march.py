"""The march (agent/phases/march.py) on an in-process world: a follower keeps station on a
parent that the test moves, a lost parent halts it with the reason, a failed member
halts the fleet, the leader waits for a follower that lost its parent.

The parent is moved by the body's camera: every image the child takes first moves the
parent 5 cm along the axis until it has marched 0.6 m, then the parent reports ``done``
- deterministic, no threads and no timing.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from agent.adapters import FormationAdapter, PerceptionAdapter
from agent.body.base import Frame
from agent.body.in_process import WorldBody
from agent.config import AgentConfig
from agent.core.control import wrap_pi
from agent.core.formation.params import PlanParams
from agent.core.formation.plan import Plan
from agent.core.formation.view.route import Route, route_vector, station_offset
from agent.net.bus import Bus
from agent.phases.march import LOST, Marcher, MarchHalt
from agent.phases.membership import Peer
from agent.wire import NeighborRecordMsg
from sim.physics.world import World
from tests.body.conftest import Robot, parts


def formed(world: World) -> tuple[Plan, float]:
    """The plan on true records, every robot put on its slot facing the axis."""
    pos = {i: np.asarray(world.pose(i)[:2]) for i in world.robot_ids}
    recs = tuple(
        NeighborRecordMsg(
            sender=i, round=0,
            neighbours=tuple(tuple(float(v) for v in pos[j] - pos[i]) for j in pos if j != i),
        )
        for i in pos
    )  # fmt: skip
    fa = FormationAdapter()
    plan = fa.plan(recs, PlanParams())
    origin = pos[plan.frame_robot] - np.asarray(plan.robot(plan.frame_robot).start)
    axis = fa.axis_angle(plan)
    for rp in plan.robots:
        x, y = origin + np.asarray(rp.target)
        world.set_pose(rp.robot_id, float(x), float(y), axis)
    return plan, axis


class MovingParent(WorldBody):
    """The child's body; each image first moves the parent ``step`` along ``axis``."""

    def __init__(self, world: World, rid: int, parent: int, axis: float, total: float) -> None:
        super().__init__(world, rid)
        self.parent, self.axis, self.left = parent, axis, total
        self.on_arrival: list[Peer] = []

    def camera(self, yaw: float) -> Frame:
        if self.left > 1e-9:
            d = min(0.05, self.left)
            self.left -= d
            x, y, h = self.world.pose(self.parent)
            self.world.set_pose(
                self.parent, x + d * math.cos(self.axis), y + d * math.sin(self.axis), h
            )
        elif self.on_arrival:
            self.on_arrival[0].phase = "done"
        return super().camera(yaw)


def child_runner(
    world: World, bus: Bus, perception: PerceptionAdapter, body: WorldBody, plan: Plan,
    axis: float, **cfg: object,
) -> Robot:  # fmt: skip
    settings: dict[str, object] = {"wave_timeout": 5.0, **cfg}
    config = AgentConfig(
        robot_id=body.robot_id, fleet_size=3,
        march=Route(distance=0.6), **settings,  # type: ignore[arg-type]
    )  # fmt: skip
    r = parts(body, config, perception, bus)
    r.course.follow(plan)
    r.course.face(wrap_pi(axis))
    r.ctx.beliefs.heading = wrap_pi(axis)  # fixed frames are world-parallel here
    for rp in plan.robots:
        if rp.robot_id != body.robot_id:
            r.membership.peers[rp.robot_id] = Peer(alive=True, phase="march", seen_alive=True)
    return r


def test_route_vector_and_station_offset(world: World) -> None:
    plan, axis = formed(world)
    v = route_vector(plan, Route(distance=2.0), axis)
    assert v == pytest.approx(2.0 * np.array([math.cos(axis), math.sin(axis)]))
    lead = np.asarray(plan.robot(plan.leader).target)
    assert route_vector(plan, Route(to=(1.0, 2.0)), axis) == pytest.approx(
        np.array([1.0, 2.0]) - lead
    )
    child = next(rp for rp in plan.robots if rp.parent >= 0)
    off = station_offset(plan, child.robot_id)
    assert float(np.hypot(*off)) == pytest.approx(0.8, abs=1e-6)
    # the parent is ahead of the child, 30° off the axis
    ang = math.acos(float(np.dot(off, [math.cos(axis), math.sin(axis)])) / 0.8)
    assert ang == pytest.approx(math.radians(30), abs=1e-6)


def test_follower_keeps_station_on_a_marching_parent(
    world: World, bus: Bus, perception: PerceptionAdapter
) -> None:
    plan, axis = formed(world)
    child = next(rp for rp in plan.robots if rp.parent >= 0)
    body = MovingParent(world, child.robot_id, child.parent, axis, 0.6)
    # the bound on waiting for the parent is wall time: generous, so that a loaded
    # machine (slow renders) never ends the march early; the parent's moves end it
    r = child_runner(world, bus, perception, body, plan, axis, wave_timeout=120.0)
    body.on_arrival.append(r.membership.peers[child.parent])
    want = station_offset(plan, child.robot_id)
    start = np.asarray(world.pose(child.robot_id)[:2])
    m = Marcher(r.ctx, r.membership, r.motion, plan, Route(distance=0.6), axis)
    m.run()
    now = np.asarray(world.pose(child.robot_id)[:2])
    err = np.subtract(world.pose(child.parent)[:2], now) - want
    assert float(np.hypot(*err)) < 0.1, err  # station kept within 12.5 % of d_e
    assert float(np.dot(now - start, [math.cos(axis), math.sin(axis)])) > 0.45
    assert m.worst_range > 0.0  # it saw the parent pull away
    assert abs(wrap_pi(world.pose(child.robot_id)[2] - axis)) < math.radians(6)
    assert world.locomotion.contacts == 0


def test_lost_parent_halts_with_the_reason_after_a_head_search(
    world: World, bus: Bus, perception: PerceptionAdapter
) -> None:
    plan, axis = formed(world)
    child = next(rp for rp in plan.robots if rp.parent >= 0)
    body = WorldBody(world, child.robot_id)
    r = child_runner(world, bus, perception, body, plan, axis, lost_rounds=1)
    x, y, h = world.pose(child.parent)
    world.set_pose(child.parent, x + 3.0 * math.cos(axis), y + 3.0 * math.sin(axis), h)
    h0 = world.pose(child.robot_id)[2]
    with pytest.raises(MarchHalt, match=f"lost sight of parent {child.parent}"):
        Marcher(r.ctx, r.membership, r.motion, plan, Route(distance=0.6), axis).run()
    assert world.pose(child.robot_id)[2] == pytest.approx(h0)  # searched with the head only
    assert r.ctx.report.phase == "march"


def test_a_failed_member_halts_the_march(
    world: World, bus: Bus, perception: PerceptionAdapter
) -> None:
    plan, axis = formed(world)
    child = next(rp for rp in plan.robots if rp.parent >= 0)
    r = child_runner(world, bus, perception, WorldBody(world, child.robot_id), plan, axis)
    other = next(i for i in plan.ids if i != child.robot_id)
    r.membership.peers[other].phase = "failed"
    with pytest.raises(MarchHalt, match=f"robot {other} failed"):
        Marcher(r.ctx, r.membership, r.motion, plan, Route(distance=0.6), axis).run()
    r.membership.peers[other] = Peer(alive=False, phase="march", seen_alive=True)
    with pytest.raises(MarchHalt, match=f"robot {other} left"):
        Marcher(r.ctx, r.membership, r.motion, plan, Route(distance=0.6), axis).check_fleet()


def test_the_leader_sees_who_lost_its_parent(
    world: World, bus: Bus, perception: PerceptionAdapter
) -> None:
    plan, axis = formed(world)
    lead = plan.leader
    r = child_runner(world, bus, perception, WorldBody(world, lead), plan, axis)
    m = Marcher(r.ctx, r.membership, r.motion, plan, Route(distance=0.6), axis)
    assert m.lost_followers() == []
    lost = next(i for i in plan.ids if i != lead)
    r.membership.peers[lost].detail = f"{LOST} {lead}: head search 1"
    assert m.lost_followers() == [lost]
    r.membership.peers[lost].phase = "done"  # only a marching follower holds the fleet
    assert m.lost_followers() == []
