"""A zenoh router: the rendezvous of agents and world on separate hosts (docs/design.md §3, §5).

Secure (the default, docs/design.md §8): ``--credentials DIR`` (or ``$NAO_CREDENTIALS``); the
router listens on ``tls/0.0.0.0:7447`` and ``tls/0.0.0.0:7448``, accepts only links with a certificate of the
fleet CA (mutual TLS) and enforces the fleet's access control by common name
(``agent.wire.trust.acl_settings``); identities revoked by the folder's ``crl.pem``
(``python -m tools.fleet revoke``) get no rule at all, so the router refuses everything
they send and delivers nothing to them (listed on stderr at start; restart the router
to apply a new list). Every other process then runs with ``--credentials DIR
--connect tls/ROUTER:7447`` as a zenoh client. ``--insecure`` (development only): plain
TCP on ``tcp/0.0.0.0:7447`` and ``:7448``, anyone may connect. Port 7447
(``agent.wire.BUS_PORT``) carries robot-to-robot traffic, port 7448
(``WORLD_PORT``) the world's link and the agents' body sessions (``python -m agent
--world-connect``): one router, two ports, so that fault injection can spare the
world's traffic by port (``tools.packet_drop --exempt-port 7448``). This router (a zenoh-python session in
``mode: "router"``; no separate binary) forwards the traffic. It prints one ready line::

    router ready zid=<hex> listen=tls/0.0.0.0:7447,tls/0.0.0.0:7448

and runs until SIGTERM or SIGINT, then closes the session and exits 0.

``python -m tools.router (--credentials DIR | --insecure) [--listen EP]... [--connect EP]...
[--no-multicast-scouting]``
"""

from __future__ import annotations

import argparse
import os
import signal
import sys
import threading
from types import FrameType

import zenoh

from agent.net.bus import zenoh_config
from agent.wire import (
    BUS_PORT,
    CREDENTIALS_ENV,
    WORLD_PORT,
    add_network_arguments,
    network_spec,
)
from agent.wire.trust import Credentials

DEFAULT_LISTEN = [f"tcp/0.0.0.0:{BUS_PORT}", f"tcp/0.0.0.0:{WORLD_PORT}"]
DEFAULT_LISTEN_TLS = [f"tls/0.0.0.0:{BUS_PORT}", f"tls/0.0.0.0:{WORLD_PORT}"]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m tools.router", description="zenoh router")
    add_network_arguments(ap, ("router",))
    args = ap.parse_args(argv)
    if not args.listen:
        secure = not args.insecure and (args.credentials or os.environ.get(CREDENTIALS_ENV))
        args.listen = list(DEFAULT_LISTEN_TLS if secure else DEFAULT_LISTEN)
    listen = args.listen
    try:
        spec = network_spec(args, "router", default_mode="router")
        cfg = zenoh_config(spec)
        revoked = sorted(Credentials(spec.credentials).revoked) if spec.tls and spec.secure else []
    except ValueError as exc:  # TrustError is one: a bad certificate or revocation list
        print(f"router: {exc}", file=sys.stderr)
        return 2
    if revoked:
        names = ", ".join(w.cn for w in revoked)
        print(f"router: revoked, denied everything: {names}", file=sys.stderr, flush=True)

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
