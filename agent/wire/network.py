"""How a process joins the bus (docs/design.md §3, §8): the join flags every process shares and
the zenoh settings they produce (pure data: JSON5 text for ``zenoh.Config``).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from dataclasses import dataclass

from agent.wire.access import acl_settings, tls_settings
from agent.wire.credentials import Credentials
from agent.wire.identity import Identity

# --------------------------------------------------------------------------- joining


ZENOH_MODES = ("peer", "client", "router")


#: zenoh settings for lossy radio links, for every process. zenoh's defaults
#: (10 s lease, 10 s to open a TLS session, a client that gives up after its first
#: failed connection) break at 30 % loss per direction, where TCP retransmission stalls
#: for seconds. Measured with ``tools.eval_loss`` (README "Fault injection and
#: containers"): a 30 s lease, 30 s to open or accept a session, and a client that keeps
#: trying to connect for 60 s (retries from 0.5 s, backing off to 4 s). A session that
#: still breaks reconnects; the agents' membership grace (``agent.core.grace.Grace``)
#: bridges its vanished tokens. Keep-alives: four per lease (zenoh's own ratio: a link
#: counts as failed after four silent intervals, ITU-T G.8013/Y.1731 asks for 3.5), one
#: every 7.5 s, and zenoh sends one only when nothing else was sent on the link for that
#: long: a waiting fleet's statuses keep its links alive at 10 s apart, so each link
#: carries one keep-alive between two statuses (six a lease cost an idle agent 0.03 % of
#: a core more in the full mesh of ``python -m tools.bench idle``, 10 peers).
LOSSY_LINK_SETTINGS: tuple[tuple[str, str], ...] = (
    ("transport/link/tx/lease", "30000"),
    ("transport/link/tx/keep_alive", "4"),
    ("transport/unicast/open_timeout", "30000"),
    ("transport/unicast/accept_timeout", "30000"),
    ("connect/timeout_ms", "{router: -1, peer: -1, client: 60000}"),
    ("connect/retry", "{period_init_ms: 500, period_max_ms: 4000, period_increase_factor: 2}"),
)

#: zenoh settings for a process that mostly waits. zenoh's shared-memory transport (on by
#: default) keeps a task waking about every 100 ms: 0.15 % of a core per process with
#: nothing to send (measured: five bare zenoh clients, 0.15 % with it and 0.00–0.05 %
#: without; ``python -m tools.bench idle``). The fleet's messages are a few hundred bytes,
#: below its 3 kB threshold, robots on separate hosts share no memory, and the camera's
#: pictures cross the router's TLS link: nothing here uses it.
QUIET_SETTINGS: tuple[tuple[str, str], ...] = (("transport/shared_memory/enabled", "false"),)


@dataclass(frozen=True)
class NetworkSpec:
    """How a process joins the bus (docs/design.md §3): zenoh mode, endpoints, scouting.

    Pure data shared by every process (agents, world, router, tools), so that all of them
    accept and check the same flags; :meth:`json5_items` gives the zenoh config entries,
    which ``agent/net/bus.py`` and the world turn into a ``zenoh.Config``. The defaults suit
    peers on one machine (multicast scouting); separate hosts use ``connect`` to a router.
    """

    connect: tuple[str, ...] = ()
    listen: tuple[str, ...] = ()
    multicast_scouting: bool = True
    mode: str = "peer"
    #: The fleet credentials folder (``agent.wire.trust``); empty: insecure (development only).
    credentials: str = ""
    #: Whose key opens the links: a common name of ``agent.wire.trust.Identity`` (``robot-2``).
    identity: str = ""
    #: With credentials: TLS links and access control (False: signatures over plain
    #: links, for tests of the end-to-end layer as if a router were compromised).
    tls: bool = True

    def __post_init__(self) -> None:
        if self.mode not in ZENOH_MODES:
            raise ValueError(f"mode must be peer, client or router, got {self.mode!r}")
        if self.credentials and not self.identity:
            raise ValueError("credentials need the identity whose key opens the links")
        if self.credentials and self.tls:
            if self.mode == "peer":
                raise ValueError(
                    "with credentials every process is a zenoh client of a TLS router "
                    "(python -m tools.router --credentials DIR); use --mode client"
                )
            if self.mode == "client" and not self.connect:
                raise ValueError("with credentials, --connect tls/ROUTER:7447 is required")
            for ep in (*self.connect, *self.listen):
                if not ep.startswith("tls/"):
                    raise ValueError(f"with credentials every link is TLS: {ep!r} is not tls/...")
        for ep in (*self.connect, *self.listen):
            if not isinstance(ep, str) or "/" not in ep:
                raise ValueError(
                    f"endpoint {ep!r} is not of the form proto/address, e.g. tcp/127.0.0.1:7447"
                )
        if self.mode == "client" and not self.connect and not self.multicast_scouting:
            raise ValueError(
                "client mode without --connect needs multicast scouting to find a router"
            )
        if self.mode == "router" and not self.listen:
            raise ValueError("a router needs at least one --listen endpoint")

    def json5_items(self) -> list[tuple[str, str]]:
        """(key, JSON5 value) pairs for ``zenoh.Config.insert_json5``."""
        items = [("mode", json.dumps(self.mode)), *LOSSY_LINK_SETTINGS, *QUIET_SETTINGS]
        if self.connect:
            items.append(("connect/endpoints", json.dumps(list(self.connect))))
        if self.listen:
            items.append(("listen/endpoints", json.dumps(list(self.listen))))
        items.append(("scouting/multicast/enabled", json.dumps(self.multicast_scouting)))
        if self.credentials and self.tls:
            creds = Credentials(self.credentials)
            who = Identity.parse(self.identity)
            items.append(("transport/link/tls", json.dumps(tls_settings(creds, who))))
            if self.mode == "router":
                items.append(("access_control", json.dumps(acl_settings(creds.roster))))
        return items

    @property
    def secure(self) -> bool:
        return bool(self.credentials)


#: The router's port for robot-to-robot traffic (records, digests, statuses, tokens).
BUS_PORT = 7447
#: The router's second port (spared by fault injection): world links and the agents' body sessions
#: (``python -m agent --world-connect``). On a real NAO camera and legs are on board, so
#: fault injection (``tools.packet_drop --exempt-port``) spares this port and drops only
#: robot-to-robot traffic.
WORLD_PORT = 7448

#: Environment variable naming the credentials folder (containers: a mounted secret).
CREDENTIALS_ENV = "NAO_CREDENTIALS"
INSECURE_WARNING = (
    "WARNING: --insecure: no TLS, no access control, no signatures. Anyone on the network "
    "can forge records, walk any robot and read everything. Development only."
)


def add_network_arguments(p: argparse.ArgumentParser, modes: tuple[str, ...]) -> None:
    """The join flags every process shares: endpoints, scouting, mode, credentials."""
    p.add_argument(
        "--connect", action="append", default=[], metavar="EP", help="zenoh endpoint to connect to"
    )
    p.add_argument(
        "--listen", action="append", default=[], metavar="EP", help="zenoh endpoint to listen on"
    )
    p.add_argument(
        "--no-multicast-scouting", action="store_true", help="disable multicast scouting"
    )
    p.add_argument(
        "--mode",
        choices=modes,
        default=None,
        help="zenoh mode (default: client with credentials, else peer)",
    )
    p.add_argument(
        "--credentials",
        metavar="DIR",
        default=None,
        help="fleet credentials folder (python -m tools.fleet init; default: $NAO_CREDENTIALS)",
    )
    p.add_argument(
        "--insecure",
        action="store_true",
        help="no TLS, access control or signatures (development only; prints a warning)",
    )
    p.add_argument(
        "--plain-links",
        action="store_true",
        help="tests only: signed messages over plain TCP, no TLS or access control",
    )


def network_spec(
    args: argparse.Namespace, identity: str, default_mode: str = "peer"
) -> NetworkSpec:
    """The :class:`NetworkSpec` of flags added by :func:`add_network_arguments`.

    Secure by default: without credentials (flag or ``$NAO_CREDENTIALS``) it raises
    ``ValueError`` unless ``--insecure`` was given, which prints a warning to stderr.
    Secure sessions are zenoh clients of a TLS router unless ``--mode`` says otherwise.
    """
    creds = "" if args.insecure else (args.credentials or os.environ.get(CREDENTIALS_ENV, ""))
    if args.insecure:
        print(INSECURE_WARNING, file=sys.stderr, flush=True)
    elif not creds:
        raise ValueError(
            "no fleet credentials: pass --credentials DIR (create them with "
            "python -m tools.fleet init) or set NAO_CREDENTIALS; --insecure for development"
        )
    tls = not args.plain_links
    mode = args.mode or ("client" if creds and tls and default_mode == "peer" else default_mode)
    return NetworkSpec(
        connect=tuple(args.connect),
        listen=tuple(args.listen),
        multicast_scouting=not args.no_multicast_scouting,
        mode=mode,
        credentials=creds,
        identity=identity if creds else "",
        tls=tls,
    )
