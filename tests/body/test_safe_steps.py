"""Safe steps (agent/core/control/corridor.py in agent/phases/safe_steps.py) on an in-process
world: a NAO stands in the robot's corridor; the robot sees it in the compass image, waits, then
walks round it by via steps and reaches its goal without contact (execution noise moves robots off
their planned corridors).

Real renders and the real detector; the world's motion noise is on. Ground truth comes
from the world, which the agent never reads.
"""

from __future__ import annotations

import math
from collections.abc import Iterator

import numpy as np
import pytest

from agent.adapters import PerceptionAdapter
from agent.body.in_process import WorldBody
from agent.config import AgentConfig
from agent.core.control.corridor import CorridorParams
from agent.core.formation.plan import Plan, RobotPlan
from agent.net.bus import Bus
from agent.phases.context import AgentFailure
from agent.phases.membership import Peer
from agent.phases.reporting import Phase
from sim.physics.nao_model import FOOTPRINT_RADIUS
from sim.physics.world import World
from sim.scenarios import RobotSpec, Scenario
from tests.body.conftest import Robot, parts

#: robot 1 facing north, robot 2 standing 0.8 m ahead of it, facing it
BLOCKED = Scenario(
    robots=(
        RobotSpec(1, 0.0, -0.8, math.pi / 2),
        RobotSpec(2, 0.0, 0.0, -math.pi / 2),
    ),
    seed=5,
    room=3.0,
)


@pytest.fixture()
def blocked() -> Iterator[World]:
    with World(BLOCKED) as w:
        yield w


def _runner(world: World, bus: Bus, perception: PerceptionAdapter) -> Robot:
    r = parts(WorldBody(world, 1), AgentConfig(robot_id=1), perception, bus)
    r.safe_steps.corridor = CorridorParams(poll=0.05)
    return r


def _separation(world: World) -> float:
    return float(np.hypot(*np.subtract(world.pose(1)[:2], world.pose(2)[:2])))


def _separations(r: Robot, world: World) -> list[float]:
    """Robot 1's separation from robot 2 after each of its steps (filled as it walks)."""
    seps: list[float] = []
    walk_step = r.motion.walk_step

    def step(distance: float) -> object:
        rep = walk_step(distance)
        seps.append(_separation(world))
        return rep

    r.motion.walk_step = step  # type: ignore[method-assign,assignment]
    return seps


def test_a_nao_in_the_corridor_is_waited_for_then_walked_round(
    blocked: World, bus: Bus, perception: PerceptionAdapter
) -> None:
    r = _runner(blocked, bus, perception)
    details: list[str] = []
    status = r.ctx.report.status

    def record(phase: Phase, progress: float = 0.0, detail: str = "", **kw: object) -> None:
        details.append(detail)
        status(phase, progress, detail, **kw)  # type: ignore[arg-type]

    r.ctx.report.status = record  # type: ignore[method-assign]
    seps = _separations(r, blocked)
    goal = np.array([0.0, 1.6])  # 0.8 m beyond the NAO, straight through it
    r.safe_steps.walk_to(goal, lambda p: None)
    x, y, _ = blocked.pose(1)
    assert math.hypot(x - 0.0, y - 0.8) < 0.15  # arrived (0.8 m past the NAO's centre)
    assert r.safe_steps.waits >= 1 and r.safe_steps.vias >= 1
    assert any(d.startswith("waiting: NAO ahead at") for d in details), details
    assert blocked.locomotion.contacts == 0
    assert min(seps) > 2 * FOOTPRINT_RADIUS + 0.05, seps
    assert blocked.pose(2)[:2] == (0.0, 0.0)  # the NAO never moved


