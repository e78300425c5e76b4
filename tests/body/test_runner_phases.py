"""The runner's moving phases, one by one, on an in-process world (no network).

:class:`agent.body.in_process.WorldBody` gives real renders and the world's seeded motion
noise without a network; the bus is a real zenoh session with no peers (the phases
publish statuses). Ground truth comes from the world, which the agent never reads.

Every robot of a generated scenario starts facing north, so each fixed frame (4.1.1) is
the world frame moved to the robot's start.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from agent.adapters import FormationAdapter, PerceptionAdapter
from agent.body.in_process import WorldBody
from agent.config import AgentConfig
from agent.core.control import wrap_pi
from agent.core.formation.params import PlanParams
from agent.core.formation.plan import first_shape
from agent.core.formation.reshape import circle_leader
from agent.core.formation.shape.spec import BUILTIN, PYRAMID, Shape
from agent.net.bus import Bus
from agent.phases.context import NORTH
from agent.phases.membership import Peer
from agent.wire import NeighborRecordMsg
from sim.physics.world import World
from tests.body.conftest import Robot, parts


def robot_for(
    rid: int, world: World, bus: Bus, perception: PerceptionAdapter, shape: Shape = PYRAMID
) -> Robot:
    cfg = AgentConfig(robot_id=rid, fleet_size=3, wave_timeout=5.0, shape=shape)
    return parts(WorldBody(world, rid), cfg, perception, bus)


def test_search_sees_every_neighbour_where_it_stands(
    world: World, bus: Bus, perception: PerceptionAdapter
) -> None:
    r = robot_for(1, world, bus, perception)
    x0, y0, h0 = world.pose(1)
    rec = r.search.localise(r.search.sweep())
    truth = {j: np.subtract(world.pose(j)[:2], (x0, y0)) for j in (2, 3)}
    assert len(rec.neighbours) == 2, rec
    for j, p in truth.items():
        d = min(float(np.hypot(*(np.asarray(n) - p))) for n in rec.neighbours)
        assert d < 0.05 + 0.12 * float(np.hypot(*p)), (j, p, rec.neighbours)
    # the half turn was measured by the overlapping views: the robot stays at θ = 180°
    # (no circle completed), and it knows its heading
    h = world.pose(1)[2]
    assert abs(wrap_pi(h - h0 - math.pi)) < math.radians(10)
    assert abs(wrap_pi(r.ctx.beliefs.heading - (NORTH + wrap_pi(h - h0)))) < math.radians(1)
    assert r.ctx.beliefs.compass_gain != 1.0 and 0.9 <= r.ctx.beliefs.compass_gain <= 1.1


def test_without_overlapping_views_the_search_completes_the_circle(
    world: World, bus: Bus, perception: PerceptionAdapter
) -> None:
    # head yaws within ±40°: the sweeps at θ = 0 and 180° never look the same way
    cfg = AgentConfig(
        robot_id=2, fleet_size=3, wave_timeout=5.0, search_yaws=tuple(np.radians([-40, 0, 40]))
    )
    r = parts(WorldBody(world, 2), cfg, perception, bus)
    h0 = world.pose(2)[2]
    r.search.sweep()
    h = world.pose(2)[2]
    assert abs(wrap_pi(h - h0)) < math.radians(10)  # back near θ = 0
    assert abs(wrap_pi(r.ctx.beliefs.heading - (NORTH + wrap_pi(h - h0)))) < math.radians(1)
    assert 0.9 <= r.ctx.beliefs.compass_gain <= 1.1 and r.ctx.beliefs.compass_gain != 1.0


def test_rotate_turns_by_the_compass(world: World, bus: Bus, perception: PerceptionAdapter) -> None:
    r = robot_for(2, world, bus, perception)
    h0 = world.pose(2)[2]
    done = r.motion.rotate(math.pi / 2)
    turned = wrap_pi(world.pose(2)[2] - h0)
    assert turned == pytest.approx(math.pi / 2, abs=math.radians(4))
    assert done == pytest.approx(turned, abs=math.radians(3))
    assert r.ctx.beliefs.heading == pytest.approx(NORTH + done, abs=1e-9)
    assert r.motion.compass_failures == 0


def test_walk_to_reaches_the_goal_in_steps(
    world: World, bus: Bus, perception: PerceptionAdapter
) -> None:
    r = robot_for(3, world, bus, perception)
    x0, y0, _ = world.pose(3)
    seen: list[float] = []
    goal = np.array([0.0, -0.5])  # behind: turn round, then about three 20 cm steps
    r.safe_steps.walk_to(goal, seen.append)
    x, y, _ = world.pose(3)
    assert np.hypot(x - x0 - goal[0], y - y0 - goal[1]) < 0.08
    assert float(np.hypot(*(r.ctx.beliefs.position - goal))) < 0.05  # what it believes
    assert len(seen) >= 3 and seen[-1] == pytest.approx(1.0, abs=0.05)
    assert world.locomotion.contacts == 0


def _true_records(world: World) -> tuple[NeighborRecordMsg, ...]:
    pos = {i: np.asarray(world.pose(i)[:2]) for i in world.robot_ids}
    return tuple(
        NeighborRecordMsg(
            sender=i,
            round=0,
            neighbours=tuple(tuple(float(v) for v in pos[j] - pos[i]) for j in pos if j != i),
        )
        for i in pos
    )


def test_correct_steps_towards_the_planned_offset_to_the_parent(
    world: World, bus: Bus, perception: PerceptionAdapter
) -> None:
    fa = FormationAdapter()
    plan = fa.plan(_true_records(world), PlanParams())
    origin = np.asarray(world.pose(plan.frame_robot)[:2]) - np.asarray(
        plan.robot(plan.frame_robot).start
    )
    axis = fa.axis_angle(plan)
    for rp in plan.robots:  # everyone holds its slot, facing the pyramid axis
        x, y = origin + np.asarray(rp.target)
        world.set_pose(rp.robot_id, float(x), float(y), axis)
    child = next(rp for rp in plan.robots if rp.parent >= 0)
    parent = plan.robot(child.parent)
    want = np.asarray(parent.target) - np.asarray(child.target)
    # the child stands 15 cm off its slot, sideways to the axis
    x, y, h = world.pose(child.robot_id)
    off = 0.15 * np.array([-math.sin(axis), math.cos(axis)])
    world.set_pose(child.robot_id, x + off[0], y + off[1], h)

    r = robot_for(child.robot_id, world, bus, perception)
    r.course.follow(plan)
    r.course.face(wrap_pi(axis))
    r.ctx.beliefs.heading = wrap_pi(axis)  # fixed frames are world-parallel here
    r.membership.peers[parent.robot_id] = Peer(alive=True, phase="done", seen_alive=True)

    def offset_error() -> float:
        d = np.subtract(world.pose(parent.robot_id)[:2], world.pose(child.robot_id)[:2])
        return float(np.hypot(*(d - want)))

    assert offset_error() == pytest.approx(0.15, abs=1e-6)
    r.hold.correct()
    assert offset_error() < 0.06
    assert world.locomotion.contacts == 0


def test_a_small_correction_is_a_sidestep_without_turning(
    world: World, bus: Bus, perception: PerceptionAdapter
) -> None:
    """A correction across the axis stepped sideways (NAOqi moveTo(0, y, 0))
    instead of turning to it, walking and turning back (~12 compass turn steps, ~20 s a
    level of the pyramid at 50 NAOs)."""
    r, plan, child, axis = _holding(world, bus, perception)
    parent = plan.robot(child.parent)
    want = np.asarray(parent.target) - np.asarray(child.target)
    x, y, h = world.pose(child.robot_id)
    off = 0.10 * np.array([math.sin(axis), -math.cos(axis)])  # 10 cm to its right
    world.set_pose(child.robot_id, x + off[0], y + off[1], h)
    turns: list[float] = []
    turn = r.motion.turn

    def counted(angle: float) -> object:
        turns.append(angle)
        return turn(angle)

    r.motion.turn = counted  # type: ignore[method-assign,assignment]
    r.hold.correct()
    d = np.subtract(world.pose(parent.robot_id)[:2], world.pose(child.robot_id)[:2])
    assert float(np.hypot(*(d - want))) < 0.05
    assert len(turns) <= 2, turns  # at most a drift's turn back to the axis
    assert world.locomotion.contacts == 0


def _holding(world: World, bus: Bus, perception: PerceptionAdapter, shape: Shape = PYRAMID):  # type: ignore[no-untyped-def]
    """Every robot on its slot facing the shape's axis; the runner of a child."""
    fa = FormationAdapter()
    plan = fa.plan(_true_records(world), PlanParams(shape=shape))
    origin = np.asarray(world.pose(plan.frame_robot)[:2]) - np.asarray(
        plan.robot(plan.frame_robot).start
    )
    axis = fa.axis_angle(plan)
    for rp in plan.robots:
        x, y = origin + np.asarray(rp.target)
        world.set_pose(rp.robot_id, float(x), float(y), axis)
    child = next(rp for rp in plan.robots if rp.parent >= 0)
    r = robot_for(child.robot_id, world, bus, perception, shape)
    r.course.follow(plan)
    r.course.face(wrap_pi(axis))
    r.ctx.beliefs.heading = wrap_pi(axis)
    r.membership.peers[int(child.parent)] = Peer(alive=True, phase="done", seen_alive=True)
    return r, plan, child, axis


