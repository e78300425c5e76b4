"""Marching in formation after ``hold`` (AUV paper §I–II: "the multi-robot
system should march in a pattern", followers "follow the leaders or other robots in
front of them by visual servoing"; NAO paper 4.2 for the 20 cm steps).

**Route.** Part of the agreed parameters (:meth:`agent.config.AgentConfig.agreed_params`),
so every agent derives the same displacement V of the pyramid in the common frame:
``--march D``: V = D·(cos β, sin β) along the pyramid's axis β; ``--march-to X,Y``:
V = (X, Y) − the leader's planned target. The pyramid *translates* by V: its axis keeps
its direction (a route at 90° to the axis moves the pyramid sideways; nobody re-plans),
so every child keeps its parent at the plan's offset, parent target − child target.

**Leader.** Walks from its planned target to target + V in steps of ``march_step``
(10 cm, half a follower's 20 cm), with the visual compass after each step
(``Motion.walk_step``), then turns to the axis. After each step it rests ``march_pause`` times
as long as the step took (a duty cycle of 1 / (1 + pause)): a follower's cycle (look
at the parent, detect, turn, step, compass) takes about three times the leader's
(pause 4: the leader moves at most 10 cm per 5 of its step times), so
the leader's speed is kept well below what its followers can do. Before each step it
reads the statuses: it waits while any follower reports that it has lost its parent
(detail starting with :data:`LOST`), and halts if a member failed or left.

**Followers.** Keep station on their parent by vision alone: each cycle the head turns
to where the parent is predicted, the detector measures it (range, bearing in the
fixed frame), :class:`~agent.core.control.station.StationKeeper` (PI, speed-limited) gives a
displacement (PI; the parent's estimated advance only feeds the prediction) and
:func:`~agent.core.control.station.unicycle_step` a turn of at most 15° (none below 8°) and a
walk, the body kept within 40° of the march direction (so that the parent, ahead at
φ_e off the axis, stays within the head's ±119.5°, and heading drift is turned back) -
or of its opposite, walking backwards, when the parent's planned bearing is more than
90° off the march direction (a route across the axis);
the prediction is the measurement less the step walked plus the parent's advance. No radio is needed for
this; statuses go on being published for viewers. A follower's march ends when it has
stood still for two cycles and its parent reported ``done`` (the radio only says when
the march is over); without that status, when it has covered the route less a margin
by dead reckoning and its parent has been still for ``QUIET`` seconds.

**Losing sight.** A parent not found within ``GATE`` of the prediction is lost: the
follower stops, publishes ``lost parent …``, and searches with its head only (yaw
offsets of ±20°, ±40°, ±60° around the prediction; the body never turns, so never into
a neighbour), ``lost_rounds`` times with a pause in between (the fleet waits meanwhile).
Found: the integrals are reset and the march goes on. Not found: :class:`MarchHalt`
with the reason; the runner publishes ``failed``, and every other agent, seeing a
member failed, stops and halts too.

**Safety.** The safe-step rule holds on the march: a step never ends within 2·radius of
a robot in view unless it moves away from it (:func:`agent.core.control.station.safe_walk`).
"""

from __future__ import annotations

import logging
import math
from typing import TYPE_CHECKING

import numpy as np

from agent.core.control import PAPER_GAINS, STEP_GAINS, next_leg, wrap_pi
from agent.core.control.station import StationGains, StationKeeper, safe_walk, unicycle_step
from agent.core.formation.params import PlanParams
from agent.core.formation.view.route import route_vector, station_offset
from agent.core.nao import HEAD_YAW_LIMIT
from agent.phases.context import Context
from agent.phases.reporting import Phase
from agent.phases.roles import Fleet, Mover

if TYPE_CHECKING:
    from agent.core.formation.plan import Plan
    from agent.core.formation.view.route import Route

log = logging.getLogger("agent.phases.march")

