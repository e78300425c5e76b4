"""agent/phases/research.py alone: re-search rounds (NAO paper 4.1.3 rule 2) against a fake
fleet, mover and search (tests/phases/fakes.py), on the real formation core's decision.

Robot 3; in ``lost_records()`` it sees nobody and nobody sees it, so it is the one
outside the fleet. The walk in the world is in tests/body/test_explore.py.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from agent.adapters import FormationAdapter
from agent.config import AgentConfig
from agent.core.agreement import Agreement, Decision
from agent.phases.context import AgentFailure, Context
from agent.phases.membership import Peer
from agent.phases.research import Research
from agent.wire import NeighborRecordMsg, canonical_digest
from tests.phases.fakes import Clock, FakeFleet, FakeMover, FakeSurveyor, context, records


class Blind:
    """A perception that sees no NAO (the exploration's way is always clear)."""

    def detect(self, image: np.ndarray, yaw: float) -> list[object]:
        return []

    def to_fixed(self, dets: list[object], heading: float) -> tuple[np.ndarray, ...]:
        return np.zeros((0, 2)), np.zeros(0), np.zeros(0)


@dataclasses.dataclass
class Rig:
    research: Research
    ctx: Context
    fleet: FakeFleet
    mover: FakeMover
    search: FakeSurveyor


def rig(**cfg: object) -> Rig:
    clock = Clock()
    config = AgentConfig(robot_id=3, fleet_size=3, **cfg)  # type: ignore[arg-type]
    ctx = context(config, FormationAdapter(), Blind(), clock)  # type: ignore[arg-type]
    fleet, mover, search = FakeFleet(clock), FakeMover(ctx.beliefs), FakeSurveyor(3)
    return Rig(Research(ctx, fleet, mover, search), ctx, fleet, mover, search)  # type: ignore[arg-type]


def lost_records() -> tuple[NeighborRecordMsg, ...]:
    """Robots 1 and 2 see each other; robot 3 sees nobody and nobody sees it."""
    return (
        NeighborRecordMsg(sender=1, round=0, neighbours=((-1.0, 0.1),)),
        NeighborRecordMsg(sender=2, round=0, neighbours=((1.0, -0.1),)),
        NeighborRecordMsg(sender=3, round=0, neighbours=()),
    )


def test_research_returns_nothing_for_a_connected_fleet() -> None:
    r = rig()
    assert r.research.next_round(Decision("agreed", records=records())) is None
    assert r.search.round == 0 and r.search.searches == 0


def test_research_stops_the_fleet_after_the_last_round() -> None:
    r = rig(research_rounds=0)
    with pytest.raises(AgentFailure, match=r"robots \[3\] outside .* after 0 re-search round"):
        r.research.next_round(Decision("agreed", records=lost_records()))
    assert r.search.round == 0  # nobody moved on to another round


def test_a_robot_outside_explores_and_searches_again_in_the_next_round() -> None:
    r = rig()
    recs = lost_records()
    r.fleet.agreement = Agreement(3, recs[2], 0.0, fleet_size=3, digest_fn=canonical_digest)
    move = FormationAdapter().research(recs, 1, r.ctx.cfg.explore_step).move(3)
    record = r.research.next_round(Decision("agreed", records=recs))
    assert record is not None and record.round == 1 and r.search.round == 1
    assert r.fleet.agreement is None and len(r.fleet.retired) == 1  # the round is over
    assert sum(r.mover.walks) == pytest.approx(float(np.hypot(*move)), abs=0.01)
    assert np.allclose(r.ctx.beliefs.position, 0.0)  # the new record's origin: here
    assert r.mover.last_frame is None and r.search.searches == 1
    said = r.ctx.bus.statuses()  # type: ignore[attr-defined]
    assert said[0].phase == "explore" and said[0].detail.startswith("round 1: fleet not connected")


def test_a_robot_inside_waits_for_the_searchers_then_searches_again() -> None:
    r = rig()
    recs = (  # robot 1 outside: robots 2 and 3 (this one) see each other
        NeighborRecordMsg(sender=1, round=0, neighbours=()),
        NeighborRecordMsg(sender=2, round=0, neighbours=((1.0, -0.1),)),
        NeighborRecordMsg(sender=3, round=0, neighbours=((-1.0, 0.1),)),
    )
    r.fleet.peers[1] = Peer(alive=True, phase="explore", seen_alive=True)
    r.fleet.early_records[1] = NeighborRecordMsg(sender=1, round=1, neighbours=())
    record = r.research.next_round(Decision("agreed", records=recs))
    assert record is not None and record.round == 1 and r.mover.walks == []
    said = r.ctx.bus.statuses()[0]  # type: ignore[attr-defined]
    assert (said.phase, said.detail) == (
        "explore",
        "round 1: waiting for robots [1] to explore and search",
    )


def test_a_waiting_robot_stops_when_a_searcher_failed() -> None:
    r = rig()
    r.search.begin_round(1)
    r.fleet.peers[1] = Peer(alive=True, phase="failed", seen_alive=True)
    with pytest.raises(AgentFailure, match="robot 1 failed in re-search round 1"):
        r.research.wait_for_searchers((1,))
    r.fleet.peers[1] = Peer(alive=False, phase="explore", seen_alive=True)
    with pytest.raises(AgentFailure, match="robot 1 left in re-search round 1"):
        r.research.wait_for_searchers((1,))


def test_a_waiting_robot_stops_when_a_searcher_takes_too_long() -> None:
    r = rig(research_timeout=0.3)
    r.search.begin_round(1)
    r.fleet.peers[1] = Peer(alive=True, phase="explore", seen_alive=True)
    with pytest.raises(AgentFailure, match=r"robots \[1\] did not search again within 0.3 s"):
        r.research.wait_for_searchers((1,))
    # a record of the round from the searcher ends the wait
    r.fleet.early_records[1] = NeighborRecordMsg(sender=1, round=1, neighbours=())
    r.research.wait_for_searchers((1,))


def test_a_digest_of_the_round_ends_the_wait_too() -> None:
    from agent.wire import DigestMsg

    r = rig()
    r.search.begin_round(2)
    r.fleet.peers[1] = Peer(alive=True, phase="explore", seen_alive=True)
    r.fleet.early_digests[1] = DigestMsg(sender=1, round=2, digest="ab" * 32, members=(1,))
    r.research.wait_for_searchers((1,))
    r.fleet.early_digests[1] = DigestMsg(sender=1, round=1, digest="ab" * 32, members=(1,))
    with pytest.raises(AgentFailure, match="did not search again"):
        r.research.wait_for_searchers((1,))


def test_research_config_is_validated() -> None:
    for kw, match in (
        ({"research_rounds": -1}, "research_rounds"),
        ({"research_rounds": 11}, "research_rounds"),
        ({"explore_step": 0.1}, "explore_step"),
        ({"explore_step": math.inf}, "explore_step"),
        ({"research_timeout": 0.0}, "research_timeout"),
    ):
        with pytest.raises(ValueError, match=match):
            AgentConfig(robot_id=1, **kw)  # type: ignore[arg-type]
    assert AgentConfig(robot_id=1).agreed_params()["research_rounds"] == 2


def test_nobody_walks_when_no_robot_saw_any_other() -> None:
    """A fleet whose records are all empty stops at once, naming the calibration: its
    robots may not recognise each other, and could not see each other on the way."""
    empty = tuple(NeighborRecordMsg(sender=i, round=0, neighbours=()) for i in (1, 2, 3))
    r = rig()
    with pytest.raises(AgentFailure, match=r"no robot saw any other.*calibration built-in"):
        r.research.next_round(Decision("agreed", records=empty))
    assert r.mover.walks == [] and r.search.round == 0
    lab = rig(calibration="ab" * 32)
    with pytest.raises(AgentFailure, match="calibration abababababab"):
        lab.research.next_round(Decision("agreed", records=empty))
