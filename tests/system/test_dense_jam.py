"""Dense jam (no robot jams for good), as real processes: the world and four agents over loopback; a
fifth NAO, which runs no agent, stands on a slot of the fleet's plan
(tools/jam_scenario.py). The robot of that slot cannot reach it; the fleet must stop
honestly (agent/core/formation/waves/jam.py): every agent ends ``failed``, the robot of the
slot naming why it cannot reach it and every other agent the same root, nobody reports
the formation held, and ground truth agrees (the slot is still taken by the bystander,
no contact). A fleet that refuses every candidate frame before anyone walks (the
bystander's sightings pair with no member's) is the other honest stop, checked as such.
"""

from __future__ import annotations

import math
import time
from pathlib import Path

import pytest

from agent.config import AgentConfig
from agent.core.formation.waves.jam import FLEET_STOP
from agent.net.bus import Bus, BusConfig
from agent.wire import KEY_STATUS_ALL, KEY_WORLD_TRUTH_ALL, ContactMsg, StatusMsg
from sim.physics.nao_model import FOOTPRINT_RADIUS
from sim.scenarios import dump
from tests.system.world import Watch, agent_on
from tools.harness.procs import (
    Proc,
    free_port,
    robot_ids,
    start_world,
    stop,
    wait_ready,
)
from tools.jam_scenario import jam_scenario

pytestmark = [pytest.mark.system, pytest.mark.slow]

#: The refusal every agent reports when no candidate frame passes the fault test.
REFUSED = "planning failed on the agreed records: no frame passes the fault test"

FLEET = 4
LIMIT = 900.0  # s for the whole run on a loaded 2-core machine


def test_a_slot_taken_by_a_bystander_stops_the_fleet_honestly(tmp_path: Path) -> None:
    sc, victim = jam_scenario(FLEET, 1)
    path = tmp_path / "dense_jam.json"
    dump(sc, path)
    bystander = FLEET + 1
    spot = next((r.x, r.y) for r in sc.robots if r.id == bystander)
    ep = f"tcp/127.0.0.1:{free_port()}"
    bus = Bus(BusConfig(connect=(ep,), multicast_scouting=False))
    bus.subscribe(KEY_STATUS_ALL)
    bus.subscribe(KEY_WORLD_TRUTH_ALL)
    world = start_world(FLEET + 1, 1, ep, tmp_path, ["--scenario", str(path)])
    procs: list[Proc] = [world]
    w = Watch()
    contacts: list[ContactMsg] = []
    blocked = False
    try:
        wait_ready(world, 120, lambda: bus.drain(0.1))
        assert robot_ids(world.lines, FLEET + 1) == list(range(1, FLEET + 2))
        agents = {
            i: agent_on(ep, AgentConfig(robot_id=i, fleet_size=FLEET), tmp_path)
            for i in range(1, FLEET + 1)
        }
        procs += list(agents.values())
        deadline = time.monotonic() + LIMIT
        while time.monotonic() < deadline:
            for ev in bus.drain(0.2):
                w.take(ev.msg)
                if isinstance(ev.msg, ContactMsg):
                    contacts.append(ev.msg)
                if isinstance(ev.msg, StatusMsg) and "waiting: NAO ahead" in ev.msg.detail:
                    blocked = blocked or ev.msg.sender == victim
            if all(a.popen.poll() is not None for a in agents.values()):
                break
        for _ in range(10):  # the last statuses and truth still on their way
            for ev in bus.drain(0.2):
                w.take(ev.msg)
        codes = {i: a.popen.poll() for i, a in agents.items()}
    finally:
        for p in reversed(procs):
            stop(p)
        bus.close()
    logs = {i: (tmp_path / f"agent-{i}.log").read_text()[-1500:] for i in range(1, FLEET + 1)}
    assert codes == dict.fromkeys(range(1, FLEET + 1), 1), (codes, logs)
    final = {i: w.final[i] for i in range(1, FLEET + 1)}
    # nobody reports the formation held around the hole
    assert {s.phase for s in final.values()} == {"failed"}, final
    starts = {r.id: (r.x, r.y) for r in sc.robots}
    if all(REFUSED in s.error for s in final.values()):
        # the other honest stop, before anyone moves: no candidate frame passes the fault
        # test (the bystander's sightings, which no member's record pairs, are a NAO
        # without a record where two members' agree, frame/faults/outsiders.py; seen by
        # one alone, a lost stray); every agent says so, and nobody walked
        for i in range(1, FLEET + 1):
            assert math.dist(w.last[i], starts[i]) < 0.02, (i, w.last[i], starts[i])
        assert contacts == []
        return
    # one root: the robot whose slot the bystander takes (by the agents' own plan; the
    # ground-truth plan names ``victim``)
    roots = [i for i, s in final.items() if FLEET_STOP not in s.error]
    assert roots == [victim], {i: s.error for i, s in final.items()}
    assert blocked, "the robot of the taken slot was never seen waiting"
    root = final[victim].error
    assert f"robot {victim} cannot reach its slot: a NAO not in the plan" in root, root
    # the same reason on every other agent: the root, named alike
    assert {s.error for i, s in final.items() if i != victim} == {
        f"AgentFailure: {FLEET_STOP}robot {victim} failed: {root}"
    }, final
    # ground truth agrees: the bystander still stands on the slot, nobody touched anybody
    assert math.dist(w.last[bystander], spot) < 0.02
    assert math.dist(w.last[victim], spot) > 2 * FOOTPRINT_RADIUS
    assert contacts == []
