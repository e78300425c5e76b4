"""agent/phases/waves.py alone: the plan made, the wait for the earlier waves and the move,
against a fake fleet, mover and stepper (tests/phases/fakes.py), on the real formation
core; and the :class:`~agent.phases.waves.Itinerary` that owns the plan.

Robot 3 of the three robots of ``records()``; the wait's timeout passes on a fake clock.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from agent.adapters import FormationAdapter
from agent.config import AgentConfig
from agent.core.agreement import Decision
from agent.core.formation.params import PlanParams
from agent.core.formation.plan import Plan
from agent.phases.context import NORTH, AgentFailure, Context
from agent.phases.membership import Peer
from agent.phases.reporting import Phase
from agent.phases.waves import Itinerary, Waves
from agent.wire import canonical_digest
from tests.phases.fakes import Clock, FakeFleet, FakeMover, FakeStepper, context, records


@dataclasses.dataclass
class Rig:
    waves: Waves
    ctx: Context
    fleet: FakeFleet
    course: Itinerary
    mover: FakeMover
    steps: FakeStepper


def rig(formation: object = None, **cfg: object) -> Rig:
    clock = Clock(1000.0)
    config = AgentConfig(robot_id=3, fleet_size=3, **{"wave_timeout": 2.0, **cfg})  # type: ignore[arg-type]
    ctx = context(config, formation or FormationAdapter(), clock=clock)  # type: ignore[arg-type]
    fleet, course = FakeFleet(clock), Itinerary()
    mover, steps = FakeMover(ctx.beliefs), FakeStepper(ctx.beliefs)
    return Rig(Waves(ctx, fleet, mover, steps, course), ctx, fleet, course, mover, steps)  # type: ignore[arg-type]


def common_plan() -> Plan:
    return FormationAdapter().plan(records(), PlanParams())


def waiting(ids: tuple[int, ...], arcs: tuple[float, ...] | None = None) -> Rig:
    """Robot 3 following the common plan, waiting for ``ids`` (its ``after`` list), each
    until it has walked ``arcs`` of its path (None: until it holds its slot)."""
    r = rig()
    plan = common_plan()
    change = {"after": ids} if arcs is None else {"after": ids, "after_at": arcs}
    robots = tuple(
        dataclasses.replace(rp, **change) if rp.robot_id == 3 else rp  # type: ignore[arg-type]
        for rp in plan.robots
    )
    r.course.follow(dataclasses.replace(plan, robots=robots, digest="ab" * 32))
    return r


# --------------------------------------------------------------------------- the itinerary


def test_the_itinerary_has_no_plan_before_one_is_agreed() -> None:
    course = Itinerary()
    assert course.planned is None and course.digest == "" and course.leg == 0
    assert course.final_heading == NORTH
    with pytest.raises(AgentFailure, match="no plan yet"):
        _ = course.plan
    plan = common_plan()
    course.follow(plan)
    course.at_leg(2)
    course.face(0.3)
    assert course.plan is plan and course.digest == plan.digest
    assert (course.leg, course.final_heading) == (2, 0.3)


# --------------------------------------------------------------------------- PLAN


def test_make_plan_plans_with_the_agents_parameters() -> None:
    r = rig(orientation="cp", strategy="paper")
    recs = records()
    plan = r.waves.make_plan(Decision("agreed", records=recs, digest=canonical_digest(recs)))
    assert plan.axis == pytest.approx(math.pi / 2)
    assert plan.digest == FormationAdapter().plan(recs, r.ctx.cfg.plan_params()).digest
    # followed, served, the agreed sessions pinned, and said in the status
    assert r.course.plan is plan and r.course.digest == plan.digest
    assert r.fleet.served is not None and r.fleet.served.digest == canonical_digest(recs)
    assert r.fleet.pinned == ({1, 2, 3}, plan.digest)
    said = r.ctx.bus.statuses()[-1]  # type: ignore[attr-defined]
    assert (said.phase, said.progress, said.plan_digest) == ("plan", 1.0, plan.digest)
    assert said.wave == plan.robot(3).wave == r.ctx.report.figures.wave


def test_a_robot_the_plan_leaves_out_stands_still_with_the_reason() -> None:
    class LeavesOut(FormationAdapter):
        def plan(self, msgs, params):  # type: ignore[no-untyped-def]
            plan = super().plan(msgs, params)
            return dataclasses.replace(plan, excluded=(3,), verdict="robot 3 does not fit")

    r = rig(LeavesOut())
    recs = records()
    with pytest.raises(AgentFailure, match="left out of the plan, standing still: robot 3 does"):
        r.waves.make_plan(Decision("agreed", records=recs, digest=canonical_digest(recs)))
    assert r.course.planned is not None and r.course.plan.excluded == (3,)
    assert r.ctx.report.figures.plan_digest == r.course.digest and r.ctx.report.figures.wave == -1
    assert r.fleet.pinned is None and r.fleet.served is None  # it takes no part


def test_a_plan_the_core_refuses_stops_the_robot() -> None:
    class Refuses(FormationAdapter):
        def plan(self, msgs, params):  # type: ignore[no-untyped-def]
            raise ValueError("two robots in one place")

    r = rig(Refuses())
    with pytest.raises(AgentFailure, match="planning failed on the agreed records: two robots"):
        r.waves.make_plan(Decision("agreed", records=records(), digest="ab" * 32))
    assert r.course.planned is None


# --------------------------------------------------------------------------- WAIT


def test_a_robot_with_an_empty_after_list_starts_at_once() -> None:
    r = waiting(())
    r.fleet.peers[1] = Peer(alive=True, phase="move", seen_alive=True)
    r.waves.wait_for_earlier_waves()  # returns although robot 1 still moves


def test_waits_pass_when_earlier_waves_hold() -> None:
    r = waiting((1, 2))
    for i in (1, 2):
        r.fleet.peers[i] = Peer(alive=True, phase="hold", seen_alive=True)
    r.waves.wait_for_earlier_waves()


def test_an_earlier_wave_done_on_another_plan_does_not_hold_this_one() -> None:
    """After a reshape a member still ``done`` on the held plan has not started the new
    one (agent/phases/transitions/reshaping.py): it is waited for, until it holds this plan."""
    r = waiting((1, 2))
    for i in (1, 2):
        r.fleet.peers[i] = Peer(alive=True, phase="done", seen_alive=True, plan_digest="cd" * 32)
    with pytest.raises(AgentFailure, match=r"robots \[1, 2\] of earlier waves did not pass"):
        r.waves.wait_for_earlier_waves()
    for i in (1, 2):
        r.fleet.peers[i] = Peer(alive=True, phase="hold", seen_alive=True, plan_digest="ab" * 32)
    r.waves.wait_for_earlier_waves()


def test_member_of_an_earlier_wave_that_leaves_stops_us() -> None:
    r = waiting((1, 2))
    r.fleet.peers[1] = Peer(alive=False, phase="move", seen_alive=True)
    r.fleet.peers[2] = Peer(alive=True, phase="hold", seen_alive=True)
    with pytest.raises(AgentFailure, match=r"robot 1 of wave .* left before holding"):
        r.waves.wait_for_earlier_waves()


def test_failed_member_of_an_earlier_wave_stops_us() -> None:
    r = waiting((1, 2))
    r.fleet.peers[1] = Peer(alive=True, phase="hold", seen_alive=True)
    r.fleet.peers[2] = Peer(alive=True, phase="failed", seen_alive=True)
    with pytest.raises(AgentFailure, match=r"robot 2 of wave \d+ failed"):
        r.waves.wait_for_earlier_waves()


def test_the_fleets_reason_to_stop_stops_the_wait() -> None:
    """The membership names a failed member of the plan (jam.py rule 4): the wait stops
    with that reason (tests/phases/test_membership.py for the rule itself)."""
    r = waiting((1, 2))
    r.fleet.peers[1] = Peer(alive=True, phase="hold", seen_alive=True)
    r.fleet.peers[2] = Peer(alive=True, phase="failed", seen_alive=True)
    r.fleet.stop = "formation incomplete: robot 2 failed"
    with pytest.raises(AgentFailure, match=r"formation incomplete: robot 2 failed"):
        r.waves.wait_for_earlier_waves()


def test_a_robot_blocked_by_us_makes_us_yield() -> None:
    """Jams (agent/core/formation/waves/jam.py rule 2): robot 1 cannot reach its slot
    because robot 3 (us, not moved yet) stands too near it, and we wait for robot 1."""
    r = waiting((1, 2))
    r.fleet.peers[1] = Peer(alive=True, phase="move", seen_alive=True, blocked_by=3)
    r.fleet.peers[2] = Peer(alive=True, phase="hold", seen_alive=True)
    start = r.ctx.clock()
    r.waves.wait_for_earlier_waves()  # returns at once: no timeout
    assert r.ctx.clock() == start
    said = r.ctx.bus.statuses()[-1]  # type: ignore[attr-defined]
    assert (said.phase, said.detail) == ("wait", "yielding to robot(s) [1]")
    # the claim of robot 1 on somebody else: we wait our turn
    r.fleet.peers[1] = Peer(alive=True, phase="move", seen_alive=True, blocked_by=2)
    with pytest.raises(AgentFailure, match=r"robots \[1\] of earlier waves did not pass"):
        r.waves.wait_for_earlier_waves()


def test_no_yield_while_an_independent_robot_is_pending() -> None:
    r = waiting((1, 2))
    r.fleet.peers[1] = Peer(alive=True, phase="move", seen_alive=True, blocked_by=3)
    r.fleet.peers[2] = Peer(alive=True, phase="move", seen_alive=True)
    with pytest.raises(AgentFailure, match=r"robots \[1, 2\] of earlier waves did not pass"):
        r.waves.wait_for_earlier_waves()


def test_a_robot_past_its_release_point_lets_us_start() -> None:
    """Finer waits: robot 1 walks on the same plan and is 1.5 m along its
    path, past the 1.2 m we wait for; robot 2 holds."""
    r = waiting((1, 2), (1.2, 0.7))
    digest = r.course.digest
    r.fleet.peers[1] = Peer(
        alive=True, phase="move", seen_alive=True, plan_digest=digest, walked=1.5
    )
    r.fleet.peers[2] = Peer(alive=True, phase="hold", seen_alive=True)
    r.waves.wait_for_earlier_waves()  # returns at once


@pytest.mark.parametrize(
    ("walked", "digest", "phase"),
    [(1.1, "ab" * 32, "move"), (1.5, "cd" * 32, "move"), (1.5, "ab" * 32, "wait")],
)
def test_a_robot_short_of_its_release_point_is_waited_for(
    walked: float, digest: str, phase: str
) -> None:
    """Short of 1.2 m, or progress along another plan's path, or not walking: wait."""
    r = waiting((1,), (1.2,))
    r.fleet.peers[1] = Peer(
        alive=True, phase=phase, seen_alive=True, plan_digest=digest, walked=walked
    )
    with pytest.raises(AgentFailure, match=r"robots \[1\] of earlier waves did not pass"):
        r.waves.wait_for_earlier_waves()


