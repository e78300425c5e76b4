"""Plan, wait and move: the agreed plan executed wave by wave (NAO paper 4.1.2–4.2,
5.2.2 (iii) steps 3–7; AUV III.B–C for the pyramid; docs/design.md §1 steps 5–6).

PLAN  the formation core on the agreed records (identical on every agent): this
      robot's slot, wave and parent (:meth:`Waves.make_plan`; computed in a worker
      thread while this one keeps pumping the bus, :func:`while_pumping`), turned to
      its own fixed frame by its estimated start heading (docs/design.md §9); a robot the
      fleet's check left out stands still and stops with the reason. From then on the agreed
      record set is served (agent/phases/record_sets.py) and only the agreed sessions
      count (agent/phases/membership.py).
WAIT  until its first step's gate is open: every robot it waits for (the plan's ``after``
      lists, agent/core/formation/waves/execution.py) whose path comes near that step is
      past the last point of its path near it (agent/core/formation/waves/gates.py: that
      robot's published ``walked`` along its path, or it holds its slot), leader first:
      an event, never a time; but yield (start now) when the robots it still waits for are
      blocked by it, or wait for one that is (dense fleets never jam for good,
      agent/core/formation/waves/jam.py rule 2); stop with the fleet's reason once a member
      of the plan has failed (rule 4).
MOVE  rotation control to face each leg's goal, distance control in 20 cm steps with
      the heading corrected after each (4.2, 5.2.2), every step checked first: its gate
      (held at, as at the start, until the robots it waits for are past the stretch; the
      same yield and stop) and its corridor (agent/phases/safe_steps.py); then the turn to
      the pyramid axis. A robot restarted mid-move (a crash) goes on from its journaled
      leg. While it walks it publishes how far along its planned path it is (``walked``,
      :func:`~agent.core.formation.waves.release.walked_along`), at once when it passes
      a milestone of its path that robots gated on it wait for (gates.py).

The agreed plan and this robot's way through it (the leg it is on, the pyramid axis it
faces at the end) are the :class:`Itinerary`'s, which the waves write and the hold, the
safe steps and crash recovery read (the :class:`~agent.phases.roles.Course` role).

Long computations while the bus is pumped (so that agreement scales to 50 NAOs and
more: an agent keeps hearing the fleet while it plans): an agent that agreed must go on
answering the agreement while it plans, repeating its digest until every member has
moved on (:mod:`agent.core.agreement`, NAO paper 4.1.2's exchange made loss-tolerant).
At 100 NAOs on 2 cores a plan took minutes; robot 77, planning, repeated nothing
meanwhile, and three members whose copy of its last digest had been dropped stopped on
"no news for 300 s". The plan is the same whatever thread computes it: it reads only the
agreed records and parameters (:func:`plan_pumping`, also for the candidate plan of
agent/phases/agreeing.py).
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from concurrent.futures import TimeoutError as Pending
from typing import TypeVar

from agent.core.agreement import Decision
from agent.core.control import PAPER_GAINS, STEP_LENGTH, wrap_pi
from agent.core.formation.plan import Plan, first_shape
from agent.core.formation.shape.spec import Shape
from agent.core.formation.view.own_frame import in_own_frame
from agent.core.formation.waves.gates import STEP_SLACK, Gates, milestones, predecessors
from agent.core.formation.waves.jam import yields
from agent.core.formation.waves.release import walked_along
from agent.phases.context import NORTH, AgentFailure, Context
from agent.phases.membership import on_plan
from agent.phases.record_sets import record_set
from agent.phases.reporting import Phase
from agent.phases.roles import Course, Fleet, Hearing, Mover, Stepper
from agent.wire import NeighborRecordMsg

log = logging.getLogger("agent.phases.waves")

#: Seconds between two pumps of the bus while the plan is computed.
PLAN_PUMP_S = 0.1

T = TypeVar("T")


def while_pumping(compute: Callable[[], T], pump: Callable[[], None], every: float) -> T:
    """``compute()`` in a worker thread, ``pump()`` here every ``every`` seconds until it
    is done; its result, or its exception raised here (module docstring). A pump that
    raises waits for the computation (the worker is never left running) and raises."""
    if not every > 0:
        raise ValueError(f"every must be > 0 s, got {every}")
    with ThreadPoolExecutor(max_workers=1, thread_name_prefix="plan") as pool:
        job = pool.submit(compute)
        while True:
            try:
                return job.result(timeout=every)
            except Pending:
                if job.done():  # compute itself raised a TimeoutError
                    raise
                pump()


def plan_pumping(ctx: Context, fleet: Hearing, records: tuple[NeighborRecordMsg, ...]) -> Plan:
    """The formation core's plan of ``records`` with this agent's parameters, computed
    while ``fleet`` is pumped (:func:`while_pumping`); ``ValueError`` if it refuses."""
    params = ctx.cfg.plan_params()
    return while_pumping(
        lambda: ctx.formation.plan(records, params), lambda: fleet.pump(0.0), PLAN_PUMP_S
    )


class Itinerary:
    """The agreed plan and this robot's way through it (module docstring): the plan (in
    this robot's fixed frame; left in the common frame for a robot the plan left out)
    and its digest, the leg of the move the robot is on, the pyramid axis it faces at
    the end (north until the goals are known)."""

    def __init__(self) -> None:
        self._plan: Plan | None = None
        self._common: Plan | None = None
        self._shape: Shape | None = None
        self._history: tuple[str, ...] = ()
        self._leg = 0
        self._final_heading = NORTH

    @property
    def planned(self) -> Plan | None:
        """The agreed plan, None before one."""
        return self._plan

    @property
    def plan(self) -> Plan:
        """The agreed plan (after :meth:`Waves.make_plan`); AgentFailure before one."""
        if self._plan is None:
            raise AgentFailure("no plan yet")
        return self._plan

    @property
    def common(self) -> Plan:
        """The agreed plan in the common frame (every agent's, bit for bit: what a
        reshape starts from, agent/core/formation/reshape.py); AgentFailure before one."""
        if self._common is None:
            raise AgentFailure("no plan yet")
        return self._common

    @property
    def shape(self) -> Shape | None:
        """The shape the plan builds when a reshape command chose it; None: the agreed
        parameters' (``--shape``)."""
        return self._shape

    @property
    def history(self) -> tuple[str, ...]:
        """The digests of every plan this robot followed, the current one last."""
        return self._history

    @property
    def digest(self) -> str:
        """The agreed plan's digest ("" before one): the common plan's, on every agent."""
        return "" if self._plan is None else str(self._plan.digest)

    @property
    def leg(self) -> int:
        """The leg of the move this robot is on (0 before the move)."""
        return self._leg

    @property
    def final_heading(self) -> float:
        """The pyramid axis, once the goals are known (north before)."""
        return self._final_heading

    def follow(self, plan: Plan, common: Plan | None = None, shape: Shape | None = None) -> None:
        """``plan`` is the agreed one (``common``: the same in the common frame, when
        ``plan`` is turned to this robot's own; ``shape``: the one a reshape chose); a new
        plan is walked from its first leg."""
        self._plan = plan
        self._common = plan if common is None else common
        if plan.digest not in self._history:
            self._history = (*self._history, str(plan.digest))
        if shape is not None:
            self._shape = shape
        self._leg = 0

    def at_leg(self, leg: int) -> None:
        """The robot is on leg ``leg`` of its move (or resumes there after a crash)."""
        self._leg = leg

    def face(self, final_heading: float) -> None:
        """The pyramid axis this robot faces once it has arrived."""
        self._final_heading = final_heading


