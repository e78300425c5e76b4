"""What a robot says of itself: its status to the fleet, its phase times for the report,
its state to the journal (docs/design.md §1, §8; NAO paper 5.2.2 (iii) steps 1–7).

:class:`Phase` names the phases of the machine (agent/phases/runner.py). Its values are
the wire's :data:`agent.wire.PHASES`, the strings statuses and journals carry: a
:class:`Phase` is written as its string and read back from it, so statuses and journals
are the same bytes as with plain strings.

One :class:`Reporter` per agent owns:

* the phase (entered through :meth:`Reporter.status`) and the :class:`Timeline` of the
  phases' starts;
* what every status carries besides the phase (:class:`Figures`), each figure written by
  its one owner through a typed method: the plan digest and the wave
  (agent/phases/waves.py), how far the robot has walked along its planned path (waves.py),
  the member its way is blocked by (agent/phases/safe_steps.py), how far it has stepped
  since it arrived and its own check of its pair (agent/phases/hold.py);
* the pace of the statuses. They go out on change, with a slow heartbeat: a new phase
  (or ``force``) at once; a changed status of the same phase (progress, detail, ...) at
  most every :func:`status_interval`; an unchanged one only every
  :func:`heartbeat_interval` (twice per membership grace, agent/core/grace.py, so
  that a member out of reach still counts while it is heard); once more, as a changed
  one, when a member (re)appears (:meth:`Reporter.say_again`). :meth:`Reporter.due` says
  when the next one is due, so that a waiting phase sleeps until then
  (agent/phases/membership.py);
* the journal it writes at every phase change (:attr:`Reporter.journal`, a
  :class:`Recorder`: crash recovery, agent/recovery/; none unless the agent keeps one).
  Motion journals each command through it before the body is asked, and the search
  the reference view (agent/phases/motion.py, search.py).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from enum import StrEnum
from typing import Protocol

import numpy as np

from agent.body.base import Body
from agent.config import AgentConfig
from agent.core.agreement import HEARD_PER_S
from agent.core.formation.shape.verdict import PairCheck
from agent.net.bus import Bus
from agent.wire import MAX_SHIFT, MAX_WALKED, StatusMsg, key_status


class Phase(StrEnum):
    """The phases of one robot, in the order of the machine (module docstring)."""

    START = "start"
    SEARCH = "search"
    LOCALISE = "localise"
    EXCHANGE = "exchange"
    AGREE = "agree"
    EXPLORE = "explore"
    PLAN = "plan"
    WAIT = "wait"
    MOVE = "move"
    HOLD = "hold"
    MARCH = "march"
    DONE = "done"
    FAILED = "failed"


STATUS_MIN_INTERVAL = 3.0  # s between progress statuses of the same phase


def status_interval(fleet_size: int | None) -> float:
    """Seconds between progress statuses (and waiting heartbeats) of one robot:
    :data:`STATUS_MIN_INTERVAL`, or ``fleet_size / HEARD_PER_S`` in a larger fleet, the
    agreement's budget (every member verifies every status; at 100 NAOs a 3 s cadence
    was ~33 a second): 10 s at 100 NAOs, half the membership grace of 20 s."""
    if fleet_size is None:
        return STATUS_MIN_INTERVAL
    return max(STATUS_MIN_INTERVAL, fleet_size / HEARD_PER_S)


#: Heartbeats (unchanged statuses) per membership grace (agent/core/grace.py). A member's
#: liveness is its zenoh liveliness token (a crashed process's links close at once, a
#: vanished host's after the link lease, agent/wire/network.py); the heartbeat bridges a
#: token that vanished while its member still publishes (heard every ``grace / 2`` s, its
#: silence stays half the grace below the count) and repeats the robot's state for a
#: member that missed a status while its links were cut. Each one wakes every member of the fleet
#: (the idle bench, docs/agent.md), so it is as slow as that allows: twice per grace, the
#: pace of a 100-NAO fleet already (:func:`status_interval`).
HEARTBEATS_PER_GRACE = 2


def heartbeat_interval(fleet_size: int | None, grace: float) -> float:
    """Seconds between repeats of an unchanged status (the heartbeat of a waiting robot):
    ``grace / HEARTBEATS_PER_GRACE`` (10 s with the default grace of 20 s), never more
    often than :func:`status_interval` (10 s at 100 NAOs too)."""
    return max(status_interval(fleet_size), grace / HEARTBEATS_PER_GRACE)


@dataclass
class Timeline:
    """Wall and sim time at each phase start, and the process's CPU time (every thread:
    the zenoh session's too) for the report."""

    marks: list[tuple[str, float, float]] = field(default_factory=list)
    cpu: list[float] = field(default_factory=list)

    def mark(self, phase: str, t_sim: float) -> None:
        self.marks.append((phase, time.monotonic(), t_sim))
        self.cpu.append(time.process_time())

    def costs(self) -> str:
        """``phase wall/CPU`` seconds of each phase entered, up to now, after the CPU
        seconds of the set-up (imports, session, perception); e.g. ``set-up -/1.2, search
        190/4.1, wait 88/1.9``: what a robot costs its host while it searches, waits..."""
        now = (time.monotonic(), time.process_time())
        parts = [f"set-up -/{self.cpu[0]:.1f}"] if self.cpu else []
        for k, (phase, wall, _) in enumerate(self.marks):
            end_wall = self.marks[k + 1][1] if k + 1 < len(self.marks) else now[0]
            end_cpu = self.cpu[k + 1] if k + 1 < len(self.cpu) else now[1]
            parts.append(f"{phase} {end_wall - wall:.0f}/{end_cpu - self.cpu[k]:.1f}")
        return ", ".join(parts)


