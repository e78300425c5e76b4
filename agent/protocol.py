"""The wire contract between agents and the world (DESIGN.md §3).

Key expressions, message dataclasses and the msgpack codec. This is the one module of
``agent/`` that ``sim/`` may import. Every message on the wire is a msgpack map
``{"v": SCHEMA_VERSION, "t": <type tag>, ...fields}``; :func:`decode` validates the
version, the type tag, every field's type, range and size, and rejects anything that
does not fit with a :class:`ProtocolError` (a ``ValueError``) whose text is the reason.
It never returns a half-valid message.

Units: metres, radians, seconds of *sim* time. Robot ids are ints in [0, MAX_ROBOT_ID].
Images are encoded (PNG) bytes of a BGR uint8 picture, as OpenCV writes them.
"""

from __future__ import annotations

import argparse
import collections
import contextlib
import json
import math
import os
import queue
import re
import sys
import threading
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field, fields
from typing import Any, ClassVar, Generic, Protocol, TypeVar

import msgpack

from agent import nao as nao  # NAO facts, shared with sim/ through this module

SCHEMA_VERSION = 1
MAX_ROBOT_ID = 65535
MAX_NEIGHBOURS = 64
MAX_OBSTACLES = 32  # obstacles one robot may report in its record
MAX_MEMBERS = 1024
MAX_TEXT = 512
MAX_IMAGE_BYTES = 8 * 1024 * 1024
MAX_MESSAGE_BYTES = MAX_IMAGE_BYTES + 4096
#: Publications (records, digests, statuses, clock, truth for 1024 robots: ~40 KB) are
#: small; only camera replies carry an image. Subscribers reject bigger payloads unread.
MAX_PUBLICATION_BYTES = 64 * 1024
#: World requests (register, camera, walk, turn) are a few dozen bytes.
MAX_REQUEST_BYTES = 1024
#: msgpack limits of :func:`unpack_bounded` (see its docstring for why these values).
MAX_OBJECTS = 8192
MAX_DEPTH = 8
MAX_MAP_LEN = 32
MAX_ARRAY_LEN = MAX_MEMBERS
MAX_STR_BYTES = 4 * MAX_TEXT  # MAX_TEXT characters of UTF-8
MAX_COORD = 1000.0  # metres: no NAO fleet spans a kilometre
MAX_STEP = 50.0  # metres: the longest single walk command accepted
HEAD_YAW_LIMIT = nao.HEAD_YAW_LIMIT
DIGEST_HEX_LEN = 64

PHASES = (
    "start",
    "search",
    "localise",
    "exchange",
    "agree",
    "explore",
    "plan",
    "wait",
    "move",
    "hold",
    "march",
    "done",
    "failed",
)

# --------------------------------------------------------------------------- keys

KEY_ALIVE_PREFIX = "nao/alive"
KEY_ALIVE_ALL = "nao/alive/*"
KEY_RECORD_ALL = "nao/*/record"
KEY_DIGEST_ALL = "nao/*/digest"
KEY_STATUS_ALL = "nao/*/status"
#: Every agent's record-set queryable (issue #9): the agreed records by digest.
KEY_RECORDS_ALL = "nao/*/records"
KEY_WORLD_REGISTER = "world/register"
KEY_WORLD_CLOCK = "world/clock"
KEY_WORLD_TRUTH_POSES = "world/truth/poses"
KEY_WORLD_TRUTH_CONTACTS = "world/truth/contacts"
KEY_WORLD_TRUTH_ALL = "world/truth/**"


def key_alive(robot_id: int) -> str:
    return f"{KEY_ALIVE_PREFIX}/{_check_id(robot_id)}"


def key_record(robot_id: int) -> str:
    return f"nao/{_check_id(robot_id)}/record"


def key_digest(robot_id: int) -> str:
    return f"nao/{_check_id(robot_id)}/digest"


def key_status(robot_id: int) -> str:
    return f"nao/{_check_id(robot_id)}/status"


def key_records(robot_id: int) -> str:
    return f"nao/{_check_id(robot_id)}/records"


def key_camera(robot_id: int) -> str:
    return f"world/robot/{_check_id(robot_id)}/camera"


def key_walk(robot_id: int) -> str:
    return f"world/robot/{_check_id(robot_id)}/walk"


def key_turn(robot_id: int) -> str:
    return f"world/robot/{_check_id(robot_id)}/turn"


def id_from_key(key: str) -> int:
    """The robot id in ``nao/{id}/...``, ``nao/alive/{id}`` or ``world/robot/{id}/...``."""
    if not isinstance(key, str) or len(key) > 256:
        raise ProtocolError(f"key {_short(key)} is not a key expression of at most 256 characters")
    parts = key.split("/")
    if len(parts) >= 3 and parts[0] == "nao" and parts[1] == "alive":
        raw = parts[2]
    elif len(parts) >= 2 and parts[0] == "nao":
        raw = parts[1]
    elif len(parts) >= 3 and parts[0] == "world" and parts[1] == "robot":
        raw = parts[2]
    else:
        raise ProtocolError(f"key {_short(key)} names no robot")
    if not _ID_TEXT.fullmatch(raw):
        raise ProtocolError(
            f"key {_short(key)}: robot id {_short(raw)} is not a non-negative integer "
            "in ASCII digits without leading zeros"
        )
    return _check_id(int(raw))


