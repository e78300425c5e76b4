"""Stand-ins for one collaborator's neighbours, through their roles (agent/phases/roles.py),
so that a test runs one collaborator of the phase machine alone.

Time is a :class:`Clock` the test owns: every wait of the fakes moves it to the deadline
at once, so a phase that waits for a timeout returns in no time. The bus has no network:
what is published is encoded (the bytes the wire would carry) and counted, queries are
answered by the test (nobody, by default). The real :class:`~agent.phases.context.Context`
and :class:`~agent.phases.reporting.Reporter` sit on top of them.
"""

from __future__ import annotations

from collections.abc import Callable, Collection
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from agent.body.base import Frame, MotionResult
from agent.config import AgentConfig
from agent.core.agreement import Agreement, Decision
from agent.core.control import wrap_pi
from agent.core.formation.plan import Plan
from agent.net.bus import Event, QueryTimeout, Stats
from agent.phases.context import Beliefs, Context
from agent.phases.membership import MIN_WAIT, Peer
from agent.phases.roles import Course
from agent.seams import Formation, Perception, Sightings
from agent.wire import (
    DigestMsg,
    Guard,
    Message,
    NeighborRecordMsg,
    RecordSetReply,
    StatusMsg,
    decode,
    encode,
)

# robots 1, 2, 3 at known world positions; every robot sees every other one
WORLD = {1: (0.0, 0.0), 2: (-1.0, 0.1), 3: (0.9, -0.2)}


def records() -> tuple[NeighborRecordMsg, ...]:
    """The records of the robots of :data:`WORLD` (round 0, aligned starts)."""
    out = []
    for i, (x, y) in WORLD.items():
        nb = tuple((wx - x, wy - y) for j, (wx, wy) in WORLD.items() if j != i)
        out.append(NeighborRecordMsg(sender=i, round=0, neighbours=nb))
    return tuple(out)


class Clock:
    """The agent's clock, moved by the test and by the fakes' waits."""

    def __init__(self, t: float = 0.0) -> None:
        self.t = t

    def __call__(self) -> float:
        return self.t

    def advance(self, dt: float) -> None:
        self.t += max(0.0, dt)


class FakeBus:
    """A bus without a network (module docstring): ``events`` are drained by the
    membership, ``answer`` (None: nobody) answers every query."""

    def __init__(self, clock: Clock | None = None) -> None:
        self.clock = clock
        self.stats = Stats()
        self.published: list[tuple[str, Message]] = []
        self.events: list[Event] = []
        self.answer: Callable[..., Message] | None = None
        self.guard = Guard(lambda *a: None)
        self.served: dict[str, Callable[[Message], Message | None]] = {}
        self.subscribed: list[str] = []

    def publish(self, key: str, msg: Message, category: str = "") -> int:
        data = encode(msg)  # the bytes the wire carries; they must decode the same
        assert decode(data, type(msg)) == msg
        cat = category or msg.TAG
        self.stats.published_bytes[cat] += len(data)
        self.stats.published_count[cat] += 1
        self.published.append((key, msg))
        return len(data)

    def statuses(self) -> list[StatusMsg]:
        return [m for _, m in self.published if isinstance(m, StatusMsg)]

    def drain(self, timeout: float = 0.0) -> list[Event]:
        out, self.events = self.events, []
        if not out and self.clock is not None:
            self.clock.advance(timeout)  # nothing arrives: the whole wait passes
        return out

    def query(
        self, key: str, msg: Message, expect: type, timeout: float = 0.0, accept: Any = None
    ) -> Message:
        if self.answer is None:
            if self.clock is not None:
                self.clock.advance(timeout)
            raise QueryTimeout(f"{key}: no reply within {timeout:g} s")
        return self.answer(key, msg, expect, timeout, accept)

    def subscribe(self, key: str, max_bytes: int = 0, remote_only: bool = False) -> None:
        self.subscribed.append(key)

    def watch_alive(self, key: str) -> None:
        self.subscribed.append(key)

    def declare_alive(self, key: str) -> None:
        self.subscribed.append(key)

    def serve(self, key: str, answer: Callable[[Message], Message | None]) -> None:
        self.served[key] = answer


