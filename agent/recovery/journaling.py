"""Writing the journal (crashed agents resume; docs/design.md §8 "Faults"): before every command
sent to the body and at every phase change, so that a restarted agent knows where it was and what it
may have been doing (agent/recovery/journal.py holds the format, agent/recovery/resume.py
reads it back). Each command is journaled with its motion request id (so that a resume never walks
twice), and the run's identity with every write; once the run is over for this robot (``done``,
``failed``, or stopped by the operator) a final record says so (:meth:`Journaling.finish`).

:class:`Journaling` is the phases' :class:`~agent.phases.reporting.Recorder`: the reporter
calls it at every phase change, motion before every command, the search with the
reference view. It owns the journal and the run's identity (``run_epoch``: when this
robot's first process of the run started, kept across resumptions; set by the resumption
when the agent starts). While the agent resumes (:meth:`Journaling.resuming`) the
journal keeps the journaled state and follows only the body (:class:`MotionJournal`).

A failing disk never stops the agent: the error is logged and the journal given up.
"""

from __future__ import annotations

import logging
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import replace

import numpy as np

from agent.core.control import wrap_pi
from agent.phases.context import Beliefs, Context
from agent.phases.roles import Course, Fleet, Surveyor
from agent.recovery.journal import Journal, JournalState
from agent.wire import reason

log = logging.getLogger("agent.recovery.journaling")


class MotionJournal:
    """The journal while resuming: the journaled state ``st`` with the beliefs as they
    are and the command about to be sent (phase changes write nothing: the journaled
    phase stands until the resumption is over). A failing disk gives it up (logged)."""

    def __init__(self, beliefs: Beliefs, journal: Journal | None, st: JournalState) -> None:
        self.beliefs, self.journal, self.st = beliefs, journal, st

    def hook(self, command: str = "", value: float = 0.0, request_id: int = 0) -> None:
        """A command about to be sent is journaled (a phase change is not)."""
        if command:
            self.save(command, value, request_id)

    def save(self, command: str = "", value: float = 0.0, request_id: int = 0) -> None:
        """Journal ``st`` with the beliefs now and ``command`` (none: nothing in flight)."""
        if self.journal is None:
            return
        b = self.beliefs
        state = replace(
            self.st,
            heading=float(wrap_pi(b.heading)),
            position=(float(b.position[0]), float(b.position[1])),
            command=command,
            command_value=float(value),
            request_id=request_id,
        )
        try:
            self.journal.save(state)
        except (OSError, ValueError) as exc:
            log.error("journal write failed while resuming, given up: %s", exc)
            self.journal = None


class Journaling:
    """Writes ``journal`` with the state of the robot of ``ctx`` (module docstring): its
    phase and beliefs, its record (``survey``; the agreement's once one is under way,
    ``fleet``), the agreed plan's digest and the leg of the move (``course``)."""

    def __init__(
        self,
        journal: Journal | None,
        ctx: Context,
        fleet: Fleet,
        course: Course,
        survey: Surveyor,
    ) -> None:
        #: the journal (None: none kept, or given up on a failing disk)
        self.journal: Journal | None = journal
        self.ctx = ctx
        self.fleet = fleet
        self.course = course
        self.survey = survey
        self._run_epoch = 0
        self._resuming: MotionJournal | None = None

    @property
    def run_epoch(self) -> int:
        """When this robot's first process of the current run started (ms since the Unix
        epoch; 0 before the agent started)."""
        return self._run_epoch

    def join_run(self, epoch: int) -> None:
        """The run this robot's journal belongs to from now on (its ``run_epoch``)."""
        self._run_epoch = epoch

    def state(
        self, command: str = "", value: float = 0.0, request_id: int = 0, final: str = ""
    ) -> JournalState:
        """The agent's state to journal now (with the command about to be sent and its
        request id; ``final``: how the run ended, "" while it goes on)."""
        ctx, agr = self.ctx, self.fleet.agreement
        decided = agr.decide(ctx.clock()) if agr is not None and agr.agreed else None
        record = agr.records.get(ctx.me) if agr is not None else self.survey.record
        b = ctx.beliefs
        return JournalState(
            robot_id=ctx.me,
            phase=ctx.report.phase,
            heading=float(wrap_pi(b.heading)),
            position=(float(b.position[0]), float(b.position[1])),
            compass_gain=b.compass_gain,
            record=record,
            agreed_digest=decided.digest if decided else "",
            agreed_members=tuple(int(m) for m in decided.members) if decided else (),
            plan_digest=self.course.digest,
            leg=self.course.leg,
            command=command,
            command_value=float(value),
            request_id=request_id,
            run_epoch=self._run_epoch,
            final=final,
        )

    def save(self, command: str = "", value: float = 0.0, request_id: int = 0) -> None:
        """Write the journal, before ``command`` is sent with ``request_id`` (none: a
        phase change); while resuming, only a command, by :class:`MotionJournal`. A
        failing disk is logged and the journal given up, never fatal."""
        if self._resuming is not None:
            self._resuming.hook(command, value, request_id)
            return
        self._write(command, value, request_id, "")

    def reference(self, image: np.ndarray) -> None:
        """Keep the view that defines the fixed frame (the resumption re-measures the
        heading against it); a failing disk is logged."""
        if self.journal is None or self._resuming is not None:
            return
        try:
            self.journal.save_reference(image)
        except (OSError, ValueError) as exc:
            log.error("reference view not journaled: %s", reason(exc))

    def finish(self, end: str) -> None:
        """The final record (a finished run's journal must not derail the next run): the run is over
        for this robot (``done``, ``failed`` or ``stopped``); the next start archives this
        journal."""
        self._write("", 0.0, 0, end)

    @contextmanager
    def resuming(self, st: JournalState) -> Iterator[MotionJournal]:
        """While the agent resumes from ``st``: the journal keeps ``st`` (its phase, record,
        agreement, leg), and only the body's motions are journaled, by the
        :class:`MotionJournal` yielded (a crash during the resumption resumes from ``st``
        again, neither replaying a command nor forgetting a turn)."""
        motions = MotionJournal(self.ctx.beliefs, self.journal, st)
        self._resuming = motions
        try:
            yield motions
        finally:
            self._resuming = None

    def _write(self, command: str, value: float, request_id: int, final: str) -> None:
        journal = self.journal
        if journal is None:
            return
        try:
            journal.save(self.state(command, value, request_id, final))
        except (OSError, ValueError) as exc:
            log.error("journal write failed, journal given up: %s", reason(exc))
            self.journal = None
