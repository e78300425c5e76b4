"""Wait until a zenoh key is served: start-up ordering for containers (DESIGN.md §5).

``docker compose`` starts the agents as soon as the world's container exists, but the
world needs a few seconds before it serves ``world/register``, and a zenoh query that
meets no queryable returns at once with no reply. So the agent containers run::

    python -m tools.wait_for world/register --queryable --connect tcp/router:7447 \\
        && exec python -m agent --id auto ...

With ``--queryable`` it waits until a querier on KEY has a matching queryable (zenoh's
matching status: nothing is sent to the world, no id is claimed); without, until the
first publication on KEY arrives (e.g. ``world/clock``). Exits 0 (printing ``seen KEY``),
1 after ``--timeout`` seconds with the reason on stderr, 2 on bad arguments.
"""

from __future__ import annotations

import argparse
import sys
import threading
import time

import zenoh

from agent.bus import zenoh_config
from agent.protocol import Guard, NetworkSpec


def wait_for(
    key: str,
    connect: list[str],
    timeout: float,
    multicast_scouting: bool,
    queryable: bool = False,
) -> bool:
    """True once ``key`` is served, False after ``timeout`` seconds.

    ``queryable``: a queryable matches ``key``; otherwise: a sample on ``key`` arrived.
    """
    cfg = zenoh_config(NetworkSpec(connect=tuple(connect), multicast_scouting=multicast_scouting))
    seen = threading.Event()  # all the callback records: bounded by construction
    guard = Guard(lambda line: print(f"wait_for: {line}", file=sys.stderr))
    with zenoh.open(cfg) as session:
        if queryable:
            querier = session.declare_querier(key)
            end = time.monotonic() + timeout
            try:
                while time.monotonic() < end:
                    status = querier.matching_status  # a MatchingStatus (stub says bool)
                    if bool(getattr(status, "matching", status)):
                        return True
                    time.sleep(0.1)  # polling zenoh's matching status, bounded by timeout
                return False
            finally:
                querier.undeclare()
        sub = session.declare_subscriber(key, guard.wrap(lambda s: seen.set(), f"sample on {key}"))
        try:
            return seen.wait(timeout)
        finally:
            sub.undeclare()


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(
        prog="python -m tools.wait_for", description=__doc__.split("\n")[0]
    )
    ap.add_argument("key", help="key expression to wait for, e.g. world/clock")
    ap.add_argument("--connect", action="append", default=[], help="zenoh endpoint")
    ap.add_argument("--timeout", type=float, default=120.0, help="seconds (default 120)")
    ap.add_argument("--no-multicast-scouting", action="store_true")
    ap.add_argument("--queryable", action="store_true", help="wait for a queryable on KEY")
    args = ap.parse_args(argv)
    if not args.timeout > 0:
        print("wait_for: --timeout must be > 0", file=sys.stderr)
        return 2
    try:
        ok = wait_for(
            args.key, args.connect, args.timeout, not args.no_multicast_scouting, args.queryable
        )
    except Exception as exc:  # zenoh raises its own ZError for bad keys/endpoints
        print(f"wait_for: {exc}", file=sys.stderr)
        return 2
    if not ok:
        what = "no queryable for" if args.queryable else "nothing on"
        print(f"wait_for: {what} {args.key} within {args.timeout:g} s", file=sys.stderr)
        return 1
    print(f"seen {args.key}", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
