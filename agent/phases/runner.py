"""The phase machine of one agent (DESIGN.md §1; NAO paper 5.2.2 (iii) steps 1–7).

SEARCH   sweep the head over [-119.5°, 119.5°] at θ = 0, turn to θ = 180° with the
         rotation control, sweep again (5.2.2 (iii) step 2); complete the circle to
         calibrate the compass against the first image (an addition).
LOCALISE detections → fixed frame (eqs. 7–8) with the compass-estimated heading,
         merged across images.
EXCHANGE/AGREE publish the record, collect every member's, move only once every live
         member published the same digest (agent/core/agreement.py).
EXPLORE  re-search (4.1.3 rule 2, agent/core/formation/research.py): when the agreed records
         leave robots outside the connected fleet, those robots make a deterministic
         exploration move (camera check before each step), and then every robot
         searches again and a new exchange round is agreed; after
         ``research_rounds`` rounds the fleet stops with the reason
         (:meth:`Runner.research`).
PLAN     formation core on the agreed records (4.1.2–4.2): identical on every agent.
WAIT     for every robot of earlier waves to hold (leader first, 5.2.2 step 7).
MOVE     rotation control to face the goal, distance control in 20 cm steps with the
         heading corrected after each (4.2, 5.2.2), then turn to the pyramid axis;
         each step's corridor checked first (an addition, agent/core/control/corridor.py);
         a step's drift too large to be plausible is re-measured, not discarded
         (an addition, :meth:`Runner._confirm_drift`).
HOLD     arrived (status ``hold``); once the whole fleet has arrived and the parent is
         ``done`` (``march``), look at the parent and step by the measured offset error
         (an addition, see :meth:`Runner.correct`), then ``done`` and stay until all are.
MARCH    with a route (issue #13, agent/phases/march.py): after the correction, ``march`` and
         wait until every member is marching; the leader walks the route, followers
         keep station on their parent by vision; then ``done`` as above.

Heading belief: the agent's heading in its fixed frame starts at pi/2 (every robot
faces north at the start, 4.1.1) and changes only by visual-compass measurements of its
own turns and steps (eq. 2), or, when the compass fails, by the turn it commanded.
Position belief: (0, 0) in the fixed frame at the start, dead-reckoned from the
commanded steps along the believed heading. Agents never read ground truth.
"""

from __future__ import annotations

import contextlib
import logging
import time
import traceback
from collections.abc import Callable

from agent.body.base import Body, BodyError
from agent.net.bus import Bus
from agent.phases.agreeing import Agreeing
from agent.phases.config import AgentConfig
from agent.phases.context import AgentFailure, Context
from agent.phases.hold import Hold
from agent.phases.march import MarchHalt
from agent.phases.membership import Membership
from agent.phases.motion import Motion
from agent.phases.research import Research
from agent.phases.safe_steps import SafeSteps
from agent.phases.seams import Formation, Perception
from agent.phases.search import Search
from agent.phases.waves import Waves
from agent.wire import (
    NeighborRecordMsg,
    StatusMsg,
    key_alive,
    key_status,
    reason,
)

log = logging.getLogger("agent.phases.runner")