def test_earlier_wave_that_never_holds_times_out() -> None:
    r = waiting((1, 2))
    r.fleet.peers[1] = Peer(alive=True, phase="move", seen_alive=True)
    r.fleet.peers[2] = Peer(alive=True, phase="hold", seen_alive=True)
    start = r.ctx.clock()
    with pytest.raises(AgentFailure, match=r"robots \[1\] of earlier waves did not pass"):
        r.waves.wait_for_earlier_waves()
    assert r.ctx.clock() - start > r.ctx.cfg.wave_timeout  # waited the whole timeout
    said = r.ctx.bus.statuses()[-1]  # type: ignore[attr-defined]
    assert (said.phase, said.detail) == ("wait", "waiting for wave(s) of [1]")


# --------------------------------------------------------------------------- MOVE


class TwoLegs(FormationAdapter):
    """Robot 3's path in two legs, 1 m north then 1 m east, ending facing east."""

    def goals(self, plan, me):  # type: ignore[no-untyped-def]
        return [np.array([0.0, 1.0]), np.array([1.0, 1.0])], 0.0


def test_the_move_walks_each_leg_says_how_far_and_faces_the_axis() -> None:
    r = rig(TwoLegs())
    r.course.follow(common_plan())
    r.waves.move()
    assert [g.tolist() for g in r.steps.goals] == [[0.0, 1.0], [1.0, 1.0]]
    assert r.steps.forgotten == 1 and r.mover.last_frame is None  # a fresh look
    assert r.course.leg == 1 and r.course.final_heading == 0.0
    assert r.mover.turns[-1] == pytest.approx(-NORTH)  # from north to the axis (east)
    assert r.ctx.report.figures.walked == pytest.approx(2.0)
    said = [(s.phase, s.detail, s.walked) for s in r.ctx.bus.statuses()]  # type: ignore[attr-defined]
    assert said[0] == (Phase.MOVE, "2 leg(s)", 0.0)


