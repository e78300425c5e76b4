"""The agent's durable journal: what a restarted agent resumes from.

The papers assume robots never crash. An agent started with ``--state-dir DIR`` writes
its state to ``DIR/robot-{id}.journal`` at every phase change and before every motion;
restarted after a crash with the same ``--state-dir`` it resumes from it
(:mod:`agent.recovery.resume`). What is kept (:class:`JournalState`):

* the phase, the heading and position beliefs (fixed frame, eq. 2), the compass gain;
* its own neighbour record (4.1.2) once localised;
* the agreed record-set digest and members, and the plan digest, once agreed;
* the move's leg index, and the command in flight (``turn``/``walk``, its value and its
  motion request id: written *before* the body is asked, so after a crash it is known
  what the robot may have been doing, and the command can be asked again with the same
  id, which the world answers with its first result);
* which fleet run it belongs to (a finished run's journal must not derail the next): ``run_epoch``,
  when this robot's first process of the run started (ms since the Unix epoch, kept across
  resumptions), and ``written_ms``, when it was written; with the record's round before agreement,
  and the agreed digest and members after, they name the run (the rule that decides whether it
  is still going is in :mod:`agent.recovery.runs`);
* ``final``: ``done``, ``failed`` or ``stopped`` once the run is over for this robot
  (the last record written); a final journal is never resumed, only archived;
* separately, once per search, the fixed-frame **reference view**: the head-yaw-0 image
  taken at θ = 0 that defines the fixed frame, against which the visual compass
  (§3.2.1) re-measures the heading after a crash (``DIR/robot-{id}.reference``).

Durability: each file is written whole to a temporary file, ``fsync``'d, renamed over
the old one (atomic on POSIX) and the directory ``fsync``'d, so a crash leaves the old
or the new version, never a mixture. Format: ``MAGIC``, a 4-byte length, the SHA-256 of
the body, the body (msgpack). Reading trusts nothing: sizes are bounded
(:data:`MAX_STATE_BYTES`, :data:`MAX_REFERENCE_BYTES`), the checksum, the version and
every field are checked, and anything that does not fit raises :class:`JournalError`
(a ``ValueError``) with the reason; the caller reports it and starts afresh.

A journal that is not resumed (final, of a run that ended, or unusable) is archived
(:meth:`Journal.archive`): renamed with a timestamp suffix, at most
:data:`ARCHIVES_KEPT` kept per file, so the next run starts from an empty slot and the
history stays at hand.
"""

from __future__ import annotations

import contextlib
import hashlib
import math
import os
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass, fields, replace
from pathlib import Path
from typing import Any

import msgpack
import numpy as np

from agent.phases.reporting import Phase
from agent.wire import (
    MAX_MEMBERS,
    PHASES,
    NeighborRecordMsg,
    ProtocolError,
    decode,
    encode,
    unpack_bounded,
)

JOURNAL_VERSION = 2
MAGIC_STATE = b"NAOJRNL1"
MAGIC_REFERENCE = b"NAOREFV1"
#: The state is a few hundred bytes (a record: at most MAX_NEIGHBOURS (128) neighbours,
#: under 8 KB; the agreed members: at most MAX_MEMBERS ids).
MAX_STATE_BYTES = 64 * 1024
#: A reference view: a BGR uint8 image, at most 1280 x 960.
MAX_REFERENCE_BYTES = 1280 * 960 * 3 + 1024
MAX_IMAGE_SIDE = 1280
#: Commands a journal may hold in flight.
COMMANDS = ("", "turn", "walk", "side")
#: How a run ended for this robot ("": not yet).
FINALS = ("", "done", "failed", "stopped")
#: Journaled phases that end the run for this robot even without a final record (a
#: crash while lingering in ``done``, or after publishing ``failed``).
FINAL_PHASES = (Phase.DONE, Phase.FAILED)
#: Archived journals (and reference views) kept per robot, newest first.
ARCHIVES_KEPT = 3
#: Largest motion request id (the wire's bound, 2^53 - 1).
MAX_REQUEST_ID = 2**53 - 1
_HEAD = len(MAGIC_STATE) + 4 + 32


class JournalError(ValueError):
    """A journal that cannot be used (missing parts, corrupt, foreign); the text says why."""


