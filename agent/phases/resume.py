"""Resuming an agent after a crash (issue #9; DESIGN.md §1 phases, NAO paper 4.1–5.2).

The papers assume no robot ever crashes. An agent started with ``--state-dir`` journals
its state (:mod:`agent.phases.journal`, written by :mod:`agent.phases.journaling`);
restarted after a crash it resumes where it was (:class:`Resumption`):

* **Before the search ended** (no record yet): it searches again. If it crashed during
  a turn it first turns back to θ = 0 and re-measures its heading against the journaled
  reference view (the image that defines the fixed frame) with the visual compass
  (§3.2.1), instead of assuming it faces north.
* **Before agreement** (a record, no agreement): it rejoins the exchange with its
  journaled record (no new search); the others keep it as a member through the
  membership grace period (:class:`agent.core.grace.Grace`). If the others agreed while it
  was down (its digest had matched theirs before the crash), it asks for any agreed set
  and adopts it when that set holds its own record exactly as journaled.
* **After agreement**: it asks the fleet for the agreed record set by its digest (every
  agent serves ``nao/{id}/records``: agent/phases/record_sets.py), checks the set against
  the digest and the members (:func:`~agent.phases.record_sets.records_of`), recomputes
  the plan (identical: the same bit-identical inputs) and checks it against the journaled
  plan digest, then goes on: waiting for earlier waves, the move from the journaled leg
  (after re-measuring its heading: the command in flight is taken as executed, the world
  having received it), holding, or ``done``. The others accept its new session once it
  shows the agreed digest (``Membership.current_session``). A crash during the march is
  not resumed: the agent stops safely (``failed``).

Tie-breaks: a command in flight at the crash counts as executed (the world executes a
request it received; the agent spends nearly all of a motion waiting for the reply);
the compass's re-measurement overrides the estimate when it is within 20° of it.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Sequence

import numpy as np

from agent.body.zenoh_world import retry_no_route
from agent.core.agreed_params import params_digest
from agent.core.agreement import Agreement
from agent.core.control import PAPER_GAINS, advance, wrap_pi
from agent.net.bus import Bus, BusError
from agent.phases.context import NORTH, AgentFailure, Context
from agent.phases.journal import Journal, JournalError, JournalState
from agent.phases.record_sets import records_of
from agent.phases.roles import Fleet, Hearing, Mover, Planner
from agent.wire import (
    KEY_RECORDS_ALL,
    NeighborRecordMsg,
    ProtocolError,
    RecordSetReply,
    RecordSetRequest,
    canonical_digest,
    decode,
)

log = logging.getLogger("agent.phases.resume")

#: s a restarted agent keeps asking the fleet for its agreed records.
FETCH_TIMEOUT = 60.0
#: s one record-set query waits for replies.
QUERY_TIMEOUT = 3.0
#: The compass's re-measured heading replaces the estimate only within this of it.
REMEASURE_LIMIT = math.radians(20.0)
#: Below this the robot does not turn back to θ = 0 to re-measure (compass overlap).
REORIENT_MIN = math.radians(5.0)
#: Where a resumed agent starts, by journaled phase (after agreement).
AGREED_STAGES = {"plan": "wait", "wait": "wait", "move": "move", "hold": "hold", "done": "done"}


# --------------------------------------------------------------------------- asking the fleet


def agreed_by_others(bus: Bus, own: NeighborRecordMsg) -> tuple[str, tuple[int, ...]] | None:
    """(digest, members) of a record set the others agreed on while this agent was down
    (after its digest had matched theirs), holding its record exactly as journaled; None
    when nobody has agreed. Asks once for any agreed set (``RecordSetRequest("")``)."""

    def check(rep: RecordSetReply) -> tuple[NeighborRecordMsg, ...]:
        try:
            senders = tuple(sorted(decode(r, NeighborRecordMsg).sender for r in rep.records))
        except ProtocolError as exc:
            raise ValueError(str(exc)) from None
        recs = records_of(rep, rep.digest, senders)
        if own not in recs:
            raise ValueError(f"record set {rep.digest[:12]} lacks this robot's record")
        return recs

    def accept(rep: RecordSetReply) -> str:
        try:
            check(rep)
        except ValueError as exc:
            return str(exc)
        return ""

    try:
        rep = retry_no_route(
            lambda: bus.query(
                KEY_RECORDS_ALL, RecordSetRequest(digest=""), RecordSetReply, QUERY_TIMEOUT, accept
            ),
            QUERY_TIMEOUT,
        )
    except BusError:
        return None
    return rep.digest, tuple(r.sender for r in check(rep))


def fetch_records(
    ctx: Context,
    fleet: Hearing,
    digest: str,
    members: Sequence[int],
    timeout: float = FETCH_TIMEOUT,
) -> tuple[NeighborRecordMsg, ...]:
    """Ask every agent for the record set ``digest`` until one answers with it."""

    def accept(rep: RecordSetReply) -> str:
        try:
            records_of(rep, digest, members)
        except ValueError as exc:
            return str(exc)
        return ""

    end = ctx.clock() + timeout
    last = "no reply"
    while ctx.clock() < end:
        try:
            rep = retry_no_route(
                lambda: ctx.bus.query(
                    KEY_RECORDS_ALL,
                    RecordSetRequest(digest=digest),
                    RecordSetReply,
                    QUERY_TIMEOUT,
                    accept,
                ),
                QUERY_TIMEOUT,
            )
            log.info("agreed records %s fetched from robot %d", digest[:12], rep.sender)
            return records_of(rep, digest, members)
        except BusError as exc:
            last = str(exc)
        fleet.pump(0.5)  # keep hearing the fleet while nobody answers
    raise ValueError(f"nobody served the agreed records {digest[:12]} in {timeout:g} s: {last}")


# --------------------------------------------------------------------------- resuming


def load(journal: Journal) -> JournalState | None:
    """The journaled state; a corrupt or foreign journal is reported and ignored."""
    try:
        st = journal.load()
    except JournalError as exc:
        log.error("journal %s unusable, starting afresh: %s", journal.state_path, exc)
        return None
    if st is not None:
        log.info(
            "journal: phase %s, heading %.1f°, position %s, command in flight %s",
            st.phase, math.degrees(st.heading), [round(v, 3) for v in st.position],
            f"{st.command} {st.command_value:+.3f}" if st.command else "none",
        )  # fmt: skip
    return st


class Resumption:
    """Where a (restarted) agent starts, and its state restored from the journal."""

    def __init__(self, ctx: Context, fleet: Fleet, motion: Mover, planner: Planner) -> None:
        self.ctx = ctx
        self.fleet = fleet
        self.motion = motion
        self.planner = planner

    def start(self) -> tuple[str, NeighborRecordMsg | None]:
        """Where to start: ``search`` afresh, or what the journal says."""
        if self.ctx.journal is None:
            return "search", None
        st = load(self.ctx.journal)
        if st is None:
            return "search", None
        stage, record = self.resume(st)
        log.info("robot %d resumes at %s (journaled phase %s)", self.ctx.me, stage, st.phase)
        return stage, record

    def resume(self, st: JournalState) -> tuple[str, NeighborRecordMsg | None]:
        """Restore the agent from ``st``; the stage to go on with (``search``, ``agree``,
        ``wait``, ``move``, ``hold``, ``done``) and the record to agree on. Raises
        ``AgentFailure`` (a safe stop) when it cannot resume safely.

        The journal is not written while resuming: a crash during the resumption resumes
        from the same journal again."""
        journal, self.ctx.journal = self.ctx.journal, None
        try:
            return self._resume(st, journal)
        finally:
            self.ctx.journal = journal

    def _resume(
        self, st: JournalState, journal: Journal | None
    ) -> tuple[str, NeighborRecordMsg | None]:
        ctx, b = self.ctx, self.ctx.beliefs
        # not resumed: a failed run; the march (by design); an exploration move of a
        # re-search round (4.1.3 rule 2), whose record and origin were being replaced
        if st.phase in ("failed", "march", "explore"):
            raise AgentFailure(
                f"journal says phase {st.phase} at the crash: not resumed "
                "(clear the state folder for a new run)"
            )
        b.compass_gain = st.compass_gain
        b.heading = st.heading
        b.position = np.array(st.position, dtype=np.float64)
        if st.command == "turn":
            b.heading = wrap_pi(st.heading + st.command_value)
        elif st.command == "walk":
            b.position = advance(b.position, st.heading, st.heading, st.command_value)
        moved = st.command != "" or abs(wrap_pi(b.heading - NORTH)) > REORIENT_MIN
        if st.record is None:
            if moved:
                self.remeasure_heading(journal)
            b.heading = NORTH  # the new search defines the fixed frame again from here
            return "search", None
        ctx.record_round = st.record.round
        ctx.own_record = st.record
        digest, members, phase = st.agreed_digest, st.agreed_members, st.phase
        if not digest:
            found = agreed_by_others(ctx.bus, st.record)
            if found is None:
                return "agree", st.record
            digest, members = found
            phase = "plan"
            log.info("the others agreed on %s with this robot's record: adopted", digest[:12])
        ctx.status("plan", 0.0, "resumed: fetching the agreed records", force=True)
        records = fetch_records(ctx, self.fleet, digest, members)
        agr = Agreement.restored(
            ctx.me,
            records,
            ctx.clock(),
            digest_fn=canonical_digest,
            params=params_digest(ctx.cfg.agreed_params()),
            backoff_max=ctx.cfg.backoff_max,
        )
        self.fleet.agreement = agr
        decision = agr.decide(ctx.clock())
        self.planner.make_plan(decision)
        if st.plan_digest and ctx.plan_digest != st.plan_digest:
            raise AgentFailure(
                f"recomputed plan {ctx.plan_digest[:12]} differs from the journaled "
                f"{st.plan_digest[:12]}: not moving"
            )
        stage = AGREED_STAGES.get(phase, "wait")
        if stage in ("move", "hold") and (moved or st.command):
            self.remeasure_heading(journal)
        ctx.leg = st.leg
        return stage, st.record

    def remeasure_heading(self, journal: Journal | None) -> None:
        """Turn to θ = 0 (by the estimate) and measure the heading against the reference view."""
        ctx, b = self.ctx, self.ctx.beliefs
        ref = None
        if journal is not None:
            try:
                ref = journal.load_reference()
            except JournalError as exc:
                log.error("reference view unusable: %s", exc)
        if ref is None:
            log.warning(
                "no reference view: heading %.1f° by dead reckoning", math.degrees(b.heading)
            )
            return
        self.motion.last_frame = None
        turn = wrap_pi(NORTH - b.heading)
        if abs(turn) > REORIENT_MIN:
            self.motion.rotate(turn, PAPER_GAINS, "resumed: turn to θ = 0° to re-measure")
        frame = self.motion.look(0.0)
        res = ctx.perception.measure_turn(ref, frame.image)
        if not res.ok:
            log.warning(
                "heading re-measurement failed (%s): kept %.1f°",
                res.reason,
                math.degrees(b.heading),
            )
            return
        measured = wrap_pi(NORTH + float(res.dtheta))
        off = wrap_pi(measured - b.heading)
        if abs(off) > REMEASURE_LIMIT:
            log.warning(
                "heading re-measured %.1f°, %.1f° off the estimate: kept the estimate",
                math.degrees(measured), math.degrees(off),
            )  # fmt: skip
            return
        log.info(
            "heading re-measured against the reference view: %.1f° (estimate %.1f°)",
            math.degrees(measured), math.degrees(b.heading),
        )  # fmt: skip
        b.heading = measured
        self.motion.last_frame = frame