def test_a_nao_standing_on_the_goal_stops_the_robot_with_a_reason(
    blocked: World, bus: Bus, perception: PerceptionAdapter
) -> None:
    # the goal is where the other NAO stands: no step round it reaches it; the robot
    # waits its bounded number of polls and fails safely
    r = _runner(blocked, bus, perception)
    r.safe_steps.corridor = CorridorParams(poll=0.01, max_polls=3)
    with pytest.raises(AgentFailure, match="blocked"):
        r.safe_steps.walk_to(np.array([0.0, 0.75]), lambda p: None)
    assert blocked.locomotion.contacts == 0
    assert _separation(blocked) > 2 * FOOTPRINT_RADIUS


def _plan_with_robot_2_on_the_goal() -> Plan:
    """Robot 1 (world (0, -0.8)) planned to (0, -0.05), robot 2 standing at its start
    (0, 0), planned to (1.5, 0) after robot 1: the jam of a dense fleet (world = fixed frame
    shifted, both facing north at the start of robot 1's frame)."""

    def rp(i: int, start: tuple[float, float], target: tuple[float, float], wave: int) -> RobotPlan:
        s, t = np.array(start), np.array(target)
        d = t - s
        return RobotPlan(
            robot_id=i, start=s, target=t, order=i - 1, parent=-1 if i == 1 else 1,
            heading=math.atan2(d[1], d[0]), distance=float(np.hypot(*d)), wave=wave,
            after=() if i == 1 else (1,),
        )  # fmt: skip

    robots = (rp(1, (0.0, -0.8), (0.0, -0.05), 0), rp(2, (0.0, 0.0), (1.5, 0.0), 1))
    return Plan(
        frame_robot=1, leader=1, axis=math.pi / 2, origin=np.zeros(2), robots=robots,
        waves=((1,), (2,)), digest="00",
    )  # fmt: skip


def _jammed(
    world: World, bus: Bus, perception: PerceptionAdapter, phase: str, walked: float = 0.0
) -> Robot:
    cfg = AgentConfig(robot_id=1, wave_timeout=1.0)  # 10 polls for a robot not moved yet
    r = parts(WorldBody(world, 1), cfg, perception, bus)
    r.safe_steps.corridor = CorridorParams(poll=0.01, max_polls=3)
    r.course.follow(_plan_with_robot_2_on_the_goal())
    r.membership.peers[2] = Peer(alive=True, phase=phase, seen_alive=True, walked=walked)
    return r


def test_a_jammed_robot_names_its_blocker_and_goes_on_once_it_yields(
    blocked: World, bus: Bus, perception: PerceptionAdapter
) -> None:
    """Robot 2 has not moved (``wait``) and stands on robot 1's goal: robot 1
    names it (``blocked_by`` 2) and waits; robot 2 yields (here: the world moves it, as
    its own agent would walk away), and robot 1 reaches its goal."""
    r = _jammed(blocked, bus, perception, "wait")
    claims: list[int] = []
    report = r.ctx.report
    status = report.status

    def record(phase: Phase, progress: float = 0.0, detail: str = "", **kw: object) -> None:
        claims.append(report.figures.blocked_by)
        if report.figures.blocked_by == 2 and blocked.pose(2)[:2] == (0.0, 0.0):
            blocked.set_pose(2, 1.5, 0.0, -math.pi / 2)  # robot 2 yields
        status(phase, progress, detail, **kw)  # type: ignore[arg-type]

    report.status = record  # type: ignore[method-assign]
    r.safe_steps.walk_to(np.array([0.0, 0.75]), lambda p: None)
    assert 2 in claims and report.figures.blocked_by == -1  # claimed, then cleared
    x, y, _ = blocked.pose(1)
    assert math.hypot(x, y + 0.05) < 0.15
    assert blocked.locomotion.contacts == 0


