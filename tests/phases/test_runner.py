"""The runner's boundaries and its safety rules, without the world.

The adapters run on the real formation core and the real perception merge; the wave
rule runs on a real (unconnected) zenoh session. The phases that move the robot are in
tests/body/test_runner_phases.py, on an in-process world.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Iterator

import numpy as np
import pytest

from agent.adapters import FormationAdapter, PerceptionAdapter
from agent.body.zenoh_world import ZenohBody
from agent.config import AgentConfig
from agent.core.agreed_params import params_digest
from agent.core.agreement import Agreement, Decision
from agent.core.formation.params import PlanParams
from agent.core.formation.view.route import Route
from agent.net.bus import Bus, BusConfig, Event
from agent.phases.context import AgentFailure
from agent.phases.membership import Peer
from agent.phases.runner import Runner, report_unavailable
from agent.wire import NeighborRecordMsg, StatusMsg, canonical_digest

# robots 1, 2, 3 at known world positions; every robot sees every other one
WORLD = {1: (0.0, 0.0), 2: (-1.0, 0.1), 3: (0.9, -0.2)}


def records() -> tuple[NeighborRecordMsg, ...]:
    out = []
    for i, (x, y) in WORLD.items():
        nb = tuple((wx - x, wy - y) for j, (wx, wy) in WORLD.items() if j != i)
        out.append(NeighborRecordMsg(sender=i, round=0, neighbours=nb))
    return tuple(out)


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
    pts, ori, conf = PerceptionAdapter.merge([s1, s2])
    assert pts.shape == (2, 2)
    k = int(np.argmin(np.hypot(pts[:, 0] - 1.05, pts[:, 1])))
    assert conf[k] == pytest.approx(0.9) and ori[k] == pytest.approx(0.3)
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
    [({"orientation": "north"}, "orientation must be one of"), ({"strategy": "x"}, "strategy")],
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


@pytest.fixture(scope="module")
def perception() -> PerceptionAdapter:
    return PerceptionAdapter()


@pytest.fixture()
def runner(perception: PerceptionAdapter) -> Iterator[Runner]:
    bus = Bus(BusConfig(multicast_scouting=False))
    cfg = AgentConfig(robot_id=3, fleet_size=3, wave_timeout=2.0)
    r = Runner(bus, ZenohBody(bus, 3), cfg, perception, FormationAdapter())
    r.ctx.plan = r.ctx.formation.plan(records(), PlanParams())
    try:
        yield r
    finally:
        bus.close()


def test_make_plan_plans_with_the_agents_parameters(perception: PerceptionAdapter) -> None:
    bus = Bus(BusConfig(multicast_scouting=False))
    try:
        cfg = AgentConfig(robot_id=3, fleet_size=3, orientation="cp", strategy="paper")
        r = Runner(bus, ZenohBody(bus, 3), cfg, perception, FormationAdapter())
        plan = r.waves.make_plan(
            Decision("agreed", records=records(), digest=canonical_digest(records()))
        )
    finally:
        bus.close()
    assert plan.axis == pytest.approx(math.pi / 2)
    assert plan.digest == FormationAdapter().plan(records(), cfg.plan_params()).digest


def earlier(r: Runner) -> list[int]:
    return [i for i in (1, 2, 3) if r.ctx.plan.robot(i).wave < r.ctx.plan.robot(3).wave]


def after(r: Runner, ids: tuple[int, ...]) -> None:
    """Make robot 3 of ``r``'s plan wait for ``ids`` (its ``after`` list)."""
    robots = tuple(
        dataclasses.replace(rp, after=ids) if rp.robot_id == 3 else rp for rp in r.ctx.plan.robots
    )
    r.ctx.plan = dataclasses.replace(r.ctx.plan, robots=robots)


def test_runner_rejects_config_for_another_robot(perception: PerceptionAdapter) -> None:
    bus = Bus(BusConfig(multicast_scouting=False))
    try:
        with pytest.raises(ValueError, match="driven with config for"):
            Runner(bus, ZenohBody(bus, 1), AgentConfig(robot_id=2), perception, FormationAdapter())
    finally:
        bus.close()


