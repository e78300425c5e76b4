"""Safety with real processes: a member that dies stops the others before they move.

The world and three ``python -m agent`` processes over loopback; agent 3 is killed
(SIGKILL, no goodbye) during its search. Agents 1 and 2 must end ``failed`` with a
reason naming robot 3 (and the other survivor if that one stopped first), exit 1,
and never walk: ground truth shows them where they started (they only turned on the
spot while searching).
"""

from __future__ import annotations

import argparse
import math
import re
import signal
import time
from pathlib import Path

import pytest

from agent.bus import Bus, BusConfig
from agent.protocol import KEY_STATUS_ALL, KEY_WORLD_TRUTH_ALL, StatusMsg, TruthPosesMsg
from tools.demo import free_port, robot_ids, start_agent, start_world, stop

pytestmark = [pytest.mark.system, pytest.mark.slow]


def test_member_killed_during_search_stops_the_others_unmoved(tmp_path: Path) -> None:
    ep = f"tcp/127.0.0.1:{free_port()}"
    args = argparse.Namespace(d_e=0.8, phi_e_deg=30.0, agree_timeout=20.0, agent_log_level="INFO")
    bus = Bus(BusConfig(connect=(ep,), multicast_scouting=False))
    bus.subscribe(KEY_STATUS_ALL)
    bus.subscribe(KEY_WORLD_TRUTH_ALL)
    world = start_world(3, 5, ep, tmp_path, [])
    procs = [world]
    try:
        deadline = time.monotonic() + 120
        while not any("ready" in ln for ln in world.lines):
            assert world.popen.poll() is None and time.monotonic() < deadline, "world not ready"
            bus.drain(0.1)
        ids = robot_ids(world.lines, 3)
        agents = {i: start_agent(i, 3, ep, tmp_path, args) for i in ids}
        procs += list(agents.values())
        victim, survivors = ids[-1], ids[:-1]
        first: dict[int, tuple[float, float]] = {}
        last: dict[int, tuple[float, float]] = {}
        final: dict[int, StatusMsg] = {}
        killed = False
        deadline = time.monotonic() + 240
        while time.monotonic() < deadline:
            for ev in bus.drain(0.1):
                msg = ev.msg
                if isinstance(msg, TruthPosesMsg):
                    for rid, x, y, _ in msg.poses:
                        first.setdefault(rid, (x, y))
                        last[rid] = (x, y)
                elif isinstance(msg, StatusMsg):
                    final[msg.sender] = msg
                    # the first search status is always published (a phase change);
                    # progress statuses come only every few seconds, and a fast search
                    # may end before one is due
                    if msg.sender == victim and msg.phase == "search" and not killed:
                        agents[victim].popen.send_signal(signal.SIGKILL)
                        killed = True
            if killed and all(agents[i].popen.poll() is not None for i in survivors):
                break
        assert killed, "the victim never started searching"
        named: set[int] = set()
        for i in survivors:
            assert agents[i].popen.poll() == 1, f"agent {i} did not stop with a failure"
            st = final[i]
            assert st.phase == "failed", st
            # Why it stopped: who left (the victim, or a survivor that stopped earlier), or,
            # when the victim was gone before this survivor's exchange began (it never
            # counted it as a member), no agreement within the timeout without it.
            m = re.search(r"member\(s\) \[([\d, ]+)\] left before agreement", st.error)
            t = re.search(r"no agreement after [\d.]+ s; (\d) of 3 members alive", st.error)
            assert m is not None or (t is not None and t.group(1) == "2"), st.error
            if m is not None:
                left = {int(x) for x in m.group(1).split(",")}
                assert left <= set(ids) - {i}, st.error
                named |= left
            else:
                named.add(victim)
            assert st.plan_digest == ""  # it never planned
            dx = last[i][0] - first[i][0]
            dy = last[i][1] - first[i][1]
            assert math.hypot(dx, dy) < 0.02, f"robot {i} moved {math.hypot(dx, dy):.3f} m"
        assert victim in named  # the first survivor to stop did so for the victim
    finally:
        for p in reversed(procs):
            stop(p)
        bus.close()
