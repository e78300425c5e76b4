"""The operator's side of reshaping (tools/lib/reshape.py, ``tools.fleet reshape``, the
demo's ``--reshape``): when it sends, re-sends and stops; how a transition is judged and
timed; a robot's key cannot command; the flags and the judge of the final shape."""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from agent.config import load_shape
from agent.core.formation.params import PlanParams
from agent.core.formation.plan import plan_from_positions
from agent.core.formation.reshape import command_shape, transition_plan
from agent.core.formation.shape.spec import BUILTIN
from agent.wire import ReshapeMsg
from agent.wire import trust as T
from tools import fleet
from tools.harness.fleet import FleetSpec
from tools.harness.fleet_flags import RESHAPE_WAIT, parse_fleet_spec
from tools.lib.reshape import (
    Reshaper,
    Seen,
    command_of,
    final_shape_spec,
    held_digest,
    judge_reshapes,
)

ROOT = Path(__file__).resolve().parents[2]
A, B, C = "aa" * 32, "bb" * 32, "cc" * 32
ROBOTS = (1, 2, 3)


def fleet_at(phase: str, digest: str, t: float = 10.0, detail: str = "") -> dict[int, Seen]:
    return {i: Seen(phase, digest, t, detail) for i in ROBOTS}


def operator(*shapes: str) -> tuple[Reshaper, list[ReshapeMsg]]:
    sent: list[ReshapeMsg] = []
    op = Reshaper([BUILTIN[s] for s in shapes], ROBOTS, sent.append, resend=2.0, timeout=60.0)
    return op, sent


def test_command_of_a_builtin_and_a_file_give_back_their_shape() -> None:
    for shape in (BUILTIN["wedge"], load_shape(str(ROOT / "docs/examples/wedge.json"))):
        msg = command_of(shape, A, 3)
        assert (msg.base, msg.command, msg.shape_digest) == (A, 3, shape.digest)
        got = command_shape(msg.name, msg.rule, msg.orient, msg.slots, msg.shape_digest)
        assert got.digest == shape.digest


def test_held_digest_needs_every_robot_done_on_one_plan() -> None:
    assert held_digest(fleet_at("done", A), ROBOTS) == A
    mixed = {**fleet_at("done", A), 3: Seen("done", B)}
    assert held_digest(mixed, ROBOTS) == ""
    assert held_digest({**fleet_at("done", A), 2: Seen("hold", A)}, ROBOTS) == ""
    assert held_digest({1: Seen("done", A)}, ROBOTS) == ""


def test_two_shapes_in_turn_sent_once_the_fleet_holds_resent_until_taken() -> None:
    op, sent = operator("line", "wedge")
    assert op.step(0.0, fleet_at("hold", A)) and sent == []  # not held yet: wait
    assert op.step(1.0, fleet_at("done", A, t=100.0))
    assert [(m.command, m.base, m.name) for m in sent] == [(1, A, "line")]
    op.step(2.0, fleet_at("done", A))  # within the re-send period
    op.step(3.5, fleet_at("done", A))  # nobody took it: again
    assert len(sent) == 2
    taking = {**fleet_at("move", B), 3: Seen("done", A)}
    op.step(6.0, taking)  # robot 3 still holds the old plan: again
    assert len(sent) == 3
    op.step(9.0, fleet_at("move", B))  # every robot has left the old plan: no more
    assert len(sent) == 3
    assert op.step(21.0, fleet_at("done", B, t=160.0))
    (line,) = op.done
    assert (line.outcome, line.plan, line.sends) == ("held", B, 3)
    assert line.wall_s == 20.0 and line.sim_s == 60.0
    assert [(m.command, m.base, m.name) for m in sent[3:]] == [(2, B, "wedge")]
    assert not op.step(40.0, fleet_at("done", C, t=200.0))
    assert [t.outcome for t in op.done] == ["held", "held"] and op.ok and not op.pending


def test_a_refusal_or_a_failure_stops_the_operator() -> None:
    op, _ = operator("line", "wedge")
    op.step(0.0, fleet_at("done", A))
    no = "reshape 1 to line refused: shape 'line': its fields make digest x"
    assert not op.step(1.0, fleet_at("done", A, detail=no))
    assert [t.outcome for t in op.done] == ["refused"] and not op.ok
    assert op.done[0].detail == no
    op, _ = operator("line")
    op.step(0.0, fleet_at("done", A))
    assert not op.step(5.0, {**fleet_at("move", B), 2: Seen("failed", B, detail="stuck")})
    assert op.done[0].outcome == "failed" and "robots [2] failed" in op.done[0].detail


