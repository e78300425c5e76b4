"""The agent's Zenoh session (docs/design.md §3): the only module of ``agent/`` that imports zenoh.

Peer mode by default with multicast scouting (the one-machine demo); ``connect`` /
``listen`` endpoints, ``no_multicast_scouting`` and ``mode`` mirror zenoh's own example
flags for separate hosts, containers and routers. Every payload is an
``agent.wire`` message; what fails to decode is dropped with a logged reason and
counted, never raised into the caller's loop.

Callbacks only hand samples to thread-safe queues (zenoh must not be called, and
nothing may block, inside a callback); the caller drains them with :meth:`Bus.drain`.
The one exception is :meth:`Bus.serve` (the agreed record set by digest, for an agent restarted
after a crash): it replies from within the queryable's callback, as zenoh's own queryable examples
do, with an answer computed from an immutable snapshot (no lock, no I/O but the reply).

Hardening against hostile input: a payload's size is checked before it is copied out of zenoh
(``MAX_PUBLICATION_BYTES`` for subscriptions, ``MAX_MESSAGE_BYTES`` for query replies);
every callback survives every exception, counts it in ``stats.rejected`` and logs a
reason of at most 200 characters (rate limited); the event queue is bounded in events
and payload bytes (``EVENT_CAPS``, ``EVENT_MAX_BYTES``: a full lane drops its oldest
events, counted in ``stats.dropped``); a
reply that is not what was asked for is a :class:`BusError`, never another exception.
"""

from __future__ import annotations

import contextlib
import logging
import math
import queue
import threading
import time
from collections import Counter
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from typing import Any, TypeVar

import zenoh

from agent.net.replies import REPLY_GRACE, ReplyInbox
from agent.wire import (
    BUSY,
    KEY_RESHAPE,
    MAX_MESSAGE_BYTES,
    MAX_PUBLICATION_BYTES,
    MAX_REQUEST_BYTES,
    ErrorReply,
    Guard,
    Inbox,
    Message,
    NetworkSpec,
    ProtocolError,
    decode,
    encode,
    id_from_key,
    reason,
    take_payload,
)
from agent.wire.trust import (
    MAX_SEALED_BYTES,
    Credentials,
    Identity,
    Signer,
    TrustError,
    Verifier,
)

log = logging.getLogger("agent.net.bus")

M = TypeVar("M", bound=Message)

#: A query that ends with no reply within this many seconds met no queryable (see NoRoute).
NO_ROUTE_WINDOW = 0.25
#: Capacity of the event queue's lanes. Messages: a few seconds of a large fleet's
#: records, digests and statuses (re-published, so a dropped one comes again);
#: liveliness changes have their own lane so that a message flood cannot push out a
#: membership change, and so do neighbour records: a record is published once and
#: repaired only on a hint, and at 100 NAOs a flood of statuses pushed 23 of the 100
#: records out of the run observer's lane (at 100 NAOs the evaluator could not
#: recompute the plan, and judged a formation it had no plan for).
EVENT_CAPS = {"alive": 1024, "record": 1024, "msg": 4096}
#: ... and the payload bytes the message lanes may hold (a decoded message takes up to
#: ~12x its payload in Python objects: 4 MiB of payloads stay within ~50 MB; records
#: are ~1 kB each, MAX_RECORD_BYTES at most).
EVENT_MAX_BYTES = {"record": 2 * 1024 * 1024, "msg": 4 * 1024 * 1024}
#: Keys of the record lane: ``agent.wire.key_record`` ends so.
RECORD_SUFFIX = "/record"
#: A query's reasons for failing: at most this many are kept (the rest are counted).
MAX_REPLY_ERRORS = 4


#: What :meth:`Bus.query` records of zenoh's own error reply when a get's timeout runs out.
ZENOH_TIMEOUT = "error reply: b'Timeout' (zenoh: the query's timeout ran out)"


class BusError(RuntimeError):
    """A query that got no usable reply (timeout, error reply, undecodable reply)."""


class NoRoute(BusError):
    """A query that ended at once with no reply at all: no queryable was reachable yet.

    Zenoh finishes a ``get`` immediately when it knows no matching queryable, e.g. a
    fresh peer session that has not learnt the world's routes, or a route being rebuilt
    after a lossy link dropped. Nothing was executed, so the caller may retry.
    """


class Busy(BusError):
    """The queryable answered that it is overloaded (an ``ErrorReply`` whose reason starts
    with :data:`agent.wire.BUSY`) and executed nothing: the caller may ask again later."""