class FakeBody:
    """A body that does what it is told at once and keeps what it was told."""

    def __init__(self, robot_id: int, image: np.ndarray | None = None) -> None:
        self.robot_id = robot_id
        self.t_sim = 0.0
        self.clock_error = 0.0
        self.sent: list[tuple[str, float, int]] = []
        self.image = np.zeros((4, 5, 3), np.uint8) if image is None else image
        self.next_id = 100

    def new_request_id(self) -> int:
        self.next_id += 1
        return self.next_id

    def camera(self, yaw: float) -> Frame:
        return Frame(self.image, yaw, self.t_sim)

    def _do(self, what: str, value: float, request_id: int) -> MotionResult:
        self.sent.append((what, value, request_id))
        self.t_sim += 1.0
        return MotionResult("done", self.t_sim)

    def walk(self, distance: float, request_id: int = 0) -> MotionResult:
        return self._do("walk", distance, request_id)

    def side(self, distance: float, request_id: int = 0) -> MotionResult:
        return self._do("side", distance, request_id)

    def turn(self, angle: float, request_id: int = 0) -> MotionResult:
        return self._do("turn", angle, request_id)

    def stop(self) -> None:
        """Nothing moves."""

    def close(self) -> None:
        """Nothing to close."""


class FakeJournal:
    """A :class:`~agent.phases.reporting.Recorder` that keeps what it was told, with the
    phase of ``report`` (if given) at each save."""

    def __init__(self, report: Any = None) -> None:
        self.report = report
        self.saved: list[tuple[str, float, int, str]] = []
        self.references: list[np.ndarray] = []

    def save(self, command: str = "", value: float = 0.0, request_id: int = 0) -> None:
        phase = str(self.report.phase) if self.report is not None else ""
        self.saved.append((command, value, request_id, phase))

    def reference(self, image: np.ndarray) -> None:
        self.references.append(image)


def context(
    cfg: AgentConfig,
    formation: Formation | None = None,
    perception: Perception | None = None,
    clock: Clock | None = None,
) -> Context:
    """A robot's context on a :class:`FakeBus` and a :class:`FakeBody`, on ``clock``."""
    clock = clock or Clock()
    bus, body = FakeBus(clock), FakeBody(cfg.robot_id)
    return Context.of(bus, body, cfg, perception, formation, clock)  # type: ignore[arg-type]


@dataclass
class FakeFleet:
    """The :class:`~agent.phases.roles.Fleet` role as the test sets it: the peers, the
    agreement, the early records; ``stop`` is what :meth:`fleet_stop` says of any plan,
    ``clear`` what :meth:`arrived` says of any robots.
    Waits move ``clock`` to their deadline (a pump by its timeout), handing ``heard``
    to the observers first."""

    clock: Clock
    peers: dict[int, Peer] = field(default_factory=dict)
    agreement: Agreement[NeighborRecordMsg] | None = None
    early_records: dict[int, NeighborRecordMsg] = field(default_factory=dict)
    early_digests: dict[int, DigestMsg] = field(default_factory=dict)
    served: RecordSetReply | None = None
    observers: list[Callable[[Event], None]] = field(default_factory=list)
    heard: list[Event] = field(default_factory=list)
    stop: str = ""
    clear: bool = True
    pumps: int = 0
    retired: list[Agreement[NeighborRecordMsg]] = field(default_factory=list)
    pinned: tuple[set[int], str] | None = None

    def pump(self, timeout: float = 0.0) -> None:
        self.pumps += 1
        self._hear()
        self.clock.advance(timeout)

    def wait_until(self, deadline: float) -> None:
        """As the membership's wait: until ``deadline``, at least ``MIN_WAIT``."""
        self.pumps += 1
        self._hear()
        self.clock.t = max(self.clock.t + MIN_WAIT, deadline)

    def _hear(self) -> None:
        heard, self.heard = self.heard, []
        for ev in heard:
            for observe in list(self.observers):
                observe(ev)

    def peer(self, rid: int) -> Peer:
        return self.peers.get(rid, Peer())

    def open_round(self, agr: Agreement[NeighborRecordMsg]) -> None:
        self.agreement = agr

    def retire(self) -> None:
        if self.agreement is not None:
            self.retired.append(self.agreement)
        self.agreement = None

    def pin_sessions(self, members: set[int], plan_digest: str) -> None:
        self.pinned = (members, plan_digest)

    def arrived(self, among: Collection[int] | None = None, digest: str = "") -> bool:
        return self.clear

    def fleet_stop(self, plan: Plan | None) -> str:
        return self.stop


