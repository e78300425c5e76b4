"""Re-search rounds: robots left outside the fleet explore and every robot searches again
(NAO paper 4.1.3 rule 2; the decision is agent/core/formation/frame/research.py).

When the agreed records leave robots outside the connected fleet, every agent decides
alike who is outside and where each of those robots moves. Those robots make their
deterministic exploration move, checked with the camera before each step
(:meth:`Research.explore`); the others stand still until each of them has published a
record or digest of the new round (:meth:`Research.wait_for_searchers`). Then every
robot searches again from where it stands and the caller agrees the new round. After
``research_rounds`` rounds the fleet stops with the reason.
"""

from __future__ import annotations

import logging

import numpy as np

from agent.core.agreement import Decision
from agent.core.control import PAPER_GAINS, next_leg
from agent.core.formation.frame.research import step_blocked
from agent.phases.context import AgentFailure, Context
from agent.phases.reporting import Phase
from agent.phases.roles import Fleet, Mover, Surveyor
from agent.wire import NeighborRecordMsg

log = logging.getLogger("agent.phases.research")


class Research:
    """The re-search rounds of one robot (module docstring)."""

    def __init__(self, ctx: Context, fleet: Fleet, motion: Mover, search: Surveyor) -> None:
        self.ctx = ctx
        self.fleet = fleet
        self.motion = motion
        self.search = search

    def next_round(self, decision: Decision[NeighborRecordMsg]) -> NeighborRecordMsg | None:
        """Re-search (NAO paper 4.1.3 rule 2) on the agreed records: ``None`` when the
        fleet is connected, else this robot's record of the next round.

        Every agent decides alike from the agreed records (agent/core/formation/frame/research.py).
        The robots outside the kept group make their exploration move, checked with the
        camera before each step (:meth:`explore`); the others wait until each of them
        has published a record or digest of the new round (it has walked and searched),
        so that the robots it now sees look again too (eq. 9 needs both sides). Then
        every robot searches again with its record's origin where it stands (the fixed
        frame moves with it, 4.1.1; the heading belief is kept from the compass), and
        the caller agrees the new round. After ``research_rounds`` rounds the fleet
        stops: the reason names who is still outside.
        """
        ctx = self.ctx
        k = self.search.round + 1
        verdict = ctx.formation.research(decision.records, k, ctx.cfg.explore_step)
        if verdict.connected:
            return None
        if verdict.blind:
            cal = ctx.cfg.calibration[:12] or "built-in"
            raise AgentFailure(f"{verdict.reason} (calibration {cal}): stopping")
        if k > ctx.cfg.research_rounds:
            raise AgentFailure(
                f"{verdict.reason} after {ctx.cfg.research_rounds} re-search round(s): "
                "stopping (4.1.3 rule 2)"
            )
        log.info("re-search round %d: %s", k, verdict.reason)
        self.search.begin_round(k)
        self.fleet.retire()
        if ctx.me in verdict.searchers:
            ctx.report.status(Phase.EXPLORE, 0.0, f"round {k}: {verdict.reason}", force=True)
            self.explore(verdict.move(ctx.me))
        else:
            self.wait_for_searchers(verdict.searchers)
        ctx.beliefs.position = np.zeros(2)  # the new record's origin: here
        self.motion.last_frame = None
        return self.search.localise(self.search.sweep())

    def explore(self, move: np.ndarray) -> None:
        """Walk the exploration ``move`` (fixed frame, m) in steps; before each step the
        yaw-0 image is checked: a NAO inside the step's sweep (2·radius + 0.1 m wide,
        :func:`~agent.core.formation.frame.research.step_blocked`) ends the move there."""
        ctx, b, motion = self.ctx, self.ctx.beliefs, self.motion
        goal = b.position + np.asarray(move, dtype=np.float64)
        total = float(np.hypot(*move)) or 1.0
        clearance = 2.0 * ctx.cfg.radius + 0.1
        motion.last_frame = None
        for _ in range(200):
            leg = next_leg(b.position, b.heading, goal)
            if leg is None:
                return
            if abs(leg.turn) > ctx.cfg.rotation_tolerance:
                motion.rotate(leg.turn, PAPER_GAINS, "explore: turn")
            frame = motion.reference()
            motion.last_frame = frame
            pts, _, _ = ctx.perception.to_fixed(
                ctx.perception.detect(frame.image, frame.yaw), b.heading
            )
            hit = step_blocked(pts, b.heading, leg.walk, clearance)
            if hit is not None:
                log.info(
                    "explore: a NAO at %s blocks the next step: move ends at believed %s",
                    pts[hit].round(2).tolist(), b.position.round(2).tolist(),
                )  # fmt: skip
                ctx.report.status(Phase.EXPLORE, 1.0, "a NAO ahead: move ended", force=True)
                return
            motion.walk_step(leg.walk)
            done = 1.0 - max(0.0, leg.remaining - abs(leg.walk)) / total
            ctx.report.status(Phase.EXPLORE, done, f"round {self.search.round}: exploring")
        raise AgentFailure("exploration move did not converge in 200 steps")

    def wait_for_searchers(self, searchers: tuple[int, ...]) -> None:
        """Stand still until every searcher published a record or digest of this round."""
        ctx, fleet = self.ctx, self.fleet
        k = self.search.round
        deadline = ctx.clock() + ctx.cfg.research_timeout
        text = f"round {k}: waiting for robots {list(searchers)} to explore and search"
        ctx.report.status(Phase.EXPLORE, 0.0, text, force=True)
        fleet.pump()
        while True:
            pending = []
            for i in searchers:
                rec, dig = fleet.early_records.get(i), fleet.early_digests.get(i)
                if (rec is not None and rec.round >= k) or (dig is not None and dig.round >= k):
                    continue
                peer = fleet.peer(i)
                if peer.phase == Phase.FAILED:
                    raise AgentFailure(f"robot {i} failed in re-search round {k}")
                if peer.seen_alive and not peer.alive:
                    raise AgentFailure(f"robot {i} left in re-search round {k}")
                pending.append(i)
            if not pending:
                return
            if ctx.clock() > deadline:
                raise AgentFailure(
                    f"robots {pending} did not search again within "
                    f"{ctx.cfg.research_timeout:g} s (re-search round {k})"
                )
            ctx.report.status(Phase.EXPLORE, 0.0, text)
            fleet.wait_until(min(deadline, ctx.report.due()))  # or news
