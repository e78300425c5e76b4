"""Safety with real processes: a member that dies stops the others before they move.

The world and three ``python -m agent`` processes over loopback; agent 3 is killed
(SIGKILL, no goodbye) during its search. Agents 1 and 2 must end ``failed`` with a
reason naming robot 3 (and the other survivor if that one stopped first), exit 1,
and never walk: ground truth shows them where they started (they only turned on the
spot while searching).
"""

from __future__ import annotations

import re
import signal
import time
from pathlib import Path

import pytest

from agent.config import AgentConfig
from agent.wire import StatusMsg
from tests.system.world import Watch, agent_on, watched_world

pytestmark = [pytest.mark.system, pytest.mark.slow]


def test_member_killed_during_search_stops_the_others_unmoved(tmp_path: Path) -> None:
    with watched_world(tmp_path, 3, 5) as (ep, bus, ids, procs):
        agents = {
            i: agent_on(ep, AgentConfig(robot_id=i, fleet_size=3, timeout=20.0), tmp_path)
            for i in ids
        }
        procs += list(agents.values())
        victim, survivors = ids[-1], ids[:-1]
        w = Watch()
        killed = False
        deadline = time.monotonic() + 240
        while time.monotonic() < deadline:
            for ev in bus.drain(0.1):
                msg = ev.msg
                w.take(msg)
                # the first search status is always published (a phase change);
                # progress statuses come only every few seconds, and a fast search
                # may end before one is due
                status = msg if isinstance(msg, StatusMsg) else None
                if status and status.sender == victim and status.phase == "search" and not killed:
                    agents[victim].popen.send_signal(signal.SIGKILL)
                    killed = True
            if killed and all(agents[i].popen.poll() is not None for i in survivors):
                break
        assert killed, "the victim never started searching"
        named: set[int] = set()
        for i in survivors:
            assert agents[i].popen.poll() == 1, f"agent {i} did not stop with a failure"
            st = w.final[i]
            assert st.phase == "failed", st
            # Why it stopped: who left (the victim, or a survivor that stopped earlier), or,
            # when the victim was gone before this survivor's exchange began (it never
            # counted it as a member), no agreement within the timeout without it.
            m = re.search(r"member\(s\) \[([\d, ]+)\] left before agreement", st.error)
            t = re.search(r"no news for [\d.]+ s \([^)]*\); (\d) of 3 members alive", st.error)
            assert m is not None or (t is not None and t.group(1) == "2"), st.error
            if m is not None:
                left = {int(x) for x in m.group(1).split(",")}
                assert left <= set(ids) - {i}, st.error
                named |= left
            else:
                named.add(victim)
            assert st.plan_digest == ""  # it never planned
            assert w.moved(i) < 0.02, f"robot {i} moved {w.moved(i):.3f} m"
        assert victim in named  # the first survivor to stop did so for the victim
