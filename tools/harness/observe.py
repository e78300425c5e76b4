"""What a run shows on the bus: the MCAP recorder, the observer of statuses, records,
digests and ground truth, and the live status lines (docs/design.md §1 phases).

An evaluator's view: it reads ground truth (``world/truth/**``); agents never do.
"""

from __future__ import annotations

import json
import math
import sys
import threading
import time
from collections import defaultdict
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, Any

from agent.core.formation.params import PlanParams
from agent.net.bus import Bus, BusError
from agent.wire import (
    KEY_ALIVE_ALL,
    KEY_CAMERA_FEED_ALL,
    KEY_DIGEST_ALL,
    KEY_RECORD_ALL,
    KEY_RESHAPE,
    KEY_STATUS_ALL,
    KEY_WORLD_TRUTH_ALL,
    MAX_CAMERA_PUBLICATION_BYTES,
    CameraMsg,
    ContactMsg,
    DigestMsg,
    Guard,
    NeighborRecordMsg,
    RecordSetReply,
    RecordSetRequest,
    StatusMsg,
    TruthPosesMsg,
    canonical_digest,
    encode,
    id_from_key,
    key_records,
    records_of,
)
from tools.harness.procs import FleetNet
from tools.harness.view.foxglove import JSON
from tools.harness.view.live import Fanout, Sink
from tools.harness.view.scene import Scene

# ===================================================================== recording


class Recorder:
    """MCAP file of everything the demo saw, and Foxglove's view of it.

    Two kinds of channel (docs/agent.md "Recordings"): one per bus key with the exact
    msgpack wire payloads (``tools.replay`` reads them), and the JSON channels of
    Foxglove's well-known schemas that :class:`tools.harness.view.scene.Scene` derives from the
    same messages (``/scene``, ``/scene/obstacles``, ``/scene/plan``, ``/tf``, ``/log``,
    ``/robots/{id}/status``, ``/nao/{id}/camera`` and its ``/annotations``). Every message's log time is the world time (``t_sim``) of
    the latest ground-truth sample (0 before the first); its publish time is the wall
    clock (the replay's timeline).

    Why MCAP: a single indexed, self-describing file that the ``mcap`` package (already
    a dependency) reads back without a viewer, and that Foxglove and Lichtblick open and
    draw. A failure of the Foxglove view never costs a raw message: it is counted in
    ``scene_rejected`` and its reason logged (rate limited).

    ``params``: the fleet's planning parameters (default: the demo's), ``obstacles``: the
    world's (x, y, radius), if known; else the scenario file that the harness writes beside
    the recording (``scenario.json``) during this run is read. ``sinks``: where the
    Foxglove channels go besides the file (``--live``: :class:`tools.harness.view.live.LiveServer`);
    one scene builder for all (:class:`tools.harness.view.live.Fanout`).
    """

    def __init__(
        self,
        path: Path,
        params: PlanParams | None = None,
        obstacles: Sequence[tuple[float, float, float]] | None = None,
        sinks: Sequence[Sink] = (),
    ) -> None:
        from mcap.writer import Writer

        started = time.time_ns()
        self._f = path.open("wb")
        self._w = Writer(self._f)
        self._w.start(profile="", library="nao-formation tools.demo")
        self._schema = self._w.register_schema(
            name="agent.wire", encoding="", data=b"msgpack map, see agent/wire/"
        )
        self._schemas: dict[str, int] = {}
        self._channels: dict[str, int] = {}
        self._lock = threading.RLock()
        self.count = 0
        #: world time (ns) of the latest truth sample: every message's log time
        self.world_ns = 0
        #: the scene's channels go to this file first, then to ``sinks`` (the live view)
        self.fanout = Fanout(self._emit, sinks)
        self.scene = Scene(self.fanout, params, obstacles, path.parent / "scenario.json", started)
        self.scene_rejected = 0
        self.guard = Guard(lambda line: print(f"recorder: {line}", file=sys.stderr))

    def record(self, key: str, msg: Any) -> None:
        """One observed message: its wire payload on channel ``key``, then the Foxglove view."""
        with self._lock:
            if isinstance(msg, TruthPosesMsg):
                self.world_ns = max(self.world_ns, round(msg.t_sim * 1e9))
            self.write(key, encode(msg))
            try:
                self.scene.take(key, msg, self.world_ns)
            except Exception as exc:  # the viewer's channels must never cost the recording
                self.scene_rejected += 1
                self.guard.reject(f"Foxglove view of {key}", exc)

    def write(self, topic: str, data: bytes, t_ns: int | None = None) -> None:
        """``data`` on the msgpack channel ``topic``; log time ``t_ns`` (default: the world
        time), publish time the wall clock."""
        with self._lock:
            ch = self._channels.get(topic)
            if ch is None:
                ch = self._w.register_channel(topic, "msgpack", self._schema)
                self._channels[topic] = ch
            self._add(ch, data, self.world_ns if t_ns is None else t_ns)

    def _add(self, channel: int, data: bytes, t_ns: int) -> None:
        self._w.add_message(
            channel, log_time=t_ns, data=data, publish_time=time.time_ns(), sequence=self.count
        )
        self.count += 1

    def _emit(self, topic: str, schema: JSON, message: JSON, t_ns: int) -> None:
        """One JSON message of a Foxglove (or ``nao.``) schema on ``topic``."""
        data = json.dumps(message, separators=(",", ":"), allow_nan=False).encode()
        with self._lock:
            ch = self._channels.get(topic)
            if ch is None:
                name = str(schema["title"])
                sid = self._schemas.get(name)
                if sid is None:
                    sid = self._w.register_schema(
                        name=name, encoding="jsonschema", data=json.dumps(schema).encode()
                    )
                    self._schemas[name] = sid
                ch = self._w.register_channel(topic, "json", sid)
                self._channels[topic] = ch
            self._add(ch, data, t_ns)

    def close(self) -> None:
        with self._lock:
            try:
                self.scene.finish()
            except Exception as exc:  # as in record(): the file is still finished
                self.scene_rejected += 1
                self.guard.reject("Foxglove view of the plan", exc)
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
    #: camera frames for viewers (``--publish-camera``): kept apart from the
    #: bytes above, which are the fleet's own traffic; observer wall times of the first
    #: and the last frame (s)
    camera_frames: int = 0
    camera_bytes: int = 0
    camera_wall: tuple[float, float] | None = None