#: A robot id in a key: ASCII digits, no sign, no leading zero (one spelling per robot).
_ID_TEXT = re.compile(r"0|[1-9][0-9]{0,4}", re.ASCII)


def _short(v: Any, limit: int = 40) -> str:
    """``repr(v)`` cut to ``limit`` characters, for error texts about untrusted values."""
    if isinstance(v, str | bytes) and len(v) > limit:
        v = v[:limit]  # never repr a megabyte to cut it afterwards
    elif isinstance(v, list | tuple | dict) and len(v) > 8:
        return f"<{type(v).__name__} of {len(v)} items>"
    text = repr(v)
    return text if len(text) <= limit else text[: limit - 3] + "..."


# --------------------------------------------------------------------------- joining


ZENOH_MODES = ("peer", "client", "router")


#: zenoh settings for lossy radio links (issue #9), for every process. zenoh's defaults
#: (10 s lease, 10 s to open a TLS session, a client that gives up after its first
#: failed connection) break at 30 % loss per direction, where TCP retransmission stalls
#: for seconds. Measured with ``tools.eval_loss`` (README "Fault injection and
#: containers"): a 30 s lease with a keep-alive every 5 s (lease / 6), 30 s to open or
#: accept a session, and a client that keeps trying to connect for 60 s (retries from
#: 0.5 s, backing off to 4 s). A session that still breaks reconnects; the agents'
#: membership grace (``agent.exchange.Grace``) bridges its vanished tokens.
LOSSY_LINK_SETTINGS: tuple[tuple[str, str], ...] = (
    ("transport/link/tx/lease", "30000"),
    ("transport/link/tx/keep_alive", "6"),
    ("transport/unicast/open_timeout", "30000"),
    ("transport/unicast/accept_timeout", "30000"),
    ("connect/timeout_ms", "{router: -1, peer: -1, client: 60000}"),
    ("connect/retry", "{period_init_ms: 500, period_max_ms: 4000, period_increase_factor: 2}"),
)


@dataclass(frozen=True)
class NetworkSpec:
    """How a process joins the bus (DESIGN.md §3): zenoh mode, endpoints, scouting.

    Pure data shared by every process (agents, world, router, tools), so that all of them
    accept and check the same flags; :meth:`json5_items` gives the zenoh config entries,
    which ``agent/bus.py`` and the world turn into a ``zenoh.Config``. The defaults suit
    peers on one machine (multicast scouting); separate hosts use ``connect`` to a router.
    """

    connect: tuple[str, ...] = ()
    listen: tuple[str, ...] = ()
    multicast_scouting: bool = True
    mode: str = "peer"
    #: The fleet credentials folder (``agent.trust``); empty: insecure (development only).
    credentials: str = ""
    #: Whose key opens the links: a common name of ``agent.trust.Identity`` (``robot-2``).
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
        items = [("mode", json.dumps(self.mode)), *LOSSY_LINK_SETTINGS]
        if self.connect:
            items.append(("connect/endpoints", json.dumps(list(self.connect))))
        if self.listen:
            items.append(("listen/endpoints", json.dumps(list(self.listen))))
        items.append(("scouting/multicast/enabled", json.dumps(self.multicast_scouting)))
        if self.credentials and self.tls:
            from agent.trust import Credentials, Identity, acl_settings, tls_settings

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
#: The router's second port (issue #9): world links and the agents' body sessions
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


# --------------------------------------------------------------------------- errors


class ProtocolError(ValueError):
    """A payload or key that does not fit the schema; the text is the reason."""


def _check_id(robot_id: Any) -> int:
    if isinstance(robot_id, bool) or not isinstance(robot_id, int):
        raise ProtocolError(f"robot id must be an int, got {type(robot_id).__name__}")
    if not 0 <= robot_id <= MAX_ROBOT_ID:
        raise ProtocolError(f"robot id {robot_id} outside [0, {MAX_ROBOT_ID}]")
    return robot_id


# --------------------------------------------------------------------------- validators


def _int(name: str, lo: int, hi: int) -> Callable[[Any], int]:
    def check(v: Any) -> int:
        if isinstance(v, bool) or not isinstance(v, int):
            raise ProtocolError(f"{name}: expected int, got {type(v).__name__}")
        if not lo <= v <= hi:
            raise ProtocolError(f"{name}: {v} outside [{lo}, {hi}]")
        return v

    return check


def _float(name: str, lo: float = -math.inf, hi: float = math.inf) -> Callable[[Any], float]:
    def check(v: Any) -> float:
        if isinstance(v, bool) or not isinstance(v, int | float):
            raise ProtocolError(f"{name}: expected a number, got {type(v).__name__}")
        f = float(v)
        if not math.isfinite(f):
            raise ProtocolError(f"{name}: {f} is not finite")
        if not lo <= f <= hi:
            raise ProtocolError(f"{name}: {f} outside [{lo}, {hi}]")
        return f

    return check


def _bool(name: str) -> Callable[[Any], bool]:
    def check(v: Any) -> bool:
        if not isinstance(v, bool):
            raise ProtocolError(f"{name}: expected bool, got {type(v).__name__}")
        return v

    return check