def test_verify_measures_the_pair_and_says_so_in_the_status(
    world: World, bus: Bus, perception: PerceptionAdapter
) -> None:
    r, _, child, _ = _holding(world, bus, perception)
    r.hold.verify()
    check = r.ctx.report.figures.check
    assert check is not None and check.parent == child.parent and check.ok
    assert abs(check.r_d) < 0.06 and abs(check.r_phi) < 0.15


def test_verify_measures_a_line_s_child_beside_its_parent(
    world: World, bus: Bus, perception: PerceptionAdapter
) -> None:
    # a line: the parent stands d_e to the child's side (90° off its facing), and the pair
    # is judged against that edge of the line's tree; as a pyramid pair it would be wrong
    r, _, child, _ = _holding(world, bus, perception, BUILTIN["line"])
    r.hold.verify()
    check = r.ctx.report.figures.check
    assert check is not None and check.parent == child.parent and check.ok
    assert abs(check.r_d) < 0.06 and abs(check.r_phi) < 0.15
    assert abs(abs(math.degrees(check.angle)) - 90.0) < 5.0


def test_verify_stops_a_robot_whose_parent_is_not_where_the_plan_says(
    world: World, bus: Bus, perception: PerceptionAdapter
) -> None:
    from agent.phases.context import AgentFailure

    r, _, child, axis = _holding(world, bus, perception)
    # the child stands 0.25 m behind its slot: r_d about +30 %, out of tolerance, and
    # within max_correction (0.3 m), so the parent is still found
    x, y, h = world.pose(child.robot_id)
    world.set_pose(child.robot_id, x - 0.25 * math.cos(axis), y - 0.25 * math.sin(axis), h)
    with pytest.raises(AgentFailure, match="formation off: r_d"):
        r.hold.verify()
    check = r.ctx.report.figures.check
    assert check is not None and not check.ok


