"""Motion: the body's turns and steps, measured by the visual compass (NAO paper 4.2,
eq. 2; 5.2.2 (1) rotation control; §3.2.1 visual compass).

* :meth:`Motion.rotate`: the rotation control (PID, steps of at most 15°) with the
  compass between the head-yaw-0 images before and after each step as feedback.
* :meth:`Motion.walk_step`: one straight step; the compass measures its drift and the
  position is dead-reckoned along the believed heading (eq. 2).
* Compass reads: when the compass fails, the command is believed; a reading far from
  the command is implausible (:func:`_plausible`) and ignored. A step's implausibly
  large drift is re-measured rather than discarded (an addition, as execution noise is real:
  :meth:`Motion._confirm_drift`).

Every command is journaled before it is sent, with the motion request id it is sent with
(crashed agents resume, and survive a second crash: ``Reporter.journal``,
``Body.new_request_id``), so a restarted agent can ask for it again without the robot moving twice;
the last head-yaw-0 image is kept as the next compass reference (:attr:`Motion.last_frame`).
A step whose compass read failed keeps the reference it was read against, once: its drift,
believed 0, is then in the next step's reading, which measures the rotation of both
(:meth:`Motion._next_reference`). Failed reads are missing data; without this, each
lets the heading belief drift by a step's real drift unseen (up to ~9°), and a robot
whose check looks only at its parent cannot see its own heading off.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable

import numpy as np

from agent.body.base import Frame, MotionResult
from agent.core.control import PAPER_GAINS, PidGains, RotationControl, advance, wrap_pi
from agent.phases.context import AgentFailure, Context
from agent.phases.roles import Hearing

log = logging.getLogger("agent.phases.motion")

MAX_TURN_STEP = math.radians(40.0)  # largest turn taken to re-measure a step's drift


def _plausible(measured: float, commanded: float, walking: bool) -> bool:
    """Whether a compass rotation is believable against the command (rad).

    A measurement far from the command is more likely a mismatch than a fall: 10° (or
    60 % of the command) for a turn; 20° for a step, whose drift reaches ~9° in the
    simulator at noise 1 (a larger one is re-measured, :meth:`Motion._confirm_drift`).
    """
    limit = math.radians(20.0 if walking else 10.0)
    return abs(measured - commanded) <= max(limit, 0.6 * abs(commanded))


class Motion:
    """Turns and steps of one robot, with the compass's measurements (module docstring)."""

    def __init__(self, ctx: Context, fleet: Hearing) -> None:
        self.ctx = ctx
        self.fleet = fleet
        self.last_frame: Frame | None = None  # the compass reference (head yaw 0)
        self.carried = False  # last_frame is kept from before a step whose read failed
        self.compass_failures = 0
        self.compass_uses = 0
        self.drift_checks = 0  # implausible step drifts re-measured (_confirm_drift)
        self.steps = 0  # straight steps walked (the age of a sighting)

    def look(self, yaw: float = 0.0) -> Frame:
        """The camera's image at head ``yaw`` (rad); the fleet is heard meanwhile."""
        frame = self.ctx.body.camera(yaw)
        self.fleet.pump()
        return frame

    def reference(self) -> Frame:
        """The compass reference: the last head-yaw-0 image, or a fresh one."""
        if self.last_frame is None:
            self.carried = False
            return self.look(0.0)
        return self.last_frame

    def _next_reference(self, before: Frame, after: Frame, read: bool) -> Frame:
        """The reference after a step: ``after`` when its compass read, else ``before``,
        once. The next step's reading is then against the image from before the failed
        step, and holds that step's drift too (its heading was believed unchanged). The
        images are then two steps (~40 cm) apart; the walk's central band looks along
        the way walked, where that shift moves the view least, and a reading that does
        not match fails as any other. A second failure in a row takes ``after``: the
        image before may be the one that does not match."""
        if read or self.carried:
            self.carried = False
            return after
        self.carried = True
        return before

    def rotate(self, angle: float, gains: PidGains = PAPER_GAINS, label: str = "") -> float:
        """Turn the body by ``angle`` (rad, + CCW) with the rotation control (5.2.2 (1)).

        A ``label`` names the turn in the robot's status: said at once after its first
        step, the turn under way and journaled (a labelled turn is a change of what the
        body does, a few per run, like a phase change: a fault injector waits for it to
        kill a robot whose heading is in doubt), then as progress at the status pace.

        Returns the rotation completed according to the compass (rad)."""
        b = self.ctx.beliefs
        rc = RotationControl(angle, gains=gains, tolerance=self.ctx.cfg.rotation_tolerance)
        report = self.ctx.report
        said = False
        before = self.reference()
        while not (rc.done or rc.exhausted):
            u = rc.next_step()
            rep = self.turn(u)
            self.fleet.pump()
            after = self.look(0.0)
            measured = self._compass(before, after, u)
            rc.record(measured)
            b.heading = wrap_pi(b.heading + measured)
            log.debug(
                "turn t_sim %.2f cmd %+.2f° measured %+.2f° heading %.2f°",
                rep.t_sim, math.degrees(u), math.degrees(measured), math.degrees(b.heading),
            )  # fmt: skip
            before = after
            if label:
                left = f"{label}: {math.degrees(rc.error):+.1f}° to go"
                report.status(report.phase, detail=left, force=not said)
                said = True
            if rep.status == "contact":
                log.warning("contact while turning")
        self.last_frame, self.carried = before, False
        return rc.completed

    def turn(self, angle: float) -> MotionResult:
        """One turn command, journaled with its request id before it is sent."""
        body = self.ctx.body
        rid = body.new_request_id()
        self.ctx.report.journal.save("turn", angle, rid)
        return body.turn(angle, rid)

    def _compass(
        self, before: Frame, after: Frame, commanded: float, walking: bool = False
    ) -> float:
        """The rotation between two head-yaw-0 frames; the command when the compass fails
        or its match is implausible (:meth:`_read`)."""
        value, _, _ = self._read(before, after, commanded, walking)
        return value

    def _read(
        self, before: Frame, after: Frame, commanded: float, walking: bool = False
    ) -> tuple[float, float | None, bool]:
        """(rotation to believe, suspect, read): the compass between two head-yaw-0 frames;
        ``read`` is False when it failed.

        ``walking``: the frames are 20 cm apart, so only the central band of the image
        is matched (see :meth:`agent.adapters.PerceptionAdapter.measure_walk`). When the
        compass fails, the command is believed; when it matches but far from the
        command, the command is believed and the match is returned as ``suspect``
        (a step's real drift may be that large: :meth:`_confirm_drift`)."""
        if walking:
            res = self.ctx.perception.measure_walk(before.image, after.image)
        else:
            res = self.ctx.perception.measure_turn(before.image, after.image)
        self.compass_uses += 1
        if not res.ok:
            self.compass_failures += 1
            log.warning(
                "compass failed (%s): assuming the %s %+.1f°",
                res.reason, "drift" if walking else "command",
                math.degrees(commanded),
            )  # fmt: skip
            return commanded, None, False
        dtheta = float(res.dtheta) * self.ctx.beliefs.compass_gain
        if not _plausible(dtheta, commanded, walking):
            self.compass_failures += 1
            log.warning(
                "compass %+.1f° implausible against %+.1f°: ignored",
                math.degrees(dtheta), math.degrees(commanded),
            )  # fmt: skip
            return commanded, dtheta, True
        return dtheta, None, True

    def _confirm_drift(self, before: Frame, h0: float, suspect: float) -> tuple[Frame, float]:
        """Re-measure a step's drift that the compass reported implausibly large.

        A large drift may be real (a NAO veering strongly: ~9° per 20 cm step in the
        paper's Table 2, several times that under heavy noise) or a wrong match. The
        robot turns by ``-suspect``, the turn the distance control would make next if
        the drift were real, and measures the rotation between the image *before the
        step* and the new one: close to 0 if the drift was real, close to the turn if it
        was a mismatch. Either way that net rotation is the new heading's measurement
        against ``h0``, taken with little image shift in the likely case. Returns (the
        new image, the net rotation since ``before``); when the re-measurement fails or
        fits neither case, the drift is taken as 0 and the turn as commanded (the
        behaviour without this check)."""
        u = float(np.clip(-suspect, -MAX_TURN_STEP, MAX_TURN_STEP))
        self.turn(u)
        self.fleet.pump()
        after = self.look(0.0)
        res = self.ctx.perception.measure_walk(before.image, after.image)
        self.compass_uses += 1
        net = float(res.dtheta) * self.ctx.beliefs.compass_gain if res.ok else math.nan
        if res.ok and (_plausible(net, 0.0, True) or _plausible(net, u, True)):
            self.drift_checks += 1
            log.info(
                "drift %+.1f° re-measured after a %+.1f° turn: net %+.1f° (%s)",
                math.degrees(suspect), math.degrees(u), math.degrees(net),
                "real" if abs(net) < abs(net - u) else "mismatch",
            )  # fmt: skip
            return after, net
        self.compass_failures += 1
        log.warning(
            "drift %+.1f° not confirmed (%s): assuming none",
            math.degrees(suspect), res.reason if not res.ok else f"net {math.degrees(net):+.1f}°",
        )  # fmt: skip
        return after, u

    def _step(
        self, command: str, distance: float, send: Callable[[float, int], MotionResult]
    ) -> tuple[Frame, Frame, MotionResult, float, float | None, bool]:
        """What a straight step and a sidestep share: the command journaled with its
        request id and sent, then the compass between the yaw-0 images before and after
        (the walk's central band, :meth:`_read`). Returns (before, after, the body's
        result, drift, suspect, whether the compass read)."""
        before = self.reference()
        rid = self.ctx.body.new_request_id()
        self.ctx.report.journal.save(command, distance, rid)
        rep = send(distance, rid)
        self.steps += 1
        self.fleet.pump()
        after = self.look(0.0)
        drift, suspect, read = self._read(before, after, 0.0, walking=True)
        return before, after, rep, drift, suspect, read

    def walk_step(self, distance: float) -> MotionResult:
        """One straight step, the compass's drift and dead reckoning (4.2, eq. 2); a
        drift too large to be plausible is re-measured (:meth:`_confirm_drift`)."""
        b = self.ctx.beliefs
        h0, p0 = b.heading, b.position
        before, after, rep, drift, suspect, read = self._step("walk", distance, self.ctx.body.walk)
        turned = 0.0
        if suspect is not None and rep.status != "contact":
            # the step is over: believed (drift unknown yet) before the re-measuring
            # turn is journaled, so that a crash during that turn does not undo the step
            b.position = advance(p0, h0, h0, distance)
            after, net = self._confirm_drift(before, h0, suspect)
            turned = float(np.clip(-suspect, -MAX_TURN_STEP, MAX_TURN_STEP))
            drift = net - turned  # the turn taken as commanded, for dead reckoning
        b.heading = wrap_pi(h0 + drift + turned)
        self.last_frame = self._next_reference(before, after, read)
        b.position = advance(p0, h0, wrap_pi(h0 + drift), distance)
        log.debug(
            "walk t_sim %.2f %.3f m drift %+.2f° heading %.2f° position %s",
            rep.t_sim, distance, math.degrees(drift), math.degrees(b.heading),
            b.position.round(3).tolist(),
        )  # fmt: skip
        if rep.status == "contact":
            raise AgentFailure(f"contact while walking at believed {b.position.round(2).tolist()}")
        return rep

    def side_step(self, distance: float) -> MotionResult:
        """One sidestep (+ to the left; NAOqi's ``moveTo(0, y, 0)``) and dead reckoning:
        the position moves ``distance`` across the believed heading, the heading by the
        compass's reading between the images before and after (the walk's central band;
        an implausible reading is taken as no drift). An addition to the papers, which
        only walk straight and turn: a NAO steps sideways by itself, and the final
        alignment's few centimetres across the axis (:mod:`agent.phases.hold`) otherwise
        cost a turn there and back (at 50 NAOs, ~20 s of turn steps for 4 cm)."""
        b = self.ctx.beliefs
        h0, p0 = b.heading, b.position
        before, after, rep, drift, suspect, read = self._step("side", distance, self.ctx.body.side)
        if suspect is not None:
            drift = 0.0
        b.heading = wrap_pi(h0 + drift)
        self.last_frame = self._next_reference(before, after, read)
        across = math.pi / 2
        b.position = advance(p0, h0 + across, wrap_pi(h0 + drift) + across, distance)
        if rep.status == "contact":
            raise AgentFailure(
                f"contact while stepping sideways at believed {b.position.round(2).tolist()}"
            )
        return rep
