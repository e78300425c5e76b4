"""Search and localise: what one robot sees from where it stands (NAO paper 5.2.2 (iii)
step 2; 3.1–3.2 localisation; eqs. 7–8 into the fixed frame; 5.1.2 obstacles).

SEARCH   sweep the head over the configured yaws (within ±119.5°) at θ = 0, turn to
         θ = 180° with the rotation control, sweep again; then complete the circle to
         calibrate the compass against the first image (an addition, :meth:`Search.sweep`).
LOCALISE the detections into the fixed frame (eqs. 7–8) with the compass-estimated
         heading, merged across images into this robot's neighbour record (4.1.2),
         with the static obstacles seen (:meth:`Search.localise`).

The head-yaw-0 image taken first *defines* the fixed frame; it is journaled as the
reference view a restarted agent re-measures its heading against (issue #9).
"""

from __future__ import annotations

import logging
import math

import numpy as np

from agent.body.base import Frame
from agent.core.control import PAPER_GAINS, wrap_pi
from agent.core.perception.detector import Detection
from agent.core.perception.obstacles import ObstacleDetection
from agent.phases.context import NORTH, Context
from agent.phases.roles import Mover
from agent.seams import Sightings
from agent.wire import NeighborRecordMsg, reason

log = logging.getLogger("agent.phases.search")


class Search:
    """The search sweeps, the compass calibration and the record (module docstring)."""

    def __init__(self, ctx: Context, motion: Mover) -> None:
        self.ctx = ctx
        self.motion = motion
        self.obstacle_sightings: list[np.ndarray] = []  # fixed frame, one array per image

    def sweep(self) -> list[Sightings]:
        """Sweeps at θ = 0 and θ = 180° (5.2.2 (iii)); returns fixed-frame sightings.

        Addition to the paper: after the second sweep the robot completes the circle
        back to θ = 0. The yaw-0 image taken at the start *defines* the fixed frame, so
        the compass between it and the image after the full circle gives the absolute
        residual r; the compass gain is then (2π + r) / (sum of compass steps), which
        removes the compass's scale error (parallax of the off-axis camera) from the
        θ = 180° sweep and from every later turn, and the heading is known absolutely.
        """
        ctx, b, motion = self.ctx, self.ctx.beliefs, self.motion
        ctx.status("search", 0.0, "sweep at θ = 0°")
        h0 = b.heading  # north at the start; kept from the compass in re-search rounds
        n = 2 * len(ctx.cfg.search_yaws)
        raw: list[tuple[int, list[Detection]]] = []
        obst: list[tuple[int, list[ObstacleDetection]]] = []  # 5.1.2: obstacles seen
        done = 0
        origin: Frame | None = None
        turned = [0.0, 0.0]
        for sweep in range(2):
            if sweep == 1:
                turned[0] = motion.rotate(math.pi, PAPER_GAINS, "turn to θ = 180°")
            for yaw in ctx.cfg.search_yaws:
                frame = motion.look(yaw)
                if abs(yaw) < 1e-9:
                    motion.last_frame = frame
                    if sweep == 0:
                        origin = frame
                raw.append((sweep, ctx.perception.detect(frame.image, yaw)))
                obst.append((sweep, ctx.perception.detect_obstacles(frame.image, yaw)))
                done += 1
                ctx.status(
                    "search", done / n, f"θ = {180 * sweep}°, head {math.degrees(yaw):+.0f}°"
                )
            # the last image of the sweep was not at yaw 0: refresh the compass reference
            motion.last_frame = motion.look(0.0)
            if origin is None:
                origin = motion.last_frame
            if sweep == 0 and ctx.journal is not None:  # the view that defines the fixed frame
                try:
                    ctx.journal.save_reference(origin.image)
                except (OSError, ValueError) as exc:
                    log.error("reference view not journaled: %s", reason(exc))
        heading_180 = b.heading
        turned[1] = motion.rotate(math.pi, PAPER_GAINS, "complete the circle to θ = 0°")
        assert origin is not None and motion.last_frame is not None
        self._calibrate(origin, motion.last_frame, turned, h0)
        if b.compass_gain != 1.0:
            heading_180 = wrap_pi(h0 + b.compass_gain * turned[0])
        self.obstacle_sightings = [
            ctx.perception.obstacles_fixed(o, h0 if sweep == 0 else heading_180)
            for sweep, o in obst
        ]
        return [
            ctx.perception.to_fixed(dets, h0 if sweep == 0 else heading_180) for sweep, dets in raw
        ]

    def _calibrate(
        self, origin: Frame, final: Frame, turned: list[float], h0: float = NORTH
    ) -> None:
        """Compass gain and absolute heading from the full circle (see :meth:`sweep`)."""
        res = self.ctx.perception.measure_turn(origin.image, final.image)
        total = turned[0] + turned[1]
        if not res.ok or total < math.pi:
            log.warning("compass calibration skipped: %s", res.reason if not res.ok else "no turn")
            return
        r = float(res.dtheta)
        gain = (2.0 * math.pi + r) / total
        if not 0.9 <= gain <= 1.1:
            log.warning("compass gain %.4f implausible: kept 1.0", gain)
            return
        self.ctx.beliefs.compass_gain = gain
        self.ctx.beliefs.heading = wrap_pi(h0 + r)
        log.info(
            "compass calibrated over the circle: gain %.4f, residual %+.2f°", gain, math.degrees(r)
        )

    def localise(self, sightings: list[Sightings]) -> NeighborRecordMsg:
        """This robot's record of the current round: the merged neighbours (4.1.2) and
        obstacles (5.1.2) in its fixed frame."""
        ctx = self.ctx
        ctx.status("localise", 0.0)
        pts, ori, conf = ctx.perception.merge(sightings)
        obstacles = ctx.perception.merge_obstacles(self.obstacle_sightings)
        fault = ctx.cfg.sensor_fault
        if fault is not None:  # the evaluation's test tool, never on a real fleet
            log.warning("test tool: this robot's record carries the sensor fault %s", fault)
            pts, ori = fault.apply(pts, ori)
        rec = NeighborRecordMsg(
            sender=ctx.me,
            round=ctx.record_round,
            neighbours=tuple((float(x), float(y)) for x, y in pts),
            orientations=tuple(float(o) for o in ori),
            confidences=tuple(float(c) for c in conf),
            obstacles=tuple((float(x), float(y)) for x, y in obstacles),
        )
        ctx.own_record = rec
        ctx.status("localise", 1.0, f"{len(pts)} neighbours, {len(obstacles)} obstacles")
        return rec
