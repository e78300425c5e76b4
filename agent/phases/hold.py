"""Hold, correct, march and finish: what a robot does once it has arrived (docs/design.md §1 step 7,
hold and march; the correction follows AUV paper §II, robots follow the robot in front
by visual servoing; NAO paper 5.2.2 (iii) step 7 for holding).

HOLD     arrived (status ``hold``); once the parent is ``done`` (or ``march``) and no
         robot may still walk near the sight line to it, look at the parent and step by
         the measured offset error (an addition, :meth:`Hold.correct`; meanwhile step
         with the parent, :meth:`Hold._follow`); then measure the pair once more and
         judge it (:meth:`Hold.verify`, docs/design.md §9): out of tolerance, the robot stops
         with the figure instead of reporting done.
MARCH    with a route (march in formation, agent/phases/march.py): ``march`` and wait until every
         member is marching; the leader walks the route, followers keep station on their
         parent by vision.
DONE     ``done``, and stay until every member is, repeating the status as heartbeats
         (:meth:`Hold.wait_all`; a final status published once into a cut session
         reaches nobody on a lossy radio). A member of the plan that failed leaves a hole: every
         waiting robot, and every robot that was done, then stops with the fleet's one
         reason (agent/core/formation/waves/jam.py rule 4: a dense fleet never reports a formation around
         a hole) instead of reporting a formation held.
"""

from __future__ import annotations

import logging
import math

import numpy as np

from agent.core.control import PAPER_GAINS, wrap_pi
from agent.core.control.alignment import look_yaws, match_parent
from agent.core.formation.frame.faults.fault_test import ALPHA
from agent.core.formation.plan import first_shape
from agent.core.formation.shape.verdict import check_edge, facing_misfit, facing_tolerance
from agent.core.formation.view.passers_by import passers_by
from agent.core.formation.view.route import Route
from agent.core.nao import CAMERA_HFOV, HEAD_YAW_LIMIT
from agent.core.perception.sighting_noise import shipped_noise
from agent.phases.context import AgentFailure, Context
from agent.phases.march import Marcher
from agent.phases.membership import Peer, on_plan
from agent.phases.reporting import Phase
from agent.phases.roles import Course, Fleet, Mover, Stepper

log = logging.getLogger("agent.phases.hold")

#: Smallest step of its parent a child follows (m); smaller ones are left to the child's
#: own alignment (measured at 50 NAOs when a follow cost a turn, a step and a turn back:
#: following every 3 cm made each level of the pyramid slower, not faster; since the
#: sidesteps a follow of up to SIDE_MAX turns no more, and the threshold is not re-tuned).
FOLLOW_MIN = 0.08
#: Largest part of a step, across and along the robot's heading, taken as a sidestep and
#: a straight step without turning (m; :meth:`Hold._step`); below SIDE_MIN nothing is
#: walked (the corrections' own threshold is 3 cm over both).
SIDE_MAX = 0.15
SIDE_MIN = 0.005


