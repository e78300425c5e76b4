"""Resuming an agent after a crash (issue #9; DESIGN.md §1 phases, NAO paper 4.1–5.2).

The papers assume no robot ever crashes. An agent started with ``--state-dir`` journals
its state (:mod:`agent.phases.journal`); restarted after a crash it resumes where it was:

* **Before the search ended** (no record yet): it searches again. If it crashed during
  a turn it first turns back to θ = 0 and re-measures its heading against the journaled
  reference view (the image that defines the fixed frame) with the visual compass
  (§3.2.1), instead of assuming it faces north.
* **Before agreement** (a record, no agreement): it rejoins the exchange with its
  journaled record (no new search); the others keep it as a member through the
  membership grace period (:class:`agent.core.agreement.Grace`). If the others agreed while it
  was down (its digest had matched theirs before the crash), it asks for any agreed set
  and adopts it when that set holds its own record exactly as journaled.
* **After agreement**: it asks the fleet for the agreed record set by its digest (every
  agent serves ``nao/{id}/records``: :func:`answer`), checks the set against the
  digest and the members (:func:`records_of`), recomputes the plan (identical: the same
  bit-identical inputs) and checks it against the journaled plan digest, then goes on:
  waiting for earlier waves, the move from the journaled leg (after re-measuring its
  heading: the command in flight is taken as executed, the world having received it),
  holding, or ``done``. The others accept its new session once it shows the agreed
  digest (``Runner._current_session``). A crash during the march is not resumed: the
  agent stops safely (``failed``).

Tie-breaks: a command in flight at the crash counts as executed (the world executes a
request it received; the agent spends nearly all of a motion waiting for the reply);
the compass's re-measurement overrides the estimate when it is within 20° of it.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np

from agent.body.zenoh_world import retry_no_route
from agent.core.agreement import Agreement, params_digest
from agent.core.control import PAPER_GAINS, advance, wrap_pi
from agent.net.bus import Bus, BusError
from agent.phases.context import NORTH, AgentFailure
from agent.phases.journal import Journal, JournalError, JournalState
from agent.phases.record_sets import records_of
from agent.wire import (
    KEY_RECORDS_ALL,
    NeighborRecordMsg,
    ProtocolError,
    RecordSetReply,
    RecordSetRequest,
    canonical_digest,
    decode,
)

if TYPE_CHECKING:
    from agent.phases.runner import Runner

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
    runner: Runner, digest: str, members: Sequence[int], timeout: float = FETCH_TIMEOUT
) -> tuple[NeighborRecordMsg, ...]:
    """Ask every agent for the record set ``digest`` until one answers with it."""

    def accept(rep: RecordSetReply) -> str:
        try:
            records_of(rep, digest, members)
        except ValueError as exc:
            return str(exc)
        return ""

    end = runner.ctx.clock() + timeout
    last = "no reply"
    while runner.ctx.clock() < end:
        try:
            rep = retry_no_route(
                lambda: runner.ctx.bus.query(
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
        runner.membership.pump(0.5)  # keep hearing the fleet while nobody answers
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


def resume(runner: Runner, st: JournalState) -> tuple[str, NeighborRecordMsg | None]:
    """Restore ``runner`` from ``st``; the stage to go on with (``search``, ``agree``,
    ``wait``, ``move``, ``hold``, ``done``) and the record to agree on. Raises
    ``AgentFailure`` (a safe stop) when it cannot resume safely.

    The journal is not written while resuming: a crash during the resumption resumes
    from the same journal again."""
    journal, runner.ctx.journal = runner.ctx.journal, None
    try:
        return _resume(runner, st, journal)
    finally:
        runner.ctx.journal = journal


def _resume(
    runner: Runner, st: JournalState, journal: Journal | None
) -> tuple[str, NeighborRecordMsg | None]:
    # not resumed: a failed run; the march (by design); an exploration move of a
    # re-search round (4.1.3 rule 2), whose record and origin were being replaced
    if st.phase in ("failed", "march", "explore"):
        raise AgentFailure(
            f"journal says phase {st.phase} at the crash: not resumed "
            "(clear the state folder for a new run)"
        )
    runner.ctx.beliefs.compass_gain = st.compass_gain
    runner.ctx.beliefs.heading = st.heading
    runner.ctx.beliefs.position = np.array(st.position, dtype=np.float64)
    if st.command == "turn":
        runner.ctx.beliefs.heading = wrap_pi(st.heading + st.command_value)
    elif st.command == "walk":
        runner.ctx.beliefs.position = advance(
            runner.ctx.beliefs.position, st.heading, st.heading, st.command_value
        )
    moved = st.command != "" or abs(wrap_pi(runner.ctx.beliefs.heading - NORTH)) > REORIENT_MIN
    if st.record is None:
        if moved:
            remeasure_heading(runner, journal)
        runner.ctx.beliefs.heading = NORTH  # the new search defines the fixed frame again from here
        return "search", None
    runner.ctx.record_round = st.record.round
    runner.ctx.own_record = st.record
    digest, members, phase = st.agreed_digest, st.agreed_members, st.phase
    if not digest:
        found = agreed_by_others(runner.ctx.bus, st.record)
        if found is None:
            return "agree", st.record
        digest, members = found
        phase = "plan"
        log.info("the others agreed on %s with this robot's record: adopted", digest[:12])
    runner.ctx.status("plan", 0.0, "resumed: fetching the agreed records", force=True)
    records = fetch_records(runner, digest, members)
    agr = Agreement.restored(
        runner.ctx.me,
        records,
        runner.ctx.clock(),
        digest_fn=canonical_digest,
        params=params_digest(runner.ctx.cfg.agreed_params()),
        backoff_max=runner.ctx.cfg.backoff_max,
    )
    runner.membership.agreement = agr
    decision = agr.decide(runner.ctx.clock())
    runner.waves.make_plan(decision)
    if st.plan_digest and runner.ctx.plan_digest != st.plan_digest:
        raise AgentFailure(
            f"recomputed plan {runner.ctx.plan_digest[:12]} differs from the journaled "
            f"{st.plan_digest[:12]}: not moving"
        )
    stage = AGREED_STAGES.get(phase, "wait")
    if stage in ("move", "hold") and (moved or st.command):
        remeasure_heading(runner, journal)
    runner.ctx.leg = st.leg
    return stage, st.record


def remeasure_heading(runner: Runner, journal: Journal | None) -> None:
    """Turn to θ = 0 (by the estimate) and measure the heading against the reference view."""
    ref = None
    if journal is not None:
        try:
            ref = journal.load_reference()
        except JournalError as exc:
            log.error("reference view unusable: %s", exc)
    if ref is None:
        log.warning(
            "no reference view: heading %.1f° by dead reckoning",
            math.degrees(runner.ctx.beliefs.heading),
        )
        return
    runner.motion.last_frame = None
    turn = wrap_pi(NORTH - runner.ctx.beliefs.heading)
    if abs(turn) > REORIENT_MIN:
        runner.motion.rotate(turn, PAPER_GAINS, "resumed: turn to θ = 0° to re-measure")
    frame = runner.motion.look(0.0)
    res = runner.ctx.perception.measure_turn(ref, frame.image)
    if not res.ok:
        log.warning(
            "heading re-measurement failed (%s): kept %.1f°",
            res.reason,
            math.degrees(runner.ctx.beliefs.heading),
        )
        return
    measured = wrap_pi(NORTH + float(res.dtheta))
    off = wrap_pi(measured - runner.ctx.beliefs.heading)
    if abs(off) > REMEASURE_LIMIT:
        log.warning(
            "heading re-measured %.1f°, %.1f° off the estimate: kept the estimate",
            math.degrees(measured), math.degrees(off),
        )  # fmt: skip
        return
    log.info(
        "heading re-measured against the reference view: %.1f° (estimate %.1f°)",
        math.degrees(measured), math.degrees(runner.ctx.beliefs.heading),
    )  # fmt: skip
    runner.ctx.beliefs.heading = measured
    runner.motion.last_frame = frame


def journal_state(runner: Runner, command: str = "", value: float = 0.0) -> JournalState:
    """The runner's state to journal now (with the command about to be sent)."""
    agr = runner.membership.agreement
    decided = agr.decide(runner.ctx.clock()) if agr is not None and agr.agreed else None
    record = agr.records.get(runner.ctx.me) if agr is not None else runner.ctx.own_record
    return JournalState(
        robot_id=runner.ctx.me,
        phase=runner.ctx.phase,
        heading=float(wrap_pi(runner.ctx.beliefs.heading)),
        position=(float(runner.ctx.beliefs.position[0]), float(runner.ctx.beliefs.position[1])),
        compass_gain=runner.ctx.beliefs.compass_gain,
        record=record,
        agreed_digest=decided.digest if decided else "",
        agreed_members=tuple(int(m) for m in decided.members) if decided else (),
        plan_digest=runner.ctx.plan_digest,
        leg=runner.ctx.leg,
        command=command,
        command_value=float(value),
    )