@pytest.mark.parametrize(
    ("phase", "walked", "who"),
    [
        ("wait", 0.0, "robot 2 \\(wait\\) in its way for 10 polls"),
        # in its move phase with nothing walked (turning, or waiting for its own way):
        # still at its start, named, and waited for as long as one not moved yet
        ("move", 0.0, "robot 2 \\(move\\) in its way for 10 polls"),
        # once its status says it has walked 0.5 m, it is expected there, on its path: the
        # NAO at its start is none of the plan's
        ("move", 0.5, "a NAO not in the plan \\(or one walking\\) in its way for 3 polls"),
        # a robot that holds is expected on its slot, (1.5, 0): the NAO on the goal is
        # none of the plan's, and no yield will come
        ("hold", 0.0, "a NAO not in the plan \\(or one walking\\) in its way for 3 polls"),
    ],
)
def test_a_jammed_robot_stops_naming_its_blocker(
    blocked: World, bus: Bus, perception: PerceptionAdapter, phase: str, walked: float, who: str
) -> None:
    """It waits the wave timeout's worth of polls for a robot that has not moved, the
    corridor's ``max_polls`` for any other NAO, then stops with a reason naming it."""
    r = _jammed(blocked, bus, perception, phase, walked)
    with pytest.raises(AgentFailure, match=f"robot 1 cannot reach its slot: {who}"):
        r.safe_steps.walk_to(np.array([0.0, 0.75]), lambda p: None)
    assert blocked.locomotion.contacts == 0 and blocked.pose(2)[:2] == (0.0, 0.0)


@pytest.mark.parametrize("seed", [0, 1])
def test_a_nao_standing_beside_the_way_is_walked_round_not_crept_past(
    bus: Bus, perception: PerceptionAdapter, seed: int
) -> None:
    """At 100 NAOs: a NAO holding 0.25 m beside a robot's straight way. Checked one
    step ahead only, it blocked the step once it was 0.6 m ahead, too near to be seen
    surely: the robot stepped back, saw the step clear, stepped on, and crept past it until
    the sighting was lost beside it, then touched it (both seeds, before the lookahead).
    With the way ``lookahead`` m beyond the step checked too, it is seen blocking while in
    the image, and walked round."""
    beside = Scenario(
        robots=(RobotSpec(1, 0.0, -1.2, math.pi / 2), RobotSpec(2, 0.25, 0.0, math.pi)),
        seed=seed,
        room=4.0,
    )
    with World(beside, noise=True) as world:
        r = _runner(world, bus, perception)
        seps = _separations(r, world)
        r.safe_steps.walk_to(np.array([0.0, 2.4]), lambda p: None)  # 1.2 m past the NAO
        x, y, _ = world.pose(1)
        assert math.hypot(x, y - 1.2) < 0.15
        assert world.locomotion.contacts == 0
        assert r.safe_steps.vias >= 1
        assert min(seps) > 2 * FOOTPRINT_RADIUS + 0.05, seps


def _ranked_plan_with_robot_2_in_the_way(unmoved: bool = False) -> Plan:
    """Robot 1 (start (0, -0.8)) planned to (0, 1.6), in the last wave after 20 robots
    standing far off (rank 21: a patience of 22 polls); robot 2 stands at (0, 0) in robot
    1's way: planned to it (or, ``unmoved``, starting there and waiting for robot 1)
    (plan frame = world frame, as in the jam plan above)."""

    def rp(
        i: int, start: tuple[float, float], target: tuple[float, float], wave: int, *after: int
    ) -> RobotPlan:
        s, t = np.array(start), np.array(target)
        d = t - s
        return RobotPlan(
            robot_id=i, start=s, target=t, order=i, parent=-1 if i == 1 else 1,
            heading=math.atan2(d[1], d[0]), distance=float(np.hypot(*d)), wave=wave,
            after=after,
        )  # fmt: skip

    far = tuple(rp(i, (20.0 + i, 20.0), (20.0 + i, 20.0), 0) for i in range(3, 23))
    two = rp(2, (0.0, 0.0), (3.0, 3.0), 3, 1) if unmoved else rp(2, (3.0, 3.0), (0.0, 0.0), 1)
    robots = (rp(1, (0.0, -0.8), (0.0, 1.6), 2), two, *far)
    return Plan(
        frame_robot=1, leader=1, axis=math.pi / 2, origin=np.zeros(2), robots=robots,
        waves=(tuple(range(3, 23)), (2,), (1,)), digest="00",
    )  # fmt: skip