class QueryTimeout(BusError):
    """A query whose reply did not come within its timeout (the request, or its reply,
    may have been lost, or the queryable is slow). A motion may have been executed:
    repeat it only with the same request id (``agent.body.zenoh_world.ZenohBody``)."""


class SessionUnavailable(BusError):
    """The zenoh session could not be opened (no router reached within zenoh's connect
    window, or a TLS handshake that a lossy link did not let through)."""


_T = TypeVar("_T")


def open_retrying(
    open_fn: Callable[[], _T],
    give_up_s: float,
    clock: Callable[[], float] = time.monotonic,
    sleep: Callable[[float], None] = time.sleep,
    wait: tuple[float, float] = (1.0, 8.0),
) -> _T:
    """``open_fn()``, called again after :class:`SessionUnavailable` until ``give_up_s``
    seconds have passed (then the last error is raised).

    On a lossy radio, at 50 % loss per direction a TLS session may not open within zenoh's own
    connect window (``connect/timeout_ms`` of ``agent.wire.LOSSY_LINK_SETTINGS``); a
    lossy start should only delay the agent. Waits between attempts double from
    ``wait[0]`` to ``wait[1]`` s and never pass the deadline.
    """
    if not (math.isfinite(give_up_s) and give_up_s >= 0.0):
        raise ValueError(f"give_up_s must be finite and >= 0, got {give_up_s}")
    if not 0.0 < wait[0] <= wait[1]:
        raise ValueError(f"need 0 < wait[0] <= wait[1], got {wait}")
    deadline = clock() + give_up_s
    pause = wait[0]
    while True:
        try:
            return open_fn()
        except SessionUnavailable as exc:
            left = deadline - clock()
            if left <= 0.0:
                raise
            log.warning("%s; trying again (%.0f s left)", exc, left)
            sleep(min(pause, left))
            pause = min(wait[1], 2.0 * pause)


#: How the agent joins the bus: the shared :class:`agent.wire.NetworkSpec`.
BusConfig = NetworkSpec


def zenoh_config(spec: NetworkSpec) -> zenoh.Config:
    """The zenoh config of ``spec``."""
    cfg = zenoh.Config()
    for key, value in spec.json5_items():
        cfg.insert_json5(key, value)
    return cfg


def key_owner(key: str) -> Identity:
    """Who may sign on ``key``: the world on ``world/...``, robot i on ``nao/i/...``, the
    operator on :data:`~agent.wire.keys.KEY_RESHAPE` (never a robot: a robot's key cannot
    command the fleet)."""
    if key == KEY_RESHAPE:
        return Identity("operator")
    return Identity("world") if key.startswith("world/") else Identity.robot(id_from_key(key))


def reply_signers(key: str) -> tuple[Identity, ...]:
    """Who may sign a reply on ``key``: its owner, and on a camera key
    (``world/robot/{i}/camera``) also the render workers (the world's cameras drawn by other
    processes, for large fleets)."""
    owner = key_owner(key)
    if owner == Identity("world") and key.startswith("world/robot/") and key.endswith("/camera"):
        return owner, Identity("render")
    return (owner,)


@dataclass(frozen=True)
class Event:
    """One thing that arrived: a decoded message on ``key``, or a liveliness change."""

    kind: str  # "msg" | "alive" | "gone"
    key: str
    msg: Any = None
    robot_id: int = -1
    #: Who signed ``msg`` and in which epoch (``agent.wire.trust``); empty / -1 when insecure.
    signer: str = ""
    epoch: int = -1
    #: Bytes of the sample on the wire (the envelope included).
    size: int = 0
    #: ``time.monotonic()`` when the sample reached this process (0.0: not a sample),
    #: before its checks and before it waited in the queue (a loaded reader's own lag).
    t_rx: float = 0.0


