"""agent/phases/motion.py alone: every command journaled with the request id it is sent with
before the body is asked, and the beliefs that follow it, on a fake body and compass
(tests/phases/fakes.py). The compass on real renders: tests/body/test_drift.py.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from agent.config import AgentConfig
from agent.core.perception.compass import CompassResult
from agent.phases.context import NORTH, AgentFailure, Context
from agent.phases.motion import Motion
from agent.phases.reporting import Phase
from tests.phases.fakes import Clock, FakeBody, FakeFleet, context


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


def test_a_contact_while_walking_stops_the_robot_with_where_it_believes_it_is() -> None:
    from agent.body.base import MotionResult

    m, _, body, _ = motion(dtheta=None)
    body.walk = lambda d, request_id=0: MotionResult("contact", 1.0, "robot 1")  # type: ignore[method-assign]
    with pytest.raises(AgentFailure, match=r"contact while walking at believed \[0.0, 0.2\]"):
        m.walk_step(0.2)