def _str(
    name: str, max_len: int = MAX_TEXT, choices: tuple[str, ...] | None = None
) -> Callable[[Any], str]:
    def check(v: Any) -> str:
        if not isinstance(v, str):
            raise ProtocolError(f"{name}: expected str, got {type(v).__name__}")
        if len(v) > max_len:
            raise ProtocolError(f"{name}: {len(v)} characters, at most {max_len}")
        if choices is not None and v not in choices:
            raise ProtocolError(f"{name}: {_short(v)} is not one of {', '.join(choices)}")
        return v

    return check


def _hex(
    name: str, length: int = DIGEST_HEX_LEN, allow_empty: bool = False
) -> Callable[[Any], str]:
    def check(v: Any) -> str:
        if not isinstance(v, str):
            raise ProtocolError(f"{name}: expected hex str, got {type(v).__name__}")
        if allow_empty and v == "":
            return v
        if len(v) != length or any(c not in "0123456789abcdef" for c in v):
            raise ProtocolError(f"{name}: expected {length} lowercase hex digits")
        return v

    return check


def _bytes(name: str, max_len: int) -> Callable[[Any], bytes]:
    def check(v: Any) -> bytes:
        if not isinstance(v, bytes | bytearray):
            raise ProtocolError(f"{name}: expected bytes, got {type(v).__name__}")
        if len(v) > max_len:
            raise ProtocolError(f"{name}: {len(v)} bytes, at most {max_len}")
        return bytes(v)

    return check


def _seq(name: str, item: Callable[[Any], Any], max_len: int) -> Callable[[Any], tuple[Any, ...]]:
    def check(v: Any) -> tuple[Any, ...]:
        if not isinstance(v, list | tuple):
            raise ProtocolError(f"{name}: expected a list, got {type(v).__name__}")
        if len(v) > max_len:
            raise ProtocolError(f"{name}: {len(v)} items, at most {max_len}")
        return tuple(item(x) for x in v)

    return check


def _tuple(name: str, *items: Callable[[Any], Any]) -> Callable[[Any], tuple[Any, ...]]:
    def check(v: Any) -> tuple[Any, ...]:
        if not isinstance(v, list | tuple) or len(v) != len(items):
            raise ProtocolError(f"{name}: expected a list of {len(items)} items")
        return tuple(f(x) for f, x in zip(items, v, strict=True))

    return check


def _optional(check: Callable[[Any], Any]) -> Callable[[Any], Any]:
    def opt(v: Any) -> Any:
        return None if v is None else check(v)

    return opt


_XY = _tuple("point", _float("x", -MAX_COORD, MAX_COORD), _float("y", -MAX_COORD, MAX_COORD))
_ID = _int("id", 0, MAX_ROBOT_ID)


# --------------------------------------------------------------------------- messages

M = TypeVar("M", bound="Message")
_REGISTRY: dict[str, type[Message]] = {}


@dataclass(frozen=True)
class Message:
    """Base of every wire message. Subclasses set ``TAG`` and ``SCHEMA``."""

    TAG: ClassVar[str] = ""
    SCHEMA: ClassVar[Mapping[str, Callable[[Any], Any]]] = {}

    def __init_subclass__(cls, **kwargs: Any) -> None:
        super().__init_subclass__(**kwargs)
        if cls.TAG:
            if cls.TAG in _REGISTRY:
                raise TypeError(f"duplicate message tag {cls.TAG!r}")
            _REGISTRY[cls.TAG] = cls

    def __post_init__(self) -> None:
        # Validate on construction too, so a bad message cannot even be sent.
        for f in fields(self):
            check = self.SCHEMA.get(f.name)
            if check is None:
                raise TypeError(f"{type(self).__name__}.{f.name} has no schema entry")
            object.__setattr__(self, f.name, check(getattr(self, f.name)))

    def to_wire(self) -> dict[str, Any]:
        out: dict[str, Any] = {"v": SCHEMA_VERSION, "t": self.TAG}
        for f in fields(self):
            out[f.name] = _plain(getattr(self, f.name))
        return out


def _plain(v: Any) -> Any:
    if isinstance(v, tuple):
        return [_plain(x) for x in v]
    return v


@dataclass(frozen=True)
class NeighborRecordMsg(Message):
    """A robot's neighbour record (NAO paper 4.1.2): detections in its fixed frame.

    ``neighbours`` are (x, y) in metres; ``orientations`` (rad, the matched mask's
    relative orientation) and ``confidences`` (λ) are empty or one per neighbour.
    ``round`` counts search rounds (a robot that found nobody searches again).
    ``obstacles`` (x, y) in metres are the static obstacles it saw (5.1.2), in the same
    fixed frame; empty from a sender that saw none or predates them.
    """

    TAG: ClassVar[str] = "record"
    sender: int
    round: int
    neighbours: tuple[tuple[float, float], ...]
    orientations: tuple[float, ...] = ()
    confidences: tuple[float, ...] = ()
    obstacles: tuple[tuple[float, float], ...] = ()
    SCHEMA: ClassVar[Mapping[str, Callable[[Any], Any]]] = {
        "sender": _ID,
        "round": _int("round", 0, 1_000_000),
        "neighbours": _seq("neighbours", _XY, MAX_NEIGHBOURS),
        "orientations": _seq("orientations", _float("orientation", -10.0, 10.0), MAX_NEIGHBOURS),
        "confidences": _seq("confidences", _float("confidence", 0.0, 1.0), MAX_NEIGHBOURS),
        "obstacles": _seq("obstacles", _XY, MAX_OBSTACLES),
    }

    def __post_init__(self) -> None:
        super().__post_init__()
        k = len(self.neighbours)
        for name in ("orientations", "confidences"):
            n = len(getattr(self, name))
            if n not in (0, k):
                raise ProtocolError(f"{name}: {n} values for {k} neighbours")


