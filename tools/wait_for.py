"""Wait until a zenoh key is served: start-up ordering for containers (docs/design.md §5).

``docker compose`` starts the agents as soon as the world's container exists, but the
world needs a few seconds before it serves ``world/register``, and a zenoh query that
meets no queryable returns at once with no reply. So the agent containers run::

    python -m tools.wait_for world/clock --credentials /run/secrets/fleet \\
        --connect tls/router:7447 --no-multicast-scouting \\
        && exec python -m agent --id auto ...

Without ``--queryable`` it waits until the first publication on KEY arrives (the world
publishes ``world/clock`` once it serves); with ``--queryable``, until a querier on KEY
has a matching queryable (zenoh's matching status: nothing is sent, no id is claimed).

It joins like every process (``agent.wire.add_network_arguments``): secure by default
with ``--credentials DIR`` (or ``$NAO_CREDENTIALS``) as a zenoh client of the TLS router,
``--insecure`` for development. ``--identity CN`` picks whose key opens the link; by
default the first key the folder holds of ``observer``, the robots (lowest id first),
``world``. The router's access control decides what that identity may see: any fleet
member may subscribe to ``world/clock``; only robots and the world see the queryable
``world/register``, observers only subscribe. Exits 0 (printing ``seen KEY``), 1 after
``--timeout`` seconds with the reason on stderr (an unreachable router counts as not yet
served: it is retried until then), 2 on bad arguments or credentials.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import threading
import time
from pathlib import Path

import zenoh

from agent.net.bus import zenoh_config
from agent.wire import Guard, NetworkSpec, add_network_arguments, network_spec


def default_identity(credentials: str) -> str:
    """The identity whose key a credentials folder holds: observer, robots, then world."""
    from agent.wire.trust import Credentials, Identity

    creds = Credentials(credentials)
    who = [Identity("observer"), *(Identity.robot(r) for r in creds.own_robot_keys())]
    for ident in (*who, Identity("world")):
        if creds.paths.key(ident).is_file():
            return ident.cn
    raise ValueError(f"{credentials} holds no observer, robot or world key")


def _check_key(credentials: str, cn: str) -> None:
    from agent.wire.trust import FleetPaths, Identity

    if not FleetPaths(Path(credentials)).key(Identity.parse(cn)).is_file():
        raise ValueError(f"{credentials} holds no private key for {cn}")


def _open(cfg: zenoh.Config, end: float) -> zenoh.Session | None:
    """A session, retrying until ``end`` (monotonic) while the router cannot be reached.

    A client's ``zenoh.open`` fails when no router answers: not started yet, or a lossy
    link that loses the TLS handshake. Either may pass, so it is retried; the last
    error is printed when time is up (None).
    """
    last = ""
    while True:
        # zenoh's own connect retries (agent.wire.LOSSY_LINK_SETTINGS) within our limit
        left_ms = max(1000, int(1000 * (end - time.monotonic())))
        cfg.insert_json5("connect/timeout_ms", f"{{router: -1, peer: -1, client: {left_ms}}}")
        try:
            return zenoh.open(cfg)
        except zenoh.ZError as exc:
            last = str(exc)
        if time.monotonic() + 1.0 >= end:
            print(f"wait_for: no session: {last}", file=sys.stderr, flush=True)
            return None
        time.sleep(1.0)  # a retry per second, bounded by the caller's timeout


def wait_for(key: str, spec: NetworkSpec, timeout: float, queryable: bool = False) -> bool:
    """True once ``key`` is served, False after ``timeout`` seconds (including the time
    it takes to reach the router: an unreachable router is retried, not an error).

    ``queryable``: a queryable matches ``key``; otherwise: a sample on ``key`` arrived.
    """
    cfg = zenoh_config(spec)
    end = time.monotonic() + timeout
    session = _open(cfg, end)
    if session is None:
        return False
    seen = threading.Event()  # all the callback records: bounded by construction
    guard = Guard(lambda line: print(f"wait_for: {line}", file=sys.stderr))
    with session:
        if queryable:
            querier = session.declare_querier(key)
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
            return seen.wait(max(0.0, end - time.monotonic()))
        finally:
            sub.undeclare()


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(
        prog="python -m tools.wait_for", description=__doc__.split("\n")[0]
    )
    ap.add_argument("key", help="key expression to wait for, e.g. world/clock")
    ap.add_argument("--timeout", type=float, default=120.0, help="seconds (default 120)")
    ap.add_argument("--queryable", action="store_true", help="wait for a queryable on KEY")
    ap.add_argument(
        "--identity",
        metavar="CN",
        default="",
        help="whose key opens the link (default: observer, else a robot, else world)",
    )
    add_network_arguments(ap, ("peer", "client"))
    args = ap.parse_args(argv)
    if not args.timeout > 0:
        print("wait_for: --timeout must be > 0", file=sys.stderr)
        return 2
    try:
        spec = network_spec(args, "observer")
        if spec.credentials:
            who = args.identity or default_identity(spec.credentials)
            _check_key(spec.credentials, who)
            spec = dataclasses.replace(spec, identity=who)
        ok = wait_for(args.key, spec, args.timeout, args.queryable)
    except Exception as exc:  # bad flags or credentials (ValueError); zenoh's ZError
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
