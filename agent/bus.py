"""The agent's Zenoh session (DESIGN.md §3): the only module of ``agent/`` that imports zenoh.

Peer mode by default with multicast scouting (the one-machine demo); ``connect`` /
``listen`` endpoints, ``no_multicast_scouting`` and ``mode`` mirror zenoh's own example
flags for separate hosts, containers and routers. Every payload is an
``agent.protocol`` message; what fails to decode is dropped with a logged reason and
counted, never raised into the caller's loop.

Callbacks only hand samples to thread-safe queues (zenoh must not be called, and
nothing may block, inside a callback); the caller drains them with :meth:`Bus.drain`.
"""

from __future__ import annotations

import contextlib
import logging
import math
import queue
import threading
import time
from collections import Counter
from dataclasses import dataclass, field
from typing import Any, TypeVar

import zenoh

from agent.protocol import (
    ErrorReply,
    Message,
    NetworkSpec,
    ProtocolError,
    decode,
    encode,
    id_from_key,
)
from agent.trust import (
    MAX_SEALED_BYTES,
    Credentials,
    Identity,
    Signer,
    TrustError,
    Verifier,
)

log = logging.getLogger("agent.bus")

M = TypeVar("M", bound=Message)

#: A query that ends with no reply within this many seconds met no queryable (see NoRoute).
NO_ROUTE_WINDOW = 0.25


class BusError(RuntimeError):
    """A query that got no usable reply (timeout, error reply, undecodable reply)."""


class NoRoute(BusError):
    """A query that ended at once with no reply at all: no queryable was reachable yet.

    Zenoh finishes a ``get`` immediately when it knows no matching queryable, e.g. a
    fresh peer session that has not learnt the world's routes, or a route being rebuilt
    after a lossy link dropped. Nothing was executed, so the caller may retry.
    """


#: How the agent joins the bus: the shared :class:`agent.protocol.NetworkSpec`.
BusConfig = NetworkSpec


def zenoh_config(spec: NetworkSpec) -> zenoh.Config:
    """The zenoh config of ``spec``."""
    cfg = zenoh.Config()
    for key, value in spec.json5_items():
        cfg.insert_json5(key, value)
    return cfg


@dataclass(frozen=True)
class Event:
    """One thing that arrived: a decoded message on ``key``, or a liveliness change."""

    kind: str  # "msg" | "alive" | "gone"
    key: str
    msg: Any = None
    robot_id: int = -1
    #: Who signed ``msg`` and in which epoch (``agent.trust``); empty / -1 when insecure.
    signer: str = ""
    epoch: int = -1
    #: Bytes of the sample on the wire (the envelope included).
    size: int = 0


@dataclass
class Stats:
    published_bytes: Counter[str] = field(default_factory=Counter)
    published_count: Counter[str] = field(default_factory=Counter)
    query_bytes: int = 0
    rejected: int = 0
    #: Of ``rejected``: envelopes that failed authentication (forged, replayed, unsigned).
    untrusted: int = 0

    @property
    def total_published(self) -> int:
        return sum(self.published_bytes.values())


