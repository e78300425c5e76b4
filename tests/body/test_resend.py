"""The motion in flight at a crash, asked again with its journaled request id (a resume that
survives a second crash).

On the zenoh world of tests/body/conftest.py (real zenoh sessions on loopback, the
world's loop in a thread of this process): robot 1 walks with a request id, its agent
"crashes" (the body is dropped) and a new body, the restarted agent's, asks for the same
walk with the same id. The world answers from its cache: the robot moves once, and the
resumed agent's belief follows the answer once.
"""

from __future__ import annotations

from collections.abc import Iterator

import pytest

from agent.adapters import PerceptionAdapter
from agent.body.zenoh_world import ZenohBody
from agent.config import AgentConfig
from agent.phases.context import NORTH
from agent.phases.roles import Crew
from agent.recovery.journal import JournalState
from agent.recovery.journaling import Journaling
from agent.recovery.resume import Resumption
from agent.recovery.runs import Verdict
from tests.body.conftest import FACING, Rig, parts, rig
from tests.phases.fakes import FakePlanner


@pytest.fixture(scope="module")
def zenoh() -> Iterator[Rig]:
    with rig("zenoh", FACING) as r:
        yield r


def restarted(r: Rig) -> ZenohBody:
    """Robot 1's body in a restarted agent (its own session's ids start elsewhere)."""
    body = r.make(1)
    assert isinstance(body, ZenohBody)
    return body


def test_a_repeated_walk_is_answered_from_the_worlds_cache(zenoh: Rig) -> None:
    crashed = restarted(zenoh)
    x0, y0, h0 = zenoh.world.pose(1)
    rid = crashed.new_request_id()
    first = crashed.walk(0.1, rid)
    assert first.status == "done"
    assert zenoh.world.pose(1)[1] == pytest.approx(y0 + 0.1, abs=1e-6)
    repeats = zenoh.server.motions.repeats
    again = restarted(zenoh).walk(0.1, rid)
    assert again == first  # the first result, t_sim included
    assert zenoh.server.motions.repeats == repeats + 1
    assert zenoh.world.pose(1) == pytest.approx((x0, y0 + 0.1, h0), abs=1e-6)  # moved once
    assert restarted(zenoh).walk(-0.1).status == "done"  # a fresh id: a new motion
    assert zenoh.world.pose(1) == pytest.approx((x0, y0, h0), abs=1e-6)


@pytest.mark.parametrize(("command", "moved"), [("walk", (0.0, 0.1)), ("side", (-0.1, 0.0))])
def test_a_resumed_agent_sends_the_motion_in_flight_again_and_moves_once(
    zenoh: Rig, perception: PerceptionAdapter, command: str, moved: tuple[float, float]
) -> None:
    """A walk, or a sidestep (journaled as ``side``), in flight at the crash:
    asked again with its id, answered from the world's cache, believed once (a sidestep
    across the heading: facing north, to the west)."""
    x0, y0, h0 = zenoh.world.pose(1)
    crashed = restarted(zenoh)
    rid = crashed.new_request_id()
    # journaled before the motion was sent; the agent crashed before it saw the reply
    st = JournalState(
        robot_id=1, phase="search", heading=NORTH, command=command, command_value=0.1,
        request_id=rid,
    )  # fmt: skip
    send = crashed.walk if command == "walk" else crashed.side
    assert send(0.1, rid).status == "done"
    body = restarted(zenoh)
    r = parts(body, AgentConfig(robot_id=1, fleet_size=2), perception, body.bus)
    crew = Crew(r.ctx, r.membership, r.motion, FakePlanner(r.ctx, r.course), r.course, r.search)
    resumption = Resumption(Journaling(None, r.ctx, r.membership, r.course, r.search), crew)
    repeats = zenoh.server.motions.repeats
    assert resumption.resume(st, Verdict(True, "peers searching")) == ("search", None)
    assert zenoh.server.motions.repeats == repeats + 1  # answered from the cache
    want = (x0 + moved[0], y0 + moved[1], h0)
    assert zenoh.world.pose(1) == pytest.approx(want, abs=1e-6)  # once
    assert r.ctx.beliefs.heading == pytest.approx(NORTH)
    # the belief followed the motion once (before the new search resets the frame)
    assert r.ctx.beliefs.position == pytest.approx(moved, abs=1e-9)
    back = body.walk if command == "walk" else body.side
    assert back(-0.1).status == "done"