LOST = "lost parent"  # status detail prefix of a follower searching for its parent
GATE = 0.45  # m: a detection this close to the prediction is the parent
SEARCH_GATE = 0.6  # m: wider while searching (the parent may have moved on)
SEARCH_OFFSETS = tuple(math.radians(a) for a in (0, 20, -20, 40, -40, 60, -60))
CLEARANCE = 2.0 * PlanParams().radius  # the safe-step rule's 2·radius
# kF = 0: the leader's steps come in bursts (walk, rest), so the parent's estimated
# advance overshoots in the rests (measured: zig-zags, a lost parent at 6 robots); the
# estimate still feeds the prediction used to find the parent.
GAINS = StationGains(kp=0.8, ki=0.2, kf=0.0)
MAX_OFF = math.radians(40.0)  # a follower's body stays this close to the march direction
QUIET = 20.0  # s of a still parent that end a follower's march without the radio


class MarchHalt(RuntimeError):
    """The march cannot go on safely; the text is the reason (the runner fails with it)."""


class Marcher:
    """One agent's march; :meth:`run` returns when it is over or raises MarchHalt."""

    def __init__(
        self, ctx: Context, fleet: Fleet, motion: Mover, plan: Plan, route: Route, axis: float
    ) -> None:
        self.ctx = ctx
        self.fleet = fleet
        self.motion = motion
        self.plan = plan
        self.route = route
        self.axis = axis
        self.v = route_vector(self.plan, route, axis)
        self.length = float(np.hypot(*self.v))
        self.direction = math.atan2(float(self.v[1]), float(self.v[0]))
        self.members = [int(i) for i in ctx.formation.members(self.plan) if i != ctx.me]
        self.worst_range = 0.0  # largest |e_ρ| / d_ref measured by a follower (its own view)
        self.worst_bearing = 0.0  # largest |e_β| (rad)
        self.seen_last = np.zeros((0, 2))  # the robots in the last image (for the log)

    # ------------------------------------------------------------ fleet checks

    def check_fleet(self) -> None:
        """Halt if a member failed or left (the fleet halts cleanly)."""
        for i in self.members:
            peer = self.fleet.peers.get(i)
            if peer is None:
                continue
            if peer.phase == Phase.FAILED:
                raise MarchHalt(f"halted: robot {i} failed on the march")
            if peer.seen_alive and not peer.alive:
                raise MarchHalt(f"halted: robot {i} left on the march")

    def lost_followers(self) -> list[int]:
        return [
            i
            for i in self.members
            if (p := self.fleet.peers.get(i)) is not None
            and p.phase == Phase.MARCH
            and p.detail.startswith(LOST)
        ]

    def run(self) -> None:
        rp = self.plan.robot(self.ctx.me)
        log.info("march: V = %s (%.2f m), axis %.1f°", self.v.round(3).tolist(), self.length,
                 math.degrees(self.axis))  # fmt: skip
        if int(rp.parent) < 0:
            self.lead()
        else:
            self.follow(int(rp.parent))
        turn = wrap_pi(self.axis - self.ctx.beliefs.heading)
        self.motion.rotate(turn, PAPER_GAINS, "turn to axis")

    # ------------------------------------------------------------ leader

    def lead(self) -> None:
        ctx, b = self.ctx, self.ctx.beliefs
        rp = self.plan.robot(ctx.me)
        start = np.asarray(rp.start, dtype=np.float64).reshape(2)
        goal = np.asarray(rp.target, dtype=np.float64).reshape(2) + self.v - start
        origin = b.position.copy()
        for _ in range(int(self.length / ctx.cfg.march_step) * 4 + 200):
            self.fleet.pump(0.0)
            self.check_fleet()
            lost = self.lost_followers()
            if lost:
                text = f"waiting: {lost} lost their parent"
                ctx.report.status(Phase.MARCH, self._progress(origin), text)
                self.fleet.pump(0.2)
                continue
            leg = next_leg(b.position, b.heading, goal, step=ctx.cfg.march_step, tolerance=0.05)
            if leg is None:
                return
            if abs(leg.turn) > ctx.cfg.rotation_tolerance:
                big = abs(leg.turn) >= math.radians(15)
                self.motion.rotate(leg.turn, PAPER_GAINS if big else STEP_GAINS)
            walk = safe_walk(leg.walk, b.heading, self._others_ahead(), CLEARANCE)
            if walk == 0.0:
                ctx.report.status(Phase.MARCH, self._progress(origin), "a robot ahead: waiting")
                self.fleet.pump(0.5)
                continue
            t0 = ctx.clock()
            self.motion.walk_step(walk)
            text = f"leading: {leg.remaining:.2f} m to go"
            ctx.report.status(Phase.MARCH, self._progress(origin), text)
            rest = ctx.clock() + ctx.cfg.march_pause * (ctx.clock() - t0)
            while ctx.clock() < rest:
                self.fleet.pump(min(0.2, max(0.0, rest - ctx.clock())))
        raise MarchHalt("the leader did not reach the end of the route")

    def _others_ahead(self) -> np.ndarray:
        """Robots in the last yaw-0 image (fixed frame, relative to me)."""
        frame = self.motion.reference()
        pts, _, _ = self.ctx.perception.to_fixed(
            self.ctx.perception.detect(frame.image, 0.0), self.ctx.beliefs.heading
        )
        return np.asarray(pts, dtype=np.float64).reshape(-1, 2)

    def _progress(self, origin: np.ndarray) -> float:
        if self.length <= 0.0:
            return 1.0
        return float(np.dot(self.ctx.beliefs.position - origin, self.v)) / self.length**2

    # ------------------------------------------------------------ follower

    def follow(self, parent: int) -> None:
        ctx, b = self.ctx, self.ctx.beliefs
        offset = station_offset(self.plan, ctx.me)
        beta_ref = math.atan2(offset[1], offset[0])
        keeper = StationKeeper(float(np.hypot(*offset)), beta_ref, GAINS)
        # face the march direction, or march backwards when the parent would be behind
        # (a route across the axis): the parent stays within the head's reach
        ref = self.direction
        if abs(wrap_pi(beta_ref - ref)) > math.pi / 2:
            ref = wrap_pi(ref + math.pi)
        predicted = offset.copy()
        origin = b.position.copy()
        margin = max(0.3, 0.15 * self.length)
        still = 0
        still_since = ctx.clock()
        moves = int(self.length / ctx.cfg.march_step) * 6 + 120  # steps allowed
        deadline = ctx.clock() + ctx.cfg.wave_timeout  # waiting for the parent, bounded
        while moves > 0 and ctx.clock() < deadline:
            self.fleet.pump(0.0)
            self.check_fleet()
            seen = self.sight((predicted, offset), GATE, (0.0,))
            if seen is None:
                seen = self.search(parent, predicted, offset)
                keeper.reset()
            rel, others = seen
            rho, beta = float(np.hypot(*rel)), math.atan2(float(rel[1]), float(rel[0]))
            here = (float(b.position[0]), float(b.position[1]))
            cmd = keeper.update(rho, beta, here)
            self.worst_range = max(self.worst_range, abs(cmd.e_range) / keeper.d_ref)
            self.worst_bearing = max(self.worst_bearing, abs(cmd.e_bearing))
            travelled = self._progress(origin) * self.length
            ctx.report.status(
                Phase.MARCH, self._progress(origin),
                f"parent {parent} at {rho:.2f} m, {math.degrees(beta):+.0f}°",
            )  # fmt: skip
            still = still + 1 if cmd.size == 0.0 else 0
            if still <= 1:
                still_since = ctx.clock()
            parent_done = self.fleet.peer(parent).phase == Phase.DONE
            quiet = ctx.clock() - still_since >= QUIET and travelled >= self.length - margin
            if still >= 2 and (parent_done or quiet):
                log.info("march over: travelled %.2f m, parent at %.2f m %+.1f°", travelled,
                         rho, math.degrees(beta))  # fmt: skip
                return
            ahead = np.asarray(keeper.advance)  # where the parent goes meanwhile
            if cmd.size == 0.0:
                predicted = rel + ahead
                self.fleet.pump(0.3)  # the parent has not moved: give it time to
                continue
            turn, _ = unicycle_step(cmd.dx, cmd.dy, b.heading)
            # keep the body within MAX_OFF of the march direction: the parent stays
            # within the head's reach (±119.5°), and drift is turned back
            off = wrap_pi(b.heading + turn - ref)
            if abs(off) > MAX_OFF:
                turn = wrap_pi(ref + math.copysign(MAX_OFF, off) - b.heading)
            h = b.heading + turn
            walk = cmd.dx * math.cos(h) + cmd.dy * math.sin(h)
            before = b.position.copy()
            moves -= 1
            if turn != 0.0:
                self.motion.rotate(turn, STEP_GAINS)
            walk = safe_walk(walk, b.heading, others, CLEARANCE)
            if abs(walk) >= 0.01:
                self.motion.walk_step(walk)
            predicted = rel - (b.position - before) + ahead
        raise MarchHalt(f"station keeping on parent {parent} did not settle")

    def sight(
        self,
        centres: tuple[np.ndarray, ...],
        gate: float,
        offsets: tuple[float, ...],
        search: bool = False,
    ) -> tuple[np.ndarray, np.ndarray] | None:
        """The parent's relative position (fixed frame) and every robot seen, looking at
        the first centre (the prediction) with the head turned by each offset in turn:
        the detection nearest the first centre within ``gate``, else nearest the next
        (the plan's offset: where the parent is if the pyramid holds); while
        ``search``ing, else the detection at the predicted range (± 0.3 m) and bearing
        (± 35°: the heading belief may have drifted); None if none."""
        ctx, b = self.ctx, self.ctx.beliefs
        predicted = centres[0]
        bearing = math.atan2(float(predicted[1]), float(predicted[0]))
        for off in offsets:
            yaw = wrap_pi(bearing - b.heading + off)
            yaw = float(np.clip(yaw, -HEAD_YAW_LIMIT, HEAD_YAW_LIMIT))
            frame = self.motion.look(yaw)
            dets = ctx.perception.detect(frame.image, yaw)
            pts, _, _ = ctx.perception.to_fixed(dets, b.heading)
            pts = np.asarray(pts, dtype=np.float64).reshape(-1, 2)
            if len(pts) == 0:
                continue
            self.seen_last = pts
            for c in centres:
                d = np.hypot(*(pts - c).T)
                k = int(np.argmin(d))
                if d[k] <= gate:
                    return pts[k], pts
            if search:  # tolerate a heading error: range within 0.3 m, bearing 35°
                rho_c = float(np.hypot(*predicted))
                rho = np.hypot(pts[:, 0], pts[:, 1])
                dbeta = np.abs(
                    (np.arctan2(pts[:, 1], pts[:, 0]) - bearing + np.pi) % (2 * np.pi) - np.pi
                )
                ok = (np.abs(rho - rho_c) <= 0.3) & (dbeta <= math.radians(35))
                if np.any(ok):
                    score = np.where(
                        ok, np.abs(rho - rho_c) / 0.3 + dbeta / math.radians(35), np.inf
                    )
                    k = int(np.argmin(score))
                    return pts[k], pts
        return None

    def search(
        self, parent: int, predicted: np.ndarray, offset: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """Lost: stop, say so, search with the head (never the body); halt if not found."""
        ctx, b = self.ctx, self.ctx.beliefs
        for k in range(ctx.cfg.lost_rounds):
            ctx.report.status(Phase.MARCH, 0.0, f"{LOST} {parent}: head search {k + 1}", force=True)
            log.warning("lost parent %d (predicted at %s, heading %.1f°; last seen %s): "
                        "head search %d", parent, predicted.round(2).tolist(),
                        math.degrees(b.heading), self.seen_last.round(2).tolist(),
                        k + 1)  # fmt: skip
            seen = self.sight((predicted, offset), SEARCH_GATE, SEARCH_OFFSETS, search=True)
            if seen is not None:
                ctx.report.status(Phase.MARCH, 0.0, f"reacquired parent {parent}", force=True)
                return seen
            self.fleet.pump(1.0)  # the fleet stops for us meanwhile
            self.check_fleet()
        raise MarchHalt(
            f"lost sight of parent {parent} on the march: not found in "
            f"{ctx.cfg.lost_rounds} head searches around {predicted.round(2).tolist()}"
        )