class Hold:
    """The arrived robot's phases (module docstring)."""

    def __init__(
        self, ctx: Context, fleet: Fleet, motion: Mover, steps: Stepper, course: Course
    ) -> None:
        #: the mask orientation of the parent last found (:meth:`_find_parent`); nan: none
        self.parent_facing = math.nan
        #: why :meth:`_wait_for_parent` gave up, once it has
        self._parent_wait: str | None = None
        #: the parent's offset from the correction's last look, when the robot did not
        #: move after it (:meth:`verify` judges that measurement instead of looking again)
        self._still_seen: np.ndarray | None = None
        #: where this robot believed it stood when it arrived (fixed frame), and how far
        #: it has followed its parent's steps since (:meth:`_follow`)
        self._arrived_at = np.zeros(2)
        self._followed = np.zeros(2)
        self.ctx = ctx
        self.fleet = fleet
        self.motion = motion
        self.steps = steps
        self.course = course

    def run(self, march: bool = True, tune: bool | None = None) -> None:
        """Arrived: correct against the parent, check the pair, march if there is a route
        (and ``march``: not after a reshape), report ``done`` and stay until all are.

        ``tune``: on the circle pattern's circle, whether to correct and check at all (the
        fine tuning on the centre robot, ``--no-cp-tune``); None: every other hold, which
        corrects unless ``--no-correct`` and always checks."""
        ctx, report, course = self.ctx, self.ctx.report, self.course
        where = ctx.beliefs.position.round(2).tolist()
        self._arrived_at = ctx.beliefs.position.copy()
        report.status(Phase.HOLD, 0.5, f"arrived at believed {where}", force=True)
        if tune is None or tune:
            self.correct(ctx.cfg.correct if tune is None else tune)
            self.verify()
        if ctx.cfg.march is not None and march:
            report.status(Phase.MARCH, 0.0, "formation held; waiting for the fleet", force=True)
            self.wait_all((Phase.MARCH, Phase.DONE, Phase.FAILED), Phase.MARCH, "waiting for")
            failed = [i for i, p in self.fleet.peers.items() if p.phase == Phase.FAILED]
            if failed:
                raise AgentFailure(f"not marching: robot(s) {sorted(failed)} failed")
            report.status(Phase.MARCH, 0.01, "marching", force=True)
            route = ctx.cfg.march
            if route.to is not None:  # a point of the common frame, into this robot's
                psi = course.plan.psi_of(ctx.me) if course.planned is not None else 0.0
                c, s = math.cos(psi), math.sin(psi)
                x, y = route.to
                route = Route(to=(c * x + s * y, -s * x + c * y))
            marcher = Marcher(
                ctx, self.fleet, self.motion, course.plan, route, course.final_heading
            )
            marcher.run()
            log.info(
                "march done at believed %s; worst seen |e_d| %.1f %%, |e_phi| %.1f°",
                ctx.beliefs.position.round(2).tolist(), 100 * marcher.worst_range,
                math.degrees(marcher.worst_bearing),
            )  # fmt: skip
            self.verify()  # the march's end is checked the same way
        self.finish()

    def correct(self, enabled: bool = True) -> None:
        """Visual alignment to the parent, once nobody may pass near (an addition; none
        unless ``enabled``).

        The papers walk the plan open-loop; the residual error is dominated by the
        distance estimates of the search (~10 % at 1.2 m, better at d_e). The pyramid
        is defined by parent–child offsets (AUV II: robots follow the robot in front
        by visual servoing), so once the parent has finished its own correction
        (``done``) and nobody may still walk near the sight line
        (:meth:`_wait_for_parent`), the child looks at where the plan puts its parent,
        measures it and steps by the difference (twice at most). The head
        fans out around the expected bearing until it finds a NAO within
        ``max_correction`` of the planned offset (:meth:`_find_parent`); a NAO farther
        off is another robot or a wrong match, and corrections below 3 cm are not walked.
        """
        ctx = self.ctx
        plan = self.course.plan
        rp = plan.robot(ctx.me)
        parent = int(rp.parent)
        if parent < 0 or not enabled:
            return
        why = self._wait_for_parent(parent)
        if why:
            log.warning("%s: no correction", why)
            return
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
            if size < 0.03:  # not walked: this look is already the final state's
                self._still_seen = seen
                break
            ctx.report.status(Phase.HOLD, 0.75, f"correcting {size:.2f} m towards parent {parent}")
            self._step(err)

    def _step(self, by: np.ndarray) -> None:
        """Step by ``by`` (fixed frame), face the pyramid axis again and publish how far
        this robot has now stepped since it arrived (common frame: ``shift``).

        Up to :data:`SIDE_MAX` across the robot's heading is a sidestep and the rest a
        step straight ahead or back, without turning (:meth:`Motion.side_step`); a
        larger step turns to it, walks and turns back (before the sidesteps,
        every correction did: at 50 NAOs a 4 cm correction took ~20 s of turn steps,
        on every level of the pyramid in turn). The sidestep is not checked by the camera,
        which looks ahead: it is short, and it is taken only once no robot may still
        pass near (:meth:`_wait_for_parent`)."""
        ctx = self.ctx
        b = ctx.beliefs
        self.motion.last_frame = None
        u = np.array([math.cos(b.heading), math.sin(b.heading)])
        along = float(by @ u)
        across = float(by[1] * u[0] - by[0] * u[1])  # + to the left
        if abs(across) <= SIDE_MAX and abs(along) <= SIDE_MAX:
            if abs(across) >= SIDE_MIN:
                self.motion.side_step(across)
            if abs(along) >= SIDE_MIN:
                goal = b.position + along * u
                self.steps.walk_to(goal, lambda p: None, backward_within=0.5)
        else:
            self.steps.walk_to(b.position + by, lambda p: None, backward_within=0.5)
        turn = wrap_pi(self.course.final_heading - b.heading)
        if abs(turn) > ctx.cfg.rotation_tolerance:
            self.motion.rotate(turn, PAPER_GAINS)
        moved = ctx.beliefs.position - self._arrived_at
        psi = self.course.plan.psi_of(ctx.me)
        c, s = math.cos(psi), math.sin(psi)  # own frame -> common frame
        shift = (c * moved[0] - s * moved[1], s * moved[0] + c * moved[1])
        report = ctx.report
        report.show_shift(shift)
        text = f"stepped {np.round(shift, 3).tolist()} since arrival"
        report.status(report.phase, 0.75, text, force=True)

    def _follow(self, parent: int) -> None:
        """Step as far as ``parent`` has stepped since it arrived, not yet followed (its
        ``shift``, common frame): while the parent aligns to its own parent, its children
        move with it, so that a correction near the top of the pyramid does not pass down
        it one level after another (at 50 NAOs one robot's 0.15 m made every
        robot below it walk the same 0.15 m in turn, ~8 s a level). Only steps of at least
        :data:`FOLLOW_MIN` and within twice ``max_correction``; the child's own alignment
        measures the parent afterwards."""
        ctx = self.ctx
        peer = self.fleet.peer(parent)
        if peer.phase != Phase.HOLD or peer.plan_digest != self.course.digest:
            return
        psi = self.course.plan.psi_of(ctx.me)
        c, s = math.cos(psi), math.sin(psi)  # common frame -> own frame: turned by -psi
        sx, sy = peer.shift
        want = np.array([c * sx + s * sy, -s * sx + c * sy])
        todo = want - self._followed
        if (
            float(np.hypot(*want)) > 2.0 * ctx.cfg.max_correction
            or float(np.hypot(*todo)) < FOLLOW_MIN
        ):
            return
        log.info("following parent %d: %s m", parent, todo.round(3).tolist())
        self._step(todo)
        self._followed = want

    def _wait_for_parent(self, parent: int) -> str:
        """Wait until ``parent`` is ``done`` (or ``march``) and every robot that may still
        pass near this robot's sight line to it has arrived
        (:func:`~agent.core.formation.view.passers_by.passers_by`: within twice the robot
        radius plus ``max_correction``; before, the whole fleet); "" then, else
        why not (the parent failed, or did not finish within
        ``wave_timeout``; that answer is kept, so the check after the correction does not
        wait a second time).

        A parent out of reach (its token gone and silent for the membership grace) is
        waited for, as the agreement waits for a member out of reach on a lossy radio: on a
        lossy link it is usually this robot's own session that was cut, and the parent
        it cannot hear stands in the formation all the same. Before, a parent out of
        reach stopped this robot at once ("formation unverified").
        """
        ctx = self.ctx
        if self._parent_wait is not None:
            return self._parent_wait
        deadline = ctx.clock() + ctx.cfg.wave_timeout
        # who may still walk near this robot's sight line to its parent (every agent
        # computes the same from the same plan)
        margin = 2.0 * ctx.cfg.plan_params().radius + ctx.cfg.max_correction
        passing = passers_by(self.course.plan, ctx.me, margin)
        why = ""
        self.fleet.pump()
        while True:
            stop = self.fleet.fleet_stop(self.course.planned)
            if stop:
                raise AgentFailure(stop)
            peer = self.fleet.peer(parent)
            if peer.phase == Phase.FAILED:
                why = f"parent {parent} failed"
                break
            clear = self.fleet.arrived(passing, self.course.digest)
            finished = on_plan(peer, (Phase.DONE, Phase.MARCH), self.course.digest)
            if finished and clear:
                break
            if clear and ctx.cfg.correct:
                self._follow(parent)
            gone = peer.seen_alive and not peer.alive
            if ctx.clock() > deadline:
                if finished:
                    why = f"robot(s) passing near did not arrive in time ({list(passing)})"
                else:
                    why = f"parent {parent} {'out of reach' if gone else 'did not finish'} in time"
                break
            state = "out of reach" if gone else "not done"
            text = f"arrived; waiting for parent {parent} ({state})"
            ctx.report.status(ctx.report.phase, 0.5, text)
            self.fleet.wait_until(min(deadline, ctx.report.due()))  # or news
        if why:
            self._parent_wait = why
        return why

    def verify(self) -> None:
        """ "Done" is a measurement (docs/design.md §9): look at the parent and judge the pair.

        The child looks where the plan puts its parent (:meth:`_find_parent`; or takes
        the correction's last look, when it did not move after it) and judges
        the measured offset with the formula the evaluation uses
        (:func:`agent.core.formation.shape.verdict.check_edge`: r_d, r_φ against its slot's
        distance and angle from its parent in the shape's tree). The figures travel in
        every later status. A parent not found within ``max_correction`` of its planned
        place, a pair out of tolerance, or a parent whose mask says it faces further from
        the axis this robot believes in than a sound pair's mask error reaches at the
        fault test's α (:func:`agent.core.formation.shape.verdict.facing_tolerance`: the
        parent's heading or this robot's own is off), stops this robot with the figure:
        the fleet never reports "formation held" on a formation its own camera says is
        wrong. The leader has no parent to check.
        """
        ctx, report = self.ctx, self.ctx.report
        plan = self.course.plan
        rp = plan.robot(ctx.me)
        parent = int(rp.parent)
        if parent < 0:
            return
        why = self._wait_for_parent(parent)
        if why:
            raise AgentFailure(f"formation unverified: {why}")
        expected = np.asarray(plan.robot(parent).target, dtype=np.float64) - np.asarray(
            rp.target, dtype=np.float64
        )
        # the correction's last look, when nothing moved after it; else a look now
        seen, self._still_seen = self._still_seen, None
        if seen is None:
            seen = self._find_parent(expected, parent)
        if seen is None:
            raise AgentFailure(
                f"formation off: parent {parent} not within {ctx.cfg.max_correction:.2f} m "
                "of its planned place"
            )
        params = ctx.cfg.plan_params()
        axis = self.course.final_heading
        # this child's slot in the shape's tree: its distance and angle from its parent
        # a transition's shape, else the agreed plan's (the circle pattern's circle, after
        # a restart too: the journal keeps the plan, not its shape)
        shape = self.course.shape or first_shape(params, len(plan.robots))
        slots = shape.slots(len(plan.robots), params.d_e, params.phi_e)
        _, dist, ang = slots.edge(rp.order)
        check = check_edge(ctx.me, parent, seen, axis, dist, ang, params.phi_e)
        report.show_check(check)
        log.info("own check: %s", check.text())
        if not check.sure:  # with a margin for the camera's own error
            raise AgentFailure(f"formation off: {check.text()}")
        if math.isfinite(self.parent_facing):  # the parent's mask, independent of our frame
            off = facing_misfit(seen, self.parent_facing, axis)
            log.info(
                "own check: parent %d faces %.0f° off the axis (mask)", parent, math.degrees(off)
            )
            if abs(off) > facing_tolerance(shipped_noise().sigma_mask, ALPHA):
                raise AgentFailure(
                    f"formation off: parent {parent} faces {math.degrees(off):+.0f}° from the "
                    "axis this robot believes in (its mask): its heading or this robot's is off"
                )
        # where this robot stands, as measured on its parent's planned place (its fixed
        # frame, from its start): the belief a later plan's legs start from (a
        # transition's goals, agent/adapters.py)
        parent_at = np.asarray(plan.robot(parent).target, dtype=np.float64)
        ctx.beliefs.position = parent_at - seen - np.asarray(rp.start, dtype=np.float64)
        self._face_axis()
        report.status(report.phase, 0.9, f"own check: {check.text()}", force=True)

    def _find_parent(self, expected: np.ndarray, parent: int) -> np.ndarray | None:
        """The parent's measured offset (fixed frame), or None: the head looks at the
        expected bearing, then fans out (agent/core/control/alignment.py look_yaws) until an
        image shows a NAO within ``max_correction`` of the expected offset (match_parent;
        a NAO farther off is another robot, or a wrong match)."""
        ctx = self.ctx
        bearing = math.atan2(float(expected[1]), float(expected[0]))
        turn = wrap_pi(bearing - ctx.beliefs.heading)
        if abs(turn) > HEAD_YAW_LIMIT:  # behind the head's reach: the body turns to it
            log.info("parent %d at %.0f° off the heading: turning to it", parent,
                     math.degrees(turn))  # fmt: skip
            self.motion.rotate(turn, PAPER_GAINS)
        nearest = math.inf
        for yaw in look_yaws(bearing, ctx.beliefs.heading, CAMERA_HFOV / 3.0, HEAD_YAW_LIMIT):
            frame = self.motion.look(yaw)
            dets = ctx.perception.detect(frame.image, yaw)
            pts, _, faces = ctx.perception.to_fixed(dets, ctx.beliefs.heading)
            pts = np.asarray(pts, dtype=np.float64).reshape(-1, 2)
            k = match_parent(pts, expected, ctx.cfg.max_correction)
            if k is not None:
                faces = np.asarray(faces, dtype=np.float64).reshape(-1)
                self.parent_facing = float(faces[k]) if len(faces) > k else math.nan
                return np.asarray(pts[k], dtype=np.float64)
            if len(pts):
                nearest = min(nearest, float(np.min(np.hypot(*(pts - expected).T))))
        if math.isfinite(nearest):
            log.warning(
                "correction: parent %d not seen within %.2f m of %s (nearest NAO %.2f m off)",
                parent, ctx.cfg.max_correction, expected.round(3).tolist(), nearest,
            )  # fmt: skip
        else:
            log.warning("correction: parent %d not seen", parent)
        return None

    def _face_axis(self) -> None:
        """Turn back to the formation's axis after a look that turned the body
        (:meth:`_find_parent`)."""
        turn = wrap_pi(self.course.final_heading - self.ctx.beliefs.heading)
        if abs(turn) > self.ctx.cfg.rotation_tolerance:
            self.motion.rotate(turn, PAPER_GAINS)

    def finish(self) -> None:
        """``done``, and stay until every member is; a member that failed meanwhile
        leaves a hole: stop with the fleet's reason (module docstring)."""
        self.ctx.report.status(Phase.DONE, 1.0, "formation held", force=True)
        self.wait_all(
            (Phase.DONE, Phase.FAILED),
            Phase.DONE,
            "formation held; waiting for",
            self.ctx.cfg.member_grace,
        )
        stop = self.fleet.fleet_stop(self.course.planned)
        if stop:
            raise AgentFailure(stop)

    def _finished(self, peer: Peer, phases: tuple[Phase, ...], mine: Phase) -> bool:
        """Whether ``peer`` is in ``phases`` of this robot's plan; waiting to be ``done``,
        also when it shows a plan this robot never followed: a reshape's, which it
        started only once it was done on this one (agent/phases/transitions/reshaping.py)."""
        if on_plan(peer, phases, self.course.digest):
            return True
        ahead = bool(peer.plan_digest) and peer.plan_digest not in self.course.history
        return mine == Phase.DONE and ahead

    def wait_all(
        self, phases: tuple[Phase, ...], mine: Phase, text: str, linger: float = 0.0
    ) -> None:
        """Stay (heartbeats) until every live member is in ``phases`` (bounded).

        ``linger``: a member out of reach (its token gone) not yet seen in ``phases`` is
        waited for too, for up to ``linger`` s, while our heartbeats repeat our status: on
        a lossy link a session can stay cut for longer than the membership
        grace, and a final ``done`` published once into a cut session reaches nobody.
        """
        ctx, fleet = self.ctx, self.fleet
        # the plan's members (a member out of reach has left the live set since)
        plan = self.course.planned
        members = tuple(ctx.formation.members(plan)) if plan is not None else ()
        start = ctx.clock()
        deadline = start + ctx.cfg.wave_timeout
        fleet.pump()
        while ctx.clock() < deadline:
            patient = ctx.clock() - start < linger
            waiting = [
                i
                for i in members
                if i != ctx.me
                and not self._finished(fleet.peer(i), phases, mine)
                and (fleet.peer(i).alive or patient)
            ]
            agr = fleet.agreement
            if not waiting and (agr is None or not agr.due(ctx.clock())):
                return
            progress = 1.0 if mine == Phase.DONE else 0.0
            ctx.report.status(mine, progress, f"{text} {waiting}")  # on change, or a heartbeat
            # asleep until news, the next status, the linger's end or the deadline
            until = min(deadline, ctx.report.due())
            if patient:
                until = min(until, start + linger)
            fleet.wait_until(until)
        if mine == Phase.MARCH:
            raise AgentFailure("the fleet did not get ready to march in time")
