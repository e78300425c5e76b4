"""Plan, wait and move: the agreed plan executed wave by wave (NAO paper 4.1.2–4.2,
5.2.2 (iii) steps 3–7; AUV III.B–C for the pyramid; docs/design.md §1 steps 5–6).

PLAN  the formation core on the agreed records (identical on every agent): this
      robot's slot, wave and parent (:meth:`Waves.make_plan`; computed in a worker
      thread while this one keeps pumping the bus, agent/phases/pumping.py), turned to
      its own fixed frame by its estimated start heading (docs/design.md §9); a robot the
      fleet's check left out stands still and stops with the reason. From then on the agreed
      record set is served (agent/phases/record_sets.py) and only the agreed sessions
      count (agent/phases/membership.py).
WAIT  for every robot of this robot's ``after`` list to walk past its release point
      (the plan's ``after_at``: that robot's published ``walked`` along its path, or it
      holds its slot, so that it need not wait for the whole walk; agent/core/formation/waves/release.py),
      leader first (agent/core/formation/waves/execution.py): an event, never a time; but yield (start
      now) when the robots it still waits for are blocked by it, or wait for one that is (dense
      fleets never jam for good, agent/core/formation/waves/jam.py rule 2); stop with the fleet's reason
      once a member of the plan has failed (rule 4).
MOVE  rotation control to face each leg's goal, distance control in 20 cm steps with
      the heading corrected after each (4.2, 5.2.2), every step checked first
      (agent/phases/safe_steps.py), then the turn to the pyramid axis. A robot restarted
      mid-move (a crash) goes on from its journaled leg. While it walks it publishes
      how far along its planned path it is (``walked``, :func:`~agent.core.formation.waves.release.walked_along`), at once
      when it passes a release point that a robot waits for.
"""

from __future__ import annotations

import logging
import math

from agent.core.agreement import Decision
from agent.core.control import PAPER_GAINS, wrap_pi
from agent.core.formation.plan import Plan
from agent.core.formation.view.own_frame import in_own_frame
from agent.core.formation.waves.jam import yields
from agent.core.formation.waves.release import walked_along
from agent.phases.context import AgentFailure, Context
from agent.phases.pumping import plan_pumping
from agent.phases.record_sets import record_set
from agent.phases.roles import Fleet, Mover, Stepper
from agent.wire import NeighborRecordMsg

log = logging.getLogger("agent.phases.waves")


def _released(peer_walked: float, at: float, same_plan: bool) -> bool:
    """A robot walking the same plan is past the release point ``at`` of its path."""
    return same_plan and math.isfinite(peer_walked) and peer_walked >= at


class Waves:
    """This robot's part of the plan (module docstring)."""

    def __init__(self, ctx: Context, fleet: Fleet, motion: Mover, steps: Stepper) -> None:
        self.ctx = ctx
        self.fleet = fleet
        self.motion = motion
        self.steps = steps

    def make_plan(self, decision: Decision[NeighborRecordMsg]) -> Plan:
        """The plan of the agreed ``decision``; AgentFailure if the core refuses it."""
        ctx = self.ctx
        ctx.status("plan", 0.0, decision.reason)
        try:
            plan = plan_pumping(ctx, self.fleet, decision.records)
        except ValueError as exc:
            raise AgentFailure(f"planning failed on the agreed records: {exc}") from None
        ctx.plan_digest = str(plan.digest)
        if ctx.me in plan.excluded:  # the fleet's check named this robot (docs/design.md §9)
            ctx.plan = plan
            raise AgentFailure(
                f"left out of the plan, standing still: {plan.verdict or 'sightings do not fit'}"
            )
        # the common frame turned to this robot's fixed frame by its start heading ψ
        ctx.plan = plan = in_own_frame(plan, plan.psi_of(ctx.me))
        self.fleet.served = record_set(ctx.me, decision)
        self.fleet.pin_sessions({int(r) for r in ctx.formation.members(plan)})
        ctx.wave = int(plan.robot(ctx.me).wave)
        ctx.status("plan", 1.0, f"wave {ctx.wave}, leader {plan.leader}", force=True)
        return plan

    def wait_for_earlier_waves(self) -> None:
        """Start once every robot of this robot's ``after`` list holds its slot (the plan's
        execution rule, ``agent/core/formation/waves/execution.py``; the leader's list is empty),
        or once the robots still pending are jammed on this one (module docstring)."""
        ctx = self.ctx
        plan = ctx.plan
        members = set(ctx.formation.members(plan))
        mine = plan.robot(ctx.me)
        earlier = sorted(int(i) for i in mine.after if int(i) in members and int(i) != ctx.me)
        # release points (plan arc lengths); none given: each must hold its slot
        at = (
            {int(i): float(x) for i, x in zip(mine.after, mine.after_at, strict=True)}
            if len(mine.after_at) == len(mine.after)
            else {}
        )
        after = {int(r.robot_id): tuple(int(j) for j in r.after) for r in plan.robots}
        deadline = ctx.clock() + ctx.cfg.wave_timeout
        self.fleet.pump()
        while True:
            why = self.fleet.fleet_stop()
            if why:
                raise AgentFailure(why)
            pending = []
            for i in earlier:
                peer = self.fleet.peer(i)
                if peer.phase in ("hold", "march", "done"):
                    continue
                same_plan = peer.plan_digest == ctx.plan_digest
                if peer.phase == "move" and i in at and _released(peer.walked, at[i], same_plan):
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
            claims = {i: self.fleet.peer(i).blocked_by for i in sorted(members - {ctx.me})}
            to = yields(after, ctx.me, pending, claims)
            if to:
                log.info("yielding to robot(s) %s, blocked by this robot: starting now", to)
                ctx.status("wait", 1.0, f"yielding to robot(s) {to}", force=True)
                return
            if ctx.clock() > deadline:
                raise AgentFailure(f"robots {pending} of earlier waves did not hold in time")
            ctx.status("wait", 0.0, f"waiting for wave(s) of {pending}")
            self.fleet.wait_until(min(deadline, ctx.status_due()))  # or news

    def move(self) -> None:
        """Walk the plan's legs from the journaled one on, then face the pyramid axis."""
        ctx = self.ctx
        plan = ctx.plan
        self.motion.last_frame = None  # others moved meanwhile: a fresh compass reference
        self.steps.forget()  # and the NAOs seen before are elsewhere now
        goals, final_heading = ctx.formation.goals(plan, ctx.me)
        ctx.final_heading = final_heading
        # the release points others wait for on this robot's path: passing one is news
        releases = sorted(
            x
            for r in plan.robots
            if len(r.after_at) == len(r.after)
            for i, x in zip(r.after, r.after_at, strict=True)
            if int(i) == ctx.me
        )
        ctx.walked = walked_along(goals, ctx.leg, ctx.beliefs.position)
        ctx.status("move", 0.0, f"{len(goals)} leg(s)")
        n = len(goals)
        for k, goal in enumerate(goals):
            if k < ctx.leg:
                continue  # walked before a restart (a crash mid-move)
            ctx.leg = k

            def progress(p: float, k: int = k) -> None:
                before = ctx.walked
                ctx.walked = max(before, walked_along(goals, k, ctx.beliefs.position))
                news = any(before < x <= ctx.walked for x in releases)
                ctx.status("move", (k + p) / n, f"leg {k + 1}/{n}", force=news)

            self.steps.walk_to(goal, progress)
        turn = wrap_pi(final_heading - ctx.beliefs.heading)
        self.motion.rotate(turn, PAPER_GAINS, "turn to pyramid axis")
