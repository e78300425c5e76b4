"""A shape other than the pyramid end to end: ``python -m tools.demo --shape line`` with 3
robots as real processes (world + 3 agents over loopback), judged from the ground truth
against the line's own tree (the leader in the middle, a child d_e to each side)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

pytestmark = [pytest.mark.system, pytest.mark.slow]

ROOT = Path(__file__).resolve().parents[2]


def test_three_robots_build_a_line(tmp_path: Path) -> None:
    res = subprocess.run(
        [sys.executable, "-m", "tools.demo", "--robots", "3", "--seed", "1", "--shape", "line",
         "--out", str(tmp_path / "demo"), "--json", str(tmp_path / "result.json"),
         "--timeout", "240", "--no-publish-camera"],
        cwd=ROOT, capture_output=True, text=True, timeout=290,
    )  # fmt: skip
    assert "identical plan digests" in res.stdout, res.stderr[-2000:]
    r = json.loads((tmp_path / "result.json").read_text())
    assert r["shape_spec"] == "line"
    assert r["exit_codes"] == {"1": 0, "2": 0, "3": 0}, r.get("errors")
    assert r["identical_digests"] is True
    assert r["evaluator_plan_digest"] == r["plan_digests"]["1"]
    # the line from ground truth: the leader's two children, one on each side, in tolerance
    assert len(r["pairs"]) == 2
    assert sorted(p["side"] for p in r["pairs"]) == ["left", "right"]
    for p in r["pairs"]:
        assert p["parent"] == r["leader"]
        assert abs(p["r_d"]) <= 0.125 and abs(p["r_phi"]) <= 0.30, p
        assert abs(p["angle_deg"] - 90.0) <= 9.0, p  # beside the parent, not behind it
    assert r["contacts"] == 0 and r["min_separation"] > 0.4
    assert r["success"] is True and res.returncode == 0