@dataclass(frozen=True)
class DigestMsg(Message):
    """The digest of the record set an agent holds, and the members it covers.

    ``params``: the digest of the agent's agreed planning parameters (d_e, φ_e,
    radius, strategy, march route; :func:`agent.exchange.params_digest`), empty from
    a sender that predates it. Agreement needs it equal on every member too."""

    TAG: ClassVar[str] = "digest"
    sender: int
    round: int
    digest: str
    members: tuple[int, ...]
    params: str = ""
    SCHEMA: ClassVar[Mapping[str, Callable[[Any], Any]]] = {
        "sender": _ID,
        "round": _int("round", 0, 1_000_000),
        "digest": _hex("digest"),
        "members": _seq("members", _ID, MAX_MEMBERS),
        "params": _hex("params", allow_empty=True),
    }


@dataclass(frozen=True)
class StatusMsg(Message):
    """Phase and progress of one agent, for viewers and for wave sequencing."""

    TAG: ClassVar[str] = "status"
    sender: int
    phase: str
    progress: float = 0.0
    detail: str = ""
    plan_digest: str = ""
    wave: int = -1
    error: str = ""
    t_sim: float = 0.0
    bytes_sent: int = 0
    SCHEMA: ClassVar[Mapping[str, Callable[[Any], Any]]] = {
        "sender": _ID,
        "phase": _str("phase", 16, PHASES),
        "progress": _float("progress", 0.0, 1.0),
        "detail": _str("detail"),
        "plan_digest": _hex("plan_digest", allow_empty=True),
        "wave": _int("wave", -1, 1_000_000),
        "error": _str("error"),
        "t_sim": _float("t_sim", 0.0),
        "bytes_sent": _int("bytes_sent", 0, 2**62),
    }


#: A neighbour record's wire form in a :class:`RecordSetReply` (64 neighbours: ~2.5 KB).
MAX_RECORD_BYTES = 4096


@dataclass(frozen=True)
class RecordSetRequest(Message):
    """Ask the agents for the agreed record set whose digest is ``digest`` (issue #9:
    a restarted agent fetches what it agreed on); empty: whatever set they agreed on.
    Only agents holding it answer."""

    TAG: ClassVar[str] = "recordset?"
    digest: str
    SCHEMA: ClassVar[Mapping[str, Callable[[Any], Any]]] = {
        "digest": _hex("digest", allow_empty=True)
    }


@dataclass(frozen=True)
class RecordSetReply(Message):
    """The agreed record set ``digest`` as held by ``sender``: each record's wire form
    (:func:`encode` of a :class:`NeighborRecordMsg`), sorted by sender, exactly the
    bytes :func:`agent.exchange.canonical_digest` hashes, so the asker checks the set
    against the digest before using it."""

    TAG: ClassVar[str] = "recordset"
    sender: int
    digest: str
    records: tuple[bytes, ...]
    SCHEMA: ClassVar[Mapping[str, Callable[[Any], Any]]] = {
        "sender": _ID,
        "digest": _hex("digest"),
        "records": _seq("records", _bytes("record", MAX_RECORD_BYTES), MAX_MEMBERS),
    }


@dataclass(frozen=True)
class RegisterRequest(Message):
    """Ask the world for a free robot id (``--id auto``); ``want`` is a preference or -1."""

    TAG: ClassVar[str] = "register"
    want: int = -1
    SCHEMA: ClassVar[Mapping[str, Callable[[Any], Any]]] = {"want": _int("want", -1, MAX_ROBOT_ID)}


@dataclass(frozen=True)
class RegisterReply(Message):
    TAG: ClassVar[str] = "registered"
    robot_id: int
    SCHEMA: ClassVar[Mapping[str, Callable[[Any], Any]]] = {"robot_id": _ID}


@dataclass(frozen=True)
class CameraRequest(Message):
    """Render the forehead camera with the head at ``yaw`` (rad, +left, |yaw| <= 119.5°)."""

    TAG: ClassVar[str] = "camera"
    yaw: float = 0.0
    SCHEMA: ClassVar[Mapping[str, Callable[[Any], Any]]] = {"yaw": _float("yaw")}


@dataclass(frozen=True)
class CameraReply(Message):
    TAG: ClassVar[str] = "image"
    robot_id: int
    yaw: float
    t_sim: float
    width: int
    height: int
    encoding: str
    data: bytes = field(repr=False)
    SCHEMA: ClassVar[Mapping[str, Callable[[Any], Any]]] = {
        "robot_id": _ID,
        "yaw": _float("yaw", -HEAD_YAW_LIMIT - 1e-9, HEAD_YAW_LIMIT + 1e-9),
        "t_sim": _float("t_sim", 0.0),
        "width": _int("width", 1, 8192),
        "height": _int("height", 1, 8192),
        "encoding": _str("encoding", 8, ("png",)),
        "data": _bytes("data", MAX_IMAGE_BYTES),
    }


