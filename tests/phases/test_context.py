"""agent/phases/context.py: what the collaborators share is small and read-only; every
other piece of a robot's state has one owner (docs/design.md §2)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from agent.config import AgentConfig
from agent.phases.context import NORTH, Context
from agent.phases.reporting import Phase, Reporter
from tests.phases.fakes import Clock, context


def test_the_context_is_eight_read_only_fields() -> None:
    assert [f.name for f in dataclasses.fields(Context)] == [
        "bus", "body", "cfg", "perception", "formation", "clock", "beliefs", "report",
    ]  # fmt: skip
    ctx = context(AgentConfig(robot_id=3))
    with pytest.raises(dataclasses.FrozenInstanceError):
        ctx.cfg = AgentConfig(robot_id=4)  # type: ignore[misc]


def test_a_fresh_robot_faces_north_at_its_origin_before_any_phase() -> None:
    clock = Clock(5.0)
    ctx = context(AgentConfig(robot_id=3, fleet_size=3), clock=clock)
    assert ctx.me == 3 and ctx.clock() == 5.0
    assert ctx.beliefs.heading == NORTH and np.array_equal(ctx.beliefs.position, [0.0, 0.0])
    assert ctx.beliefs.compass_gain == 1.0
    assert isinstance(ctx.report, Reporter) and ctx.report.phase is Phase.START
