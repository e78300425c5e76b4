"""agent/phases/motion.py alone: every command journaled with the request id it is sent with
before the body is asked, and the beliefs that follow it, on a fake body and compass
(tests/phases/fakes.py). The compass on real renders: tests/body/test_drift.py.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from agent.body.base import Frame
from agent.config import AgentConfig
from agent.core.perception.compass import CompassResult
from agent.phases.context import NORTH, AgentFailure, Context
from agent.phases.motion import Motion
from agent.phases.reporting import Phase
from tests.phases.fakes import Clock, FakeBody, FakeBus, FakeFleet, context


class Compass:
    """A compass that reads ``dtheta`` (None: it fails) between any two images."""

    def __init__(self, dtheta: float | None) -> None:
        self.dtheta = dtheta

    def _read(self) -> CompassResult:
        if self.dtheta is None:
            return CompassResult(False, 0.0, 0, 0, 0.0, "no features")
        return CompassResult(True, self.dtheta, 50, 40, 0.8, "")

    def measure_turn(self, before: np.ndarray, after: np.ndarray) -> CompassResult:
        return self._read()

    def measure_walk(self, before: np.ndarray, after: np.ndarray) -> CompassResult:
        return self._read()


class Journal:
    """A recorder that checks, for each command, that the body has not been asked yet."""

    def __init__(self, body: FakeBody) -> None:
        self.body = body
        self.saved: list[tuple[str, float, int, int]] = []

    def save(self, command: str = "", value: float = 0.0, request_id: int = 0) -> None:
        self.saved.append((command, value, request_id, len(self.body.sent)))

    def reference(self, image: np.ndarray) -> None:
        """Not used by motion."""


def motion(dtheta: float | None = None) -> tuple[Motion, Context, FakeBody, Journal]:
    ctx = context(AgentConfig(robot_id=3), perception=Compass(dtheta), clock=Clock())  # type: ignore[arg-type]
    body = ctx.body
    assert isinstance(body, FakeBody)
    journal = Journal(body)
    ctx.report.journal = journal
    return Motion(ctx, FakeFleet(Clock())), ctx, body, journal  # type: ignore[arg-type]


def test_each_turn_is_journaled_with_the_request_id_it_is_sent_with() -> None:
    m, _, body, journal = motion()
    m.turn(0.1)
    m.turn(-0.2)
    assert body.sent == [("turn", 0.1, 101), ("turn", -0.2, 102)]
    assert journal.saved == [("turn", 0.1, 101, 0), ("turn", -0.2, 102, 1)]  # before each


def test_each_step_is_journaled_before_it_is_sent_and_dead_reckoned() -> None:
    m, ctx, body, journal = motion(dtheta=None)  # the compass fails: no drift believed
    m.walk_step(0.2)
    m.side_step(0.05)
    assert body.sent == [("walk", 0.2, 101), ("side", 0.05, 102)]
    assert journal.saved == [("walk", 0.2, 101, 0), ("side", 0.05, 102, 1)]
    assert ctx.beliefs.heading == NORTH
    assert ctx.beliefs.position == pytest.approx([-0.05, 0.2])  # north, then to the left
    assert m.steps == 2 and m.compass_failures == 2  # a sidestep is a step too


def test_rotate_follows_the_compass_and_says_how_far_is_left() -> None:
    m, ctx, body, _ = motion(dtheta=math.radians(10.0))
    ctx.report.status(Phase.MOVE, force=True)
    done = m.rotate(math.radians(30.0), label="turn to the axis")
    assert done == pytest.approx(math.radians(30.0))
    assert [c for c, _, _ in body.sent] == ["turn"] * 3
    assert ctx.beliefs.heading == pytest.approx(NORTH + math.radians(30.0))
    # the phase stays; the detail says how far is left (statuses held back meanwhile)
    assert ctx.report.phase is Phase.MOVE and m.last_frame is not None


def test_a_labelled_turn_is_said_once_under_way_and_an_unlabelled_one_is_not() -> None:
    """Within the status pace of the phase's first status, the labelled turn is said at
    once after its first step (journaled, sent: the heading in doubt); its progress is
    then held back."""
    m, ctx, _, _ = motion(dtheta=math.radians(10.0))
    bus = ctx.bus
    assert isinstance(bus, FakeBus)
    ctx.report.status(Phase.SEARCH, 0.0, "sweep at θ = 0°")
    m.rotate(math.radians(30.0))
    assert [s.detail for s in bus.statuses()] == ["sweep at θ = 0°"]
    m.rotate(math.radians(30.0), label="turn to θ = 180°")
    said = [s.detail for s in bus.statuses()]
    # said after its first 10° step, the next two held back
    assert said == ["sweep at θ = 0°", "turn to θ = 180°: +20.0° to go"], said


def test_a_contact_while_walking_stops_the_robot_with_where_it_believes_it_is() -> None:
    from agent.body.base import MotionResult

    m, _, body, _ = motion(dtheta=None)
    body.walk = lambda d, request_id=0: MotionResult("contact", 1.0, "robot 1")  # type: ignore[method-assign]
    with pytest.raises(AgentFailure, match=r"contact while walking at believed \[0.0, 0.2\]"):
        m.walk_step(0.2)


class Scripted:
    """A compass over images stamped with their sim time (``image[0, 0]``): it reads the
    true rotation between them (``heading`` at each time), or fails for the pairs in
    ``fails``; ``reads`` lists the (before, after) times it was asked."""

    def __init__(self, heading: dict[int, float], fails: set[tuple[int, int]]) -> None:
        self.heading, self.fails = heading, fails
        self.reads: list[tuple[int, int]] = []

    def measure_walk(self, before: np.ndarray, after: np.ndarray) -> CompassResult:
        tb, ta = int(before[0, 0]), int(after[0, 0])
        self.reads.append((tb, ta))
        if (tb, ta) in self.fails:
            return CompassResult(False, 0.0, 0, 0, 0.0, "matches disagree")
        return CompassResult(True, self.heading[ta] - self.heading[tb], 50, 40, 0.8, "")

    measure_turn = measure_walk


def stamped(compass: Scripted) -> tuple[Motion, Context]:
    ctx = context(AgentConfig(robot_id=3), perception=compass, clock=Clock())  # type: ignore[arg-type]
    body = ctx.body
    assert isinstance(body, FakeBody)
    ctx.report.journal = Journal(body)
    body.camera = lambda yaw: Frame(np.full((4, 4), body.t_sim), yaw, body.t_sim)  # type: ignore[method-assign]
    return Motion(ctx, FakeFleet(Clock())), ctx  # type: ignore[arg-type]


def test_a_failed_read_keeps_its_reference_and_the_next_step_measures_both_drifts() -> None:
    """Steps drifting +3° then +2°: the first read fails (its drift believed 0); the second
    reads against the image before the first step and the heading ends +5°, not +2°."""
    compass = Scripted({0: 0.0, 1: math.radians(3.0), 2: math.radians(5.0)}, {(0, 1)})
    m, ctx = stamped(compass)
    m.walk_step(0.2)
    assert ctx.beliefs.heading == NORTH and m.carried
    m.walk_step(0.2)
    assert compass.reads == [(0, 1), (0, 2)]
    assert ctx.beliefs.heading == pytest.approx(NORTH + math.radians(5.0))
    assert not m.carried and m.compass_failures == 1


def test_two_failed_reads_in_a_row_take_the_newest_image() -> None:
    """The image before may be the one that does not match: the reference is carried once."""
    h = {0: 0.0, 1: 0.01, 2: 0.03, 3: 0.06}
    compass = Scripted(h, {(0, 1), (0, 2)})
    m, ctx = stamped(compass)
    for _ in range(3):
        m.side_step(0.05)
    assert compass.reads == [(0, 1), (0, 2), (2, 3)]
    assert ctx.beliefs.heading == pytest.approx(NORTH + 0.03)  # step 3's drift only


def test_a_turn_after_a_failed_step_measures_the_step_drift_too() -> None:
    """The rotation control reads from the carried image: the belief ends where the robot
    faces, the failed step's drift included."""
    h = {0: 0.0, 1: math.radians(4.0), 2: math.radians(4.0 + 10.0)}
    compass = Scripted(h, {(0, 1)})
    m, ctx = stamped(compass)
    m.walk_step(0.2)
    m.rotate(math.radians(14.0))
    assert compass.reads[:2] == [(0, 1), (0, 2)]
    assert ctx.beliefs.heading == pytest.approx(NORTH + math.radians(14.0))
    assert not m.carried
