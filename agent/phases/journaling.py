"""Writing the journal (issue #9; DESIGN.md §8 "Faults"): before every command sent to the
body and at every phase change, so that a restarted agent knows where it was and what it
may have been doing (agent/phases/journal.py holds the format, agent/phases/resume.py
reads it back).

A failing disk never stops the agent: the error is logged and the journal given up.
"""

from __future__ import annotations

import logging

from agent.core.agreement import Agreement
from agent.core.control import wrap_pi
from agent.phases.context import Context
from agent.phases.journal import JournalState
from agent.phases.roles import Fleet
from agent.wire import NeighborRecordMsg, reason

log = logging.getLogger("agent.phases.journaling")


def journal_state(
    ctx: Context,
    agr: Agreement[NeighborRecordMsg] | None,
    command: str = "",
    value: float = 0.0,
) -> JournalState:
    """The agent's state to journal now (with the command about to be sent)."""
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
    )


class Journaling:
    """The context's journal hook: :meth:`save` writes ``ctx.journal`` if one is kept."""

    def __init__(self, ctx: Context, fleet: Fleet) -> None:
        self.ctx = ctx
        self.fleet = fleet

    def save(self, command: str = "", value: float = 0.0) -> None:
        """Write the journal (issue #9), before ``command`` is sent; a failing disk is
        logged and the journal given up, never fatal."""
        journal = self.ctx.journal
        if journal is None:
            return
        try:
            journal.save(journal_state(self.ctx, self.fleet.agreement, command, value))
        except (OSError, ValueError) as exc:
            log.error("journal write failed, journal given up: %s", reason(exc))
            self.ctx.journal = None