@dataclass(frozen=True)
class JournalState:
    """One agent's state at one instant (see the module docstring)."""

    robot_id: int
    #: the phase (given as a :class:`Phase` or its string; kept as the :class:`Phase`)
    phase: Phase = Phase.START
    heading: float = math.pi / 2
    position: tuple[float, float] = (0.0, 0.0)
    compass_gain: float = 1.0
    record: NeighborRecordMsg | None = None
    agreed_digest: str = ""
    agreed_members: tuple[int, ...] = ()
    plan_digest: str = ""
    leg: int = 0
    command: str = ""
    command_value: float = 0.0
    #: The command's motion request id (0: none, or a body without ids).
    request_id: int = 0
    #: ms since the Unix epoch when this robot's first process of the run started.
    run_epoch: int = 0
    #: ms since the Unix epoch when this state was written (set by :meth:`Journal.save`).
    written_ms: int = 0
    #: How the run ended for this robot (:data:`FINALS`; "": it has not).
    final: str = ""
    #: Writes so far (the newest version wins; for logs and tests).
    seq: int = 0

    def __post_init__(self) -> None:
        _check_state(self)
        object.__setattr__(self, "phase", Phase(self.phase))

    @property
    def is_final(self) -> bool:
        """Whether the run is over for this robot: a final record, or a journaled
        ``done`` or ``failed`` (never resumed)."""
        return bool(self.final) or self.phase in FINAL_PHASES


def _finite(name: str, v: Any, lo: float = -math.inf, hi: float = math.inf) -> float:
    if isinstance(v, bool) or not isinstance(v, int | float):
        raise JournalError(f"{name}: expected a number, got {type(v).__name__}")
    f = float(v)
    if not (math.isfinite(f) and lo <= f <= hi):
        raise JournalError(f"{name}: {f} outside [{lo}, {hi}]")
    return f


def _int(name: str, v: Any, lo: int, hi: int) -> int:
    if isinstance(v, bool) or not isinstance(v, int) or not lo <= v <= hi:
        raise JournalError(f"{name}: expected an int in [{lo}, {hi}], got {str(v)[:24]}")
    return v


def _hex(name: str, v: Any) -> str:
    if not isinstance(v, str) or (
        v and (len(v) != 64 or any(c not in "0123456789abcdef" for c in v))
    ):
        raise JournalError(f"{name}: expected empty or 64 lowercase hex digits")
    return v


def _check_state(s: JournalState) -> None:
    _int("robot_id", s.robot_id, 0, 65535)
    if s.phase not in PHASES:
        raise JournalError(f"phase {str(s.phase)[:24]!r} is not a phase")
    _finite("heading", s.heading, -10.0, 10.0)
    if not isinstance(s.position, tuple) or len(s.position) != 2:
        raise JournalError("position: expected (x, y)")
    for v in s.position:
        _finite("position", v, -1000.0, 1000.0)
    _finite("compass_gain", s.compass_gain, 0.5, 2.0)
    if s.record is not None and (
        not isinstance(s.record, NeighborRecordMsg) or s.record.sender != s.robot_id
    ):
        raise JournalError("record: not this robot's neighbour record")
    _hex("agreed_digest", s.agreed_digest)
    _hex("plan_digest", s.plan_digest)
    if not isinstance(s.agreed_members, tuple) or len(s.agreed_members) > MAX_MEMBERS:
        raise JournalError("agreed_members: expected a tuple of robot ids")
    for m in s.agreed_members:
        _int("agreed member", m, 0, 65535)
    if bool(s.agreed_digest) != bool(s.agreed_members):
        raise JournalError("agreed_digest and agreed_members go together")
    _int("leg", s.leg, 0, 1000)
    if s.command not in COMMANDS:
        raise JournalError(f"command {str(s.command)[:24]!r} is not one of {COMMANDS}")
    _finite("command_value", s.command_value, -100.0, 100.0)
    _int("request_id", s.request_id, 0, MAX_REQUEST_ID)
    if s.request_id and not s.command:
        raise JournalError("request_id without a command in flight")
    _int("run_epoch", s.run_epoch, 0, 2**62)
    _int("written_ms", s.written_ms, 0, 2**62)
    if s.final not in FINALS:
        raise JournalError(f"final {str(s.final)[:24]!r} is not one of {FINALS}")
    _int("seq", s.seq, 0, 2**62)


# --------------------------------------------------------------------------- framing


def _frame(magic: bytes, body: bytes) -> bytes:
    return magic + len(body).to_bytes(4, "big") + hashlib.sha256(body).digest() + body


def _unframe(magic: bytes, data: bytes, limit: int, what: str) -> bytes:
    if len(data) < _HEAD:
        raise JournalError(f"{what}: truncated ({len(data)} bytes)")
    if data[: len(magic)] != magic:
        raise JournalError(f"{what}: not a journal of this version (bad magic)")
    n = int.from_bytes(data[len(magic) : len(magic) + 4], "big")
    if n > limit:
        raise JournalError(f"{what}: body of {n} bytes, at most {limit}")
    body = data[_HEAD:]
    if len(body) != n:
        raise JournalError(f"{what}: body of {len(body)} bytes, header says {n}")
    if hashlib.sha256(body).digest() != data[len(magic) + 4 : _HEAD]:
        raise JournalError(f"{what}: checksum mismatch (corrupt)")
    return body