@dataclass(frozen=True)
class Figures:
    """What every status of this robot carries besides its phase (module docstring)."""

    #: the digest of the agreed plan ("" before one) and this robot's wave in it (-1)
    plan_digest: str = ""
    wave: int = -1
    #: the robot's own check of its pair after hold (agent/core/formation/shape/verdict.py)
    check: PairCheck | None = None
    #: the member this robot's way is blocked by, beyond its patience (-1: none;
    #: agent/core/formation/waves/jam.py)
    blocked_by: int = -1
    #: finer waits: how far this robot has walked along its planned path (m, plan arc
    #: length, never decreasing during a move): a robot waiting for it starts once it is
    #: past its release point
    walked: float = 0.0
    #: how far this robot has stepped since it arrived (m, common frame of the plan): its
    #: children follow it
    shift: tuple[float, float] = (0.0, 0.0)


class Recorder(Protocol):
    """The journal as the phases write it (crash recovery, agent/recovery/)."""

    def save(self, command: str = "", value: float = 0.0, request_id: int = 0) -> None:
        """The state now, before ``command`` (none: a phase change) is sent with
        ``request_id``."""

    def reference(self, image: np.ndarray) -> None:
        """The view that defines the fixed frame (the search's first head-yaw-0 image)."""


class NoJournal:
    """The :class:`Recorder` of an agent that keeps no journal: it writes nothing."""

    def save(self, command: str = "", value: float = 0.0, request_id: int = 0) -> None:
        """Nothing is kept."""

    def reference(self, image: np.ndarray) -> None:
        """Nothing is kept."""


