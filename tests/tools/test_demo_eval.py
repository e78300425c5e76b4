"""tools/harness evaluation helpers: known answers worked by hand."""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from agent.core.formation.params import D_E, PHI_E_DEG
from tools.harness.judge import evaluate, judge_march, min_separation, summarise
from tools.harness.observe import AgentView, Observer
from tools.harness.procs import robot_ids
from tools.harness.run_report import moved, plot


def test_evaluate_perfect_pyramid_facing_north() -> None:
    d, phi = D_E, math.radians(PHI_E_DEG)
    # leader 1 at origin facing +y; children behind-left (2) and behind-right (3)
    final = {
        1: (0.0, 0.0, math.pi / 2),
        2: (-d * math.sin(phi), -d * math.cos(phi), math.pi / 2),
        3: (d * math.sin(phi), -d * math.cos(phi), math.pi / 2),
    }
    rows = evaluate(final, [(2, 1), (3, 1)], math.pi / 2, d, phi)
    for r in rows:
        assert r["distance"] == pytest.approx(d)
        assert r["angle_deg"] == pytest.approx(30.0)
        assert r["r_d"] == pytest.approx(0.0, abs=1e-12)
        assert r["r_phi"] == pytest.approx(0.0, abs=1e-9)


def test_evaluate_errors_known_answer() -> None:
    # child 0.9 m straight behind the parent: r_d = +12.5 %, angle 0 -> r_phi = -100 %
    final = {1: (0.0, 0.0, 0.0), 2: (-0.9, 0.0, 0.0)}
    (r,) = evaluate(final, [(2, 1)], 0.0, 0.8, math.radians(30))
    assert r["r_d"] == pytest.approx(0.125)
    assert r["angle_deg"] == pytest.approx(0.0, abs=1e-6)
    assert r["r_phi"] == pytest.approx(-1.0)


def test_min_separation() -> None:
    obs = Observer(0.0)
    obs.truth = [
        (0.0, {1: (0.0, 0.0, 0.0), 2: (1.0, 0.0, 0.0)}),
        (1.0, {1: (0.0, 0.0, 0.0), 2: (0.5, 0.0, 0.0)}),
    ]
    assert min_separation(obs) == pytest.approx(0.5)


def test_robot_ids_from_ready_line() -> None:
    assert robot_ids(["x", "sim ready robots=3,1,2 room=6 seed=1"], 3) == [1, 2, 3]
    with pytest.raises(RuntimeError, match="asked for 4"):
        robot_ids(["sim ready robots=1,2,3 room=6"], 4)
    with pytest.raises(RuntimeError, match="without robot ids"):
        robot_ids(["sim ready"], 3)


def test_summarise_failure_without_truth(tmp_path: Path) -> None:
    obs = Observer(0.0)
    obs.agents[1] = AgentView(phase="failed", error="no agreement", exit_code=1)
    r = summarise(obs, {"robots": 1, "seed": 0, "d_e": D_E, "phi_e_deg": PHI_E_DEG}, tmp_path,
                  [1], D_E, math.radians(PHI_E_DEG), quiet=True)  # fmt: skip
    assert r["success"] is False
    assert r["errors"] == {"1": "no agreement"}
    assert (tmp_path / "result.json").is_file()


def test_summarise_judges_the_shape_the_run_was_given(tmp_path: Path) -> None:
    # three robots standing in a line facing north, the leader in the middle: a line, no
    # pyramid
    obs = Observer(0.0)
    line = {1: (0.0, 0.0, math.pi / 2), 2: (-0.8, 0.0, math.pi / 2), 3: (0.8, 0.0, math.pi / 2)}
    obs.truth = [(0.0, line), (1.0, line)]
    for i in (1, 2, 3):
        obs.agents[i] = AgentView(phase="done", exit_code=0, plan_digest="ab")
    for spec, ok in (("line", True), ("pyramid", False)):
        result = {"robots": 3, "seed": 0, "d_e": 0.8, "phi_e_deg": 30.0, "shape_spec": spec}
        r = summarise(obs, result, tmp_path, [1, 2, 3], 0.8, math.radians(30), quiet=True)
        assert r["within_tolerance"] is ok, r["pairs"]
        assert len(r["pairs"]) == 2
    assert {p["side"] for p in r["pairs"]} == {"left", "right"}


def test_moved_is_the_longest_start_to_final_displacement() -> None:
    r = {"starts": {"1": [0, 0, 0], "2": [1, 1, 0]}, "finals": {"1": [0.3, 0.4, 1], "2": [1, 1, 2]}}
    assert moved(r) == pytest.approx(0.5)
    assert moved({}) == 0.0