@dataclass
class Stats:
    published_bytes: Counter[str] = field(default_factory=Counter)
    published_count: Counter[str] = field(default_factory=Counter)
    query_bytes: int = 0
    #: payloads, tokens and replies refused (undecodable, oversized, unexpected)
    rejected: int = 0
    #: Of ``rejected``: envelopes that failed authentication (forged, replayed, unsigned).
    untrusted: int = 0
    #: events dropped unread because the queue was full (oldest first)
    dropped: int = 0

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
        self.events: Inbox[Event] = Inbox(EVENT_CAPS, max_weight=EVENT_MAX_BYTES)
        self.stats = Stats()
        self._keep: list[Any] = []  # subscribers, tokens, publishers: keep them alive
        self._publishers: dict[str, Any] = {}
        self._lock = threading.Lock()
        self._closed = False
        self.guard = Guard(log.warning, on_reject=self._count_rejected)
        self._drop_log = Guard(log.warning, burst=3, per_second=0.2)  # drops: stats.dropped
        try:
            self.session = zenoh.open(zenoh_config(self.config))
        except zenoh.ZError as exc:  # no router reached (not up yet, a lossy handshake)
            raise SessionUnavailable(f"cannot open the zenoh session: {reason(exc)}") from None

    def _count_rejected(self) -> None:
        with self._lock:
            self.stats.rejected += 1

    def _put(self, ev: Event, size: int = 0) -> None:
        lane = (
            "alive" if ev.kind != "msg" else "record" if ev.key.endswith(RECORD_SUFFIX) else "msg"
        )
        dropped = self.events.put(lane, ev, size)
        if dropped:
            with self._lock:
                self.stats.dropped += dropped
            self._drop_log.reject(f"{lane} queue full", f"{dropped} oldest event(s) dropped")

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
            self.session.close()  # type: ignore[no-untyped-call]

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

    def subscribe(
        self, key_expr: str, max_bytes: int = MAX_PUBLICATION_BYTES, remote_only: bool = False
    ) -> None:
        """Decoded messages on ``key_expr`` arrive as ``Event("msg", key, msg)``.

        Payloads over ``max_bytes`` are rejected without being copied. ``remote_only``:
        what this session publishes itself is not delivered back (an agent's own records,
        digests and statuses, which it would only open, check the signature of and drop:
        one message in N of an N-robot fleet's, ~1 ms of CPU each on an idle agent,
        ``python -m tools.bench idle``)."""

        def on_sample(sample: zenoh.Sample) -> None:
            self._on_sample(sample, max_bytes)

        origin = zenoh.Locality.REMOTE if remote_only else zenoh.Locality.ANY
        sub = self.session.declare_subscriber(key_expr, on_sample, allowed_origin=origin)
        self._keep.append(sub)

    def _on_sample(self, sample: Any, max_bytes: int = MAX_PUBLICATION_BYTES) -> None:
        """The subscriber callback: never raises; what does not decode is counted."""
        key = "?"
        t_rx = time.monotonic()
        try:
            key = str(sample.key_expr)
            self._accept(key, take_payload(sample.payload, max_bytes), max_bytes, t_rx)
        except Exception as exc:  # ProtocolError, and anything unforeseen: count, go on
            self._reject(f"message on {key}", exc)

    def _enqueue_sample(self, key: str, data: bytes) -> None:
        """Open and decode ``data`` as if it had arrived on ``key`` (tests, tools)."""
        try:
            self._accept(key, data, MAX_PUBLICATION_BYTES, time.monotonic())
        except Exception as exc:
            self._reject(f"message on {key}", exc)

    def _accept(self, key: str, data: bytes, max_bytes: int, t_rx: float = 0.0) -> None:
        signer, epoch, payload = self._open(key, data)
        msg = decode(payload, max_bytes=max_bytes)
        ev = Event("msg", key, msg, signer=signer, epoch=epoch, size=len(data), t_rx=t_rx)
        self._put(ev, len(data))

    def _reject(self, what: str, exc: BaseException) -> None:
        """Count (``rejected``; ``untrusted`` for authentication failures) and log."""
        if isinstance(exc, TrustError):
            with self._lock:
                self.stats.untrusted += 1
        self.guard.reject(what, exc)

    def _open(self, key: str, data: bytes) -> tuple[str, int, bytes]:
        """(signer, epoch, payload) of a publication on ``key``; the signer must own ``key``.

        ``nao/{i}/...`` must be signed by ``robot-i``, ``world/...`` by the world.
        Insecure buses pass the payload through unchanged.
        """
        if self.verifier is None:
            return "", -1, data
        opened = self.verifier.open(key, data)
        owner = key_owner(key)
        if opened.who != owner:
            raise TrustError(f"{opened.who.cn} signed a message on {key}, owned by {owner.cn}")
        return opened.who.cn, opened.epoch, opened.payload

    # ----------------------------------------------------------------- liveliness

    def declare_alive(self, key: str) -> None:
        self._keep.append(self.session.liveliness().declare_token(key))

    def watch_alive(self, key_expr: str) -> None:
        """Liveliness of ``key_expr`` (with history) as ``alive`` / ``gone`` events."""

        def on_sample(sample: zenoh.Sample) -> None:
            self._on_alive(sample)

        self._keep.append(
            self.session.liveliness().declare_subscriber(key_expr, on_sample, history=True)
        )

    def _on_alive(self, sample: Any) -> None:
        """The liveliness callback: never raises; a token naming no robot is counted."""
        key = "?"
        try:
            key = str(sample.key_expr)
            rid = id_from_key(key)
            kind = "alive" if sample.kind == zenoh.SampleKind.PUT else "gone"
            self._put(Event(kind, key, robot_id=rid))
        except Exception as exc:
            self.guard.reject(f"liveliness token {key}", exc)

    # ----------------------------------------------------------------- events

    def drain(self, timeout: float = 0.0) -> list[Event]:
        """Every event queued now; waits up to ``timeout`` s for the first one."""
        out: list[Event] = []
        try:
            _, ev = self.events.get(timeout=timeout) if timeout > 0 else self.events.get_nowait()
        except queue.Empty:
            return out
        out.append(ev)
        while True:
            try:
                out.append(self.events.get_nowait()[1])
            except queue.Empty:
                return out

    # ----------------------------------------------------------------- serving

    def serve(self, key: str, answer: Callable[[Message], Message | None]) -> None:
        """Answer queries on ``key`` (one of this robot's own ``nao/{id}/...`` keys).

        ``answer(request)`` returns the reply, or None to stay silent (zenoh then ends
        the query for the asker without a reply from here). It runs in zenoh's callback
        thread: it must be quick and must not use the bus. Requests are bounded
        (``MAX_REQUEST_BYTES``), opened (secure: any fleet member may ask, the reply is
        sealed on ``key`` and bound to the request) and decoded; whatever fails is
        counted in ``stats.rejected`` and gets no reply.
        """

        def on_query(q: zenoh.Query) -> None:
            self._on_query(q, key, answer)

        self._keep.append(self.session.declare_queryable(key, on_query))

    def _on_query(self, q: Any, key: str, answer: Callable[[Message], Message | None]) -> None:
        """The queryable callback: never raises."""
        try:
            raw = q.payload
            if raw is None:
                raise ProtocolError("query without a payload")
            data = take_payload(raw, MAX_REQUEST_BYTES + 1024)
            nonce = b""
            if self.verifier is not None:
                opened = self.verifier.open(str(q.key_expr), data)
                data, nonce = opened.payload, opened.nonce
            rep = answer(decode(data, max_bytes=MAX_REQUEST_BYTES))
            if rep is not None:
                out = encode(rep)
                if self.signer is not None:
                    out = self.signer.seal(key, out, bind=nonce)
                q.reply(key, out)
        except Exception as exc:
            self._reject(f"query on {key}", exc)
        finally:
            with contextlib.suppress(Exception):
                q.drop()

    # ----------------------------------------------------------------- queries

    def query(
        self,
        key: str,
        msg: Message,
        expect: type[M],
        timeout: float = 10.0,
        accept: Callable[[M], str] | None = None,
        best: bool = False,
    ) -> M:
        """Send ``msg`` to the queryable on ``key`` and return its reply of type ``expect``.

        Raises :class:`BusError` with the reason on timeout, an ``ErrorReply`` or a reply
        that does not decode. ``accept(reply)``: a reason to skip the reply ("" takes
        it), for queries several peers answer (the first acceptable reply wins).
        Replies on ``world/...`` must be sealed by the world (a camera's also by a render
        worker), on ``nao/{i}/...`` by robot i, on the key the reply names.

        ``best``: zenoh sends the query to one complete queryable, the nearest, if there
        is one, else to every matching one (``QueryTarget.BEST_MATCHING``): a camera
        query goes to one render worker, not to all (so that more workers draw more pictures).
        Default: to every matching queryable.
        """
        data = encode(msg)
        nonce = b""
        if self.signer is not None:
            data, nonce = self.signer.seal_request(key, data)
        with self._lock:
            self.stats.query_bytes += len(data)
        started = time.monotonic()
        try:
            # Every queryable that matches gets the query and every reply is kept (no
            # consolidation): a stranger's queryable answering first cannot hide the world's.
            # With ``best``, one complete queryable (in a routed fleet the router's access
            # control lets only the world and the render workers declare them on world/**).
            target = zenoh.QueryTarget.BEST_MATCHING if best else zenoh.QueryTarget.ALL
            inbox = ReplyInbox()  # bounded, read with a deadline (agent/net/replies.py)
            self.session.get(
                key,
                zenoh.handlers.Callback(inbox.put, inbox.end),
                payload=data,
                timeout=timeout,
                target=target,
                consolidation=zenoh.ConsolidationMode.NONE,
            )
        except Exception as exc:  # zenoh refused the query (bad key, closed session)
            raise BusError(f"{key}: query failed: {reason(exc)}") from None
        errors: list[str] = []
        replies = inbox.stream(started + timeout + REPLY_GRACE)
        out = self._first_reply(key, replies, expect, errors, nonce, accept)
        if out is not None:
            return out
        if errors and all(e == ZENOH_TIMEOUT for e in errors):
            # the get's own timeout ran out: zenoh ends it with an error reply "Timeout"
            # (at 100 NAOs a camera query that waited past its attempt was
            # taken for a world's error, and the robot stopped instead of asking again);
            # zenoh may end it sooner (at 100 NAOs, while the fleet started: 0.4 s of 100)
            waited = time.monotonic() - started
            raise QueryTimeout(f"{key}: no reply within {timeout:g} s (zenoh ended it "
                               f"after {waited:.1f} s)")  # fmt: skip
        if errors:
            shown = errors[:MAX_REPLY_ERRORS]
            if len(errors) > MAX_REPLY_ERRORS:
                shown.append(f"and {len(errors) - MAX_REPLY_ERRORS} more")
            raise BusError(f"{key}: {'; '.join(shown)}")
        elapsed = time.monotonic() - started
        if elapsed < min(NO_ROUTE_WINDOW, timeout / 2):
            raise NoRoute(f"{key}: no reply: no queryable reachable (ended after {elapsed:.3f} s)")
        raise QueryTimeout(f"{key}: no reply within {timeout:g} s")

    def _first_reply(
        self,
        key: str,
        replies: Iterable[Any],
        expect: type[M],
        errors: list[str],
        nonce: bytes = b"",
        accept: Callable[[M], str] | None = None,
    ) -> M | None:
        """The first reply of type ``expect``; the reasons the others were refused go to
        ``errors``. An ``ErrorReply`` raises :class:`BusError`. Never raises anything else:
        every unusable reply is counted in ``stats.rejected``."""
        try:
            for reply in replies:
                try:
                    out = self._reply_message(key, reply, nonce)
                except BusError as exc:  # an error reply (zenoh's "Timeout" among them)
                    errors.append(str(exc))
                    continue
                except Exception as exc:  # ProtocolError or anything unforeseen
                    errors.append(reason(exc))
                    self._reject(f"reply on {key}", exc)
                    continue
                if isinstance(out, ErrorReply):
                    kind = Busy if out.reason.startswith(BUSY) else BusError
                    raise kind(f"{key}: {out.reason}")
                if not isinstance(out, expect):
                    why = f"unexpected reply {type(out).__name__}, expected {expect.__name__}"
                    errors.append(why)
                    self.guard.reject(f"reply on {key}", why)
                    continue
                why = accept(out) if accept is not None else ""
                if why:
                    errors.append(why)
                    self.guard.reject(f"reply on {key}", why)
                    continue
                return out
        except BusError:
            raise
        except Exception as exc:  # the reply stream itself failed
            errors.append(f"reply stream failed: {reason(exc)}")
            self.guard.reject(f"replies on {key}", exc)
        return None

    def _reply_message(self, key: str, reply: Any, nonce: bytes) -> Any:
        """The decoded message of one reply, or an exception saying why not.

        Secure: the reply must be bound to this request and sealed by the world
        (``world/...``), or by the robot owning the key the reply names (``nao/i/...``)."""
        ok = reply.ok
        if ok is None:
            err = reply.err
            if err is None:
                raise BusError("empty reply")
            text = take_payload(err.payload, 4096)[:200]
            if text == b"Timeout":
                raise BusError(ZENOH_TIMEOUT)
            raise BusError(f"error reply: {text!r}")
        raw = take_payload(ok.payload, MAX_SEALED_BYTES if self.verifier else MAX_MESSAGE_BYTES)
        if self.verifier is not None:
            rkey = key if key.startswith("world/") else str(ok.key_expr)
            signers = reply_signers(rkey)
            opened = self.verifier.open(rkey, raw, bind=nonce, replay=False)
            if opened.who not in signers:
                names = " or ".join(s.cn for s in signers)
                raise TrustError(f"reply signed by {opened.who.cn}, not {names}")
            raw = opened.payload
        try:
            return decode(raw)
        except ProtocolError as exc:
            raise ProtocolError(f"undecodable reply: {exc}") from None