class Reporter:
    """The status publisher of one robot, its timeline and its journal (module docstring)."""

    def __init__(
        self, bus: Bus, body: Body, cfg: AgentConfig, clock: Callable[[], float] = time.monotonic
    ) -> None:
        self._bus = bus
        self._body = body
        self._cfg = cfg
        self._clock = clock
        self._phase = Phase.START
        self._figures = Figures()
        self._last = -math.inf  # when the last status was published
        # what the last status published said (but its sim time and byte count), and
        # whether a later call said something else that is not out yet (due)
        self._said: tuple[Phase, float, str, str, Figures] | None = None
        self._pending = False
        self.timeline = Timeline()
        #: written at every phase change; motion and search write it too (set once by
        #: the runner: its crash recovery, when the agent keeps a journal)
        self.journal: Recorder = NoJournal()

    @property
    def phase(self) -> Phase:
        """The phase entered last."""
        return self._phase

    @property
    def figures(self) -> Figures:
        """What the next status carries besides the phase."""
        return self._figures

    @property
    def interval(self) -> float:
        """Seconds between this robot's progress statuses (:func:`status_interval`)."""
        return status_interval(self._cfg.fleet_size)

    @property
    def heartbeat(self) -> float:
        """Seconds between repeats of an unchanged status (:func:`heartbeat_interval`)."""
        return heartbeat_interval(self._cfg.fleet_size, self._cfg.member_grace)

    def due(self) -> float:
        """When the next status is due (on the agent's clock): a changed one held back by
        :attr:`interval`, else the heartbeat (module docstring)."""
        return self._last + (self.interval if self._pending else self.heartbeat)

    def say_again(self) -> None:
        """Repeat the status at the next chance, :attr:`interval` after the last one, not
        a heartbeat: a member (re)appeared that may have missed it (a newcomer, or one
        back after its links were cut, when a status published meanwhile reached nobody)."""
        self._said, self._pending = None, True

    def show_plan(self, digest: str, wave: int) -> None:
        """The agreed plan's digest and this robot's wave in it (-1: not in a wave); a
        new plan (a reshape's) starts with none of the old one's check, walk and shift."""
        old = self._figures
        if old.plan_digest and digest != old.plan_digest:
            old = Figures(blocked_by=old.blocked_by)
        self._figures = replace(old, plan_digest=digest, wave=wave)

    def show_check(self, check: PairCheck) -> None:
        """This robot's own check of its pair."""
        self._figures = replace(self._figures, check=check)

    def show_blocked_by(self, robot: int) -> None:
        """The member this robot's way is blocked by (-1: none)."""
        self._figures = replace(self._figures, blocked_by=robot)

    def show_walked(self, walked: float) -> None:
        """How far this robot has walked along its planned path (m)."""
        self._figures = replace(self._figures, walked=walked)

    def show_shift(self, shift: tuple[float, float]) -> None:
        """How far this robot has stepped since it arrived (m, common frame)."""
        self._figures = replace(self._figures, shift=shift)

    def status(
        self,
        phase: Phase,
        progress: float = 0.0,
        detail: str = "",
        error: str = "",
        force: bool = False,
    ) -> None:
        """Publish this robot's status: at once on a phase change (journaled then) or
        with ``force``; a changed one at most every :func:`status_interval` seconds; an
        unchanged one every :func:`heartbeat_interval` seconds (module docstring)."""
        now = self._clock()
        changed = phase != self._phase
        if changed:
            self.timeline.mark(phase, self._body.t_sim)
        self._phase = phase
        if changed:
            self.journal.save()
        progress, detail, error = min(1.0, max(0.0, progress)), detail[:500], error[:500]
        # what it says (but its sim time and byte count), compared as plain values: the
        # wire message is built (and checked) only when it goes out, so that a waiting
        # robot's wake-ups cost no message they do not send
        said = (phase, progress, detail, error, self._figures)
        fresh = said != self._said
        gap = now - self._last
        if not (changed or force or gap >= (self.interval if fresh else self.heartbeat)):
            self._pending = fresh
            return
        self._last = now
        self._said, self._pending = said, False
        msg = self._message(phase, progress, detail, error)
        self._bus.publish(key_status(msg.sender), msg, "status")

    def _message(self, phase: Phase, progress: float, detail: str, error: str) -> StatusMsg:
        """The status to publish now: ``phase`` and the words given, the figures, the
        body's sim time and the bytes this robot has published."""
        f = self._figures
        return StatusMsg(
            sender=self._cfg.robot_id,
            phase=phase.value,
            progress=progress,
            detail=detail,
            plan_digest=f.plan_digest,
            wave=f.wave,
            error=error,
            t_sim=self._body.t_sim,
            bytes_sent=self._bus.stats.total_published,
            check_parent=-1 if f.check is None else f.check.parent,
            r_d=0.0 if f.check is None else max(-100.0, min(100.0, f.check.r_d)),
            r_phi=0.0 if f.check is None else max(-100.0, min(100.0, f.check.r_phi)),
            blocked_by=f.blocked_by,
            walked=min(MAX_WALKED, max(0.0, f.walked)),
            shift_x=min(MAX_SHIFT, max(-MAX_SHIFT, f.shift[0])),
            shift_y=min(MAX_SHIFT, max(-MAX_SHIFT, f.shift[1])),
            calibration=self._cfg.calibration,
        )