def test_the_move_goes_on_from_the_journaled_leg() -> None:
    """A robot restarted mid-move (crash recovery restores the leg): the legs before are
    not walked again."""
    r = rig(TwoLegs())
    r.course.follow(common_plan())
    r.course.at_leg(1)
    r.ctx.beliefs.position = np.array([0.0, 1.0])
    r.waves.move()
    assert [g.tolist() for g in r.steps.goals] == [[1.0, 1.0]]
    assert r.ctx.report.figures.walked == pytest.approx(2.0)


def test_passing_a_release_point_is_said_at_once() -> None:
    """Robot 1 waits until robot 3 is 0.5 m along its path: the status that says robot 3
    passed it goes out at once (force), not at the next progress status."""
    r = rig(TwoLegs())
    plan = common_plan()
    robots = tuple(
        dataclasses.replace(rp, after=(3,), after_at=(0.5,)) if rp.robot_id == 1 else rp
        for rp in plan.robots
    )
    r.course.follow(dataclasses.replace(plan, robots=robots))
    r.ctx.report.status(Phase.MOVE, force=True)  # a status just out: the next is held back
    n = len(r.ctx.bus.statuses())  # type: ignore[attr-defined]
    r.waves.move()
    walked = [s.walked for s in r.ctx.bus.statuses()[n:]]  # type: ignore[attr-defined]
    assert walked and walked[0] == pytest.approx(1.0)  # the first leg's end, past 0.5 m
