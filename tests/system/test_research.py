"""Re-search (NAO paper 4.1.3 rule 2) with real processes: the world and four agents.

Both scenarios (``sim/scenarios/research_*.json``) hold robots 1–3 within sight of each
other and robot 4 beyond sight (> 4 m from everyone; the detector sees NAOs to ~3.5 m):

- ``research_found``: robot 4's first exploration leg (2 m, the spiral's heading for
  id 4) brings it within ~2.5 m of the fleet; after one re-search round the fleet
  agrees on round-1 records and builds the pyramid.
- ``research_lost``: the leg leads away from the fleet; with ``--research-rounds 1``
  every agent stops with the same reason after one round, and robots 1–3 never walk
  (they only turn on the spot while searching again).
"""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest

pytestmark = [pytest.mark.system, pytest.mark.slow]

ROOT = Path(__file__).resolve().parents[2]


def demo(tmp_path: Path, scenario: str, *extra: str) -> dict[str, Any]:
    out = tmp_path / "demo"
    cmd = [
        sys.executable, "-m", "tools.demo", "--robots", "4",
        f"--world-arg=--scenario={ROOT / 'sim' / 'scenarios' / scenario}.json",
        "--out", str(out), "--json", str(tmp_path / "result.json"), "--timeout", "420", *extra,
    ]  # fmt: skip
    res = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, timeout=480)
    assert (tmp_path / "result.json").exists(), res.stderr[-3000:]
    r: dict[str, Any] = json.loads((tmp_path / "result.json").read_text())
    r["stdout"] = res.stdout
    r["returncode"] = res.returncode
    return r


def moved(r: dict[str, Any], rid: int) -> float:
    (x0, y0, _), (x1, y1, _) = r["starts"][str(rid)], r["finals"][str(rid)]
    return math.hypot(x1 - x0, y1 - y0)


def test_robot_beyond_sight_finds_the_fleet_by_re_search(tmp_path: Path) -> None:
    r = demo(tmp_path, "research_found")
    assert r["exit_codes"] == {"1": 0, "2": 0, "3": 0, "4": 0}, r.get("errors")
    assert set(r["final_phase"].values()) == {"done"}
    # everyone's agreed record is of re-search round 1
    assert r["record_rounds"] == {"1": 1, "2": 1, "3": 1, "4": 1}
    assert r["identical_digests"] is True
    assert r["evaluator_plan_digest"] == r["plan_digests"]["1"]
    assert len(r["pairs"]) == 3
    for p in r["pairs"]:
        assert abs(p["r_d"]) <= 0.125 and abs(p["r_phi"]) <= 0.30, p
    assert r["contacts"] == 0
    assert r["success"] is True and r["returncode"] == 0
    log = (tmp_path / "demo" / "agent-1.log").read_text()
    assert "re-search round 1: fleet not connected: robots [4]" in log
    assert (tmp_path / "demo" / "formation.png").read_bytes()[:4] == b"\x89PNG"


def test_robot_that_cannot_find_the_fleet_stops_everyone_cleanly(tmp_path: Path) -> None:
    r = demo(tmp_path, "research_lost", "--research-rounds", "1")
    assert r["returncode"] == 1 and "RESULT: FAILURE" in r["stdout"]
    assert r["exit_codes"] == {"1": 1, "2": 1, "3": 1, "4": 1}
    assert set(r["final_phase"].values()) == {"failed"}
    reasons = set(r["errors"].values())
    assert len(reasons) == 1, reasons  # every agent stopped for the same reason
    (why,) = reasons
    assert "robots [4] outside the group of robots [1, 2, 3]" in why
    assert "after 1 re-search round(s)" in why
    assert r["record_rounds"] == {"1": 1, "2": 1, "3": 1, "4": 1}
    assert set(r["plan_digests"].values()) == {""}  # nobody planned
    assert r["contacts"] == 0
    # robot 4 explored (about 2 m); the others never walked
    assert moved(r, 4) > 1.5
    for i in (1, 2, 3):
        assert moved(r, i) < 0.05, (i, moved(r, i))
