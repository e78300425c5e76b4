"""The live view of a run: the Foxglove WebSocket server that the scene's channels are
also sent to while the recorder writes them (docs/design.md §10 "Seeing the fleet",
"Live"; docs/view.md).

One scene builder (:class:`tools.harness.view.scene.Scene`), several sinks: the MCAP recorder
(:class:`tools.harness.observe.Recorder`) and :class:`LiveServer`, each a :class:`Sink`.
:class:`Fanout` is the scene's ``Emit`` over them; a sink that fails is counted and
logged, never costs another sink a message.

:class:`LiveServer` is foxglove-sdk's WebSocket server (Foxglove WebSocket protocol,
subprotocol ``foxglove.sdk.v1``) in a context of its own, one JSON channel per topic with
the topic's JSON Schema. Foxglove, Lichtblick and the page of :mod:`tools.harness.view.webpage`
connect to it. The protocol has no latched topics: a viewer that subscribes late would
never see the obstacles or the plan, which are sent once. So the latest message of each
topic in :data:`LATCHED` is sent again every :data:`RELATCH_S` seconds of wall time.

``--live [HOST:PORT]`` (:func:`add_live_arguments`, :func:`live_sinks`) is the one flag
of every tool that observes a run in its own process; one server per address and
process (:func:`serve`): the runs of an evaluation matrix share it, and a viewer stays
connected from one run to the next.
"""

from __future__ import annotations

import argparse
import json
import sys
import threading
import time
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, Protocol

from agent.wire import Guard
from tools.harness.view.foxglove import JSON

if TYPE_CHECKING:
    from foxglove.websocket import ServerListener

DEFAULT_LIVE = "127.0.0.1:8765"
#: topics whose latest message a late viewer needs (sent once or rarely)
LATCHED = ("/scene/obstacles", "/scene/plan")
#: how often (wall s) the latched topics are sent again
RELATCH_S = 1.0


class Sink(Protocol):
    """Takes one JSON ``message`` of ``schema`` on ``topic`` at world time ``t_ns``
    (the signature of :class:`tools.harness.view.scene.Emit`)."""

    def emit(self, topic: str, schema: JSON, message: JSON, t_ns: int) -> None: ...


class Fanout:
    """The scene's ``Emit`` over a primary sink and extra ones. The primary (the MCAP
    recorder) gets the message first and its failure is the caller's, as without extra
    sinks; an extra sink that raises is counted in ``rejected`` (its reason logged, rate
    limited), and the next ones still get the message."""

    def __init__(
        self,
        primary: Callable[[str, JSON, JSON, int], None],
        extra: Sequence[Sink],
        log: Callable[[str], None] | None = None,
    ) -> None:
        self.primary = primary
        self.extra = list(extra)
        self.rejected = 0
        self.guard = Guard(log or (lambda line: print(f"view: {line}", file=sys.stderr)))

    def __call__(self, topic: str, schema: JSON, message: JSON, t_ns: int) -> None:
        self.primary(topic, schema, message, t_ns)
        for sink in self.extra:
            try:
                sink.emit(topic, schema, message, t_ns)
            except Exception as exc:  # a viewer never costs the recording a message
                self.rejected += 1
                self.guard.reject(f"{type(sink).__name__} on {topic}", exc)


def parse_address(text: str, default_port: int = 8765) -> tuple[str, int]:
    """``HOST:PORT``, ``HOST`` or ``:PORT`` → (host, port); port 0: any free port."""
    host, sep, port = text.rpartition(":")
    if not sep:
        host, port = text, str(default_port)
    host = host.strip("[]") or "127.0.0.1"
    if not port.isdigit() or not 0 <= int(port) <= 65535:
        raise ValueError(f"expected HOST:PORT, got {text!r}")
    return host, int(port)