#: Motion request ids (issue #9): 0 is "no id" (executed every time); 1..MAX_REQUEST_ID
#: are executed once per (robot, id) by the world, which answers a repeat with the
#: first result, so a client may retry a timed-out motion with the same id.
MAX_REQUEST_ID = 2**53 - 1
_REQUEST_ID = _int("request_id", 0, MAX_REQUEST_ID)


@dataclass(frozen=True)
class WalkRequest(Message):
    """Walk straight ahead ``distance`` metres (negative: backwards); ``request_id``:
    see :data:`MAX_REQUEST_ID`."""

    TAG: ClassVar[str] = "walk"
    distance: float
    request_id: int = 0
    SCHEMA: ClassVar[Mapping[str, Callable[[Any], Any]]] = {
        "distance": _float("distance"),
        "request_id": _REQUEST_ID,
    }


@dataclass(frozen=True)
class TurnRequest(Message):
    """Turn on the spot by ``angle`` radians (positive: counter-clockwise); ``request_id``:
    see :data:`MAX_REQUEST_ID`."""

    TAG: ClassVar[str] = "turn"
    angle: float
    request_id: int = 0
    SCHEMA: ClassVar[Mapping[str, Callable[[Any], Any]]] = {
        "angle": _float("angle"),
        "request_id": _REQUEST_ID,
    }


@dataclass(frozen=True)
class CommandReply(Message):
    """Completion of a walk or turn: ``status`` is done, contact (stopped by a contact)
    or error. Carries no pose: agents never learn ground truth."""

    TAG: ClassVar[str] = "done"
    robot_id: int
    status: str
    t_sim: float
    detail: str = ""
    SCHEMA: ClassVar[Mapping[str, Callable[[Any], Any]]] = {
        "robot_id": _ID,
        "status": _str("status", 16, ("done", "contact", "error")),
        "t_sim": _float("t_sim", 0.0),
        "detail": _str("detail"),
    }


@dataclass(frozen=True)
class ErrorReply(Message):
    """The reply to a request the world cannot serve; ``reason`` says why."""

    TAG: ClassVar[str] = "error"
    reason: str
    SCHEMA: ClassVar[Mapping[str, Callable[[Any], Any]]] = {"reason": _str("reason")}


@dataclass(frozen=True)
class ClockMsg(Message):
    TAG: ClassVar[str] = "clock"
    t_sim: float
    SCHEMA: ClassVar[Mapping[str, Callable[[Any], Any]]] = {"t_sim": _float("t_sim", 0.0)}


@dataclass(frozen=True)
class TruthPosesMsg(Message):
    """Ground truth (evaluation only): ``poses`` are (id, x, y, heading)."""

    TAG: ClassVar[str] = "truth"
    t_sim: float
    poses: tuple[tuple[int, float, float, float], ...]
    contacts: int = 0
    SCHEMA: ClassVar[Mapping[str, Callable[[Any], Any]]] = {
        "t_sim": _float("t_sim", 0.0),
        "poses": _seq(
            "poses",
            _tuple(
                "pose",
                _ID,
                _float("x", -MAX_COORD, MAX_COORD),
                _float("y", -MAX_COORD, MAX_COORD),
                _float("heading"),
            ),
            MAX_MEMBERS,
        ),
        "contacts": _int("contacts", 0, 2**62),
    }


@dataclass(frozen=True)
class ContactMsg(Message):
    """A contact between two bodies (evaluation only); ``b`` is -1 for an obstacle."""

    TAG: ClassVar[str] = "contact"
    t_sim: float
    a: int
    b: int
    SCHEMA: ClassVar[Mapping[str, Callable[[Any], Any]]] = {
        "t_sim": _float("t_sim", 0.0),
        "a": _ID,
        "b": _int("b", -1, MAX_ROBOT_ID),
    }


# --------------------------------------------------------------------------- codec


def encode(msg: Message) -> bytes:
    """msgpack bytes of ``msg`` with the schema version and type tag."""
    if not isinstance(msg, Message) or not msg.TAG:
        raise ProtocolError(f"cannot encode {type(msg).__name__}: not a wire message")
    data = msgpack.packb(msg.to_wire(), use_bin_type=True)
    assert isinstance(data, bytes)
    return data


class _Sized(Protocol):
    def __len__(self) -> int: ...
    def to_bytes(self) -> bytes: ...


def take_payload(payload: _Sized | None, max_bytes: int) -> bytes:
    """The bytes of a zenoh payload (``ZBytes``), its length checked *before* the copy.

    Raises :class:`ProtocolError` for a missing payload or one over ``max_bytes``: an
    oversized payload is never copied out of zenoh's buffers.
    """
    if payload is None:
        raise ProtocolError("no payload")
    n = len(payload)
    if n > max_bytes:
        raise ProtocolError(f"payload of {n} bytes exceeds {max_bytes}")
    data = payload.to_bytes()
    if len(data) != n:  # cannot happen with ZBytes; a lying object must not slip through
        raise ProtocolError(f"payload said {n} bytes, gave {len(data)}")
    return data


