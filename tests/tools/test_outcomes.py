"""Every outcome of tools.harness.judge.outcome, from a truth stream: the recorded 3-NAO run
(tests/data/demo-3-seed1.mcap) and synthetic streams, judged end to end by
``summarise`` (who moved and the shape from the truth, exit codes as the processes
gave them); the tools' failure counts."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import pytest

from agent.wire import NeighborRecordMsg
from tests.tools.test_truth import PHI, D, pyramid
from tools.harness import report
from tools.harness.judge import FAILURES, OUTCOMES, outcome, summarise
from tools.harness.observe import AgentView, Observer

DATA = Path(__file__).resolve().parents[1] / "data"
A, B = "a" * 64, "b" * 64


def recorded(name: str = "demo-3-seed1.mcap") -> Observer:
    """The observer of a recorded run, as tools.demo saw it (every message in order)."""
    from mcap.reader import make_reader

    from agent.wire import decode

    obs = Observer(0.0)
    with (DATA / name).open("rb") as f:
        for _, channel, message in make_reader(f).iter_messages(log_time_order=True):
            if channel.message_encoding == "msgpack":
                obs.take(channel.topic, decode(message.data), None)
    return obs


def judged(
    obs: Observer, tmp: Path, codes: dict[int, int | None], quiet: bool = True, **extra: Any
) -> dict[str, Any]:
    for i, c in codes.items():
        obs.agents.setdefault(i, AgentView()).exit_code = c
    result = {"robots": len(codes), "seed": 1, "d_e": D, "phi_e_deg": 30.0, **extra}
    return summarise(obs, result, tmp, sorted(codes), D, PHI, quiet)


def synthetic(track: dict[int, list[tuple[float, float, float]]]) -> Observer:
    """An observer whose truth stream has sample k of each robot's ``track``."""
    obs = Observer(0.0)
    for k in range(max(len(t) for t in track.values())):
        obs.truth.append((float(k), {i: t[min(k, len(t) - 1)] for i, t in track.items()}))
    return obs


def agent(phase: str, digest: str = "", error: str = "") -> AgentView:
    return AgentView(phase=phase, plan_digest=digest, error=error)


def test_complete_on_the_recorded_run(tmp_path: Path) -> None:
    r = judged(recorded(), tmp_path, {1: 0, 2: 0, 3: 0})
    assert r["outcome"] == "complete" and r["success"]
    assert sorted(r["movers"]) == [1, 2, 3] and r["shape"]["ok"] and r["shape"]["leader"] == 2
    assert {p["side"] for p in r["pairs"]} == {"left", "right"}
    assert r["plan_matches_records"]  # the evaluator's plan still names who is left out
    # the same run with an agent that did not exit 0 is no success (its process says so)
    again = judged(recorded(), tmp_path, {1: 0, 2: 1, 3: 0})
    assert again["outcome"] == "safe_abort" and not again["success"]


def test_complete_on_the_recorded_circle_pattern_run(tmp_path: Path) -> None:
    """4 NAOs with ``--orientation cp`` (seed 1, aligned starts): the evaluator plans the
    circle and the pyramid from it, and gets the agents' final digest; the truth's
    pyramid faces north, led by the robot the circle put at 90°, and the frame robot did
    not move while the circle was built."""
    r = judged(recorded("demo-cp-4-seed1.mcap"), tmp_path, {1: 0, 2: 0, 3: 0, 4: 0},
               orientation="cp")  # fmt: skip
    assert r["outcome"] == "complete" and r["success"] and r["plan_matches_records"]
    assert abs(r["axis_deg"] - 90.0) < 1.0 and abs(r["shape"]["facing_deg"] - 90.0) < 5.0
    assert r["shape"]["leader"] == r["leader"] == 4
    assert r["t_sim_settled"] > r["t_sim_plan"] > 0.0
    # judged without the orientation, the records plan another formation: no match
    other = judged(recorded("demo-cp-4-seed1.mcap"), tmp_path, {1: 0, 2: 0, 3: 0, 4: 0})
    assert not other["plan_matches_records"]


def fleet_with_one_left_out() -> Observer:
    """Robots 1-3 walk into a pyramid; robot 4 stands still, left out by the fleet."""
    final = pyramid(3, math.pi / 2, (0.0, 1.0))
    starts = {1: (0.0, -1.0, math.pi / 2), 2: (-1.5, -1.0, math.pi / 2), 3: (1.5, -1.0, 0.0)}
    obs = synthetic({i: [starts[i], final[i]] for i in (1, 2, 3)} | {4: [(3.0, 3.0, 0.0)]})
    for i in (1, 2, 3):
        obs.agents[i] = agent("done", A)
    obs.agents[4] = agent("failed", A, "left out of the plan, standing still: masks disagree")
    return obs


def test_complete_when_only_the_faulty_robot_is_left_out(tmp_path: Path) -> None:
    r = judged(fleet_with_one_left_out(), tmp_path, {1: 0, 2: 0, 3: 0, 4: 1}, excluded=[4],
               agent_args=["4:--sensor-fault=shift:0.5"])  # fmt: skip
    assert (r["outcome"], r["success"]) == ("complete", True)
    assert r["injected_faults"] == [4] and r["movers"] == [1, 2, 3]


