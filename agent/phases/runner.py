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
import math
import time
import traceback
from collections.abc import Callable

import numpy as np

from agent.body.base import Body, BodyError
from agent.core.agreement import Decision
from agent.core.control import (
    PAPER_GAINS,
    wrap_pi,
)
from agent.core.control.alignment import look_yaws, match_parent
from agent.core.formation.plan import Plan
from agent.core.nao import CAMERA_HFOV, HEAD_YAW_LIMIT
from agent.net.bus import Bus
from agent.phases.agreeing import Agreeing
from agent.phases.config import AgentConfig
from agent.phases.context import AgentFailure, Context
from agent.phases.march import Marcher, MarchHalt
from agent.phases.membership import Membership
from agent.phases.motion import Motion
from agent.phases.record_sets import record_set
from agent.phases.research import Research
from agent.phases.safe_steps import SafeSteps
from agent.phases.seams import Formation, Perception
from agent.phases.search import Search
from agent.wire import (
    NeighborRecordMsg,
    StatusMsg,
    key_alive,
    key_status,
    reason,
)

log = logging.getLogger("agent.phases.runner")

HEARTBEAT = 3.0  # s between statuses while waiting


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

    # ================================================================= phases

    def make_plan(self, decision: Decision[NeighborRecordMsg]) -> Plan:
        self.ctx.status("plan", 0.0, decision.reason)
        try:
            plan = self.ctx.formation.plan(decision.records, self.ctx.cfg.plan_params())
        except ValueError as exc:
            raise AgentFailure(f"planning failed on the agreed records: {exc}") from None
        self.ctx.plan = plan
        self.ctx.plan_digest = str(plan.digest)
        self.membership.served = record_set(self.ctx.me, decision)
        self.membership.pin_sessions({int(r) for r in self.ctx.formation.members(plan)})
        rp = plan.robot(self.ctx.me)
        self.ctx.wave = int(rp.wave)
        self.ctx.status("plan", 1.0, f"wave {self.ctx.wave}, leader {plan.leader}", force=True)
        return plan

    def wait_for_earlier_waves(self) -> None:
        """Start once every robot of this robot's ``after`` list holds its slot (the plan's
        execution rule, ``agent/core/formation/execution.py``; the leader's list is empty)."""
        plan = self.ctx.plan
        members = set(self.ctx.formation.members(plan))
        earlier = sorted(
            int(i)
            for i in plan.robot(self.ctx.me).after
            if int(i) in members and int(i) != self.ctx.me
        )
        deadline = self.ctx.clock() + self.ctx.cfg.wave_timeout
        while True:
            self.membership.pump(0.1)
            pending = []
            for i in earlier:
                peer = self.membership.peer(i)
                if peer.phase in ("hold", "march", "done"):
                    continue
                if peer.seen_alive and not peer.alive:
                    raise AgentFailure(
                        f"robot {i} of wave {plan.robot(i).wave} left before holding"
                    )
                if peer.phase == "failed":
                    raise AgentFailure(f"robot {i} of wave {plan.robot(i).wave} failed")
                pending.append(i)
            if not pending:
                return
            if self.ctx.clock() > deadline:
                raise AgentFailure(f"robots {pending} of earlier waves did not hold in time")
            self.ctx.status("wait", 0.0, f"waiting for wave(s) of {pending}")

    def move(self) -> None:
        plan = self.ctx.plan
        self.motion.last_frame = None  # others moved meanwhile: a fresh compass reference
        self.safe_steps.forget()  # and the NAOs seen before are elsewhere now
        goals, final_heading = self.ctx.formation.goals(plan, self.ctx.me)
        self.ctx.final_heading = final_heading
        self.ctx.status("move", 0.0, f"{len(goals)} leg(s)")
        n = len(goals)
        for k, goal in enumerate(goals):
            if k < self.ctx.leg:
                continue  # walked before a restart (issue #9)
            self.ctx.leg = k

            def progress(p: float, k: int = k) -> None:
                self.ctx.status("move", (k + p) / n, f"leg {k + 1}/{n}")

            self.safe_steps.walk_to(goal, progress)
        self.motion.rotate(
            wrap_pi(final_heading - self.ctx.beliefs.heading), PAPER_GAINS, "turn to pyramid axis"
        )

    def correct(self) -> None:
        """Visual alignment to the parent, once everyone has arrived (an addition).

        The papers walk the plan open-loop; the residual error is dominated by the
        distance estimates of the search (~10 % at 1.2 m, better at d_e). The pyramid
        is defined by parent–child offsets (AUV II: robots follow the robot in front
        by visual servoing), so once the whole fleet has arrived and the parent has
        finished its own correction (``done``), the child looks at where the plan puts
        its parent, measures it and steps by the difference (twice at most). The head
        fans out around the expected bearing until it finds a NAO within
        ``max_correction`` of the planned offset (:meth:`_find_parent`); a NAO farther
        off is another robot or a wrong match, and corrections below 3 cm are not walked.
        """
        plan = self.ctx.plan
        rp = plan.robot(self.ctx.me)
        parent = int(rp.parent)
        if parent < 0 or not self.ctx.cfg.correct:
            return
        deadline = self.ctx.clock() + self.ctx.cfg.wave_timeout
        while True:
            self.membership.pump(0.1)
            peer = self.membership.peer(parent)
            if peer.phase == "failed" or (peer.seen_alive and not peer.alive):
                log.warning("parent %d is gone: no correction", parent)
                return
            if peer.phase in ("done", "march") and self.membership.all_arrived():
                break
            if self.ctx.clock() > deadline:
                log.warning("parent %d did not finish in time: no correction", parent)
                return
            self.ctx.status("hold", 0.5, f"arrived; waiting for parent {parent}")
        expected = np.asarray(plan.robot(parent).target, dtype=np.float64) - np.asarray(
            rp.target, dtype=np.float64
        )
        for attempt in range(2):
            seen = self._find_parent(expected, parent)
            if seen is None:
                return
            err = seen - expected
            size = float(np.hypot(*err))
            log.info(
                "correction %d: parent %d seen at %s, planned %s, step %.3f m",
                attempt + 1, parent, seen.round(3).tolist(), expected.round(3).tolist(), size,
            )  # fmt: skip
            if size < 0.03:
                break
            self.ctx.status("hold", 0.75, f"correcting {size:.2f} m towards parent {parent}")
            self.motion.last_frame = None
            self.safe_steps.walk_to(
                self.ctx.beliefs.position + err, lambda p: None, backward_within=0.5
            )
            self.motion.rotate(
                wrap_pi(self.ctx.final_heading - self.ctx.beliefs.heading), PAPER_GAINS
            )

    def _find_parent(self, expected: np.ndarray, parent: int) -> np.ndarray | None:
        """The parent's measured offset (fixed frame), or None: the head looks at the
        expected bearing, then fans out (agent/core/control/alignment.py look_yaws) until an
        image shows a NAO within ``max_correction`` of the expected offset (match_parent;
        a NAO farther off is another robot, or a wrong match)."""
        bearing = math.atan2(float(expected[1]), float(expected[0]))
        nearest = math.inf
        for yaw in look_yaws(bearing, self.ctx.beliefs.heading, CAMERA_HFOV / 3.0, HEAD_YAW_LIMIT):
            frame = self.motion.look(yaw)
            dets = self.ctx.perception.detect(frame.image, yaw)
            pts, _, _ = self.ctx.perception.to_fixed(dets, self.ctx.beliefs.heading)
            pts = np.asarray(pts, dtype=np.float64).reshape(-1, 2)
            k = match_parent(pts, expected, self.ctx.cfg.max_correction)
            if k is not None:
                return np.asarray(pts[k], dtype=np.float64)
            if len(pts):
                nearest = min(nearest, float(np.min(np.hypot(*(pts - expected).T))))
        if math.isfinite(nearest):
            log.warning(
                "correction: parent %d not seen within %.2f m of %s (nearest NAO %.2f m off)",
                parent, self.ctx.cfg.max_correction, expected.round(3).tolist(), nearest,
            )  # fmt: skip
        else:
            log.warning("correction: parent %d not seen", parent)
        return None

    def hold(self) -> None:
        """Arrived: correct against the parent, march if there is a route, report
        ``done`` and stay until all are."""
        self.ctx.status(
            "hold",
            0.5,
            f"arrived at believed {self.ctx.beliefs.position.round(2).tolist()}",
            force=True,
        )
        self.correct()
        if self.ctx.cfg.march is not None:
            self.ctx.status("march", 0.0, "formation held; waiting for the fleet", force=True)
            self._wait_all(("march", "done", "failed"), "march", "waiting for")
            failed = [i for i, p in self.membership.peers.items() if p.phase == "failed"]
            if failed:
                raise AgentFailure(f"not marching: robot(s) {sorted(failed)} failed")
            self.ctx.status("march", 0.01, "marching", force=True)
            marcher = Marcher(self, self.ctx.cfg.march, self.ctx.final_heading)
            marcher.run()
            log.info(
                "march done at believed %s; worst seen |e_d| %.1f %%, |e_phi| %.1f°",
                self.ctx.beliefs.position.round(2).tolist(), 100 * marcher.worst_range,
                math.degrees(marcher.worst_bearing),
            )  # fmt: skip
        self.finish()

    def finish(self) -> None:
        """``done``, and stay until every member is."""
        self.ctx.status("done", 1.0, "formation held", force=True)
        self._wait_all(
            ("done", "failed"), "done", "formation held; waiting for", self.ctx.cfg.member_grace
        )

    def _wait_all(self, phases: tuple[str, ...], mine: str, text: str, linger: float = 0.0) -> None:
        """Stay (heartbeats) until every live member is in ``phases`` (bounded).

        ``linger``: a member out of reach (its token gone) not yet seen in ``phases`` is
        waited for too, for up to ``linger`` s, while our heartbeats repeat our status: on
        a lossy link (issue #9) a session can stay cut for longer than the membership
        grace, and a final ``done`` published once into a cut session reaches nobody.
        """
        # the plan's members (a member out of reach has left the live set since)
        plan = self.ctx.planned
        members = tuple(self.ctx.formation.members(plan)) if plan is not None else ()
        start = self.ctx.clock()
        deadline = start + self.ctx.cfg.wave_timeout
        while self.ctx.clock() < deadline:
            self.membership.pump(0.2)
            patient = self.ctx.clock() - start < linger
            waiting = [
                i
                for i in members
                if i != self.ctx.me
                and self.membership.peer(i).phase not in phases
                and (self.membership.peer(i).alive or patient)
            ]
            if not waiting and (
                self.membership.agreement is None
                or not self.membership.agreement.due(self.ctx.clock())
            ):
                return
            if self.ctx.clock() - self.ctx.last_status >= HEARTBEAT:
                self.ctx.status(
                    mine, 1.0 if mine == "done" else 0.0, f"{text} {waiting}", force=True
                )
        if mine == "march":
            raise AgentFailure("the fleet did not get ready to march in time")

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
                self.make_plan(decision)
            if stage in ("search", "agree", "wait"):
                self.wait_for_earlier_waves()
            if stage in ("search", "agree", "wait", "move"):
                self.move()
            if stage == "done":
                self.finish()
            else:
                self.hold()
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