def test_a_robot_with_an_empty_after_list_starts_at_once(runner: Runner) -> None:
    after(runner, ())
    runner.membership.peers[1] = Peer(alive=True, phase="move", seen_alive=True)
    runner.waves.wait_for_earlier_waves()  # returns although robot 1 still moves


def test_waits_pass_when_earlier_waves_hold(runner: Runner) -> None:
    after(runner, (1, 2))
    for i in (1, 2):
        runner.membership.peers[i] = Peer(alive=True, phase="hold", seen_alive=True)
    runner.waves.wait_for_earlier_waves()


def test_member_of_an_earlier_wave_that_leaves_stops_us(runner: Runner) -> None:
    after(runner, (1, 2))
    runner.membership.peers[1] = Peer(alive=False, phase="move", seen_alive=True)
    runner.membership.peers[2] = Peer(alive=True, phase="hold", seen_alive=True)
    with pytest.raises(AgentFailure, match=r"robot 1 of wave .* left before holding"):
        runner.waves.wait_for_earlier_waves()


def test_failed_member_of_an_earlier_wave_stops_us(runner: Runner) -> None:
    after(runner, (1, 2))
    runner.membership.peers[1] = Peer(alive=True, phase="hold", seen_alive=True)
    runner.membership.peers[2] = Peer(alive=True, phase="failed", seen_alive=True)
    with pytest.raises(AgentFailure, match=r"formation incomplete: robot 2 failed"):
        runner.waves.wait_for_earlier_waves()


def test_a_robot_blocked_by_us_makes_us_yield(runner: Runner) -> None:
    """Jams (agent/core/formation/waves/jam.py rule 2): robot 1 cannot reach its slot
    because robot 3 (us, not moved yet) stands too near it, and we wait for robot 1."""
    after(runner, (1, 2))
    runner.membership.peers[1] = Peer(alive=True, phase="move", seen_alive=True, blocked_by=3)
    runner.membership.peers[2] = Peer(alive=True, phase="hold", seen_alive=True)
    runner.waves.wait_for_earlier_waves()  # returns at once: no timeout
    # the claim of robot 1 on somebody else: we wait our turn
    runner.membership.peers[1] = Peer(alive=True, phase="move", seen_alive=True, blocked_by=2)
    with pytest.raises(AgentFailure, match=r"robots \[1\] of earlier waves did not hold"):
        runner.waves.wait_for_earlier_waves()


def test_no_yield_while_an_independent_robot_is_pending(runner: Runner) -> None:
    after(runner, (1, 2))
    runner.membership.peers[1] = Peer(alive=True, phase="move", seen_alive=True, blocked_by=3)
    runner.membership.peers[2] = Peer(alive=True, phase="move", seen_alive=True)
    with pytest.raises(AgentFailure, match=r"robots \[1, 2\] of earlier waves did not hold"):
        runner.waves.wait_for_earlier_waves()


def test_a_failed_member_stops_a_robot_that_was_done(runner: Runner) -> None:
    """No 'formation held' around a hole: the fleet's one reason (jam.py rule 4)."""
    runner.membership.peers[1] = Peer(alive=True, phase="done", seen_alive=True)
    runner.membership.peers[2] = Peer(
        alive=True, phase="failed", seen_alive=True, error="robot 2 cannot reach its slot"
    )
    with pytest.raises(
        AgentFailure, match="formation incomplete: robot 2 failed: robot 2 cannot reach its slot"
    ):
        runner.hold.finish()


def at(r: Runner, ids: tuple[int, ...], arcs: tuple[float, ...]) -> None:
    """Make robot 3 wait for ``ids`` until each has walked ``arcs`` of its path."""
    robots = tuple(
        dataclasses.replace(rp, after=ids, after_at=arcs) if rp.robot_id == 3 else rp
        for rp in r.ctx.plan.robots
    )
    r.ctx.plan = dataclasses.replace(r.ctx.plan, robots=robots)
    r.ctx.plan_digest = "ab" * 32


