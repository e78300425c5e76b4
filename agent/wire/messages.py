"""Message schemas of the wire contract (docs/design.md §3).

Every message on the wire is a msgpack map ``{"v": SCHEMA_VERSION, "t": <type tag>,
...fields}``; each class declares its fields' validators (:mod:`agent.wire.fields`).
A camera reply carries a BGR uint8 picture as raw pixels or PNG (:mod:`agent.wire.picture`);
the camera frames agents publish for viewers (:class:`CameraMsg`) are JPEG thumbnails.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field, fields, is_dataclass
from typing import Any, ClassVar, TypeVar

from agent.wire.fields import (
    _ID,
    _XY,
    HEAD_YAW_LIMIT,
    MAX_CAMERA_DETECTIONS,
    MAX_COORD,
    MAX_IMAGE_BYTES,
    MAX_MEMBERS,
    MAX_NEIGHBOURS,
    MAX_OBSTACLES,
    MAX_ROBOT_ID,
    MAX_SHIFT,
    MAX_SIDE_STEP,
    MAX_STANCES,
    MAX_THUMBNAIL_BYTES,
    MAX_THUMBNAIL_HEIGHT,
    MAX_THUMBNAIL_WIDTH,
    MAX_WALKED,
    PICTURE_ENCODINGS,
    SCHEMA_VERSION,
    ProtocolError,
    _bytes,
    _float,
    _hex,
    _int,
    _seq,
    _str,
    _tuple,
)

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
    if is_dataclass(v) and not isinstance(v, type):  # a record inside a message: a map
        return {f.name: _plain(getattr(v, f.name)) for f in fields(v)}
    return v


@dataclass(frozen=True)
class NeighborRecordMsg(Message):
    """A robot's neighbour record (NAO paper 4.1.2): detections in its fixed frame.

    ``neighbours`` are (x, y) in metres; ``orientations`` (rad, the matched mask's
    relative orientation) and ``confidences`` (λ) are empty or one per neighbour.
    ``round`` counts search rounds (a robot that found nobody searches again).
    ``obstacles`` (x, y) in metres are the static obstacles it saw (5.1.2), in the same
    fixed frame; empty from a sender that saw none or predates them.
    ``calibration``: the digest of the recogniser's calibration the detections were
    made with (:mod:`agent.core.perception.calibration`); empty from a sender that
    predates it.
    ``seen_at``: empty or one per neighbour, the sender's clock (s; sim time in the
    simulation) when the image its orientation comes from was taken. ``stances``: the
    spans ``(from, to, heading)`` of the sender's clock over which its body stood still
    at ``heading`` (rad, turned from its heading when its fixed frame was defined), in
    time order; its body turned between them; ``clock_error``: how far (s) the sender's
    clock may be from the fleet's (docs/design.md §9 "Masks seen mid-turn").
    """

    TAG: ClassVar[str] = "record"
    sender: int
    round: int
    neighbours: tuple[tuple[float, float], ...]
    orientations: tuple[float, ...] = ()
    confidences: tuple[float, ...] = ()
    obstacles: tuple[tuple[float, float], ...] = ()
    calibration: str = ""
    seen_at: tuple[float, ...] = ()
    stances: tuple[tuple[float, float, float], ...] = ()
    clock_error: float = 0.0
    SCHEMA: ClassVar[Mapping[str, Callable[[Any], Any]]] = {
        "sender": _ID,
        "round": _int("round", 0, 1_000_000),
        "neighbours": _seq("neighbours", _XY, MAX_NEIGHBOURS),
        "orientations": _seq("orientations", _float("orientation", -10.0, 10.0), MAX_NEIGHBOURS),
        "confidences": _seq("confidences", _float("confidence", 0.0, 1.0), MAX_NEIGHBOURS),
        "obstacles": _seq("obstacles", _XY, MAX_OBSTACLES),
        "calibration": _hex("calibration", allow_empty=True),
        "seen_at": _seq("seen_at", _float("seen_at", 0.0), MAX_NEIGHBOURS),
        "stances": _seq(
            "stances",
            _tuple(
                "stance",
                _float("stance from", 0.0),
                _float("stance to", 0.0),
                _float("stance heading", -10.0, 10.0),
            ),
            MAX_STANCES,
        ),
        "clock_error": _float("clock_error", 0.0, 10.0),
    }

    def __post_init__(self) -> None:
        super().__post_init__()
        k = len(self.neighbours)
        last = 0.0
        for t0, t1, _ in self.stances:
            if not last <= t0 <= t1:
                raise ProtocolError(f"stances: span ({t0}, {t1}) out of time order")
            last = t1
        for name in ("orientations", "confidences", "seen_at"):
            n = len(getattr(self, name))
            if n not in (0, k):
                raise ProtocolError(f"{name}: {n} values for {k} neighbours")


@dataclass(frozen=True)
class DigestMsg(Message):
    """The digest of the record set an agent holds, and the members it covers.

    ``params``: the digest of the agent's agreed planning parameters (d_e, φ_e,
    radius, strategy, march route; :func:`agent.core.agreement.params_digest`), empty from
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
    """Phase and progress of one agent, for viewers and for wave sequencing.

    ``check_parent`` >= 0: the robot measured that parent with its camera after hold and
    judged the pair (``r_d``, ``r_phi``: NAO paper 5.1.1, ``agent.core.formation.shape.verdict``);
    -1: no such measurement (yet, or the leader).

    ``blocked_by`` >= 0: the robot's way to its slot has stayed blocked by that member
    beyond its patience (a dense fleet's jam, ``agent.core.formation.waves.jam``); -1: not blocked.

    ``walked``: how far the robot has walked along its planned path (m, arc length of the
    plan ``plan_digest``, never decreasing during its ``move``; 0 before it): a robot
    that waits for it starts once it is past the release point in the plan's
    ``after_at`` (finer waits, ``agent.core.formation.waves.release``).

    ``shift_x``, ``shift_y``: how far the robot has stepped since it arrived (m, the
    common frame of ``plan_digest``): its alignment to its own parent, which its children
    follow at once instead of one level after another (``agent.phases.hold``).

    ``calibration``: the digest of the recogniser's calibration the robot uses (the
    built-in one or a lab's, :mod:`agent.core.perception.calibration`); empty from a
    sender that predates it.
    """

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
    check_parent: int = -1
    r_d: float = 0.0
    r_phi: float = 0.0
    blocked_by: int = -1
    walked: float = 0.0
    shift_x: float = 0.0
    shift_y: float = 0.0
    calibration: str = ""
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
        "check_parent": _int("check_parent", -1, MAX_ROBOT_ID),
        "r_d": _float("r_d", -100.0, 100.0),
        "r_phi": _float("r_phi", -100.0, 100.0),
        "blocked_by": _int("blocked_by", -1, MAX_ROBOT_ID),
        "walked": _float("walked", 0.0, MAX_WALKED),
        "shift_x": _float("shift_x", -MAX_SHIFT, MAX_SHIFT),
        "shift_y": _float("shift_y", -MAX_SHIFT, MAX_SHIFT),
        "calibration": _hex("calibration", allow_empty=True),
    }