@dataclass
class Observer:
    t0: float
    agents: dict[int, AgentView] = field(default_factory=dict)
    truth: list[tuple[float, dict[int, tuple[float, float, float]]]] = field(default_factory=list)
    contacts: list[tuple[float, int, int]] = field(default_factory=list)
    truth_contacts: int = 0
    records: dict[int, NeighborRecordMsg] = field(default_factory=dict)
    #: per robot the truth sample at which its newest (re-)search round's record arrived:
    #: where it stood when it published the start its plan is built from
    record_sample: dict[int, int] = field(default_factory=dict)
    digests: dict[int, DigestMsg] = field(default_factory=dict)
    #: per agreed digest, how often its record set was asked of the members and when
    #: last (``time.monotonic()``; :func:`fetch_agreed_records`)
    fetches: dict[str, tuple[int, float]] = field(default_factory=dict)
    #: the agreed digest the records held were last found to hash to ("": not checked
    #: since a record arrived; :func:`fetch_agreed_records`)
    held_digest: str = ""
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
            self.take(ev.key, ev.msg, rec, ev.size, ev.t_rx)
        except Exception as exc:
            self.rejected += 1
            self.guard.reject(f"message on {ev.key}", exc)

    def take(
        self, key: str, msg: Any, rec: Recorder | None, size: int = 0, t_rx: float = 0.0
    ) -> None:
        """Record one message; ``size``: its bytes on the wire (0: its encoding's);
        ``t_rx``: ``time.monotonic()`` when it reached this process (0.0: now). Phase times
        are arrival times: a loaded observer's queue and recording do not delay them."""
        now = (t_rx if t_rx > 0.0 else time.monotonic()) - self.t0
        if rec is not None:
            rec.record(key, msg)
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
        if isinstance(msg, CameraMsg):
            view.camera_frames += 1
            view.camera_bytes += size or len(encode(msg))
            view.camera_wall = (
                (now, now) if view.camera_wall is None else (view.camera_wall[0], now)
            )
            return
        kind = key.rsplit("/", 1)[-1]
        view.bytes_by_kind[kind] += size or len(encode(msg))
        view.count_by_kind[kind] += 1
        if isinstance(msg, StatusMsg):
            # the first formation's phases (a reshape's plan, wait, move and hold come
            # after its done: docs/formation.md "Reshaping" times them per transition)
            if msg.phase not in view.phase_wall and "done" not in view.phase_wall:
                view.phase_wall[msg.phase] = now
                view.phase_sim[msg.phase] = msg.t_sim
            view.phase, view.progress, view.detail = msg.phase, msg.progress, msg.detail
            if msg.phase == "march" and view.march_sample is None:
                view.march_sample = len(self.truth)
            # the plan a robot reported last (a status without one, e.g. of an agent
            # restarted before it resumed, does not erase it)
            view.error, view.plan_digest, view.wave, view.t_sim = (
                msg.error, msg.plan_digest or view.plan_digest, msg.wave, msg.t_sim,
            )  # fmt: skip
            if msg.check_parent >= 0:
                view.check = (msg.check_parent, msg.r_d, msg.r_phi)
        elif isinstance(msg, NeighborRecordMsg):
            old = self.records.get(msg.sender)
            if old is None or old.round <= msg.round:  # the newest (re-)search round
                self.records[msg.sender] = msg
                self.held_digest = ""
            if old is None or old.round < msg.round:
                self.record_sample[msg.sender] = max(len(self.truth) - 1, 0)
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
    """The observer's bus: statuses, records, digests, camera frames, ground truth and
    membership."""
    bus = Bus(net.observer())
    watch(bus)
    return bus