def test_a_robot_past_its_release_point_lets_us_start(runner: Runner) -> None:
    """Finer waits: robot 1 walks on the same plan and is 1.5 m along its
    path, past the 1.2 m we wait for; robot 2 holds."""
    at(runner, (1, 2), (1.2, 0.7))
    digest = runner.ctx.plan_digest
    runner.membership.peers[1] = Peer(
        alive=True, phase="move", seen_alive=True, plan_digest=digest, walked=1.5
    )
    runner.membership.peers[2] = Peer(alive=True, phase="hold", seen_alive=True)
    runner.waves.wait_for_earlier_waves()  # returns at once


@pytest.mark.parametrize(
    ("walked", "digest", "phase"),
    [(1.1, "ab" * 32, "move"), (1.5, "cd" * 32, "move"), (1.5, "ab" * 32, "wait")],
)
def test_a_robot_short_of_its_release_point_is_waited_for(
    runner: Runner, walked: float, digest: str, phase: str
) -> None:
    """Short of 1.2 m, or progress along another plan's path, or not walking: wait."""
    at(runner, (1,), (1.2,))
    runner.membership.peers[1] = Peer(
        alive=True, phase=phase, seen_alive=True, plan_digest=digest, walked=walked
    )
    with pytest.raises(AgentFailure, match=r"robots \[1\] of earlier waves did not hold"):
        runner.waves.wait_for_earlier_waves()


def test_progress_heard_only_grows_for_one_plan(runner: Runner) -> None:
    from agent.net.bus import Event

    runner.membership.handle(Event("alive", "nao/alive/2", robot_id=2))
    d1, d2 = "ab" * 32, "cd" * 32
    for walked, digest in ((2.0, d1), (1.0, d1)):  # a late, older status changes nothing
        msg = StatusMsg(sender=2, phase="move", plan_digest=digest, walked=walked)
        runner.membership.handle(Event("msg", "nao/2/status", msg))
    assert runner.membership.peers[2].walked == 2.0
    msg = StatusMsg(sender=2, phase="move", plan_digest=d2, walked=0.5)  # a new plan
    runner.membership.handle(Event("msg", "nao/2/status", msg))
    assert runner.membership.peers[2].walked == 0.5


def test_earlier_wave_that_never_holds_times_out(runner: Runner) -> None:
    after(runner, (1, 2))
    runner.membership.peers[1] = Peer(alive=True, phase="move", seen_alive=True)
    runner.membership.peers[2] = Peer(alive=True, phase="hold", seen_alive=True)
    with pytest.raises(AgentFailure, match=r"robots \[1\] of earlier waves did not hold"):
        runner.waves.wait_for_earlier_waves()


def test_unavailable_perception_fails_safely_with_reason() -> None:
    with Bus(BusConfig(multicast_scouting=False)) as bus:
        assert report_unavailable(bus, 3, "perception unavailable: no D-base") == 1
        assert bus.stats.published_count["status"] == 1


def test_messages_whose_sender_does_not_own_the_key_are_dropped(runner: Runner) -> None:
    from agent.net.bus import Event

    impostor = NeighborRecordMsg(sender=2, round=0, neighbours=((1.0, 0.0),))
    runner.membership.handle(Event("msg", "nao/1/record", impostor))
    assert runner.membership.early_records == {}
    runner.membership.handle(Event("msg", "nao/2/record", impostor))
    assert runner.membership.early_records == {}  # 2 is no member yet: no state kept for it
    runner.membership.handle(Event("alive", "nao/alive/2", robot_id=2))
    runner.membership.handle(Event("msg", "nao/2/record", impostor))
    assert runner.membership.early_records == {2: impostor}


