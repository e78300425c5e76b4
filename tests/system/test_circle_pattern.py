"""The circle pattern walked end to end with real processes (AUV paper III.B.2.a;
docs/formation.md "The circle pattern"): ``python -m tools.demo --robots 4 --orientation
cp`` (secure, one agent process per NAO, the rendered perception).

Every robot but the frame robot walks to the circle round it, fine-tunes its place from
a look at it, then the robot at 90° leads the pyramid from the circle. The ground truth
judges the pyramid; the evaluator recomputes both plans from the signed records and
gets the agents' final digest; the frame robot did not move while the circle was built.
"""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from tests.system.world import run_demo

pytestmark = [pytest.mark.system, pytest.mark.slow]


def test_four_naos_walk_the_circle_then_build_the_pyramid(tmp_path: Path) -> None:
    res, r = run_demo(tmp_path, "--robots", "4", "--seed", "1", "--orientation", "cp")
    assert res.returncode == 0, res.stdout[-3000:] + res.stderr[-3000:]
    assert r["outcome"] == "complete" and r["contacts"] == 0
    assert r["plan_matches_records"] is True and r["identical_digests"] is True
    assert r["shape"]["ok"] is True
    # the pyramid faces north (the truth), led by the robot the evaluator's plan names
    assert abs(math.remainder(r["shape"]["facing_deg"] - 90.0, 360.0)) < 10.0
    assert abs(math.remainder(r["axis_deg"] - 90.0, 360.0)) < 1.0  # the aligned starts'
    assert r["shape"]["leader"] == r["leader"]
    logs = "".join(p.read_text() for p in (tmp_path / "demo").glob("agent-*.log"))
    assert logs.count("from the circle") == 4  # every agent planned from the circle
    assert "correction 1: parent" in logs  # the fine tuning on the centre robot