def test_verify_of_a_failed_parent_is_no_verdict(
    world: World, bus: Bus, perception: PerceptionAdapter
) -> None:
    from agent.phases.context import AgentFailure

    r, _, child, _ = _holding(world, bus, perception)
    r.membership.peers[int(child.parent)] = Peer(alive=True, phase="failed", seen_alive=True)
    # the fleet's one reason (agent/core/formation/waves/jam.py rule 4), naming the failed parent
    with pytest.raises(AgentFailure, match=f"formation incomplete: robot {child.parent} failed"):
        r.hold.verify()


def test_verify_sees_a_parent_facing_away_from_the_axis_by_its_mask(
    world: World, bus: Bus, perception: PerceptionAdapter
) -> None:
    from agent.phases.context import AgentFailure

    r, _, child, axis = _holding(world, bus, perception)
    # the parent stands on its slot but faces 70° off the axis: what a child whose own
    # start heading was misjudged by 70° would believe it sees, position for position
    x, y, _ = world.pose(int(child.parent))
    world.set_pose(int(child.parent), x, y, axis + math.radians(70))
    with pytest.raises(AgentFailure, match="faces"):
        r.hold.verify()


def test_verify_waits_for_a_parent_out_of_reach_and_then_says_so(
    world: World, bus: Bus, perception: PerceptionAdapter
) -> None:
    """A parent out of reach (token gone, silent for the grace) that had not reported
    ``done`` is waited for until ``wave_timeout`` (5 s here), not taken for gone at once;
    the answer is kept, so a second look does not wait again."""
    import time

    from agent.phases.context import AgentFailure

    r, _, child, _ = _holding(world, bus, perception)
    r.membership.peers[int(child.parent)] = Peer(alive=False, phase="hold", seen_alive=True)
    t0 = time.monotonic()
    with pytest.raises(AgentFailure, match=f"parent {child.parent} out of reach in time"):
        r.hold.verify()
    assert time.monotonic() - t0 >= 5.0
    t1 = time.monotonic()
    with pytest.raises(AgentFailure, match="out of reach in time"):
        r.hold.verify()
    assert time.monotonic() - t1 < 1.0