def test_a_transition_not_held_in_time_is_a_timeout() -> None:
    op, _ = operator("line")
    op.step(0.0, fleet_at("done", A))
    assert op.step(59.0, fleet_at("move", B))
    assert not op.step(61.0, fleet_at("move", B))
    assert op.done[0].outcome == "timeout" and math.isclose(op.done[0].wall_s, 61.0)


def test_a_robot_key_cannot_command(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    root = tmp_path / "fleet"
    T.create_fleet(root, [1, 2])
    robot = tmp_path / "robot-1"
    assert fleet.main(["export", str(root), "--identity", "robot-1", "--out", str(robot)]) == 0
    argv = ["reshape", "--shape", "line", "--fleet-size", "2", "--credentials", str(robot)]
    assert fleet.main([*argv, "--connect", "tls/127.0.0.1:9", "--no-multicast-scouting"]) == 2
    assert "no usable private key for operator" in capsys.readouterr().err
    bad = ["reshape", "--shape", "nope", "--fleet-size", "2", "--credentials", str(root)]
    assert fleet.main(bad) == 2
    assert "neither a built-in" in capsys.readouterr().err


def test_the_demo_flags_give_the_shapes_and_the_agents_wait() -> None:
    spec = parse_fleet_spec(["--robots", "8", "--reshape", "line", "--reshape", "wedge"])
    assert [s.name for s in spec.reshapes] == ["line", "wedge"]
    assert spec.agent.reshape_wait == RESHAPE_WAIT
    assert "--reshape-wait=20.0" in spec.agent_config(1).to_argv()
    assert spec.meta()["reshape_specs"] == ["line", "wedge"]
    assert parse_fleet_spec([]).agent.reshape_wait == 0.0
    assert "reshape_specs" not in parse_fleet_spec([]).meta()
    with pytest.raises(SystemExit):
        parse_fleet_spec(["--reshape", "spiral"])
    with pytest.raises(ValueError, match="need agents that wait"):
        FleetSpec(reshapes=(BUILTIN["line"],))


def test_the_judge_recomputes_the_transitions_held_and_the_final_shape() -> None:
    p = PlanParams()
    first = plan_from_positions([1, 2, 3], [[0.0, 0.0], [1.5, 0.0], [0.0, 1.5]], p)
    result: dict[str, object] = {"shape_spec": "pyramid", "reshape_specs": ["line", "wedge"]}
    assert final_shape_spec(result) == "pyramid"
    result["reshapes"] = [{"outcome": "held"}, {"outcome": "refused"}]
    final = judge_reshapes(result, first, p)
    assert final.digest == transition_plan(first, BUILTIN["line"], p).digest
    assert result["evaluator_plan_digest"] == final.digest and result["reshape_ok"] is False
    assert final_shape_spec(result) == "line"
    result["reshapes"] = [{"outcome": "held"}, {"outcome": "held"}]
    judge_reshapes(result, first, p)
    assert result["reshape_ok"] is True and final_shape_spec(result) == "wedge"


def test_a_robot_the_fleet_left_out_is_no_member_to_reshape() -> None:
    """It stopped by design (``failed``, left out of the plan) and stands still: the
    others hold, so the command goes out, and the transition is judged on them."""
    op, sent = operator("line")
    out = Seen("failed", A, 5.0, "", "AgentFailure: left out of the plan, standing still: x")
    assert op.step(0.0, {**fleet_at("done", A), 3: out}) and len(sent) == 1
    assert sent[0].base == A
    assert not op.step(9.0, {**fleet_at("done", B, t=50.0), 3: out})
    assert op.ok and op.done[0].sim_s == 40.0
    # a robot that failed otherwise is a failure of the fleet
    op, sent = operator("line")
    broken = Seen("failed", A, 5.0, "", "AgentFailure: formation off: parent 1")
    assert op.step(0.0, {**fleet_at("done", A), 3: broken}) and sent == []
