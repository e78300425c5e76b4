"""A step's drift the compass reports implausibly large is re-measured
(:meth:`agent.phases.motion.Motion._confirm_drift`: execution noise).

At ``--noise-scale 2`` a NAO that veers strongly drifts 20–30° in one 20 cm step; the
compass measured it correctly, the runner took it for a mismatch and believed 0°, and
the robot ended its walk with its heading that far off, so its final offset from its
parent was rotated by as much (pairs off by 70–80 % in r_φ). Real renders and the real
compass on an in-process world; the drift is the world's, set per robot.
"""

from __future__ import annotations

import math
from collections.abc import Iterator

import numpy as np
import pytest

from agent.adapters import PerceptionAdapter
from agent.body.in_process import WorldBody
from agent.config import AgentConfig
from agent.core.control import wrap_pi
from agent.core.perception.compass import CompassResult
from agent.net.bus import Bus
from agent.phases.context import NORTH
from agent.phases.motion import _plausible
from sim.physics.locomotion import NoiseModel
from sim.physics.world import World
from sim.scenarios import RobotSpec, Scenario
from tests.body.conftest import Robot, parts

#: one robot at the origin facing north, in the textured room
ALONE = Scenario(robots=(RobotSpec(1, 0.0, -0.6, math.pi / 2),), seed=7, room=3.0)


@pytest.fixture()
def alone() -> Iterator[World]:
    with World(ALONE) as w:
        w.locomotion.noise = NoiseModel.none()  # only the drift set by each test
        w.locomotion.drift[1] = 0.0
        yield w


def _robot(world: World, bus: Bus, perception: PerceptionAdapter) -> Robot:
    return parts(WorldBody(world, 1), AgentConfig(robot_id=1), perception, bus)


def _true_heading_change(world: World, h0: float) -> float:
    return wrap_pi(world.pose(1)[2] - h0)


@pytest.mark.parametrize(
    ("measured", "commanded", "walking", "expected"),
    [
        (math.radians(19.9), 0.0, True, True),
        (math.radians(-20.1), 0.0, True, False),
        (math.radians(9.9), 0.0, False, True),
        (math.radians(10.1), 0.0, False, False),
        (math.radians(40.0 + 23.9), math.radians(40.0), False, True),  # 60 % of 40° = 24°
        (math.radians(40.0 + 24.1), math.radians(40.0), False, False),
    ],
)
def test_plausibility_of_a_compass_rotation(
    measured: float, commanded: float, walking: bool, expected: bool
) -> None:
    assert _plausible(measured, commanded, walking) is expected


def test_a_real_large_drift_is_confirmed_and_believed(
    alone: World, bus: Bus, perception: PerceptionAdapter
) -> None:
    # 2.0 rad/m: about -23° in every 20 cm step, beyond the 20° plausibility limit
    alone.locomotion.drift[1] = -2.0
    r = _robot(alone, bus, perception)
    h0 = alone.pose(1)[2]
    r.motion.walk_step(0.2)
    true = _true_heading_change(alone, h0)
    assert r.motion.drift_checks == 1
    assert wrap_pi(r.ctx.beliefs.heading - NORTH) == pytest.approx(true, abs=math.radians(2))
    # after the re-measuring turn the robot faces about where it faced before the step
    assert abs(true) < math.radians(8)


def test_walking_to_a_goal_with_large_drifts_keeps_the_heading(
    alone: World, bus: Bus, perception: PerceptionAdapter
) -> None:
    alone.locomotion.drift[1] = 2.2
    r = _robot(alone, bus, perception)
    x0, y0, h0 = alone.pose(1)
    goal = np.array([0.0, 0.8])  # four steps north
    r.safe_steps.walk_to(goal, lambda p: None)
    r.motion.rotate(wrap_pi(NORTH - r.ctx.beliefs.heading))
    x, y, _ = alone.pose(1)
    assert r.motion.drift_checks >= 2
    assert abs(_true_heading_change(alone, h0)) < math.radians(4)  # faces north again
    assert math.hypot(x - x0 - goal[0], y - y0 - goal[1]) < 0.1


class _OneMismatch(PerceptionAdapter):
    """The first walking measurement is a wrong match of -30°; the rest are real."""

    def __init__(self, real: PerceptionAdapter) -> None:
        self.__dict__.update(real.__dict__)
        self.fooled = False

    def measure_walk(self, before: np.ndarray, after: np.ndarray) -> CompassResult:
        if not self.fooled:
            self.fooled = True
            return CompassResult(True, math.radians(-30.0), 100, 80, 0.8, "ok")
        return super().measure_walk(before, after)


def test_a_wrong_match_is_found_out_by_the_re_measurement(
    alone: World, bus: Bus, perception: PerceptionAdapter
) -> None:
    r = parts(WorldBody(alone, 1), AgentConfig(robot_id=1), _OneMismatch(perception), bus)
    h0 = alone.pose(1)[2]
    r.motion.walk_step(0.2)
    # no drift at all: the re-measuring turn of +30° is all the robot turned, and the
    # compass between the images before the step and after the turn says so
    true = _true_heading_change(alone, h0)
    assert true == pytest.approx(math.radians(30.0), abs=math.radians(2))
    assert wrap_pi(r.ctx.beliefs.heading - NORTH) == pytest.approx(true, abs=math.radians(2))
    assert r.ctx.beliefs.position == pytest.approx([0.0, 0.2], abs=0.01)


class _Unconfirmed(PerceptionAdapter):
    """A -30° match after the step, then ``second`` for the re-measurement."""

    def __init__(self, real: PerceptionAdapter, second: CompassResult) -> None:
        self.__dict__.update(real.__dict__)
        self.results = [CompassResult(True, math.radians(-30.0), 100, 80, 0.8, "ok"), second]

    def measure_walk(self, before: np.ndarray, after: np.ndarray) -> CompassResult:
        return self.results.pop(0)


@pytest.mark.parametrize(
    "second",
    [
        CompassResult(False, 0.0, 3, 0, 0.0, "too few matches (3 < 15)"),  # fails
        CompassResult(True, math.radians(80.0), 100, 80, 0.8, "ok"),  # fits neither case
    ],
)
def test_an_unconfirmed_drift_counts_as_none(
    alone: World, bus: Bus, perception: PerceptionAdapter, second: CompassResult
) -> None:
    r = parts(WorldBody(alone, 1), AgentConfig(robot_id=1), _Unconfirmed(perception, second), bus)
    r.motion.walk_step(0.2)
    # the behaviour without the re-measurement: no drift, and the turn as commanded
    assert r.ctx.beliefs.heading == pytest.approx(NORTH + math.radians(30.0), abs=1e-9)
    assert r.ctx.beliefs.position == pytest.approx([0.0, 0.2], abs=1e-9)
    assert r.motion.drift_checks == 0 and r.motion.compass_failures == 2
