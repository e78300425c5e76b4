"""``python -m agent.idle``: an agent that only waits, for ``python -m tools.bench idle``.

    python -m agent.idle --id N --fleet-size F [the join and fleet flags of python -m agent]

The real phase machine (:class:`agent.phases.runner.Runner`, docs/design.md §1) on a
real zenoh session, entered at the agreement (``Runner.phases(Phase.AGREE, ...)``) with
an empty record of its own, as a robot whose search is over. Its flags are those of
``python -m agent`` and are read by the same parser (:func:`agent.__main__.parse_args`),
and its session is opened by the same code (:func:`agent.__main__.open_bus`): secure by
default, a zenoh client of the fleet's TLS router (``--credentials DIR --connect
tls/ROUTER:7447``) signing every message and checking every signature, as the agents a
user runs do; ``--insecure`` for peers on plain TCP (docs/design.md §8). Its settings
come from :func:`agent.__main__.agent_config`, so ``--timeout`` (the agreement's) is the
caller's to set beyond the run.

It has no world: its body answers its id and sim time and never moves, its perception
is never called. Given a fleet size larger than the agents started (``--fleet-size`` is
required), its agreement can never complete, and it waits there until it is stopped:
what it costs its host is the cost of waiting alone (bus traffic, signatures,
wake-ups, zenoh's threads). The tools start it as a process, never import it
(tests/test_layers.py).
"""

from __future__ import annotations

import logging
import sys
from typing import cast

from agent.__main__ import agent_config, open_bus, parse_args
from agent.adapters import FormationAdapter
from agent.body.base import Body
from agent.net.bus import BusError
from agent.phases.reporting import Phase
from agent.phases.runner import Runner
from agent.seams import Perception
from agent.wire import NeighborRecordMsg


class Still:
    """A body that stands still: the waits never move it."""

    def __init__(self, robot_id: int) -> None:
        self.robot_id = robot_id
        self.t_sim = 0.0

    def stop(self) -> None:
        """Nothing moves."""


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    logging.basicConfig(
        level=args.log_level,
        format="%(asctime)s agent.idle[%(process)d] %(levelname)s %(name)s: %(message)s",
        stream=sys.stderr,
    )
    log = logging.getLogger("agent.idle")
    if args.fleet_size is None or args.id == "auto":
        print("python -m agent.idle: needs --id N and --fleet-size F", file=sys.stderr)
        return 2
    try:
        bus, world, rid = open_bus(args, log)
    except ValueError as exc:  # usage: bad flags, no credentials (TrustError is one too)
        print(f"python -m agent.idle: {exc}", file=sys.stderr)
        return 2
    except BusError as exc:  # no session
        log.error("%s", exc)
        return 1
    try:
        body, blind = cast(Body, Still(rid)), cast(Perception, None)
        runner = Runner(bus, body, agent_config(args, rid), blind, FormationAdapter())
        runner.membership.start()
        runner.ctx.report.status(Phase.START, 0.0, "joined", force=True)
        runner.phases(Phase.AGREE, NeighborRecordMsg(sender=rid, round=0, neighbours=()))
    except KeyboardInterrupt:
        pass
    finally:
        if world is not bus:
            world.close()
        bus.close()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
