"""Safe steps: where a robot decides to take a step (an addition to NAO paper 4.2: execution noise
moves robots off their planned corridors).

The papers walk each trajectory open-loop in 20 cm steps (distance control, 4.2). Here
every step is checked first (:meth:`SafeSteps.clear_way`, the rule of
agent/core/control/corridor.py) against the NAOs in the head-yaw-0 image the compass
takes anyway and those seen in the last few steps (a NAO too near or beside the robot is
out of the image but still there):

* **GO**: walk the step (:meth:`agent.phases.motion.Motion.walk_step`);
* **wait**: a NAO blocks the corridor; look again every poll (status detail
  ``waiting: NAO ahead at [x, y]``); a blocker only remembered is re-checked
  (:meth:`SafeSteps._recheck`: step back if too near to see, look at it with the head
  if beside); bounded by ``max_polls``;
* **VIA**: once this robot's patience (its rank in the plan, (wave, id) order) is
  spent, a tangent step round the blocker, until the way to the goal is clear again;
  a tangent step whose own corridor the image after the turn shows blocked is planned
  again from that image once the patience is spent (:meth:`SafeSteps._via_step`).
  Off the plan, a via step clears the members where the plan and their statuses put
  them (standing, or the next stretch of a walking member's path:
  :meth:`SafeSteps._members`) as it clears the NAOs seen; once a via step is walked,
  every later step towards that goal treats them as NAOs seen (they block it).
  A blocker taken for a member that holds its slot, that the plan left out, or that
  has not moved and waits (through the plan) for this robot will not walk on before
  this one passes: the patience is then the first rank's (one poll), whatever this
  robot's rank (at 50 NAOs robot 37, rank ~30, waited 32-33 polls, 80 s of
  the critical chain, for robot 6 standing at its start, whose ``after`` list names 37).
* **jam** (a dense fleet never jams for good, agent/core/formation/waves/jam.py): still blocked once the
  patience is spent, the robot names the member it takes for the blocker (status ``blocked_by``,
  :meth:`SafeSteps._claim`): a robot that has not moved yet and waits for this one
  yields (agent/phases/waves.py). It waits longer for a blocker that has not moved yet
  (up to the wave timeout) than for any other (``max_polls``), then stops naming it;
  and it stops at once with the fleet's reason when a member of the plan has failed.

:meth:`SafeSteps.walk_to` is the distance control to a goal with these checks.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable

import numpy as np

from agent.core.control import PAPER_GAINS, STEP_GAINS, next_leg, wrap_pi
from agent.core.control.corridor import (
    GO,
    VIA,
    CorridorParams,
    Verdict,
    back_off,
    check_step,
    confirmed,
    in_view,
    patience,
    plan_rank,
)
from agent.core.formation.waves.gates import MILESTONE
from agent.core.formation.waves.jam import (
    HOLDING,
    MOVING,
    STOP,
    UNMOVED,
    at_start,
    blocker_of,
    expected_places,
    jam_verdict,
    waits_for,
)
from agent.core.formation.waves.release import tail
from agent.core.nao import CAMERA_HFOV, HEAD_YAW_LIMIT
from agent.phases.context import AgentFailure, Context
from agent.phases.roles import Course, Fleet, Mover

log = logging.getLogger("agent.phases.safe_steps")

#: m: a NAO seen this near a member's expected place is taken for that member (rule 1 of
#: agent/core/formation/waves/jam.py): the detector's range error at 1 m and a step's drift
BLOCKER_MATCH = 0.3
#: m of a walking member's path, beyond the arc its last status gave, that a step off the
#: plan clears: the progress said at each milestone (gates.py), so about one lag
STRETCH = MILESTONE
#: the arcs beyond the status's of the points that stand for that stretch (0.1 m apart)
STRETCH_POINTS = tuple(0.1 * k for k in range(round(STRETCH / 0.1) + 1))


class SafeSteps:
    """The distance control whose every step is checked first (module docstring)."""

    def __init__(self, ctx: Context, fleet: Fleet, motion: Mover, course: Course) -> None:
        self.ctx = ctx
        self.fleet = fleet
        self.motion = motion
        self.course = course  # the plan, once agreed: the ranks, and who a blocker is
        self.corridor = CorridorParams()  # the safe-step check before each step
        self.waits = 0  # polls spent waiting for a clear corridor
        self.vias = 0  # via (tangent) steps taken round a blocking NAO
        #: polls spent on via steps found blocked after the turn (not walked), this goal
        self.refused = 0
        self.seen: list[tuple[np.ndarray, int]] = []  # (NAO seen, fixed frame; at step)
        #: a via step was walked towards this goal: the robot is off its planned path, and
        #: every step clears the members where the plan and their statuses put them
        self.off_plan = False

    def forget(self) -> None:
        """Forget the NAOs seen: they have moved meanwhile (a new move begins)."""
        self.seen = []

    def walk_to(
        self,
        goal: np.ndarray,
        progress: Callable[[float], None],
        backward_within: float = 0.0,
        gate: Callable[[float], None] | None = None,
    ) -> None:
        """Distance control to ``goal`` (fixed frame, m) from the dead-reckoned position,
        each step checked first: ``gate(walk)`` before a step forward (it returns once the
        robot may walk it: agent/phases/waves.py), then :meth:`clear_way` (a blocked step
        waits, then detours by tangent steps round the blocker until the way to the goal
        is clear again)."""
        b = self.ctx.beliefs
        total = float(np.hypot(*(goal - b.position))) or 1.0
        cp = self.corridor
        self.refused = 0
        self.off_plan = False
        side = 0  # the side of the detour under way (0: none)
        for _ in range(200):
            leg = next_leg(b.position, b.heading, goal, backward_within=backward_within)
            if leg is None:
                return
            ahead = min(cp.lookahead, max(0.0, leg.remaining - abs(leg.walk)))
            if side:  # detouring: do the NAOs seen lately still block the way to the goal?
                to_goal = wrap_pi(b.heading + leg.turn)
                wait = patience(self._rank(), cp)
                rel = self._remembered()
                v = check_step(
                    leg.walk, to_goal, rel, cp, wait, side=side, goal=goal - b.position,
                    ahead=ahead, members=self._members(),
                )  # fmt: skip
                if v.action == VIA and self._via_step(v):
                    continue
                side = 0
            why = self.fleet.fleet_stop(self.course.planned)
            if why:
                raise AgentFailure(why)
            if abs(leg.turn) > self.ctx.cfg.rotation_tolerance:
                self.motion.rotate(
                    leg.turn, STEP_GAINS if abs(leg.turn) < math.radians(15) else PAPER_GAINS
                )
            if gate is not None and leg.walk > 0:
                gate(leg.walk)
            v = self.clear_way(leg.walk, goal=goal, ahead=ahead)
            if v.action == VIA:
                side = v.side if self._via_step(v) else 0
                continue
            self.motion.walk_step(leg.walk)
            progress(1.0 - max(0.0, leg.remaining - abs(leg.walk)) / total)
        raise AgentFailure("distance control did not converge in 200 steps")

    def _via_step(self, v: Verdict) -> bool:
        """Turn to the via step's heading, check its corridor again (no further via), walk;
        False, not walked, when that corridor stays blocked past this robot's patience:
        the image after the turn shows what the via was planned without (a NAO out of
        the earlier view, one seen afresh nearer). The caller then plans the detour again
        from what it has seen since (at 50 NAOs robot 37 waited 60 polls, then
        stopped the fleet, facing a NAO that held its slot 0.6 m ahead)."""
        turn = wrap_pi(v.heading - self.ctx.beliefs.heading)
        if abs(turn) > self.ctx.cfg.rotation_tolerance:
            self.motion.rotate(turn, STEP_GAINS if abs(turn) < math.radians(15) else PAPER_GAINS)
        if self.clear_way(v.walk, via=False).action != GO:
            return False
        self.vias += 1
        self.off_plan = True
        self.motion.walk_step(v.walk)
        return True

    def _remembered(self) -> np.ndarray:
        """The NAOs seen in the last ``memory_steps`` steps, relative to here (fixed frame):
        a NAO closer than the detector's range, or beside the robot, is not in the image
        but is still there."""
        keep = [(p, k) for p, k in self.seen if self.motion.steps - k <= self.corridor.memory_steps]
        self.seen = keep
        if not keep:
            return np.zeros((0, 2))
        return np.array([p for p, _ in keep]) - self.ctx.beliefs.position

    def clear_way(
        self, walk: float, via: bool = True, goal: np.ndarray | None = None, ahead: float = 0.0
    ) -> Verdict:
        """Check the next step's corridor and ``ahead`` m of the way beyond it
        (agent/core/control/corridor.py) against the NAOs in
        the yaw-0 image the compass takes anyway and those seen lately: returns GO, or
        (``via``) VIA once this robot's patience (its plan rank) is spent; waits
        meanwhile, looking again every poll (status detail ``waiting: NAO ahead at
        [x, y]``, fixed frame). Past its patience it names its blocker (:meth:`_claim`).
        Bounded (agent/core/formation/waves/jam.py rule 3): AgentFailure after ``max_polls``
        polls, or the wave timeout's worth for a blocker that has not moved yet; at once
        when a member of the plan has failed (rule 4). A via step's own check (``via``
        False) returns its blocked verdict once the patience is spent, for the caller to
        plan the detour again (:meth:`_via_step`); ``max_polls`` such polls for one goal
        end in AgentFailure."""
        b = self.ctx.beliefs
        cp = self.corridor
        rank = now_rank = self._rank()
        long_polls = max(cp.max_polls, int(self.ctx.cfg.wave_timeout / max(cp.poll, 0.1)))
        waited = 0
        while True:
            frame = self.motion.reference()
            self.motion.last_frame = frame
            seen, _, _ = self.ctx.perception.to_fixed(
                self.ctx.perception.detect(frame.image, 0.0), b.heading
            )
            for p in np.asarray(seen, dtype=np.float64).reshape(-1, 2):
                self.seen.append((b.position + p, self.motion.steps))
            members = self._members() if via or self.off_plan else None
            others = self._remembered()
            if self.off_plan and members is not None:  # off the plan: they block as seen
                others = np.vstack([others, members])
            v = check_step(
                walk, b.heading, others, cp, waited if via else 0, now_rank,
                goal=None if goal is None else goal - b.position, ahead=ahead,
                members=members if via else None,
            )  # fmt: skip
            if v.action == GO or (v.action == VIA and via):
                if waited:
                    log.info("corridor: %s after %d poll(s)", v.action, waited)
                self._claim(-1)
                return v
            where = (b.position + v.blockers[0]).round(2).tolist()
            why = self.fleet.fleet_stop(self.course.planned)
            if why:
                raise AgentFailure(why)
            by = ""
            if via and waited >= patience(now_rank, cp):  # patience spent: name the blocker
                blocker = self._blocker(v.blockers[0])
                phase = self.fleet.peer(blocker).phase if blocker >= 0 else ""
                jv = jam_verdict(self.ctx.me, blocker, phase, waited, cp.max_polls, long_polls)
                if jv.action == STOP:
                    self._claim(-1)
                    raise AgentFailure(
                        f"{jv.reason} (way blocked at believed {b.position.round(2).tolist()})"
                    )
                self._claim(blocker)
                by = f" (robot {blocker})" if blocker >= 0 else ""
            elif not via and waited >= patience(now_rank, cp):  # a via step: re-plan it
                self.refused += waited
                if self.refused >= cp.max_polls:
                    raise AgentFailure(
                        f"way blocked for {cp.max_polls} polls at believed "
                        f"{b.position.round(2).tolist()}"
                    )
                log.info(
                    "corridor: via step blocked after %d poll(s): detour planned again", waited
                )
                return v
            report = self.ctx.report
            report.status(
                report.phase, detail=f"waiting: NAO ahead at {where}{by}", force=waited == 0
            )
            self.waits += 1
            waited += 1
            # a NAO that holds its slot (or was left out of the plan) will not walk on:
            # waiting out this robot's rank is no use, so the patience is the first rank's
            now_rank = 0 if self._stands(self._blocker(v.blockers[0])) else rank
            self.fleet.pump(cp.poll)
            if waited and not confirmed(v.blockers[0], seen, cp):
                self._recheck(v.blockers[0], seen, where)
            self.motion.last_frame = None  # look again
            # what the next image shows is seen afresh: a NAO that walked on is forgotten
            if self.seen:
                rel = np.array([p for p, _ in self.seen]) - b.position
                shown = in_view(rel, b.heading, CAMERA_HFOV)
                self.seen = [e for e, gone in zip(self.seen, shown, strict=True) if not gone]

    def _places(self) -> tuple[np.ndarray, dict[int, np.ndarray]]:
        """(where this robot is believed, in the plan's frame; where the other members are
        expected, by the plan and the phases heard: jam.py rule 1; a robot the plan left
        out stands at its start). Nothing without a plan."""
        plan = self.course.planned
        if plan is None:
            return np.zeros(2), {}
        me = self.ctx.me
        here = np.asarray(plan.robot(me).start, dtype=np.float64) + self.ctx.beliefs.position
        others = [int(i) for i in self.ctx.formation.members(plan) if int(i) != me]
        left_out = set(plan.excluded)
        places = expected_places(
            {i: plan.robot(i).start for i in others},
            {i: plan.robot(i).target for i in others},
            {i: "start" if i in left_out else self.fleet.peer(i).phase for i in others},
            {i: self.fleet.peer(i).walked for i in others if i not in left_out},
            {i: plan.robot(i).path() for i in others},
        )
        return here, places

    def _members(self) -> np.ndarray:
        """Where the other members are by the plan and their statuses, relative to this
        robot (fixed frame), seen or not: the expected place of each (:meth:`_places`),
        and for one walking, its path from that place to :data:`STRETCH` m beyond (its
        status may lag its walk by about a milestone). Ids ascending. What a step off the
        plan must clear (corridor.py ``check_step``)."""
        here, places = self._places()
        plan = self.course.planned
        pts: list[np.ndarray] = []
        for i in sorted(places):
            peer = self.fleet.peer(i)
            assert plan is not None  # places come from a plan
            if i in plan.excluded or at_start(peer.phase, peer.walked) or peer.phase != MOVING:
                pts.append(places[i])  # standing: at its start, on its slot
                continue
            path = plan.robot(i).path()
            pts.extend(tail(path, peer.walked + d)[0] for d in STRETCH_POINTS)
        if not pts:
            return np.zeros((0, 2))
        return np.asarray([np.asarray(p, dtype=np.float64) - here for p in pts])

    def _blocker(self, rel: np.ndarray) -> int:
        """The member taken for the NAO at ``rel`` (relative, fixed frame): the one whose
        expected place is nearest (:meth:`_places`); -1 without a plan or a match."""
        here, places = self._places()
        return blocker_of(here + rel, places, BLOCKER_MATCH) if places else -1

    def _stands(self, blocker: int) -> bool:
        """Whether waiting for member ``blocker`` to walk on is no use: it holds its slot,
        the plan left it out (it stands at its start), or it has not moved, or holds on its
        way, and waits, through the plan's ``after`` lists, for this robot (it moves only
        once this robot is past it, or yields once claimed: jam.py rule 2); False for -1
        (no member named)."""
        plan = self.course.planned
        if blocker < 0 or plan is None:
            return False
        phase = self.fleet.peer(blocker).phase
        if blocker in plan.excluded or phase in HOLDING:
            return True
        after = {int(r.robot_id): tuple(int(j) for j in r.after) for r in plan.robots}
        return (phase in UNMOVED or phase == MOVING) and waits_for(after, blocker, self.ctx.me)

    def _claim(self, blocker: int) -> None:
        """Publish that this robot's way is blocked by ``blocker`` (-1: no longer)."""
        report = self.ctx.report
        if blocker == report.figures.blocked_by:
            return
        if blocker >= 0:
            log.info("corridor: blocked by robot %d beyond patience: claimed", blocker)
        report.show_blocked_by(blocker)
        report.status(report.phase, detail=self._claim_text(blocker), force=True)

    @staticmethod
    def _claim_text(blocker: int) -> str:
        return f"blocked by robot {blocker}" if blocker >= 0 else "way clear"

    def _recheck(self, blocker: np.ndarray, seen: np.ndarray, where: list[float]) -> None:
        """A blocker only remembered, not in the yaw-0 image: find out whether it is still
        there. Too near ahead to be seen surely (< FORGET_NEAR): step back (``back_off``); out of
        the yaw-0 image (beside the robot): look at it with the head, forget what that
        image should show and does not, remember what it shows. Otherwise the memory
        would keep a NAO that walked away until this robot's patience ran out."""
        b = self.ctx.beliefs
        back = back_off(blocker[None, :], seen, b.heading, CAMERA_HFOV, self.corridor)
        if back > 0.01:
            log.info("corridor: NAO remembered at %s, too near to see: %.2f m back", where, back)
            self.motion.walk_step(-back)
            return
        if bool(in_view(blocker[None, :], b.heading, CAMERA_HFOV, near=0.0)[0]):
            return  # the yaw-0 image covers it: the loop's own look decides
        bearing = math.atan2(float(blocker[1]), float(blocker[0]))
        yaw = float(np.clip(wrap_pi(bearing - b.heading), -HEAD_YAW_LIMIT, HEAD_YAW_LIMIT))
        frame = self.motion.look(yaw)
        fresh, _, _ = self.ctx.perception.to_fixed(
            self.ctx.perception.detect(frame.image, yaw), b.heading
        )
        if self.seen:
            rel = np.array([p for p, _ in self.seen]) - b.position
            shown = in_view(rel, b.heading + yaw, CAMERA_HFOV)
            self.seen = [e for e, gone in zip(self.seen, shown, strict=True) if not gone]
        for p in np.asarray(fresh, dtype=np.float64).reshape(-1, 2):
            self.seen.append((b.position + p, self.motion.steps))
        log.info(
            "corridor: looked at the NAO remembered at %s (head %+.0f°): %d NAO(s) in view",
            where, math.degrees(yaw), len(fresh),
        )  # fmt: skip

    def _rank(self) -> int:
        """This robot's rank in the shared plan, (wave, id) order (0 without a plan)."""
        plan = self.course.planned
        if plan is None:
            return 0
        return plan_rank([(int(rp.wave), int(rp.robot_id)) for rp in plan.robots], self.ctx.me)