def _read(path: Path, limit: int, what: str) -> bytes | None:
    """The bytes of ``path`` (None when absent), refusing more than ``limit`` + header."""
    try:
        with path.open("rb") as f:
            data = f.read(limit + _HEAD + 1)
    except FileNotFoundError:
        return None
    except OSError as exc:
        raise JournalError(f"{what}: cannot read {path}: {exc}") from None
    if len(data) > limit + _HEAD:
        raise JournalError(f"{what}: {path} is larger than {limit + _HEAD} bytes")
    return data


def write_atomic(path: Path, data: bytes) -> None:
    """Write ``data`` to ``path`` durably: temp file, fsync, rename, fsync of the folder."""
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise
    dfd = os.open(path.parent, os.O_RDONLY)
    try:
        os.fsync(dfd)
    finally:
        os.close(dfd)


# --------------------------------------------------------------------------- codec


def encode_state(s: JournalState) -> bytes:
    body = {
        "v": JOURNAL_VERSION,
        "robot_id": s.robot_id,
        "phase": s.phase.value,
        "heading": s.heading,
        "position": list(s.position),
        "compass_gain": s.compass_gain,
        "record": encode(s.record) if s.record is not None else None,
        "agreed_digest": s.agreed_digest,
        "agreed_members": list(s.agreed_members),
        "plan_digest": s.plan_digest,
        "leg": s.leg,
        "command": s.command,
        "command_value": s.command_value,
        "request_id": s.request_id,
        "run_epoch": s.run_epoch,
        "written_ms": s.written_ms,
        "final": s.final,
        "seq": s.seq,
    }
    data = msgpack.packb(body, use_bin_type=True)
    assert isinstance(data, bytes)
    if len(data) > MAX_STATE_BYTES:
        raise JournalError(f"state of {len(data)} bytes exceeds {MAX_STATE_BYTES}")
    return _frame(MAGIC_STATE, data)


def decode_state(data: bytes) -> JournalState:
    """The state in ``data``; :class:`JournalError` for anything that does not fit."""
    body = _unframe(MAGIC_STATE, data, MAX_STATE_BYTES, "journal")
    try:
        obj = unpack_bounded(body, MAX_STATE_BYTES)
    except ProtocolError as exc:
        raise JournalError(f"journal: {exc}") from None
    if not isinstance(obj, dict):
        raise JournalError("journal: not a map")
    if obj.get("v") != JOURNAL_VERSION or type(obj.get("v")) is not int:
        raise JournalError(f"journal: version {str(obj.get('v'))[:12]}, expected {JOURNAL_VERSION}")
    expected = {"v"} | {f.name for f in fields(JournalState)}
    if set(obj) != expected:
        raise JournalError(f"journal: fields {sorted(map(str, set(obj) ^ expected))[:4]} differ")
    raw = obj["record"]
    record = None
    if raw is not None:
        if not isinstance(raw, bytes):
            raise JournalError("journal: record is not bytes")
        try:
            record = decode(raw, NeighborRecordMsg)
        except ProtocolError as exc:
            raise JournalError(f"journal: record: {exc}") from None
    pos, members = obj["position"], obj["agreed_members"]
    if not isinstance(pos, list) or not isinstance(members, list):
        raise JournalError("journal: position and agreed_members must be lists")
    try:
        return JournalState(
            robot_id=obj["robot_id"],
            phase=obj["phase"],
            heading=obj["heading"],
            position=tuple(pos),  # checked in __post_init__
            compass_gain=obj["compass_gain"],
            record=record,
            agreed_digest=obj["agreed_digest"],
            agreed_members=tuple(members),
            plan_digest=obj["plan_digest"],
            leg=obj["leg"],
            command=obj["command"],
            command_value=obj["command_value"],
            request_id=obj["request_id"],
            run_epoch=obj["run_epoch"],
            written_ms=obj["written_ms"],
            final=obj["final"],
            seq=obj["seq"],
        )
    except TypeError as exc:  # an unhashable phase, command or final
        raise JournalError(f"journal: {exc}") from None


def encode_reference(image: np.ndarray) -> bytes:
    img = np.ascontiguousarray(image)
    if img.dtype != np.uint8 or img.ndim != 3 or img.shape[2] != 3:
        raise JournalError(f"reference view must be (H, W, 3) uint8, got {img.shape} {img.dtype}")
    h, w = int(img.shape[0]), int(img.shape[1])
    if not (1 <= h <= MAX_IMAGE_SIDE and 1 <= w <= MAX_IMAGE_SIDE):
        raise JournalError(f"reference view {w}x{h} larger than {MAX_IMAGE_SIDE} px a side")
    return _frame(MAGIC_REFERENCE, h.to_bytes(2, "big") + w.to_bytes(2, "big") + img.tobytes())