def test_only_the_current_session_of_a_member_counts(runner: Runner) -> None:
    from agent.net.bus import Event

    runner.membership.handle(Event("alive", "nao/alive/2", robot_id=2))
    new = NeighborRecordMsg(sender=2, round=0, neighbours=((1.0, 0.0),))
    old = NeighborRecordMsg(sender=2, round=3, neighbours=((9.0, 0.0),))
    runner.membership.handle(Event("msg", "nao/2/record", new, signer="robot-2", epoch=200))
    runner.membership.handle(Event("msg", "nao/2/record", old, signer="robot-2", epoch=100))
    assert runner.membership.early_records == {2: new}  # the older session (a replay) is ignored
    runner.membership.agreed_epochs = {2: 200}
    runner.membership.handle(
        Event("msg", "nao/2/status", StatusMsg(sender=2, phase="done"), epoch=300)
    )
    assert (
        runner.membership.peers[2].phase != "done"
    )  # after agreement only the agreed session counts


def test_a_vanished_token_is_a_departure_only_after_the_grace_period(
    perception: PerceptionAdapter,
) -> None:
    from agent.net.bus import Event

    now = [0.0]
    bus = Bus(BusConfig(multicast_scouting=False))
    try:
        cfg = AgentConfig(robot_id=3, fleet_size=3, member_grace=10.0)
        r = Runner(
            bus, ZenohBody(bus, 3), cfg, perception, FormationAdapter(), clock=lambda: now[0]
        )
        r.membership.agreement = Agreement(
            3, records()[2], 0.0, fleet_size=3, digest_fn=canonical_digest
        )
        for i in (1, 2):
            r.membership.handle(Event("alive", f"nao/alive/{i}", robot_id=i))
        r.membership.handle(Event("gone", "nao/alive/1", robot_id=1))
        r.membership.handle(Event("gone", "nao/alive/2", robot_id=2))
        now[0] = 8.0  # robot 2 is heard from: a heartbeat
        r.membership.handle(Event("msg", "nao/2/status", StatusMsg(sender=2, phase="agree")))
        now[0] = 9.9
        r.membership.pump()
        assert (
            r.membership.peers[1].alive
            and r.membership.peers[2].alive
            and r.membership.agreement.left == set()
        )
        now[0] = 10.0
        r.membership.pump()
        assert not r.membership.peers[1].alive and r.membership.agreement.left == {1}
        assert r.membership.peers[2].alive  # its grace runs from its last status
        r.membership.handle(Event("alive", "nao/alive/2", robot_id=2))  # reconnected
        now[0] = 30.0
        r.membership.pump()
        assert r.membership.peers[2].alive and r.membership.agreement.left == {1}
    finally:
        bus.close()


# ---------------------------------------------------------------- re-search (4.1.3 rule 2)


def _lost_records() -> tuple[NeighborRecordMsg, ...]:
    """Robots 1 and 2 see each other; robot 3 sees nobody and nobody sees it."""
    return (
        NeighborRecordMsg(sender=1, round=0, neighbours=((-1.0, 0.1),)),
        NeighborRecordMsg(sender=2, round=0, neighbours=((1.0, -0.1),)),
        NeighborRecordMsg(sender=3, round=0, neighbours=()),
    )


def test_research_returns_nothing_for_a_connected_fleet(runner: Runner) -> None:
    assert runner.research.next_round(Decision("agreed", records=records())) is None
    assert runner.ctx.record_round == 0


def test_research_stops_the_fleet_after_the_last_round(runner: Runner) -> None:
    runner.ctx.cfg = dataclasses.replace(runner.ctx.cfg, research_rounds=0)
    with pytest.raises(AgentFailure, match=r"robots \[3\] outside .* after 0 re-search round"):
        runner.research.next_round(Decision("agreed", records=_lost_records()))
    assert runner.ctx.record_round == 0  # nobody moved on to another round


