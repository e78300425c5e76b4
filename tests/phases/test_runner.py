"""The runner's boundaries, without the world: the adapters and the configuration it is
given, how it composes its collaborators, where it enters the phases and how a run
ends.

The adapters run on the real formation core and the real perception merge. Each
collaborator is tested alone in its own file of tests/phases/ (waves, hold, membership,
research, search, motion, agreeing, reporting), crash recovery in tests/recovery/; the
phases that move the robot are in tests/body/test_runner_phases.py, on an in-process
world.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from agent.adapters import FormationAdapter, PerceptionAdapter
from agent.config import AgentConfig
from agent.core.agreed_params import params_digest
from agent.core.formation.params import PlanParams
from agent.core.formation.view.route import Route
from agent.net.bus import Bus, BusConfig
from agent.phases.context import AgentFailure
from agent.phases.reporting import Phase
from agent.phases.roles import Crew
from agent.phases.runner import Fresh, Runner, report_unavailable
from agent.wire import NeighborRecordMsg, key_alive
from tests.phases.fakes import WORLD, Clock, FakeBody, FakeBus, records


def test_formation_adapter_goals_are_plan_targets_in_own_fixed_frame() -> None:
    fa = FormationAdapter()
    plan = fa.plan(records(), PlanParams())
    assert fa.members(plan) == [1, 2, 3]
    for i in (1, 2, 3):
        rp = plan.robot(i)
        goals, heading = fa.goals(plan, i)
        # the common frame is parallel to every fixed frame: only a translation
        want = np.asarray(rp.target) - np.asarray(rp.start)
        if np.hypot(*want) > 1e-9:
            assert goals[-1] == pytest.approx(want)
        assert heading == pytest.approx(plan.axis)
        # and start + goal is where the robot ends in the world
        assert np.asarray(WORLD[i]) + goals[-1] == pytest.approx(
            np.asarray(rp.target) + np.asarray(WORLD[plan.frame_robot]), abs=1e-9
        )


def test_formation_adapter_is_order_independent() -> None:
    fa = FormationAdapter()
    a = fa.plan(records(), PlanParams())
    b = fa.plan(tuple(reversed(records())), PlanParams())
    assert a.digest == b.digest


def test_formation_adapter_axis_from_vector_or_angle() -> None:
    class P:
        axis = (0.0, 1.0)

    class Q:
        axis = 0.25

    assert FormationAdapter.axis_angle(P()) == pytest.approx(math.pi / 2)  # type: ignore[arg-type]
    assert FormationAdapter.axis_angle(Q()) == pytest.approx(0.25)  # type: ignore[arg-type]


def test_perception_merge_keeps_best_sighting_per_neighbour() -> None:
    s1 = (np.array([[1.0, 0.0], [0.0, 1.0]]), np.array([0.7, 0.9]), np.array([0.1, 0.2]))
    s2 = (np.array([[1.1, 0.0]]), np.array([0.9]), np.array([0.3]))
    pts, ori, conf, best = PerceptionAdapter.merge([s1, s2])
    assert pts.shape == (2, 2)
    k = int(np.argmin(np.hypot(pts[:, 0] - 1.05, pts[:, 1])))
    assert conf[k] == pytest.approx(0.9) and ori[k] == pytest.approx(0.3)
    assert best[k] == 2  # the third sighting of the three, in order
    assert best[1 - k] == 1
    assert PerceptionAdapter.merge([])[0].shape == (0, 2)


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"fleet_size": 0}, "fleet size"),
        ({"d_e": 0.0}, "d_e"),
        ({"phi_e": math.radians(95)}, "phi_e"),
        ({"timeout": -1.0}, "timeout"),
        ({"member_grace": -1.0}, "member_grace"),
        ({"search_yaws": (math.radians(130),)}, "search yaw"),
        ({"march_step": 0.5}, "march_step"),
        ({"march_pause": -1.0}, "march_pause"),
        ({"lost_rounds": 0}, "lost_rounds"),
    ],
)
def test_agent_config_rejects_bad_values(kwargs: dict[str, object], match: str) -> None:
    with pytest.raises(ValueError, match=match):
        AgentConfig(robot_id=1, **kwargs)  # type: ignore[arg-type]


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({}, "exactly one"),
        ({"distance": 1.0, "to": (1.0, 2.0)}, "exactly one"),
        ({"distance": 0.0}, "march distance"),
        ({"distance": math.inf}, "march distance"),
        ({"to": (math.nan, 0.0)}, "march point"),
        ({"to": (1.0, 2.0, 3.0)}, "march point"),
    ],
)
def test_route_rejects_bad_values(kwargs: dict[str, object], match: str) -> None:
    with pytest.raises(ValueError, match=match):
        Route(**kwargs)  # type: ignore[arg-type]


def test_agreed_params_cover_the_route_and_the_geometry() -> None:
    base = AgentConfig(robot_id=1, march=Route(distance=3.0))
    same = AgentConfig(robot_id=2, march=Route(distance=3.0), timeout=9.0)
    d = params_digest(base.agreed_params())
    assert params_digest(same.agreed_params()) == d  # robot id and limits are not agreed
    for other in (
        AgentConfig(robot_id=1, march=Route(distance=2.0)),
        AgentConfig(robot_id=1, march=Route(to=(3.0, 0.0))),
        AgentConfig(robot_id=1),
        AgentConfig(robot_id=1, march=Route(distance=3.0), d_e=0.9),
        AgentConfig(robot_id=1, march=Route(distance=3.0), phi_e=math.radians(31)),
        AgentConfig(robot_id=1, march=Route(distance=3.0), orientation="cp"),
        AgentConfig(robot_id=1, march=Route(distance=3.0), strategy="paper"),
    ):
        assert params_digest(other.agreed_params()) != d, other
    assert base.agreed_params()["route"] == ("axis", 3.0)
    assert Route(to=(1.0, -2.0)).key() == ("to", 1.0, -2.0)


def test_plan_params_carry_orientation_and_strategy() -> None:
    cfg = AgentConfig(robot_id=1, d_e=0.9, orientation="cp", strategy="capt")
    pp = cfg.plan_params()
    assert (pp.d_e, pp.phi_e, pp.orientation, pp.strategy) == (0.9, cfg.phi_e, "cp", "capt")
    assert cfg.agreed_params()["orientation"] == "cp"
    assert cfg.agreed_params()["strategy"] == "capt"


@pytest.mark.parametrize(
    "kwargs, match",
    [({"orientation": "south"}, "orientation must be one of"), ({"strategy": "x"}, "strategy")],
)
def test_config_rejects_unknown_orientation_and_strategy(
    kwargs: dict[str, str], match: str
) -> None:
    with pytest.raises(ValueError, match=match):
        AgentConfig(robot_id=1, **kwargs)  # type: ignore[arg-type]


def test_cp_plan_faces_north_of_the_common_frame() -> None:
    fa = FormationAdapter()
    pca = fa.plan(records(), PlanParams())
    cp = fa.plan(records(), AgentConfig(robot_id=1, orientation="cp").plan_params())
    assert fa.axis_angle(cp) == pytest.approx(math.pi / 2)
    assert cp.digest != pca.digest


class Recovery:
    """A crash recovery that says where to start and keeps what it is told."""

    def __init__(self, crew: Crew, stage: Phase = Phase.HOLD) -> None:
        self.crew = crew
        self.stage = stage
        self.ends: list[str] = []
        self.saved: list[tuple[str, float, int]] = []

    def start(self) -> tuple[Phase, NeighborRecordMsg | None]:
        return self.stage, None

    def finish(self, end: str) -> None:
        self.ends.append(end)

    def save(self, command: str = "", value: float = 0.0, request_id: int = 0) -> None:
        self.saved.append((command, value, request_id))

    def reference(self, image: np.ndarray) -> None:
        """Not used here."""


def runner(stage: Phase = Phase.HOLD) -> tuple[Runner, Recovery, FakeBus]:
    """Robot 3 on a bus without a network, with a recovery that starts it at ``stage``."""
    clock = Clock()
    bus = FakeBus(clock)
    made: list[Recovery] = []

    def recovery(crew: Crew) -> Recovery:
        made.append(Recovery(crew, stage))
        return made[0]

    cfg = AgentConfig(robot_id=3, fleet_size=3)
    r = Runner(bus, FakeBody(3), cfg, None, FormationAdapter(), clock, recovery)  # type: ignore[arg-type]
    return r, made[0], bus


def test_runner_rejects_config_for_another_robot() -> None:
    with pytest.raises(ValueError, match="driven with config for"):
        Runner(FakeBus(), FakeBody(1), AgentConfig(robot_id=2), None, FormationAdapter())  # type: ignore[arg-type]


def test_the_collaborators_share_one_context_and_recovery_gets_the_crew() -> None:
    r, recovery, _ = runner()
    crew = recovery.crew
    assert (crew.ctx, crew.fleet, crew.motion) == (r.ctx, r.membership, r.motion)
    assert (crew.planner, crew.course, crew.survey) == (r.waves, r.course, r.search)
    assert r.recovery is recovery and r.ctx.report.journal is recovery  # journaled through it
    for c in (r.motion, r.safe_steps, r.search, r.agreeing, r.research, r.waves, r.hold):
        assert c.ctx is r.ctx
    assert r.waves.course is r.hold.course is r.safe_steps.course is r.course


def test_without_recovery_every_start_is_a_fresh_search() -> None:
    r = Runner(FakeBus(), FakeBody(3), AgentConfig(robot_id=3), None, FormationAdapter())  # type: ignore[arg-type]
    assert isinstance(r.recovery, Fresh) and r.recovery.start() == (Phase.SEARCH, None)
    assert r.ctx.report.journal is r.recovery


def test_a_run_enters_where_recovery_says_and_ends_done() -> None:
    r, recovery, bus = runner(Phase.HOLD)
    entered: list[str] = []
    r.waves.move = lambda: entered.append("move")  # type: ignore[method-assign]
    r.hold.run = lambda: entered.append("hold")  # type: ignore[method-assign]
    assert r.run() == 0
    assert entered == ["hold"] and recovery.ends == ["done"]
    assert key_alive(3) in bus.subscribed  # the robot joined first
    r, recovery, _ = runner(Phase.MOVE)
    entered.clear()
    r.waves.move = lambda: entered.append("move")  # type: ignore[method-assign]
    r.hold.run = lambda: entered.append("hold")  # type: ignore[method-assign]
    assert r.run() == 0 and entered == ["move", "hold"]


def test_a_run_that_fails_stops_safely_says_why_and_ends_failed() -> None:
    r, recovery, bus = runner(Phase.HOLD)

    def fail() -> None:
        raise AgentFailure("parent 1 failed")

    r.hold.run = fail  # type: ignore[method-assign]
    assert r.run() == 1
    said = bus.statuses()[-1]
    assert (said.phase, said.error) == ("failed", "AgentFailure: parent 1 failed")
    assert recovery.ends == ["failed"]
    assert r.ctx.clock() >= 1.0  # it let the failure reach the others


def test_a_bug_in_a_phase_stops_safely_too() -> None:
    r, recovery, bus = runner(Phase.HOLD)

    def bug() -> None:
        raise KeyError("oops")

    r.hold.run = bug  # type: ignore[method-assign]
    assert r.run() == 1
    assert bus.statuses()[-1].error.startswith("unexpected KeyError")
    assert recovery.ends == ["failed"]


def test_a_run_stopped_by_the_operator_ends_stopped() -> None:
    r, recovery, _ = runner(Phase.HOLD)

    def interrupted() -> None:
        raise KeyboardInterrupt

    r.hold.run = interrupted  # type: ignore[method-assign]
    with pytest.raises(KeyboardInterrupt):
        r.run()
    assert recovery.ends == ["stopped"]


def test_unavailable_perception_fails_safely_with_reason() -> None:
    with Bus(BusConfig(multicast_scouting=False)) as bus:
        assert report_unavailable(bus, 3, "perception unavailable: no D-base") == 1
        assert bus.stats.published_count["status"] == 1
