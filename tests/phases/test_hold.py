"""agent/phases/hold.py alone: ``done`` and the wait for every member, against a fake fleet
(tests/phases/fakes.py) on a fake clock. The alignment to the parent and the robot's own
check, with real renders, are in tests/body/test_runner_phases.py.

Robot 3 of the three robots of ``records()``, in ``done``.
"""

from __future__ import annotations

import dataclasses

import pytest

from agent.adapters import FormationAdapter
from agent.config import AgentConfig
from agent.core.formation.params import PlanParams
from agent.phases.context import AgentFailure, Context
from agent.phases.hold import Hold
from agent.phases.membership import Peer
from agent.phases.reporting import Phase
from agent.phases.waves import Itinerary
from tests.phases.fakes import Clock, FakeBus, FakeFleet, FakeMover, FakeStepper, context, records


@dataclasses.dataclass
class Rig:
    hold: Hold
    ctx: Context
    fleet: FakeFleet
    bus: FakeBus


def rig(peers: dict[int, Peer]) -> Rig:
    clock = Clock()
    cfg = AgentConfig(robot_id=3, fleet_size=3, wave_timeout=60.0, member_grace=10.0)
    ctx = context(cfg, FormationAdapter(), clock=clock)
    fleet, course = FakeFleet(clock, peers=dict(peers)), Itinerary()
    course.follow(FormationAdapter().plan(records(), PlanParams()))
    hold = Hold(ctx, fleet, FakeMover(ctx.beliefs), FakeStepper(ctx.beliefs), course)  # type: ignore[arg-type]
    assert isinstance(ctx.bus, FakeBus)
    return Rig(hold, ctx, fleet, ctx.bus)


def test_a_failed_member_stops_a_robot_that_was_done() -> None:
    """No 'formation held' around a hole: the fleet's one reason (jam.py rule 4; the
    rule itself in tests/phases/test_membership.py)."""
    r = rig(
        {
            1: Peer(alive=True, phase="done", seen_alive=True),
            2: Peer(alive=True, phase="failed", seen_alive=True),
        }
    )
    r.fleet.stop = "formation incomplete: robot 2 failed: robot 2 cannot reach its slot"
    with pytest.raises(AgentFailure, match="formation incomplete: robot 2 failed: robot 2 cannot"):
        r.hold.finish()
    assert r.bus.statuses()[0].phase == "done"  # said done, then stopped


def test_done_once_every_member_is_done() -> None:
    r = rig({i: Peer(alive=True, phase="done", seen_alive=True) for i in (1, 2)})
    r.hold.finish()
    said = r.bus.statuses()
    assert [(s.phase, s.progress, s.detail) for s in said] == [("done", 1.0, "formation held")]


def test_done_lingers_with_heartbeats_for_members_out_of_reach() -> None:
    r = rig({i: Peer(alive=False, phase="hold", seen_alive=True) for i in (1, 2)})
    r.ctx.report.status(Phase.DONE, 1.0, force=True)
    r.hold.wait_all((Phase.DONE, Phase.FAILED), Phase.DONE, "waiting for", linger=10.0)
    # returned once the linger passed, having re-published ``done`` meanwhile
    assert r.ctx.clock() >= r.ctx.cfg.member_grace
    assert r.bus.stats.published_count["status"] >= 3


def test_done_does_not_linger_once_every_member_is_seen_done() -> None:
    r = rig(
        {
            1: Peer(alive=False, phase="done", seen_alive=True),
            2: Peer(alive=True, phase="done", seen_alive=True),
        }
    )
    r.ctx.report.status(Phase.DONE, 1.0, force=True)
    r.hold.wait_all((Phase.DONE, Phase.FAILED), Phase.DONE, "waiting for", linger=10.0)
    assert r.ctx.clock() < 3.0  # no heartbeat was due
    assert r.bus.stats.published_count["status"] == 1


def test_without_linger_members_out_of_reach_are_not_waited_for() -> None:
    r = rig({i: Peer(alive=False, phase="hold", seen_alive=True) for i in (1, 2)})
    r.hold.wait_all((Phase.DONE, Phase.FAILED), Phase.DONE, "waiting for")
    assert r.ctx.clock() < 3.0


def test_a_fleet_that_never_gets_ready_to_march_stops_the_robot() -> None:
    r = rig({i: Peer(alive=True, phase="hold", seen_alive=True) for i in (1, 2)})
    with pytest.raises(AgentFailure, match="did not get ready to march in time"):
        r.hold.wait_all((Phase.MARCH, Phase.DONE, Phase.FAILED), Phase.MARCH, "waiting for")
    assert r.ctx.clock() >= r.ctx.cfg.wave_timeout
    assert r.bus.statuses()[-1].detail == "waiting for [1, 2]"