def _released(peer_walked: float, at: float, same_plan: bool) -> bool:
    """A robot walking the same plan is past the release point ``at`` of its path."""
    return same_plan and math.isfinite(peer_walked) and peer_walked >= at


class Waves:
    """This robot's part of the plan (module docstring)."""

    def __init__(
        self, ctx: Context, fleet: Fleet, motion: Mover, steps: Stepper, course: Course
    ) -> None:
        self.ctx = ctx
        self.fleet = fleet
        self.motion = motion
        self.steps = steps
        self.course = course
        #: this robot's gates in the plan of the digest they were made for
        self._gates: tuple[str, Gates | None] = ("", None)

    def make_plan(self, decision: Decision[NeighborRecordMsg]) -> Plan:
        """The plan of the agreed ``decision``; AgentFailure if the core refuses it."""
        ctx, report = self.ctx, self.ctx.report
        report.status(Phase.PLAN, 0.0, decision.reason)
        try:
            plan = plan_pumping(ctx, self.fleet, decision.records)
        except ValueError as exc:
            raise AgentFailure(f"planning failed on the agreed records: {exc}") from None
        digest = str(plan.digest)
        report.show_plan(digest, -1)
        if ctx.me in plan.excluded:  # the fleet's check named this robot (docs/design.md §9)
            self.course.follow(plan)
            raise AgentFailure(
                f"left out of the plan, standing still: {plan.verdict or 'sightings do not fit'}"
            )
        # the common frame turned to this robot's fixed frame by its start heading ψ
        common, plan = plan, in_own_frame(plan, plan.psi_of(ctx.me))
        first = first_shape(ctx.cfg.plan_params(), len(plan.robots))  # cp: the circle
        self.course.follow(plan, common, first)
        self.fleet.served = record_set(ctx.me, decision)
        self.fleet.pin_sessions({int(r) for r in ctx.formation.members(plan)}, digest)
        wave = int(plan.robot(ctx.me).wave)
        report.show_plan(digest, wave)
        report.status(Phase.PLAN, 1.0, f"wave {wave}, leader {plan.leader}", force=True)
        return plan

    def _rows(self) -> tuple[tuple[int, ...], list[list[int]], list[list[float]]]:
        """The plan's ids by row, its ``after`` lists and release points by row (a robot
        named without release points must hold its slot: its whole length)."""
        plan = self.course.plan
        ids = plan.ids
        row = {rid: k for k, rid in enumerate(ids)}
        after = [[row[int(j)] for j in r.after if int(j) in row] for r in plan.robots]
        at = [
            [float(x) for j, x in zip(r.after, r.after_at, strict=True) if int(j) in row]
            if len(r.after_at) == len(r.after)
            else [plan.robot(int(j)).length() for j in r.after if int(j) in row]
            for r in plan.robots
        ]
        return ids, after, at

    def gates(self) -> Gates:
        """This robot's gates in the agreed plan (own frame; made once per plan)."""
        plan = self.course.plan
        key, made = self._gates
        if made is None or key != plan.digest:
            ids, after, at = self._rows()
            clearance = 2.0 * self.ctx.cfg.radius
            made = Gates(plan.paths(), after, ids.index(self.ctx.me), clearance, at)
            self._gates = (str(plan.digest), made)
        return made

    def _pending(self, y0: float, y1: float) -> list[int]:
        """The members this robot still waits for before it walks the stretch ``[y0, y1]``
        of its path (gates.py); AgentFailure when one of them left or failed."""
        plan = self.course.plan
        members = set(self.ctx.formation.members(plan))
        ids = plan.ids
        pending = []
        for row, at in self.gates().needs(y0, y1):
            i = ids[row]
            if i not in members or i == self.ctx.me:
                continue
            peer = self.fleet.peer(i)
            if on_plan(peer, (Phase.HOLD, Phase.MARCH, Phase.DONE), self.course.digest):
                continue
            same_plan = peer.plan_digest == self.course.digest
            if peer.phase == Phase.MOVE and _released(peer.walked, at, same_plan):
                continue
            if peer.seen_alive and not peer.alive:
                raise AgentFailure(f"robot {i} of wave {plan.robot(i).wave} left before holding")
            if peer.phase == Phase.FAILED:
                raise AgentFailure(f"robot {i} of wave {plan.robot(i).wave} failed")
            pending.append(i)
        return pending

    def _until_open(self, y0: float, y1: float, phase: Phase, progress: float) -> None:
        """Hold until the gate of the stretch ``[y0, y1]`` is open (module docstring: WAIT,
        and before each step of MOVE), or the robots still pending are jammed on this one
        (yield); AgentFailure with the fleet's reason, or when they do not pass in time."""
        ctx, report = self.ctx, self.ctx.report
        plan = self.course.plan
        members = set(ctx.formation.members(plan))
        after = {int(r.robot_id): tuple(int(j) for j in r.after) for r in plan.robots}
        deadline = ctx.clock() + ctx.cfg.wave_timeout
        held = False
        self.fleet.pump()
        while True:
            why = self.fleet.fleet_stop(plan)
            if why:
                raise AgentFailure(why)
            pending = self._pending(y0, y1)
            if not pending:
                return
            claims = {i: self.fleet.peer(i).blocked_by for i in sorted(members - {ctx.me})}
            to = yields(after, ctx.me, pending, claims)
            if to:
                log.info("yielding to robot(s) %s, blocked by this robot: going on", to)
                report.status(phase, progress, f"yielding to robot(s) {to}", force=True)
                return
            if ctx.clock() > deadline:
                raise AgentFailure(f"robots {pending} of earlier waves did not pass in time")
            if phase == Phase.WAIT:
                report.status(phase, 0.0, f"waiting for wave(s) of {pending}")
            else:  # at once: those gated on this robot place it by its progress
                detail = f"holding at {y0:.2f} m of the path for robot(s) {pending}"
                report.status(phase, progress, detail, force=not held)
                held = True
            self.fleet.wait_until(min(deadline, report.due()))  # or news

    def wait_for_earlier_waves(self) -> None:
        """Start once the gate of the first step is open (module docstring; the plan's
        execution rule, ``agent/core/formation/waves/gates.py``; the leader waits for
        nobody), or once the robots still pending are jammed on this one."""
        self._until_open(0.0, STEP_LENGTH + STEP_SLACK, Phase.WAIT, 0.0)

    def move(self) -> None:
        """Walk the plan's legs from the journaled one on, then face the pyramid axis."""
        ctx, report, course = self.ctx, self.ctx.report, self.course
        plan = course.plan
        self.motion.last_frame = None  # others moved meanwhile: a fresh compass reference
        self.steps.forget()  # and the NAOs seen before are elsewhere now
        goals, final_heading = ctx.formation.goals(plan, ctx.me)
        course.face(final_heading)
        # the milestones of this robot's path that robots gated on it wait for: passing
        # one is news (gates.py)
        ids, after, at = self._rows()
        me = ids.index(ctx.me)
        # (none beyond the last release point: past it nobody waits for news of this one;
        # a robot gated on it only through others waits for its hold)
        gated = [b for b in range(len(ids)) if me in predecessors(after, b)]
        direct = [x for b in gated for j, x in zip(after[b], at[b], strict=True) if j == me]
        through = any(me not in after[b] for b in gated)
        top = plan.robot(ctx.me).length() if through else max(direct, default=0.0)
        releases = milestones(top, direct)
        report.show_walked(walked_along(goals, course.leg, ctx.beliefs.position))
        report.status(Phase.MOVE, 0.0, f"{len(goals)} leg(s)")
        n = len(goals)
        for k, goal in enumerate(goals):
            if k < course.leg:
                continue  # walked before a restart (a crash mid-move)
            course.at_leg(k)

            def progress(p: float, k: int = k) -> None:
                before = report.figures.walked
                walked = max(before, walked_along(goals, k, ctx.beliefs.position))
                report.show_walked(walked)
                news = any(before < x <= walked for x in releases)
                report.status(Phase.MOVE, (k + p) / n, f"leg {k + 1}/{n}", force=news)

            def gate(walk: float, k: int = k) -> None:
                y0 = report.figures.walked
                self._until_open(y0, y0 + abs(walk) + STEP_SLACK, Phase.MOVE, k / n)

            self.steps.walk_to(goal, progress, gate=gate)
        turn = wrap_pi(final_heading - ctx.beliefs.heading)
        self.motion.rotate(turn, PAPER_GAINS, "turn to the formation axis")