class FakeMover:
    """The :class:`~agent.phases.roles.Mover` role: turns and steps believed as commanded."""

    def __init__(self, beliefs: Beliefs, image: np.ndarray | None = None) -> None:
        self.beliefs = beliefs
        self.last_frame: Frame | None = None
        self.steps = 0
        self.turns: list[float] = []
        self.walks: list[float] = []
        self.image = np.zeros((4, 5, 3), np.uint8) if image is None else image

    def look(self, yaw: float = 0.0) -> Frame:
        return Frame(self.image, yaw, 0.0)

    def reference(self) -> Frame:
        return self.last_frame if self.last_frame is not None else self.look(0.0)

    def rotate(self, angle: float, gains: object = None, label: str = "") -> float:
        self.turns.append(angle)
        self.beliefs.heading = wrap_pi(self.beliefs.heading + angle)
        return angle

    def walk_step(self, distance: float) -> MotionResult:
        self.walks.append(distance)
        self.steps += 1
        h = self.beliefs.heading
        self.beliefs.position = self.beliefs.position + distance * np.array([np.cos(h), np.sin(h)])
        return MotionResult("done", 0.0)

    def side_step(self, distance: float) -> MotionResult:
        self.walks.append(distance)
        return MotionResult("done", 0.0)


class FakeSurveyor:
    """The :class:`~agent.phases.roles.Surveyor` role: a search that finds ``neighbours``."""

    def __init__(self, me: int, neighbours: tuple[tuple[float, float], ...] = ()) -> None:
        self.me = me
        self.neighbours = neighbours
        self.round = 0
        self.record: NeighborRecordMsg | None = None
        self.searches = 0

    def sweep(self) -> list[Sightings]:
        self.searches += 1
        return []

    def localise(self, sightings: list[Sightings]) -> NeighborRecordMsg:
        self.record = NeighborRecordMsg(
            sender=self.me, round=self.round, neighbours=self.neighbours
        )
        return self.record

    def begin_round(self, round_: int) -> None:
        self.round = round_

    def restore(self, record: NeighborRecordMsg) -> None:
        self.round, self.record = record.round, record

    def restarted(self, start_heading: float) -> None:
        self.start_heading: float | None = start_heading


class FakeStepper:
    """The :class:`~agent.phases.roles.Stepper` role: every goal reached at once."""

    def __init__(self, beliefs: Beliefs) -> None:
        self.beliefs = beliefs
        self.goals: list[np.ndarray] = []
        self.forgotten = 0

    def walk_to(
        self,
        goal: np.ndarray,
        progress: Callable[[float], None],
        backward_within: float = 0.0,
        gate: Callable[[float], None] | None = None,
    ) -> None:
        if gate is not None:  # the whole leg as one step
            gate(float(np.hypot(*(np.asarray(goal) - self.beliefs.position))))
        self.goals.append(np.asarray(goal, dtype=np.float64))
        self.beliefs.position = np.asarray(goal, dtype=np.float64).copy()
        progress(1.0)

    def forget(self) -> None:
        self.forgotten += 1


class FakePlanner:
    """The :class:`~agent.phases.roles.Planner` role: the formation core's plan of the
    decision, followed by ``course`` (in the common frame: the robots start aligned)."""

    def __init__(self, ctx: Context, course: Course) -> None:
        self.ctx = ctx
        self.course = course
        self.decisions: list[Decision[NeighborRecordMsg]] = []

    def make_plan(self, decision: Decision[NeighborRecordMsg]) -> Plan:
        self.decisions.append(decision)
        plan = self.ctx.formation.plan(decision.records, self.ctx.cfg.plan_params())
        self.course.follow(plan)
        return plan
