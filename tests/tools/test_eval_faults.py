"""tools.eval_faults: triggers, the verdict of a run (the one rule of
tools.harness.judge.outcome on what eval_faults observes), the report, the command line."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest

from tools import eval_faults
from tools.eval_faults import Run, triggered
from tools.harness.judge import outcome
from tools.harness.observe import AgentView


def view(phase: str, detail: str = "", progress: float = 0.0, digest: str = "") -> AgentView:
    v = AgentView(phase=phase, detail=detail, progress=progress, plan_digest=digest)
    v.phase_wall[phase] = 1.0
    return v


@pytest.mark.parametrize(
    ("phase", "v", "want"),
    [
        ("search", view("search", "θ = 0°, head +20°"), False),
        ("search", view("search", "turn to θ = 180°: +90.0° to go"), True),
        ("agree", view("exchange"), True),
        ("agree", view("agree"), True),
        ("agree", view("search"), False),
        ("wait", view("wait"), True),
        ("move", view("move", progress=0.0), True),
        ("move", view("move", progress=0.2), True),
        ("hold", view("hold"), True),
        ("hold", view("done"), False),
    ],
)
def test_triggers(phase: str, v: AgentView, want: bool) -> None:
    assert triggered(v, phase) is want


def judge(result: dict[str, Any], views: dict[int, AgentView]) -> tuple[str, str]:
    """The verdict of a run whose agents ``views`` showed (movers and plan digests, as
    ``tools.harness.judge.summarise`` records them from eval_faults' observer)."""
    ids = sorted(views)
    seen = {
        "movers": [i for i in ids if "move" in views[i].phase_wall],
        "plan_digests": {str(i): views[i].plan_digest for i in ids},
    }
    return outcome({**seen, **result})


def _result(**over: Any) -> dict[str, Any]:
    r: dict[str, Any] = {
        "exit_codes": {"1": 0, "2": 0},
        "final_phase": {"1": "done", "2": "done"},
        "identical_digests": True,
        "contacts": 0,
        "within_tolerance": True,
        "errors": {},
        "evaluator_plan_digest": "a" * 64,
        "shape": {"ok": True, "missing": [], "leader_in_front": True},
    }
    r.update(over)
    return r


D1, D2 = "a" * 64, "b" * 64


def test_judge_complete_safe_abort_and_unsafe() -> None:
    done = {1: view("done", digest=D1), 2: view("done", digest=D1)}
    for v in done.values():
        v.phase_wall["move"] = 2.0
    assert judge(_result(), done) == ("complete", "done, pairs within tolerance")
    # every agent done on a formation the ground truth fails: a silent wrong "done"
    got, detail = judge(_result(within_tolerance=False), done)
    assert got == "unsafe" and "every agent said done on a wrong formation" in detail
    assert judge(_result(contacts=2), done) == ("unsafe", "2 contact(s)")
    split = {1: view("move", digest=D1), 2: view("wait", digest=D2)}
    got, detail = judge(_result(identical_digests=False), split)
    assert got == "unsafe" and "moved; plan digests differ" in detail
    failed = {1: view("failed"), 2: view("failed")}
    res = _result(
        exit_codes={"1": 1, "2": 1},
        final_phase={"1": "failed", "2": "failed"},
        identical_digests=False,
        errors={"1": "member(s) [2] left before agreement"},
        timeout="agents still running after 9 s",
    )
    got, detail = judge(res, failed)
    assert got == "safe_abort" and "left before agreement" in detail and "still" in detail
    # different digests but nobody walked: safe
    apart = {1: view("wait", digest=D1), 2: view("plan", digest=D2)}
    res2 = _result(exit_codes={"1": 1, "2": 1}, identical_digests=False)
    assert judge(res2, apart)[0] == "safe_abort"


def test_report_table_json_and_figure(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    runs = [
        Run(1, "kill-agent@move", "complete", 0, 80.0, "done", 2, 30.0, True),
        Run(2, "kill-agent@move", "safe_abort", 0, 90.0, "x", 3, 31.0, False),
        Run(1, "kill-router@agree", "complete", 0, 70.0, "done", -1, 20.0),
        Run(1, "kill-agent@wait", "complete", 0, 70.0, "fault never injected"),
    ]
    args = eval_faults.parse_args(["--out", str(tmp_path), "--json", str(tmp_path / "f.json")])
    eval_faults.write(args, runs)
    doc = json.loads((tmp_path / "f.json").read_text())
    outcomes = [r["outcome"] for r in doc["runs"]]
    assert outcomes == ["complete", "safe_abort", "complete", "complete"]
    assert set(doc["runs"][0]) >= {"seed", "fault", "outcome", "contacts", "wall_s", "detail"}
    assert (tmp_path / "faults.png").stat().st_size > 0
    eval_faults.print_table(runs)
    out = capsys.readouterr().out
    assert "kill-agent@move" in out and "all" in out
    merged = tmp_path / "merged"
    argv = ["--report", str(tmp_path / "f.json"), str(tmp_path / "f.json"), "--out", str(merged)]
    assert eval_faults.main(argv) == 0
    assert len(json.loads((merged / "results.json").read_text())["runs"]) == 8


def test_command_line() -> None:
    a = eval_faults.parse_args([])
    assert a.faults == list(eval_faults.FAULTS) and a.restart_after == 3.0
    a = eval_faults.parse_args(["--fault", "kill-agent@wait,kill-router@move"])
    assert a.faults == ["kill-agent@wait", "kill-router@move"]
    with pytest.raises(SystemExit):
        eval_faults.parse_args(["--fault", "kill-agent@fly"])
    with pytest.raises(SystemExit):
        eval_faults.parse_args(["--fault", "kill-router@move", "--insecure"])
    with pytest.raises(SystemExit):
        eval_faults.parse_args(["--seeds", "0"])
