"""Fleet parameters end to end, with real processes (agreed planning parameters).

* A mismatched agent: the world and three ``python -m agent`` processes over loopback,
  one started with ``--orientation cp`` while the others plan with ``pca``. Every agent
  must stop ``failed`` with a reason naming that robot (the odd one too), exit 1,
  never plan, and never walk (ground truth: each ends where it started; the search only
  turns on the spot).
* ``python -m tools.demo --scenario FILE --orientation cp``: robots and ids from the file
  (ids 2, 5, 7, secure fleet), every agent plans the CP pyramid (axis north of the common
  frame) and the fleet builds it.
"""

from __future__ import annotations

import json
import subprocess
import sys
import time
from dataclasses import replace
from pathlib import Path

import pytest

from agent.config import AgentConfig
from sim import scenarios
from tests.system.world import Watch, agent_on, watched_world

pytestmark = [pytest.mark.system, pytest.mark.slow]

ROOT = Path(__file__).resolve().parents[2]


def agent_config(rid: int, orientation: str) -> AgentConfig:
    return AgentConfig(robot_id=rid, fleet_size=3, timeout=60.0, orientation=orientation)


def test_agent_with_other_parameters_is_named_and_nobody_walks(tmp_path: Path) -> None:
    with watched_world(tmp_path, 3, 1) as (ep, bus, ids, procs):
        odd = ids[1]
        agents = {
            i: agent_on(ep, agent_config(i, "cp" if i == odd else "pca"), tmp_path) for i in ids
        }
        procs += list(agents.values())
        w = Watch()
        deadline = time.monotonic() + 300
        while time.monotonic() < deadline:
            for ev in bus.drain(0.1):
                w.take(ev.msg)
            if all(a.popen.poll() is not None for a in agents.values()):
                break
        for _ in range(10):  # the last truth after the agents stopped
            for ev in bus.drain(0.1):
                w.take(ev.msg)
        for i in ids:
            assert agents[i].popen.poll() == 1, f"agent {i} did not stop with a failure"
            st = w.final[i]
            assert st.phase == "failed", st
            assert f"robot(s) [{odd}] plan with different parameters" in st.error, (i, st.error)
            assert ("this robot among them" in st.error) == (i == odd), st.error
            assert st.plan_digest == "" and st.wave == -1  # it never planned
            assert w.moved(i) < 0.02, f"robot {i} moved {w.moved(i):.3f} m"


def test_demo_on_a_scenario_file_plans_the_cp_pyramid(tmp_path: Path) -> None:
    sc = scenarios.generate(3, 1)
    sc = replace(sc, robots=tuple(replace(r, id=i) for r, i in zip(sc.robots, (2, 5, 7))))
    path = tmp_path / "three.json"
    scenarios.dump(sc, path)
    res = subprocess.run(
        [sys.executable, "-m", "tools.demo", "--scenario", str(path), "--orientation", "cp",
         "--out", str(tmp_path / "demo"), "--json", str(tmp_path / "r.json"), "--timeout", "240"],
        cwd=ROOT, capture_output=True, text=True, timeout=300,
    )  # fmt: skip
    assert "identical plan digests" in res.stdout, res.stderr[-2000:]
    r = json.loads((tmp_path / "r.json").read_text())
    assert r["ids"] == [2, 5, 7] and r["robots"] == 3 and r["seed"] == sc.seed
    assert r["secure"] is True and r["orientation"] == "cp"
    assert r["exit_codes"] == {"2": 0, "5": 0, "7": 0}, r.get("errors")
    assert r["identical_digests"] is True
    assert r["evaluator_plan_digest"] == r["plan_digests"]["2"]
    # CP: north of the common frame; the evaluator places that frame in the world by a
    # rigid fit of the starts (tools/lib/frame_fit.py), good to a fraction of a degree
    assert r["axis_deg"] == pytest.approx(90.0, abs=2.0)
    assert len(r["pairs"]) == 2 and r["contacts"] == 0
    assert r["success"] is True and res.returncode == 0
