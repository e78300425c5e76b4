"""Search and localise: what one robot sees from where it stands (NAO paper 5.2.2 (iii)
step 2; 3.1–3.2 localisation; eqs. 7–8 into the fixed frame; 5.1.2 obstacles).

SEARCH   sweep the head over the configured yaws (within ±119.5°) at θ = 0, turn to
         θ = 180° with the rotation control, sweep again; the half turn is measured
         where the two sweeps' views overlap, which calibrates the compass (an
         addition; the circle is completed only when those views do not agree,
         :meth:`Search.sweep`).
LOCALISE the detections into the fixed frame (eqs. 7–8) with the compass-estimated
         heading, merged across images into this robot's neighbour record (4.1.2),
         with the static obstacles seen (:meth:`Search.localise`).

The head-yaw-0 image taken first *defines* the fixed frame; it is journaled as the
reference view a restarted agent re-measures its heading against after a crash.

The search owns this robot's record and the re-search round it belongs to (4.1.3 rule 2:
:meth:`Search.begin_round`, by agent/phases/research.py); a restarted agent restores
them from its journal (:meth:`Search.restore`, agent/recovery/resume.py).
"""

from __future__ import annotations

import logging
import math

import numpy as np

from agent.body.base import Frame
from agent.core.control import PAPER_GAINS, wrap_pi
from agent.core.perception.detector import Detection
from agent.core.perception.half_turn import half_turn, overlap_pairs
from agent.core.perception.obstacles import ObstacleDetection
from agent.phases.context import NORTH, Context
from agent.phases.reporting import Phase
from agent.phases.roles import Mover
from agent.seams import Sightings
from agent.wire import NeighborRecordMsg

log = logging.getLogger("agent.phases.search")