def decode_reference(data: bytes) -> np.ndarray:
    body = _unframe(MAGIC_REFERENCE, data, MAX_REFERENCE_BYTES, "reference view")
    if len(body) < 4:
        raise JournalError("reference view: no size")
    h, w = int.from_bytes(body[:2], "big"), int.from_bytes(body[2:4], "big")
    if not (1 <= h <= MAX_IMAGE_SIDE and 1 <= w <= MAX_IMAGE_SIDE) or len(body) != 4 + h * w * 3:
        raise JournalError(f"reference view: {len(body) - 4} pixel bytes for {w}x{h}")
    return np.frombuffer(body[4:], dtype=np.uint8).reshape(h, w, 3).copy()


# --------------------------------------------------------------------------- the journal


def _stamp(t: float) -> str:
    """A sortable UTC timestamp with milliseconds: ``20250101T120000.123Z``."""
    ms = int(t * 1000)
    return time.strftime("%Y%m%dT%H%M%S", time.gmtime(ms // 1000)) + f".{ms % 1000:03d}Z"


class Journal:
    """The journal files of robot ``robot_id`` under ``folder`` (created if needed).

    ``wall``: the wall clock (s since the Unix epoch) for ``written_ms``, the process's
    start (:attr:`opened_ms`) and the archives' timestamps."""

    def __init__(
        self, folder: Path | str, robot_id: int, wall: Callable[[], float] = time.time
    ) -> None:
        self.folder = Path(folder)
        self.robot_id = _int("robot_id", robot_id, 0, 65535)
        self.folder.mkdir(parents=True, exist_ok=True)
        self.state_path = self.folder / f"robot-{robot_id}.journal"
        self.reference_path = self.folder / f"robot-{robot_id}.reference"
        self.seq = 0
        self.wall = wall
        #: When this process opened the journal (ms): a fresh run's ``run_epoch``.
        self.opened_ms = self.now_ms()

    def now_ms(self) -> int:
        return int(self.wall() * 1000)

    def save(self, state: JournalState) -> JournalState:
        """Write ``state`` durably (its ``seq`` set to the next write's, ``written_ms``
        to now); returns it."""
        self.seq += 1
        st = replace(state, seq=self.seq, written_ms=self.now_ms())
        write_atomic(self.state_path, encode_state(st))
        return st

    def load(self) -> JournalState | None:
        """The journaled state, None when there is none; :class:`JournalError` when it
        is unusable (corrupt, another robot's)."""
        data = _read(self.state_path, MAX_STATE_BYTES, "journal")
        if data is None:
            return None
        st = decode_state(data)
        if st.robot_id != self.robot_id:
            raise JournalError(f"journal of robot {st.robot_id}, this is robot {self.robot_id}")
        self.seq = max(self.seq, st.seq)
        return st

    def save_reference(self, image: np.ndarray) -> None:
        write_atomic(self.reference_path, encode_reference(image))

    def load_reference(self) -> np.ndarray | None:
        data = _read(self.reference_path, MAX_REFERENCE_BYTES, "reference view")
        return None if data is None else decode_reference(data)

    def clear(self) -> None:
        """Forget everything (a run that ended: the next start is a new run)."""
        for p in (self.state_path, self.reference_path):
            p.unlink(missing_ok=True)

    def archive(self) -> list[Path]:
        """Move the journal and the reference view aside: each renamed with the suffix
        ``.{UTC timestamp}``, the oldest archives beyond :data:`ARCHIVES_KEPT` per file
        deleted. Returns the new paths (none when there was nothing to archive)."""
        stamp = _stamp(self.wall())
        out = []
        for p in (self.state_path, self.reference_path):
            if not p.exists():
                continue
            dest = p.with_name(f"{p.name}.{stamp}")
            k = 1
            while dest.exists():  # two archives within one millisecond
                dest = p.with_name(f"{p.name}.{stamp}-{k}")
                k += 1
            os.replace(p, dest)
            out.append(dest)
            for old in self.archives(p)[ARCHIVES_KEPT:]:
                with contextlib.suppress(OSError):
                    old.unlink()
        self.seq = 0
        return out

    def archives(self, path: Path | None = None) -> list[Path]:
        """The archives of ``path`` (default: the journal), newest first."""
        p = self.state_path if path is None else path
        return sorted(self.folder.glob(f"{p.name}.*"), reverse=True)
