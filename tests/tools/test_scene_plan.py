"""The plan the view draws while the fleet walks (tools/harness/view/scene.py): the
targets of the plan the agents reported, for every built-in shape and the circle
pattern, drawn at the status that first names the plan; fed the fleet of six of
tests/tools/fleet6.py."""

from __future__ import annotations

from typing import Any

import pytest

from agent.core.formation.params import PlanParams
from agent.core.formation.plan import Plan
from agent.core.formation.reshape import from_circle, transition_plan
from agent.core.formation.shape.spec import BUILTIN
from agent.wire import StatusMsg, TruthPosesMsg
from tests.tools import fleet6
from tests.tools.test_foxglove import conforms
from tools.harness.view import foxglove as fg
from tools.harness.view.scene import Scene
from tools.lib.reshape import command_of

Drawn = list[tuple[int, dict[str, Any]]]


def watch(params: PlanParams | None, msgs: list[tuple[str, Any]], finish: bool = False) -> Drawn:
    """The ``/scene/plan`` updates (world time, update) of a scene fed ``msgs``."""
    plans: Drawn = []

    def emit(topic: str, schema: Any, message: Any, t_ns: int) -> None:
        if topic == "/scene/plan":
            conforms(message, fg.SCENE_UPDATE)  # with its deletion, Foxglove's schema
            plans.append((t_ns, message))

    scene = Scene(emit, params=params)
    world_ns = 0
    for key, msg in msgs:
        if isinstance(msg, TruthPosesMsg):
            world_ns = round(msg.t_sim * 1e9)
        scene.take(key, msg, world_ns)
    if finish:
        scene.finish()
    return plans


def drawn_targets(update: dict[str, Any]) -> dict[int, tuple[float, float]]:
    out = {}
    for e in update["entities"]:
        if e["id"].startswith("plan/robot/"):
            pos = e["cylinders"][0]["pose"]["position"]
            out[int(e["id"].rsplit("/", 1)[1])] = (pos["x"], pos["y"])
    return out


@pytest.mark.parametrize("name", sorted(BUILTIN))
def test_every_shapes_targets_are_drawn_when_the_fleet_starts_to_move(name: str) -> None:
    params = PlanParams(shape=BUILTIN[name])
    plan = fleet6.plan(params)
    [(t_ns, update)] = watch(params, fleet6.run(str(plan.digest)))  # before the run is over
    assert t_ns == 1_000_000_000  # the world time of the first status that named the plan
    got, want = drawn_targets(update), fleet6.targets(plan)
    assert sorted(got) == sorted(want) == list(fleet6.WORLD)
    for rid, xy in want.items():
        assert got[rid] == pytest.approx(xy, abs=1e-4)
    assert update["deletions"][0]["type"] == 1  # the drawing replaces any earlier one


@pytest.mark.parametrize("name", sorted(set(BUILTIN) - {"pyramid"}))
def test_the_pyramids_parameters_draw_no_other_shapes_plan(name: str) -> None:
    """A scene that plans with other parameters than the fleet's (the pyramid, the default,
    for a fleet of another shape) computes another digest and draws nothing while the
    fleet walks; at the end it says why. The harness and the view give it the fleet's."""
    digest = str(fleet6.plan(PlanParams(shape=BUILTIN[name])).digest)
    assert watch(None, fleet6.run(digest), finish=True) == []


def test_a_record_that_comes_after_the_plans_first_status_still_draws_it_live() -> None:
    params = PlanParams(shape=BUILTIN["wedge"])
    plan = fleet6.plan(params)
    msgs = fleet6.run(str(plan.digest))
    late = next(k for k, (key, _) in enumerate(msgs) if key == "nao/6/record")
    first_status = next(k for k, (key, _) in enumerate(msgs) if key.endswith("/status"))
    msgs.insert(first_status + 1, msgs.pop(late))  # after robot 1's first status
    [(t_ns, update)] = watch(params, msgs)
    assert t_ns == 1_000_000_000 and len(drawn_targets(update)) == 6


def test_statuses_without_news_do_not_plan_again() -> None:
    """A plan not drawable from what the scene holds is planned again only when a record,
    a robot's start or a reported digest came since the scene last planned."""
    tries: list[int] = []

    class Counting(Scene):
        def _plans(self, fa: Any, records: Any) -> Any:
            tries.append(len(records))
            return super()._plans(fa, records)

    scene = Counting(lambda *a: None, params=PlanParams())
    plan = fleet6.plan(PlanParams())
    scene.take("world/truth/poses", fleet6.truth(0.5), 500)
    for r in fleet6.records()[:-1]:
        scene.take(f"nao/{r.sender}/record", r, 500)
    st = StatusMsg(sender=1, phase="move", plan_digest=str(plan.digest))
    for _ in range(5):
        scene.take("nao/1/status", st, 600)
    assert tries == [5] and not scene.plan_drawn
    last = fleet6.records()[-1]
    scene.take("nao/6/record", last, 700)
    scene.take("nao/6/record", last, 700)  # re-published: no news
    for _ in range(5):
        scene.take("nao/1/status", st, 800)
    assert tries == [5, 6] and scene.plan_drawn == plan.digest


def test_with_the_circle_pattern_the_formation_from_the_circle_replaces_the_circle() -> None:
    params = PlanParams(shape=BUILTIN["wedge"], orientation="cp")
    circle = fleet6.plan(params)
    formation = from_circle(circle, params)
    plans = watch(params, fleet6.run(str(circle.digest), str(formation.digest)), finish=True)
    drawn_one_then_the_other(plans, circle, formation)  # the circle's targets are gone


def drawn_one_then_the_other(plans: Drawn, first: Plan, then: Plan) -> None:
    """Two drawings, at the first status naming each plan: ``first``'s targets, then
    ``then``'s in their place (the common frame: ``first``'s frame robot's start)."""
    [(t1, one), (t2, other)] = plans
    assert (t1, t2) == (1_000_000_000, 2_000_000_000)
    for update, plan in ((one, first), (other, then)):
        got, want = drawn_targets(update), fleet6.targets(plan, first)
        assert sorted(got) == sorted(want)
        for rid, xy in want.items():
            assert got[rid] == pytest.approx(xy, abs=1e-4)
    assert other["deletions"][0]["type"] == 1  # the drawing replaces the first


def _reshaped(held: str, after: str, base: str = "") -> list[tuple[str, Any]]:
    """The six report the plan ``held``, the operator commands the line from ``base``
    (default ``held``), and the six report the plan ``after``."""
    msgs = fleet6.run(held, after)
    at = next(k for k, (_, m) in enumerate(msgs) if getattr(m, "plan_digest", "") == after)
    msgs.insert(at, ("fleet/reshape", command_of(BUILTIN["line"], base or held, 1)))
    return msgs


def test_a_reshape_the_operator_commanded_replaces_the_held_shapes_targets() -> None:
    params = PlanParams()  # the pyramid
    held = fleet6.plan(params)
    after = transition_plan(held, BUILTIN["line"], params)
    plans = watch(params, _reshaped(str(held.digest), str(after.digest)))
    drawn_one_then_the_other(plans, held, after)  # the pyramid's targets are gone


def test_a_reshape_from_a_plan_nobody_holds_draws_nothing_new() -> None:
    params = PlanParams()
    held = fleet6.plan(params)
    after = transition_plan(held, BUILTIN["line"], params)
    msgs = _reshaped(str(held.digest), str(after.digest), base="ab" * 32)
    assert len(watch(params, msgs, finish=True)) == 1  # the held plan only
