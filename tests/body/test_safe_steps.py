"""Safe steps (agent/core/control/corridor.py in agent/phases/safe_steps.py) on an in-process
world: a NAO stands in the robot's corridor; the robot sees it in the compass image, waits, then
walks round it by via steps and reaches its goal without contact (issue #10).

Real renders and the real detector; the world's motion noise is on. Ground truth comes
from the world, which the agent never reads.
"""

from __future__ import annotations

import math
from collections.abc import Iterator

import numpy as np
import pytest

from agent.adapters import FormationAdapter, PerceptionAdapter
from agent.body.in_process import WorldBody
from agent.config import AgentConfig
from agent.core.control.corridor import CorridorParams
from agent.net.bus import Bus
from agent.phases.context import AgentFailure
from agent.phases.runner import Runner
from sim.nao_model import FOOTPRINT_RADIUS
from sim.scenarios import RobotSpec, Scenario
from sim.world import World

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


def _runner(world: World, bus: Bus, perception: PerceptionAdapter) -> Runner:
    r = Runner(bus, WorldBody(world, 1), AgentConfig(robot_id=1), perception, FormationAdapter())
    r.safe_steps.corridor = CorridorParams(poll=0.05)
    return r


def _separation(world: World) -> float:
    return float(np.hypot(*np.subtract(world.pose(1)[:2], world.pose(2)[:2])))


def test_a_nao_in_the_corridor_is_waited_for_then_walked_round(
    blocked: World, bus: Bus, perception: PerceptionAdapter
) -> None:
    r = _runner(blocked, bus, perception)
    details: list[str] = []
    status = r.ctx.status

    def record(phase: str, progress: float = 0.0, detail: str = "", **kw: object) -> None:
        details.append(detail)
        status(phase, progress, detail, **kw)  # type: ignore[arg-type]

    r.ctx.status = record  # type: ignore[method-assign]
    seps: list[float] = []
    walk_step = r.motion.walk_step

    def step(distance: float) -> object:
        rep = walk_step(distance)
        seps.append(_separation(blocked))
        return rep

    r.motion.walk_step = step  # type: ignore[method-assign,assignment]
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
