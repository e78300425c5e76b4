"""The bounded msgpack codec (docs/design.md §3): encode, and decode untrusted bytes.

:func:`decode` validates the version, the type tag, every field's type, range and size,
and rejects anything that does not fit with a :class:`ProtocolError` whose text is the
reason. It never returns a half-valid message. Sizes are bounded *before* anything is
copied or unpacked (:func:`take_payload`, :func:`unpack_bounded`).
"""

from __future__ import annotations

import hashlib
from collections.abc import Sequence
from dataclasses import fields
from typing import Any, Protocol

import msgpack

from agent.wire.fields import (
    MAX_ARRAY_LEN,
    MAX_DEPTH,
    MAX_IMAGE_BYTES,
    MAX_MAP_LEN,
    MAX_MESSAGE_BYTES,
    MAX_OBJECTS,
    MAX_STR_BYTES,
    SCHEMA_VERSION,
    ProtocolError,
    _short,
)
from agent.wire.messages import _REGISTRY, M, Message, NeighborRecordMsg, RecordSetReply

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
    other exception leaves this function (the fuzz test in tests/wire/test_fuzz.py and
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


def canonical_digest(records: Sequence[NeighborRecordMsg]) -> str:
    """SHA-256 over the msgpack wire form of the records sorted by sender id.

    The wire form is exactly what was exchanged, so equal digests mean bit-identical
    planning inputs on every agent.
    """
    h = hashlib.sha256()
    for rec in sorted(records, key=lambda r: r.sender):
        data = encode(rec)
        h.update(len(data).to_bytes(4, "big"))
        h.update(data)
    return h.hexdigest()


def records_of(
    reply: RecordSetReply, digest: str, members: Sequence[int]
) -> tuple[NeighborRecordMsg, ...]:
    """The records of an agreed record set (``nao/{i}/records``) once checked: the digest
    asked for, records that decode, one per member, sorted by sender, hashing to
    ``digest`` (:func:`canonical_digest`): the asker trusts no server, only the digest the
    members agreed on. ``ValueError`` otherwise."""
    if reply.digest != digest:
        raise ValueError(f"record set {reply.digest[:12]} is not the one asked for")
    try:
        recs = tuple(decode(r, NeighborRecordMsg) for r in reply.records)
    except ProtocolError as exc:
        raise ValueError(f"record set from robot {reply.sender}: {exc}") from None
    senders = [r.sender for r in recs]
    if senders != sorted(set(senders)) or tuple(senders) != tuple(members):
        raise ValueError(f"record set covers {senders}, the agreement {list(members)}")
    got = canonical_digest(recs)
    if got != digest:
        raise ValueError(f"record set hashes to {got[:12]}, not {digest[:12]}")
    return recs
