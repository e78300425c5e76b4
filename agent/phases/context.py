"""What every collaborator of the phase machine shares (docs/design.md §1, §8; NAO paper 4.1.1).

The phase machine (:mod:`agent.phases.runner`) is split into collaborators, one per
concern (membership, motion, safe steps, search, agreement, re-search, waves, hold,
resume); they share this small :class:`Context` and nothing else of each other but the
typed roles of :mod:`agent.phases.roles`:

* the robot's seams: the bus, its :class:`~agent.body.base.Body`, its configuration,
  its :class:`~agent.seams.Perception` and :class:`~agent.seams.Formation`,
  and a clock;
* its :class:`Beliefs`. Heading: the agent's heading in its fixed frame starts at
  :data:`NORTH` (every robot faces north at the start, 4.1.1) and changes only by
  visual-compass measurements of its own turns and steps (eq. 2), or, when the compass
  fails, by the turn it commanded. Position: (0, 0) in the fixed frame at the start,
  dead-reckoned from the commanded steps along the believed heading. Agents never read
  ground truth;
* where it is: the phase, its record and round, the agreed plan, its wave and leg;
* the status publisher (:meth:`Context.status`), which marks the :class:`Timeline` and
  writes the journal (crashed agents resume) at every phase change through ``journal_hook``.
  Statuses go out on change, with a slow heartbeat: a new phase (or ``force``) at once;
  a changed status of the same phase (progress, detail, ...) at most every
  :func:`status_interval`; an unchanged one only every :func:`heartbeat_interval`
  (well inside the membership grace, agent/core/grace.py, so that a member out of reach
  still counts while it is heard). :meth:`Context.status_due` says when the next one is
  due, so that a waiting phase sleeps until then (agent/phases/membership.py).

:class:`AgentFailure` is the one way a collaborator stops the robot safely.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace

import numpy as np
import numpy.typing as npt

from agent.body.base import Body
from agent.config import AgentConfig
from agent.core.agreement import HEARD_PER_S
from agent.core.formation.plan import Plan
from agent.core.formation.shape.verdict import PairCheck
from agent.net.bus import Bus
from agent.phases.journal import Journal
from agent.seams import Formation, Perception
from agent.wire import MAX_SHIFT, MAX_WALKED, NeighborRecordMsg, StatusMsg, key_status

#: Every robot faces north of its fixed frame at the start (4.1.1).
NORTH = math.pi / 2
STATUS_MIN_INTERVAL = 3.0  # s between progress statuses of the same phase


def status_interval(fleet_size: int | None) -> float:
    """Seconds between progress statuses (and waiting heartbeats) of one robot:
    :data:`STATUS_MIN_INTERVAL`, or ``fleet_size / HEARD_PER_S`` in a larger fleet, the
    agreement's budget (every member verifies every status; at 100 NAOs a 3 s cadence
    was ~33 a second): 10 s at 100 NAOs, well inside the membership grace of 20 s."""
    if fleet_size is None:
        return STATUS_MIN_INTERVAL
    return max(STATUS_MIN_INTERVAL, fleet_size / HEARD_PER_S)


#: Heartbeats (unchanged statuses) per membership grace: a member whose token vanished is
#: heard this many times before it would count as gone (agent/core/grace.py).
HEARTBEATS_PER_GRACE = 3


def heartbeat_interval(fleet_size: int | None, grace: float) -> float:
    """Seconds between repeats of an unchanged status (the heartbeat of a waiting robot):
    ``grace / HEARTBEATS_PER_GRACE`` (6.7 s with the default grace of 20 s), never more
    often than :func:`status_interval` (10 s at 100 NAOs: twice per grace)."""
    return max(status_interval(fleet_size), grace / HEARTBEATS_PER_GRACE)


class AgentFailure(RuntimeError):
    """A reason to stop safely (status ``failed``); the text is the reason."""


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


@dataclass
class Beliefs:
    """The robot's beliefs about itself in its fixed frame (see the module docstring)."""

    heading: float = NORTH
    position: npt.NDArray[np.float64] = field(default_factory=lambda: np.zeros(2))
    compass_gain: float = 1.0  # calibrated by the search's half turn (search.py)


def _no_journal(command: str = "", value: float = 0.0, request_id: int = 0) -> None:
    """The journal hook of an agent that keeps no journal."""


