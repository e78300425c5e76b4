"""The circle pattern walked (AUV paper III.B.2.a, Fig. 3 and Fig. 12b; docs/formation.md
"The circle pattern"): with ``--orientation cp`` the agreed plan is the circle round the
frame robot (agent/core/formation/shape/circle_pattern.py), and once the whole fleet
holds it, every agent plans the formation from it, identically, and walks it.

CIRCLE   the agreed plan: the centre robot stands still; the others walk to the circle
         as every plan is walked; each fine-tunes its place from a look at the centre
         (the hold's correction on its parent, agent/phases/hold.py; none with
         ``--no-cp-tune``: the paper's "no tune" rows); ``done`` once every member is.
PLAN     the formation from the circle (agent/core/formation/reshape.py ``from_circle``):
         the robot at 90° of the common frame leads where it stands, the formation faces
         north; its digest chains the circle's.
WAIT, MOVE, HOLD, (MARCH), DONE   as for every plan.
"""

from __future__ import annotations

import logging

from agent.core.formation.reshape import circle_leader, from_circle
from agent.phases.context import AgentFailure, Context
from agent.phases.reporting import Phase
from agent.phases.roles import Course, Fleet
from agent.phases.transitions.reshaping import PLAN_PUMP_S, take
from agent.phases.waves import while_pumping

log = logging.getLogger("agent.phases.transitions.circle_pattern")


class CirclePattern:
    """From the held circle to the formation (module docstring)."""

    def __init__(self, ctx: Context, fleet: Fleet, course: Course) -> None:
        self.ctx = ctx
        self.fleet = fleet
        self.course = course

    def plan(self) -> None:
        """Plan the formation from the circle the fleet holds and follow it;
        AgentFailure when the core finds no safe plan."""
        ctx, report, course = self.ctx, self.ctx.report, self.course
        params = ctx.cfg.plan_params()
        circle = course.common
        leader = circle_leader(circle)
        report.status(Phase.PLAN, 0.0, f"from the circle: robot {leader} leads", force=True)
        try:
            plan = while_pumping(
                lambda: from_circle(circle, params),
                lambda: self.fleet.pump(0.0),
                PLAN_PUMP_S,
            )
        except ValueError as exc:
            raise AgentFailure(f"no plan from the circle: {exc}") from None
        wave = take(ctx, course, plan, params.shape)
        log.info(
            "from the circle %s: plan %s, wave %d, leader %d",
            circle.digest[:12], plan.digest[:12], wave, plan.leader,
        )  # fmt: skip
        report.status(Phase.PLAN, 1.0, f"from the circle: wave {wave}", force=True)