def watch(bus: Bus) -> None:
    """Subscribe ``bus`` to what an observer sees: statuses, records, digests, the
    operator's reshape commands, camera frames (agents with ``--publish-camera``; bounded
    before the copy), ground truth and membership."""
    for key in (KEY_STATUS_ALL, KEY_RECORD_ALL, KEY_DIGEST_ALL, KEY_RESHAPE, KEY_WORLD_TRUTH_ALL):
        bus.subscribe(key)
    bus.subscribe(KEY_CAMERA_FEED_ALL, MAX_CAMERA_PUBLICATION_BYTES)
    bus.watch_alive(KEY_ALIVE_ALL)


#: Times the observer asks the members for an agreed record set it missed part of, the
#: pause between two asks (s: a member serves the set once it has agreed) and how long it
#: waits for each answer (s).
FETCH_ASKS = 3
FETCH_GAP = 2.0
FETCH_TIMEOUT = 2.0


def fetch_agreed_records(bus: Bus, obs: Observer) -> bool:
    """The records of the fleet's agreement that ``obs`` missed, asked of the members.

    A record is published once; under a flood (a rogue's 10 000 forged messages on a
    robot's record key, plain links) the router dropped the observer's copy of robot 1's,
    while the agents had agreed on it, and the judge could not recompute their plan. Once
    every member's digest names one record set and the records ``obs`` holds of its
    members do not hash to it (one is missing, or of another round), the set is asked of
    the members by that digest (``nao/{i}/records``, lowest id first, the answer sealed by
    the robot that serves it), at most :data:`FETCH_ASKS` times :data:`FETCH_GAP` s
    apart, and taken only if :func:`records_of` finds it the set the digest names: one
    record per member, hashing to it. True when records were added."""
    digests = {d.digest for d in obs.digests.values()}
    if len(digests) != 1:
        return False
    (digest,) = digests
    if obs.held_digest == digest:
        return False
    members = tuple(sorted(min(obs.digests.values(), key=lambda d: d.sender).members))
    held = [obs.records[m] for m in members if m in obs.records]
    if len(held) == len(members) and canonical_digest(held) == digest:
        obs.held_digest = digest
        return False
    asks, last = obs.fetches.get(digest, (0, -math.inf))
    now = time.monotonic()
    if asks >= FETCH_ASKS or now - last < FETCH_GAP:
        return False
    obs.fetches[digest] = (asks + 1, now)
    for rid in members:
        try:
            reply = bus.query(key_records(rid), RecordSetRequest(digest=digest), RecordSetReply,
                              timeout=FETCH_TIMEOUT)  # fmt: skip
            records = records_of(reply, digest, members)
        except (BusError, ValueError) as exc:
            obs.guard.reject(f"record set from robot {rid}", exc)
            continue
        for r in records:  # the agreed set: taken as it is, whatever round was held
            obs.records[r.sender] = r
        obs.held_digest = digest
        return True
    return False


#: How far two truth samples' poses may differ for a world that stands still (m, rad):
#: the world moves a robot only by its motions, far more than this in 0.1 s.
STILL = 1e-4


def observe_still(bus: Bus, obs: Observer, rec: Recorder | None, seconds: float) -> None:
    """Hand what arrives to ``obs`` until the world stands still, or for ``seconds``: two
    truth samples arrived here, the later one equal to the one before in every robot's
    pose (within :data:`STILL`). Called once every agent has exited: the world publishes
    each motion's last pose before it replies (sim/server/server.py), so the samples
    after the exits show the end, unless a dead agent's motion is still being walked out,
    which the next samples then show moving."""
    end, first = time.monotonic() + seconds, len(obs.truth)
    while time.monotonic() < end:
        for ev in bus.drain(0.1):
            obs.take_event(ev, rec)
        if len(obs.truth) >= first + 2 and _same_poses(obs.truth[-2][1], obs.truth[-1][1]):
            return


def _same_poses(
    a: dict[int, tuple[float, float, float]], b: dict[int, tuple[float, float, float]]
) -> bool:
    return a.keys() == b.keys() and all(
        max(abs(u - v) for u, v in zip(a[i], b[i], strict=True)) <= STILL for i in a
    )
