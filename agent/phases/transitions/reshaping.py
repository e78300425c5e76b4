"""Reshape on command: the held formation becomes another shape (docs/formation.md
"Reshaping", docs/design.md §11; the plan is agent/core/formation/reshape.py).

LISTEN   with ``--reshape-wait S``, once the whole fleet is ``done`` the robot stays,
         ``done``, for S s (again after each reshape), listening for the operator's
         command (:class:`~agent.wire.ReshapeMsg` on ``fleet/reshape``; the bus let through
         only the operator's signature, agent/net/bus.py ``key_owner``; the router lets
         only the operator publish it). No command within S s: the run ends, ``done``.
CHECK    the command must name the plan this robot holds (its ``base``: the digest every
         robot shows in its status) and a shape the core builds with the digest the
         command gives, for this fleet; otherwise it is refused, with the reason in the
         status and the log, and the robot goes on holding. Every robot refuses the same
         commands: the check reads only the command and the agreed plan. A command heard
         before the fleet held is kept and deferred (agent/phases/membership.py says so
         in the status); one for another plan than the held one is refused once it is
         clear that this robot holds another.
PLAN     the transition from the held plan (common frame) to the new shape, identical on
         every agent (computed while the bus is pumped); this robot's belief frame is
         moved to the new plan's start, its held slot (the plan's legs are goals from
         the start, agent/adapters.py ``goals``).
WAIT, MOVE, HOLD, DONE   as for every plan (agent/phases/waves.py, hold.py): the waves'
         release points, checked 20 cm steps, the child's camera check on its parent and
         its correction, ``done`` once every member is, on the new plan (a member
         ``done`` on the old one has not started yet: agent/phases/membership.py
         ``on_plan``).
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Mapping

import numpy as np

from agent.core.formation.plan import Plan
from agent.core.formation.reshape import command_shape, transition_plan
from agent.core.formation.shape.spec import Shape
from agent.core.formation.view.own_frame import in_own_frame
from agent.phases.context import AgentFailure, Context
from agent.phases.reporting import Phase
from agent.phases.roles import Course, Fleet
from agent.phases.waves import while_pumping
from agent.wire import ReshapeMsg

log = logging.getLogger("agent.phases.transitions.reshaping")

#: Seconds between two pumps of the bus while the transition is planned.
PLAN_PUMP_S = 0.1


def take(ctx: Context, course: Course, plan: Plan, shape: Shape) -> int:
    """Follow the transition ``plan`` (common frame) to ``shape`` from the plan the course
    holds: this robot's belief frame moves to the new plan's start, its held slot (the
    plan's legs are goals from the start, agent/adapters.py ``goals``). Its wave."""
    me = ctx.me
    own = in_own_frame(plan, plan.psi_of(me))
    mine = course.plan.robot(me)
    rebase = np.asarray(mine.target, dtype=np.float64) - np.asarray(mine.start, dtype=np.float64)
    ctx.beliefs.position = ctx.beliefs.position - rebase
    course.follow(own, plan, shape)
    wave = int(own.robot(me).wave)
    ctx.report.show_plan(plan.digest, wave)
    return wave


class Reshaping:
    """The robot's reshapes after the fleet holds (module docstring). ``commands``: the
    operator's newest command per plan it reshapes (the membership's); ``walk``: wait for
    the earlier waves, move and hold on the course's plan (the runner's phases)."""

    def __init__(
        self,
        ctx: Context,
        fleet: Fleet,
        commands: Mapping[str, ReshapeMsg],
        course: Course,
        walk: Callable[[], None],
    ) -> None:
        self.ctx = ctx
        self.fleet = fleet
        self.commands = commands
        self.course = course
        self.walk = walk
        #: the commands acted on or refused, by (base, number): each once
        self.seen: set[tuple[str, int]] = set()
        #: the shapes taken, in order (name, plan digest)
        self.taken: list[tuple[str, str]] = []

    def run(self) -> None:
        """Listen and reshape until no command comes for ``reshape_wait`` s."""
        ctx = self.ctx
        wait = ctx.cfg.reshape_wait
        if wait <= 0.0:
            return
        while True:
            cmd = self.listen(ctx.clock() + wait)
            if cmd is None:
                return
            self.reshape(cmd)

    def listen(self, until: float) -> ReshapeMsg | None:
        """The next command for the held plan, or None at ``until`` (commands for other
        plans are refused on the way)."""
        ctx, report = self.ctx, self.ctx.report
        text = f"formation held; listening for a reshape command ({ctx.cfg.reshape_wait:g} s)"
        report.status(Phase.DONE, 1.0, text, force=True)
        while True:
            self.fleet.pump()
            stop = self.fleet.fleet_stop(self.course.planned)
            if stop:
                raise AgentFailure(stop)
            for base, cmd in sorted(self.commands.items()):
                key = (base, cmd.command)
                if key in self.seen:
                    continue
                self.seen.add(key)
                if base == self.course.digest:
                    return cmd
                self.refuse(cmd, f"it reshapes plan {base[:12]}, this robot holds "
                                 f"{self.course.digest[:12]}")  # fmt: skip
            if ctx.clock() >= until:
                log.info("no reshape command for %g s: the run ends", ctx.cfg.reshape_wait)
                return None
            report.status(Phase.DONE, 1.0, text)  # heartbeats
            self.fleet.wait_until(min(until, report.due()))

    def refuse(self, cmd: ReshapeMsg, why: str) -> None:
        """Say why ``cmd`` is refused; the robot goes on holding."""
        log.warning("reshape %d to %s refused: %s", cmd.command, cmd.name, why)
        text = f"reshape {cmd.command} to {cmd.name} refused: {why}"
        self.ctx.report.status(Phase.DONE, 1.0, text[:500], force=True)

    def reshape(self, cmd: ReshapeMsg) -> None:
        """Plan the transition of ``cmd`` and walk it (module docstring)."""
        ctx, report, course = self.ctx, self.ctx.report, self.course
        params = ctx.cfg.plan_params()
        held = course.common
        try:
            shape = command_shape(cmd.name, cmd.rule, cmd.orient, cmd.slots, cmd.shape_digest)
            report.status(Phase.PLAN, 0.0, f"reshape {cmd.command}: {shape.text()}", force=True)
            plan = while_pumping(
                lambda: transition_plan(held, shape, params),
                lambda: self.fleet.pump(0.0),
                PLAN_PUMP_S,
            )
        except ValueError as exc:
            self.refuse(cmd, str(exc))
            return
        wave = take(ctx, course, plan, shape)
        log.info(
            "reshape %d: %s from plan %s, plan %s, wave %d, leader %d",
            cmd.command, shape.text(), held.digest[:12], plan.digest[:12], wave, plan.leader,
        )  # fmt: skip
        report.status(Phase.PLAN, 1.0, f"reshape to {shape.name}: wave {wave}", force=True)
        self.walk()
        self.taken.append((shape.name, plan.digest))
