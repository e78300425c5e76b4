"""A zenoh router: the rendezvous of agents and world on separate hosts (DESIGN.md §3, §5).

On one machine every process finds the others by multicast scouting. Across hosts,
containers or network namespaces, processes run with ``--connect tcp/ROUTER:7447
--no-multicast-scouting`` and this router (a zenoh-python session in ``mode: "router"``;
no separate binary) forwards their traffic. It prints one ready line to stdout::

    router ready zid=<hex> listen=tcp/0.0.0.0:7447

and runs until SIGTERM or SIGINT, then closes the session and exits 0.

``python -m tools.router [--listen tcp/0.0.0.0:7447]... [--connect EP]...
[--no-multicast-scouting]``
"""

from __future__ import annotations

import argparse
import signal
import sys
import threading
from types import FrameType

import zenoh

from agent.bus import zenoh_config
from agent.protocol import NetworkSpec

DEFAULT_LISTEN = "tcp/0.0.0.0:7447"


def router_config(
    listen: list[str], connect: list[str] | None = None, multicast_scouting: bool = True
) -> zenoh.Config:
    """The zenoh config of a router listening on ``listen`` (and connecting to ``connect``)."""
    spec = NetworkSpec(
        mode="router",
        listen=tuple(listen),
        connect=tuple(connect or ()),
        multicast_scouting=bool(multicast_scouting),
    )
    return zenoh_config(spec)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m tools.router", description="zenoh router")
    ap.add_argument("--listen", action="append", help=f"endpoint (default {DEFAULT_LISTEN})")
    ap.add_argument("--connect", action="append", default=[], help="another router to join")
    ap.add_argument("--no-multicast-scouting", action="store_true")
    args = ap.parse_args(argv)
    listen = args.listen or [DEFAULT_LISTEN]
    try:
        cfg = router_config(listen, args.connect, not args.no_multicast_scouting)
    except ValueError as exc:
        print(f"router: {exc}", file=sys.stderr)
        return 2

    stop = threading.Event()

    def on_signal(signum: int, frame: FrameType | None) -> None:
        stop.set()

    signal.signal(signal.SIGTERM, on_signal)
    signal.signal(signal.SIGINT, on_signal)
    try:
        session = zenoh.open(cfg)
    except Exception as exc:  # zenoh raises its own ZError for bad/occupied endpoints
        print(f"router: cannot open a zenoh router on {listen}: {exc}", file=sys.stderr)
        return 1
    try:
        print(f"router ready zid={session.zid()} listen={','.join(listen)}", flush=True)
        while not stop.wait(1.0):
            pass
    finally:
        session.close()
    print("router stopped", file=sys.stderr, flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
