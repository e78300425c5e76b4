"""Writing the journal (crashed agents resume; docs/design.md §8 "Faults"): before every command
sent to the body and at every phase change, so that a restarted agent knows where it was and what it
may have been doing (agent/recovery/journal.py holds the format, agent/recovery/resume.py
reads it back). Each command is journaled with its motion request id (so that a resume never walks
twice), and the run's identity with every write; once the run is over for this robot (``done``,
``failed``, or stopped by the operator) a final record says so (:meth:`Journaling.finish`).

A failing disk never stops the agent: the error is logged and the journal given up.
"""

from __future__ import annotations

import logging

from agent.core.agreement import Agreement
from agent.core.control import wrap_pi
from agent.phases.context import Context
from agent.phases.roles import Fleet
from agent.recovery.journal import JournalState
from agent.wire import NeighborRecordMsg, reason

log = logging.getLogger("agent.recovery.journaling")


def journal_state(
    ctx: Context,
    agr: Agreement[NeighborRecordMsg] | None,
    command: str = "",
    value: float = 0.0,
    request_id: int = 0,
    final: str = "",
) -> JournalState:
    """The agent's state to journal now (with the command about to be sent and its
    request id; ``final``: how the run ended, "" while it goes on)."""
    decided = agr.decide(ctx.clock()) if agr is not None and agr.agreed else None
    record = agr.records.get(ctx.me) if agr is not None else ctx.own_record
    b = ctx.beliefs
    return JournalState(
        robot_id=ctx.me,
        phase=ctx.phase,
        heading=float(wrap_pi(b.heading)),
        position=(float(b.position[0]), float(b.position[1])),
        compass_gain=b.compass_gain,
        record=record,
        agreed_digest=decided.digest if decided else "",
        agreed_members=tuple(int(m) for m in decided.members) if decided else (),
        plan_digest=ctx.plan_digest,
        leg=ctx.leg,
        command=command,
        command_value=float(value),
        request_id=request_id,
        run_epoch=ctx.run_epoch,
        final=final,
    )


class Journaling:
    """The context's journal hook: :meth:`save` writes ``ctx.journal`` if one is kept."""

    def __init__(self, ctx: Context, fleet: Fleet) -> None:
        self.ctx = ctx
        self.fleet = fleet

    def save(self, command: str = "", value: float = 0.0, request_id: int = 0) -> None:
        """Write the journal, before ``command`` is sent with ``request_id``;
        a failing disk is logged and the journal given up, never fatal."""
        self._write(command, value, request_id, "")

    def finish(self, end: str) -> None:
        """The final record (a finished run's journal must not derail the next run): the run is over
        for this robot (``done``, ``failed`` or ``stopped``); the next start archives this
        journal."""
        self._write("", 0.0, 0, end)

    def _write(self, command: str, value: float, request_id: int, final: str) -> None:
        journal = self.ctx.journal
        if journal is None:
            return
        try:
            state = journal_state(self.ctx, self.fleet.agreement, command, value, request_id, final)
            journal.save(state)
        except (OSError, ValueError) as exc:
            log.error("journal write failed, journal given up: %s", reason(exc))
            self.ctx.journal = None