def test_a_waiting_robot_stops_when_a_searcher_failed(runner: Runner) -> None:
    runner.ctx.record_round = 1
    runner.membership.peers[1] = Peer(alive=True, phase="failed", seen_alive=True)
    with pytest.raises(AgentFailure, match="robot 1 failed in re-search round 1"):
        runner.research.wait_for_searchers((1,))
    runner.membership.peers[1] = Peer(alive=False, phase="explore", seen_alive=True)
    with pytest.raises(AgentFailure, match="robot 1 left in re-search round 1"):
        runner.research.wait_for_searchers((1,))
    runner.membership.peers[1] = Peer(alive=True, phase="explore", seen_alive=True)
    runner.ctx.cfg = dataclasses.replace(runner.ctx.cfg, research_timeout=0.3)
    with pytest.raises(AgentFailure, match=r"robots \[1\] did not search again within 0.3 s"):
        runner.research.wait_for_searchers((1,))
    # a record of the round from the searcher ends the wait
    runner.membership.early_records[1] = NeighborRecordMsg(sender=1, round=1, neighbours=())
    runner.research.wait_for_searchers((1,))


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


def _lingering(perception: PerceptionAdapter, peers: dict[int, Peer]) -> tuple[Runner, Bus]:
    """Robot 3 in ``done`` with a fake clock that advances 0.25 s per reading, and by
    the time each wait on the bus would sleep (nothing arrives)."""
    t = [0.0]

    def clock() -> float:
        t[0] += 0.25
        return t[0]

    def drain(timeout: float = 0.0) -> list[Event]:
        t[0] += timeout
        return []

    bus = Bus(BusConfig(multicast_scouting=False))
    bus.drain = drain  # type: ignore[method-assign]
    cfg = AgentConfig(robot_id=3, fleet_size=3, wave_timeout=60.0, member_grace=10.0)
    r = Runner(bus, ZenohBody(bus, 3), cfg, perception, FormationAdapter(), clock=clock)
    r.ctx.plan = r.ctx.formation.plan(records(), PlanParams())
    r.membership.peers.update(peers)
    return r, bus


def test_done_lingers_with_heartbeats_for_members_out_of_reach(
    perception: PerceptionAdapter,
) -> None:
    out_of_reach = {i: Peer(alive=False, phase="hold", seen_alive=True) for i in (1, 2)}
    r, bus = _lingering(perception, out_of_reach)
    try:
        r.ctx.status("done", 1.0, force=True)
        r.hold.wait_all(("done", "failed"), "done", "waiting for", linger=r.ctx.cfg.member_grace)
        # returned once the linger passed, having re-published ``done`` meanwhile
        assert r.ctx.clock() >= r.ctx.cfg.member_grace
        assert bus.stats.published_count["status"] >= 3
    finally:
        bus.close()


def test_done_does_not_linger_once_every_member_is_seen_done(
    perception: PerceptionAdapter,
) -> None:
    r, bus = _lingering(
        perception,
        {
            1: Peer(alive=False, phase="done", seen_alive=True),
            2: Peer(alive=True, phase="done", seen_alive=True),
        },
    )
    try:
        r.ctx.status("done", 1.0, force=True)
        r.hold.wait_all(("done", "failed"), "done", "waiting for", linger=r.ctx.cfg.member_grace)
        assert r.ctx.clock() < 3.0  # no heartbeat was due
        assert bus.stats.published_count["status"] == 1
    finally:
        bus.close()


def test_without_linger_members_out_of_reach_are_not_waited_for(
    perception: PerceptionAdapter,
) -> None:
    out_of_reach = {i: Peer(alive=False, phase="hold", seen_alive=True) for i in (1, 2)}
    r, bus = _lingering(perception, out_of_reach)
    try:
        r.hold.wait_all(("done", "failed"), "done", "waiting for")
        assert r.ctx.clock() < 3.0
    finally:
        bus.close()


def test_the_timeline_reports_wall_and_cpu_seconds_per_phase() -> None:
    from agent.phases.context import Timeline

    tl = Timeline()
    assert tl.costs() == ""
    tl.mark("search", 0.0)
    tl.mark("wait", 1.0)
    parts = tl.costs().split(", ")
    assert [p.split(" ")[0] for p in parts] == ["set-up", "search", "wait"]
    assert parts[0].startswith("set-up -/")
    wall, cpu = (float(v) for v in parts[1].split(" ")[1].split("/"))
    assert wall >= 0.0 and cpu >= 0.0
