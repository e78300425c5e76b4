"""Looks on the world clock (sim/server/glances.py, sim/server/camera_desk.py): what a look costs,
the glances in flight, and a real world's camera desk charging them while others walk."""

from __future__ import annotations

import math
from typing import Any

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from agent.wire import BUSY, CameraReply, ErrorReply, Message
from sim.physics.locomotion import DT
from sim.physics.world import World
from sim.scenarios import RobotSpec, Scenario
from sim.server.camera_desk import CameraDesk
from sim.server.glances import CAPTURE_S, HEAD_YAW_MAX_SPEED, SETTLE_S, Glances, LookTiming
from sim.server.pending_pictures import Admission

NORTH = math.pi / 2


def test_a_look_costs_turn_settle_and_capture() -> None:
    t = LookTiming()
    assert t.speed == pytest.approx(0.3 * HEAD_YAW_MAX_SPEED)  # setAngles at 0.3 of 8.27 rad/s
    assert pytest.approx(0.05) == CAPTURE_S  # 1.5 frames at 30 fps
    step = math.radians(30.0)
    assert t.cost(0.0, step) == pytest.approx(step / t.speed + SETTLE_S + CAPTURE_S)
    assert t.cost(step, 0.0) == t.cost(0.0, step)
    assert t.cost(0.4, 0.4) == CAPTURE_S  # no turn, no settling: the next frame
    full = t.cost(-math.radians(119.5), math.radians(119.5))
    assert 1.7 < full < 2.0


@pytest.mark.parametrize(
    ("fields", "reason"),
    [
        ({"speed": 0.0}, "head speed"),
        ({"speed": math.inf}, "head speed"),
        ({"settle": -0.1}, "settle time"),
        ({"capture": math.nan}, "capture time"),
    ],
)
def test_bad_timings_are_refused(fields: dict[str, float], reason: str) -> None:
    with pytest.raises(ValueError, match=reason):
        LookTiming(**fields)


def test_a_non_finite_yaw_has_no_cost() -> None:
    with pytest.raises(ValueError, match="not finite"):
        LookTiming().cost(0.0, math.nan)


def test_one_glance_per_robot_repeats_take_it_over_other_yaws_are_busy() -> None:
    g: Glances[str] = Glances()
    assert g.start("q1", 1, 0.5, 0.0, 10.0) == (Admission.NEW, None)
    assert g.start("q1b", 1, 0.5, 0.0, 10.1) == (Admission.REBOUND, "q1")
    assert g.start("q1c", 1, -0.5, 0.0, 10.1) == (Admission.BUSY, None)
    assert g.start("q2", 2, 0.0, 0.0, 10.0) == (Admission.NEW, None)
    assert len(g) == 2
    assert g.due(10.0) == []
    (first,) = g.due(10.0 + CAPTURE_S)  # robot 2 did not turn: done first
    assert (first.robot_id, first.query) == (2, "q2")
    (second,) = g.due(11.0)
    assert (second.query, second.t_start) == ("q1b", 10.0)  # the repeat, the first start
    assert second.t_end == pytest.approx(10.0 + LookTiming().cost(0.0, 0.5))
    assert g.charged == pytest.approx(LookTiming().cost(0.0, 0.5) + CAPTURE_S)
    g.start("q3", 3, 0.1, 0.0, 11.0)
    assert [x.query for x in g.drain()] == ["q3"] and len(g) == 0


@settings(max_examples=100, deadline=None)
@given(st.lists(st.tuples(st.integers(1, 30), st.floats(-2.0, 2.0)), min_size=1, max_size=12))
def test_glances_end_in_time_then_id_order_whatever_the_order_they_came_in(
    starts: list[tuple[int, float]],
) -> None:
    """Determinism: the pictures of looks due together are taken in one order."""
    by_robot = dict(starts)  # one look per robot
    orders = [sorted(by_robot), sorted(by_robot, reverse=True)]
    taken = []
    for order in orders:
        g: Glances[int] = Glances()
        for rid in order:
            g.start(rid, rid, by_robot[rid], 0.0, 0.0)
        got = g.due(10.0)
        assert [(x.t_end, x.robot_id) for x in got] == sorted((x.t_end, x.robot_id) for x in got)
        taken.append([x.robot_id for x in got])
    assert taken[0] == taken[1] and len(taken[0]) == len(by_robot)


# ------------------------------------------------------------------ the camera desk