@pytest.mark.parametrize(
    ("phase", "unmoved", "polls"),
    [("hold", False, (1, 4)), ("move", False, (22, 40)), ("wait", True, (1, 4))],
)
def test_a_nao_that_holds_its_slot_is_walked_round_without_waiting_out_the_rank(
    blocked: World,
    bus: Bus,
    perception: PerceptionAdapter,
    phase: str,
    unmoved: bool,
    polls: tuple[int, int],
) -> None:
    """At 50 NAOs: a robot of rank ~30 waited 33 polls (80 s of the critical
    chain) for a NAO that stood on its slot. A blocker taken for a member that holds
    will not walk on: one poll, then round it; so for one that has not moved and waits
    for this robot (it was robot 6 at its start, waiting for robot 37); a NAO walking
    (no expected place) is waited for as the rank says (the deadlock rule between two
    walking robots)."""
    r = _runner(blocked, bus, perception)
    r.safe_steps.corridor = CorridorParams(poll=0.01)
    r.course.follow(_ranked_plan_with_robot_2_in_the_way(unmoved))
    r.membership.peers[2] = Peer(alive=True, phase=phase, seen_alive=True)
    assert r.safe_steps._rank() >= 20  # a patience of 21 polls or more
    r.safe_steps.walk_to(np.array([0.0, 2.4]), lambda p: None)  # its slot, fixed frame
    x, y, _ = blocked.pose(1)
    assert math.hypot(x, y - 1.6) < 0.15
    assert polls[0] <= r.safe_steps.waits <= polls[1] and r.safe_steps.vias >= 1
    assert blocked.locomotion.contacts == 0


def test_a_via_step_blocked_after_the_turn_is_planned_again(
    bus: Bus, perception: PerceptionAdapter
) -> None:
    """At 50 NAOs: robot 37 turned for a via step, saw a NAO that held its slot
    0.6 m ahead in the turned image, waited 60 polls for it and stopped the fleet. Here
    robot 3 stands on the right tangent round robot 2, outside the first image (44° off
    the heading): the via step planned without it is found blocked after the turn, not
    walked, and the detour is planned again (round the left) from what the robot has seen
    (before: ``max_polls`` polls, then AgentFailure)."""
    hidden = Scenario(
        robots=(
            RobotSpec(1, 0.0, -0.8, math.pi / 2),
            RobotSpec(2, 0.0, 0.0, -math.pi / 2),
            RobotSpec(3, 0.62 * math.cos(0.81), -0.8 + 0.62 * math.sin(0.81), math.pi),
        ),
        seed=5,
        room=4.0,
    )
    with World(hidden) as world:
        r = _runner(world, bus, perception)
        r.safe_steps.corridor = CorridorParams(poll=0.01, max_polls=8)
        r.safe_steps.walk_to(np.array([0.0, 2.4]), lambda p: None)  # 0.8 m past robot 2
        x, y, _ = world.pose(1)
        assert math.hypot(x, y - 1.6) < 0.15
        assert r.safe_steps.refused >= 1 and r.safe_steps.vias >= 1
        assert world.locomotion.contacts == 0


