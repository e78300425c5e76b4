"""The exploration move of a re-search round (NAO paper 4.1.3 rule 2) on an in-process world.

:meth:`agent.phases.research.Research.explore` walks the move in 20 cm steps and checks the yaw-0
image before each one: a NAO inside the step's sweep ends the move there.
"""

from __future__ import annotations

import math
from collections.abc import Iterator

import numpy as np
import pytest

from agent.adapters import PerceptionAdapter
from agent.body.in_process import WorldBody
from agent.config import AgentConfig
from agent.net.bus import Bus
from sim.physics.world import World
from sim.scenarios import RobotSpec, Scenario
from tests.body.conftest import Robot, parts

NORTH = math.pi / 2

#: robot 1 at the origin facing north, robot 2 1.2 m ahead of it, robot 3 off to the side
AHEAD = Scenario(
    robots=(
        RobotSpec(1, 0.0, 0.0, NORTH),
        RobotSpec(2, 0.0, 1.2, NORTH),
        RobotSpec(3, 2.0, -1.0, NORTH),
    ),
    seed=5,
    room=3.5,
)


@pytest.fixture()
def ahead() -> Iterator[World]:
    with World(AHEAD) as w:
        yield w


def explorer(rid: int, world: World, bus: Bus, perception: PerceptionAdapter) -> Robot:
    cfg = AgentConfig(robot_id=rid, fleet_size=3)
    return parts(WorldBody(world, rid), cfg, perception, bus)


def test_explore_stops_before_a_nao_seen_ahead(
    ahead: World, bus: Bus, perception: PerceptionAdapter
) -> None:
    r = explorer(1, ahead, bus, perception)
    r.research.explore(np.array([0.0, 2.0]))  # straight through robot 2
    x, y, _ = ahead.pose(1)
    gap = math.dist((x, y), ahead.pose(2)[:2])
    # stopped with robot 2 inside the next step's sweep (0.2 + 0.5 m), not in contact
    assert 0.45 < gap <= 0.2 + 2 * r.ctx.cfg.radius + 0.1 + 0.1, gap
    assert y > 0.1  # it did walk while the way was clear
    assert ahead.locomotion.contacts == 0
    assert float(np.hypot(*r.ctx.beliefs.position)) == pytest.approx(y, abs=0.1)


def test_explore_walks_the_move_when_the_way_is_clear(
    ahead: World, bus: Bus, perception: PerceptionAdapter
) -> None:
    r = explorer(3, ahead, bus, perception)
    r.research.explore(np.array([0.0, -0.8]))  # south: nobody there (turns round first)
    x, y, _ = ahead.pose(3)
    assert math.hypot(x - 2.0, y + 1.8) < 0.1
    assert float(np.hypot(*(r.ctx.beliefs.position - [0.0, -0.8]))) < 0.05
    assert ahead.locomotion.contacts == 0
