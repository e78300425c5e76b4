"""Crashed agents and restarted routers with real processes (issue #9; tools.eval_faults).

A secure fleet (TLS router, every process a zenoh client, agents with ``--state-dir``):

* an agent killed (SIGKILL) after agreement, during its move, and started again 3 s
  later resumes from its journal (fetches the agreed records by digest, recomputes the
  same plan, goes on from its leg) and the fleet finishes the formation;
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


def test_agent_killed_during_its_move_resumes_and_the_formation_completes(
    tmp_path: Path,
) -> None:
    run, out = _run("kill-agent@move", tmp_path)
    assert run.victim >= 0 and run.injected_at_s is not None, run
    assert run.outcome == "complete", run
    assert run.contacts == 0
    log = (out / f"agent-{run.victim}.log").read_text(errors="replace")
    assert "resumes at move" in log and "fetched from robot" in log, log[-2000:]


def test_router_killed_during_the_move_and_restarted_the_formation_completes(
    tmp_path: Path,
) -> None:
    run, _ = _run("kill-router@move", tmp_path)
    assert run.injected_at_s is not None, run
    assert run.outcome == "complete", run
    assert run.contacts == 0
