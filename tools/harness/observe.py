"""What a run shows on the bus: the MCAP recorder, the observer of statuses, records,
digests and ground truth, and the live status lines (DESIGN.md §1 phases).

An evaluator's view: it reads ground truth (``world/truth/**``); agents never do.
"""

from __future__ import annotations

import sys
import threading
import time
from collections import defaultdict
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, Any

from agent.net.bus import Bus
from agent.wire import (
    KEY_ALIVE_ALL,
    KEY_DIGEST_ALL,
    KEY_RECORD_ALL,
    KEY_STATUS_ALL,
    KEY_WORLD_TRUTH_ALL,
    ContactMsg,
    DigestMsg,
    Guard,
    NeighborRecordMsg,
    StatusMsg,
    TruthPosesMsg,
    encode,
    id_from_key,
)
from tools.harness.procs import FleetNet

# ===================================================================== recording


class Recorder:
    """MCAP file of everything the demo saw: one channel per topic, msgpack wire payloads.

    Why MCAP: a single indexed, self-describing file that the ``mcap`` package (already
    a dependency) reads back without a viewer, and Foxglove opens directly.
    """

    def __init__(self, path: Path) -> None:
        from mcap.writer import Writer

        self._f = path.open("wb")
        self._w = Writer(self._f)
        self._w.start(profile="", library="nao-formation tools.demo")
        self._schema = self._w.register_schema(
            name="agent.wire", encoding="", data=b"msgpack map, see agent/wire/"
        )
        self._channels: dict[str, int] = {}
        self._lock = threading.Lock()
        self.count = 0

    def write(self, topic: str, data: bytes, t_ns: int | None = None) -> None:
        t = time.time_ns() if t_ns is None else t_ns
        with self._lock:
            ch = self._channels.get(topic)
            if ch is None:
                ch = self._w.register_channel(topic, "msgpack", self._schema)
                self._channels[topic] = ch
            self._w.add_message(ch, log_time=t, data=data, publish_time=t, sequence=self.count)
            self.count += 1

    def close(self) -> None:
        with self._lock:
            self._w.finish()
            self._f.close()


# ===================================================================== observation


@dataclass
class AgentView:
    phase: str = "-"
    progress: float = 0.0
    detail: str = ""
    error: str = ""
    plan_digest: str = ""
    wave: int = -1
    t_sim: float = 0.0
    march_sample: int | None = None  # truth samples seen at its first ``march`` status
    phase_wall: dict[str, float] = field(default_factory=dict)
    phase_sim: dict[str, float] = field(default_factory=dict)
    bytes_by_kind: dict[str, int] = field(default_factory=lambda: defaultdict(int))
    count_by_kind: dict[str, int] = field(default_factory=lambda: defaultdict(int))
    exit_code: int | None = None
    #: the robot's own check of its pair after hold (parent id, r_d, r_φ); None: none
    check: tuple[int, float, float] | None = None


