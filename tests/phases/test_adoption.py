"""Agreement by adoption (a lossy radio): a member already acting on the plan of exactly our
records is adopted, computed while the bus is pumped (agent/phases/pumping.py)."""

from __future__ import annotations

import pytest

from agent.adapters import FormationAdapter, PerceptionAdapter
from agent.body.zenoh_world import ZenohBody
from agent.config import AgentConfig
from agent.core.agreed_params import params_digest
from agent.core.agreement import Agreement
from agent.net.bus import Bus, BusConfig
from agent.phases.runner import Runner
from agent.wire import StatusMsg, canonical_digest
from tests.phases.test_runner import records


@pytest.fixture(scope="module")
def perception() -> PerceptionAdapter:
    return PerceptionAdapter()


def _waiting(perception: PerceptionAdapter) -> tuple[Runner, Bus]:
    """Robot 3 holding every record, no matching digest from 1 and 2 yet."""
    from agent.net.bus import Event

    bus = Bus(BusConfig(multicast_scouting=False))
    r = Runner(bus, ZenohBody(bus, 3), AgentConfig(robot_id=3, fleet_size=3), perception,
               FormationAdapter())  # fmt: skip
    r.membership.agreement = Agreement(3, records()[2], 0.0, fleet_size=3,
                            params=params_digest(r.ctx.cfg.agreed_params()), digest_fn=canonical_digest)  # fmt: skip
    for i in (1, 2):
        r.membership.handle(Event("alive", f"nao/alive/{i}", robot_id=i))
        r.membership.agreement.on_record(records()[i - 1], 0.0)
    return r, bus


def _claim(r: Runner, i: int, plan_digest: str, params: str) -> None:
    from agent.net.bus import Event
    from agent.wire import DigestMsg

    assert r.membership.agreement is not None
    r.membership.agreement.on_digest(
        DigestMsg(sender=i, round=0, digest="0" * 64, members=(i,), params=params), 0.0
    )
    r.membership.handle(Event("msg", f"nao/{i}/status", StatusMsg(sender=i, phase="move",
                                                        plan_digest=plan_digest)))  # fmt: skip


def test_a_member_moving_on_the_plan_of_our_records_is_adopted(
    perception: PerceptionAdapter,
) -> None:
    r, bus = _waiting(perception)
    try:
        agr = r.membership.agreement
        assert agr is not None and agr.decide(0.0).kind == "wait"
        assert r.agreeing.adopt_plan(agr) is None  # nobody has a plan yet
        ours = str(r.ctx.formation.plan(records(), r.ctx.cfg.plan_params()).digest)
        _claim(r, 2, ours, agr.params)
        d = r.agreeing.adopt_plan(agr)
        assert d is not None and d.kind == "agreed" and d.members == (1, 2, 3)
        assert "robot(s) [2] act on the plan" in d.reason
        assert agr.decide(1.0) is d
    finally:
        bus.close()


@pytest.mark.parametrize("other", ["plan", "params"])
def test_a_member_on_another_plan_or_with_other_params_is_not_adopted(
    perception: PerceptionAdapter, other: str
) -> None:
    r, bus = _waiting(perception)
    try:
        agr = r.membership.agreement
        assert agr is not None
        ours = str(r.ctx.formation.plan(records(), r.ctx.cfg.plan_params()).digest)
        _claim(r, 2, "f" * 64 if other == "plan" else ours,
               agr.params if other == "plan" else "e" * 64)  # fmt: skip
        assert r.agreeing.adopt_plan(agr) is None
        assert agr.decide(0.0).kind != "agreed"
    finally:
        bus.close()


def test_no_adoption_when_the_records_change_while_we_plan(
    perception: PerceptionAdapter,
) -> None:
    """The candidate plan is computed while the bus is pumped (agent/phases/pumping.py):
    a record that changes meanwhile makes the candidate stale, and nothing is adopted."""
    from dataclasses import replace

    r, bus = _waiting(perception)
    try:
        agr = r.membership.agreement
        assert agr is not None
        ours = str(r.ctx.formation.plan(records(), r.ctx.cfg.plan_params()).digest)
        _claim(r, 2, ours, agr.params)
        plan = r.ctx.formation.plan

        def plan_then_change(*args: object) -> object:
            out = plan(*args)  # type: ignore[arg-type]
            agr.records[1] = replace(agr.records[1], neighbours=((1.0, 0.25),))
            return out

        r.ctx.formation.plan = plan_then_change  # type: ignore[method-assign]
        assert r.agreeing.adopt_plan(agr) is None
        assert agr.decide(0.0).kind != "agreed"
    finally:
        bus.close()