# msgpack's first bytes (https://github.com/msgpack/msgpack/blob/master/spec.md): the
# size of what follows each type byte. Used by the structure scan below.
_FIXED = {0xC0: 0, 0xC2: 0, 0xC3: 0, 0xCA: 4, 0xCB: 8, 0xCC: 1, 0xCD: 2, 0xCE: 4, 0xCF: 8}
_FIXED.update({0xD0: 1, 0xD1: 2, 0xD2: 4, 0xD3: 8})
_SIZED = {0xC4: 1, 0xC5: 2, 0xC6: 4, 0xD9: 1, 0xDA: 2, 0xDB: 4}  # bin 8/16/32, str 8/16/32
_CONTAINERS = {0xDC: (2, 1), 0xDD: (4, 1), 0xDE: (2, 2), 0xDF: (4, 2)}  # array, map 16/32
_EXT = frozenset({0xC7, 0xC8, 0xC9, 0xD4, 0xD5, 0xD6, 0xD7, 0xD8})


def _scan(
    raw: bytes,
    max_objects: int,
    max_depth: int,
    max_str: int = MAX_STR_BYTES,
    max_bin: int = MAX_IMAGE_BYTES,
) -> None:
    """Walk the msgpack structure of ``raw`` without building it.

    Rejects, before anything is allocated per object: more than ``max_objects``
    objects, nesting deeper than ``max_depth``, containers longer than the codec's
    limits, ext types, the reserved byte 0xc1, truncation and trailing bytes. The walk
    stops at the first excess, so its cost is bounded by ``max_objects`` steps whatever
    the payload's size (strings and binaries are skipped, not read).
    """
    n = len(raw)
    pos = 0
    left = [1]  # objects still to read in each open container; the top holds one object
    objects = 0
    while left:
        if left[-1] == 0:
            left.pop()
            continue
        left[-1] -= 1
        if pos >= n:
            raise ProtocolError(f"not msgpack: truncated: {n} bytes end before the object does")
        b = raw[pos]
        pos += 1
        objects += 1
        if objects > max_objects:
            raise ProtocolError(f"more than {max_objects} msgpack objects")
        count = 0
        if b <= 0x7F or b >= 0xE0:  # positive/negative fixint
            continue
        if b <= 0x8F:  # fixmap
            count = 2 * (b & 0x0F)
        elif b <= 0x9F:  # fixarray
            count = b & 0x0F
        elif b <= 0xBF:  # fixstr
            if b & 0x1F > max_str:
                raise ProtocolError(f"string of {b & 0x1F} bytes, at most {max_str}")
            pos += b & 0x1F
        elif b in _FIXED:
            pos += _FIXED[b]
        elif b in _SIZED:
            w = _SIZED[b]
            size = int.from_bytes(raw[pos : pos + w], "big")
            limit = max_str if b >= 0xD9 else max_bin
            if size > limit:
                kind = "string" if b >= 0xD9 else "binary"
                raise ProtocolError(f"{kind} of {size} bytes, at most {limit}")
            pos += w + size
        elif b in _CONTAINERS:
            w, per = _CONTAINERS[b]
            items = int.from_bytes(raw[pos : pos + w], "big")
            pos += w
            limit = MAX_MAP_LEN if per == 2 else MAX_ARRAY_LEN
            if items > limit:
                kind = "map of" if per == 2 else "array of"
                raise ProtocolError(f"{kind} {items} entries, at most {limit}")
            count = per * items
        elif b in _EXT:
            raise ProtocolError(f"msgpack ext type (0x{b:02x}) is not part of the protocol")
        else:  # 0xc1: never used
            raise ProtocolError(f"not msgpack: invalid byte 0x{b:02x} at {pos - 1}")
        if pos > n:
            raise ProtocolError(f"not msgpack: truncated: needs {pos} bytes, has {n}")
        if count:
            if len(left) > max_depth:
                raise ProtocolError(f"msgpack nested deeper than {max_depth}")
            left.append(count)
    if pos != n:
        raise ProtocolError(
            f"not msgpack: {n - pos} bytes of trailing data after the msgpack object"
        )