class Bus:
    """A zenoh session with message-level publish, subscribe, query and liveliness."""

    def __init__(self, config: BusConfig | None = None) -> None:
        self.config = config or BusConfig()
        self.signer: Signer | None = None
        self.verifier: Verifier | None = None
        if self.config.secure:
            creds = Credentials(self.config.credentials)
            self.signer = creds.signer(Identity.parse(self.config.identity))
            self.verifier = creds.verifier()
        self.session = zenoh.open(zenoh_config(self.config))
        self.events: queue.Queue[Event] = queue.Queue()
        self.stats = Stats()
        self._keep: list[Any] = []  # subscribers, tokens, publishers: keep them alive
        self._publishers: dict[str, Any] = {}
        self._lock = threading.Lock()
        self._closed = False
        self._last_warn = -math.inf
        self._suppressed = 0

    # ----------------------------------------------------------------- lifecycle

    def close(self) -> None:
        if self._closed:
            return
        self._closed = True
        for obj in reversed(self._keep):
            with contextlib.suppress(Exception):
                obj.undeclare()
        self._keep.clear()
        self._publishers.clear()
        with contextlib.suppress(Exception):
            self.session.close()

    def __enter__(self) -> Bus:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # ----------------------------------------------------------------- pub/sub

    def publish(self, key: str, msg: Message, category: str = "") -> int:
        """Publish ``msg`` on ``key`` (reliable, sealed when secure); returns its size in bytes."""
        data = encode(msg)
        if self.signer is not None:
            data = self.signer.seal(key, data)
        pub = self._publishers.get(key)
        if pub is None:
            pub = self.session.declare_publisher(key, reliability=zenoh.Reliability.RELIABLE)
            self._publishers[key] = pub
            self._keep.append(pub)
        pub.put(data)
        cat = category or msg.TAG
        with self._lock:
            self.stats.published_bytes[cat] += len(data)
            self.stats.published_count[cat] += 1
        return len(data)

    def subscribe(self, key_expr: str) -> None:
        """Decoded messages on ``key_expr`` arrive as ``Event("msg", key, msg)``."""

        def on_sample(sample: zenoh.Sample) -> None:
            if len(sample.payload) > MAX_SEALED_BYTES:  # bounded before it is copied
                with self._lock:
                    self.stats.rejected += 1
                log.warning(
                    "rejected message on %s: %d bytes", sample.key_expr, len(sample.payload)
                )
                return
            self._enqueue_sample(str(sample.key_expr), sample.payload.to_bytes())

        self._keep.append(self.session.declare_subscriber(key_expr, on_sample))

    def _enqueue_sample(self, key: str, data: bytes) -> None:
        try:
            signer, epoch, payload = self._open(key, data)
            msg = decode(payload)
        except ProtocolError as exc:
            with self._lock:
                self.stats.rejected += 1
                if isinstance(exc, TrustError):
                    self.stats.untrusted += 1
            self._warn(f"rejected message on {key}: {exc}")
            return
        self.events.put(Event("msg", key, msg, signer=signer, epoch=epoch, size=len(data)))

    def _open(self, key: str, data: bytes) -> tuple[str, int, bytes]:
        """(signer, epoch, payload) of a publication on ``key``; the signer must own ``key``.

        ``nao/{i}/...`` must be signed by ``robot-i``, ``world/...`` by the world.
        Insecure buses pass the payload through unchanged.
        """
        if self.verifier is None:
            return "", -1, data
        opened = self.verifier.open(key, data)
        owner = Identity("world") if key.startswith("world/") else Identity.robot(id_from_key(key))
        if opened.who != owner:
            raise TrustError(f"{opened.who.cn} signed a message on {key}, owned by {owner.cn}")
        return opened.who.cn, opened.epoch, opened.payload

    def _warn(self, text: str) -> None:
        """Log ``text`` (cut to 200 characters) at most once a second; a flood of
        rejected messages must not become a flood of log lines."""
        now = time.monotonic()
        with self._lock:
            if now - self._last_warn < 1.0:
                self._suppressed += 1
                return
            self._last_warn, n, self._suppressed = now, self._suppressed, 0
        more = f" ({n} more rejected since the last report)" if n else ""
        log.warning("%s%s", text[:200], more)

    # ----------------------------------------------------------------- liveliness

    def declare_alive(self, key: str) -> None:
        self._keep.append(self.session.liveliness().declare_token(key))

    def watch_alive(self, key_expr: str) -> None:
        """Liveliness of ``key_expr`` (with history) as ``alive`` / ``gone`` events."""

        def on_sample(sample: zenoh.Sample) -> None:
            key = str(sample.key_expr)
            try:
                rid = id_from_key(key)
            except ProtocolError as exc:
                log.warning("ignored liveliness token %s: %s", key, exc)
                return
            kind = "alive" if sample.kind == zenoh.SampleKind.PUT else "gone"
            self.events.put(Event(kind, key, robot_id=rid))

        self._keep.append(
            self.session.liveliness().declare_subscriber(key_expr, on_sample, history=True)
        )

    # ----------------------------------------------------------------- events

    def drain(self, timeout: float = 0.0) -> list[Event]:
        """Every event queued now; waits up to ``timeout`` s for the first one."""
        out: list[Event] = []
        try:
            out.append(
                self.events.get(timeout=timeout) if timeout > 0 else self.events.get_nowait()
            )
        except queue.Empty:
            return out
        while True:
            try:
                out.append(self.events.get_nowait())
            except queue.Empty:
                return out

    # ----------------------------------------------------------------- queries

    def query(self, key: str, msg: Message, expect: type[M], timeout: float = 10.0) -> M:
        """Send ``msg`` to the queryable on ``key`` and return its reply of type ``expect``.

        Raises :class:`BusError` with the reason on timeout, an ``ErrorReply`` or a reply
        that does not decode.
        """
        data = encode(msg)
        nonce = b""
        if self.signer is not None:
            data, nonce = self.signer.seal_request(key, data)
        with self._lock:
            self.stats.query_bytes += len(data)
        started = time.monotonic()
        # Every queryable that matches gets the query and every reply is kept (no
        # consolidation): a stranger's queryable answering first cannot hide the world's.
        replies = self.session.get(
            key,
            payload=data,
            timeout=timeout,
            target=zenoh.QueryTarget.ALL,
            consolidation=zenoh.ConsolidationMode.NONE,
        )
        errors: list[str] = []
        for reply in replies:
            if reply.ok is None:
                err = reply.err
                errors.append(
                    f"error reply: {bytes(err.payload.to_bytes())[:200]!r}"
                    if err
                    else "empty reply"
                )
                continue
            raw = reply.ok.payload.to_bytes()
            try:
                if self.verifier is not None:
                    opened = self.verifier.open(key, raw, bind=nonce, replay=False)
                    if opened.who != Identity("world"):
                        raise TrustError(f"reply signed by {opened.who.cn}, not the world")
                    raw = opened.payload
                out = decode(raw)
            except ProtocolError as exc:
                with self._lock:
                    self.stats.rejected += 1
                    if isinstance(exc, TrustError):
                        self.stats.untrusted += 1
                errors.append(f"rejected reply: {str(exc)[:200]}")
                continue
            if isinstance(out, ErrorReply):
                raise BusError(f"{key}: {out.reason}")
            if not isinstance(out, expect):
                errors.append(f"unexpected reply {type(out).__name__}")
                continue
            return out
        if errors:
            raise BusError(f"{key}: {'; '.join(errors)}")
        elapsed = time.monotonic() - started
        if elapsed < min(NO_ROUTE_WINDOW, timeout / 2):
            raise NoRoute(f"{key}: no reply: no queryable reachable (ended after {elapsed:.3f} s)")
        raise BusError(f"{key}: no reply within {timeout:g} s")
