"""agent/phases/transitions/reshaping.py and its parts in the membership, the itinerary and the hold:
the operator's command heard, kept, deferred or refused with the reason; the transition
planned from the held plan and walked; waits that tell the old plan from the new. Against
the fakes of tests/phases/fakes.py on a fake clock; the whole fleet, with real processes,
is tests/system/test_reshape.py.

Robot 3 of the three robots of ``records()``.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from agent.adapters import FormationAdapter
from agent.config import AgentConfig
from agent.core.formation.params import PlanParams
from agent.core.formation.reshape import transition_plan
from agent.core.formation.shape.spec import BUILTIN
from agent.core.formation.view.own_frame import in_own_frame
from agent.net.bus import Event
from agent.phases.context import AgentFailure, Context
from agent.phases.hold import Hold
from agent.phases.membership import COMMANDS_KEPT, Membership, Peer, on_plan
from agent.phases.reporting import Phase
from agent.phases.transitions.reshaping import Reshaping
from agent.phases.waves import Itinerary
from agent.wire import KEY_RESHAPE, ReshapeMsg, StatusMsg
from tests.phases.fakes import Clock, FakeBus, FakeFleet, FakeMover, FakeStepper, context, records

LINE = BUILTIN["line"]
OLD, NEW = "ab" * 32, "cd" * 32


def command(base: str, number: int = 1, **kw: object) -> ReshapeMsg:
    fields: dict[str, object] = {
        "command": number, "base": base, "name": "line", "rule": "line", "orient": "width",
        "shape_digest": LINE.digest,
    }  # fmt: skip
    fields.update(kw)
    return ReshapeMsg(**fields)  # type: ignore[arg-type]


@dataclasses.dataclass
class Rig:
    shaping: Reshaping
    ctx: Context
    fleet: FakeFleet
    course: Itinerary
    commands: dict[str, ReshapeMsg]
    walks: list[str]

    @property
    def said(self) -> list[str]:
        assert isinstance(self.ctx.bus, FakeBus)
        return [s.detail for s in self.ctx.bus.statuses()]


def rig(wait: float = 30.0, psi: float = 0.4) -> Rig:
    clock = Clock()
    cfg = AgentConfig(robot_id=3, fleet_size=3, reshape_wait=wait)
    ctx = context(cfg, FormationAdapter(), clock=clock)
    fleet, course = FakeFleet(clock), Itinerary()
    common = FormationAdapter().plan(records(), PlanParams())
    common = dataclasses.replace(common, psi=np.array([0.0, 0.2, psi]))
    course.follow(in_own_frame(common, psi), common)
    commands: dict[str, ReshapeMsg] = {}
    walks: list[str] = []
    shaping = Reshaping(ctx, fleet, commands, course, lambda: walks.append(course.digest))
    return Rig(shaping, ctx, fleet, course, commands, walks)


def test_without_a_wait_the_run_ends_at_done() -> None:
    r = rig(wait=0.0)
    r.shaping.run()
    assert r.said == [] and r.walks == []


def test_no_command_within_the_wait_ends_the_run_listening() -> None:
    r = rig(wait=30.0)
    r.shaping.run()
    assert r.ctx.clock() >= 30.0
    assert r.said[0].startswith("formation held; listening for a reshape command (30 s)")
    assert r.walks == []


def test_a_command_for_the_held_plan_is_planned_and_walked_once() -> None:
    r = rig()
    held, held_own = r.course.common, r.course.plan
    mine = held_own.robot(3)
    r.ctx.beliefs.position = np.asarray(mine.target - mine.start) + 0.02  # held, corrected
    r.commands[held.digest] = command(held.digest)
    r.shaping.run()
    want = transition_plan(held, LINE, PlanParams())
    assert r.walks == [want.digest] and r.course.digest == want.digest
    assert r.course.shape == LINE and r.course.history == (held.digest, want.digest)
    np.testing.assert_array_equal(r.course.common.targets(), want.targets())
    # the belief frame moved to the new plan's start: the held slot, plus the correction
    np.testing.assert_allclose(r.ctx.beliefs.position, [0.02, 0.02], atol=1e-12)
    own = r.course.plan.robot(3)
    np.testing.assert_allclose(own.start, mine.target, atol=1e-12)
    assert r.ctx.report.figures.plan_digest == want.digest
    assert any(d.startswith("reshape 1: line") for d in r.said)
    assert r.shaping.taken == [("line", want.digest)]


def test_a_command_for_another_plan_is_refused_with_the_reason() -> None:
    r = rig(wait=5.0)
    r.commands[OLD] = command(OLD, 4)
    r.shaping.run()
    assert r.walks == []
    refused = [d for d in r.said if "refused" in d]
    assert len(refused) == 1  # once, however long it listens
    assert refused[0].startswith(f"reshape 4 to line refused: it reshapes plan {OLD[:12]}")


@pytest.mark.parametrize(
    ("kw", "why"),
    [
        ({"shape_digest": NEW}, "the command says cdcdcdcdcdcd"),
        ({"rule": "spiral"}, "shape rule must be one of"),
        ({"name": "two", "rule": "tree", "slots": ((0, 0.8, 3.0),)}, "has 2 slots, too few"),
    ],
)
def test_a_command_the_core_refuses_leaves_the_fleet_holding(
    kw: dict[str, object], why: str
) -> None:
    r = rig(wait=5.0)
    held = r.course.digest
    if kw.get("rule") == "tree":
        from agent.core.formation.shape.spec import TREE, Shape

        kw["shape_digest"] = Shape("two", TREE, ((0, 0.8, 3.0),), "width").digest
    r.commands[held] = command(held, **kw)
    r.shaping.run()
    assert r.walks == [] and r.course.digest == held
    (refused,) = [d for d in r.said if "refused" in d]
    assert why in refused


def test_a_member_failed_stops_the_listening_robot() -> None:
    r = rig()
    r.fleet.stop = "formation incomplete: robot 2 failed"
    with pytest.raises(AgentFailure, match="robot 2 failed"):
        r.shaping.run()


# --------------------------------------------------------------------------- membership


def membership(phase: Phase = Phase.DONE) -> Membership:
    ctx = context(AgentConfig(robot_id=3, fleet_size=3), FormationAdapter(), clock=Clock())
    if phase != Phase.START:
        ctx.report.status(phase, 0.5, force=True)
    return Membership(ctx)


def test_the_membership_hears_the_command_on_its_key_only() -> None:
    m = membership()
    m.start()
    assert isinstance(m.ctx.bus, FakeBus) and KEY_RESHAPE in m.ctx.bus.subscribed
    m.handle(Event("msg", "nao/2/status", command(OLD)))  # not on its key: ignored
    assert m.commands == {}
    m.handle(Event("msg", KEY_RESHAPE, command(OLD, 2)))
    m.handle(Event("msg", KEY_RESHAPE, command(OLD, 1)))  # older: kept is the newest
    m.handle(Event("msg", KEY_RESHAPE, command(NEW, 1)))
    assert {b: c.command for b, c in m.commands.items()} == {OLD: 2, NEW: 1}


def test_the_commands_kept_are_bounded() -> None:
    m = membership()
    bases = [f"{k:064x}" for k in range(COMMANDS_KEPT + 3)]
    for b in bases:
        m.take_command(command(b))
    assert list(m.commands) == bases[-COMMANDS_KEPT:]


def test_a_command_before_the_fleet_holds_is_deferred_and_said_so() -> None:
    m = membership(Phase.MOVE)
    m.take_command(command(OLD, 7))
    assert isinstance(m.ctx.bus, FakeBus)
    last = m.ctx.bus.statuses()[-1]
    assert last.phase == "move"
    assert last.detail == "reshape 7 to line deferred until the fleet holds"
    assert OLD in m.commands  # kept for when it holds


def test_on_plan_tells_the_old_plan_from_the_new() -> None:
    done_old = Peer(alive=True, phase="done", plan_digest=OLD)
    assert on_plan(done_old, ("done",), "")
    assert on_plan(done_old, ("done",), OLD)
    assert not on_plan(done_old, ("done",), NEW)  # not yet started the new plan
    assert on_plan(Peer(phase="failed", plan_digest=OLD), ("done", "failed"), NEW)
    assert on_plan(Peer(phase="hold"), ("hold",), NEW)  # no digest shown: counted
    assert not on_plan(Peer(phase="move", plan_digest=NEW), ("hold",), NEW)


def test_wave_and_parent_waits_need_the_new_plan() -> None:
    """A parent ``done`` on the held plan has not started the reshape's: a child waits."""
    first = FormationAdapter().plan(records(), PlanParams())
    plan = transition_plan(first, LINE, PlanParams())
    me = next(r for r in plan.robots if r.parent >= 0)  # a child in the line
    clock = Clock()
    cfg = AgentConfig(robot_id=me.robot_id, fleet_size=3, wave_timeout=5.0)
    ctx = context(cfg, FormationAdapter(), clock=clock)
    course = Itinerary()
    course.follow(first)
    course.follow(plan, plan, LINE)
    old = first.digest
    peers = {
        i: Peer(alive=True, seen_alive=True, phase="done", plan_digest=old)
        for i in plan.ids
        if i != me.robot_id
    }
    fleet = FakeFleet(clock, peers=peers)
    hold = Hold(ctx, fleet, FakeMover(ctx.beliefs), FakeStepper(ctx.beliefs), course)  # type: ignore[arg-type]
    why = hold._wait_for_parent(int(me.parent))
    assert why.startswith(f"parent {me.parent} did not finish in time")
    # done on the old plan: still waited for; on a plan never followed: ahead, done
    assert not hold._finished(peers[int(me.parent)], (Phase.DONE,), Phase.DONE)
    ahead = Peer(alive=True, phase="plan", plan_digest=NEW)
    assert hold._finished(ahead, (Phase.DONE,), Phase.DONE)
    assert not hold._finished(ahead, (Phase.MARCH,), Phase.MARCH)


def test_a_new_plan_starts_with_none_of_the_old_figures() -> None:
    r = rig()
    rep = r.ctx.report
    rep.show_plan(OLD, 1)
    rep.show_walked(2.5)
    rep.show_shift((0.1, 0.0))
    rep.show_plan(OLD, 1)  # the same plan: kept
    assert rep.figures.walked == 2.5
    rep.show_plan(NEW, 0)
    assert rep.figures.walked == 0.0 and rep.figures.shift == (0.0, 0.0)
    assert (rep.figures.plan_digest, rep.figures.wave) == (NEW, 0)
    assert isinstance(StatusMsg(sender=3, phase="done"), StatusMsg)