def unpack_bounded(
    data: bytes | bytearray | memoryview,
    max_bytes: int = MAX_MESSAGE_BYTES,
    *,
    max_objects: int = MAX_OBJECTS,
    max_depth: int = MAX_DEPTH,
    max_str_bytes: int = MAX_STR_BYTES,
    max_bin_bytes: int = MAX_IMAGE_BYTES,
) -> Any:
    """One msgpack object from ``data`` within hard limits, or :class:`ProtocolError`.

    The limits bound time and memory for *any* input, valid or not: the size is checked
    first (pass the payload's length check to :func:`take_payload` to avoid the copy
    too); a structure scan then rejects more than ``max_objects`` objects (a truth
    message for 1024 robots has ~5200; each object costs ~50-100 B of Python memory, so
    8192 objects stay under 1 MB), nesting deeper than ``max_depth`` (messages are 3
    deep), maps over ``MAX_MAP_LEN`` entries (messages have at most 11 fields), arrays
    over ``MAX_ARRAY_LEN`` items (``MAX_MEMBERS``), strings over ``MAX_STR_BYTES`` (the
    UTF-8 of ``MAX_TEXT`` characters), binaries over ``MAX_IMAGE_BYTES``, ext types and
    trailing bytes; msgpack's own limits repeat these caps. Map keys must be text or
    bytes; text must be valid UTF-8. Every failure is a ``ProtocolError``.

    For an envelope that carries a whole message as one binary field, pass
    ``max_bin_bytes=MAX_MESSAGE_BYTES`` and a ``max_bytes`` that adds the envelope's own
    overhead; then :func:`decode` the inner bytes (the limits apply again there).
    """
    if not isinstance(data, bytes | bytearray | memoryview):
        raise ProtocolError(f"expected bytes, got {type(data).__name__}")
    n = data.nbytes if isinstance(data, memoryview) else len(data)
    if n > max_bytes:
        raise ProtocolError(f"message of {n} bytes exceeds {max_bytes}")
    raw = bytes(data)
    _scan(raw, max_objects, max_depth, max_str_bytes, max_bin_bytes)
    try:
        return msgpack.unpackb(
            raw,
            raw=False,
            strict_map_key=True,
            max_str_len=max_str_bytes,
            max_bin_len=max_bin_bytes,
            max_array_len=MAX_ARRAY_LEN,
            max_map_len=MAX_MAP_LEN,
            max_ext_len=0,
        )
    except Exception as exc:  # msgpack raises several unrelated types
        raise ProtocolError(f"not msgpack: {type(exc).__name__}: {_short(str(exc), 120)}") from None


def decode(
    data: bytes | bytearray | memoryview,
    expect: type[M] | None = None,
    *,
    max_bytes: int = MAX_MESSAGE_BYTES,
) -> Any:
    """Parse and validate one message. ``expect`` restricts the accepted type.

    Raises :class:`ProtocolError` with the reason for anything that does not fit; no
    other exception leaves this function (the fuzz test in tests/test_fuzz.py and
    ``python -m tools.fuzz`` hold it to that).
    """
    obj = unpack_bounded(data, max_bytes)
    if not isinstance(obj, dict):
        raise ProtocolError(f"expected a map, got {type(obj).__name__}")
    if not all(isinstance(k, str) for k in obj):
        raise ProtocolError("field names must be text, got binary")
    version = obj.get("v")
    if type(version) is not int or version != SCHEMA_VERSION:  # not True, not 1.0
        raise ProtocolError(
            f"schema version {_short(version)}, this build speaks {SCHEMA_VERSION} (an int)"
        )
    tag = obj.get("t")
    cls = _REGISTRY.get(tag) if isinstance(tag, str) else None
    if cls is None:
        raise ProtocolError(f"unknown message type {_short(tag)}")
    if expect is not None and cls is not expect:
        raise ProtocolError(f"expected a {expect.TAG!r} message, got {tag!r}")
    names = {f.name for f in fields(cls)}
    extra = set(obj) - names - {"v", "t"}
    if extra:
        shown = ", ".join(_short(k, 24) for k in sorted(extra)[:4])
        more = f" and {len(extra) - 4} more" if len(extra) > 4 else ""
        raise ProtocolError(f"{tag}: unknown fields {shown}{more}")
    kwargs = {k: obj[k] for k in names if k in obj}
    try:
        return cls(**kwargs)
    except ProtocolError:
        raise
    except TypeError as exc:  # a required field is missing
        raise ProtocolError(f"{tag}: {exc}") from None


def message_types() -> dict[str, type[Message]]:
    """Every registered message class by tag (for tests and tools)."""
    return dict(_REGISTRY)


# --------------------------------------------------------------------------- receiving
# Shared by every process that listens on the bus (agents, world, tools): the world may
# import only this module of agent/, so the receiving helpers live here too.

#: Log lines about rejected input are cut to this many characters.
MAX_REASON = 200

T = TypeVar("T")


def reason(exc: BaseException | str, limit: int = MAX_REASON) -> str:
    """One log line about ``exc``: its text (with the type unless it is a
    ``ProtocolError``), on one line, cut to ``limit`` characters."""
    if isinstance(exc, str):
        text = exc
    else:
        try:
            msg = str(exc)
        except Exception:  # an exception whose __str__ raises: still a reason
            msg = "<unprintable>"
        text = msg if isinstance(exc, ProtocolError) else f"{type(exc).__name__}: {msg}"
    text = text[: limit * 2].replace("\n", " ").replace("\r", " ")
    return text if len(text) <= limit else text[: limit - 3] + "..."