#: A neighbour record's wire form in a :class:`RecordSetReply`: MAX_NEIGHBOURS (128)
#: neighbours and MAX_OBSTACLES obstacles take ~5.4 KB (64 and 32: 3.1 KB).
MAX_RECORD_BYTES = 8192


@dataclass(frozen=True)
class RecordSetRequest(Message):
    """Ask the agents for the agreed record set whose digest is ``digest`` (crashed agents:
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
    bytes :func:`agent.wire.codec.canonical_digest` hashes, so the asker checks the set
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


#: Largest scenario a world hands out (JSON text of ``sim.scenarios.to_dict``).
MAX_SCENARIO_BYTES = 1 << 20


@dataclass(frozen=True)
class ScenarioRequest(Message):
    """Ask the world for its scenario (a render worker building its copy of the room)."""

    TAG: ClassVar[str] = "scenario?"
    SCHEMA: ClassVar[Mapping[str, Callable[[Any], Any]]] = {}


@dataclass(frozen=True)
class ScenarioReply(Message):
    """The world's scenario as JSON text (``sim.scenarios.to_dict``): same scenario and
    seed, same room and textures."""

    TAG: ClassVar[str] = "scenario"
    scenario: bytes = field(repr=False)
    SCHEMA: ClassVar[Mapping[str, Callable[[Any], Any]]] = {
        "scenario": _bytes("scenario", MAX_SCENARIO_BYTES)
    }


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
        "encoding": _str("encoding", 8, PICTURE_ENCODINGS),
        "data": _bytes("data", MAX_IMAGE_BYTES),
    }


#: Motion request ids (lost replies on a lossy radio): 0 is "no id" (executed every time);
#: 1..MAX_REQUEST_ID are executed once per (robot, id) by the world, which answers a repeat with the
#: first result, so a client may retry a timed-out motion with the same id.
MAX_REQUEST_ID = 2**53 - 1
_REQUEST_ID = _int("request_id", 0, MAX_REQUEST_ID)


@dataclass(frozen=True)
class WalkRequest(Message):
    """Walk straight ahead ``distance`` metres (negative: backwards), or, with
    ``distance`` 0, step ``lateral`` metres sideways (positive: to the left; NAOqi's
    ``moveTo(0, y, 0)``, at most :data:`MAX_SIDE_STEP`); ``request_id``: see
    :data:`MAX_REQUEST_ID`."""

    TAG: ClassVar[str] = "walk"
    distance: float
    request_id: int = 0
    lateral: float = 0.0
    SCHEMA: ClassVar[Mapping[str, Callable[[Any], Any]]] = {
        "distance": _float("distance"),
        "request_id": _REQUEST_ID,
        "lateral": _float("lateral", -MAX_SIDE_STEP, MAX_SIDE_STEP),
    }

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.lateral and self.distance:
            raise ProtocolError("walk: a step is straight ahead or sideways, not both")


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


#: How the reason of an :class:`ErrorReply` begins when the server is overloaded and
#: executed nothing: the caller may ask again later (at 100 NAOs the world's
#: bounded render queue refused pictures, and agents stopped on it).
BUSY = "world busy"


@dataclass(frozen=True)
class ErrorReply(Message):
    """The reply to a request the world cannot serve; ``reason`` says why (starting
    with :data:`BUSY` when it may be asked again later)."""

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


_PIXEL = _int("box", 0, max(MAX_THUMBNAIL_WIDTH, MAX_THUMBNAIL_HEIGHT))
_BOX_CHECK = _tuple("box", _PIXEL, _PIXEL, _PIXEL, _PIXEL)
_DETECTION_SCHEMA: Mapping[str, Callable[[Any], Any]] = {
    "id": _ID,
    "box": _BOX_CHECK,
    "d": _float("d", 0.0, 100.0),
    "phi": _float("phi", -2.0 * math.pi, 2.0 * math.pi),
}


@dataclass(frozen=True)
class CameraDetection:
    """One detection drawn on a camera thumbnail: ``id`` its number in the frame (the
    NAOs look alike: the camera cannot tell whom it sees), ``box`` (x, y, w, h) in
    thumbnail pixels, ``d`` the distance (m, NAO paper eq. 6) and ``phi`` the bearing
    (rad, +left, body frame: head yaw + pixel offset, eq. 3). On the wire: a map with
    exactly these four keys."""

    id: int
    box: tuple[int, int, int, int]
    d: float
    phi: float

    def __post_init__(self) -> None:
        for name, check in _DETECTION_SCHEMA.items():
            object.__setattr__(self, name, check(getattr(self, name)))


def _detection(v: Any) -> CameraDetection:
    if isinstance(v, CameraDetection):
        return v
    if not isinstance(v, dict):
        raise ProtocolError(f"detection: expected a map, got {type(v).__name__}")
    if set(v) != set(_DETECTION_SCHEMA):  # keys of any type: compared, never printed raw
        want = ", ".join(_DETECTION_SCHEMA)
        raise ProtocolError(f"detection: expected exactly the keys {want}")
    return CameraDetection(id=v["id"], box=v["box"], d=v["d"], phi=v["phi"])


@dataclass(frozen=True)
class CameraMsg(Message):
    """A camera frame robot ``robot`` analysed, for viewers (docs/design.md §10):
    published on ``nao/{robot}/camera`` only with ``--publish-camera``, at most a few per
    second (agent/phases/camera_feed.py).

    ``seq`` counts the frames published by this agent process; ``t_sim`` is the robot's
    time of the frame (s: sim time in the simulation, as :attr:`StatusMsg.t_sim`; the wire
    map's ``t`` is every message's type tag, so the field cannot be called ``t``); ``jpeg`` a
    JPEG thumbnail of ``width`` x ``height`` pixels (at most 320 x 240 and 32 KiB), ``yaw``
    the head yaw it was taken at (rad), ``detections`` what the detector found in it, boxes
    in thumbnail pixels.
    """

    TAG: ClassVar[str] = "thumbnail"
    robot: int
    seq: int
    t_sim: float
    width: int
    height: int
    jpeg: bytes = field(repr=False)
    yaw: float = 0.0
    detections: tuple[CameraDetection, ...] = ()
    SCHEMA: ClassVar[Mapping[str, Callable[[Any], Any]]] = {
        "robot": _int("robot", 0, MAX_ROBOT_ID),
        "seq": _int("seq", 0, 2**53),
        "t_sim": _float("t_sim", 0.0),
        "width": _int("width", 1, MAX_THUMBNAIL_WIDTH),
        "height": _int("height", 1, MAX_THUMBNAIL_HEIGHT),
        "jpeg": _bytes("jpeg", MAX_THUMBNAIL_BYTES),
        "yaw": _float("yaw", -HEAD_YAW_LIMIT - 1e-9, HEAD_YAW_LIMIT + 1e-9),
        "detections": _seq("detections", _detection, MAX_CAMERA_DETECTIONS),
    }

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.jpeg[:3] != b"\xff\xd8\xff":
            raise ProtocolError("jpeg: not a JPEG image (no start-of-image marker)")
        for det in self.detections:
            x, y, w, h = det.box
            if x + w > self.width or y + h > self.height:
                raise ProtocolError(
                    f"detection {det.id}: box {det.box} outside the {self.width}x{self.height} "
                    "thumbnail"
                )
