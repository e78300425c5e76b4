"""A query to the world as its zenoh callbacks take it (docs/design.md §3 queryables, §8 trust).

The world's callbacks run on zenoh's threads; what they may do is here, and none of it
touches the world. :class:`Request` is a query authenticated when the world runs with
credentials: the payload taken out of its ``agent.wire.trust`` envelope (length checked
before the copy, at most ``MAX_REQUEST_BYTES``), the signer known, and every reply sealed
by the world and bound to the request, so that a reply can neither be forged nor
replayed to another request. :func:`check` decodes and checks its payload cheaply where
it arrives (robot id, schema, the camera's yaw) and gives a :class:`CheckedRequest`, or
a ``ValueError`` saying why not; the world loop (:mod:`sim.server.server`) serves the checked
ones and answers the others with their reason.

- ``world/register``: ``RegisterRequest(want)``; no payload means any free id.
- ``world/robot/{id}/camera``: ``CameraRequest(yaw)``; without a payload the selector
  parameter ``yaw`` (radians, at most ``MAX_PARAM_CHARS`` characters) is read instead.
- ``world/robot/{id}/walk`` / ``turn``: ``WalkRequest`` / ``TurnRequest``.
- ``world/scenario``: ``ScenarioRequest`` (or no payload), asked by render workers.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol, TypeVar

from agent.wire import (
    MAX_REQUEST_BYTES,
    CameraRequest,
    Message,
    ProtocolError,
    RegisterRequest,
    ScenarioRequest,
    TurnRequest,
    WalkRequest,
    decode,
    encode,
    id_from_key,
    take_payload,
    trust,
)
from sim.camera import camera

#: Longest ``yaw`` selector parameter read (a float needs a few dozen characters).
MAX_PARAM_CHARS = 64

M = TypeVar("M", bound=Message)


class Payload(Protocol):
    """A query's payload (zenoh's ``ZBytes``): its length is known before the copy."""

    def __len__(self) -> int: ...

    def to_bytes(self) -> bytes: ...


class Parameters(Protocol):
    """A query's selector parameters (zenoh's ``Parameters``)."""

    def get(self, key: str, /) -> str | None: ...


class Query(Protocol):
    """What the world reads of a query: a zenoh ``Query``, or an in-process gateway's
    stand-in (``sim.naoqi_gateway.LocalQuery``)."""

    @property
    def key_expr(self) -> object: ...

    @property
    def parameters(self) -> Parameters: ...

    @property
    def payload(self) -> Payload | None: ...

    def reply(self, key_expr: str, payload: bytes, /) -> object: ...

    def drop(self) -> None: ...


class Request:
    """One query to the world, authenticated when the world runs with credentials.

    Secure: the payload is the :mod:`agent.wire.trust` envelope's, ``signer`` is who sealed
    it, and replies are sealed by the world and bound to the request (``nonce``), so a
    reply can neither be forged nor replayed to another request. Insecure: the query's
    own payload, no signer.
    """

    def __init__(
        self,
        q: Query,
        verifier: trust.Verifier | None,
        signer: trust.Signer | None,
    ) -> None:
        self.q = q
        self.key = str(q.key_expr)
        self.parameters = q.parameters
        self.signer = signer
        self.who: trust.Identity | None = None
        self.epoch = -1
        self.nonce = b""
        raw = q.payload
        data = take_payload(raw, MAX_REQUEST_BYTES) if raw is not None else None
        if verifier is not None:
            if data is None:
                raise trust.TrustError(f"unsigned request on {self.key}")
            opened = verifier.open(self.key, data)
            self.who, self.epoch, self.nonce = opened.who, opened.epoch, opened.nonce
            data = opened.payload
        self.payload: bytes | None = data

    def reply(self, msg: Message) -> None:
        data = encode(msg)
        if self.signer is not None:
            data = self.signer.seal(self.key, data, bind=self.nonce)
        self.q.reply(self.key, data)
        self.q.drop()

    def refuse(self) -> None:
        """No answer at all: a stranger learns nothing (zenoh ends its query)."""
        self.q.drop()


@dataclass
class CheckedRequest:
    """A request that passed the callback's checks: ``msg`` is its decoded payload
    (a ``RegisterRequest``, ``CameraRequest``, ``WalkRequest`` or ``TurnRequest``)."""

    kind: str
    query: Request
    robot_id: int  # -1 for register and scenario
    msg: Message


def payload_size(q: Query) -> int:
    """Length of a query's payload (0 if none or unreadable), without copying it."""
    try:
        return 0 if q.payload is None else len(q.payload)
    except Exception:
        return 0


def check(kind: str, q: Request, robot_ids: frozenset[int]) -> CheckedRequest:
    """The request ``q`` of ``kind`` decoded and checked, or a ``ValueError`` saying why not
    (``ProtocolError`` is one)."""
    payload = q.payload
    if kind == "register":
        if payload is None:
            return CheckedRequest(kind, q, -1, RegisterRequest())
        return CheckedRequest(kind, q, -1, decode_as(payload, RegisterRequest))
    if kind == "scenario":
        if payload is None:
            return CheckedRequest(kind, q, -1, ScenarioRequest())
        return CheckedRequest(kind, q, -1, decode_as(payload, ScenarioRequest))
    rid = id_from_key(q.key)
    if rid not in robot_ids:
        raise ValueError(f"unknown robot {rid}; robots are {sorted(robot_ids)}")
    if kind == "camera":
        if payload is not None:
            yaw = decode_as(payload, CameraRequest).yaw
        else:
            raw = q.parameters.get("yaw")
            if raw is not None and len(raw) > MAX_PARAM_CHARS:
                raise ValueError(f"yaw parameter of {len(raw)} characters is not a number")
            try:
                yaw = float(raw) if raw is not None else 0.0
            except ValueError:
                raise ValueError(f"yaw parameter {raw!r} is not a number") from None
        return CheckedRequest(kind, q, rid, CameraRequest(yaw=camera.check_yaw(yaw)))
    if kind == "walk":
        return CheckedRequest(kind, q, rid, decode_as(payload, WalkRequest))
    if kind == "turn":
        return CheckedRequest(kind, q, rid, decode_as(payload, TurnRequest))
    raise ValueError(f"unknown request kind {kind!r}")


def decode_as(payload: bytes | None, cls: type[M]) -> M:
    """``payload`` (already bounded by :class:`Request`) decoded as a ``cls``."""
    if payload is None:
        raise ProtocolError(f"missing {cls.TAG!r} payload")
    msg: M = decode(payload, expect=cls, max_bytes=MAX_REQUEST_BYTES)
    return msg
