"""``python -m agent.idle``: an agent that only waits, for ``python -m tools.bench idle``.

    python -m agent.idle --id N --fleet-size F --connect EP

The real phase machine (:class:`agent.phases.runner.Runner`, docs/design.md §1) on a
real zenoh session (insecure, ``--connect EP``, no multicast), entered at the agreement
(``Runner.phases(Phase.AGREE, ...)``) with an empty record of its own, as a robot whose
search is over. It has no world: its body answers its id and sim time and never moves,
its perception is never called. Given a fleet size larger than the agents started, its
agreement can never complete, and it waits there (the agreement timeout is set beyond
any run) until it is stopped: what it costs its host is the cost of waiting alone (bus
traffic, wake-ups, zenoh's threads). The tools start it as a process, never import it
(tests/test_layers.py).
"""

from __future__ import annotations

import argparse
from typing import cast

from agent.adapters import FormationAdapter
from agent.body.base import Body
from agent.config import AgentConfig
from agent.net.bus import Bus, BusConfig
from agent.phases.reporting import Phase
from agent.phases.runner import Runner
from agent.seams import Perception
from agent.wire import NeighborRecordMsg

#: Agreement timeout of a waiting agent (s): beyond any benchmark.
NEVER = 1e6


class Still:
    """A body that stands still: the waits never move it."""

    def __init__(self, robot_id: int) -> None:
        self.robot_id = robot_id
        self.t_sim = 0.0

    def stop(self) -> None:
        """Nothing moves."""


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m agent.idle", description=__doc__)
    p.add_argument("--id", type=int, required=True, help="robot id")
    p.add_argument("--fleet-size", type=int, required=True, help="more than the agents started")
    p.add_argument("--connect", required=True, metavar="EP", help="zenoh endpoint, tcp/...")
    a = p.parse_args(argv)
    bus = Bus(BusConfig(connect=(a.connect,), multicast_scouting=False))
    try:
        cfg = AgentConfig(robot_id=a.id, fleet_size=a.fleet_size, timeout=NEVER)
        body, blind = cast(Body, Still(a.id)), cast(Perception, None)
        runner = Runner(bus, body, cfg, blind, FormationAdapter())
        runner.membership.start()
        runner.ctx.report.status(Phase.START, 0.0, "joined", force=True)
        runner.phases(Phase.AGREE, NeighborRecordMsg(sender=a.id, round=0, neighbours=()))
    except KeyboardInterrupt:
        pass
    finally:
        bus.close()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