def test_a_via_step_clears_a_member_standing_where_the_plan_says(
    bus: Bus, perception: PerceptionAdapter
) -> None:
    """The scene above, with robot 3 a member of the plan that has not moved (``wait``,
    at its start): the via step, off the plan, clears where robot 3 stands by the plan
    though no image has shown it, so the detour goes round the left at once, and no via
    step is found blocked after its turn (at 100 NAOs a detour's tangent steps passed
    0.39 m from a member standing at its start, unseen, which then walked into it)."""
    spot = (0.62 * math.cos(0.81), -0.8 + 0.62 * math.sin(0.81))
    hidden = Scenario(
        robots=(
            RobotSpec(1, 0.0, -0.8, math.pi / 2),
            RobotSpec(2, 0.0, 0.0, -math.pi / 2),
            RobotSpec(3, *spot, math.pi),
        ),
        seed=5,
        room=4.0,
    )

    def rp(i: int, start: tuple[float, float], target: tuple[float, float], wave: int) -> RobotPlan:
        s, t = np.array(start), np.array(target)
        d = t - s
        return RobotPlan(
            robot_id=i, start=s, target=t, order=i, parent=-1 if i == 1 else 1,
            heading=math.atan2(d[1], d[0]), distance=float(np.hypot(*d)), wave=wave,
            after=(1,) if i == 3 else (),
        )  # fmt: skip

    robots = (rp(1, (0.0, -0.8), (0.0, 1.6), 1), rp(2, (3.0, 3.0), (0.0, 0.0), 0),
              rp(3, spot, (3.0, -3.0), 2))  # fmt: skip
    plan = Plan(
        frame_robot=1, leader=1, axis=math.pi / 2, origin=np.zeros(2), robots=robots,
        waves=((2,), (1,), (3,)), digest="00",
    )  # fmt: skip
    with World(hidden) as world:
        r = _runner(world, bus, perception)
        r.safe_steps.corridor = CorridorParams(poll=0.01, max_polls=8)
        r.course.follow(plan)
        r.membership.peers[2] = Peer(alive=True, phase="hold", seen_alive=True)
        r.membership.peers[3] = Peer(alive=True, phase="wait", seen_alive=True)
        assert r.safe_steps._members() == pytest.approx(
            np.array([[0.0, 0.8], [spot[0], spot[1] + 0.8]])
        )
        xs: list[float] = []
        walk_step = r.motion.walk_step

        def step(distance: float) -> object:
            rep = walk_step(distance)
            xs.append(world.pose(1)[0])
            return rep

        r.motion.walk_step = step  # type: ignore[method-assign,assignment]
        r.safe_steps.walk_to(np.array([0.0, 2.4]), lambda p: None)  # 0.8 m past robot 2
        x, y, _ = world.pose(1)
        assert math.hypot(x, y - 1.6) < 0.15
        assert r.safe_steps.refused == 0 and r.safe_steps.vias >= 1
        assert min(xs) < -0.2 and max(xs) < 0.1, xs  # round the left, never to the right
        assert world.locomotion.contacts == 0


def test_a_walking_member_is_expected_on_the_next_stretch_of_its_path(
    blocked: World, bus: Bus, perception: PerceptionAdapter
) -> None:
    """Robot 2 walks its planned path from (3, 3) to (0, 0) and said 1.0 m walked: a step
    off the plan clears its path from 1.0 to 1.5 m (its status may lag by a milestone);
    the 20 far robots still at their starts stand there. Relative to robot 1 at its start
    (0, -0.8) in the plan's frame."""
    r = _runner(blocked, bus, perception)
    r.course.follow(_ranked_plan_with_robot_2_in_the_way())
    r.membership.peers[2] = Peer(alive=True, phase="move", seen_alive=True, walked=1.0)
    pts = r.safe_steps._members()
    u = np.array([-1.0, -1.0]) / math.sqrt(2.0)
    stretch = [np.array([3.0, 3.0]) + (1.0 + 0.1 * k) * u - np.array([0.0, -0.8]) for k in range(6)]
    far = [np.array([20.0 + i, 20.8]) for i in range(3, 23)]
    np.testing.assert_allclose(pts, np.array(stretch + far), atol=1e-9)
    assert not r.safe_steps.off_plan  # no via step walked yet: planned steps ignore them