@dataclass
class Observer:
    t0: float
    agents: dict[int, AgentView] = field(default_factory=dict)
    truth: list[tuple[float, dict[int, tuple[float, float, float]]]] = field(default_factory=list)
    contacts: list[tuple[float, int, int]] = field(default_factory=list)
    truth_contacts: int = 0
    records: dict[int, NeighborRecordMsg] = field(default_factory=dict)
    digests: dict[int, DigestMsg] = field(default_factory=dict)
    #: events whose handling failed (counted, reason logged, the observer goes on)
    rejected: int = 0
    guard: Guard = field(
        default_factory=lambda: Guard(lambda line: print(f"observer: {line}", file=sys.stderr))
    )

    def take_event(self, ev: Any, rec: Recorder | None) -> None:
        """:meth:`take` for one bus event; never raises (a failure is counted in
        ``rejected`` and logged with a reason cut to 200 characters, rate limited)."""
        if ev.kind != "msg":
            return
        try:
            self.take(ev.key, ev.msg, rec, ev.size)
        except Exception as exc:
            self.rejected += 1
            self.guard.reject(f"message on {ev.key}", exc)

    def take(self, key: str, msg: Any, rec: Recorder | None, size: int = 0) -> None:
        """Record one message; ``size``: its bytes on the wire (0: its encoding's)."""
        if rec is not None:
            rec.write(key, encode(msg))
        now = time.monotonic() - self.t0
        if isinstance(msg, TruthPosesMsg):
            self.truth.append((msg.t_sim, {p[0]: (p[1], p[2], p[3]) for p in msg.poses}))
            self.truth_contacts = max(self.truth_contacts, msg.contacts)
            return
        if isinstance(msg, ContactMsg):
            self.contacts.append((msg.t_sim, msg.a, msg.b))
            return
        try:
            sender = id_from_key(key)
        except ValueError:
            return
        view = self.agents.setdefault(sender, AgentView())
        kind = key.rsplit("/", 1)[-1]
        view.bytes_by_kind[kind] += size or len(encode(msg))
        view.count_by_kind[kind] += 1
        if isinstance(msg, StatusMsg):
            if msg.phase not in view.phase_wall:
                view.phase_wall[msg.phase] = now
                view.phase_sim[msg.phase] = msg.t_sim
            view.phase, view.progress, view.detail = msg.phase, msg.progress, msg.detail
            if msg.phase == "march" and view.march_sample is None:
                view.march_sample = len(self.truth)
            view.error, view.plan_digest, view.wave, view.t_sim = (
                msg.error, msg.plan_digest, msg.wave, msg.t_sim,
            )  # fmt: skip
            if msg.check_parent >= 0:
                view.check = (msg.check_parent, msg.r_d, msg.r_phi)
        elif isinstance(msg, NeighborRecordMsg):
            old = self.records.get(msg.sender)
            if old is None or old.round <= msg.round:  # the newest (re-)search round
                self.records[msg.sender] = msg
        elif isinstance(msg, DigestMsg):
            self.digests[msg.sender] = msg


class LiveView:
    """One line per agent, repainted in place on a terminal, else printed on changes."""

    def __init__(self, stream: IO[str], ids: list[int]) -> None:
        self.stream = stream
        self.ids = ids
        self.tty = stream.isatty()
        self.drawn = 0
        self.last: dict[int, str] = {}
        self.last_draw = 0.0

    def line(self, rid: int, v: AgentView | None, elapsed: float) -> str:
        if v is None:
            return f"  robot {rid:2d} | {'(waiting)':10s}"
        n = 20
        fill = round(v.progress * n)
        bar = "#" * fill + "." * (n - fill)
        wave = f"w{v.wave}" if v.wave >= 0 else "  "
        text = (v.error or v.detail)[:60]
        return f"  robot {rid:2d} | {v.phase:9s} [{bar}] {wave:3s} t_sim {v.t_sim:6.1f}s | {text}"

    def update(self, obs: Observer, elapsed: float, force: bool = False) -> None:
        if self.tty:
            if not force and elapsed - self.last_draw < 0.25:
                return
            self.last_draw = elapsed
            if self.drawn:
                self.stream.write(f"\x1b[{self.drawn}A")
            head = f"nao-formation demo  wall {elapsed:6.1f}s"
            rows = [head] + [self.line(i, obs.agents.get(i), elapsed) for i in self.ids]
            for r in rows:
                self.stream.write("\x1b[2K" + r + "\n")
            self.drawn = len(rows)
            self.stream.flush()
            return
        for i in self.ids:
            v = obs.agents.get(i)
            key = "" if v is None else f"{v.phase}:{v.error}"
            if key and self.last.get(i) != key:
                self.last[i] = key
                self.stream.write(f"[{elapsed:6.1f}s]{self.line(i, v, elapsed)}\n")
                self.stream.flush()


def observer_bus(net: FleetNet) -> Bus:
    """The observer's bus: statuses, records, digests, ground truth and membership."""
    bus = Bus(net.observer())
    watch(bus)
    return bus


def watch(bus: Bus) -> None:
    """Subscribe ``bus`` to what an observer sees: statuses, records, digests, ground
    truth and membership."""
    for key in (KEY_STATUS_ALL, KEY_RECORD_ALL, KEY_DIGEST_ALL, KEY_WORLD_TRUTH_ALL):
        bus.subscribe(key)
    bus.watch_alive(KEY_ALIVE_ALL)


def observe_for(bus: Bus, obs: Observer, rec: Recorder | None, seconds: float) -> None:
    """Hand what arrives on ``bus`` to ``obs`` for ``seconds`` (polls, bounded)."""
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        for ev in bus.drain(0.1):
            obs.take_event(ev, rec)