def test_verify_measures_a_parent_out_of_reach_that_reported_done(
    world: World, bus: Bus, perception: PerceptionAdapter
) -> None:
    """Its last status was ``done``: it stands where it finished, and the camera, not the
    network, judges the pair (before: "formation unverified: parent is gone")."""
    r, _, child, _ = _holding(world, bus, perception)
    r.membership.peers[int(child.parent)] = Peer(alive=False, phase="done", seen_alive=True)
    r.hold.verify()
    check = r.ctx.report.figures.check
    assert check is not None and check.ok


def test_a_child_waits_for_the_robots_passing_its_sight_line_only(
    world: World, bus: Bus, perception: PerceptionAdapter
) -> None:
    """The alignment waits for the parent and for the robots that may still
    walk near the sight line to it, not for the whole fleet."""
    from tests.formation.view.test_passers_by import plan_of, robot

    plan = plan_of(
        robot(1, (0.0, 3.0), (0.0, 0.0), -1),
        robot(2, (-3.0, -0.4), (-0.7, -0.4), 1),
        robot(3, (-2.0, -1.0), (2.0, -1.0), 1),  # passes 0.6 m below 2's slot
        robot(4, (5.0, 5.0), (6.0, 5.0), 1),  # far away
    )
    cfg = AgentConfig(robot_id=2, fleet_size=4, wave_timeout=0.5)
    r = parts(WorldBody(world, 2), cfg, perception, bus)
    r.course.follow(plan)
    peers = r.membership.peers
    peers[1] = Peer(alive=True, phase="done", seen_alive=True)
    peers[3] = Peer(alive=True, phase="move", seen_alive=True)
    peers[4] = Peer(alive=True, phase="move", seen_alive=True)
    assert r.hold._wait_for_parent(1).startswith("robot(s) passing near did not arrive")
    r.hold._parent_wait = None
    peers[3] = Peer(alive=True, phase="hold", seen_alive=True)
    assert r.hold._wait_for_parent(1) == ""  # 4 still walks, far from the sight line


def test_verify_judges_the_last_look_of_a_correction_that_did_not_walk(
    world: World, bus: Bus, perception: PerceptionAdapter
) -> None:
    """A robot on its slot finds nothing to correct; that look is the final
    state's, and verify judges it instead of asking the world for the same picture."""
    r, _, child, _ = _holding(world, bus, perception)
    pictures: list[float] = []
    camera = r.ctx.body.camera

    def counted(yaw: float):  # type: ignore[no-untyped-def]
        pictures.append(yaw)
        return camera(yaw)

    r.ctx.body.camera = counted  # type: ignore[method-assign]
    r.hold.correct()
    looked = len(pictures)
    assert looked >= 1 and world.locomotion.contacts == 0
    r.hold.verify()
    assert len(pictures) == looked  # no new picture
    check = r.ctx.report.figures.check
    assert check is not None and check.parent == child.parent and check.ok
    r.hold.verify()  # a second verify (after a march) looks again
    assert len(pictures) > looked


