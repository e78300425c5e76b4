"""Robots set down facing any direction, as real processes (docs/design.md §9).

``python -m tools.demo --headings random`` (world + agents over loopback, secure by
default) and one robot with an injected sensor fault (``--sensor-fault``, the agent's
test tool). Both are judged with the one rule of the evaluation tools
(``tools.harness.judge.outcome``). Runs vary with the load on the machine, so the tests
accept a formation or an honest stop, and fail on what must never happen: a contact,
robots walking on plans they do not share, or every agent saying "done" on a formation
the ground truth fails.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.system.world import run_demo
from tools.harness.judge import outcome

pytestmark = [pytest.mark.system, pytest.mark.slow]


def _judged(r: dict[str, object]) -> tuple[str, str]:
    assert r, "the demo wrote no result"
    got, detail = outcome(r)
    assert got != "unsafe", detail
    assert r["contacts"] == 0
    return got, detail


def test_four_robots_facing_random_directions(tmp_path: Path) -> None:
    res, r = run_demo(tmp_path, "--robots", "4", "--seed", "1", "--headings", "random")
    got, detail = _judged(r)
    assert r["headings"] == "random"
    starts = [round(v[2], 2) for v in r["starts"].values()]
    assert len(set(starts)) == 4  # they really face four ways
    if got == "complete":
        assert res.returncode == 0 or r["excluded"], detail
        # every child measured its parent and found the pair in tolerance
        assert set(r["own_checks"]) == {str(c["child"]) for c in r["pairs"]}
    else:  # an honest stop: some agent said why
        assert r["errors"], detail


def test_a_robot_with_a_shifted_record(tmp_path: Path) -> None:
    _, r = run_demo(
        tmp_path, "--robots", "5", "--seed", "2", "--agent-arg=3:--sensor-fault=shift:0.5"
    )
    got, detail = _judged(r)
    if r.get("excluded"):
        assert r["excluded"] == [3], r.get("verdict")
    assert "sensor fault shift:0.5" in (tmp_path / "demo" / "agent-3.log").read_text()
    assert got in ("complete", "safe_abort"), detail
