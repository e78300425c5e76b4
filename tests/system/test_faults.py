"""Crashed agents and restarted routers with real processes (tools.eval_faults).

A secure fleet (TLS router, every process a zenoh client, agents with ``--state-dir``):

* an agent killed (SIGKILL) after agreement, during its move, and started again 3 s
  later resumes from its journal (fetches the agreed records by digest, recomputes the
  same plan, goes on from its leg) and the fleet finishes the formation;
* the same run again over the same folder (the stale journal): every agent
  finds its journal of the finished run in the same ``--state-dir``, archives it and
  starts a new run, which completes too (before, it resumed the old agreement and
  stopped after 60 s with "nobody served the agreed records");
* an agent killed during its search searches again, and is planned on like the rest;
* the router killed while the fleet moves and started again 3 s later: the clients
  reconnect, the grace period keeps the membership, the fleet finishes.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from tools import eval_faults

pytestmark = [pytest.mark.system, pytest.mark.slow]


def _run(fault: str, tmp_path: Path) -> tuple[eval_faults.Run, Path]:
    args = eval_faults.parse_args(["--fault", fault, "--timeout", "600"])
    out = tmp_path / fault.replace("@", "-")
    return eval_faults.run_one(args, fault, 1, out), out


@pytest.fixture(scope="module")
def killed_in_move(tmp_path_factory: pytest.TempPathFactory) -> tuple[eval_faults.Run, Path]:
    """The first pass of ``kill-agent@move`` (its folder's ``state/`` then holds the
    journals of a finished run)."""
    return _run("kill-agent@move", tmp_path_factory.mktemp("faults"))


def test_agent_killed_during_its_move_resumes_and_the_formation_completes(
    killed_in_move: tuple[eval_faults.Run, Path],
) -> None:
    run, out = killed_in_move
    assert run.victim >= 0 and run.injected_at_s is not None, run
    assert run.outcome == "complete", run
    assert run.contacts == 0
    log = (out / f"agent-{run.victim}.log").read_text(errors="replace")
    assert "resumes at move" in log and "fetched from robot" in log, log[-2000:]


def test_the_same_run_again_over_the_finished_runs_journals_completes(
    killed_in_move: tuple[eval_faults.Run, Path],
) -> None:
    first, out = killed_in_move
    assert first.outcome == "complete", first  # the journals left are of a finished run
    journals = sorted(p.name for p in (out / "state").iterdir())
    assert journals, "the first pass left no journal"
    args = eval_faults.parse_args(["--fault", "kill-agent@move", "--timeout", "600"])
    run = eval_faults.run_one(args, "kill-agent@move", 1, out)  # the same folder
    assert run.outcome == "complete", run
    assert run.contacts == 0
    logs = sorted(out.glob("agent-*.log"))
    assert len(logs) == args.robots, logs
    for path in logs:  # every agent of the second pass: the old journal set aside
        log = path.read_text(errors="replace")
        assert "starts a new run: the run ended for this robot" in log, log[:3000]
        assert "journal archived as" in log, log[:3000]
        assert "nobody served the agreed records" not in log, log[-2000:]


def test_router_killed_during_the_move_and_restarted_the_formation_completes(
    tmp_path: Path,
) -> None:
    run, _ = _run("kill-router@move", tmp_path)
    assert run.injected_at_s is not None, run
    assert run.outcome == "complete", run
    assert run.contacts == 0


def test_agent_killed_during_its_search_is_in_the_pyramid(tmp_path: Path) -> None:
    """Killed mid-search and started again, the robot searches again and its record's
    stances begin with the instant it was set down: the others' masks of it, taken while
    its body stood where the crash left it, are set aside, and it is planned on like the
    rest (judged from the truth: ``complete``, never ``degraded``)."""
    run, out = _run("kill-agent@search", tmp_path)
    assert run.victim >= 0 and run.injected_at_s is not None, run
    assert run.outcome == "complete", run
    assert run.contacts == 0
    log = (out / f"agent-{run.victim}.log").read_text(errors="replace")
    assert "resumes at search" in log, log[-2000:]