class Guard:
    """Keeps zenoh callbacks alive: every exception is caught, counted and logged.

    :meth:`wrap` turns a callback into one that never raises; :meth:`reject` counts one
    rejected input and logs its reason (cut to ``MAX_REASON`` characters). Log lines are
    rate limited (``burst`` lines, then ``per_second``), so a flood of garbage cannot
    flood the log; the next line that is written says how many were suppressed.
    Thread-safe: zenoh calls callbacks from its own threads.
    """

    def __init__(
        self,
        log: Callable[[str], Any],
        *,
        on_reject: Callable[[], Any] | None = None,
        burst: int = 20,
        per_second: float = 2.0,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        if burst < 1 or not per_second > 0:
            raise ValueError(f"need burst >= 1 and per_second > 0, got {burst}, {per_second}")
        self._log = log
        self._on_reject = on_reject
        self._burst = float(burst)
        self._rate = per_second
        self._clock = clock
        self._tokens = float(burst)
        self._last = clock()
        self._lock = threading.Lock()
        self.rejected = 0
        self.suppressed = 0

    def reject(self, what: str, why: BaseException | str) -> None:
        """Count one rejected input on ``what`` and log ``why`` (rate limited)."""
        with self._lock:
            self.rejected += 1
            now = self._clock()
            self._tokens = min(self._burst, self._tokens + (now - self._last) * self._rate)
            self._last = now
            if self._tokens < 1.0:
                self.suppressed += 1
                line = None
            else:
                self._tokens -= 1.0
                extra = f" (+{self.suppressed} suppressed)" if self.suppressed else ""
                self.suppressed = 0
                line = f"rejected {reason(what, 80)}: {reason(why)}{extra}"
        if self._on_reject is not None:
            with contextlib.suppress(Exception):  # a counter must not break its callback
                self._on_reject()
        if line is not None:
            with contextlib.suppress(Exception):  # nor may a broken log
                self._log(line)

    def wrap(self, fn: Callable[[T], Any], what: str) -> Callable[[T], None]:
        """``fn`` as a callback that counts and logs any exception instead of raising."""

        def guarded(arg: T) -> None:
            try:
                fn(arg)
            except Exception as exc:
                self.reject(what, exc)

        return guarded


class Inbox(Generic[T]):
    """Bounded, thread-safe queue in lanes: a full lane drops its *oldest* items.

    ``caps`` names the lanes and their capacity in items; ``max_weight`` optionally caps
    a lane's total weight too (e.g. payload bytes, so that a lane of big messages stays
    small in memory). :meth:`put` returns how many items it dropped to make room (an
    item heavier than the whole lane is itself dropped) and counts them in
    ``dropped[lane]``. :meth:`get` takes the oldest item of all lanes (arrival order),
    or with ``priority=True`` the oldest of the first non-empty lane in the order of
    ``caps``. Raises ``queue.Empty`` like ``queue.Queue``.
    """

    def __init__(
        self,
        caps: Mapping[str, int],
        priority: bool = False,
        max_weight: Mapping[str, int] | None = None,
    ) -> None:
        weights = dict(max_weight or {})
        if (
            not caps
            or any(isinstance(c, bool) or not isinstance(c, int) or c < 1 for c in caps.values())
            or any(w < 1 for w in weights.values())
            or not set(weights) <= set(caps)
        ):
            raise ValueError(
                f"every lane needs a capacity >= 1 (and weight cap >= 1), got {dict(caps)}, "
                f"{weights}"
            )
        self._lanes: dict[str, collections.deque[tuple[int, T, int]]] = {
            lane: collections.deque() for lane in caps
        }
        self._caps = dict(caps)
        self._max_weight = weights
        self._weight: collections.Counter[str] = collections.Counter()
        self._priority = priority
        self._seq = 0
        self._cond = threading.Condition()
        self.dropped: collections.Counter[str] = collections.Counter()

    def put(self, lane: str, item: T, weight: int = 0) -> int:
        """Queue ``item``; returns the number of items dropped (oldest first)."""
        with self._cond:
            q = self._lanes[lane]
            cap_w = self._max_weight.get(lane)
            if cap_w is not None and weight > cap_w:
                self.dropped[lane] += 1
                return 1
            dropped = 0
            while q and (
                len(q) >= self._caps[lane]
                or (cap_w is not None and self._weight[lane] + weight > cap_w)
            ):
                self._weight[lane] -= q.popleft()[2]
                dropped += 1
            if dropped:
                self.dropped[lane] += dropped
            q.append((self._seq, item, weight))
            self._weight[lane] += weight
            self._seq += 1
            self._cond.notify()
            return dropped

    def _pop(self) -> tuple[str, T] | None:
        best: str | None = None
        for lane, q in self._lanes.items():
            if q and (best is None or (not self._priority and q[0][0] < self._lanes[best][0][0])):
                best = lane
                if self._priority:
                    break
        if best is None:
            return None
        _, item, weight = self._lanes[best].popleft()
        self._weight[best] -= weight
        return best, item

    def get(self, timeout: float | None = None) -> tuple[str, T]:
        """The next (lane, item), waiting up to ``timeout`` s (None: forever)."""
        with self._cond:
            end = None if timeout is None else time.monotonic() + timeout
            while True:
                got = self._pop()
                if got is not None:
                    return got
                left = None if end is None else end - time.monotonic()
                if left is not None and left <= 0:
                    raise queue.Empty
                self._cond.wait(left)

    def get_nowait(self) -> tuple[str, T]:
        with self._cond:
            got = self._pop()
            if got is None:
                raise queue.Empty
            return got

    def __len__(self) -> int:
        with self._cond:
            return sum(len(q) for q in self._lanes.values())

    def lengths(self) -> dict[str, int]:
        with self._cond:
            return {lane: len(q) for lane, q in self._lanes.items()}

    def weights(self) -> dict[str, int]:
        with self._cond:
            return {lane: self._weight[lane] for lane in self._lanes}


# --------------------------------------------------------------------------- trust
# The signed envelope and the fleet credentials are part of the wire contract; sim/
# reaches them here. Imported last: agent.trust uses the codec above.
from agent import trust  # noqa: E402, F401