class Runner:
    """Drives one robot through the phases; :meth:`run` returns the exit code.

    It depends only on the seams of :mod:`agent.phases.seams`: a :class:`~agent.phases.seams.Body`
    (zenoh world, NAOqi or in-process world), a :class:`~agent.phases.seams.Perception` and a
    :class:`~agent.phases.seams.Formation`; the bus carries the exchange between agents.
    """

    def __init__(
        self,
        bus: Bus,
        body: Body,
        config: AgentConfig,
        perception: Perception,
        formation: Formation,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        if body.robot_id != config.robot_id:
            raise ValueError(f"robot {body.robot_id} driven with config for {config.robot_id}")
        self.ctx = Context(bus, body, config, perception, formation, clock)
        self.ctx.journal_hook = self._journal
        self.membership = Membership(self.ctx)
        self.motion = Motion(self.ctx, self.membership)
        self.safe_steps = SafeSteps(self.ctx, self.membership, self.motion)
        self.search = Search(self.ctx, self.motion)
        self.agreeing = Agreeing(self.ctx, self.membership)
        self.research = Research(self.ctx, self.membership, self.motion, self.search)
        self.waves = Waves(self.ctx, self.membership, self.motion, self.safe_steps)
        self.hold = Hold(self.ctx, self.membership, self.motion, self.safe_steps)

    # ================================================================= plumbing

    def _journal(self, command: str = "", value: float = 0.0) -> None:
        """Write the journal (issue #9), before ``command`` is sent; a failing disk is
        logged and the journal given up, never fatal."""
        if self.ctx.journal is None:
            return
        from agent.phases.resume import journal_state

        try:
            self.ctx.journal.save(journal_state(self, command, value))
        except (OSError, ValueError) as exc:
            log.error("journal write failed, journal given up: %s", reason(exc))
            self.ctx.journal = None

    # ================================================================= main

    def run(self) -> int:
        try:
            self.membership.start()
            stage, record = self.resume()
            if stage == "search":
                self.ctx.status("start", 0.0, "joined", force=True)
                record = self.search.localise(self.search.sweep())
            if stage in ("search", "agree"):
                assert record is not None
                while True:  # re-search rounds (4.1.3 rule 2) until the fleet is connected
                    decision = self.agreeing.agree(record)
                    if decision.kind != "agreed":
                        raise AgentFailure(decision.reason)
                    again = self.research.next_round(decision)
                    if again is None:
                        break
                    record = again
                self.waves.make_plan(decision)
            if stage in ("search", "agree", "wait"):
                self.waves.wait_for_earlier_waves()
            if stage in ("search", "agree", "wait", "move"):
                self.waves.move()
            if stage == "done":
                self.hold.finish()
            else:
                self.hold.run()
            return 0
        except (AgentFailure, MarchHalt, BodyError, ValueError) as exc:
            return self.fail(reason(exc))
        except Exception as exc:  # a bug or an input nobody foresaw: stop safely, never crash
            log.error(
                "robot %d: unexpected %s\n%s",
                self.ctx.me,
                reason(exc),
                "".join(traceback.format_tb(exc.__traceback__))[-2000:],
            )
            try:
                return self.fail(f"unexpected {reason(exc)}")
            except Exception as exc2:
                log.error("robot %d could not publish failed: %s", self.ctx.me, reason(exc2))
                return 1
        finally:
            with contextlib.suppress(BodyError):
                self.ctx.body.stop()

    def resume(self) -> tuple[str, NeighborRecordMsg | None]:
        """Where to start: ``search`` afresh, or what the journal says (agent/phases/resume.py)."""
        if self.ctx.journal is None:
            return "search", None
        from agent.phases import resume

        st = resume.load(self.ctx.journal)
        if st is None:
            return "search", None
        stage, record = resume.resume(self, st)
        log.info("robot %d resumes at %s (journaled phase %s)", self.ctx.me, stage, st.phase)
        return stage, record

    def fail(self, reason: str) -> int:
        """Stop safely: publish ``failed`` with ``reason``, let it reach the others; 1."""
        log.error("robot %d failed: %s", self.ctx.me, reason)
        self.ctx.status("failed", 0.0, error=reason, force=True)
        # let the failure status and any pending digest reach the others
        end = self.ctx.clock() + 1.0
        while self.ctx.clock() < end:
            self.membership.pump(0.1)
        return 1


def report_unavailable(bus: Bus, robot_id: int, reason: str) -> int:
    """An agent that cannot run (perception or formation core missing) joins, publishes
    ``failed`` with ``reason`` so the fleet stops safely, and returns exit code 1."""
    log.error("robot %d cannot run: %s", robot_id, reason)
    bus.declare_alive(key_alive(robot_id))
    msg = StatusMsg(sender=robot_id, phase="failed", error=reason[:500])
    bus.publish(key_status(robot_id), msg, "status")
    bus.drain(1.0)
    return 1