def test_degraded_when_a_sound_robot_is_left_out(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    r = judged(fleet_with_one_left_out(), tmp_path, {1: 0, 2: 0, 3: 0, 4: 1}, quiet=False,
               excluded=[4], agent_args=["2:--sensor-fault=shift:0.5"])  # fmt: skip
    assert r["outcome"] == "degraded" and not r["success"]
    assert "sound robots [4]" in r["outcome_detail"]
    assert "RESULT: DEGRADED" in capsys.readouterr().out
    assert "degraded" in FAILURES


def test_unsafe_a_robot_walked_but_its_plan_was_never_heard(tmp_path: Path) -> None:
    # robot 3 walked 1 m; its statuses (and plan) were lost, it never said "move": judged
    # by statuses it stood still, by the truth it moved without a plan
    obs = synthetic(
        {1: [(0.0, 0.0, 0.0)], 2: [(2.0, 0.0, 0.0)], 3: [(4.0, 0.0, 0.0), (4.0, 1.0, 0.0)]}
    )
    obs.agents[1] = agent("failed", error="no agreement")
    obs.agents[2] = agent("failed", error="no agreement")
    obs.agents[3] = agent("search")
    r = judged(obs, tmp_path, {1: 1, 2: 1, 3: 1})
    assert "move" not in obs.agents[3].phase_wall  # no status ever said so
    assert r["movers"] == [3] and r["moved_m"]["3"] == pytest.approx(1.0)
    assert outcome(r) == ("unsafe", "robots [3] moved without reporting a plan")


def test_unsafe_a_robot_walked_on_a_plan_nobody_else_shared(tmp_path: Path) -> None:
    obs = synthetic(
        {1: [(0.0, 0.0, 0.0)], 2: [(2.0, 0.0, 0.0)], 3: [(4.0, 0.0, 0.0), (4.0, 1.0, 0.0)]}
    )
    obs.agents[1], obs.agents[2] = agent("failed", A), agent("failed", A)
    obs.agents[3] = agent("failed", B)
    r = judged(obs, tmp_path, {1: 1, 2: 1, 3: 1})
    assert r["outcome"] == "unsafe" and "plan digests differ" in r["outcome_detail"]


def test_unsafe_every_agent_done_on_a_wrong_formation(tmp_path: Path) -> None:
    final = pyramid(3, math.pi / 2)
    final[3] = (1.3 * final[3][0], 1.3 * final[3][1], final[3][2])  # r_d +30 %
    obs = synthetic({i: [(3.0 * i, -3.0, 0.0), final[i]] for i in (1, 2, 3)})
    for i in (1, 2, 3):
        obs.agents[i] = agent("done", A)
    r = judged(obs, tmp_path, {1: 0, 2: 0, 3: 0})
    assert r["outcome"] == "unsafe" and "wrong formation" in r["outcome_detail"]
    assert r["silent_wrong"]


def test_safe_abort_exploring_before_the_last_record_is_no_move(tmp_path: Path) -> None:
    # robot 3 explored 2 m (a re-search round), published its round-1 record, then the
    # fleet stopped: nobody moved after the records the plan would start from
    obs = synthetic({1: [(0.0, 0.0, 0.0)], 2: [(1.0, 0.0, 0.0)],
                     3: [(5.0, 0.0, 0.0), (6.0, 0.0, 0.0), (7.0, 0.0, 0.0)]})  # fmt: skip
    obs.take("nao/3/record", NeighborRecordMsg(sender=3, neighbours=(), round=0), None)
    obs.truth.extend(obs.truth[-1:] * 2)
    obs.take("nao/3/record", NeighborRecordMsg(sender=3, neighbours=(), round=1), None)
    for i in (1, 2, 3):
        obs.agents[i] = agent("failed", error="no plan: too few robots seen")
    r = judged(obs, tmp_path, {1: 1, 2: 1, 3: 1})
    assert r["movers"] == [] and r["moved_m"]["3"] == 0.0
    assert r["outcome"] == "safe_abort" and "too few robots" in r["outcome_detail"]


def test_unjudged_when_the_truth_lost_a_member(tmp_path: Path) -> None:
    final = pyramid(3, math.pi / 2)
    obs = synthetic({i: [final[i]] for i in (1, 2)})
    for i in (1, 2, 3):
        obs.agents[i] = agent("done", A)
    r = judged(obs, tmp_path, {1: 0, 2: 0, 3: 0})
    assert r["outcome"] == "unjudged" and "[3]" in r["outcome_detail"] and not r["success"]


def test_no_result_is_a_failure_in_every_tool() -> None:
    from tools import eval_chaos, eval_scale

    assert outcome({}) == ("no_result", "no result")
    assert outcome({"no_result": "demo: world not ready"}) == ("no_result", "demo: world not ready")
    row = eval_scale.row_of({"no_result": "demo: world not ready"}, 3, 1, [])
    assert row.outcome == "no_result" and row.detail == "demo: world not ready"
    assert "no_result" in FAILURES and "safe_abort" not in FAILURES
    rows = [{"outcome": o} for o in OUTCOMES]
    assert report.failures(rows) == 3
    assert report.outcome_counts(rows[:2]) == "complete 1, degraded 1"
    assert set(report.COLOURS) == set(OUTCOMES)
    assert "no_result" in (eval_chaos.__doc__ or "")
