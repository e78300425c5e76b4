"""Agreement by adoption (a lossy radio): a member already acting on the plan of exactly our
records is adopted, computed while the bus is pumped (agent/phases/waves.py
``plan_pumping``). agent/phases/agreeing.py alone, against a fake fleet
(tests/phases/fakes.py), on the real formation core."""

from __future__ import annotations

import pytest

from agent.adapters import FormationAdapter
from agent.config import AgentConfig
from agent.core.agreed_params import params_digest
from agent.core.agreement import Agreement
from agent.phases.agreeing import Agreeing
from agent.phases.membership import Peer
from agent.wire import DigestMsg, canonical_digest
from tests.phases.fakes import Clock, FakeFleet, context, records


def _waiting() -> tuple[Agreeing, FakeFleet]:
    """Robot 3 holding every record, no matching digest from 1 and 2 yet."""
    clock = Clock()
    ctx = context(AgentConfig(robot_id=3, fleet_size=3), FormationAdapter(), clock=clock)
    fleet = FakeFleet(clock)
    fleet.agreement = Agreement(3, records()[2], 0.0, fleet_size=3,
                                params=params_digest(ctx.cfg.agreed_params()),
                                digest_fn=canonical_digest)  # fmt: skip
    for i in (1, 2):
        fleet.peers[i] = Peer(alive=True, seen_alive=True)
        fleet.agreement.member_joined(i, 0.0)
        fleet.agreement.on_record(records()[i - 1], 0.0)
    return Agreeing(ctx, fleet), fleet  # type: ignore[arg-type]


def _claim(fleet: FakeFleet, i: int, plan_digest: str, params: str) -> None:
    """Robot ``i`` agreed with ``params`` and moves on the plan ``plan_digest``."""
    assert fleet.agreement is not None
    fleet.agreement.on_digest(
        DigestMsg(sender=i, round=0, digest="0" * 64, members=(i,), params=params), 0.0
    )
    fleet.peers[i] = Peer(alive=True, seen_alive=True, phase="move", plan_digest=plan_digest)


def _ours(a: Agreeing) -> str:
    return str(a.ctx.formation.plan(records(), a.ctx.cfg.plan_params()).digest)


def test_a_member_moving_on_the_plan_of_our_records_is_adopted() -> None:
    a, fleet = _waiting()
    agr = fleet.agreement
    assert agr is not None and agr.decide(0.0).kind == "wait"
    assert a.adopt_plan(agr) is None  # nobody has a plan yet
    _claim(fleet, 2, _ours(a), agr.params)
    d = a.adopt_plan(agr)
    assert d is not None and d.kind == "agreed" and d.members == (1, 2, 3)
    assert "robot(s) [2] act on the plan" in d.reason
    assert agr.decide(1.0) is d


@pytest.mark.parametrize("other", ["plan", "params"])
def test_a_member_on_another_plan_or_with_other_params_is_not_adopted(other: str) -> None:
    a, fleet = _waiting()
    agr = fleet.agreement
    assert agr is not None
    ours = _ours(a)
    _claim(fleet, 2, "f" * 64 if other == "plan" else ours,
           agr.params if other == "plan" else "e" * 64)  # fmt: skip
    assert a.adopt_plan(agr) is None
    assert agr.decide(0.0).kind != "agreed"


def test_no_adoption_without_every_members_record() -> None:
    a, fleet = _waiting()
    agr = fleet.agreement
    assert agr is not None
    _claim(fleet, 2, _ours(a), agr.params)
    del agr.records[1]
    assert a.adopt_plan(agr) is None


def test_no_adoption_when_the_records_change_while_we_plan() -> None:
    """The candidate plan is computed while the bus is pumped (agent/phases/waves.py
    ``plan_pumping``): a record that changes meanwhile makes the candidate stale, and
    nothing is adopted."""
    from dataclasses import replace

    a, fleet = _waiting()
    agr = fleet.agreement
    assert agr is not None
    _claim(fleet, 2, _ours(a), agr.params)
    plan = a.ctx.formation.plan

    def plan_then_change(*args: object) -> object:
        out = plan(*args)  # type: ignore[arg-type]
        agr.records[1] = replace(agr.records[1], neighbours=((1.0, 0.25),))
        return out

    a.ctx.formation.plan = plan_then_change  # type: ignore[method-assign]
    assert a.adopt_plan(agr) is None
    assert agr.decide(0.0).kind != "agreed"
