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

import json
import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field, fields
from typing import Any, ClassVar, TypeVar

import msgpack

from agent import nao as nao  # NAO facts, shared with sim/ through this module

SCHEMA_VERSION = 1
MAX_ROBOT_ID = 65535
MAX_NEIGHBOURS = 64
MAX_MEMBERS = 1024
MAX_TEXT = 512
MAX_IMAGE_BYTES = 8 * 1024 * 1024
MAX_MESSAGE_BYTES = MAX_IMAGE_BYTES + 4096
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
    "plan",
    "wait",
    "move",
    "hold",
    "done",
    "failed",
)

# --------------------------------------------------------------------------- keys

KEY_ALIVE_PREFIX = "nao/alive"
KEY_ALIVE_ALL = "nao/alive/*"
KEY_RECORD_ALL = "nao/*/record"
KEY_DIGEST_ALL = "nao/*/digest"
KEY_STATUS_ALL = "nao/*/status"
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


def key_camera(robot_id: int) -> str:
    return f"world/robot/{_check_id(robot_id)}/camera"


def key_walk(robot_id: int) -> str:
    return f"world/robot/{_check_id(robot_id)}/walk"


def key_turn(robot_id: int) -> str:
    return f"world/robot/{_check_id(robot_id)}/turn"


def id_from_key(key: str) -> int:
    """The robot id in ``nao/{id}/...``, ``nao/alive/{id}`` or ``world/robot/{id}/...``."""
    parts = str(key).split("/")
    if len(parts) >= 3 and parts[0] == "nao" and parts[1] == "alive":
        raw = parts[2]
    elif len(parts) >= 2 and parts[0] == "nao":
        raw = parts[1]
    elif len(parts) >= 3 and parts[0] == "world" and parts[1] == "robot":
        raw = parts[2]
    else:
        raise ProtocolError(f"key {key!r} names no robot")
    if not raw.isdigit():
        raise ProtocolError(f"key {key!r}: robot id {raw!r} is not a non-negative integer")
    return _check_id(int(raw))


# --------------------------------------------------------------------------- joining


ZENOH_MODES = ("peer", "client", "router")


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

    def __post_init__(self) -> None:
        if self.mode not in ZENOH_MODES:
            raise ValueError(f"mode must be peer, client or router, got {self.mode!r}")
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
        items = [("mode", json.dumps(self.mode))]
        if self.connect:
            items.append(("connect/endpoints", json.dumps(list(self.connect))))
        if self.listen:
            items.append(("listen/endpoints", json.dumps(list(self.listen))))
        items.append(("scouting/multicast/enabled", json.dumps(self.multicast_scouting)))
        return items


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
            raise ProtocolError(f"{name}: {v!r} is not one of {', '.join(choices)}")
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
    """

    TAG: ClassVar[str] = "record"
    sender: int
    round: int
    neighbours: tuple[tuple[float, float], ...]
    orientations: tuple[float, ...] = ()
    confidences: tuple[float, ...] = ()
    SCHEMA: ClassVar[Mapping[str, Callable[[Any], Any]]] = {
        "sender": _ID,
        "round": _int("round", 0, 1_000_000),
        "neighbours": _seq("neighbours", _XY, MAX_NEIGHBOURS),
        "orientations": _seq("orientations", _float("orientation", -10.0, 10.0), MAX_NEIGHBOURS),
        "confidences": _seq("confidences", _float("confidence", 0.0, 1.0), MAX_NEIGHBOURS),
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
    """The digest of the record set an agent holds, and the members it covers."""

    TAG: ClassVar[str] = "digest"
    sender: int
    round: int
    digest: str
    members: tuple[int, ...]
    SCHEMA: ClassVar[Mapping[str, Callable[[Any], Any]]] = {
        "sender": _ID,
        "round": _int("round", 0, 1_000_000),
        "digest": _hex("digest"),
        "members": _seq("members", _ID, MAX_MEMBERS),
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


@dataclass(frozen=True)
class WalkRequest(Message):
    """Walk straight ahead ``distance`` metres (negative: backwards)."""

    TAG: ClassVar[str] = "walk"
    distance: float
    SCHEMA: ClassVar[Mapping[str, Callable[[Any], Any]]] = {"distance": _float("distance")}


@dataclass(frozen=True)
class TurnRequest(Message):
    """Turn on the spot by ``angle`` radians (positive: counter-clockwise)."""

    TAG: ClassVar[str] = "turn"
    angle: float
    SCHEMA: ClassVar[Mapping[str, Callable[[Any], Any]]] = {"angle": _float("angle")}


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


def decode(data: bytes | bytearray | memoryview, expect: type[M] | None = None) -> Any:
    """Parse and validate one message. ``expect`` restricts the accepted type.

    Raises :class:`ProtocolError` with the reason for anything that does not fit.
    """
    raw = bytes(data)
    if len(raw) > MAX_MESSAGE_BYTES:
        raise ProtocolError(f"message of {len(raw)} bytes exceeds {MAX_MESSAGE_BYTES}")
    try:
        obj = msgpack.unpackb(raw, raw=False, strict_map_key=True, max_bin_len=MAX_IMAGE_BYTES)
    except Exception as exc:  # msgpack raises several unrelated types
        raise ProtocolError(f"not msgpack: {type(exc).__name__}: {exc}") from None
    if not isinstance(obj, dict):
        raise ProtocolError(f"expected a map, got {type(obj).__name__}")
    version = obj.get("v")
    if version != SCHEMA_VERSION:
        raise ProtocolError(f"schema version {version!r}, this build speaks {SCHEMA_VERSION}")
    tag = obj.get("t")
    cls = _REGISTRY.get(tag) if isinstance(tag, str) else None
    if cls is None:
        raise ProtocolError(f"unknown message type {tag!r}")
    if expect is not None and cls is not expect:
        raise ProtocolError(f"expected a {expect.TAG!r} message, got {tag!r}")
    names = {f.name for f in fields(cls)}
    extra = set(obj) - names - {"v", "t"}
    if extra:
        raise ProtocolError(f"{tag}: unknown fields {sorted(extra)}")
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