class Search:
    """The search sweeps, the compass calibration and the record (module docstring)."""

    def __init__(self, ctx: Context, motion: Mover) -> None:
        self.ctx = ctx
        self.motion = motion
        self.obstacle_sightings: list[np.ndarray] = []  # fixed frame, one array per image
        self._round = 0  # the re-search round of the current record (4.1.3 rule 2)
        self._record: NeighborRecordMsg | None = None
        # the last sweep's image times (one per element of what sweep() returned) and this
        # body's stances (from, to, heading from the start heading): docs/design.md §9
        # "Masks seen mid-turn"
        self._image_times: list[float] = []
        self._stances: list[tuple[float, float, float]] = []
        #: set by :meth:`restarted`: the start heading in this process's fixed frame
        self._restart: float | None = None

    @property
    def round(self) -> int:
        """The re-search round this robot searches in (0: the first search)."""
        return self._round

    @property
    def record(self) -> NeighborRecordMsg | None:
        """This robot's record of the current round, once localised (or restored)."""
        return self._record

    def begin_round(self, round_: int) -> None:
        """A re-search round begins: the next record is of round ``round_``."""
        self._round = round_

    def restore(self, record: NeighborRecordMsg) -> None:
        """The record journaled before a crash, and its round, as this robot's."""
        self._round, self._record = record.round, record

    def restarted(self, start_heading: float) -> None:
        """This process searches after a crash of the agent (agent/recovery/resume.py): its
        fixed frame is defined again, and the body's headings since it was set down are
        unknown, with ``start_heading`` (rad, in the new frame) its heading at the start.
        The record's stances then begin with the instant it was set down, ``(0, 0,
        start_heading)``, so that a mask of this robot taken before this search (while
        its body stood where the crash left it, or turned) falls between stances and is
        set aside (docs/design.md §9, "Masks seen mid-turn"), instead of being read at the
        first stance's heading, as a robot that stood still since it was set down."""
        self._restart = wrap_pi(start_heading)

    def sweep(self) -> list[Sightings]:
        """Sweeps at θ = 0 and θ = 180° (5.2.2 (iii)); returns fixed-frame sightings.

        Addition to the paper: the half turn between the sweeps is measured absolutely
        where the two sweeps' views overlap (the head at ±119.5° after it looks where the
        head at ∓60.5° looked before: :mod:`agent.core.perception.half_turn`). The compass
        gain is then (that turn) / (sum of compass steps), which removes the compass's
        scale error (parallax of the off-axis camera) from the θ = 180° sweep and from
        every later turn, and the heading is known absolutely. When the overlapping views
        do not agree (too few features, say), the robot completes the circle to θ = 0
        instead and the compass between the yaw-0 image that *defines* the fixed frame
        and the last one gives the residual r over 2π (:meth:`_calibrate`).
        """
        ctx, b, motion = self.ctx, self.ctx.beliefs, self.motion
        ctx.report.status(Phase.SEARCH, 0.0, "sweep at θ = 0°")
        h0 = b.heading  # north at the start; kept from the compass in re-search rounds
        yaws = ctx.cfg.search_yaws
        n = 2 * len(yaws)
        pairs = overlap_pairs(yaws)
        kept = {i for i, _ in pairs}  # θ = 0 views an after-view will be matched to
        before_views: dict[int, Frame] = {}
        overlaps: list[tuple[float, float, float]] = []
        raw: list[tuple[int, list[Detection]]] = []
        obst: list[tuple[int, list[ObstacleDetection]]] = []  # 5.1.2: obstacles seen
        done = 0
        origin: Frame | None = None
        turned = [0.0, 0.0]
        times: list[float] = []  # each image's time, in the order of raw
        spans: list[list[float]] = []  # [from, to] of each stance, to be given headings
        for sweep in range(2):
            if sweep == 1:
                spans[-1][1] = self._now(spans[-1][1])
                turned[0] = motion.rotate(math.pi, PAPER_GAINS, "turn to θ = 180°")
                spans.append([self._now(math.inf)] * 2)
            for k, yaw in enumerate(yaws):
                frame = motion.look(yaw)
                times.append(frame.t_sim)
                if not spans:
                    spans.append([frame.t_sim, frame.t_sim])
                if abs(yaw) < 1e-9:
                    motion.last_frame = frame
                    if sweep == 0:
                        origin = frame
                if sweep == 0 and k in kept:
                    before_views[k] = frame
                elif sweep == 1:
                    overlaps.extend(self._overlap(before_views, pairs, k, frame))
                raw.append((sweep, ctx.perception.detect(frame.image, yaw)))
                obst.append((sweep, ctx.perception.detect_obstacles(frame.image, yaw)))
                done += 1
                ctx.report.status(
                    Phase.SEARCH, done / n, f"θ = {180 * sweep}°, head {math.degrees(yaw):+.0f}°"
                )
            # the last image of the sweep was not at yaw 0: refresh the compass reference
            motion.last_frame = motion.look(0.0)
            if origin is None:
                origin = motion.last_frame
            if sweep == 0:  # the view that defines the fixed frame
                ctx.report.journal.reference(origin.image)
        before_views.clear()
        heading_180 = b.heading
        turn = half_turn(overlaps, turned[0])
        if (
            turn is not None
            and abs(turned[0]) > 1e-3  # a rotation that turned nothing measures no gain
            and self._set_gain(turn / turned[0], f"{len(overlaps)} views")
        ):
            b.heading = wrap_pi(h0 + turn)
            heading_180 = b.heading
        else:
            log.info("half turn not measured by the views (%d matched)", len(overlaps))
            spans[-1][1] = self._now(spans[-1][1])
            turned[1] = motion.rotate(math.pi, PAPER_GAINS, "complete the circle to θ = 0°")
            spans.append([self._now(math.inf)] * 2)
            assert origin is not None and motion.last_frame is not None
            gain0 = b.compass_gain
            self._calibrate(origin, motion.last_frame, turned, h0)
            if b.compass_gain != gain0:
                heading_180 = wrap_pi(h0 + turned[0] * b.compass_gain / gain0)
        spans[-1][1] = self._now(spans[-1][1])
        heads = [h0, heading_180, b.heading][: len(spans)]
        self._stances = [
            (t0, max(t0, t1), wrap_pi(h - NORTH)) for (t0, t1), h in zip(spans, heads, strict=True)
        ]
        if self._restart is not None and self._stances and self._stances[0][0] > 0.0:
            self._stances.insert(0, (0.0, 0.0, self._restart))
        self._image_times = times
        self.obstacle_sightings = [
            ctx.perception.obstacles_fixed(o, h0 if sweep == 0 else heading_180)
            for sweep, o in obst
        ]
        return [
            ctx.perception.to_fixed(dets, h0 if sweep == 0 else heading_180) for sweep, dets in raw
        ]

    def _now(self, default: float) -> float:
        """The time of this body's last head-yaw-0 picture (``default`` if none): a bound
        of a stance, since the body stood still when it was taken."""
        frame = self.motion.last_frame
        return float(frame.t_sim) if frame is not None else default

    def _overlap(
        self, before: dict[int, Frame], pairs: tuple[tuple[int, int], ...], k: int, after: Frame
    ) -> list[tuple[float, float, float]]:
        """The compass between after-view ``k`` and the θ = 0 view it overlaps, if any:
        ``[(yaw before, yaw after, rotation)]`` (empty when the compass fails)."""
        out: list[tuple[float, float, float]] = []
        for i, j in pairs:
            if j == k and i in before:
                res = self.ctx.perception.measure_turn(before[i].image, after.image)
                if res.ok:
                    out.append((before[i].yaw, after.yaw, float(res.dtheta)))
                else:
                    log.debug("overlapping views %d/%d: %s", i, j, res.reason)
        return out

    def _set_gain(self, ratio: float, over: str) -> bool:
        """Scale the compass gain by ``ratio`` (true turn / believed turn) if plausible."""
        b = self.ctx.beliefs
        gain = b.compass_gain * ratio
        if not (math.isfinite(gain) and 0.9 <= gain <= 1.1):
            log.warning("compass gain %.4f implausible: kept %.4f", gain, b.compass_gain)
            return False
        b.compass_gain = gain
        log.info("compass calibrated over %s: gain %.4f", over, gain)
        return True

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
        if self._set_gain(
            (2.0 * math.pi + r) / total, f"the circle (residual {math.degrees(r):+.2f}°)"
        ):
            self.ctx.beliefs.heading = wrap_pi(h0 + r)

    def localise(self, sightings: list[Sightings]) -> NeighborRecordMsg:
        """This robot's record of the current round: the merged neighbours (4.1.2) and
        obstacles (5.1.2) in its fixed frame."""
        ctx = self.ctx
        ctx.report.status(Phase.LOCALISE, 0.0)
        pts, ori, conf, best = ctx.perception.merge(sightings)
        seen_at: tuple[float, ...] = ()
        if len(self._image_times) == len(sightings) and len(best):
            image = np.repeat(np.arange(len(sightings)), [len(s[0]) for s in sightings])
            seen_at = tuple(float(self._image_times[image[k]]) for k in best)
        obstacles = ctx.perception.merge_obstacles(self.obstacle_sightings)
        fault = ctx.cfg.sensor_fault
        if fault is not None:  # the evaluation's test tool, never on a real fleet
            log.warning("test tool: this robot's record carries the sensor fault %s", fault)
            pts, ori = fault.apply(pts, ori)
        rec = NeighborRecordMsg(
            sender=ctx.me,
            round=self._round,
            neighbours=tuple((float(x), float(y)) for x, y in pts),
            orientations=tuple(float(o) for o in ori),
            confidences=tuple(float(c) for c in conf),
            obstacles=tuple((float(x), float(y)) for x, y in obstacles),
            calibration=ctx.cfg.calibration,
            seen_at=seen_at,
            stances=tuple(self._stances),
            clock_error=ctx.body.clock_error if self._stances else 0.0,
        )
        self._record = rec
        ctx.report.status(Phase.LOCALISE, 1.0, f"{len(pts)} neighbours, {len(obstacles)} obstacles")
        return rec