class Desk:
    """A camera desk on a real world, its answers collected per query."""

    def __init__(self, world: World, free_looks: bool = False) -> None:
        self.world = world
        self.answers: dict[Any, list[Message]] = {}
        self.log: list[str] = []
        self.desk = CameraDesk(
            world, self._collect, self._collect, self.log.append, free_looks=free_looks
        )

    def _collect(self, q: Any, msg: Message) -> None:
        self.answers.setdefault(q, []).append(msg)

    def run(self, until: Any) -> None:
        """Step the world's clock (as the server's loop does) until ``until`` is answered."""
        for _ in range(1000):
            if until in self.answers:
                return
            self.world.locomotion.step(clock=True)
            self.desk.capture_due()
        raise AssertionError(f"{until} never answered")


@pytest.fixture(scope="module")
def world() -> Any:
    sc = Scenario(
        robots=(RobotSpec(1, 0.0, 0.0, NORTH), RobotSpec(2, 0.0, 1.0, -NORTH)),
        seed=2,
        room=4.0,
    )
    with World(sc, noise=False) as w:
        yield w


def test_a_look_is_answered_when_its_time_has_passed(world: World) -> None:
    d = Desk(world)
    t0 = world.t_sim
    yaw = 0.6
    cost = LookTiming().cost(world.head_yaw(1), yaw)
    d.desk.request("q", 1, yaw)
    assert "q" not in d.answers and d.desk.looking
    d.run("q")
    (rep,) = d.answers["q"]
    assert isinstance(rep, CameraReply) and rep.yaw == yaw
    assert cost <= rep.t_sim - t0 < cost + DT + 1e-9  # the first step at or past the end
    assert rep.t_sim == world.t_sim and not d.desk.looking
    assert world.head_yaw(1) == yaw


def test_looking_and_walking_share_one_clock(world: World) -> None:
    """Robot 2 walks while robot 1 sweeps its head: each action takes its own time on
    the one clock; the look does not hold the walk back, nor the walk the look."""
    d = Desk(world)
    legs = world.locomotion
    t0 = world.t_sim
    legs.walk(2, -0.1)  # backwards, away from robot 1
    walk_s = 0.1 / 0.06
    ends = []
    for k, yaw in enumerate((0.5, 0.0, -0.5)):
        cost = LookTiming().cost(world.head_yaw(1), yaw)
        start = world.t_sim
        d.desk.request(k, 1, yaw)
        d.run(k)
        ends.append(world.t_sim)
        assert cost <= world.t_sim - start < cost + DT + 1e-9
    done, _ = legs.run_until_idle()
    assert done and done[0].robot_id == 2
    assert done[0].t_sim - t0 == pytest.approx(walk_s, abs=2 * DT)
    assert ends[-1] < done[0].t_sim  # the sweep ended first, the walk went on


def test_a_second_yaw_while_looking_is_busy_and_a_repeat_takes_over(world: World) -> None:
    d = Desk(world)
    d.desk.request("first", 1, 0.2)
    d.desk.request("other", 1, -0.2)
    d.desk.request("again", 1, 0.2)
    (busy,) = d.answers["other"]
    assert isinstance(busy, ErrorReply) and busy.reason.startswith(BUSY)
    (gone,) = d.answers["first"]
    assert isinstance(gone, ErrorReply) and "superseded" in gone.reason
    d.run("again")
    assert isinstance(d.answers["again"][0], CameraReply)
    assert d.desk.errors == 1


def test_free_looks_answer_at_once_and_cost_nothing(world: World) -> None:
    d = Desk(world, free_looks=True)
    t0 = world.t_sim
    d.desk.request("q", 1, -1.0)
    (rep,) = d.answers["q"]
    assert isinstance(rep, CameraReply) and rep.t_sim == t0 == world.t_sim
    assert not d.desk.looking


def test_closing_the_desk_answers_the_looks_in_flight(world: World) -> None:
    d = Desk(world)
    d.desk.request("q", 2, 0.3)
    d.desk.close("world shutting down")
    (rep,) = d.answers["q"]
    assert isinstance(rep, ErrorReply) and rep.reason == "world shutting down"


def test_a_picture_that_fails_is_answered_and_the_desk_goes_on(world: World) -> None:
    d = Desk(world)
    d.desk.request("q", 1, 0.1)

    def broken(rid: int, yaw: float, shot: Any = None) -> Any:
        raise RuntimeError("renderer gone")

    real = world.render
    try:
        world.render = broken  # type: ignore[method-assign]
        d.run("q")
    finally:
        world.render = real  # type: ignore[method-assign]
    (rep,) = d.answers["q"]
    assert isinstance(rep, ErrorReply) and rep.reason == "internal: RuntimeError: renderer gone"
    assert d.log and d.desk.errors == 1