def test_a_child_follows_the_steps_its_parent_announces(
    world: World, bus: Bus, perception: PerceptionAdapter
) -> None:
    """While the parent aligns to its own parent, the child steps with it (the
    parent's ``shift``), so a correction near the top of the pyramid does not pass down
    it one level at a time; the child then announces its own shift for its children."""
    r, plan, child, axis = _holding(world, bus, perception)
    r.course.follow(dataclasses.replace(plan, digest="ab" * 32))
    parent = int(child.parent)
    # the parent has stepped 0.15 m back along the axis (common frame = world here)
    back = -0.15 * np.array([math.cos(axis), math.sin(axis)])
    r.membership.peers[parent] = Peer(
        alive=True, phase="hold", seen_alive=True, plan_digest="ab" * 32, shift=tuple(back)
    )
    start = np.asarray(world.pose(child.robot_id)[:2])
    r.hold._arrived_at = r.ctx.beliefs.position.copy()
    r.hold._follow(parent)
    moved = np.asarray(world.pose(child.robot_id)[:2]) - start
    assert float(np.hypot(*(moved - back))) < 0.06  # it stepped with its parent
    assert float(np.hypot(*(np.asarray(r.ctx.report.figures.shift) - back))) < 0.06  # and says so
    assert world.locomotion.contacts == 0
    r.hold._follow(parent)  # nothing more to follow: no step
    assert float(np.hypot(*(np.asarray(world.pose(child.robot_id)[:2]) - start - moved))) < 1e-9
    # a parent of another plan, or one done, is not followed
    r.membership.peers[parent] = Peer(
        alive=True, phase="hold", seen_alive=True, plan_digest="cd" * 32, shift=(0.0, 0.25)
    )
    r.hold._follow(parent)
    assert float(np.hypot(*(np.asarray(world.pose(child.robot_id)[:2]) - start - moved))) < 1e-9


def test_a_robot_on_the_circle_turns_to_the_centre_behind_it_and_back(
    world: World, bus: Bus, perception: PerceptionAdapter
) -> None:
    """The circle pattern's circle (AUV III.B.2.a): the robot straight north of the centre
    has its parent behind it, out of its head's reach. It turns to it, judges the pair
    against its circle edge, turns back to the axis, and then believes where it measured
    itself: the centre's planned place minus the offset it saw."""
    fa = FormationAdapter()
    params = PlanParams(orientation="cp")
    plan = fa.plan(_true_records(world), params)  # the circle round the frame robot
    ring = first_shape(params, len(plan.robots))
    origin = np.asarray(world.pose(plan.frame_robot)[:2]) - np.asarray(
        plan.robot(plan.frame_robot).start
    )
    axis = fa.axis_angle(plan)
    assert axis == pytest.approx(math.pi / 2)
    for rp in plan.robots:
        x, y = origin + np.asarray(rp.target)
        world.set_pose(rp.robot_id, float(x), float(y), axis)
    me = plan.robot(circle_leader(plan))
    assert me.parent == plan.frame_robot
    r = robot_for(me.robot_id, world, bus, perception)
    r.course.follow(plan, plan, ring)
    r.course.face(wrap_pi(axis))
    r.ctx.beliefs.heading = wrap_pi(axis)
    r.ctx.beliefs.position = np.asarray(me.target) - np.asarray(me.start) + [0.07, -0.05]
    r.membership.peers[plan.frame_robot] = Peer(alive=True, phase="done", seen_alive=True)
    r.hold.verify()
    check = r.ctx.report.figures.check
    assert check is not None and check.parent == plan.frame_robot and check.ok
    assert abs(wrap_pi(world.pose(me.robot_id)[2] - axis)) < math.radians(10)  # back
    measured = np.asarray(r.ctx.beliefs.position) + np.asarray(me.start)
    assert float(np.hypot(*(measured - np.asarray(me.target)))) < 0.05  # not 8.6 cm off
    assert world.locomotion.contacts == 0
