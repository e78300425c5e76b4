"""Resuming an agent after a crash (crashed agents and stale journals; docs/design.md §1 phases, NAO
paper 4.1–5.2).

The papers assume no robot ever crashes. An agent started with ``--state-dir`` journals
its state (:mod:`agent.recovery.journal`, written by :mod:`agent.recovery.journaling`).
Restarted, it first asks the bus whether the journal's run is still going
(:mod:`agent.recovery.runs`): a final journal, or one of a run that ended, is archived and
the robot starts afresh. A journal of a run still going is resumed (:class:`Resumption`):

* **The command in flight** at the crash is sent again with its journaled request id:
  the world answers a repeat with its first result (or, had the request not reached it,
  executes it now), so the robot moves once; the belief update follows the answer, once.
  A body without request ids (NAOqi) journals none: the command then counts as executed
  (the robot executes a request it received; the agent spends nearly all of a motion
  waiting for the reply).
* **Before the search ended** (no record yet): it searches again. If it crashed during
  a turn it first turns back to θ = 0 and re-measures its heading against the journaled
  reference view (the image that defines the fixed frame) with the visual compass
  (§3.2.1), instead of assuming it faces north.
* **Before agreement** (a record, no agreement): it rejoins the exchange with its
  journaled record (no new search); the others keep it as a member through the
  membership grace period (:class:`agent.core.grace.Grace`). If the others agreed while it
  was down (its digest had matched theirs before the crash), it adopts the agreed set
  that holds its own record exactly as journaled.
* **After agreement**: the agreed record set by its digest (every agent serves
  ``nao/{id}/records``: agent/phases/record_sets.py; the run check fetched it), checked
  against the digest and the members (:func:`~agent.wire.codec.records_of`); it
  recomputes the plan (identical: the same bit-identical inputs) and checks it against
  the journaled plan digest, then goes on: waiting for earlier waves, the move from the
  journaled leg (after re-measuring its heading), or holding. The others accept its new
  session once it shows the agreed digest (``Membership.current_session``). A crash
  during the march is not resumed: the agent stops safely (``failed``).

While resuming, the journal keeps the journaled phase, record and agreement, and follows
the body: the beliefs once the command in flight is answered, and each turn of the
resumption (re-measuring the heading, turning back to the axis at hold) with its request
id (:meth:`~agent.recovery.journaling.Journaling.resuming`): a second crash during the
resumption resumes from there.

The heading re-measurement is weighed against the estimate by their errors
(:mod:`agent.core.control.heading_fix`): in place the compass wins; away from the
reference view's place its parallax grows, and the estimate keeps its weight.
"""

from __future__ import annotations

import logging
import math

import numpy as np

from agent.body.base import MotionResult
from agent.core.agreed_params import params_digest
from agent.core.agreement import Agreement
from agent.core.control import PAPER_GAINS, advance, wrap_pi
from agent.core.control.heading_fix import compass_sigma, estimate_sigma, fuse
from agent.phases.context import NORTH, AgentFailure
from agent.phases.reporting import Phase
from agent.phases.roles import Crew
from agent.recovery.journal import Journal, JournalError, JournalState
from agent.recovery.journaling import Journaling
from agent.recovery.runs import RunCheck, Verdict, agreed_by_others, fetch_records
from agent.wire import NeighborRecordMsg, canonical_digest

log = logging.getLogger("agent.recovery.resume")

#: Below this the robot does not turn back to θ = 0 to re-measure (compass overlap).
REORIENT_MIN = math.radians(5.0)
#: Where a resumed agent starts, by journaled phase (after agreement).
AGREED_STAGES = {
    Phase.PLAN: Phase.WAIT,
    Phase.WAIT: Phase.WAIT,
    Phase.MOVE: Phase.MOVE,
    Phase.HOLD: Phase.HOLD,
}
#: Journaled phases never resumed: a run over for this robot; the march (by design); an
#: exploration move of a re-search round (4.1.3 rule 2), whose record and origin were
#: being replaced.
NOT_RESUMED = (Phase.FAILED, Phase.DONE, Phase.MARCH, Phase.EXPLORE)


def archive(journal: Journal, why: str) -> None:
    """Move the journal (and reference view) aside: the robot starts a new run."""
    try:
        moved = journal.archive()
    except OSError as exc:
        log.error("journal %s not archived (%s): %s", journal.state_path, why, exc)
        return
    if moved:
        log.info("journal archived as %s (%s)", ", ".join(p.name for p in moved), why)


