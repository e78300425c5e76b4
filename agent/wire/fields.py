"""Limits and field validators of the wire contract (docs/design.md §3).

Every message field is checked by one of these validators when it is decoded: type,
range and size. A value that does not fit raises :class:`ProtocolError` (a
``ValueError``) whose text is the reason. Units: metres, radians, seconds of *sim*
time; robot ids are ints in [0, MAX_ROBOT_ID].
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

from agent.core import nao

SCHEMA_VERSION = 1
MAX_ROBOT_ID = 65535
#: Neighbours one record may carry (fleets of 100 NAOs). A robot sees at most the others
#: within sight (``nao.SIGHT_MAX`` = 3 m); generated fleets of 100-200 put <= 50 there,
#: and a fleet of up to 128 robots (``tools.demo``'s limit) fits even if one saw them all.
MAX_NEIGHBOURS = 128
MAX_OBSTACLES = 32  # obstacles one robot may report in its record
#: Stances one record may carry: the still spans of its owner's body during its search
#: (two sweeps and up to two turns: 2-3; the bound leaves room for a re-searched round).
MAX_STANCES = 8
MAX_MEMBERS = 1024
#: Child slots of a shape a reshape command carries (its leader's slot is implicit): a
#: fixed tree for every member of the largest fleet (~30 kB, within a publication)
MAX_SHAPE_SLOTS = MAX_MEMBERS - 1
MAX_TEXT = 512
MAX_IMAGE_BYTES = 8 * 1024 * 1024
#: How a camera reply may carry its picture (:mod:`agent.wire.picture`), the default first.
PICTURE_ENCODINGS = ("bgr8", "png")
MAX_MESSAGE_BYTES = MAX_IMAGE_BYTES + 4096
#: Publications (records, digests, statuses, clock, truth for 1024 robots: ~40 KB) are
#: small; only camera replies carry an image. Subscribers reject bigger payloads unread.
MAX_PUBLICATION_BYTES = 64 * 1024
#: World requests (register, camera, walk, turn) are a few dozen bytes.
MAX_REQUEST_BYTES = 1024
#: Camera frames for viewers (``nao/{id}/camera``): a JPEG thumbnail of at most
#: this many bytes (160x120 at quality 70 is 3-8 kB), at most this size in pixels, with at
#: most this many detections.
MAX_THUMBNAIL_BYTES = 32 * 1024
MAX_THUMBNAIL_WIDTH = 320
MAX_THUMBNAIL_HEIGHT = 240
MAX_CAMERA_DETECTIONS = 16
#: A camera frame's publication: the thumbnail, its fields and detections (16 x ~45 B) and
#: the signed envelope (~100 B). Viewers subscribe with this bound, checked before the copy.
MAX_CAMERA_PUBLICATION_BYTES = MAX_THUMBNAIL_BYTES + 4096
#: msgpack limits of :func:`unpack_bounded` (see its docstring for why these values).
MAX_OBJECTS = 8192
MAX_DEPTH = 8
MAX_MAP_LEN = 32
MAX_ARRAY_LEN = MAX_MEMBERS
MAX_STR_BYTES = 4 * MAX_TEXT  # MAX_TEXT characters of UTF-8
MAX_COORD = 1000.0  # metres: no NAO fleet spans a kilometre
#: metres: a robot's steps after it arrived (its alignment; far more than it walks)
MAX_SHIFT = 10.0
MAX_STEP = 50.0  # metres: the longest single walk command accepted
MAX_SIDE_STEP = 0.3  # metres: the longest single sidestep accepted (NAOqi moveTo(0, y, 0))
#: metres: the longest planned path a status reports walking along (finer
#: waits): a path with two via points across a fleet of MAX_COORD spans < 9 km
MAX_WALKED = 10.0 * MAX_COORD
HEAD_YAW_LIMIT = nao.HEAD_YAW_LIMIT
DIGEST_HEX_LEN = 64


def _short(v: Any, limit: int = 40) -> str:
    """``repr(v)`` cut to ``limit`` characters, for error texts about untrusted values."""
    if isinstance(v, str | bytes) and len(v) > limit:
        v = v[:limit]  # never repr a megabyte to cut it afterwards
    elif isinstance(v, list | tuple | dict) and len(v) > 8:
        return f"<{type(v).__name__} of {len(v)} items>"
    text = repr(v)
    return text if len(text) <= limit else text[: limit - 3] + "..."


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