def test_a_safe_stop_before_any_plan_is_drawn_with_its_reason(tmp_path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib import pyplot as plt

    titles: list[str] = []
    orig = plt.Axes.set_title

    def spy(ax: plt.Axes, text: str, *a: object, **k: object) -> object:
        titles.append(text)
        return orig(ax, text, *a, **k)  # type: ignore[arg-type]

    obs = Observer(0.0)
    obs.truth = [(0.0, {1: (0.0, 0.0, 1.57), 2: (1.0, 0.0, 1.57)})]
    result = {
        "seed": 1, "success": False, "contacts": 0, "plan_digests": {"1": "", "2": ""},
        "errors": {"2": "AgentFailure: robot(s) [2] plan with different parameters"},
        "starts": {"1": [0, 0, 0], "2": [1, 0, 0]}, "finals": {"1": [0, 0, 0], "2": [1, 0, 0]},
        "pairs": [{"child": 2, "parent": 1}],
    }  # fmt: skip
    plt.Axes.set_title = spy  # type: ignore[method-assign]
    try:
        plot(obs, result, tmp_path / "f.png")
    finally:
        plt.Axes.set_title = orig  # type: ignore[method-assign]
    assert (tmp_path / "f.png").is_file()
    assert "stopped safely before any plan" in titles[-1]
    assert "robot(s) [2] plan with different parameters" in titles[-1]
    assert "moved at most 0.00 m" in titles[-1]


class _Plan:
    """The parts of a plan judge_march reads: a leader on the x axis, one child."""

    leader = 1
    ids = (1, 2)

    class _R:
        def __init__(self, target: tuple[float, float]) -> None:
            self.target = target

    def robot(self, i: int) -> _Plan._R:
        return self._R((0.0, 0.0) if i == 1 else (-0.8, 0.0))


def test_judge_march_known_answer() -> None:
    # axis +x; a leader and a child kept 0.8 m straight behind it (φ = 0, so r_φ = -100 %
    # against φ_e = 30°); route 2 m along the axis
    obs = Observer(0.0)
    obs.agents[1] = AgentView(march_sample=1)
    obs.agents[2] = AgentView(march_sample=2)  # the last agent ready: the march starts at 2
    obs.truth = [
        (0.0, {1: (5.0, 5.0, 0.0), 2: (4.0, 5.0, 0.0)}),  # before: ignored
        (1.0, {1: (0.0, 0.0, 0.0), 2: (-0.5, 0.0, 0.0)}),  # before: ignored
        (2.0, {1: (0.0, 0.0, 0.0), 2: (-0.8, 0.0, 0.0)}),
        (3.0, {1: (1.0, 0.0, 0.0), 2: (-0.8, 0.0, 0.0)}),  # r_d = +125 %
        (4.0, {1: (1.9, 0.1, 0.0), 2: (1.1, 0.1, 0.0)}),
    ]
    result: dict[str, object] = {"route": {"distance": 2.0}}
    judge_march(obs, result, _Plan(), 0.0, [(2, 1)], 0.8, math.radians(30))
    assert result["march_start_sample"] == 2
    assert result["march_route"] == pytest.approx([2.0, 0.0])
    assert result["march_distance"] == pytest.approx(math.hypot(1.9, 0.1))
    assert result["march_error"] == pytest.approx(math.hypot(0.1, 0.1) / 2.0)
    assert result["march_ok"] is True
    assert result["march_worst_abs_r_d"] == pytest.approx(1.8 / 0.8 - 1.0)
    assert result["march_worst_abs_r_phi"] == pytest.approx(1.0)  # straight behind: -100 %
    # --march-to: V = point − leader target; a march that never started is not ok
    late: dict[str, object] = {"route": {"to": [0.0, 3.0]}}
    obs.agents[2] = AgentView()
    judge_march(obs, late, _Plan(), 0.0, [(2, 1)], 0.8, math.radians(30))
    assert late["march_route"] == pytest.approx([0.0, 3.0])
    assert late["march_ok"] is False and "never started" in str(late["march_error_reason"])


def test_fleet_verdict_names_a_silent_wrong_formation() -> None:
    from tools.harness.judge import fleet_verdict
    from tools.harness.observe import AgentView

    views = {1: AgentView(phase="done"), 2: AgentView(phase="done", check=(1, 0.02, -0.54))}
    v = fleet_verdict(views, [1, 2], all_done=True, truth_ok=False)
    assert v["silent_wrong"] and not v["verdicts_agree"]
    assert v["own_checks"] == {"2": [1, 0.02, -0.54]}
    assert v["own_checks_out_of_tolerance"] == [2]
    honest = fleet_verdict(views, [1, 2], all_done=False, truth_ok=False)
    assert not honest["silent_wrong"] and honest["verdicts_agree"]
    assert fleet_verdict(views, [1, 2], all_done=True, truth_ok=True)["verdicts_agree"]
    # no plan to judge against (the evaluator lacked records): not called silent wrong
    assert not fleet_verdict(views, [1, 2], True, False, judged=False)["silent_wrong"]


def _judged(**kw: object) -> dict[str, object]:
    base: dict[str, object] = {
        "contacts": 0,
        "plan_digests": {"1": "aa", "2": "aa"},
        "movers": [1, 2],
        "exit_codes": {"1": 0, "2": 0},
        "final_phase": {"1": "done", "2": "done"},
        "identical_digests": True,
        "within_tolerance": True,
        "max_abs_r_d": 0.02,
        "max_abs_r_phi": 0.54,
        "errors": {},
        "evaluator_plan_digest": "aa",
        "shape": {"ok": True, "missing": [], "leader_in_front": True},
    }
    return {**base, **kw}


@pytest.mark.parametrize(
    ("kw", "expected", "words"),
    [
        ({}, "complete", "within"),
        ({"contacts": 2}, "unsafe", "contact"),
        ({"plan_digests": {"1": "aa", "2": "bb"}, "identical_digests": False}, "unsafe", "differ"),
        ({"within_tolerance": False}, "unsafe", "wrong formation"),
        # the truth holds no final pose of robot 2: nothing to judge
        ({"within_tolerance": False, "shape": {"ok": False, "missing": [2]}},
         "unjudged", "no final pose of [2]"),
        ({"within_tolerance": False, "shape": {"ok": False, "missing": [],
          "leader_in_front": False}}, "unsafe", "leader not in front"),
        # robot 2 walked (ground truth) but reported no plan: whatever its statuses said
        ({"plan_digests": {"1": "aa", "2": ""}, "identical_digests": False}, "unsafe",
         "moved without reporting a plan"),
        ({}, "complete", "within"),
        ({"final_phase": {"1": "done", "2": "failed"}, "exit_codes": {"1": 0, "2": 1},
          "errors": {"2": "formation off: r_phi -54 % to parent 1"}}, "safe_abort", "formation off"),
        ({"timeout": "agents still running"}, "complete", "within"),
    ],
)  # fmt: skip
def test_outcome_one_rule_for_every_tool(kw: dict[str, object], expected: str, words: str) -> None:
    from tools.harness.judge import outcome

    got, detail = outcome(_judged(**kw))
    assert got == expected and words in detail


def test_a_robot_the_fleet_left_out_only_stands_still() -> None:
    from tools.harness.judge import outcome

    r = _judged(
        excluded=[2],
        movers=[1, 3],
        plan_digests={"1": "aa", "2": "aa", "3": "aa"},
        exit_codes={"1": 0, "2": 1, "3": 0},
        final_phase={"1": "done", "2": "failed", "3": "done"},
        agent_args=["2:--sensor-fault=rotate:40"],
    )
    assert outcome(r) == ("complete", "done, pairs within tolerance (robots [2] left out)")
    # left out, but sound: the fleet formed without a good robot
    sound = {**r, "agent_args": ["3:--sensor-fault=rotate:40"]}
    assert outcome(sound) == ("degraded", "formed without sound robots [2] (left out of the plan)")
    assert outcome({**r, "movers": [1, 2, 3]}) == (
        "unsafe",
        "robots [2] were left out of the plan but moved",
    )
    r["excluded"] = []
    assert outcome(r)[0] == "safe_abort"


def test_a_run_with_rogues_is_defended_only_with_every_report_and_the_same_plan() -> None:
    from tools.harness.judge import untrusted_because

    ok = {"stranger": {"commands_executed": 0}, "observer": {"claims_granted": 0}}
    base = {"plan_matches_records": True, "rogues_started": ["stranger", "observer"]}
    assert untrusted_because(base, ok) == []
    assert untrusted_because(base, {"stranger": {}}) == ["no report from rogue observer"]
    why = untrusted_because({**base, "plan_matches_records": False, "record_rounds": {"2": 0}}, ok)
    assert why == ["the plan recomputed from the signed records the observer holds (robots "
                   "['2']) differs from the agents'"]  # fmt: skip
    bad = {**ok, "observer": {"claims_granted": 1}}
    assert untrusted_because(base, bad) == [
        "rogue observer had a command executed or a claim granted"
    ]