@dataclass
class Context:
    """The seams, beliefs and progress of one robot, shared by its collaborators."""

    bus: Bus
    body: Body
    cfg: AgentConfig
    perception: Perception
    formation: Formation
    clock: Callable[[], float] = time.monotonic
    beliefs: Beliefs = field(default_factory=Beliefs)
    phase: str = "start"
    record_round: int = 0  # the re-search round of the current record (4.1.3 rule 2)
    own_record: NeighborRecordMsg | None = None
    planned: Plan | None = None  # the agreed plan, once made (see :attr:`plan`)
    plan_digest: str = ""
    wave: int = -1
    # the robot's own check of its pair after hold (agent/core/formation/shape/verdict.py)
    check: PairCheck | None = None
    leg: int = 0  # the move's current leg
    final_heading: float = NORTH  # the pyramid axis, once the goals are known
    timeline: Timeline = field(default_factory=Timeline)
    # the durable journal (None: not kept); the hook writes it before each
    # command (with its motion request id) and at each phase change
    # (agent/phases/journaling.py)
    journal: Journal | None = None
    journal_hook: Callable[[str, float, int], None] = _no_journal
    # when this robot's first process of the current run started (ms since the
    # Unix epoch; journaled, kept across resumptions; agent/phases/runs.py)
    run_epoch: int = 0
    last_status: float = -math.inf  # when the last status was published
    # what the last status published said (but its sim time and byte count), and whether
    # a later call said something else that is not out yet (status_due)
    status_sent: StatusMsg | None = None
    status_pending: bool = False
    # the member this robot's way is blocked by, beyond its patience (-1: none;
    # agent/core/formation/waves/jam.py), published in every status
    blocked_by: int = -1
    # finer waits: how far this robot has walked along its planned path (m,
    # plan arc length, never decreasing during a move; agent/phases/waves.py), published
    # in every status: a robot waiting for it starts once it is past its release point
    walked: float = 0.0
    # how far this robot has stepped since it arrived (m, common frame of the
    # plan; agent/phases/hold.py), published in every status: its children follow it
    shift: tuple[float, float] = (0.0, 0.0)

    @property
    def me(self) -> int:
        return self.cfg.robot_id

    @property
    def status_interval(self) -> float:
        """Seconds between this robot's progress statuses (:func:`status_interval`)."""
        return status_interval(self.cfg.fleet_size)

    @property
    def heartbeat(self) -> float:
        """Seconds between repeats of an unchanged status (:func:`heartbeat_interval`)."""
        return heartbeat_interval(self.cfg.fleet_size, self.cfg.member_grace)

    def status_due(self) -> float:
        """When the next status is due (on :attr:`clock`): a changed one held back by
        :attr:`status_interval`, else the heartbeat (module docstring)."""
        return self.last_status + (self.status_interval if self.status_pending else self.heartbeat)

    @property
    def plan(self) -> Plan:
        """The agreed plan (after :meth:`agent.phases.waves.Waves.make_plan`)."""
        if self.planned is None:
            raise AgentFailure("no plan yet")
        return self.planned

    @plan.setter
    def plan(self, plan: Plan) -> None:
        self.planned = plan

    def status(
        self,
        phase: str,
        progress: float = 0.0,
        detail: str = "",
        error: str = "",
        force: bool = False,
    ) -> None:
        """Publish this robot's status: at once on a phase change (journaled then) or
        with ``force``; a changed one at most every :func:`status_interval` seconds; an
        unchanged one every :func:`heartbeat_interval` seconds (module docstring)."""
        now = self.clock()
        changed = phase != self.phase
        if changed:
            self.timeline.mark(phase, self.body.t_sim)
        self.phase = phase
        if changed:
            self.journal_hook("", 0.0, 0)
        msg = StatusMsg(
            sender=self.me,
            phase=phase,
            progress=min(1.0, max(0.0, progress)),
            detail=detail[:500],
            plan_digest=self.plan_digest,
            wave=self.wave,
            error=error[:500],
            t_sim=self.body.t_sim,
            bytes_sent=self.bus.stats.total_published,
            check_parent=-1 if self.check is None else self.check.parent,
            r_d=0.0 if self.check is None else max(-100.0, min(100.0, self.check.r_d)),
            r_phi=0.0 if self.check is None else max(-100.0, min(100.0, self.check.r_phi)),
            blocked_by=self.blocked_by,
            walked=min(MAX_WALKED, max(0.0, self.walked)),
            shift_x=min(MAX_SHIFT, max(-MAX_SHIFT, self.shift[0])),
            shift_y=min(MAX_SHIFT, max(-MAX_SHIFT, self.shift[1])),
            calibration=self.cfg.calibration,
        )
        said = replace(msg, t_sim=0.0, bytes_sent=0)
        fresh = said != self.status_sent
        gap = now - self.last_status
        if not (changed or force or gap >= (self.status_interval if fresh else self.heartbeat)):
            self.status_pending = fresh
            return
        self.last_status = now
        self.status_sent, self.status_pending = said, False
        self.bus.publish(key_status(self.me), msg, "status")