class LiveServer:
    """foxglove-sdk's WebSocket server, a :class:`Sink` (module docstring).

    ``port`` 0 picks a free port; :attr:`port` is the one bound. Every message is sent
    with its world time as the log time; ``sent`` counts them, ``wall_by_topic`` keeps
    the wall clock (``time.time()``) of each topic's latest message (the latency
    measurement of docs/view.md compares it with the page's clock).
    """

    def __init__(self, host: str = "127.0.0.1", port: int = 8765, name: str = "nao-formation"):
        import foxglove

        self._foxglove = foxglove
        self._ctx = foxglove.Context()
        self._subscribed: dict[str, int] = {}
        self._sub_lock = threading.Lock()
        self._server = foxglove.start_server(
            name=name, host=host, port=port, context=self._ctx, server_listener=_listener(self)
        )
        self.host = host
        self.port = int(self._server.port)
        self._channels: dict[str, foxglove.Channel] = {}
        self._latched: dict[str, tuple[bytes, int]] = {}
        self._relatched = time.monotonic()
        self._lock = threading.Lock()
        self.sent = 0
        self.wall_by_topic: dict[str, float] = {}

    @property
    def url(self) -> str:
        return f"ws://{self.host}:{self.port}"

    def emit(self, topic: str, schema: JSON, message: JSON, t_ns: int) -> None:
        data = json.dumps(message, separators=(",", ":"), allow_nan=False).encode()
        with self._lock:
            ch = self._channels.get(topic)
            if ch is None:
                ch = self._foxglove.Channel(topic, schema=schema, context=self._ctx)
                self._channels[topic] = ch
            ch.log(data, log_time=t_ns)
            self.sent += 1
            self.wall_by_topic[topic] = time.time()
            if topic in LATCHED:
                self._latched[topic] = (data, t_ns)
            now = time.monotonic()
            if now - self._relatched >= RELATCH_S:
                self._relatched = now
                for t in sorted(self._latched):
                    old, old_ns = self._latched[t]
                    self._channels[t].log(old, log_time=old_ns)

    def count(self, topic: str, change: int) -> None:
        """A viewer (un)subscribed ``topic`` (the server's listener, on its threads)."""
        with self._sub_lock:
            self._subscribed[topic] = max(0, self._subscribed.get(topic, 0) + change)

    def subscribed(self) -> dict[str, int]:
        """Subscriptions by topic (viewers connected now)."""
        with self._sub_lock:
            return {t: n for t, n in sorted(self._subscribed.items()) if n}

    def topics(self) -> list[str]:
        with self._lock:
            return sorted(self._channels)

    def close(self) -> None:
        with self._lock:
            for ch in self._channels.values():
                ch.close()
            self._channels.clear()
            self._latched.clear()
        self._server.stop()


def _listener(server: LiveServer) -> ServerListener:
    """foxglove-sdk's listener that counts the viewers' subscriptions on ``server``."""
    from foxglove.websocket import ChannelView, Client, ServerListener

    class Subscriptions(ServerListener):
        def on_subscribe(self, client: Client, channel: ChannelView) -> None:
            server.count(channel.topic, +1)

        def on_unsubscribe(self, client: Client, channel: ChannelView) -> None:
            server.count(channel.topic, -1)

    return Subscriptions()


_SERVERS: dict[tuple[str, int], LiveServer] = {}


def serve(address: str) -> LiveServer:
    """The process's live server on ``address`` (``HOST:PORT``), started on first use."""
    host, port = parse_address(address)
    server = _SERVERS.get((host, port))
    if server is None:
        server = LiveServer(host, port)
        _SERVERS[(host, port)] = server
        if port == 0:
            _SERVERS[(host, server.port)] = server
        print(f"live: Foxglove WebSocket server on {server.url}", file=sys.stderr, flush=True)
    return server


def add_live_arguments(p: argparse.ArgumentParser) -> None:
    """``--live [HOST:PORT]``: serve the run's scene live (default 127.0.0.1:8765)."""
    p.add_argument(
        "--live",
        nargs="?",
        const=DEFAULT_LIVE,
        default=None,
        metavar="HOST:PORT",
        help=(
            "serve the run live over the Foxglove WebSocket protocol (Foxglove, Lichtblick, "
            f"the page of tools.view --web); default {DEFAULT_LIVE}"
        ),
    )


def check_live_argument(p: argparse.ArgumentParser, live: str | None) -> None:
    if live is not None:
        try:
            parse_address(live)
        except ValueError as exc:
            p.error(f"--live: {exc}")


def live_sinks(live: str | None) -> list[Sink]:
    """The sinks of ``--live``: the process's server on that address, or none."""
    return [] if live is None else [serve(live)]