def load(journal: Journal) -> JournalState | None:
    """The journaled state; a corrupt or foreign journal is reported, archived and
    ignored."""
    try:
        st = journal.load()
    except JournalError as exc:
        log.error("journal %s unusable, starting afresh: %s", journal.state_path, exc)
        archive(journal, "unusable")
        return None
    if st is not None:
        log.info(
            "journal: run of %d, phase %s, heading %.1f°, position %s, command in flight %s%s",
            st.run_epoch, st.phase, math.degrees(st.heading),
            [round(v, 3) for v in st.position],
            f"{st.command} {st.command_value:+.3f} (request {st.request_id})"
            if st.command else "none",
            f", final: {st.final}" if st.final else "",
        )  # fmt: skip
    return st


class Resumption:
    """Where a (restarted) agent starts, and its state restored from the journal that
    ``journaling`` writes: the beliefs, the record (the crew's survey), the agreement (its
    fleet), the plan (its planner, into its course) and the leg."""

    def __init__(self, journaling: Journaling, crew: Crew) -> None:
        self.journaling = journaling
        self.ctx = crew.ctx
        self.fleet = crew.fleet
        self.motion = crew.motion
        self.planner = crew.planner
        self.course = crew.course
        self.survey = crew.survey
        self.runs = RunCheck(crew.ctx, crew.fleet)

    def start(self) -> tuple[Phase, NeighborRecordMsg | None]:
        """Where to start: ``search`` afresh (no journal, or one of a run that is over:
        archived), or where the journal of a run still going says."""
        journal = self.journaling.journal
        if journal is None:
            return Phase.SEARCH, None
        self.journaling.join_run(journal.opened_ms)  # a new run, unless resumed below
        st = load(journal)
        if st is None:
            return Phase.SEARCH, None
        verdict = self.runs.check(st)
        if not verdict.going:
            log.info("robot %d starts a new run: %s", self.ctx.me, verdict.why)
            archive(journal, verdict.why)
            return Phase.SEARCH, None
        log.info("robot %d: its run is still going: %s", self.ctx.me, verdict.why)
        self.journaling.join_run(st.run_epoch or journal.opened_ms)
        stage, record = self.resume(st, verdict)
        log.info("robot %d resumes at %s (journaled phase %s)", self.ctx.me, stage, st.phase)
        return stage, record

    def resume(
        self, st: JournalState, verdict: Verdict | None = None
    ) -> tuple[Phase, NeighborRecordMsg | None]:
        """Restore the agent from ``st`` (of a run still going: ``verdict``, with what
        the run check learnt; None: ask the fleet here); the stage to go on with
        (``search``, ``agree``, ``wait``, ``move``, ``hold``) and the record to agree
        on. Raises ``AgentFailure`` (a safe stop) when it cannot resume safely.

        While resuming, the journal keeps ``st`` (its phase, record, agreement, leg):
        a crash during the resumption resumes from it again. Only the body's motion is
        journaled meanwhile (:meth:`~agent.recovery.journaling.Journaling.resuming`): the
        heading and position once the command in flight is answered, and each turn of the
        resumption (the heading re-measurement, the turn back to the axis) with its request
        id, so that a second crash neither replays a command nor forgets a turn."""
        journal = self.journaling.journal
        with self.journaling.resuming(st) as motions:
            b = self.ctx.beliefs
            if st.phase in NOT_RESUMED or st.final:
                raise AgentFailure(
                    f"journal says phase {st.phase}{f' ({st.final})' if st.final else ''} "
                    "at the crash: not resumed"
                )
            b.compass_gain = st.compass_gain
            b.heading = st.heading
            b.position = np.array(st.position, dtype=np.float64)
            self.command_in_flight(st)
            if st.command:
                motions.save()  # answered: the beliefs as they are now, nothing in flight
            moved = st.command != "" or abs(wrap_pi(b.heading - NORTH)) > REORIENT_MIN
            sigma = estimate_sigma(st.command, st.command_value, known=bool(st.request_id))
            if st.record is None:
                if moved:
                    self.remeasure_heading(journal, sigma)
                # the new search defines the fixed frame again from here: the start heading
                # is then NORTH − heading, and the body's headings until now are unknown
                self.survey.restarted(wrap_pi(NORTH - b.heading))
                b.heading = NORTH
                return Phase.SEARCH, None
            self.survey.restore(st.record)
            return self.rejoin(st, journal, verdict, moved, sigma)

    def rejoin(
        self,
        st: JournalState,
        journal: Journal | None,
        verdict: Verdict | None,
        moved: bool,
        sigma: float,
    ) -> tuple[Phase, NeighborRecordMsg]:
        """With its record (restored): back into the exchange, or, agreed (by the
        journal, or by the others meanwhile), the agreed records fetched, the plan made
        again and checked against the journal, the heading re-measured before a move or
        a hold (``sigma``: the heading estimate's σ); the stage to go on with."""
        ctx, b = self.ctx, self.ctx.beliefs
        assert st.record is not None
        digest, members, phase = st.agreed_digest, st.agreed_members, st.phase
        if not digest:
            found = verdict.agreed if verdict is not None else agreed_by_others(ctx.bus, st.record)
            if found is None:
                return Phase.AGREE, st.record
            digest, members = found
            phase = Phase.PLAN
            log.info("the others agreed on %s with this robot's record: adopted", digest[:12])
        ctx.report.status(Phase.PLAN, 0.0, "resumed: fetching the agreed records", force=True)
        if verdict is not None and verdict.records and verdict.agreed == (digest, members):
            records = verdict.records
        else:
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
        course = self.course
        if st.plan_digest and course.digest != st.plan_digest:
            raise AgentFailure(
                f"recomputed plan {course.digest[:12]} differs from the journaled "
                f"{st.plan_digest[:12]}: not moving"
            )
        stage = AGREED_STAGES.get(phase, Phase.WAIT)
        if stage in (Phase.MOVE, Phase.HOLD):
            # the pyramid axis (set by the move, which a robot resumed at hold skips): the
            # hold's own check judges the pair against it
            course.face(ctx.formation.goals(course.plan, ctx.me)[1])
        if stage in (Phase.MOVE, Phase.HOLD) and moved:
            self.remeasure_heading(journal, sigma)
            turn = wrap_pi(course.final_heading - b.heading)
            if stage == Phase.HOLD and abs(turn) > REORIENT_MIN:  # face the axis again, as arrived
                self.motion.rotate(turn, PAPER_GAINS, "resumed: turn back to the pyramid axis")
        course.at_leg(st.leg)
        return stage, st.record

    def command_in_flight(self, st: JournalState) -> MotionResult | None:
        """Finish the command in flight at the crash, once: sent again with its journaled
        request id (the world answers a repeat with the first result, the robot does not
        move twice), or, journaled without one (a body without ids), counted as executed.
        The beliefs follow the command once (a contact while walking stops safely)."""
        if not st.command:
            return None
        ctx, b, v = self.ctx, self.ctx.beliefs, st.command_value
        rep = None
        if st.request_id:
            log.info(
                "the %s %+.3f in flight at the crash: asked again with its request id %d",
                st.command, v, st.request_id,
            )  # fmt: skip
            if st.command == "walk":
                rep = ctx.body.walk(v, st.request_id)
            elif st.command == "side":
                rep = ctx.body.side(v, st.request_id)
            else:
                rep = ctx.body.turn(v, st.request_id)
            self.fleet.pump()
            log.info("  answered: %s at t_sim %.2f %s", rep.status, rep.t_sim, rep.detail)
        if st.command == "turn":
            b.heading = wrap_pi(st.heading + v)
        else:
            way = st.heading + (math.pi / 2 if st.command == "side" else 0.0)
            b.position = advance(b.position, way, way, v)
        if rep is not None and rep.status == "contact":
            if st.command != "turn":
                raise AgentFailure(
                    "contact while walking (the step in flight at the crash) at believed "
                    f"{b.position.round(2).tolist()}"
                )
            log.warning("contact while turning (the turn in flight at the crash)")
        return rep

    def remeasure_heading(self, journal: Journal | None, sigma: float) -> None:
        """Turn to θ = 0 (by the estimate, σ ``sigma``), measure the heading against the
        reference view, and weigh the two by their errors (the compass's grows with the
        distance from the reference view's place, the frame's origin)."""
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
        away = float(np.hypot(*b.position))
        fix = fuse(b.heading, sigma, wrap_pi(NORTH + float(res.dtheta)), compass_sigma(away))
        verdict = "weighed in" if fix.accepted else "beyond the gate: kept the estimate"
        log.info(
            "heading re-measured %.1f m from the reference view: %+.1f° off the estimate "
            "%.1f° (σ %.1f° against the compass's %.1f°): %s, heading %.1f° (gain %.2f)",
            away, math.degrees(fix.innovation), math.degrees(b.heading),
            math.degrees(sigma), math.degrees(fix.sigma_compass), verdict,
            math.degrees(fix.heading), fix.gain,
        )  # fmt: skip
        b.heading = fix.heading
        self.motion.last_frame = frame  # the view here: the next turn's compass reference
